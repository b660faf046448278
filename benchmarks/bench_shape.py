"""Benchmark of SolverShape (Han & Harada 2012): milliseconds per step.

Grooms at the sizes of the paper's Table 1: model 1 (~20k strands x 11 vertices,
221k vertices) and model 3 (20k strands x 64 vertices, ~1.3M vertices), made with
the ``hang`` scene (strands on the lower cap of a head sphere, a small curl; a
wavier curl for model 3), with the paper's 3 sphere colliders (head and two
shoulders) and the head nodding every step.  Iteration counts are Table 2's:
model 1 2 edge-length and 3 local-shape iterations, model 3 3 and 4.

For each size and each transform method (1 serial, 2 Jacobi, 3 rest transforms)
it reports the mean wall time of a step (after a warm-up; kernel compilation is
reported apart) and a per-stage split from a second, profiled pass (profiling
synchronises after each stage, so its total is a little higher).  As a quality
proxy it also reports the RMS and largest distance of each method's vertices to
Method 1's (the paper's reference) after the same nodding steps, and the
distribution of the edge strain |l / l0 - 1| at the end (p50, p99, max, and the mean).

``--scheme defaults`` (the default) runs SolverShapeConfig's shipped defaults (substeps, the
follow-the-leader pass and its velocity correction); ``--scheme paper`` the paper's scheme alone
(one pass of Algorithm 1 per step, no follow-the-leader, no shock propagation), the solver as it
was before those.

Usage:
    python benchmarks/bench_shape.py [--arch cpu|cuda] [--sizes 20000x11,20000x64] [--methods 1,2,3]
                                     [--scheme defaults|paper] [--steps N] [--out FILE]

Figures are printed and written as JSON (default benchmarks/results/shape_<arch>.json).
"""

import argparse
import datetime
import os

import numpy as np

from harness import Bench, results_path, timed  # benchmarks/harness.py (the script's folder is on sys.path)

#: Table 2 of the paper: (edge length iterations, local shape iterations) per model size.
TABLE2_ITERATIONS = {11: (2, 3), 64: (3, 4)}
DT = 1.0 / 60.0


def groom(th, strands, vertices):
    """The hang scene with exactly ``vertices`` per strand (lengths vary by up to 15 %)."""
    from taichi_hair.scene.builtin import HangScene, build_hang

    wavy = vertices > 32
    length = 0.25 if not wavy else 0.32
    scene = HangScene(strands=strands, length=length, edge_length=length / (vertices - 1),
                      curl_radius=0.004 if wavy else 0.002, curl_pitch=0.03 if wavy else 0.06)
    return scene, build_hang(scene)


#: SolverShapeConfig fields of each --scheme (the others are the config's defaults).
SCHEMES = {"defaults": {},
           "paper": {"substeps": 1, "follow_the_leader": False, "shock_acceleration_threshold": float("inf")}}


def bench_size(th, ti, strands, vertices, methods, steps, scheme="defaults"):
    from taichi_hair.scene.builtin import nod_rotation
    from taichi_hair.contact.colliders import SphereCollider
    from taichi_hair.solvers.shape.solver import ShapeRegion, SolverShape, SolverShapeConfig

    scene, model = groom(th, strands, vertices)
    length_its, local_its = TABLE2_ITERATIONS.get(vertices, (3, 4))
    region = ShapeRegion(global_stiffness=0.2, global_range=0.3, local_stiffness=0.8, local_iterations=local_its,
                         length_iterations=length_its, damping=0.05)
    # Frictionless, as the paper's Sec. 3.5 projection.
    colliders = [SphereCollider((0.0, 0.0, 0.0), scene.sphere_radius, friction=0.0, body=0),
                 SphereCollider((0.15, -0.3, 0.0), 0.08, friction=0.0),
                 SphereCollider((-0.15, -0.3, 0.0), 0.08, friction=0.0)]
    rows = []
    finals = {}
    state, control = model.state(), model.control()
    snapshot = state.to_numpy()
    for method in methods:
        state.load(snapshot)
        cfg = SolverShapeConfig(method=method, regions=(region,), **SCHEMES[scheme])
        solver = SolverShape(model, cfg, colliders=colliders)
        t = 0.0

        def step():
            nonlocal t
            t += DT
            control.set_body_transform(0, nod_rotation(scene, t), (0.0, 0.0, 0.0))
            solver.step(state, control, DT)

        timing = timed(step, steps, warmup=2, sync=ti.sync)  # first step (compilation), 2 warm-up, timed steps
        compile_s = timing["compile_s"]
        ms = 1e3 * timing["run_mean_s"]
        solver.profile = True
        for _ in range(steps):
            step()
        stage_ms = {k: 1e3 * v / steps for k, v in solver.stage_seconds.items()}
        x = state.positions().astype(np.float64)
        assert np.all(np.isfinite(x))
        finals[method] = x
        real = model.host["edge_rest_length"] > 0
        idx = np.where(real)[0]
        stretch = np.linalg.norm(x[idx + 1] - x[idx], axis=1) / model.host["edge_rest_length"][idx] - 1.0
        strain = np.abs(stretch)
        p50, p99 = (float(v) for v in np.percentile(strain, [50, 99]))
        # Quality proxy: distance to Method 1's result after the same 3 + 2 * steps nodding steps.
        diff = np.linalg.norm(x - finals[1], axis=1) if 1 in finals else None
        rows.append({"strands": model.strand_count, "vertices_per_strand": vertices, "vertices": model.vertex_count,
                     "method": method, "scheme": scheme, "substeps": cfg.substeps,
                     "follow_the_leader": cfg.follow_the_leader,
                     "length_velocity_correction": cfg.length_velocity_correction,
                     "length_iterations": length_its, "local_iterations": local_its,
                     "colliders": len(colliders), "steps_timed": steps, "ms_per_step": ms,
                     "compile_and_first_step_s": compile_s, "stage_ms_per_step": stage_ms,
                     "steps_run": 3 + 2 * steps,
                     "edge_stretch_max": float(np.abs(stretch).max()),
                     "edge_stretch_mean": float(np.abs(stretch).mean()),
                     "edge_strain_p50": p50, "edge_strain_p99": p99,
                     "rms_distance_to_method1_mm": None if diff is None else 1e3 * float(np.sqrt(np.mean(diff**2))),
                     "max_distance_to_method1_mm": None if diff is None else 1e3 * float(diff.max())})
        stages = " ".join(f"{k}={v:.2f}" for k, v in stage_ms.items())
        dist = "" if diff is None else f"{1e3 * np.sqrt(np.mean(diff**2)):8.2f} {1e3 * diff.max():8.2f}"
        print(f"{strands:>7} x {vertices:<3} {model.vertex_count:>9} {method:>6} {ms:10.2f} {compile_s:10.2f} "
              f"{dist:>17} {100 * p50:8.4f} {100 * p99:8.4f} {100 * strain.max():8.4f} {100 * strain.mean():8.4f}  "
              f"{stages}",
              flush=True)
    return rows


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--arch", default="cpu", choices=("cpu", "cuda"))
    p.add_argument("--sizes", default="20000x11,20000x64")
    p.add_argument("--methods", default="1,2,3")
    p.add_argument("--scheme", default="defaults", choices=tuple(SCHEMES))
    p.add_argument("--steps", type=int, default=None, help="timed steps per case (default 10 on cpu, 100 on cuda)")
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)
    bench = Bench("shape", argv)
    import taichi as ti

    import taichi_hair

    taichi_hair.init(arch={"cpu": ti.cpu, "cuda": ti.cuda}[args.arch], default_fp=ti.f32, log_level=ti.WARN)
    import taichi_hair as th

    arch = str(ti.lang.impl.current_cfg().arch).split(".")[-1]
    steps = args.steps or (10 if args.arch == "cpu" else 100)
    methods = [int(m) for m in args.methods.split(",")]
    version = ".".join(map(str, ti.__version__))
    out = {"date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"), "arch": arch,
           "taichi": version, "dt_s": DT, "scheme": args.scheme, "results": []}  # the GPU's name: machine block
    print(f"SolverShape benchmark on {arch} ({os.cpu_count()} cores), taichi {version}, dt = 1/60 s, "
          f"{steps} timed steps, scheme {args.scheme} {SCHEMES[args.scheme] or '(SolverShapeConfig defaults)'}")
    print(f"{'strands x verts':>15} {'vertices':>9} {'method':>6} {'ms/step':>10} {'compile s':>10} "
          f"{'vs M1 rms/max mm':>17} {'p50 %':>8} {'p99 %':>8} {'max %':>8} {'mean %':>8}  stage ms/step")
    for size in args.sizes.split(","):
        ns, nv = (int(v) for v in size.split("x"))
        out["results"].extend(bench_size(th, ti, ns, nv, methods, steps, args.scheme))
    suffix = "" if args.scheme == "defaults" else f"_{args.scheme}"
    path = bench.write(args.out or results_path(f"shape_{arch}{suffix}.json"), out)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
