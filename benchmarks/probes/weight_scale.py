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
import sys

import numpy as np


def parse(argv):
    """(duration, drag, dt) from the command line's words."""
    duration = float(argv[0]) if len(argv) > 0 else 2.0
    drag = float(argv[1]) if len(argv) > 1 else 0.0
    dt = 1 / float(argv[2]) if len(argv) > 2 else 1 / 96
    return duration, drag, dt


def weight_rules(paper, inertia, active) -> dict:
    """The W_y rules compared: the paper's w0 = 25 scaled down, and the vertex inertia m / dt^2."""
    return {
        "paper w0=25": paper,
        "w0=5": paper / 5,
        "w0=2": paper / 12.5,
        "w0=1": paper / 25,
        "w0=0.5": paper / 50,
        "w0=0.25": paper / 100,
        "inertia x1": np.where(active, inertia, 0.0),
        "inertia x100": np.where(active, 100 * inertia, 0.0),
    }


def run(duration: float, drag: float, dt: float) -> None:
    from taichi_hair import SolverADMM, SolverADMMConfig
    from taichi_hair.bench.stability import HAIR, build_case_model, default_cases

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
    rules = weight_rules(paper, inertia, active)
    print(f"dt 1/{1 / dt:.0f} s, 10 iterations, {duration} s, drag {drag} /s; per rod: tip distance to equilibrium / L, "
          "max strain %")
    print("rule                    " + "".join(f"{c.name:>24s}" for c in cases))
    for name, w in rules.items():
        solver.buf.pair_admm_weight.from_numpy(w.astype(np.float32))
        solver.reset_duals()
        model.reset_state(st)
        for k in range(int(round(duration / dt))):
            solver.step(st, ct, dt)
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


def main(argv=None) -> int:
    args = parse(sys.argv[1:] if argv is None else list(argv))
    import taichi as ti

    import taichi_hair

    taichi_hair.init(arch=ti.cpu, log_level=ti.WARN)
    run(*args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
