"""The contact sweeps in slab groups against index order, on the grooming benchmark's groom, in one process.

Run from the repository root:
    python3 benchmarks/probes/slab_sweeps.py [--strands 86000] [--steps 8] [--sweeps 20] [--out FILE.json]

The groom of ``benchmarks/bench_groom.py`` (wavy strands x 14 vertices on ``assets/head.obj``, 10 % sag-free guides,
hair-hair contacts, 10 iterations per step).  This 2-core VM's speed drifts by 20-50 % over minutes, so two runs of
the benchmark (one per commit) cannot resolve a 5-10 % change; this probe alternates the two orders inside one
process, on the same contacts:

1. *Sweeps*: after three steps, ``--sweeps`` z-step sweeps in index order (``projection.SEQUENTIAL``) then as many in
   slab groups (``projection.SLABS``, ``contact.slabs``) then as many in the slab groups' order on one thread
   (``projection.SLAB_ORDER``), each from the same z and r~, six times over (ms per sweep each time).  All run on the
   contacts sorted by slab group; the slab groups on threads and in their order on one thread are the same
   Gauss-Seidel order (checked: the same bits of z), index order is another (groups between slabs 1|2 before 2|3).
2. *Steps*: ``--steps`` pairs of whole steps, one with the slabs (``ContactPipeline.slabs_contiguous`` left as the
   Model gives it) and one without (set to False before the step: the detection's own order, one thread), in turn
   (ms per step and the correction's sweeps of each).  Their Gauss-Seidel orders differ, so their sweeps may too.

Prints the times, their medians and ratios; a diagnostic, not a benchmark.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--strands", type=int, default=86000)
    p.add_argument("--steps", type=int, default=8)
    p.add_argument("--sweeps", type=int, default=20)
    p.add_argument("--out", default=None)
    a = p.parse_args(argv)
    import taichi as ti

    import taichi_hair

    taichi_hair.init(arch=ti.x64, default_fp=ti.f32, log_level=ti.WARN)
    from groom_drag import benchmark_session  # (this folder: the grooming benchmark's groom and session)
    from taichi_hair.contact.projection import SEQUENTIAL, SLAB_ORDER, SLABS, projection_sweep

    _, session = benchmark_session(a.strands)
    session._ensure_built()
    sim = session._sim
    pipeline = sim.solver.contacts
    runs = bool(pipeline.slabs_contiguous)
    print(f"{sim.model.strand_count} guides; the Model's slabs are runs of vertex indices: {runs}")
    for _ in range(3):
        sim.step()
    sweeps = {"index order": [], "slabs": [], "slab order": []}
    same = True
    if pipeline._slabs:
        z0 = pipeline.con.vertex_z.to_numpy()
        r0 = pipeline.con.contact_accumulated.to_numpy()
        for _ in range(6):
            ends = {}
            for name, mode in (("index order", SEQUENTIAL), ("slabs", SLABS), ("slab order", SLAB_ORDER)):
                pipeline.con.vertex_z.from_numpy(z0)
                pipeline.con.contact_accumulated.from_numpy(r0)
                projection_sweep(pipeline.con, mode)
                ti.sync()
                t = time.perf_counter()
                for _ in range(a.sweeps):
                    projection_sweep(pipeline.con, mode)
                ti.sync()
                sweeps[name].append((time.perf_counter() - t) / a.sweeps * 1e3)
                ends[name] = pipeline.con.vertex_z.to_numpy()
            same = same and np.array_equal(ends["slabs"], ends["slab order"])
        for name, v in sweeps.items():
            print(f"sweep, {name}: " + " ".join(f"{t:.2f}" for t in v) + f" ms (median {np.median(v):.2f})")
        print(f"sweep: index order / slabs {np.median(sweeps['index order']) / np.median(sweeps['slabs']):.2f}, "
              f"slab order (one thread) / slabs {np.median(sweeps['slab order']) / np.median(sweeps['slabs']):.2f}; "
              f"slabs and slab order end at the same bits: {same}")
    else:
        print(f"no slab sweeps at this step ({pipeline.contact_count} contacts): sweeps not compared")
    steps = {"slabs": [], "index order": []}
    for _ in range(a.steps):
        for name, on in (("slabs", runs), ("index order", False)):
            pipeline.slabs_contiguous = on
            ti.sync()
            t = time.perf_counter()
            sim.step()
            ti.sync()
            steps[name].append({"ms": (time.perf_counter() - t) * 1e3, "correction_sweeps": pipeline.correction_sweeps_last,
                                "slab_sweeps": bool(pipeline._slabs)})
    pipeline.slabs_contiguous = runs
    for name, v in steps.items():
        ms = [r["ms"] for r in v]
        print(f"step, {name}: " + " ".join(f"{t:.0f}" for t in ms) + f" ms (median {np.median(ms):.0f}); correction sweeps "
              f"{[r['correction_sweeps'] for r in v]}; slab sweeps used {sorted({r['slab_sweeps'] for r in v})}")
    ratio = np.median([r["ms"] for r in steps["index order"]]) / np.median([r["ms"] for r in steps["slabs"]])
    print(f"step: index order / slabs {ratio:.2f}")
    if a.out:
        with open(a.out, "w") as fh:
            json.dump({"strands": a.strands, "slabs_are_runs": runs, "sweep_ms": sweeps, "steps": steps}, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
