"""How fast one ADMM step converges, and whether the rods come to rest (issue 12 item 5; anderson.py).

Run from the repository root:
    python3 benchmarks/probes/admm_convergence.py step [STEPS_PER_S] [STATE_TIME_S]
    python3 benchmarks/probes/admm_convergence.py settle [STEPS_PER_S] [DURATION_S]

The four rods of the stability atlas (``taichi_hair.bench.stability.default_cases``), clamped
horizontally and released under gravity, drag 8 /s, dynamic backward Euler.

``step``: from the state at STATE_TIME_S (default 0.3 s, mid-fall; reached with 200 iterations per
step), one step with K iterations for each weight scale w0 and Anderson window; printed per rod:
max |x_K - x_ref| / max |x_ref - x_start|, x_ref the same step with 3,000 plain iterations.  The
warm-started duals are rescaled to each w0 (the force W_y lambda is the invariant).

``settle``: tip distance to the Model's own equilibrium (quasistatic, 4,000 steps of 10 iterations)
every 0.5 s over DURATION_S (default 2 s), 10 iterations per step, w0 = 1, Anderson window 0 and 5.
A diagnostic, not a benchmark.
"""

import math
import sys

import numpy as np


def _setup():
    from taichi_hair.bench.stability import HAIR, build_case_model, default_cases

    cases = default_cases()
    model = build_case_model(cases)
    drag = 8.0 * HAIR["density"] * math.pi * HAIR["radius"] ** 2
    return cases, model, drag


def step_study(steps_per_s: float, t_state: float) -> None:
    from taichi_hair import SolverADMM, SolverADMMConfig

    cases, model, drag = _setup()
    h = model.host
    starts, counts = h["strand_vertex_start"], h["strand_vertex_count"]
    dt = 1.0 / steps_per_s
    st, ct = model.state(), model.control()
    solvers = {w: SolverADMM(model, SolverADMMConfig(iterations=200, w0=1.0, air_viscosity=drag,
                                                     check_finite=False, anderson_window=w)) for w in (0, 5)}
    base = solvers[0]
    for _ in range(int(round(t_state / dt))):
        base.step(st, ct, dt)
    snap_state, snap = st.to_numpy(), base.checkpoint()
    x_start = st.positions().astype(np.float64)
    w_base = base.buf.pair_admm_weight.to_numpy().astype(np.float64)

    def one(window: int, w0: float, k: int) -> np.ndarray:
        solver = solvers[window]
        st.load(snap_state)
        solver.restore(snap)
        solver.buf.pair_dual.from_numpy((snap["pair_dual"] / w0).astype(snap["pair_dual"].dtype))
        solver.buf.pair_admm_weight.from_numpy((w0 * w_base).astype(np.float32))
        solver.config.iterations = k
        solver.step(st, ct, dt)
        return st.positions().astype(np.float64)

    x_ref = one(0, 1.0, 3000)
    ks = (5, 10, 20, 50, 100)
    print(f"dt 1/{steps_per_s:.0f} s, state at {t_state} s; error of one step after K iterations, per rod "
          f"({' / '.join(c.name for c in cases)})")
    for window in (0, 5):
        for w0 in (0.1, 0.3, 1.0, 3.0):
            row = []
            for k in ks:
                x = one(window, w0, k)
                err = [np.abs(x[s:s + c] - x_ref[s:s + c]).max() / np.abs(x_ref[s:s + c] - x_start[s:s + c]).max()
                       for s, c in zip(starts, counts)]
                row.append("/".join(f"{e:.0e}" for e in err))
            print(f"anderson {window} w0 {w0:4}  " + "  ".join(f"K{k}: {r}" for k, r in zip(ks, row)), flush=True)


def settle_study(steps_per_s: float, duration: float) -> None:
    from taichi_hair import SolverADMM, SolverADMMConfig

    cases, model, drag = _setup()
    h = model.host
    tips = h["strand_vertex_start"] + h["strand_vertex_count"] - 1
    lengths = np.array([c.length for c in cases])
    st, ct = model.state(), model.control()
    qs = SolverADMM(model, SolverADMMConfig(mode="quasistatic", w0=5.0, iterations=10, anderson_window=0))
    for _ in range(4000):
        qs.step(st, ct, 1.0)
    x_eq = st.positions().astype(np.float64)
    dt = 1.0 / steps_per_s
    every = int(round(0.5 / dt))
    print(f"dt 1/{steps_per_s:.0f} s, 10 iterations, w0 = 1, drag 8 /s: tip distance to equilibrium / L every 0.5 s")
    for window in (0, 5):
        solver = SolverADMM(model, SolverADMMConfig(iterations=10, w0=1.0, air_viscosity=drag, check_finite=False,
                                                    anderson_window=window))
        model.reset_state(st)
        rows = []
        for k in range(1, int(round(duration / dt)) + 1):
            solver.step(st, ct, dt)
            if k % every == 0:
                rows.append(np.linalg.norm(st.positions()[tips] - x_eq[tips], axis=1) / lengths)
        rows = np.array(rows)
        print(f"anderson window {window}")
        for j, c in enumerate(cases):
            print(f"  {c.name:14s} " + " ".join(f"{v:.1e}" for v in rows[:, j]), flush=True)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if not argv or argv[0] not in ("step", "settle"):
        print(__doc__)
        return 2
    import taichi as ti

    import taichi_hair

    taichi_hair.init(arch=ti.cpu, log_level=ti.WARN)
    rate = float(argv[1]) if len(argv) > 1 else 96.0
    if argv[0] == "step":
        step_study(rate, float(argv[2]) if len(argv) > 2 else 0.3)
    else:
        settle_study(rate, float(argv[2]) if len(argv) > 2 else 2.0)
    return 0


if __name__ == "__main__":
    sys.exit(main())
