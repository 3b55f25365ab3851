"""compare.py BEFORE AFTER: numbers equal to 1e-12 relative; text equal; timings/versions/paths ignored."""
import json, math, sys
from pathlib import Path

B, A = Path(sys.argv[1]), Path(sys.argv[2])
IGN = {"timings", "versions", "created", "started", "finished", "elapsed_s", "wall_s", "host", "platform",
       "python", "command", "argv", "cwd", "date", "time_s", "seconds", "environment", "written", "duration_s_wall"}
diffs = []

def num(x):
    try:
        return float(x)
    except ValueError:
        return None

def close(a, b):
    if a == b or (math.isnan(a) and math.isnan(b)):
        return True
    return abs(a - b) <= 1e-12 * max(abs(a), abs(b), 1e-300) or abs(a - b) < 1e-300

def cmp_obj(a, b, where):
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if k in IGN or "timing" in k or "version" in k or k.endswith("_time") or k.endswith("path"):
                continue
            if k not in a or k not in b:
                diffs.append(f"{where}.{k}: only in {'after' if k in b else 'before'}"); continue
            cmp_obj(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            diffs.append(f"{where}: length {len(a)} vs {len(b)}"); return
        for i, (x, y) in enumerate(zip(a, b)):
            cmp_obj(x, y, f"{where}[{i}]")
    elif isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool):
        if not close(float(a), float(b)):
            diffs.append(f"{where}: {a!r} vs {b!r}")
    elif a != b:
        diffs.append(f"{where}: {str(a)[:120]!r} vs {str(b)[:120]!r}")

def cmp_csv(fb, fa, name):
    lb = [l for l in fb.read_text().splitlines() if not l.startswith("#")]
    la = [l for l in fa.read_text().splitlines() if not l.startswith("#")]
    if len(lb) != len(la):
        diffs.append(f"{name}: {len(lb)} vs {len(la)} lines"); return
    bad = 0
    for i, (x, y) in enumerate(zip(lb, la)):
        cx, cy = x.split(","), y.split(",")
        if len(cx) != len(cy):
            diffs.append(f"{name}:{i}: {len(cx)} vs {len(cy)} cells"); return
        for j, (u, v) in enumerate(zip(cx, cy)):
            nu, nv = num(u), num(v)
            ok = (u == v) if nu is None or nv is None else close(nu, nv)
            if not ok:
                bad += 1
                if bad <= 3:
                    diffs.append(f"{name}: line {i} col {j}: {u} vs {v}")
    if bad > 3:
        diffs.append(f"{name}: {bad} cells differ in all")

for fb in sorted(B.rglob("*")):
    if fb.is_dir() or fb.suffix in (".png", ".html", ".log", ".out") or ".kcache" in fb.parts:
        continue
    rel = fb.relative_to(B); fa = A / rel
    if not fa.exists():
        diffs.append(f"{rel}: missing after"); continue
    if fb.suffix == ".csv":
        cmp_csv(fb, fa, str(rel))
    elif fb.suffix == ".json":
        cmp_obj(json.loads(fb.read_text()), json.loads(fa.read_text()), str(rel))
    elif fb.suffix == ".parquet":
        import pandas as pd
        x, y = pd.read_parquet(fb), pd.read_parquet(fa)
        if list(x.columns) != list(y.columns) or len(x) != len(y):
            diffs.append(f"{rel}: shape/columns differ")
        else:
            for c in x.columns:
                for i, (u, v) in enumerate(zip(x[c], y[c])):
                    if isinstance(u, float) and isinstance(v, float):
                        if not close(u, v): diffs.append(f"{rel}:{c}[{i}] {u} vs {v}"); break
                    elif u != v: diffs.append(f"{rel}:{c}[{i}] {u} vs {v}"); break
    else:
        tb = [l for l in fb.read_text(errors="replace").splitlines() if not l.startswith("#")]
        ta = [l for l in fa.read_text(errors="replace").splitlines() if not l.startswith("#")]
        if tb != ta:
            d = next(i for i, (x, y) in enumerate(zip(tb + [""], ta + [""])) if x != y)
            diffs.append(f"{rel}: line {d}: {tb[d:d+1]} vs {ta[d:d+1]}")
for fa in sorted(A.rglob("*")):
    if fa.is_file() and not (B / fa.relative_to(A)).exists() and fa.suffix not in (".png", ".html", ".log"):
        diffs.append(f"{fa.relative_to(A)}: new after")
print("\n".join(diffs)); print(f"{len(diffs)} difference(s)")
