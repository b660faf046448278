"""Dense clamped guides with contacts, quasistatic: N generated wavy strands on assets/head.obj (the grooming
benchmark's guides), 6 steps of 10 ADMM iterations; prints contacts and the largest stretch per step.
The optional second argument is a JSON object of ContactConfig overrides, e.g. '{"correction_iterations": 0}'.

Run from the repository root: ``python3 benchmarks/probes/dense_guides.py 8600 [JSON]``.  A diagnostic, not a benchmark:
it prints per-step figures.
"""

import json
import sys
import time

import numpy as np


def build_model(n: int):
    """N wavy strands of 14 vertices generated on the head mesh, clamped to body 0."""
    from taichi_hair import GroomBuilder, RodMaterial
    from taichi_hair.groom.generators import GeneratorConfig, generate_groom, load_head

    t = time.time()
    g = generate_groom(load_head(), GeneratorConfig(style="wavy", strands=n, vertices_per_strand=14, length=0.25,
                                                    seed=0))
    print("generated", time.time() - t, flush=True)
    b = GroomBuilder()
    off = g.strand_offsets
    for s in range(len(off) - 1):
        b.add_strand(g.points[off[s]:off[s + 1]], RodMaterial(), root="clamped", body=0)
    return b.finalize()


def run(n: int, overrides: dict, steps: int = 6) -> None:
    from taichi_hair import SolverADMM, SolverADMMConfig
    from taichi_hair.config import ContactConfig

    model = build_model(n)
    cfg = SolverADMMConfig(iterations=10, mode="quasistatic", w0=1.0,
                           contacts=ContactConfig(friction=0.2, velocity_margin=0.0, **overrides))
    solver = SolverADMM(model, cfg)
    st, ct = model.state(), model.control()
    for k in range(steps):
        t = time.time()
        try:
            solver.step(st, ct, 1.0)
        except Exception as e:
            print("step", k, "FAILED:", e, flush=True)
            break
        x = st.positions().astype(float)
        rl = model.host["edge_rest_length"]
        real = rl > 0
        e = np.linalg.norm(np.diff(x, axis=0, append=x[-1:]), axis=1)
        print("step", k, round(time.time() - t, 1), "s", solver.contact_stats, "max stretch",
              np.abs(e[real] / rl[real] - 1).max(), flush=True)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    import taichi as ti

    import taichi_hair

    taichi_hair.init(arch=ti.cpu, log_level=ti.WARN)
    run(int(argv[0]), json.loads(argv[1]) if len(argv) > 1 else {})
    return 0


if __name__ == "__main__":
    sys.exit(main())
