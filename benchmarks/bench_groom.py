"""Benchmark of the grooming edit loop (Daviet 2023, Sec. 5.3: 86,000 render strands, 8,600 simulated guides).

A procedural groom (``taichi_hair.groom.generators``, wavy, on ``assets/head.obj``): ``--strands`` render strands
of ``--vertices`` vertices (default 86,000 x 14: 1.2M render vertices; 10 % guides = 8,600 x 14 = 120k
simulated vertices).  A :class:`GroomingSession` runs it quasistatically with ``--iterations`` ADMM
iterations per frame (10, as the paper) and hair-hair proximity contacts (``--contacts on``; the head is
drawn, not collided, so the contact pipeline is the hair's own).  Each measured frame times, separately
and synchronised (``ti.sync``):

* simulation: ``SolverADMM.step`` of the guides (contacts included);
* skinning: ``SkinningLBS.deform`` of every render strand;
* drawing: off screen: copy the skinned positions into the viewer's strand buffer, draw the strands and the
  head, read the image back as the (H, W, 3) array of ``ViewerGGUI.image`` (what an off-screen tool pays; a
  window would ``show`` instead).  ``--drawing lines`` draws with GGUI's lines on the Vulkan device,
  ``--drawing raster`` with the Taichi rasteriser (``taichi_hair.render.raster``); ``auto`` (default) as
  the grooming app: the rasteriser when Taichi runs on the CPU.

Also reported: the one-off costs (groom generation, session build, first frame = kernel compilation) and
an edit: ``scale_length`` on 10 % of the strands followed by one frame, i.e. the in-place Model update.
``--edit spread`` (default) takes every 10th strand, all over the head (about half the render strands are
bound to an edited guide and are bound again); ``--edit region`` the 10 % whose roots are nearest one root
(a brush stroke's selection: only the region and its border are bound again).  The process is set up as the
grooming app's (``--numpy-huge-pages app``, default: NumPy's huge-page advice off and glibc keeping freed memory, see
``taichi_hair.cli.common.no_numpy_huge_pages`` and ``keep_freed_memory``); ``--numpy-huge-pages numpy`` keeps NumPy's
and glibc's defaults.  Taichi starts as in the app too: ``taichi_hair.init`` and ``cli.common.lighter_kernel_positions``
(a cheaper frontend; ``TAICHI_HAIR_STOCK_POSITIONS=1`` keeps Taichi's own, as for the app).

Usage:
    python benchmarks/bench_groom.py [--arch cpu|cuda] [--strands 86000] [--vertices 14] [--frames 5]
        [--contacts on|off] [--size 960 720] [--edit spread|region] [--rest-pose authored|sag-free]
        [--rest-max-change X] [--unheld-shape-weight W]
        [--numpy-huge-pages app|numpy] [--drawing auto|lines|raster] [--out FILE]

JSON goes to ``benchmarks/results/groom/groom_<strands>_<arch>_contacts_<on|off>.json`` by default; a run
whose simulation diverges writes what it measured and the error (exit code 1).
"""

import argparse
import datetime
import os
import sys

import numpy as np

from harness import Bench, results_path, stopwatch  # benchmarks/harness.py (the script's folder is on sys.path)


def main(argv=None):
    p = argparse.ArgumentParser()
    p.add_argument("--arch", default="cpu", choices=["cpu", "cuda", "vulkan"])
    p.add_argument("--strands", type=int, default=86000)
    p.add_argument("--vertices", type=int, default=14)
    p.add_argument("--guide-ratio", type=float, default=0.1)
    p.add_argument("--iterations", type=int, default=10)
    p.add_argument("--contact-sweeps", type=int, default=None, help="GroomingConfig.contact_sweeps (its default if unset)")
    p.add_argument("--correction-sweeps", type=int, default=None, help="GroomingConfig.correction_sweeps (default if unset)")
    p.add_argument("--contacts", choices=["on", "off"], default="on")
    p.add_argument("--frames", type=int, default=5, help="measured frames (after 2 warm-up frames)")
    p.add_argument("--size", type=int, nargs=2, default=(960, 720))
    p.add_argument("--schedule", default="auto", choices=["auto", "stage", "strand", "lanes"],
                   help="the guides' ADMM launch schedule (GroomingConfig.schedule)")
    p.add_argument("--no-draw", action="store_true", help="skip the GGUI drawing (no Vulkan device)")
    p.add_argument("--rest-pose", choices=["authored", "sag-free"], default="authored",
                   help="GroomingConfig.rest_pose: sag-free solves the guides' rest pose at the build and after the edit")
    p.add_argument("--rest-max-change", type=float, default=None,
                   help="GroomingConfig.rest_max_change: the largest rest strain change of a held guide (sag-free; "
                        "default GroomingConfig's)")
    p.add_argument("--unheld-shape-weight", type=float, default=None,
                   help="GroomingConfig.unheld_shape_weight: springs that hold the guides the sag-free rest pose does "
                        "not hold to their authored shape (0: they sag; default GroomingConfig's)")
    p.add_argument("--edit", choices=["spread", "region"], default="spread",
                   help="which 10 %% of the strands the edit takes: every 10th, or those rooted nearest one root")
    p.add_argument("--numpy-huge-pages", choices=("app", "numpy"), default="app",
                   help="app: as the grooming app and the command line do (NumPy's huge-page advice off, glibc keeping "
                        "freed memory: taichi_hair.cli.common.no_numpy_huge_pages, keep_freed_memory); numpy: NumPy's "
                        "and glibc's own defaults")
    p.add_argument("--drawing", choices=("auto", "lines", "raster"), default="auto",
                   help="ViewerGGUI(drawing=...): GGUI lines or the Taichi rasteriser (auto: raster on a CPU arch)")
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)
    bench = Bench("groom", argv)

    import taichi as ti

    import taichi_hair

    taichi_hair.init(arch=getattr(ti, args.arch), default_fp=ti.f32, log_level=ti.WARN)
    arch = str(ti.lang.impl.current_cfg().arch).split(".")[-1]
    from taichi_hair.cli.common import keep_freed_memory, lighter_kernel_positions, no_numpy_huge_pages

    # As the grooming app starts Taichi (cli.common._init_taichi): its first frame is the one measured.
    light_positions = lighter_kernel_positions()

    huge_pages_off = no_numpy_huge_pages() if args.numpy_huge_pages == "app" else False
    freed_kept = keep_freed_memory() if args.numpy_huge_pages == "app" else False
    from taichi_hair.groom.generators import HEAD_MESH_PATH, GeneratorConfig, generate_groom, load_head, read_obj_groups
    from taichi_hair.groom.session import GroomingConfig, GroomingSession
    from taichi_hair.render import CameraConfig, ViewerGGUI, strand_colors

    res = {"arch": arch, "strands": args.strands, "vertices_per_strand": args.vertices,
           "guide_ratio": args.guide_ratio, "iterations": args.iterations, "contacts": args.contacts,
           "schedule": args.schedule, "rest_pose": args.rest_pose,
           "numpy_huge_pages_off": huge_pages_off, "keep_freed_memory": freed_kept,
           "lighter_kernel_positions": light_positions,
           "image": list(args.size), "date": datetime.date.today().isoformat()}

    with stopwatch(ti.sync) as sw:
        head = load_head()
        groom = generate_groom(head, GeneratorConfig(style="wavy", strands=args.strands,
                                                     vertices_per_strand=args.vertices, length=0.25, seed=0))
    res["generate_s"] = sw.seconds
    cfg = GroomingConfig(iterations=args.iterations, guide_ratio=args.guide_ratio,
                         contacts=args.contacts == "on", autosave_every=0, schedule=args.schedule,
                         rest_pose=args.rest_pose,
                         **({} if args.contact_sweeps is None else {"contact_sweeps": args.contact_sweeps}),
                         **({} if args.correction_sweeps is None else {"correction_sweeps": args.correction_sweeps}),
                         **({} if args.rest_max_change is None else {"rest_max_change": args.rest_max_change}),
                         **({} if args.unheld_shape_weight is None else {"unheld_shape_weight": args.unheld_shape_weight}))
    res["contact_sweeps"], res["correction_sweeps"] = cfg.contact_sweeps, cfg.correction_sweeps
    session = GroomingSession(groom, cfg)
    with stopwatch(ti.sync) as sw:
        session._ensure_built()
    res["build_s"] = sw.seconds
    sim = session._sim
    res["guides"] = int(sim.model.strand_count)
    res["simulated_vertices"] = int(sim.model.vertex_count)
    res["render_vertices"] = int(groom.vertex_count)
    if args.rest_pose == "sag-free":
        res["rest_max_change"] = cfg.rest_max_change
        res["unheld_shape_weight"] = cfg.unheld_shape_weight
        res["guides_held"] = int(session.rest_pose_report()["strands_held"])
    print(f"{arch}: {args.strands} strands x {args.vertices} vertices, {res['guides']} guides "
          f"({res['simulated_vertices']} simulated vertices); generated in {res['generate_s']:.1f} s, "
          f"session built in {res['build_s']:.1f} s"
          + (f"; {res['guides_held']} guides held sag-free" if "guides_held" in res else ""), flush=True)

    viewer = None
    if not args.no_draw:
        viewer = ViewerGGUI(args.size[0], args.size[1], show_window=False, drawing=args.drawing)
        res["drawing"] = viewer.drawing
        v, f, _ = read_obj_groups(HEAD_MESH_PATH)
        viewer.set_head(v, f)
        viewer.set_camera(CameraConfig.framing(np.vstack([groom.points, v]), direction=(0.55, 0.25, 1.0)))
        viewer.set_strands(groom.points, groom.strand_offsets, strand_colors(groom, "region"))

    res["frames_all_ms"] = []  # every frame as it completes (a diverged run keeps the ones before)

    def frame():
        with stopwatch(ti.sync) as simulation:
            sim.step()  # SolverADMM.step, and the step's hair-pair figures folded into the session's quality
        with stopwatch(ti.sync) as skinning:
            sim.skin.deform(sim.state, sim.control)
        with stopwatch(ti.sync) as drawing:
            if viewer is not None:
                viewer.set_positions_field(sim.skin.fields.render_vertex_position)
                viewer.render()
                viewer.image()  # (the frame, read back: the drawing is done)
        ms = (1e3 * simulation.seconds, 1e3 * skinning.seconds, 1e3 * drawing.seconds)
        res["frames_all_ms"].append(list(ms))
        return ms

    from taichi_hair.errors import SimulationDivergedError

    out = args.out or results_path("groom", f"groom_{args.strands}_{arch}_contacts_{args.contacts}.json")
    try:
        return _measure(args, res, frame, session, sim, groom, ti, out, viewer, bench)
    except SimulationDivergedError as exc:
        # A result too: written with what was measured before it.
        res["diverged"] = str(exc)
        bench.write(out, res, indent=1)
        print(f"DIVERGED: {exc}\nwrote {out}")
        return 1


def _measure(args, res, frame, session, sim, groom, ti, out, viewer, bench):
    with stopwatch(ti.sync) as sw:
        first = frame()
    res["first_frame_s"] = sw.seconds
    res["first_frame_split_ms"] = dict(zip(("simulation", "skinning", "drawing"), first))
    print(f"first frame (kernel compilation) {res['first_frame_s']:.1f} s: "
          + ", ".join(f"{k} {v / 1e3:.1f} s" for k, v in res["first_frame_split_ms"].items()), flush=True)
    frame()
    rows = []
    res["frames_measured"] = rows
    for i in range(args.frames):
        rows.append(frame())
        print(f"  frame {i}: simulation {rows[-1][0]:.0f} ms, skinning {rows[-1][1]:.0f} ms, "
              f"drawing {rows[-1][2]:.0f} ms", flush=True)
    a = np.array(rows)
    res["ms_per_frame"] = {k: {"mean": float(a[:, j].mean()), "min": float(a[:, j].min()),
                               "max": float(a[:, j].max())}
                           for j, k in enumerate(("simulation", "skinning", "drawing"))}
    res["ms_per_frame"]["simulation_plus_skinning"] = {"mean": float((a[:, 0] + a[:, 1]).mean())}
    if sim.solver.contacts is not None:
        res["contact_stats_last_frame"] = {k: (float(v) if isinstance(v, (int, float, np.number)) else str(v))
                                           for k, v in dict(sim.solver.contact_stats).items()}
    # What the measured frames are worth (GroomingSession.quality: strain, hair pairs, last step's move, worst step).
    q = res["quality"] = session.quality()
    print(f"quality after the measured frames: strain p99 {100 * q['strain_p99']:.4f} %, max {100 * q['strain_max']:.4f} %; "
          f"hair pairs p99 {1e6 * q.get('hair_penetration_p99_m', 0.0):.1f} um, max "
          f"{1e6 * q.get('hair_penetration_max_m', 0.0):.0f} um, {q.get('crossed_pairs', 0)} crossed (worst of "
          f"{q['steps']} steps {q['crossed_pairs_worst']}); largest move of the last step "
          f"{1e3 * q['max_step_motion_m']:.3f} mm; drift p90 {1e3 * q.get('drift_p90_m', 0.0):.3f} mm", flush=True)

    # An edit: grow 10 % of the strands; the next frame updates the Model in place.
    if args.edit == "spread":
        session.select_strands(np.arange(0, groom.strand_count, 10))
    else:
        roots = groom.points[groom.strand_offsets[:-1]]
        nearest = np.argsort(np.linalg.norm(roots - roots[0], axis=1), kind="stable")
        session.select_strands(np.sort(nearest[:groom.strand_count // 10]))
    res["edit_selection"] = args.edit
    res["load_average_at_edit"] = list(os.getloadavg())
    with stopwatch(ti.sync) as sw:
        session.scale_length(1.1)
    res["edit_scale_length_s"] = sw.seconds
    with stopwatch(ti.sync) as sw:
        session._ensure_built()
    res["in_place_update_s"] = sw.seconds
    after = frame()
    res["frame_after_edit_ms"] = dict(zip(("simulation", "skinning", "drawing"), after))
    res["rebuilds"], res["updates"] = session.rebuild_count, session.update_count
    print(f"edit: scale_length on {groom.strand_count // 10} strands {res['edit_scale_length_s']:.2f} s (host), "
          f"in-place update {res['in_place_update_s']:.2f} s, next frame " +
          ", ".join(f"{k} {v:.0f} ms" for k, v in res["frame_after_edit_ms"].items())
          + f" (load average {' '.join(f'{v:.2f}' for v in res['load_average_at_edit'])})", flush=True)
    m = res["ms_per_frame"]
    print(f"ms per frame (mean of {args.frames}): simulation {m['simulation']['mean']:.0f}, "
          f"skinning {m['skinning']['mean']:.0f}, drawing {m['drawing']['mean']:.0f}")
    bench.write(out, res, indent=1)
    print(f"wrote {out}")
    if viewer is not None:
        viewer.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
