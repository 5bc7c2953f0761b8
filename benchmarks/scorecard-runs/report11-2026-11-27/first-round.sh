#!/bin/bash
# usage: run.sh TREE LABEL ; first-round evaluate of every report11 draw 0-62 with TREE
TREE=$1; L=$2
for i in $(seq 0 62); do
  d=$(printf "/work/sc19r11/report11-%04d" $i); [ -d $d ] || d=$(printf "/work/sc19r11b/report11-%04d" $i)
  [ -f $d/m0.npz ] || continue
  held=$(python3 -c "
import json
for l in open('/tmp/s19/report11.jsonl'):
    r=json.loads(l)
    if r['index']==$i: print(r['flights'][1]['log'])")
  w=/tmp/s19/paired/$L-$i; mkdir -p $w; cd $w
  ln -sf $d/$held $held 2>/dev/null; ln -sf $d/m0.npz m0.npz
  PYTHONPATH=$TREE OMP_NUM_THREADS=1 nice -n 5 /work/main/.venv/bin/python -m omavctl evaluate $held --model m0.npz --out ev.json --horizons none --json -q > /dev/null 2> err.txt
  python3 -c "
import json; d=json.load(open('ev.json'))['diagnosis']; print($i, d.get('missing'), d.get('learned_claims'), sorted(e.get('name') for e in d.get('not_pinned') or []), d.get('fit_command'))" >> /tmp/s19/paired/$L.txt 2>/dev/null || echo "$i error" >> /tmp/s19/paired/$L.txt
done
echo done >> /tmp/s19/paired/$L.txt
