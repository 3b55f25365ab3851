"""compare.py BEFORE AFTER: two recordings of record.sh, file by file; prints the differences, exits 1 on any.

- A folder that holds chewbot-export.json (what export-controller writes) is compared byte for byte, every file.
- Elsewhere: CSV cell by cell, JSON value by value, Parquet cell by cell (and its schema with the units), every
  other text file (TOML, XML, Markdown, exits.txt) line by line; comment lines are compared too. Numbers, in
  cells and inside text, are equal to 1e-12 relative; other text (and a hexadecimal digest) is equal exactly.
- Left out: figures and reports (.png, .svg, .html), the consoles (.log), times.txt, the JSON keys of timings,
  versions, the platform, start and finish dates and the command line (IGNORED below, by exact name); in every
  string and JSON key, an absolute path is reduced to its file name (the install's and the recording's folders
  differ, the file named must not), a version after "chewbot", the port of a local Dask scheduler and the fit's
  search time are masked. A sweep's spec_sha256, a digest over absolute paths, is checked on each side instead.
"""
import csv
import hashlib
import json
import math
import re
import sys
from pathlib import Path

RTOL = 1e-12
IGNORED = {"timings", "versions", "version", "mujoco_version", "platform", "created", "started", "finished",
           "written", "elapsed_s", "wall_s", "command", "argv", "cwd", "host", "environment"}
# a sweep's SHA-256 of its SPEC and input files, keyed by the files' absolute paths: checked on each side against
# the record's "spec" and "inputs" (which are compared) instead of between the sides (spec_digest)
DIGESTS = {"spec_sha256"}
SKIPPED = {".png", ".svg", ".html", ".log"}
SKIPPED_FILES = {"times.txt"}
EXPORT_MARK = "chewbot-export.json"
SHOWN = 3                                     # differences listed per file; the rest counted

NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|[-+]?(?:nan|inf)\b")
ABSOLUTE = re.compile(r"(?<![\w.~])/(?:[^/\s'\"`,;:()\[\]{}<>=|]+/)+([^/\s'\"`,;:()\[\]{}<>=|]*)")
LOCAL_PORT = re.compile(r"(://(?:127\.0\.0\.1|localhost|\[::1\])):\d+")
VERSION = re.compile(r"\b(chewbot) \d+(?:\.\d+)+(?:[.+-]?[A-Za-z0-9]+)*")
DIGEST = re.compile(r"[0-9a-f]{32,}")
WALL_TIME = re.compile(r"(\d+ evaluations), [0-9.eE+-]+ s\b")    # import-motion --fit-registration's search time


def normal(text: str) -> str:
    """The string with absolute paths reduced to their file names, local ports, chewbot's version and wall times
    masked."""
    text = WALL_TIME.sub(r"\1, WALL s", text)
    text = LOCAL_PORT.sub(r"\1:PORT", text)
    text = ABSOLUTE.sub(r"\1", text)
    return VERSION.sub(r"\1 VERSION", text)


def close(a: float, b: float) -> bool:
    if a == b or (math.isnan(a) and math.isnan(b)):
        return True
    if not (math.isfinite(a) and math.isfinite(b)):
        return False
    return abs(a - b) <= RTOL * max(abs(a), abs(b))


def same_text(a: str, b: str) -> bool:
    """Equal text between the numbers, numbers equal to RTOL."""
    if a == b:
        return True
    if DIGEST.fullmatch(a):
        return False
    a, b = normal(a), normal(b)
    if a == b:
        return True
    if NUMBER.split(a) != NUMBER.split(b):
        return False
    x, y = NUMBER.findall(a), NUMBER.findall(b)
    return len(x) == len(y) and all(close(float(u), float(v)) for u, v in zip(x, y))


class File:
    """The differences found in one file: the first SHOWN listed, the rest counted."""

    def __init__(self, name: str, found: list[str]):
        self.name, self.found, self.count = name, found, 0

    def add(self, where: str, before, after) -> None:
        self.count += 1
        if self.count <= SHOWN:
            a, b = str(before), str(after)
            start = max(0, next((i for i, (x, y) in enumerate(zip(a, b)) if x != y), min(len(a), len(b))) - 40)
            cut = "..." if start else ""
            self.found.append(f"{self.name}{where}: {cut + a[start:start + 120]!r} vs {cut + b[start:start + 120]!r}")

    def close(self) -> None:
        if self.count > SHOWN:
            self.found.append(f"{self.name}: {self.count} differences in all")


def keyed(d: dict) -> dict:
    """The dictionary with its keys normalised (a sweep's inputs are keyed by absolute path); a key met again
    after normalising gets its order of appearance."""
    out = {}
    for k, v in d.items():
        n = normal(k)
        out[n if n not in out else f"{n} #{sum(1 for m in out if m.startswith(n))}"] = v
    return out


def values(a, b, where: str, f: File) -> None:
    if isinstance(a, dict) and isinstance(b, dict):
        a, b = keyed(a), keyed(b)
        for k in sorted(set(a) | set(b)):
            if k in IGNORED or k in DIGESTS:
                continue
            if k not in a or k not in b:
                f.add(f"{where}.{k}", "(absent)" if k not in a else "present", "(absent)" if k not in b else "present")
            else:
                values(a[k], b[k], f"{where}.{k}", f)
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            f.add(where, f"{len(a)} items", f"{len(b)} items")
        else:
            for i, (x, y) in enumerate(zip(a, b)):
                values(x, y, f"{where}[{i}]", f)
    elif isinstance(a, bool) or isinstance(b, bool) or a is None or b is None:
        if a is not b:
            f.add(where, a, b)
    elif isinstance(a, (int, float)) and isinstance(b, (int, float)):
        if not close(float(a), float(b)):
            f.add(where, a, b)
    elif isinstance(a, str) and isinstance(b, str):
        if not same_text(a, b):
            f.add(where, a, b)
    elif a != b:
        f.add(where, a, b)


def spec_digest(record: dict, side: str, f: File) -> None:
    """A sweep's spec_sha256 is the SHA-256 of its SPEC's values (without "source") and its input files' digests
    (chewbot.sweep.spec.SweepSpec.digest), the one value that holds the install's absolute paths."""
    if "spec_sha256" in record:
        d = {k: v for k, v in record["spec"].items() if k != "source"}
        d["files"] = dict(sorted(record["inputs"].items()))
        digest = hashlib.sha256(json.dumps(d, sort_keys=True, default=str).encode()).hexdigest()
        if digest != record["spec_sha256"]:
            f.add(f".spec_sha256 ({side})", f"SHA-256 of spec and inputs {digest}", f"recorded {record['spec_sha256']}")


def lines(a: list[str], b: list[str], f: File) -> None:
    if len(a) != len(b):
        f.add("", f"{len(a)} lines", f"{len(b)} lines")
    for i, (x, y) in enumerate(zip(a, b)):
        if not same_text(x, y):
            f.add(f":{i + 1}", x, y)


def cells(fb: Path, fa: Path, f: File) -> None:
    lb, la = fb.read_text().splitlines(), fa.read_text().splitlines()
    if len(lb) != len(la):
        f.add("", f"{len(lb)} lines", f"{len(la)} lines")
    for i, (x, y) in enumerate(zip(lb, la)):
        if x == y:
            continue
        x, y = next(csv.reader([x])), next(csv.reader([y]))
        if len(x) != len(y):
            f.add(f":{i + 1}", f"{len(x)} cells", f"{len(y)} cells")
            continue
        for j, (u, v) in enumerate(zip(x, y)):
            if not same_text(u, v):
                f.add(f":{i + 1} column {j + 1}", u, v)


def parquet(fb: Path, fa: Path, f: File) -> None:
    import pyarrow.parquet as pq
    x, y = pq.read_table(fb), pq.read_table(fa)
    if not x.schema.equals(y.schema, check_metadata=True):
        f.add(" schema", x.schema, y.schema)
        return
    if x.num_rows != y.num_rows:
        f.add("", f"{x.num_rows} rows", f"{y.num_rows} rows")
        return
    for name in x.column_names:
        for i, (u, v) in enumerate(zip(x.column(name).to_pylist(), y.column(name).to_pylist())):
            values(u, v, f" {name}[{i}]", f)


def main() -> int:
    before, after = Path(sys.argv[1]), Path(sys.argv[2])
    if not (before / "exits.txt").is_file() or not (after / "exits.txt").is_file():
        sys.exit(f"compare.py: {before} and {after} must both be recordings of record.sh (with exits.txt)")
    exported = [p.parent for p in before.rglob(EXPORT_MARK)]

    def compared(p: Path) -> bool:
        return p.is_file() and (any(d in p.parents for d in exported) or
                                (p.suffix not in SKIPPED and p.name not in SKIPPED_FILES))

    found: list[str] = []
    for fb in sorted(p for p in before.rglob("*") if compared(p)):
        rel = fb.relative_to(before)
        fa = after / rel
        f = File(str(rel), found)
        if not fa.is_file():
            found.append(f"{rel}: missing after")
        elif any(d in fb.parents for d in exported):
            if fb.read_bytes() != fa.read_bytes():
                found.append(f"{rel}: the bytes differ (an exported controller's file)")
        elif fb.suffix == ".csv":
            cells(fb, fa, f)
        elif fb.suffix == ".json":
            b, a = json.loads(fb.read_text()), json.loads(fa.read_text())
            values(b, a, "", f)
            for record, side in ((b, "before"), (a, "after")):
                if isinstance(record, dict):
                    spec_digest(record, side, f)
        elif fb.suffix == ".parquet":
            parquet(fb, fa, f)
        else:
            lines(fb.read_text(errors="replace").splitlines(), fa.read_text(errors="replace").splitlines(), f)
        f.close()
    exported_after = [after / d.relative_to(before) for d in exported]
    for fa in sorted(after.rglob("*")):
        rel = fa.relative_to(after)
        if (fa.is_file() and not (before / rel).exists()
                and (any(d in fa.parents for d in exported_after) or compared(fa))):
            found.append(f"{rel}: new after")
    print("\n".join(found + [f"{len(found)} difference(s) between {before} and {after}"]))
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
