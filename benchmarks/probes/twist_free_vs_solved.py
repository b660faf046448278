"""Twist unknowns dropped vs solved (fidelity.py): 8 straight round strands, 300 quasistatic steps and 96
dynamic steps of a nodding head, strand and stage schedules; prints the largest position difference and
the wall times (compilation included).  A diagnostic: ``python3 benchmarks/probes/twist_free_vs_solved.py``."""
import sys
import time

import numpy as np


def build(n_strands=8, m=41, L=0.2, curl=0.0):
    from taichi_hair.builder import GroomBuilder
    from taichi_hair.config import RodMaterial

    b = GroomBuilder()
    for s in range(n_strands):
        d = np.array([np.cos(0.3 * s), 0.2, np.sin(0.3 * s)])
        d /= np.linalg.norm(d)
        t = np.linspace(0, L, m)
        p = np.array([0.05 * s, 0, 0]) + t[:, None] * d
        if curl:
            p[:, 1] += curl * np.sin(t / 0.02)
        b.add_strand(p, RodMaterial(damping_time=0.0), root="clamped", body=0)
    return b.finalize()


def nod(t):
    a = 0.5 * np.sin(2 * np.pi * 1.0 * t)
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]]) @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def run(mode, twist, steps, dt=1 / 96, its=10, sched='auto'):
    from taichi_hair.config import SolverADMMConfig
    from taichi_hair.solver_admm import SolverADMM

    model = build()
    st, ctl = model.state(), model.control()
    ctl.gravity = (0, -9.81, 0)
    sv = SolverADMM(model, SolverADMMConfig(iterations=its, mode=mode, twist=twist, schedule=sched))
    t0 = time.perf_counter()
    for k in range(steps):
        if mode == 'dynamic':
            ctl.set_body_transform(0, nod((k + 1) * dt), np.zeros(3))
        sv.step(st, ctl, dt)
    return st.positions().astype(np.float64), sv.model_choices, time.perf_counter() - t0


def main(argv=None) -> int:
    import taichi as ti

    import taichi_hair

    taichi_hair.init(arch=ti.cpu, default_fp=ti.f32, offline_cache=True, log_level=ti.WARN)
    for mode, steps in (("quasistatic", 300), ("dynamic", 96)):
        for sched in ("strand", "stage"):
            xa, ca, ta = run(mode, "auto", steps, sched=sched)
            xs, cs, ts = run(mode, "solve", steps, sched=sched)
            print(mode, sched, ca["twist"][:40], "max diff [m]", np.abs(xa - xs).max(), f"times {ta:.2f} {ts:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
