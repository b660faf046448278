"""The Pareto cantilever under ADMM variants: where Anderson acceleration helps and where it swings up
(issue 12 item 5; taichi_hair/anderson.py, ANDERSON_MIN_ITERATIONS).

Run from the repository root:
    python3 benchmarks/probes/anderson_cantilever.py [--rod K] SPEC [SPEC ...]
    e.g. python3 benchmarks/probes/anderson_cantilever.py '{"iterations": 5, "anderson_window": 0}' \
         '{"iterations": 5, "anderson_window": 5, "min_iterations": 1}'

The scene is the Pareto study's cantilever (``taichi_hair.bench.pareto_runs.build_scene("cantilever")``:
6 rods 1-30 cm, >= 16 edges, clamped horizontally, drag 8 /s), dt = 1/96 s, 1.5 s.  Each SPEC is a JSON
object of ``SolverADMMConfig`` fields, plus ``min_iterations`` to override
``anderson.ANDERSON_MIN_ITERATIONS`` for that run (e.g. 1: mix at any iteration count).  Printed per rod:
the largest tip distance to the same scene run with 300 plain iterations per step, / L, over samples
every 0.25 s; the tip speed at the end [m/s]; with ``--rod K`` also rod K's tip height every 6 steps [mm].
A diagnostic, not a benchmark.
"""

import json
import math
import sys


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    rod = None
    if argv[:1] == ["--rod"]:
        rod, argv = int(argv[1]), argv[2:]
    if not argv:
        print(__doc__)
        return 2
    import numpy as np
    import taichi as ti

    import taichi_hair

    taichi_hair.init(arch=ti.cpu, log_level=ti.WARN)
    import taichi_hair.solver_admm as solver_module
    from taichi_hair.bench import pareto_runs as P
    from taichi_hair.config import SolverADMMConfig
    from taichi_hair.solvers import make_solver
    from taichi_hair.validation.elasticity_params import GRAVITY, HAIR

    model, scene = P.build_scene("cantilever")
    tips = [s0 + c - 1 for s0, c in model.strand_slices()]
    xi = scene.drag_rate * HAIR["density"] * math.pi * HAIR["radius"] ** 2
    dt, steps = 1 / 96, 144
    default_min = solver_module.ANDERSON_MIN_ITERATIONS

    def run(fields):
        fields = dict(fields)
        solver_module.ANDERSON_MIN_ITERATIONS = int(fields.pop("min_iterations", default_min))
        st, ctl = model.state(), model.control()
        ctl.gravity = (0.0, -GRAVITY, 0.0)
        solver = make_solver("admm", model, SolverADMMConfig(**fields, air_viscosity=xi, check_finite=False))
        samples, heights = [], []
        for k in range(steps):
            solver.step(st, ctl, dt)
            x = st.vertex_position.to_numpy()
            heights.append(x[tips, 1])
            if (k + 1) % 24 == 0:
                samples.append(x[tips].astype(np.float64))
        speed = np.linalg.norm(st.vertex_velocity.to_numpy()[tips], axis=1)
        solver_module.ANDERSON_MIN_ITERATIONS = default_min
        return np.array(samples), speed, np.array(heights)

    ref, _, _ = run({"iterations": 300, "anderson_window": 0})
    for spec in argv:
        traj, speed, heights = run(json.loads(spec))
        err = (np.linalg.norm(traj - ref, axis=2) / scene.strand_lengths[None, :]).max(axis=0)
        print(spec)
        print("  rods [cm]:               ", " ".join(f"{100 * L:8.2f}" for L in scene.strand_lengths))
        print("  max tip error / L:       ", " ".join(f"{e:8.2e}" for e in err))
        print("  tip speed at 1.5 s [m/s]:", " ".join(f"{v:8.2e}" for v in speed))
        if rod is not None:
            print(f"  rod {rod} tip height every 6 steps [mm]:", " ".join(f"{1e3 * y:.2f}" for y in heights[::6, rod]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
