"""Which Taichi kernels the grooming tool's still step spends its time in (Taichi's kernel profiler).

Run from the repository root::

    python3 benchmarks/probes/groom_step_profile.py [--strands 86000] [--steps 6] [--schedule lanes]
        [--tasks 'build_adjacency|lists_from_pairs'] [--json FILE]

The groom of ``benchmarks/bench_groom.py`` (wavy strands x 14 vertices on ``assets/head.obj``, 10 % sag-free guides,
hair-hair contacts, 10 iterations per step); three steps first (compilation, the first contacts), then ``--steps``
profiled steps with nothing else in between (no skinning, no drawing).  Prints per step: the wall time, the
kernels' total, each kernel's offloaded tasks and milliseconds (a kernel's top-level loops are tasks of their own),
the contact statistics of the last step, and with ``--tasks REGEX`` the matching kernels split by task.  The profiler
synchronises after every task, so the step is a little slower than unprofiled.  A diagnostic, not a benchmark:
this is how the figures of BENCHMARKS.md's "The contact pipeline's bookkeeping" were taken.
"""

import argparse
import json
import re
import time


def grooming_session(strands: int, schedule: str = "auto", **init):
    """Taichi started (``taichi_hair.init`` on the CPU, f32, ``init`` passed on), NumPy's huge-page advice off as in the
    app, and the grooming benchmark's groom (wavy strands x 14 vertices on ``assets/head.obj``) in a built session of
    10 % sag-free guides with hair-hair contacts and 10 iterations per step (Taichi's frontend lightened as the app's,
    ``cli.common.lighter_kernel_positions``).  Returns ``(ti, groom, session)``.  The
    grooming probes (``groom_config_ab.py``, ``groom_edit_malloc.py``) import it and ``timed_frame`` from here."""
    import taichi as ti

    import taichi_hair

    taichi_hair.init(arch=ti.x64, default_fp=ti.f32, log_level=ti.WARN, **init)
    from taichi_hair.cli.common import lighter_kernel_positions, no_numpy_huge_pages
    from taichi_hair.groom.generators import GeneratorConfig, generate_groom, load_head
    from taichi_hair.groom.session import GroomingConfig, GroomingSession

    no_numpy_huge_pages()
    lighter_kernel_positions()
    groom = generate_groom(load_head(), GeneratorConfig(style="wavy", strands=strands, vertices_per_strand=14,
                                                        length=0.25, seed=0))
    session = GroomingSession(groom, GroomingConfig(iterations=10, guide_ratio=0.1, contacts=True, autosave_every=0,
                                                    rest_pose="sag-free", schedule=schedule))
    session._ensure_built()
    return ti, groom, session


def timed_frame(ti, sim) -> float:
    """One still frame of the grooming tool, simulation and skinning, synchronised: its wall time [s]."""
    t = time.perf_counter()
    sim.step()
    sim.skin.deform(sim.state, sim.control)
    ti.sync()
    return time.perf_counter() - t


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--strands", type=int, default=86000)
    ap.add_argument("--steps", type=int, default=6)
    ap.add_argument("--schedule", default="lanes", choices=("auto", "stage", "strand", "lanes"))
    ap.add_argument("--top", type=int, default=30)
    ap.add_argument("--tasks", default=None, help="regular expression: split these kernels by task")
    ap.add_argument("--json", default=None)
    a = ap.parse_args()
    ti, _, session = grooming_session(a.strands, a.schedule, kernel_profiler=True)
    sim = session._sim
    for _ in range(3):
        sim.step()
    ti.sync()
    ti.profiler.clear_kernel_profiler_info()
    t0 = time.perf_counter()
    for _ in range(a.steps):
        sim.step()
    ti.sync()
    wall = (time.perf_counter() - t0) / a.steps
    prog = ti.lang.impl.get_runtime().prog
    prog.sync_kernel_profiler()
    prog.update_kernel_profiler()
    kernels, tasks = {}, {}
    for r in prog.get_kernel_profiler_records():
        m = re.match(r"(.+?)_c\d+_", r.name)
        name = m.group(1) if m else r.name
        for table, key in ((kernels, name), (tasks, r.name)):
            row = table.setdefault(key, [0, 0.0])
            row[0] += 1
            row[1] += r.kernel_time
    total = sum(t for _, t in kernels.values()) / a.steps
    print(f"{sim.model.vertex_count} guide vertices, schedule {a.schedule}: {1e3 * wall:.1f} ms per step (wall), "
          f"kernels {total:.1f} ms per step")
    rows = sorted(kernels.items(), key=lambda kv: -kv[1][1])
    for name, (count, t) in rows[:a.top]:
        print(f"  {name:45s} {count / a.steps:7.1f} tasks {t / a.steps:8.2f} ms")
    if a.tasks:
        for name, (count, t) in sorted(tasks.items()):
            if re.match(a.tasks, name):
                print(f"  {name:70s} {count / a.steps:5.1f} {t / a.steps:8.2f} ms")
    stats = sim.solver.contacts.statistics(sim.state.vertex_position)
    print("contacts of the last step:", stats)
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"strands": a.strands, "steps": a.steps, "schedule": a.schedule, "wall_ms_per_step": 1e3 * wall,
                       "kernels_ms_per_step": {k: v[1] / a.steps for k, v in kernels.items()}, "contacts": stats},
                      f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
