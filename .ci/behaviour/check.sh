#!/usr/bin/env bash
# check.sh CHEWBOT [OUT]: record with the install CHEWBOT (into OUT, default a new /tmp/behaviour.XXXXXX) and compare
# with the baseline recorded at 5673520. Prints the differences; exits 0 when there is none, 1 when there are,
# 2 when the recording could not be made.
set -u
HERE=$(dirname "$(realpath "$0")")
BASELINE=/work/baseline/at-5673520
INPUTS=/work/baseline/inputs
[ $# -ge 1 ] || { echo "usage: check.sh CHEWBOT [OUT]" >&2; exit 2; }
C=$1; O=${2:-$(mktemp -d /tmp/behaviour.XXXXXX)}
[ -f "$BASELINE/exits.txt" ] || { echo "check.sh: no baseline in $BASELINE (README.md says how to record it)" >&2; exit 2; }
PY=$(dirname "$(realpath -s "$C")")/python
[ -x "$PY" ] || PY=python3
echo "recording with $C into $O"
"$HERE/record.sh" "$C" "$O" "$INPUTS" || exit 2
"$PY" "$HERE/compare.py" "$BASELINE" "$O"
