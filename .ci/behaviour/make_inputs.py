"""make_inputs.py [OUT]: the behaviour baseline's inputs, written into OUT (default /work/baseline/inputs).

Every input is a shipped example as it was at the baseline's commit, read from git (not from the working tree,
whose examples later issues change on purpose), plus the grid sweep's SPEC. The same bytes from any clone that
holds the commit, whatever its checked-out branch; an OUT written
by this script before (with its SHA256SUMS) is replaced as a whole, any other non-empty folder refused.
"""
import hashlib
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

BASELINE = "5673520"
REPO = Path(__file__).resolve().parents[2]
# input name in OUT -> path in the repository at BASELINE; the commands of record.sh name the left side
EXAMPLES = {
    "markers.csv": "examples/markers/chewing.csv",          # import-motion (fixed registration)
    "markers.toml": "examples/markers/subject.toml",
    "robot_log.csv": "examples/robot_log.csv",              # identify, estimate-force
    "incisor.csv": "examples/incisor.csv",                  # track-incisor
    "bite.csv": "examples/bite.csv",                        # simulate --controller hybrid --food cheddar
    "chewing.csv": "examples/recordings/chewing.csv",       # import-motion --fit-registration
    "chewing.toml": "examples/recordings/chewing.toml",
}
SPEC = """\
kind = "grid"
model = "target"
side = "left"
maps = ["workspace", "singularity", "force"]
[grid]
X_mm = { range = [-4.0, 8.0], steps = 4 }
beta_deg = { range = [0.0, 24.0], steps = 4 }
"""


def main() -> None:
    out = Path(sys.argv[1] if len(sys.argv) > 1 else "/work/baseline/inputs").resolve()
    if out.exists() and any(out.iterdir()) and not (out / "SHA256SUMS").exists():
        sys.exit(f"make_inputs.py: {out} is not empty and holds no inputs of this script (no SHA256SUMS): "
                 "give an empty or new folder")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".inputs-", dir=out.parent))
    try:
        for name, path in EXAMPLES.items():
            data = subprocess.run(["git", "-C", str(REPO), "show", f"{BASELINE}:{path}"],
                                  check=True, capture_output=True).stdout
            (tmp / name).write_bytes(data)
        (tmp / "spec.toml").write_text(SPEC)
        (tmp / "SHA256SUMS").write_text("".join(
            f"{hashlib.sha256(f.read_bytes()).hexdigest()}  {f.name}\n" for f in sorted(tmp.iterdir())))
        shutil.rmtree(out, ignore_errors=True)
        tmp.chmod(0o755)
        tmp.rename(out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    print(f"inputs of {BASELINE} in {out}")


if __name__ == "__main__":
    main()
