#!/usr/bin/env bash
# record.sh CHEWBOT OUTDIR [INPUTS]: the outputs of 25 representative commands of one chewbot install, in OUTDIR.
# INPUTS (default /work/baseline/inputs) is what make_inputs.py writes. OUTDIR is replaced if it holds an earlier
# recording (its exits.txt); any other non-empty folder is refused.
set -u
C=$(realpath "$1"); O=$(realpath -m "$2"); I=$(realpath "${3:-/work/baseline/inputs}")
[ -x "$C" ] || { echo "record.sh: $C is not an executable chewbot" >&2; exit 2; }
[ -f "$I/SHA256SUMS" ] || { echo "record.sh: $I holds no inputs (run make_inputs.py $I)" >&2; exit 2; }
(cd "$I" && sha256sum --quiet -c SHA256SUMS) || { echo "record.sh: the inputs in $I were changed" >&2; exit 2; }
if [ -e "$O" ] && [ -n "$(ls -A "$O")" ] && [ ! -f "$O/exits.txt" ]; then
  echo "record.sh: $O is not empty and is no recording (no exits.txt): give an empty or new folder" >&2; exit 2
fi
rm -rf "$O"; mkdir -p "$O"; cd "$O" || exit 2
# exits.txt (compared): each command's exit code; times.txt (not compared): its wall time in seconds
r() {
  local name=$1 start=$SECONDS; shift
  "$C" "$@" > "$name.log" 2>&1
  echo "$name exit $?" | tee -a exits.txt
  echo "$name $((SECONDS - start))" >> times.txt
}
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
r sweep sweep "$I/spec.toml" --workers 1 --out sweep
r identify identify "$I/robot_log.csv" --model target --out identified.toml
r import import-motion "$I/markers.csv" --registration "$I/markers.toml" --out task.csv
r track track-incisor "$I/incisor.csv" --out track.csv
r run-track run --task track.csv --out run-track
r tpa tpa --food cheddar --out tpa
r estimate-force estimate-force "$I/robot_log.csv" --model target --out force.csv
r sim-hybrid simulate --controller hybrid --food cheddar --task "$I/bite.csv" --out sim-hybrid
r sim-mujoco simulate --plant-engine mujoco --out sim-mujoco
r export-ct export-controller --out export-ct
r export-ne export-controller --method newton-euler --friction on --out export-ne
r import-fit import-motion "$I/chewing.csv" --registration "$I/chewing.toml" --fit-registration --out fit.csv
