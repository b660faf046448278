"""Headless stepping from Python: the ``hang`` scene without the command line.

    python apps/headless_hang.py [--frames 24] [--arch cpu]

Builds strands on a sphere, nods the sphere, steps the ADMM solver, and ends
with a check of the final state (every example does: finite values, strands
hanging below their roots, edge lengths within 1 % of rest).
"""

import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def main(argv=None):
    p = argparse.ArgumentParser()
    p.add_argument("--frames", type=int, default=24)
    p.add_argument("--strands", type=int, default=100)
    p.add_argument("--arch", default="cpu", choices=["cpu", "cuda", "vulkan"])
    args = p.parse_args(argv)

    import taichi as ti

    import taichi_hair as th

    th.init(arch=getattr(ti, args.arch), log_level=ti.WARN)
    from taichi_hair.scene.builtin import HangScene, build_hang, nod_rotation

    scene = HangScene(strands=args.strands)
    model = build_hang(scene)
    state, control = model.state(), model.control()
    solver = th.SolverADMM(model, th.SolverADMMConfig(iterations=10))
    fps, substeps = 24, 4
    dt = 1.0 / (fps * substeps)
    for frame in range(args.frames):
        for k in range(substeps):
            t = (frame * substeps + k + 1) * dt
            control.set_body_transform(0, nod_rotation(scene, t), (0.0, 0.0, 0.0))
            solver.step(state, control, dt)
    x = state.positions().astype(np.float64)
    starts = model.host["strand_vertex_start"]
    tips = starts + model.host["strand_vertex_count"] - 1
    rest = model.host["edge_rest_length"]
    e = np.linalg.norm(np.diff(x, axis=0, append=x[-1:]), axis=1)
    stretch = np.max(np.abs(e[rest > 0] / rest[rest > 0] - 1))
    ok = np.all(np.isfinite(x)) and np.all(x[tips, 1] < x[starts, 1]) and stretch < 0.01
    print(f"{model.strand_count} strands, {args.frames} frames: max stretch {100 * stretch:.3f}%, "
          f"mean tip height {np.mean(x[tips, 1]):.4f} m -> {'OK' if ok else 'FAILED'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
