"""The grooming edit with glibc keeping freed memory or not (``taichi_hair.cli.common.keep_freed_memory``; issue 15, item 4).

Run from the repository root, one process per setting, alternating (the setting is process-wide and must come first)::

    python3 benchmarks/probes/groom_edit_malloc.py [--keep] [--edits 4] [--strands 86000]

The groom of ``benchmarks/bench_groom.py`` (wavy strands x 14 vertices on ``assets/head.obj``, 10 % sag-free guides,
hair-hair contacts), NumPy's huge-page advice off as in the app; with ``--keep``, ``keep_freed_memory()`` before
anything else.  After two frames and four timed ones, ``--edits`` edits of every 10th strand (``scale_length`` 1.1,
then 1/1.1, ...), each followed by its in-place update and one frame.  Prints each edit's host and update seconds,
the frames before the edits and the peak resident memory.  The figures of ``keep_freed_memory``'s docstring are
four such processes, alternating.
"""

import argparse
import resource
import time


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--keep", action="store_true", help="apply keep_freed_memory() first")
    ap.add_argument("--edits", type=int, default=4)
    ap.add_argument("--strands", type=int, default=86000)
    args = ap.parse_args(argv)
    from taichi_hair.cli.common import keep_freed_memory

    kept = keep_freed_memory() if args.keep else False
    import numpy as np

    from groom_step_profile import grooming_session, timed_frame  # (this folder: a script's own comes first)

    ti, groom, session = grooming_session(args.strands)
    sim = session._sim

    def frame() -> float:
        return timed_frame(ti, sim)

    frame()
    frame()
    before = [frame() for _ in range(4)]
    session.select_strands(np.arange(0, groom.strand_count, 10))
    print(f"keep_freed_memory applied: {kept}", flush=True)
    for k in range(args.edits):
        t0 = time.perf_counter()
        session.scale_length(1.1 if k % 2 == 0 else 1 / 1.1)
        ti.sync()
        t1 = time.perf_counter()
        session._ensure_built()
        ti.sync()
        t2 = time.perf_counter()
        f = frame()
        print(f"edit {k}: host {t1 - t0:.3f} s, update {t2 - t1:.3f} s, total {t2 - t0:.3f} s, next frame {1e3 * f:.0f} ms",
              flush=True)
    print("frames before the edits [ms]:", [round(1e3 * v) for v in before])
    print("peak resident memory [MB]:", resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
