"""One step of the bend-twist validation's rods, plain against Anderson-accelerated, against a many-iteration
reference (issue 12 item 5: why Anderson acceleration is not the default).

Run from the repository root:
    python3 benchmarks/probes/anderson_one_step.py [PRESTEPS] [REFERENCE_ITERATIONS]     (default 60 3000)

Builds the validation's 8 x 8 grid (64 naturally curved rods, twist solved, dt and damping as
``taichi-hair validate bend-twist``), runs PRESTEPS plain steps of 50 iterations (the first 100 tilted), then
one more step from that same state with each method: the plain iteration with REFERENCE_ITERATIONS (the
reference), plain 50, and window 5 with 50 / 200 / 1,000 iterations.  Printed per method: the largest vertex
distance from the reference after the step [m], the largest twist difference [rad], and the six rods
farthest from it.  The runs are deterministic on the CPU, so every method starts from the same bits.
A diagnostic, not a benchmark.
"""

import math
import sys


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if len(argv) > 2 or any(not a.isdigit() for a in argv):
        print(__doc__)
        return 2
    presteps = int(argv[0]) if argv else 60
    ref_iterations = int(argv[1]) if len(argv) > 1 else 3000
    import numpy as np
    import taichi as ti

    import taichi_hair

    taichi_hair.init(arch=ti.cpu, log_level=ti.WARN)
    from taichi_hair.builder import GroomBuilder
    from taichi_hair.config import RodMaterial, SolverADMMConfig
    from taichi_hair.solver_admm import SolverADMM
    from taichi_hair.validation import bend_twist as bt

    cfg = bt.BendTwistConfig()
    k, phi = bt.default_grid(8)
    K, P = np.meshgrid(k, phi)
    K, P = K.ravel(), P.ravel()
    L = P / K
    hair = bt.HAIR
    mat = RodMaterial(radius=hair["radius"], density=hair["density"], youngs_modulus_bend=hair["youngs_modulus_bend"],
                      poisson_ratio=hair["poisson_ratio"], damping_time=cfg.damping_time)
    b = GroomBuilder()
    for kk, LL in zip(K, L):
        b.add_strand(bt.arc_points(kk, LL, bt.rod_edge_count(LL, cfg.max_edges)), mat, root_director=(0.0, 0.0, 1.0))
    model = b.finalize()
    xi = cfg.drag_rate * hair["density"] * math.pi * hair["radius"] ** 2
    g_tilt = (0.0, -bt.GRAVITY * math.cos(cfg.tilt), bt.GRAVITY * math.sin(cfg.tilt))

    def run(iterations, window):
        state, control = model.state(), model.control()
        # Allocated with a window, run plain (window 0) until the step under test.
        solver = SolverADMM(model, SolverADMMConfig(iterations=50, mode="dynamic", air_viscosity=xi, anderson_window=5))
        solver.anderson.window = 0
        for step in range(presteps):
            control.gravity = g_tilt if step < cfg.tilt_steps else (0.0, -bt.GRAVITY, 0.0)
            solver.step(state, control, cfg.dt)
        solver.config.iterations = iterations
        solver.anderson.window = window
        solver.step(state, control, cfg.dt)
        return state.vertex_position.to_numpy().astype(np.float64), state.edge_twist.to_numpy().astype(np.float64)

    starts, counts = model.host["strand_vertex_start"], model.host["strand_vertex_count"]
    x_ref, t_ref = run(ref_iterations, 0)
    print(f"{model.strand_count} rods, {presteps} plain steps, then one step; reference: plain, {ref_iterations} iterations")
    for iterations, window in ((50, 0), (50, 5), (200, 5), (1000, 5)):
        x, t = run(iterations, window)
        err = np.array([np.abs(x[s:s + c] - x_ref[s:s + c]).max() for s, c in zip(starts, counts)])
        worst = ", ".join(f"k={K[i]:.0f}/m L={L[i]:.2f} m {err[i]:.2e}" for i in np.argsort(err)[::-1][:6])
        print(f"window {window}, {iterations:4d} iterations: max |x - x_ref| {err.max():.3e} m, "
              f"max |theta - theta_ref| {np.abs(t - t_ref).max():.3e} rad; worst rods: {worst}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
