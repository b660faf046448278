"""What the simplifications of issue 4 item 6 save (``taichi_hair/fidelity.py``), measured.

1. Twist unknowns dropped: ms per step of SolverADMM on naturally straight round strands (dynamic,
   10 iterations, a nodding head) with ``twist="auto"`` (dropped) and ``twist="solve"`` (the paper's),
   and the largest position difference after the run.
2. Hair-hair search skipped: ms per step with contacts on, hanging strands 5 cm apart on a head
   swaying side to side (nothing within reach), ``skip_when_apart`` on and off.
3. Equilibrium only: wall time of ``equilibrium.equilibrium`` (quasistatic, w0 = 1) against a damped
   dynamic run to rest (3 s simulated) for the same cantilevers, and their distance.

Usage:
    python benchmarks/bench_fidelity.py [--arch cpu|cuda] [--strands 1000] [--out FILE]

Kernel compilation is excluded (a warm-up step first).  Figures are printed and written as JSON
(default benchmarks/results/fidelity_<arch>.json).
"""

import argparse
import time

import numpy as np

from harness import Bench, results_path, stopwatch  # benchmarks/harness.py (the script's folder is on sys.path)


def straight_groom(th, strands, vertices, gap, direction=(1.0, 0.2, 0.5), length=0.2):
    b = th.GroomBuilder()
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    side = int(np.ceil(np.sqrt(strands)))
    t = np.linspace(0.0, length, vertices)
    for k in range(strands):
        root = np.array([gap * (k % side), 0.0, gap * (k // side)])
        b.add_strand(root + t[:, None] * d)
    return b.finalize()


def nod(t):
    a = 0.5 * np.sin(2 * np.pi * t)
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]]) @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def sway(t):
    """Head translation: 5 cm side to side at 1 Hz (no rotation: strands move together)."""
    return np.array([0.05 * np.sin(2 * np.pi * t), 0.0, 0.0])


def timed_run(th, ti, model, cfg, steps, dt=1 / 96, moving="nod"):
    st, ctl = model.state(), model.control()
    ctl.gravity = (0.0, -9.81, 0.0)
    solver = th.SolverADMM(model, cfg)
    snap = st.to_numpy()
    solver.step(st, ctl, dt)  # compile
    st.load(snap)
    solver.reset_duals()
    with stopwatch(ti.sync) as sw:
        for k in range(steps):
            if moving == "nod":
                ctl.set_body_transform(0, nod((k + 1) * dt), np.zeros(3))
            elif moving == "sway":
                ctl.set_body_transform(0, np.eye(3), sway((k + 1) * dt))
            solver.step(st, ctl, dt)
    return 1e3 * sw.seconds / steps, st.positions().astype(np.float64), solver


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--arch", default="cpu", choices=("cpu", "cuda"))
    ap.add_argument("--strands", type=int, default=1000)
    ap.add_argument("--steps", type=int, default=48)
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    bench = Bench("fidelity", argv)
    import taichi as ti

    import taichi_hair as th

    th.init(arch=getattr(ti, a.arch), default_fp=ti.f32, offline_cache=True, log_level=ti.WARN)

    res = {"arch": a.arch, "date": time.strftime("%Y-%m-%d"), "strands": a.strands}

    # 1. Twist.
    model = straight_groom(th, a.strands, 32, gap=0.005)
    tw = {}
    for twist in ("auto", "solve"):
        ms, x, solver = timed_run(th, ti, model, th.SolverADMMConfig(iterations=10, twist=twist), a.steps)
        tw[twist] = (ms, x, solver.twist_free)
    res["twist"] = {"vertices": model.vertex_count, "steps": a.steps, "ms_per_step_dropped": tw["auto"][0],
                    "ms_per_step_solved": tw["solve"][0], "dropped": bool(tw["auto"][2]),
                    "max_position_difference_m": float(np.max(np.linalg.norm(tw["auto"][1] - tw["solve"][1], axis=1)))}
    print(f"twist: {model.vertex_count} vertices, {tw['auto'][0]:.2f} ms/step dropped vs {tw['solve'][0]:.2f} solved "
          f"({tw['solve'][0] / tw['auto'][0]:.2f}x); positions differ by "
          f"{res['twist']['max_position_difference_m'] * 1e6:.1f} um after {a.steps} steps")

    # 2. Hair-hair search.
    model = straight_groom(th, a.strands, 32, gap=0.05, direction=(0.0, -1.0, 0.0))
    sk = {}
    for skip in (True, False):
        cfg = th.SolverADMMConfig(iterations=10, contacts=th.ContactConfig(skip_when_apart=skip))
        ms, x, solver = timed_run(th, ti, model, cfg, a.steps // 2, moving="sway")
        sk[skip] = (ms, x, solver.contacts.hair_search_skip_count)
    res["hair_search"] = {"vertices": model.vertex_count, "ms_per_step_skipped": sk[True][0],
                          "ms_per_step_searched": sk[False][0], "steps_skipped": sk[True][2],
                          "steps": a.steps // 2, "identical": bool(np.array_equal(sk[True][1], sk[False][1]))}
    print(f"hair-hair search: strands 5 cm apart, {sk[True][0]:.2f} ms/step skipped ({sk[True][2]} of "
          f"{a.steps // 2} steps) vs {sk[False][0]:.2f} searched; identical: {res['hair_search']['identical']}")

    # 3. Equilibrium.
    from taichi_hair.solvers.equilibrium import equilibrium

    n = max(4, a.strands // 10)
    model = straight_groom(th, n, 21, gap=0.01, direction=(1.0, 0.0, 0.0), length=0.1)
    st, ctl = model.state(), model.control()
    ctl.gravity = (0.0, -9.81, 0.0)
    solver = th.SolverADMM(model, th.SolverADMMConfig(iterations=10, mode="quasistatic", w0=1.0))
    snap = st.to_numpy()
    solver.step(st, ctl, 1.0)
    st.load(snap)
    solver.reset_duals()
    with stopwatch(ti.sync) as sw:
        r = equilibrium(solver, st, ctl, 1e-6, 5000)
    t_eq = sw.seconds
    x_eq = st.positions().astype(np.float64)
    rho_a = 1300 * np.pi * (5e-5) ** 2
    ms, x_dyn, _ = timed_run(th, ti, model, th.SolverADMMConfig(iterations=10, w0=1.0, air_viscosity=20 * rho_a),
                             288, moving=None)
    res["equilibrium"] = {"strands": n, "vertices": model.vertex_count, "seconds_quasistatic": t_eq,
                          "steps_quasistatic": r.steps, "converged": r.converged,
                          "seconds_dynamic_3s": ms * 288 / 1e3,
                          "max_distance_m": float(np.max(np.linalg.norm(x_eq - x_dyn, axis=1)))}
    print(f"equilibrium: {n} cantilevers, quasistatic {t_eq:.2f} s ({r.steps} steps) vs dynamic to rest "
          f"{ms * 288 / 1e3:.2f} s (3 s simulated); rest shapes {res['equilibrium']['max_distance_m'] * 1e6:.1f} um apart")

    out = bench.write(a.out or results_path(f"fidelity_{a.arch}.json"), res)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
