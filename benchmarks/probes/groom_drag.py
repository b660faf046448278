"""What a drag does to the layering of the grooming benchmark's groom (issue 15 item 4; the grooming drag).

Run from the repository root:
    python3 benchmarks/probes/groom_drag.py [--stiffness 0.5] [--radius 0.01] [--offset 0.03] [--frames 12]
        [--release-frames 8] [--correction-cap 80] [--out FILE.json]

The groom of ``benchmarks/bench_groom.py`` (86,000 wavy strands x 14 vertices on ``assets/head.obj``, 8,600 sag-free
guides, hair-hair contacts, 10 iterations per frame).  After 4 frames it selects the vertices within ``--radius`` [m]
of the middle vertex of strand 100, drags them ``--offset`` [m] outward from the head's centre (along that vertex's
position) with ``--stiffness`` for ``--frames`` frames, then releases them for ``--release-frames`` frames.  Printed per
frame: its time, the correction's sweeps, the hair pairs crossed and the hair-pair penetration p99 / max of the step
(``GroomingSession.quality``); after the drag, how far the selected vertices moved along the drag (their targets
moved offset (1 - (1 - stiffness)^frames)).  ``--correction-cap`` sets ``ContactConfig.correction_max_iterations``
of the session's solver, ``--contact-sweeps`` and ``--correction-sweeps`` those of ``GroomingConfig`` (after the first
4 frames).  The crossed pairs are those of the pairs within reach at each step's beginning: a strand pulled farther
than that in one step can pass through another unseen.  A diagnostic, not a benchmark: one run, the frame times are
those of a shared machine.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np


def benchmark_session(strands: int):
    """(groom, session): ``benchmarks/bench_groom.py``'s groom (wavy strands x 14 vertices, 25 cm, on
    ``assets/head.obj``, seed 0) in a GroomingSession with 10 % sag-free guides, hair-hair contacts and 10 iterations
    per frame (``ti.init`` first; also used by ``slab_sweeps.py``)."""
    from taichi_hair.cli.common import no_numpy_huge_pages
    from taichi_hair.groom.generators import GeneratorConfig, generate_groom, load_head
    from taichi_hair.groom.session import GroomingConfig, GroomingSession

    no_numpy_huge_pages()
    groom = generate_groom(load_head(), GeneratorConfig(style="wavy", strands=strands, vertices_per_strand=14,
                                                        length=0.25, seed=0))
    return groom, GroomingSession(groom, GroomingConfig(iterations=10, guide_ratio=0.1, contacts=True,
                                                        autosave_every=0, rest_pose="sag-free"))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--stiffness", type=float, default=0.5)
    p.add_argument("--radius", type=float, default=0.01)
    p.add_argument("--offset", type=float, default=0.03)
    p.add_argument("--frames", type=int, default=12)
    p.add_argument("--release-frames", type=int, default=8)
    p.add_argument("--correction-cap", type=int, default=None)
    p.add_argument("--contact-sweeps", type=int, default=None)
    p.add_argument("--correction-sweeps", type=int, default=None)
    p.add_argument("--strands", type=int, default=86000)
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)

    import taichi as ti

    import taichi_hair

    taichi_hair.init(arch=ti.cpu, default_fp=ti.f32, log_level=ti.ERROR)
    _, session = benchmark_session(args.strands)
    session.advance(4)
    if args.correction_cap is not None:
        session._sim.solver.contacts.config.correction_max_iterations = args.correction_cap
    if args.contact_sweeps is not None:
        session.set_parameter("contact_sweeps", args.contact_sweeps)
    if args.correction_sweeps is not None:
        session.set_parameter("correction_sweeps", args.correction_sweeps)
    g = session.groom
    centre = g.points[g.strand_offsets[100] + 7].astype(np.float64)
    direction = centre / np.linalg.norm(centre)
    selected = session.select(centre, args.radius)
    before = g.points.astype(np.float64)
    print(f"selected {selected} vertices within {1e3 * args.radius:g} mm of {np.round(centre, 4).tolist()}; drag "
          f"{1e3 * args.offset:g} mm outward, stiffness {args.stiffness:g}", flush=True)
    session.drag(tuple(args.offset * direction), stiffness=args.stiffness)
    rows = []

    def frame(tag):
        t = time.perf_counter()
        session.advance(1)
        ms = 1e3 * (time.perf_counter() - t)
        q = session.quality(full=False)
        row = dict(tag=tag, ms=ms, sweeps=q.get("correction_sweeps", 0), crossed=q.get("crossed_pairs", 0),
                   p99_um=1e6 * q.get("hair_penetration_p99_m", 0.0), max_um=1e6 * q.get("hair_penetration_max_m", 0.0))
        rows.append(row)
        print(f"  {tag:>10}: {ms:5.0f} ms, {row['sweeps']} sweeps, {row['crossed']} crossed, hair pairs p99 "
              f"{row['p99_um']:.1f} um, max {row['max_um']:.0f} um", flush=True)

    for f in range(args.frames):
        frame(f"drag {f}")
    sel = session.vertex_selection
    moved = (session.groom.points[sel].astype(np.float64) - before[sel]) @ direction
    target = args.offset * (1 - (1 - args.stiffness) ** args.frames)
    print(f"the selected vertices moved along the drag: mean {1e3 * moved.mean():.2f} mm, p10 "
          f"{1e3 * np.percentile(moved, 10):.2f}, p90 {1e3 * np.percentile(moved, 90):.2f} mm (targets "
          f"{1e3 * target:.2f} mm)", flush=True)
    session.release()
    for f in range(args.release_frames):
        frame(f"release {f}")
    if args.out:
        with open(args.out, "w", encoding="utf-8") as fh:
            json.dump(dict(args=vars(args), selected=int(selected), frames=rows,
                           moved_mm=dict(mean=1e3 * float(moved.mean()), p10=1e3 * float(np.percentile(moved, 10)),
                                         p90=1e3 * float(np.percentile(moved, 90)), targets=1e3 * target)),
                      fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
