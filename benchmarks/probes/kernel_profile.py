"""Which Taichi kernels a ``taichi-hair simulate`` run spends its time in (Taichi's kernel profiler).

Run from the repository root, with any ``simulate`` arguments after ``--``::

    python3 benchmarks/probes/kernel_profile.py [--top 25] [--json FILE] [--tasks KERNEL ...] -- hairball --out /tmp/p

The profiler is switched on through ``TI_KERNEL_PROFILER=1`` (``ti.init`` reads it), so the run is the CLI's
own; it synchronises after every launch, so the total is a little higher than an unprofiled run.  Prints the
kernels by total time (kernel compilation of the first call is not in these figures: the profiler times the
launches) and writes them as JSON when asked.  Counts are of offloaded tasks: Taichi runs each top-level loop
of a kernel as its own task, so a kernel with 18 loops counts 18 per launch.  ``--tasks KERNEL`` also splits
that kernel's time by task (its top-level loops in source order: e.g. ``correction_sweep``'s 8 contact solves,
8 vertex updates and its edge passes), which is how the correction's sweep was taken apart.  A diagnostic, not
a benchmark.
"""

import argparse
import json
import os
import re
import sys


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if "--" in argv:
        k = argv.index("--")
        own, sim = argv[:k], argv[k + 1:]
    else:
        own, sim = [], argv
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--top", type=int, default=25)
    ap.add_argument("--json", default=None)
    ap.add_argument("--tasks", nargs="*", default=[], help="kernels to split by offloaded task")
    a = ap.parse_args(own)
    os.environ["TI_KERNEL_PROFILER"] = "1"
    import taichi as ti

    from taichi_hair.cli.main import main as cli_main

    rc = cli_main(["simulate", *sim])
    ti.sync()
    prog = ti.lang.impl.get_runtime().prog
    # As Taichi's own KernelProfiler._update_records: on CUDA the times come from events, read at the sync.
    prog.sync_kernel_profiler()
    prog.update_kernel_profiler()
    records = prog.get_kernel_profiler_records()
    by_name = {}
    for r in records:
        # Taichi names a launch "<kernel>_c<n>_<k>_kernel_<task>...": keep the kernel's own name.
        m = re.match(r"(.+?)_c\d+_", r.name)
        name = m.group(1) if m else r.name
        d = by_name.setdefault(name, [0, 0.0])
        d[0] += 1
        d[1] += r.kernel_time
    rows = sorted(((n, c, t) for n, (c, t) in by_name.items()), key=lambda x: -x[2])
    total = sum(t for _, _, t in rows) or 1.0
    print(f"kernel time {total / 1e3:.3f} s over {sum(c for _, c, _ in rows)} tasks")
    print(f"{'kernel':60s} {'tasks':>9s} {'total ms':>10s} {'ms/task':>10s} {'share':>6s}")
    for n, c, t in rows[: a.top]:
        print(f"{n[:60]:60s} {c:9d} {t:10.1f} {t / c:10.4f} {100 * t / total:5.1f}%")
    for kernel in a.tasks:
        split = {}
        for r in records:
            # "<kernel>_c<n>_<k>_kernel_<task>_<type>": the task's index within the kernel and its loop type.
            m = re.match(r"(.+?)_c\d+_\d+_kernel_(\d+)_(\w+?)(?:_[a-z]|$)", r.name) or re.match(
                r"(.+?)_c\d+_\d+_kernel_(\d+)_(.*)", r.name)
            if m and m.group(1) == kernel:
                d = split.setdefault((int(m.group(2)), m.group(3)), [0, 0.0])
                d[0] += 1
                d[1] += r.kernel_time
        print(f"\n{kernel} by task:")
        for (task, kind), (c, t) in sorted(split.items()):
            print(f"  task {task:3d} {kind[:24]:24s} {c:9d} {t:10.1f} ms {t / c:10.4f} ms/task")
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"simulate": sim, "total_ms": total,
                       "kernels": [{"name": n, "tasks": c, "total_ms": t} for n, c, t in rows]}, f, indent=1)
    return rc


if __name__ == "__main__":
    sys.exit(main())
