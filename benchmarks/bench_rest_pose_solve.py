"""Sag-free rest pose solve time at the paper's groom size (issue 14, item 4), with and without the body's support.

    python3 benchmarks/bench_rest_pose_solve.py [--strands 8600] [--vertices 32] [--style wavy]
        [--supports none,unheld,all] [--arch cpu] [--out benchmarks/results/rest_pose_solve.json]

The groom: ``assets/scenes/head_turn.toml``'s generator (``--style``, ``--strands`` guides of ``--vertices``
vertices on ``assets/head.obj``), the head mesh as its collider, body still.  For each support rule
(``[groom] rest_pose_support``: ``none`` = no contact forces in the statics; ``unheld`` = the head carries the
strands that cannot hold themselves, the shipped opt-in; ``all`` = the head may carry every strand that touches
it) the scene's own :meth:`~taichi_hair.scene.file.Scene.solve_rest_pose` is timed once (NumPy, float64; its
support search :func:`~taichi_hair.solvers.rest_support.support_from_colliders` included), after the Model is
built (building it is timed apart).  Printed and written: the seconds, the strands held, the supported
vertices, the strands whose support uses all the friction, and the largest residual of the statics.

Hair-hair support is not in the statics (the contacts between strands carry nothing at x*); what "with
contacts" means here is the head's support, the only contact support the solve models.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

from harness import ROOT, Bench

HEAD = os.path.join(ROOT, "assets", "scenes", "head_turn.toml")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--strands", type=int, default=8600)
    ap.add_argument("--vertices", type=int, default=32)
    ap.add_argument("--style", choices=("straight", "wavy", "curly"), default="wavy")
    ap.add_argument("--supports", default="none,unheld,all")
    ap.add_argument("--arch", default="cpu", choices=("cpu", "cuda", "vulkan"), help="Taichi arch (the rest-pose solve "
                    "itself runs on the host; the arch is that of the Model's fields)")
    ap.add_argument("--out", default=os.path.join(ROOT, "benchmarks", "results", "rest_pose_solve.json"))
    args = ap.parse_args(argv)
    supports = [s.strip() for s in args.supports.split(",") if s.strip()]
    for s in supports:
        if s not in ("none", "unheld", "all"):
            ap.error(f"--supports: {s!r} is not one of none, unheld, all")
    bench = Bench("rest_pose_solve", argv)

    import numpy as np
    import taichi as ti

    import taichi_hair

    taichi_hair.init(arch=getattr(ti, args.arch), log_level=ti.WARN)
    from taichi_hair.scene.file import load_scene

    rows = []
    for support in supports:
        sets = {"groom.generator": args.style, "groom.rest_pose_support": support}
        scene = load_scene(HEAD, overrides=dict(strands=args.strands, vertices_per_strand=args.vertices),
                           sets=sets)
        scene.rest_pose = "authored"   # build the Model first, then time the solve alone
        t0 = time.perf_counter()
        model = scene.build_model()
        t_model = time.perf_counter() - t0
        t0 = time.perf_counter()
        res = scene.solve_rest_pose(model)
        t_solve = time.perf_counter() - t0
        f = res.vertex_support_force
        supported = int(np.count_nonzero(np.linalg.norm(f, axis=1) > 0)) if f is not None else 0
        row = dict(support=support, strands=model.strand_count, vertices=model.vertex_count,
                   model_seconds=t_model, solve_seconds=t_solve, strands_held=res.held_count,
                   vertices_carried=supported, friction_limited=len(res.friction_limited),
                   largest_residual=float(np.nanmax(res.strand_residual)),
                   largest_rest_turn=float(res.strand_rest_turn.max()))
        rows.append(row)
        print(f"support {support:>6}: {row['strands']} strands x {args.vertices} vertices, Model {t_model:.2f} s, "
              f"solve {t_solve:.2f} s, held {row['strands_held']}, vertices carried by the head {supported}, "
              f"friction-limited strands {row['friction_limited']}, largest residual "
              f"{row['largest_residual']:.1e} of the weight", flush=True)
    path = bench.write(args.out, dict(style=args.style, vertices_per_strand=args.vertices, rows=rows))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
