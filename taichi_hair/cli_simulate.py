"""``taichi-hair simulate``: run a scene headless and write its frames."""

from __future__ import annotations

import csv
import json
import os
import sys
import time

import numpy as np

from .cli_common import CLIError, _add_common, _atomic_savez, _init_taichi


SCENES = ("hang", "hairball")


def _build_scene(args):
    """(model, solver config, colliders, rotation(t), scene description) for a named scene."""
    from . import SolverADMMConfig
    from .config import ContactConfig
    from .scenes import HairballScene, HangScene, build_hairball, build_hang, hairball_rotation, nod_rotation

    if args.scene == "hang":
        scene = HangScene(strands=args.strands, length=args.length if args.length else 0.2, seed=args.seed)
        cfg = SolverADMMConfig(iterations=args.iterations, mode="dynamic")
        return build_hang(scene), cfg, None, (lambda t: nod_rotation(scene, t)), scene
    from .colliders import SphereCollider

    scene = HairballScene(strands=args.strands, length=args.length if args.length else 0.30, seed=args.seed)
    contacts = ContactConfig(friction=scene.friction, projection_iterations=2, correction_iterations=10,
                             continuous_detections=args.continuous)
    cfg = SolverADMMConfig(iterations=args.iterations, mode="dynamic", contacts=contacts)
    ball = [SphereCollider(radius=scene.ball_radius, friction=scene.friction, body=0)]
    return build_hairball(scene), cfg, ball, hairball_rotation, scene


def cmd_simulate(args) -> int:
    if args.scene not in SCENES:
        raise CLIError(f"unknown scene {args.scene!r} (available: {', '.join(SCENES)})")
    ti, arch = _init_taichi(args.arch, args.precision)
    import resource

    from . import SimulationDivergedError, SolverADMM

    if args.frames < 1 or args.substeps < 1 or args.fps <= 0:
        raise CLIError("--frames and --substeps must be >= 1 and --fps > 0")
    try:
        t_build = time.perf_counter()
        model, cfg, colliders, rotation, scene = _build_scene(args)
    except ValueError as exc:
        raise CLIError(str(exc)) from None
    os.makedirs(args.out, exist_ok=True)
    dt = 1.0 / (args.fps * args.substeps)
    state, control = model.state(), model.control()
    solver = SolverADMM(model, cfg, profile=args.profile, colliders=colliders)
    t_build = time.perf_counter() - t_build
    # Compile every kernel on the real state (kernels are specialised per field), then restore it.
    t_compile = time.perf_counter()
    snapshot = state.to_numpy()
    solver.step(state, control, dt)
    state.load(snapshot)
    solver.reset_duals()
    solver.step_count = 0
    solver.stage_seconds = {k: 0.0 for k in solver.stage_seconds}
    t_compile = time.perf_counter() - t_compile
    with_contacts = solver.contacts is not None
    n = model.vertex_count
    frames = np.zeros((args.frames + 1, n, 3), np.float32)
    frames[0] = state.positions()
    rest_len = model.host["edge_rest_length"]
    real_edge = rest_len > 0
    mass = model.host["vertex_mass"]
    tips = model.host["strand_vertex_start"] + model.host["strand_vertex_count"] - 1
    stats_rows = []
    header = f"{'frame':>5} {'time s':>7} {'ms/frame':>9} {'max |v| m/s':>12} {'max stretch %':>13} " \
             f"{'mean tip y m':>12} {'kinetic J':>11}"
    if with_contacts:
        header += f" {'contacts':>9} {'stick':>7} {'slide':>7} {'max pen. um':>11}"
    if not args.quiet:
        print(f"{args.scene}: {model.strand_count} strands, {n} vertices, arch {arch}, {args.precision}, "
              f"{args.fps:g} fps x {args.substeps} substeps x {args.iterations} ADMM iterations "
              f"(set-up {t_build:.2f} s, kernel compilation {t_compile:.2f} s)")
        print(header)
    diverged = None
    t_all = time.perf_counter()
    completed = 0
    for f in range(1, args.frames + 1):
        t0 = time.perf_counter()
        try:
            for k in range(args.substeps):
                t = ((f - 1) * args.substeps + k + 1) * dt
                control.set_body_transform(0, rotation(t), (0.0, 0.0, 0.0))
                solver.step(state, control, dt)
        except SimulationDivergedError as exc:
            diverged = f"frame {f}: {exc}"
            break
        x = state.positions()
        v = state.vertex_velocity.to_numpy()
        ms = 1e3 * (time.perf_counter() - t0)
        e = np.linalg.norm(np.diff(x.astype(np.float64), axis=0, append=x[-1:]), axis=1)
        stretch = float(np.max(np.abs(e[real_edge] / rest_len[real_edge] - 1.0)))
        row = dict(frame=f, time=f / args.fps, ms=ms, max_speed=float(np.max(np.linalg.norm(v, axis=1))),
                   max_stretch_percent=100 * stretch, mean_tip_y=float(np.mean(x[tips, 1])),
                   kinetic=float(0.5 * np.sum(mass[:, None] * v.astype(np.float64) ** 2)))
        if with_contacts:
            cs = solver.contact_stats
            row.update(contacts=cs["contacts"], sticking=cs["sticking"], sliding=cs["sliding"],
                       max_penetration_m=cs["max_penetration_m"])
        stats_rows.append(row)
        frames[f] = x
        completed = f
        if not args.quiet:
            print(f"{f:5d} {row['time']:7.3f} {ms:9.1f} {row['max_speed']:12.4f} {row['max_stretch_percent']:13.4f} "
                  f"{row['mean_tip_y']:12.5f} {row['kinetic']:11.3e}"
                  + (f" {row['contacts']:9d} {row['sticking']:7d} {row['sliding']:7d} "
                     f"{1e6 * row['max_penetration_m']:11.2f}" if with_contacts else ""), flush=True)
    wall = time.perf_counter() - t_all
    out_npz = os.path.join(args.out, "frames.npz")
    _atomic_savez(out_npz, positions=frames[:completed + 1], fps=np.float64(args.fps),
                  strand_vertex_start=model.host["strand_vertex_start"],
                  strand_vertex_count=model.host["strand_vertex_count"],
                  sphere_radius=np.float64(getattr(scene, "sphere_radius", getattr(scene, "ball_radius", 0.0))))
    with open(os.path.join(args.out, "stats.csv"), "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(stats_rows[0].keys()) if stats_rows else ["frame"])
        w.writeheader()
        w.writerows(stats_rows)
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    summary = dict(scene=args.scene, strands=model.strand_count, vertices=n, frames=completed, arch=arch,
                   precision=args.precision, wall_seconds=wall, setup_seconds=t_build, compile_seconds=t_compile,
                   ms_per_frame=1e3 * wall / max(completed, 1), iterations=cfg.iterations, substeps=args.substeps,
                   mvertex_iterations_per_s=n * cfg.iterations * args.substeps * completed / max(wall, 1e-9) / 1e6,
                   peak_host_memory_mb=peak_mb, diverged=diverged)
    if with_contacts and stats_rows:
        summary["mean_contacts"] = float(np.mean([r["contacts"] for r in stats_rows]))
        summary["max_penetration_m"] = float(max(r["max_penetration_m"] for r in stats_rows))
    if args.profile:
        steps = max(solver.step_count, 1)
        summary["stage_ms_per_step"] = {k: 1e3 * v / steps for k, v in solver.stage_seconds.items() if v > 0}
        if not args.quiet:
            print("stage breakdown (ms per step): " + ", ".join(
                f"{k} {v:.2f}" for k, v in summary["stage_ms_per_step"].items()))
    with open(os.path.join(args.out, "summary.json"), "w") as fh:
        json.dump(summary, fh, indent=2)
    print(f"wrote {completed} frames of {n} vertices to {out_npz} "
          f"({1e3 * wall / max(completed, 1):.1f} ms/frame, {wall:.1f} s, "
          f"{summary['mvertex_iterations_per_s']:.2f} M vertex-iterations/s, peak memory {peak_mb:.0f} MB)")
    if diverged:
        print(f"error: simulation diverged at {diverged}; frames up to {completed} were kept", file=sys.stderr)
        return 1
    return 0



def register(sub) -> None:
    s = sub.add_parser("simulate", help="run a scene headless and write its frames")
    s.add_argument("scene", help="scene name: hang (strands hanging from a nodding sphere, no contacts) or "
                                 "hairball (Daviet 2023 Sec. 5.2, frictional contacts)")
    s.add_argument("--out", required=True, help="output folder (frames.npz, stats.csv, summary.json)")
    s.add_argument("--strands", type=int, default=300)
    s.add_argument("--length", type=float, default=None, help="strand length [m] (hang 0.2, hairball 0.3)")
    s.add_argument("--frames", type=int, default=48)
    s.add_argument("--fps", type=float, default=24.0)
    s.add_argument("--substeps", type=int, default=4)
    s.add_argument("--iterations", type=int, default=10, help="ADMM iterations per substep")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--continuous", type=int, default=0, metavar="N",
                   help="hairball: continuous-time collision detections per substep (paper's CT runs: 3; 0: "
                        "proximity only)")
    s.add_argument("--profile", action="store_true", help="time each stage of Algorithm 1 (synchronises after each)")
    _add_common(s)
    s.set_defaults(func=cmd_simulate)

