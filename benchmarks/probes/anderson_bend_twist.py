"""The bend-twist validation's rods under the plain and the Anderson-accelerated iteration (issue 12 item 5:
why Anderson acceleration is not the default).

Run from the repository root:
    python3 benchmarks/probes/anderson_bend_twist.py WINDOW ITERATIONS STEPS
    e.g. python3 benchmarks/probes/anderson_bend_twist.py 0 50 300; ... 5 50 300; ... 0 200 300

``taichi_hair.validation.bend_twist.run_bend_twist`` on the validation's 8 x 8 grid (64 naturally curved rods,
twist solved, dt and damping as ``taichi-hair validate bend-twist``), STEPS steps (the first 100 tilted) with
ITERATIONS ADMM iterations per step and ``SolverADMMConfig.anderson_window = WINDOW`` forced; printed: the
largest vertex speed every 100 steps [m/s].  Converged runs agree whatever the iteration count; a run that
differs from them computed another motion.  A diagnostic, not a benchmark.
"""

import sys


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if len(argv) != 3:
        print(__doc__)
        return 2
    window, iterations, steps = (int(a) for a in argv)
    import numpy as np
    import taichi as ti

    import taichi_hair

    taichi_hair.init(arch=ti.cpu, log_level=ti.WARN)
    import taichi_hair.config as config
    from taichi_hair.validation import bend_twist as bt

    plain_config = config.SolverADMMConfig
    config.SolverADMMConfig = lambda **kw: plain_config(**{**kw, "anderson_window": window})
    try:
        k, phi = bt.default_grid(8)
        K, P = np.meshgrid(k, phi)
        K, P = K.ravel(), P.ravel()
        speeds = []
        bt.run_bend_twist(K, P / K, bt.BendTwistConfig(steps=steps, tilt_steps=min(100, steps), iterations=iterations),
                          progress=lambda step, total, speed: speeds.append(speed))
    finally:
        config.SolverADMMConfig = plain_config
    print(f"window {window}, {iterations} iterations per step, {steps} steps: largest speed every 100 steps [m/s]:",
          " ".join(f"{v:.3f}" for v in speeds))
    return 0


if __name__ == "__main__":
    sys.exit(main())
