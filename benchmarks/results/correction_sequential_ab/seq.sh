#!/bin/bash
# ABAB in one code version: A = batches (TH_SEQ=0), B = sequential correction (TH_SEQ=1). Usage: seq.sh NAME ARGS...
name=$1; shift
for r in A1 B1 A2 B2; do
  case $r in A*) v=0;; B*) v=1;; esac
  out=/tmp/p/s16/abab/$name.$r
  rm -rf $out
  (cd /tmp && TH_SEQ=$v PYTHONPATH=/work/main python3 -m taichi_hair.cli simulate "$@" --profile --out $out 2>&1 | grep "stage breakdown\|^wrote" | sed 's/.*frames.npz//' | sed "s|^|$r |")
  python3 /work/shared/tools/edge_strain.py $out/frames.npz --quiet | sed "s|^|$r |"
  python3 -c "
import json;s=json.load(open('$out/summary.json'));q=s.get('quality',s)
print('$r', 'hair p99/max um %.1f/%.1f crossed %d inside %d' % (1e6*q['hair_penetration_p99_m_max'], 1e6*q['hair_penetration_max_m_max'], q['crossed_pairs_max'], q['vertices_inside_max']))"
done
