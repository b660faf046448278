"""The ``taichi-hair`` command line.

    taichi-hair simulate hang --strands 300 --frames 48 --out out/hang
    taichi-hair validate cantilever --out out/validation

Errors are one readable line on stderr and a non-zero exit code.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import sys
import time

import numpy as np


class CLIError(Exception):
    """A user-facing error: printed as one line, exit code 2."""


# --------------------------------------------------------------------------- helpers
def _init_taichi(arch: str, precision: str):
    import taichi as ti

    archs = {"cpu": ti.cpu, "cuda": ti.cuda, "gpu": ti.gpu, "vulkan": ti.vulkan}
    if arch not in archs:
        raise CLIError(f"--arch must be one of {sorted(archs)}, got {arch!r}")
    fp = {"f32": ti.f32, "f64": ti.f64}[precision]
    ti.init(arch=archs[arch], default_fp=fp, log_level=ti.WARN)
    used = str(ti.lang.impl.current_cfg().arch).split(".")[-1]
    return ti, used


def _atomic_savez(path: str, **arrays):
    tmp = path + ".tmp.npz"
    np.savez_compressed(tmp, **arrays)
    os.replace(tmp, path)


def _add_common(p):
    p.add_argument("--arch", default="cpu", help="Taichi arch: cpu (default), cuda, gpu, vulkan")
    p.add_argument("--precision", default="f32", choices=["f32", "f64"], help="floating point precision")
    p.add_argument("--quiet", action="store_true", help="print only the summary")


# --------------------------------------------------------------------------- simulate
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
    contacts = ContactConfig(friction=scene.friction, projection_iterations=2, correction_iterations=10)
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


# --------------------------------------------------------------------------- validate
def cmd_validate(args) -> int:
    if args.experiment not in ("cantilever", "stick-slip"):
        raise CLIError(f"unknown experiment {args.experiment!r} (available: cantilever, stick-slip)")
    ti, arch = _init_taichi(args.arch, args.precision)
    if args.experiment == "stick-slip":
        return _validate_stick_slip(args, arch)
    from .validation.cantilever import default_lengths, format_summary, run_cantilever, write_outputs

    if args.count < 2:
        raise CLIError("--count must be >= 2")

    def progress(it, change, err):
        if not args.quiet:
            print(f"  {it:6d} iterations: max change of H/W over the last chunk {change:.2e}, "
                  f"max |error| {100 * err:.2f}%", flush=True)

    if not args.quiet:
        print(f"cantilever: {args.count} rods from 0.5 cm to 128 cm, quasistatic ADMM, w0 = {args.w0:g}, "
              f"arch {arch}, {args.precision}")
    result = run_cantilever(default_lengths(args.count), w0=args.w0, max_iterations=args.max_iterations,
                            progress=progress, voronoi_rescaling=not args.no_voronoi_rescaling,
                            strain_measure=args.strain_measure)
    csv_path, png_path = write_outputs(result, args.out)
    print(format_summary(result))
    print(f"wrote {csv_path} and {png_path}")
    if result.max_abs_rel_error > args.tolerance:
        print(f"error: max relative error {100 * result.max_abs_rel_error:.2f}% exceeds the tolerance "
              f"{100 * args.tolerance:.2f}%", file=sys.stderr)
        return 1
    return 0


def _validate_stick_slip(args, arch) -> int:
    from .validation.stick_slip import format_summary, run_stick_slip, write_outputs

    def progress(j, d, n):
        if not args.quiet:
            print(f"  substep {j:4d}: clamp displacement {d:.3f} L, {n} rods have slid", flush=True)

    if not args.quiet:
        print(f"stick-slip: 13 friction coefficients 0..0.6, 800 quasistatic substeps to 0.6 L, arch {arch}, "
              f"{args.precision}")
    result = run_stick_slip(substeps=args.substeps, progress=progress)
    csv_path, png_path = write_outputs(result, args.out)
    print(format_summary(result))
    print(f"wrote {csv_path} and {png_path}")
    return 0


# --------------------------------------------------------------------------- main
def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="taichi-hair", description="Hair simulation on Taichi (Daviet 2023 ADMM).")
    sub = p.add_subparsers(dest="command", required=True)

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
    s.add_argument("--profile", action="store_true", help="time each stage of Algorithm 1 (synchronises after each)")
    _add_common(s)
    s.set_defaults(func=cmd_simulate)

    v = sub.add_parser("validate", help="validation experiments (Daviet 2023 Sec. 5.1)")
    v.add_argument("experiment", help="experiment name: cantilever or stick-slip")
    v.add_argument("--out", required=True, help="output folder")
    v.add_argument("--count", type=int, default=100, help="number of rod lengths")
    v.add_argument("--w0", type=float, default=0.2, help="ADMM weight scale for the quasistatic solve")
    v.add_argument("--max-iterations", type=int, default=20000)
    v.add_argument("--tolerance", type=float, default=0.02, help="max relative error accepted (exit 1 above)")
    v.add_argument("--strain-measure", default="korner", choices=["korner", "bergou"])
    v.add_argument("--no-voronoi-rescaling", action="store_true", help="disable the Sec. 5.1 boundary rescaling")
    v.add_argument("--substeps", type=int, default=800, help="stick-slip: quasistatic substeps to 0.6 L")
    _add_common(v)
    v.set_defaults(func=cmd_validate)

    from .io.cli import register as register_io

    register_io(sub)
    return p


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except CLIError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except (ValueError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except RuntimeError as exc:  # SimulationDivergedError and Taichi runtime failures
        print(f"error: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
