#!/bin/bash
# The solver sweep of BENCHMARKS.md ("10^5 states of every shipped problem file"): N uniform
# random states per configs/*.toml (Python random.Random(14)), solved cold by `trainer solve`;
# prints the status counts per file. Then, per file, `python3 tests/reference/solver_sweep_ipopt.py
# NAME OUT` solves the non-converged, the retried and 200 other states by IPOPT.
# Usage (from the repository root): tests/reference/solver_sweep.sh BIN [N] [OUT]
set -euo pipefail
BIN=$1; N=${2:-100000}; OUT=${3:-sweep}
mkdir -p "$OUT"
for f in configs/*.toml; do
  n=$(basename "$f" .toml)
  python3 - "$f" "$N" > "$OUT/$n.csv" <<'PY'
import sys, tomllib, random
c = tomllib.load(open(sys.argv[1], 'rb')); n = int(sys.argv[2])
lo, hi = c['domain']['lo'], c['domain']['hi']
r = random.Random(14)
print(','.join(f'x{k+1}' for k in range(len(lo))))
for _ in range(n):
    print(','.join(repr(l + (h - l) * r.random()) for l, h in zip(lo, hi)))
PY
  s=$(date +%s)
  "$BIN" solve --config "$f" --states "$OUT/$n.csv" --out "$OUT/$n.out.csv" 2> "$OUT/$n.err"
  e=$(date +%s)
  echo "$n $((e-s))s $(python3 -c "
import csv,collections
r=csv.DictReader(open('$OUT/$n.out.csv'));print(dict(collections.Counter(row['status'] for row in r)))") $(tail -1 "$OUT/$n.err")"
done
