"""Benchmark of SolverXPBD (the local XPBD Cosserat baseline): milliseconds per step and throughput.

Groom: the ``hang`` scene (strands planted on a nodding head sphere, a small
curl) with exactly 1000 strands x 32 vertices by default, no colliders (the
XPBD baseline has none).  For each (substeps, iterations) setting it reports
the mean wall time of a 1/60 s step after a warm-up (compilation reported
apart), the throughput in million vertex-iterations per second
(vertices x substeps x iterations / time), and, as a quality proxy, the mean
and largest relative edge stretch at the end.

Each setting runs with both schedules (``--schedules stage,strand``): one
launch per substep parallel over vertices, or one launch per step parallel
over strands (the CPU default).

Usage:
    python benchmarks/bench_xpbd.py [--arch cpu|cuda] [--strands 1000] [--vertices 32]
                                    [--settings 20x1,50x1,10x5] [--schedules stage,strand] [--steps N] [--out FILE]

Figures are printed and written as JSON (default benchmarks/results/xpbd_<arch>.json).
"""

import argparse
import datetime

import numpy as np

from harness import Bench, results_path, timed  # benchmarks/harness.py (the script's folder is on sys.path)

DT = 1.0 / 60.0


def groom(strands, vertices):
    from taichi_hair.scene.builtin import HangScene, build_hang

    length = 0.2
    scene = HangScene(strands=strands, length=length, edge_length=length / (vertices - 1))
    return scene, build_hang(scene)


def bench(ti, strands, vertices, settings, steps, schedules):
    from taichi_hair.scene.builtin import nod_rotation
    from taichi_hair.solvers.xpbd.solver import SolverXPBD, SolverXPBDConfig

    scene, model = groom(strands, vertices)
    state, control = model.state(), model.control()
    snapshot = state.to_numpy()
    rows = []
    print(f"{'strands':>7} x {'m':<3} {'vertices':>9} {'schedule':>8} {'substeps':>8} {'iters':>5} {'ms/step':>10} "
          f"{'compile_s':>10} {'Mvert-it/s':>10} {'str_mean%':>9} {'str_max%':>8}")
    for schedule, (substeps, iterations) in [(sc, st) for sc in schedules for st in settings]:
        state.load(snapshot)
        solver = SolverXPBD(model, SolverXPBDConfig(substeps=substeps, iterations=iterations, damping=1.0,
                                                    schedule=schedule))
        t = 0.0

        def step():
            nonlocal t
            t += DT
            control.set_body_transform(0, nod_rotation(scene, t), (0.0, 0.0, 0.0))
            solver.step(state, control, DT)

        timing = timed(step, steps, warmup=2, sync=ti.sync)  # first step (compilation), 2 warm-up, timed steps
        compile_s, seconds = timing["compile_s"], timing["run_mean_s"]
        x = state.positions().astype(np.float64)
        assert np.all(np.isfinite(x))
        stretch = np.abs(solver.edge_stretch(state)[model.host["edge_rest_length"] > 0])
        throughput = model.vertex_count * substeps * iterations / seconds / 1e6
        rows.append({"strands": model.strand_count, "vertices_per_strand": vertices, "vertices": model.vertex_count,
                     "schedule": solver.schedule, "substeps": substeps, "iterations": iterations,
                     "steps_timed": steps, "dt": DT,
                     "ms_per_step": 1e3 * seconds, "compile_and_first_step_s": compile_s,
                     "mega_vertex_iterations_per_s": throughput, "steps_run": 3 + steps,
                     "edge_stretch_mean": float(stretch.mean()), "edge_stretch_max": float(stretch.max())})
        print(f"{strands:>7} x {vertices:<3} {model.vertex_count:>9} {solver.schedule:>8} {substeps:>8} "
              f"{iterations:>5} "
              f"{1e3 * seconds:10.2f} {compile_s:10.2f} {throughput:10.2f} {100 * stretch.mean():9.3f} "
              f"{100 * stretch.max():8.2f}", flush=True)
    return rows


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--arch", default="cpu", choices=("cpu", "cuda"))
    p.add_argument("--strands", type=int, default=1000)
    p.add_argument("--vertices", type=int, default=32)
    p.add_argument("--settings", default="20x1,50x1,10x5", help="comma list of SUBSTEPSxITERATIONS")
    p.add_argument("--steps", type=int, default=10)
    p.add_argument("--schedules", default="stage,strand", help="comma list of SolverXPBDConfig.schedule values")
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)
    settings = [tuple(int(v) for v in s.split("x")) for s in args.settings.split(",")]
    record = Bench("bench_xpbd", argv)

    import taichi as ti

    import taichi_hair

    taichi_hair.init(arch=ti.cpu if args.arch == "cpu" else ti.cuda, default_fp=ti.f32, offline_cache=True,
                     log_level=ti.WARN)
    rows = bench(ti, args.strands, args.vertices, settings, args.steps, args.schedules.split(","))
    result = {"arch": args.arch, "precision": "f32",
              "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
              "note": "shared machine; figures are noisy", "rows": rows}
    out = record.write(args.out or results_path(f"xpbd_{args.arch}.json"), result)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
