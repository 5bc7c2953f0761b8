#!/bin/bash
# scan.sh DRAWDIR...: scan_sign.py (beside this file) on each draw's first model
# (m0.npz) judged on its held-out log; its lines to DRAWDIR/sign.txt. Run from the
# repository root with the tree to measure on PYTHONPATH (session 24: main at b67f1cb).
here=$(cd "$(dirname "$0")" && pwd)
for d in "$@"; do
  h=$(cd "$d" && ls -d held* | grep -v "ref\|eval" | head -1)
  timeout 900 python "$here/scan_sign.py" "$d" evaluate "$h" --model m0.npz \
    --out "/tmp/scan-$(basename "$d").json" --horizons none 2>&1 | grep "^\[sign\]" > "$d/sign.txt"
  echo "$(basename "$d") $(grep -c . "$d/sign.txt")"
done
