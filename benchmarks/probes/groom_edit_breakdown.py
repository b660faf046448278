"""Where a grooming edit's time goes: the host edit and the in-place update, stage by stage.

Run from the repository root::

    python3 benchmarks/probes/groom_edit_breakdown.py [--strands 86000] [--edits 7] [--json OUT]

Builds the grooming benchmark's session (``bench_groom.py``'s wavy groom, 10 % guides, hair-hair contacts, a sag-free
rest pose), steps it twice, selects every 10th strand and makes ``--edits`` edits (``scale_length`` by 1.1 and back,
alternately), each followed by its in-place update and one frame, as ``bench_groom.py``'s edit.  Each stage below is
timed by a wrapper that synchronises Taichi before and after it (so the stages' sum is a little above an unwrapped
edit's); the first edit is left out of the medians (its buffers are first touched there).  Printed: the median and
every edit's milliseconds per stage.
"""

import argparse
import collections
import json
import os
import time


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--strands", type=int, default=86000)
    ap.add_argument("--edits", type=int, default=7)
    ap.add_argument("--json", default=None, help="write the stages' milliseconds to this file")
    a = ap.parse_args(argv)
    import numpy as np
    import taichi as ti

    import taichi_hair

    taichi_hair.init(arch=ti.cpu, default_fp=ti.f32, log_level=ti.WARN)
    from taichi_hair.cli.common import keep_freed_memory, lighter_kernel_positions, no_numpy_huge_pages

    lighter_kernel_positions()
    no_numpy_huge_pages()
    keep_freed_memory()  # as the grooming app and bench_groom.py
    import taichi_hair.groom.binding as binding
    import taichi_hair.groom.session as session_module
    import taichi_hair.groom.simulation as simulation
    import taichi_hair.groom.skinning as skinning
    import taichi_hair.model as model
    import taichi_hair.solver_admm as solver_admm
    from taichi_hair.groom.generators import GeneratorConfig, generate_groom, load_head
    from taichi_hair.groom.session import GroomingConfig, GroomingSession

    times = collections.defaultdict(list)

    def timed(owner, name, label):
        f = getattr(owner, name)

        def wrapper(*args, **kwargs):
            ti.sync()
            t = time.perf_counter()
            out = f(*args, **kwargs)
            ti.sync()
            times[label].append(time.perf_counter() - t)
            return out

        setattr(owner, name, wrapper)

    for owner, name, label in (
            (session_module.GroomingSession, "scale_length", "host: scale_length"),
            (simulation.GuideSimulation, "update", "update: all of GuideSimulation.update"),
            (simulation, "guide_setup", "update: guide_setup"),
            (simulation, "guide_host", "update: guide_host"),
            (model.Model, "update", "update: Model.update (each call)"),
            (simulation.GuideSimulation, "_solve_rest_pose", "update: sag-free rest pose"),
            (solver_admm.SolverADMM, "refresh_model", "update: refresh_model"),
            (simulation.GuideSimulation, "_render_rest", "update: render rest points"),
            (skinning, "compute_binding", "update: compute_binding"),
            (binding, "_strands_to_rebind", "update: compute_binding: strands to bind again"),
            (binding, "_bind_vertices", "update: compute_binding: the bind kernel"),
            (skinning.SkinningLBS, "_upload", "update: skinning upload"),
            (simulation.GuideSimulation, "load_positions", "after: load_positions"),
            (session_module.GroomingSession, "_apply_kinematics", "after: kinematics")):
        timed(owner, name, label)

    groom = generate_groom(load_head(), GeneratorConfig(style="wavy", strands=a.strands, vertices_per_strand=14,
                                                        length=0.25, seed=0))
    session = GroomingSession(groom, GroomingConfig(iterations=10, guide_ratio=0.1, contacts=True, autosave_every=0,
                                                    rest_pose="sag-free"))
    session._ensure_built()
    sim = session._sim
    for _ in range(2):
        sim.step()
        sim.skin.deform(sim.state, sim.control)
    ti.sync()
    times.clear()
    session.select_strands(np.arange(0, groom.strand_count, 10))
    totals = []
    for k in range(a.edits):
        t0 = time.perf_counter()
        session.scale_length(1.1 if k % 2 == 0 else 1 / 1.1)
        session._ensure_built()
        ti.sync()
        totals.append(time.perf_counter() - t0)
        sim = session._sim
        sim.step()
        sim.skin.deform(sim.state, sim.control)
        ti.sync()
    res = {"strands": a.strands, "edits": a.edits, "load_average": list(os.getloadavg()),
           "edit_total_ms": [1e3 * t for t in totals], "stages_ms": {}}
    per_edit = {label: len(v) // a.edits for label, v in times.items()}
    for label, v in times.items():
        kept = v[per_edit[label]:] if a.edits > 1 else v  # the first edit left out
        res["stages_ms"][label] = {"median": 1e3 * float(np.median(kept)), "all": [round(1e3 * x, 1) for x in v]}
        print(f"{label:50s} median {1e3 * np.median(kept):7.1f} ms   {[round(1e3 * x) for x in v]}")
    print(f"{'edit: host + update (the wrappers included)':50s} median {1e3 * np.median(totals[1:] or totals):7.1f} ms   "
          f"{[round(1e3 * x) for x in totals]}")
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(res, fh, indent=1)
        print(f"wrote {a.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
