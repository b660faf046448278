#!/bin/bash
# ABAB: A = 1a06b01 (worktree /tmp/wt15), B = /work/main HEAD. Usage: run.sh NAME ARGS...
name=$1; shift
for r in A1 B1 A2 B2; do
  case $r in A*) pp=/tmp/wt15;; B*) pp=/work/main;; esac
  out=/tmp/p/s16/abab/$name.$r
  rm -rf $out
  (cd /tmp && PYTHONPATH=$pp python3 -m taichi_hair.cli simulate "$@" --quiet --profile --out $out 2>&1 | grep -v "^\[Taichi\]\|^warning" | grep -i "correction\|wrote" | sed "s|^|$r |")
  python3 /work/shared/tools/edge_strain.py $out/frames.npz --quiet | sed "s|^|$r |"
  python3 -c "
import json;s=json.load(open('$out/summary.json'));q=s.get('quality',s)
print('$r', 'hair p99/max um %.1f/%.1f crossed %d inside %d' % (1e6*q['hair_penetration_p99_m_max'], 1e6*q['hair_penetration_max_m_max'], q['crossed_pairs_max'], q['vertices_inside_max']))"
done
