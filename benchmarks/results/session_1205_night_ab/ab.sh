#!/bin/bash
# usage: ab.sh TAG ARGS... ; runs A (wt15) and B (main) alternately twice
tag=$1; shift
for r in 1 2; do
for v in A B; do
  if [ $v = A ]; then root=/tmp/wt15; else root=/work/main; fi
  d=/tmp/p/s17/ab_${tag}_$v$r; rm -rf $d
  (cd $root && PYTHONPATH=$root python3 -m taichi_hair.cli.main simulate "$@" --quiet --out $d 2>&1 | grep wrote | sed 's/.*(\(.*ms\/frame\).*/\1/' | sed "s/^/$v$r /")
  python3 - $d <<'PY'
import json, sys
q = json.load(open(sys.argv[1] + "/summary.json"))["quality"]
print(f"   strain p99 {100*q['strain_p99_max']:.3f} max {100*q['strain_max']:.3f} %, hair p99 {1e6*q.get('hair_penetration_p99_m_max',0):.1f} max {1e6*q.get('hair_penetration_max_m_max',0):.0f} um, crossed {q.get('crossed_pairs_max')}, inside {q['vertices_inside_max']}")
PY
done; done
