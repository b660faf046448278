"""The stability atlas of ADMM at two constraint weight scales w0 (issue 12 item 5's measurement).

Run from the repository root:
    python3 benchmarks/probes/atlas_w0.py W0_A,W0_B      # e.g. 1,25

Runs ``taichi_hair.bench.stability.run_atlas`` for its two ADMM rows with their w0 set to W0_A ("admm") and
W0_B ("admm_w1") instead of the study's 25 and 1, and prints the summary and every cell.  A diagnostic: the
study itself (``taichi-hair bench stability``) keeps its two rows.
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
import taichi as ti  # noqa: E402

ti.init(arch=ti.cpu, log_level=ti.WARN)
from taichi_hair.bench import stability as S  # noqa: E402

w = [float(a) for a in sys.argv[1].split(",")]
S.ADMM_W0["admm"], S.ADMM_W0["admm_w1"] = w[0], w[1]
cells = S.run_atlas(methods=("admm", "admm_w1"))
print(f"admm = w0 {w[0]}, admm_w1 = w0 {w[1]}")
print(S.format_summary(cells))
for c in cells:
    print(c.method, c.case, f"dt=1/{1 / c.dt:.0f}", c.knob, c.label, c.reason,
          f"sag {c.sag_error:.3g} stretch {c.stretch:.3g} speed {c.tip_speed:.3g}")
