"""A small dynamic scene shared by the cross-arch tests (CPU vs Vulkan)."""

import numpy as np


def build_scene():
    import taichi_hair as th

    b = th.GroomBuilder()
    for i in range(20):
        n = 41 + i
        b.add_strand(np.c_[np.linspace(0, 0.1, n), np.zeros(n), np.full(n, 0.001 * i)])
    return b.finalize()


def run_scene(model, tridiagonal="auto", steps=48):
    import taichi_hair as th

    st, ctl = model.state(), model.control()
    # The plain iteration: the arches' round-off must stay round-off (Anderson's branches would amplify it
    # up to the iteration's convergence error; anderson.py).
    solver = th.SolverADMM(model, th.SolverADMMConfig(iterations=10, tridiagonal=tridiagonal, anderson_window=0))
    for k in range(steps):
        c, s = np.cos(0.01 * k), np.sin(0.01 * k)
        ctl.set_body_transform(0, [[c, -s, 0], [s, c, 0], [0, 0, 1]], (0.0, 0.0, 0.0))
        solver.step(st, ctl, 1 / 96)
    return st.positions().astype(np.float64), solver.tridiagonal_method
