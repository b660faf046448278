"""What a grooming session's undo history holds, edit after edit: resident memory and each edit's host time.

Run from the repository root (``PYTHONPATH=OTHER_CHECKOUT`` measures another commit's library with this probe)::

    python3 benchmarks/probes/groom_edit_memory.py [--strands 86000] [--edits 30] [--undo-limit 100] [--advance N]
        [--json OUT]

Builds the grooming benchmark's groom (``bench_groom.py``'s wavy groom, 14 vertices per strand) in a session, selects
every 10th strand and makes ``--edits`` ``scale_length`` edits (by 1.1 and back, alternately), each kept in the undo
history (``--undo-limit``).  Without ``--advance`` the session has no simulation (host edits only: the history's cost,
not the update's); with ``--advance N`` the live workflow: the simulation (hair-hair contacts) runs N frames after each
edit, so the groom's current pose changes everywhere between two snapshots.  Prints the
process's resident memory every 5 edits and each edit's host seconds, and the snapshots the history kept
(``GroomingConfig.undo_limit`` and ``undo_memory_mb``); then undoes every edit and, if all were kept, checks that the
groom is the first one again, bit for bit.  As the command line and the grooming app, glibc keeps freed memory
(``keep_freed_memory``).
"""

import argparse
import json
import os
import time


def _rss_mb() -> float:
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--strands", type=int, default=86000)
    ap.add_argument("--edits", type=int, default=30)
    ap.add_argument("--undo-limit", type=int, default=100)
    ap.add_argument("--advance", type=int, default=0, help="simulated frames after each edit (0: no simulation)")
    ap.add_argument("--json", default=None, help="write the figures to this file")
    a = ap.parse_args(argv)
    import numpy as np
    import taichi as ti

    import taichi_hair

    taichi_hair.init(arch=ti.cpu, default_fp=ti.f32, log_level=ti.WARN)
    from taichi_hair.cli.common import keep_freed_memory, no_numpy_huge_pages

    no_numpy_huge_pages()
    keep_freed_memory()
    from taichi_hair.groom.generators import GeneratorConfig, generate_groom, load_head
    from taichi_hair.groom.session import GroomingConfig, GroomingSession

    groom = generate_groom(load_head(), GeneratorConfig(style="wavy", strands=a.strands, vertices_per_strand=14,
                                                        length=0.25, seed=0))
    session = GroomingSession(groom, GroomingConfig(iterations=10, guide_ratio=0.1, contacts=a.advance > 0,
                                                    autosave_every=0, rest_pose="authored", undo_limit=a.undo_limit))
    if a.advance:
        session.advance(1)  # the build and a first frame before the measurement
    first = (session.groom.points.tobytes(), session.groom.rest_points.tobytes())
    session.select_strands(np.arange(0, groom.strand_count, 10))
    res = {"strands": a.strands, "edits": a.edits, "undo_limit": a.undo_limit, "advance": a.advance,
           "load_average": list(os.getloadavg()),
           "rss_mb_before": _rss_mb(), "rss_mb": {}, "edit_ms": []}
    print(f"before the edits: {res['rss_mb_before']:.0f} MB resident")
    for k in range(a.edits):
        t = time.perf_counter()
        session.scale_length(1.1 if k % 2 == 0 else 1 / 1.1)
        res["edit_ms"].append(1e3 * (time.perf_counter() - t))
        if a.advance:
            session.advance(a.advance)
        if (k + 1) % 5 == 0 or k + 1 == a.edits:
            res["rss_mb"][k + 1] = _rss_mb()
            print(f"{k + 1:4d} edits: {res['rss_mb'][k + 1]:7.0f} MB resident, the last 5 edits "
                  f"{[round(x) for x in res['edit_ms'][-5:]]} ms")
    kept = len(session.history.undo_stack)  # (undo_limit and GroomingConfig.undo_memory_mb may have dropped some)
    res["snapshots_kept"], res["history_bytes"] = kept, session.history.bytes_held()
    print(f"undo snapshots kept: {kept} of {a.edits}, {res['history_bytes'] / 2**20:.0f} MiB below the newest")
    while session.can_undo:
        session.undo()
    same = first == (session.groom.points.tobytes(), session.groom.rest_points.tobytes())
    res["undone_to_first_bit_for_bit"] = same if kept == a.edits else None
    grow = (res["rss_mb"][a.edits] - res["rss_mb_before"]) / a.edits
    res["mb_per_edit"] = grow
    print(f"{grow:.1f} MB per edit; median edit {np.median(res['edit_ms']):.0f} ms; "
          + (f"undone to the first groom bit for bit: {same}" if kept == a.edits else "(history shorter than the edits)"))
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(res, fh, indent=1)
        print(f"wrote {a.json}")
    return 0 if same or kept < a.edits else 1


if __name__ == "__main__":
    raise SystemExit(main())
