"""``taichi-hair simulate``: run a scene headless and write its frames.

    taichi-hair simulate hang --strands 300 --frames 48 --out out/hang
    taichi-hair simulate assets/scenes/head_turn.toml --out out/head_turn.usd
    taichi-hair simulate assets/scenes/hairball.toml --out out/hb --frames 96 --resume

SCENE is a built-in name (``hang``, ``hairball``) or a TOML scene file (:mod:`taichi_hair.scene.file`).
The output is chosen by the name given to ``--out``:

- ``*.usd``, ``*.usda``, ``*.usdc``: one USD BasisCurves prim with time-sampled points (one time code
  per frame, ``timeCodesPerSecond`` = fps), written at the end;
- ``*.thair.npz`` or ``*.npz``: the native groom format with every frame in ``point_frames``;
- anything else: a folder with ``frames.npz`` (positions of every frame), ``frames/frame_NNNNN.<ext>``
  (one groom file per frame, written as it completes; ``--frame-format``), ``stats.csv`` and
  ``summary.json``.

For a file output the statistics, summary and checkpoint sit beside it: ``<name>.stats.csv``,
``<name>.summary.json``, ``<name>.checkpoint.npz``.  Checkpoints (:mod:`taichi_hair.checkpoint`, ADMM
solver only) are written every ``--checkpoint-every`` frames and at the end; ``--resume`` continues from
the last one and gives the same frames, bit for bit, as a run that never stopped (and refuses a
checkpoint made for another scene or other settings).

Model no more than the scene needs (README, "Model no more than a scene needs"): the run prints, and writes into the
summary under ``model``, what the solver chose to model and to skip.  ``--equilibrium`` asks for the rest
shape only: quasistatic steps (ADMM) until the largest displacement per step is below
``--equilibrium-tolerance``, written as frame 1.  ``--max-error E`` (a fraction of the strand length) or
``--budget-ms T`` (wall milliseconds per frame) picks the method and its knobs from the measured
speed/accuracy data (``taichi-hair bench pareto``; ``--pareto-data`` reads a re-measured ``pareto.csv``).

Every run measures its own quality (:mod:`taichi_hair.quality`, any solver): per frame, ``stats.csv`` has the
edge strain p50/p99/max, the penetration p99/max of free vertices into each body's true surface (exact
triangle distance and winding number for meshes), the vertices deeper than 0.5 mm inside a body, the largest
vertex speed and, when the ADMM solver reports them, its hair-hair penetration figures; ``summary.json`` has
the worst frame of each under ``quality`` and whether the run came to rest (``--equilibrium``: converged;
otherwise: no vertex faster than 1 cm/s in the last frame).  A run whose p99 strain passes 5 % or that
leaves vertices inside a body ends with a ``warning:`` line naming the worst strand; ``--strict`` makes it
exit with status 3.  Exit status: 0 ok, 1 diverged (or no equilibrium), 2 bad input, 3 ``--strict`` failure.
"""

from __future__ import annotations

import csv
import json
import os
import sys
import time

import numpy as np

from .common import CLIError, _add_common, _atomic_savez, _init_taichi

SCENES = ("hang", "hairball")
#: Defaults of the built-in scenes (a TOML scene's own values win unless a flag is given).
NAMED_DEFAULTS = dict(strands=300, frames=48, fps=24.0, substeps=4, iterations=10, seed=0)
USD_EXTENSIONS = (".usd", ".usda", ".usdc")


# --------------------------------------------------------------------------- scenes
def _named_scene(args):
    """The built-in scenes as :class:`~taichi_hair.scene.file.Scene` objects (their own builders)."""
    if args.vertices_per_strand is not None:
        raise CLIError(f"--vertices-per-strand applies to TOML scenes with a generated groom, not {args.scene!r} "
                       "(use --length)")
    from ..config import ContactConfig, SolverADMMConfig
    from ..scene.file import BodyAnimation, Scene
    from ..scene.builtin import HairballScene, HangScene, build_hairball, build_hang, hairball_rotation, nod_rotation

    d = {k: (getattr(args, k) if getattr(args, k) is not None else v) for k, v in NAMED_DEFAULTS.items()}
    iterations = d["iterations"]
    integ = dict(integrator=args.integrator) if args.integrator else {}
    if args.scene == "hang":
        hs = HangScene(strands=d["strands"], length=args.length if args.length else 0.2, seed=d["seed"])
        cfg = SolverADMMConfig(iterations=iterations, mode="dynamic", **integ)
        colliders = []
        body = BodyAnimation(function=lambda t: nod_rotation(hs, t), description={"preset": "hang-nod"})
        builder = (lambda: build_hang(hs))
        scene_desc = dict(vars(hs))
    else:
        hs = HairballScene(strands=d["strands"], length=args.length if args.length else 0.30, seed=d["seed"])
        contacts = ContactConfig(friction=hs.friction, projection_iterations=2, correction_iterations=10,
                                 continuous_detections=args.continuous or 0)
        cfg = SolverADMMConfig(iterations=iterations, mode="dynamic", contacts=contacts, **integ)
        from ..contact.colliders import SphereCollider

        colliders = [SphereCollider(radius=hs.ball_radius, friction=hs.friction, body=0)]
        body = BodyAnimation(function=hairball_rotation, description={"preset": "hairball"})
        builder = (lambda: build_hairball(hs))
        scene_desc = dict(vars(hs), continuous=args.continuous or 0)
    desc = {"name": args.scene, "params": scene_desc, "iterations": iterations, "fps": d["fps"],
            "substeps": d["substeps"], **integ}
    return Scene(name=args.scene, path="", frames=d["frames"], fps=d["fps"], substeps=d["substeps"],
                 gravity=(0.0, -9.81, 0.0), groom=None, solver="admm", solver_config=cfg, colliders=colliders,
                 bodies=[body], description=desc, model_builder=builder)


def _load_scene(args):
    if args.scene in SCENES:
        return _named_scene(args)
    if not args.scene.lower().endswith(".toml"):
        raise CLIError(f"unknown scene {args.scene!r} (available: {', '.join(SCENES)}, or a .toml scene file)")
    if not os.path.isfile(args.scene):
        raise CLIError(f"{args.scene}: no such scene file")
    from ..scene.file import load_scene

    over = dict(frames=args.frames, fps=args.fps, substeps=args.substeps, strands=args.strands,
                length=args.length, seed=args.seed, iterations=args.iterations, continuous=args.continuous,
                vertices_per_strand=args.vertices_per_strand, integrator=args.integrator)
    return load_scene(args.scene, over)


# --------------------------------------------------------------------------- output
def _output_layout(out: str) -> dict:
    """Where each output goes, by the extension of ``out``."""
    low = out.lower()
    if low.endswith(USD_EXTENSIONS):
        kind, base = "usd", os.path.splitext(out)[0]
    elif low.endswith(".npz"):
        kind, base = "native", out[: -len(".thair.npz")] if low.endswith(".thair.npz") else out[:-4]
    else:
        kind = "folder"
    if kind == "folder":
        return dict(kind=kind, dir=out, frames_npz=os.path.join(out, "frames.npz"),
                    frame_dir=os.path.join(out, "frames"), stats=os.path.join(out, "stats.csv"),
                    summary=os.path.join(out, "summary.json"), checkpoint=os.path.join(out, "checkpoint.npz"))
    return dict(kind=kind, dir=os.path.dirname(os.path.abspath(out)), file=out, stats=base + ".stats.csv",
                summary=base + ".summary.json", checkpoint=base + ".checkpoint.npz")


def _frame_groom(model, positions, radius, fps, frames=None):
    from ..io.groom import Groom

    h = model.host
    off = np.r_[h["strand_vertex_start"], h["strand_vertex_start"][-1] + h["strand_vertex_count"][-1]]
    g = Groom(points=np.ascontiguousarray(positions if frames is None else frames[0]),
              strand_offsets=off.astype(np.int64), radius=radius, units="m",
              params={"fps": float(fps), "usd_time_codes_per_second": float(fps)})
    if frames is not None:
        g.point_frames = np.ascontiguousarray(frames)
        g.frame_times = np.arange(frames.shape[0], dtype=np.float64)
    return g.validate()


def _atomic_text(path: str, write) -> None:
    tmp = path + ".tmp"
    with open(tmp, "w", newline="") as fh:
        write(fh)
    os.replace(tmp, path)


# --------------------------------------------------------------------------- the command
def _load_scene_reporting(args):
    """The scene, with every warning raised while reading it (units of the groom, a mesh with holes,
    skipped strands) printed as one ``warning:`` line on stderr and returned for the summary."""
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scene = _load_scene(args)
    lines = []
    for w in caught:
        text = str(w.message)
        if text not in lines:
            lines.append(text)
            print(f"warning: {text}", file=sys.stderr)
    return scene, lines


def cmd_simulate(args) -> int:
    scene, load_warnings = _load_scene_reporting(args)  # before ti.init: scene errors cost no start-up
    _check_model_options(args, scene)
    out = args.out or scene.output
    if not out:
        raise CLIError("--out is required (the scene file names no [scene] output)")
    if args.checkpoint_every < 0:
        raise CLIError("--checkpoint-every must be >= 0 (0: no checkpoints)")
    if scene.frames < 1 or scene.substeps < 1 or not scene.fps > 0:
        raise CLIError("--frames and --substeps must be >= 1 and --fps > 0")
    layout = _output_layout(out)
    if args.frame_format:
        from ..io import WRITERS, normalize_format

        fmt = normalize_format(args.frame_format)
        if fmt not in WRITERS:
            raise CLIError(f"--frame-format {args.frame_format!r} is read-only; writable: {', '.join(WRITERS)}")
        if layout["kind"] != "folder":
            raise CLIError("--frame-format applies to a folder output")
    if layout["kind"] == "usd":
        from ..io.usd import _pxr

        try:
            _pxr()
        except Exception as exc:  # noqa: BLE001 - an ImportError with install advice
            raise CLIError(f"{out}: USD output needs usd-core ({exc})") from None
    ti, arch = _init_taichi(args.arch, args.precision)
    import resource

    from .. import SimulationDivergedError

    # Refuse a checkpoint made for another scene before anything is built or compiled.
    fingerprint = {"scene": scene.description, "arch": arch, "precision": args.precision,
                   "dt": 1.0 / (scene.fps * scene.substeps), "solver": scene.solver, "version": 1,
                   "choice": {"max_error": args.max_error, "budget_ms": args.budget_ms,
                              "data": args.pareto_data}}
    fingerprint = json.loads(json.dumps(fingerprint, default=str))
    ckpt = None
    if args.resume:
        if scene.solver != "admm":
            raise CLIError(f"--resume needs the admm solver (this scene uses {scene.solver!r}, which has no "
                           "checkpoints)")
        if os.path.exists(layout["checkpoint"]):
            from ..checkpoint import fingerprint_difference, read_checkpoint

            ckpt = read_checkpoint(layout["checkpoint"])
            diff = fingerprint_difference(ckpt["fingerprint"], fingerprint)
            if diff:
                raise CLIError(f"{layout['checkpoint']}: made for a different scene or settings (differs in "
                               f"{diff}); remove it or drop --resume")
        elif not args.quiet:
            print(f"note: no checkpoint at {layout['checkpoint']}; starting from frame 0", file=sys.stderr)
    t_build = time.perf_counter()
    model = scene.build_model()
    choice = _apply_method_choice(args, scene, model)
    dt = 1.0 / (scene.fps * scene.substeps)
    state, control = model.state(), model.control()
    control.gravity = tuple(scene.gravity)
    solver = scene.make_solver(model, profile=args.profile)
    admm = scene.solver == "admm"
    t_build = time.perf_counter() - t_build

    def set_bodies(t):
        for b, (R, T) in enumerate(scene.body_transforms(t)):
            control.set_body_transform(b, R, T)

    set_bodies(0.0)
    # Compile every kernel on the real state (kernels are specialised per field), then restore it.
    t_compile = time.perf_counter()
    diverged = None
    if admm:
        snapshot = state.to_numpy()
        try:
            # BDF2: the first step is backward Euler (no history), the second compiles the BDF2 kernels.
            for _ in range(2 if getattr(scene.solver_config, "integrator", "") == "bdf2" else 1):
                solver.step(state, control, dt)
        except SimulationDivergedError as exc:
            diverged = f"frame 1: {exc}"
        state.load(snapshot)
        solver.reset_duals()
        solver.step_count = 0
        solver.iteration_count = 0
        solver.stage_seconds = {k: 0.0 for k in solver.stage_seconds}
    t_compile = time.perf_counter() - t_compile
    with_contacts = getattr(solver, "contacts", None) is not None
    n = model.vertex_count
    frames = np.zeros((scene.frames + 1, n, 3), np.float32 if args.precision == "f32" else np.float64)
    frames[0] = state.positions()
    stats_rows = []
    start = 0
    if ckpt is not None:
        state.load(ckpt["state"])
        solver.restore(ckpt["solver"])
        start = min(ckpt["frame"], scene.frames)
        frames[:start + 1] = ckpt["frame_positions"][:start + 1]
        stats_rows = [r for r in ckpt["stats"] if r["frame"] <= start]
    radius = np.asarray(model.host["strand_radius"], np.float32) if "strand_radius" in model.host else None
    if radius is not None and radius.shape != (model.strand_count,):
        radius = None
    if layout["kind"] == "folder":
        os.makedirs(layout["frame_dir"], exist_ok=True)
    else:
        os.makedirs(layout["dir"], exist_ok=True)
    frame_ext = {"thair": ".thair.npz", "usd": ".usdc"}.get(args.frame_format or "thair",
                                                              "." + (args.frame_format or "thair"))

    def write_frame_file(f):
        if layout["kind"] != "folder":
            return
        from ..io import save_groom

        save_groom(_frame_groom(model, frames[f], radius, scene.fps),
                   os.path.join(layout["frame_dir"], f"frame_{f:05d}{frame_ext}"),
                   format=args.frame_format or "thair")

    if start == 0:
        write_frame_file(0)
    rest_len = model.host["edge_rest_length"]
    real_edge = rest_len > 0
    mass = model.host["vertex_mass"]
    tips = model.host["strand_vertex_start"] + model.host["strand_vertex_count"] - 1
    header = f"{'frame':>5} {'time s':>7} {'ms/frame':>9} {'max |v| m/s':>12} {'max stretch %':>13} " \
             f"{'p99 strain %':>12} {'mean tip y m':>12} {'kinetic J':>11}"
    if scene.colliders:
        header += f" {'inside':>7} {'max depth mm':>12}"
    if with_contacts:
        header += f" {'contacts':>9} {'stick':>7} {'slide':>7} {'max pen. um':>11}"
    from ..progress import Progress

    bar = Progress(scene.frames, initial=start, label="frames", enabled=not args.quiet)
    if not args.quiet:
        iters = getattr(scene.solver_config, "iterations", None)
        print(f"{scene.name}: {model.strand_count} strands, {n} vertices, solver {scene.solver}, arch {arch}, "
              f"{args.precision}, {scene.fps:g} fps x {scene.substeps} substeps"
              + (f" x {iters} iterations" if iters else "")
              + f" (set-up {t_build:.2f} s, kernel compilation {t_compile:.2f} s)"
              + (f"; resuming after frame {start}" if start else ""))
        for line in _model_lines(solver, choice):
            print("model: " + line)
        print(header)

    def checkpoint(f):
        from ..checkpoint import write_checkpoint

        write_checkpoint(layout["checkpoint"], state.to_numpy(), solver.checkpoint(), f, frames[:f + 1],
                         stats_rows, fingerprint)

    eq = None
    t_all = time.perf_counter()
    completed = start
    for f in range(start + 1, scene.frames + 1 if diverged is None else start + 1):
        t0 = time.perf_counter()
        try:
            if args.equilibrium:
                from ..solvers.equilibrium import equilibrium

                eq = equilibrium(solver, state, control, args.equilibrium_tolerance, args.max_steps, dt,
                                 callback=lambda k, d: bar.update(0, step=k, displacement=f"{d:.2e}"))
            else:
                for k in range(scene.substeps):
                    set_bodies(((f - 1) * scene.substeps + k + 1) * dt)
                    solver.step(state, control, dt)
        except SimulationDivergedError as exc:
            diverged = f"frame {f}: {exc}"
            break
        x = state.positions()
        v = state.vertex_velocity.to_numpy()
        ms = 1e3 * (time.perf_counter() - t0)
        e = np.linalg.norm(np.diff(x.astype(np.float64), axis=0, append=x[-1:]), axis=1)
        stretch = float(np.max(np.abs(e[real_edge] / rest_len[real_edge] - 1.0)))
        row = dict(frame=f, time=f / scene.fps, ms=ms, max_speed=float(np.max(np.linalg.norm(v, axis=1))),
                   max_stretch_percent=100 * stretch, mean_tip_y=float(np.mean(x[tips, 1])),
                   kinetic=float(0.5 * np.sum(mass[:, None] * v.astype(np.float64) ** 2)))
        if with_contacts:
            cs = solver.contact_stats
            row.update(contacts=int(cs["contacts"]), sticking=int(cs["sticking"]), sliding=int(cs["sliding"]),
                       max_penetration_m=float(cs["max_penetration_m"]))
        row.update(_frame_quality(model, scene, control, x, v, getattr(solver, "contact_stats", None)))
        stats_rows.append(row)
        frames[f] = x
        completed = f
        write_frame_file(f)
        if admm and args.checkpoint_every and not args.equilibrium and (f % args.checkpoint_every == 0
                                                                        or f == scene.frames):
            checkpoint(f)
        if not args.quiet:
            bar.write(f"{f:5d} {row['time']:7.3f} {ms:9.1f} {row['max_speed']:12.4f} "
                      f"{row['max_stretch_percent']:13.4f} {100 * row['strain_p99']:12.4f} "
                      f"{row['mean_tip_y']:12.5f} {row['kinetic']:11.3e}"
                      + (f" {row['vertices_inside']:7d} {1e3 * row['body_penetration_max_m']:12.3f}"
                         if scene.colliders else "")
                      + (f" {row['contacts']:9d} {row['sticking']:7d} {row['sliding']:7d} "
                         f"{1e6 * row['max_penetration_m']:11.2f}" if with_contacts else ""))
        bar.update(f, **{"p99 strain %": f"{100 * row['strain_p99']:.2f}"},
                   **({"contacts": row["contacts"]} if with_contacts else {}))
    bar.close()
    wall = time.perf_counter() - t_all
    run_frames = completed - start
    if layout["kind"] == "folder":
        written = layout["frames_npz"]
        _atomic_savez(written, positions=frames[:completed + 1], fps=np.float64(scene.fps),
                      strand_vertex_start=model.host["strand_vertex_start"],
                      strand_vertex_count=model.host["strand_vertex_count"],
                      sphere_radius=np.float64(scene.description.get("params", {}).get(
                          "sphere_radius", scene.description.get("params", {}).get("ball_radius", 0.0))))
    else:
        from ..io import save_groom

        written = layout["file"]
        save_groom(_frame_groom(model, None, radius, scene.fps, frames[:completed + 1]), written,
                   format="usd" if layout["kind"] == "usd" else "thair")

    def write_stats(fh):
        keys = list(dict.fromkeys(k for r in stats_rows for k in r)) if stats_rows else ["frame"]
        w = csv.DictWriter(fh, fieldnames=keys, restval="")
        w.writeheader()
        w.writerows(stats_rows)

    _atomic_text(layout["stats"], write_stats)
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    iters = getattr(scene.solver_config, "iterations", 1)
    summary = dict(scene=scene.name, scene_file=scene.path or None, solver=scene.solver,
                   strands=model.strand_count, vertices=n, frames=completed, resumed_from_frame=start or None,
                   arch=arch, precision=args.precision, output=written, wall_seconds=wall, setup_seconds=t_build,
                   compile_seconds=t_compile, ms_per_frame=1e3 * wall / max(run_frames, 1), iterations=iters,
                   substeps=scene.substeps,
                   mvertex_iterations_per_s=n * (eq.iterations if eq is not None else iters * scene.substeps
                                                 * run_frames) / max(wall, 1e-9) / 1e6,
                   peak_host_memory_mb=peak_mb, diverged=diverged,
                   load_average_1min_at_end=os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
                   cpu_count=os.cpu_count())
    summary["model"] = dict(_model_report(solver), **({"method_choice": choice.description} if choice else {}))
    if choice is not None:
        summary["method_choice"] = dict(method=choice.point.method, dt=choice.point.dt,
                                        iterations=choice.point.iterations, substeps=choice.point.substeps,
                                        shape_method=choice.point.shape_method, stand_in=choice.stand_in,
                                        measured_error=choice.point.error,
                                        estimated_ms_per_frame=choice.estimated_ms_per_frame)
    if eq is not None:
        summary["equilibrium"] = dict(converged=eq.converged, steps=eq.steps, iterations=eq.iterations,
                                      last_displacement_m=eq.last_displacement,
                                      estimated_distance_m=eq.estimated_distance,
                                      tolerance_m=args.equilibrium_tolerance)
    if with_contacts and stats_rows:
        summary["mean_contacts"] = float(np.mean([r["contacts"] for r in stats_rows]))
        summary["max_penetration_m"] = float(max(r["max_penetration_m"] for r in stats_rows))
    summary["quality"] = _run_quality(stats_rows, eq)
    summary["warnings"] = load_warnings
    if args.profile and not hasattr(solver, "stage_seconds"):
        print(f"note: --profile: solver {scene.solver!r} has no stage timers", file=sys.stderr)
    elif args.profile:
        steps = max(solver.step_count, 1)
        summary["stage_ms_per_step"] = {k: 1e3 * v / steps for k, v in solver.stage_seconds.items() if v > 0}
        if not args.quiet:
            print("stage breakdown (ms per step): " + ", ".join(
                f"{k} {v:.2f}" for k, v in summary["stage_ms_per_step"].items()))
    _atomic_text(layout["summary"], lambda fh: json.dump(summary, fh, indent=2))
    print(f"wrote {completed} frames of {n} vertices to {written} "
          f"({1e3 * wall / max(run_frames, 1):.1f} ms/frame over {run_frames} frames run, {wall:.1f} s, "
          f"{summary['mvertex_iterations_per_s']:.2f} M vertex-iterations/s, peak memory {peak_mb:.0f} MB"
          + (f", mean contacts {summary['mean_contacts']:.0f}" if "mean_contacts" in summary else "") + ")")
    if diverged:
        print(f"error: simulation diverged at {diverged}; frames up to {completed} were kept", file=sys.stderr)
        if completed <= 1:
            print(f"note: {_groom_size_note(scene, model)}", file=sys.stderr)
        return 1
    failed = _quality_lines(summary["quality"])
    for line in failed if not args.strict else ():
        print(f"warning: {line}", file=sys.stderr)
    if eq is not None:
        if not eq.converged:
            print(f"error: no equilibrium within {eq.steps} quasistatic steps (the last moved a vertex by "
                  f"{eq.last_displacement:.3g} m, estimated distance left {eq.estimated_distance:.3g} m, tolerance "
                  f"{args.equilibrium_tolerance:g} m); the last state was written", file=sys.stderr)
            return 1
        print(f"equilibrium after {eq.steps} quasistatic steps ({eq.iterations} iterations; last displacement "
              f"{eq.last_displacement:.3g} m, estimated distance left {eq.estimated_distance:.3g} m)")
    if failed and args.strict:
        print(f"error: --strict: {'; '.join(failed)}", file=sys.stderr)
        return 3
    return 0


# --------------------------------------------------------------------------- quality (taichi_hair.quality)
def _frame_quality(model, scene, control, x, v, contact_stats) -> dict:
    """This frame's figures of :func:`taichi_hair.quality.frame_quality`, as stats.csv columns."""
    from ..quality import frame_quality

    rot = control.body_rotation.to_numpy() if scene.colliders else None
    tr = control.body_translation.to_numpy() if scene.colliders else None
    q = frame_quality(x, v, model.host, scene.colliders, rot, tr, contact_stats)
    q.pop("max_speed_m_s")  # the row has it as max_speed
    return q


def _run_quality(rows, eq) -> dict:
    """The run's quality for summary.json: the worst frame of each figure and the last frame's rest."""
    from ..quality import HAIR_KEYS, INSIDE_TOLERANCE_M, REST_SPEED_M_S, STRAIN_WARNING

    rows = [r for r in rows if "strain_p99" in r]
    if not rows:
        return {}
    worst = max(rows, key=lambda r: r["strain_p99"])
    q = dict(strain_warning=STRAIN_WARNING, inside_tolerance_m=INSIDE_TOLERANCE_M,
             strain_p50_max=max(r["strain_p50"] for r in rows), strain_p99_max=worst["strain_p99"],
             strain_p99_worst_frame=worst["frame"], strain_max=max(r["strain_max"] for r in rows),
             strain_worst_strand=worst["strain_worst_strand"], strain_p99_last=rows[-1]["strain_p99"])
    if "vertices_inside" in rows[-1]:
        deep = max(rows, key=lambda r: (r["vertices_inside"], r["body_penetration_max_m"]))
        q.update(body_penetration_p99_max_m=max(r["body_penetration_p99_m"] for r in rows),
                 body_penetration_max_m=max(r["body_penetration_max_m"] for r in rows),
                 vertices_inside_max=deep["vertices_inside"], vertices_inside_worst_frame=deep["frame"],
                 penetration_worst_strand=deep["penetration_worst_strand"],
                 vertices_inside_last=rows[-1]["vertices_inside"])
    for key in HAIR_KEYS:
        vals = [r[key] for r in rows if r.get(key) is not None]
        if vals:
            q[key + "_max"] = max(vals)
    last = rows[-1]["max_speed"]
    if eq is not None:
        q.update(rest_asked=True, came_to_rest=bool(eq.converged), rest_criterion="--equilibrium-tolerance")
    else:
        q.update(rest_asked=False, came_to_rest=bool(last < REST_SPEED_M_S),
                 rest_criterion=f"max vertex speed in the last frame < {REST_SPEED_M_S:g} m/s")
    q["last_frame_max_speed_m_s"] = last
    return q


def _quality_lines(q) -> list:
    """The run's failed quality figures, one line each (strain above 5 %, vertices left inside a body)."""
    lines = []
    if not q:
        return lines
    if q["strain_p99_max"] > q["strain_warning"]:
        lines.append(f"p99 edge strain reached {100 * q['strain_p99_max']:.2f} % at frame "
                     f"{q['strain_p99_worst_frame']} (above {100 * q['strain_warning']:g} %; worst strand "
                     f"{q['strain_worst_strand']}, max {100 * q['strain_max']:.2f} %)")
    if q.get("vertices_inside_max", 0) > 0:
        lines.append(f"{q['vertices_inside_max']} vertices deeper than {1e3 * q['inside_tolerance_m']:g} mm "
                     f"inside a body at frame {q['vertices_inside_worst_frame']} (worst strand "
                     f"{q['penetration_worst_strand']}, deepest {1e3 * q['body_penetration_max_m']:.2f} mm)")
    return lines


def _groom_size_note(scene, model) -> str:
    """Whether the groom's size looked wrong (a run that diverged at once)."""
    from ..io import Groom, describe_groom_size

    h = model.host
    off = np.r_[h["strand_vertex_start"], h["strand_vertex_start"][-1] + h["strand_vertex_count"][-1]]
    g = scene.groom if scene.groom is not None else Groom(points=np.asarray(h["vertex_rest_position"]),
                                                          strand_offsets=off.astype(np.int64))
    return describe_groom_size(g)


# --------------------------------------------------------------------------- model choices
def _check_model_options(args, scene) -> None:
    """Refuse combinations of --equilibrium / --max-error / --budget-ms that have no meaning."""
    if args.max_error is not None and args.budget_ms is not None:
        raise CLIError("give one of --max-error and --budget-ms, not both")
    if args.max_error is not None and not args.max_error > 0:
        raise CLIError(f"--max-error must be a positive fraction of the strand length, got {args.max_error:g}")
    if args.budget_ms is not None and not args.budget_ms > 0:
        raise CLIError(f"--budget-ms must be a positive number of milliseconds per frame, got {args.budget_ms:g}")
    if args.pareto_data is not None and args.max_error is None and args.budget_ms is None:
        raise CLIError("--pareto-data is read by --max-error or --budget-ms; give one of them")
    if args.pareto_data is not None and not os.path.isfile(args.pareto_data):
        raise CLIError(f"{args.pareto_data}: no such file (a pareto.csv written by taichi-hair bench pareto)")
    if args.equilibrium:
        if args.max_error is not None or args.budget_ms is not None:
            raise CLIError("--equilibrium runs the quasistatic ADMM solver; the speed/accuracy data are for "
                           "dynamic runs (drop --max-error/--budget-ms)")
        if scene.solver != "admm":
            raise CLIError(f"--equilibrium needs the admm solver (the scene uses {scene.solver!r}, which has no "
                           "quasistatic mode)")
        if args.resume:
            raise CLIError("--equilibrium writes one frame; --resume does not apply")
        if not args.equilibrium_tolerance > 0:
            raise CLIError(f"--equilibrium-tolerance must be a positive length [m], got {args.equilibrium_tolerance:g}")
        if args.max_steps < 1:
            raise CLIError(f"--max-steps must be >= 1, got {args.max_steps}")
        from dataclasses import replace

        # w0 = 1: the paper's 25 converges far more slowly in the quasistatic mode (solvers/equilibrium.py).
        scene.solver_config = replace(scene.solver_config, mode="quasistatic", w0=1.0)
        scene.frames = 1
        scene.description = dict(scene.description, equilibrium=args.equilibrium_tolerance)


def _apply_method_choice(args, scene, model):
    """--max-error / --budget-ms: the measured setting for this scene, applied to ``scene`` (solver, config,
    substeps); ``None`` without those options."""
    if args.max_error is None and args.budget_ms is None:
        return None
    from ..bench.pareto import load_shipped, read_csv
    from ..bench.choice import choose_for_scene, solver_config_for

    try:
        points = read_csv(args.pareto_data) if args.pareto_data else load_shipped()
    except (KeyError, ValueError, OSError) as exc:
        raise CLIError(f"{args.pareto_data or 'shipped Pareto data'}: not a pareto.csv of taichi-hair bench pareto "
                       f"({type(exc).__name__}: {exc})") from None
    cfg = scene.solver_config if scene.solver == "admm" else None
    hair_hair = cfg is not None and cfg.contacts is not None and cfg.contacts.hair_hair
    try:
        choice = choose_for_scene(points, model.strand_count, model.vertex_count, scene.fps, args.precision,
                                  hair_hair=hair_hair, colliders=bool(scene.colliders), max_error=args.max_error,
                                  budget_ms=args.budget_ms)
    except ValueError as exc:
        raise CLIError(f"{'--max-error' if args.max_error is not None else '--budget-ms'}: {exc}") from None
    scene.solver_config = solver_config_for(choice, cfg)
    scene.solver = choice.solver
    scene.substeps = choice.substeps
    return choice


def _model_report(solver) -> dict:
    if hasattr(solver, "model_report"):
        return solver.model_report()
    return {"solver": f"{type(solver).__name__}: no model simplification"}


def _model_lines(solver, choice) -> list:
    lines = [f"{k}: {v}" for k, v in _model_report(solver).items()]
    if choice is not None:
        lines.append(choice.description)
    return lines


def register(sub) -> None:
    s = sub.add_parser("simulate", help="run a scene headless and write its frames",
                       description="Run a scene headless. SCENE: hang, hairball, or a .toml scene file. The "
                                   "output is a USD file (.usd/.usda/.usdc, time samples), a native groom "
                                   "(.thair.npz, every frame) or a folder (per-frame files).")
    s.add_argument("scene", help="scene: hang (strands hanging from a nodding sphere, no contacts), hairball "
                                 "(Daviet 2023 Sec. 5.2, frictional contacts) or a .toml scene file")
    s.add_argument("--out", default=None,
                   help="output: a .usd/.usda/.usdc file, a .thair.npz file, or a folder (frames.npz, "
                        "frames/, stats.csv, summary.json); default: the scene file's [scene] output")
    s.add_argument("--strands", type=int, default=None,
                   help="strands (built-in scenes: 300; a TOML scene: its generator's count, or this many "
                        "strands kept from its groom file)")
    s.add_argument("--length", type=float, default=None,
                   help="strand length [m] (hang 0.2, hairball 0.3; a TOML scene: its generator's mean length)")
    s.add_argument("--frames", type=int, default=None, help="frames to simulate (default 48 or the scene's)")
    s.add_argument("--fps", type=float, default=None, help="frames per second (default 24 or the scene's)")
    s.add_argument("--substeps", type=int, default=None, help="solver steps per frame (default 4 or the scene's)")
    s.add_argument("--iterations", type=int, default=None,
                   help="solver iterations per substep (ADMM default 10, or the scene's)")
    s.add_argument("--integrator", choices=("backward_euler", "bdf2"), default=None,
                   help="admm time integrator (default the scene's, else backward_euler; bdf2 is second order "
                        "and keeps a swing's energy, SolverADMMConfig.integrator)")
    s.add_argument("--seed", type=int, default=None,
                   help="random seed of a procedural groom (default: the scene's, or 0)")
    s.add_argument("--vertices-per-strand", type=int, default=None,
                   help="a TOML scene's generated groom: vertices per strand (default: the scene's)")
    s.add_argument("--continuous", type=int, default=None, metavar="N",
                   help="ADMM contacts: continuous-time collision detections per substep (paper's CT runs: 3; "
                        "0: proximity only)")
    s.add_argument("--checkpoint-every", type=int, default=10, metavar="K",
                   help="write a checkpoint every K frames and at the end (ADMM solver; 0: never; default 10)")
    s.add_argument("--resume", action="store_true",
                   help="continue from the output's checkpoint (same frames as an uninterrupted run)")
    s.add_argument("--frame-format", default=None,
                   help="folder output: format of the per-frame files (thair (default), hair, data, ply, obj, "
                        "tfx, usd)")
    s.add_argument("--profile", action="store_true", help="time each stage of Algorithm 1 (synchronises after each)")
    s.add_argument("--equilibrium", action="store_true",
                   help="only the rest shape: quasistatic ADMM steps until the largest displacement per step is "
                        "below --equilibrium-tolerance; written as frame 1")
    s.add_argument("--equilibrium-tolerance", type=float, default=1e-5, metavar="M",
                   help="--equilibrium: estimated distance left to the equilibrium [m] (default 1e-5)")
    s.add_argument("--max-steps", type=int, default=2000,
                   help="--equilibrium: most quasistatic steps (default 2000)")
    s.add_argument("--max-error", type=float, default=None, metavar="E",
                   help="pick the cheapest method and knobs whose measured error (fraction of the strand length, "
                        "e.g. 0.05) is within E, from the speed/accuracy data")
    s.add_argument("--budget-ms", type=float, default=None, metavar="T",
                   help="pick the most accurate method and knobs that measured within T wall ms per frame for "
                        "this scene's vertex count")
    s.add_argument("--strict", action="store_true",
                   help="exit with status 3 when the run's quality fails (p99 edge strain above 5 %%, or free "
                        "vertices deeper than 0.5 mm inside a body; see taichi_hair.quality)")
    s.add_argument("--pareto-data", default=None, metavar="CSV",
                   help="speed/accuracy data for --max-error/--budget-ms (default: the shipped CPU "
                        "measurements; a pareto.csv from taichi-hair bench pareto)")
    _add_common(s)
    s.set_defaults(func=cmd_simulate)
