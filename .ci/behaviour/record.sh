#!/usr/bin/env bash
# record.sh CHEWBOT OUTDIR : representative commands' outputs (issue 18 behaviour baseline)
C=$1; O=$2; I=/work/baseline/inputs
rm -rf "$O"; mkdir -p "$O"; cd "$O"
cat > spec.toml <<'S'
kind = "grid"
model = "target"
side = "left"
maps = ["workspace", "singularity", "force"]
[grid]
X_mm = { range = [-4.0, 8.0], steps = 4 }
beta_deg = { range = [0.0, 24.0], steps = 4 }
S
r() { name=$1; shift; "$C" "$@" > "$name.log" 2>&1; echo "$name exit $?" | tee -a exits.txt; }
r run-hessian run --out run-hessian
r run-lagrange run --method lagrange --out run-lagrange
r run-liang run --method liang --out run-liang
r run-ne run --method newton-euler --goal min-hkp-force --friction on --out run-ne
r run-ne-uni run --method newton-euler --contact unilateral --set contact.preload_N=2 --out run-ne-uni
r run-ep run --orientation euler-parameters --out run-ep
r run-6rss run --model 6rss --side right --out run-6rss
r run-6rss-core run --model 6rss --method 6rss-core --out run-6rss-core
r run-6rss-lagrange run --model 6rss --method lagrange --out run-6rss-lagrange
r sim-ff simulate --controller feedforward --out sim-ff
r sim-pd simulate --controller pd --out sim-pd
r sim-ct simulate --controller computed-torque --out sim-ct
r sim-cmp simulate --compare --plant-set mandible.mass_g=408 --out sim-cmp
r sweep sweep spec.toml --workers 1 --out sweep
r identify identify $I/log.csv --model target --out identified.toml
r import import-motion $I/rec.csv --registration $I/reg.toml --out task.csv
r track track-incisor $I/incisor.csv --out track.csv
r run-track run --task track.csv --out run-track
