"""Quasistatic convergence of ADMM against w0 on 20 curly strands of the hang scene: the largest displacement
per step at a few step counts, and how far the state still moves between steps 300/1000 and 3000.
A diagnostic behind the choice of w0 = 1 for ``simulate --equilibrium``:
``python3 benchmarks/probes/quasistatic_w0.py``."""
import sys

import numpy as np

#: The steps whose largest displacement is printed.
REPORTED = (10, 30, 100, 300, 1000, 2000, 2999)


def run(w0: float, steps: int = 3000) -> None:
    from taichi_hair.config import SolverADMMConfig
    from taichi_hair.scene.builtin import HangScene, build_hang
    from taichi_hair.solver_admm import SolverADMM

    model = build_hang(HangScene(strands=20, length=0.2, seed=0))
    st, ctl = model.state(), model.control()
    ctl.gravity = (0, -9.81, 0)
    sv = SolverADMM(model, SolverADMMConfig(iterations=10, mode="quasistatic", w0=w0))
    prev = st.positions().astype(float)
    out = []
    hist = []
    for k in range(steps):
        sv.step(st, ctl, 1.0)
        x = st.positions().astype(float)
        d = np.abs(x - prev).max()
        prev = x
        hist.append(x)
        if k in REPORTED:
            out.append((k, d))
    print(w0, " ".join(f"{k}:{d:.1e}" for k, d in out),
          "dist(step1000->3000)", np.linalg.norm(hist[1000] - hist[-1], axis=1).max(),
          "dist(300->3000)", np.linalg.norm(hist[300] - hist[-1], axis=1).max())


def main(argv=None) -> int:
    import taichi as ti

    import taichi_hair

    taichi_hair.init(arch=ti.cpu, default_fp=ti.f32, offline_cache=True, log_level=ti.WARN)
    for w0 in (25.0, 5.0, 1.0):
        run(w0)
    return 0


if __name__ == "__main__":
    sys.exit(main())
