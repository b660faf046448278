"""How the ADMM constraint weights W_y decide whether a dynamic run comes to rest (issue 12 item 5).

Run from the repository root:
    python3 benchmarks/probes/weight_scale.py [DURATION_S] [DRAG_PER_S] [STEPS_PER_S]

The four rods of the stability atlas (taichi_hair.bench.stability.default_cases: short, long,
edge-variance, stretch-stiff), clamped horizontally, released from straight under gravity; dynamic ADMM,
dt = 1/STEPS_PER_S s (96), 10 iterations, optional air drag (velocity relaxation rate DRAG_PER_S, 0 = undamped).  The
reference is the same Model's own equilibrium: quasistatic ADMM (w0 = 5, 4,000 steps of 10 iterations).
For each weight rule W_y it prints, per rod, the tip's distance to that equilibrium after DURATION_S
(default 2 s), relative to the rod length, the largest edge strain, and whether the run stayed finite.
W_y is overwritten in the solver's buffer (same kernels, no recompilation).  A diagnostic, not a
benchmark.
"""

import math
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, ROOT)
import numpy as np  # noqa: E402
import taichi as ti  # noqa: E402

ti.init(arch=ti.cpu, log_level=ti.WARN)
from taichi_hair import SolverADMM, SolverADMMConfig  # noqa: E402
from taichi_hair.bench.stability import HAIR, build_case_model, default_cases  # noqa: E402

duration = float(sys.argv[1]) if len(sys.argv) > 1 else 2.0
drag = float(sys.argv[2]) if len(sys.argv) > 2 else 0.0
dt = 1 / float(sys.argv[3]) if len(sys.argv) > 3 else 1 / 96
cases = default_cases()
model = build_case_model(cases)
h = model.host
starts, counts = h["strand_vertex_start"], h["strand_vertex_count"]
tips = starts + counts - 1
lengths = np.array([c.length for c in cases])
rho_a = HAIR["density"] * math.pi * HAIR["radius"] ** 2

# The Model's own equilibrium.
qs = SolverADMM(model, SolverADMMConfig(mode="quasistatic", w0=5.0, iterations=10))
st, ct = model.state(), model.control()
for k in range(4000):
    qs.step(st, ct, 1.0)
x_eq = st.positions().astype(np.float64)
xe2 = x_eq.copy()
for k in range(200):
    qs.step(st, ct, 1.0)
drift = np.linalg.norm(st.positions()[tips] - xe2[tips], axis=1) / lengths
print("equilibrium: tip drift over the last 200 quasistatic steps / L:", " ".join(f"{d:.1e}" for d in drift))

solver = SolverADMM(model, SolverADMMConfig(iterations=10, w0=25.0, air_viscosity=drag * rho_a,
                                            check_finite=False))
paper = solver.buf.pair_admm_weight.to_numpy().astype(np.float64)        # 25 E_b A R^2 / (4 v*^3)
mass = h["vertex_mass"].astype(np.float64)
inertia = mass / dt**2
active = h["pair_is_active"].astype(bool)
rules = {
    "paper w0=25": paper,
    "w0=5": paper / 5,
    "w0=2": paper / 12.5,
    "w0=1": paper / 25,
    "w0=0.5": paper / 50,
    "w0=0.25": paper / 100,
    "inertia x1": np.where(active, inertia, 0.0),
    "inertia x100": np.where(active, 100 * inertia, 0.0),
}
real = h["edge_rest_length"] > 0
print(f"dt 1/{1 / dt:.0f} s, 10 iterations, {duration} s, drag {drag} /s; per rod: tip distance to equilibrium / L, "
      "max strain %")
print("rule                    " + "".join(f"{c.name:>24s}" for c in cases))
for name, w in rules.items():
    run = solver
    run.buf.pair_admm_weight.from_numpy(w.astype(np.float32))
    run.reset_duals()
    model.reset_state(st)
    for k in range(int(round(duration / dt))):
        run.step(st, ct, dt)
    x = st.positions().astype(np.float64)
    cells = []
    for i, (s, c) in enumerate(zip(starts, counts)):
        xs = x[s:s + c]
        if not np.isfinite(xs).all():
            cells.append(f"{'non-finite':>24s}")
            continue
        e = np.linalg.norm(np.diff(xs, axis=0), axis=1)
        strain = np.abs(e / h["edge_rest_length"][s:s + c - 1] - 1).max()
        err = np.linalg.norm(x[tips[i]] - x_eq[tips[i]]) / lengths[i]
        cells.append(f"{err:13.2e} {100 * strain:9.3f}")
    print(f"{name:24s}" + "".join(cells), flush=True)
