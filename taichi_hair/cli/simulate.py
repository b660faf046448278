"""``taichi-hair simulate``: run a scene headless and write its frames.

    taichi-hair simulate hang --strands 300 --frames 48 --out out/hang
    taichi-hair simulate assets/scenes/head_turn.toml --out out/head_turn.usd
    taichi-hair simulate assets/scenes/hairball.toml --out out/hb --frames 96 --resume

SCENE is a built-in name (``hang``, ``hairball``), a TOML scene file (:mod:`taichi_hair.scene.file`) or a groom
file, simulated as authored with ``--units``, ``--up``, ``--body MESH`` and ``--animation``
(:mod:`taichi_hair.scene.groom_file`)::

    taichi-hair simulate assets/ponytail/tail.tfx --scale 0.0035 --animation nod --frames 24 --out out/tail

The output is chosen by the name given to ``--out``:

- ``*.usd``, ``*.usda``, ``*.usdc``: one USD BasisCurves prim with time-sampled points (one time code
  per frame, ``timeCodesPerSecond`` = fps), written at the end;
- ``*.thair.npz`` or ``*.npz``: the native groom format with every frame in ``point_frames``;
- anything else: a folder with ``frames.npz`` (positions of every frame), ``frames/frame_NNNNN.<ext>``
  (one groom file per frame, written as it completes; ``--frame-format``), ``stats.csv`` and
  ``summary.json``.

For a file output the statistics, summary and checkpoint sit beside it, named after its whole file name:
``<file>.stats.csv``, ``<file>.summary.json``, ``<file>.checkpoint.npz`` (``x.usda`` -> ``x.usda.summary.json``).
Checkpoints (:mod:`taichi_hair.scene.checkpoint`, ADMM solver only) are written every ``--checkpoint-every``
frames and at the end; ``--resume`` continues from the last one and gives the same frames, bit for bit, as a
run that never stopped (and refuses a checkpoint made for another scene or other settings).

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

import os
import sys


from .common import CLIError, _add_common, _init_taichi

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
    integ = {k: getattr(args, k) for k in ("integrator", "schedule") if getattr(args, k)}  # (SolverADMMConfig options)
    if args.scene == "hang":
        hs = HangScene(strands=d["strands"], length=args.length if args.length else 0.2, seed=d["seed"])
        cfg = SolverADMMConfig(iterations=iterations, mode="dynamic", **integ)
        colliders = []
        body = BodyAnimation(function=lambda t: nod_rotation(hs, t), description={"preset": "hang-nod"})
        builder = (lambda: build_hang(hs, finalize=False))
        scene_desc = dict(vars(hs))
    else:
        hs = HairballScene(strands=d["strands"], length=args.length if args.length else 0.30, seed=d["seed"])
        contacts = ContactConfig(friction=hs.friction, projection_iterations=2, correction_iterations=10,
                                 continuous_detections=args.continuous or 0)
        cfg = SolverADMMConfig(iterations=iterations, mode="dynamic", contacts=contacts, **integ)
        from ..contact.colliders import SphereCollider

        colliders = [SphereCollider(radius=hs.ball_radius, friction=hs.friction, body=0)]
        body = BodyAnimation(function=hairball_rotation, description={"preset": "hairball"})
        builder = (lambda: build_hairball(hs, finalize=False))
        scene_desc = dict(vars(hs), continuous=args.continuous or 0)
    desc = {"name": args.scene, "params": scene_desc, "iterations": iterations, "fps": d["fps"],
            "substeps": d["substeps"], **integ}
    rest_pose = args.rest_pose or "authored"
    if rest_pose == "file":
        raise CLIError(f"--rest-pose file needs a groom file; the built-in scene {args.scene!r} generates its groom")
    if rest_pose != "authored":
        desc["rest_pose"] = rest_pose
    from ..io.sizing import check_simulation

    check_simulation(hs.vertex_count, d["frames"], args.scene == "hairball", f"simulate {args.scene} with "
                     f"{hs.strands:,} strands", "use fewer --strands or --frames")
    return Scene(name=args.scene, path="", frames=d["frames"], fps=d["fps"], substeps=d["substeps"],
                 gravity=(0.0, -9.81, 0.0), groom=None, solver="admm", solver_config=cfg, colliders=colliders,
                 bodies=[body], description=desc, groom_builder=builder, rest_pose=rest_pose,
                 vertex_count_hint=hs.vertex_count)


#: Options of a groom-file scene (``simulate GROOM_FILE``), with their defaults.
GROOM_FILE_OPTIONS = dict(units=None, scale=None, up=None, body=None, body_units=None, animation=None, hair_hair=False)


def _is_groom_file(name: str) -> bool:
    from ..io import EXTENSIONS

    low = name.lower()
    return any(low.endswith(ext) for ext, fmt in EXTENSIONS.items() if fmt != "tfxmesh")


def _load_scene(args):
    given = [k for k, v in GROOM_FILE_OPTIONS.items() if getattr(args, k, v) != v]
    groom_file = args.scene not in SCENES and _is_groom_file(args.scene)
    if given and not groom_file:
        where = ("set [groom] units / up and a [[colliders]] mesh in the scene file" if args.scene.endswith(".toml")
                 else "the built-in scenes make their own groom and body")
        raise CLIError(f"--{given[0].replace('_', '-')} applies to a groom file (simulate GROOM_FILE); {where}")
    if args.set and (args.scene in SCENES or groom_file):
        raise CLIError(f"--set {args.set[0]}: --set changes a scene file's keys; {args.scene!r} is "
                       + ("a built-in scene (use a scene file, e.g. assets/scenes/hairball.toml)" if args.scene in SCENES else
                          "a groom file"))
    if args.scene in SCENES:
        return _named_scene(args)
    over = dict(frames=args.frames, fps=args.fps, substeps=args.substeps, strands=args.strands,
                length=args.length, seed=args.seed, iterations=args.iterations, continuous=args.continuous,
                vertices_per_strand=args.vertices_per_strand, integrator=args.integrator, rest_pose=args.rest_pose,
                schedule=args.schedule)
    if groom_file:
        from ..scene.groom_file import scene_from_groom_file

        return scene_from_groom_file(args.scene, over, units=args.units, scale=args.scale, up=args.up or "y", body=args.body,
                                     body_units=args.body_units, animation=args.animation or "still",
                                     hair_hair=args.hair_hair)
    if not args.scene.lower().endswith(".toml"):
        raise CLIError(f"unknown scene {args.scene!r} (available: {', '.join(SCENES)}, a .toml scene file or a "
                       "groom file)")
    if not os.path.isfile(args.scene):
        raise CLIError(f"{args.scene}: no such scene file")
    from ..scene.file import load_scene, parse_set

    sets = dict(parse_set(t) for t in args.set)
    return load_scene(args.scene, over, sets)


# --------------------------------------------------------------------------- output
def _output_layout(out: str) -> dict:
    """Where each output goes, by the extension of ``out``."""
    low = out.lower()
    # A file output's sidecars are named after its whole file name (``x.usda`` -> ``x.usda.summary.json``), so two
    # outputs with the same stem (``x.usda``, ``x.thair.npz``) never share, and overwrite, each other's.
    base = out
    if low.endswith(USD_EXTENSIONS):
        kind = "usd"
    elif low.endswith(".npz"):
        kind = "native"
    else:
        kind = "folder"
    if kind == "folder":
        return dict(kind=kind, dir=out, frames_npz=os.path.join(out, "frames.npz"),
                    frame_dir=os.path.join(out, "frames"), stats=os.path.join(out, "stats.csv"),
                    summary=os.path.join(out, "summary.json"), checkpoint=os.path.join(out, "checkpoint.npz"))
    return dict(kind=kind, dir=os.path.dirname(os.path.abspath(out)), file=out, stats=base + ".stats.csv",
                summary=base + ".summary.json", checkpoint=base + ".checkpoint.npz", bodies=base + ".bodies.npz")


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
    scene, load_warnings, layout = prepare_simulate(args)
    ti, arch = _init_taichi(args.arch, args.precision)
    from .simulate_run import SimulateRun

    return SimulateRun(args, scene, load_warnings, layout, arch).run()


def prepare_simulate(args) -> tuple:
    """Everything ``simulate`` checks before ``ti.init`` (scene errors cost no start-up): the scene, the
    warnings raised while reading it, and the output layout.  A batch pack (cli/simulate_pack.py) prepares
    each of its runs with it and initialises Taichi once."""
    scene, load_warnings = _load_scene_reporting(args)
    if scene.groom is not None:
        from ..io.sizing import check_simulation

        contacts = scene.solver == "admm" and getattr(scene.solver_config, "contacts", None) is not None
        check_simulation(scene.groom.vertex_count, scene.frames, contacts, f"simulate {scene.name}",
                         "use fewer --strands or --frames")
    _check_model_options(args, scene)
    out = args.out or scene.output
    if not out:
        raise CLIError("--out is required (the scene file names no [scene] output)")
    if args.checkpoint_every < 0:
        raise CLIError("--checkpoint-every must be >= 0 (0: no checkpoints)")
    if scene.frames < 1 or scene.substeps < 1 or not scene.fps > 0:
        raise CLIError("--frames and --substeps must be >= 1 and --fps > 0")
    layout = _output_layout(out)
    n = scene.groom.vertex_count if scene.groom is not None else scene.vertex_count_hint
    if n:  # a frame buffer too large for memory is streamed to disk: is there room, before anything is built?
        from ..io.sizing import check_frame_buffer

        check_frame_buffer(n, scene.frames, os.path.dirname(os.path.abspath(layout["stats"])),
                           8 if args.precision == "f64" else 4)
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
    return scene, load_warnings, layout


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


def register(sub) -> None:
    s = sub.add_parser("simulate", help="run a scene headless and write its frames",
                       description="Run a scene headless. SCENE: hang, hairball, a .toml scene file or a "
                                   "groom file (.tfx, .hair, .data, .ply, .obj, .usd, .thair.npz). The "
                                   "output is a USD file (.usd/.usda/.usdc, time samples), a native groom "
                                   "(.thair.npz, every frame) or a folder (per-frame files).")
    s.add_argument("scene", help="scene: hang (strands hanging from a nodding sphere, no contacts), hairball "
                                 "(Daviet 2023 Sec. 5.2, frictional contacts), a .toml scene file, or a groom file")
    g = s.add_argument_group("a groom file as the scene (simulate GROOM_FILE; a scene file sets the same in "
                             "[groom] and [[colliders]])")
    g.add_argument("--units", choices=("m", "cm", "mm", "in"), default=None,
                   help="the groom file's length unit (default: metres, with a warning when the size says "
                        "otherwise)")
    g.add_argument("--scale", type=float, default=None, metavar="FACTOR",
                   help="file units -> metres, for files in no standard unit (the TressFX ponytail: 0.0035); "
                        "the body's too unless --body-units")
    g.add_argument("--up", choices=("y", "z"), default=None,
                   help="the file's up axis: z-up files are turned to the simulator's y-up (default y)")
    g.add_argument("--body", default=None, metavar="MESH",
                   help="a body mesh the hair collides with and whose roots follow it: OBJ, PLY, STL, OFF, "
                        "glTF, TressFX .tfxmesh or USD, in the groom's units and up axis unless --body-units (a USD "
                        "stage's own metersPerUnit and upAxis win)")
    g.add_argument("--body-units", choices=("m", "cm", "mm", "in"), default=None,
                   help="the body mesh's length unit when it differs from the groom's")
    g.add_argument("--animation", default=None, metavar="still|nod|turn|KEYS.toml",
                   help="the body's motion: still (default), nod (15 deg, 1.5 s), turn (40 deg, 2 s) about "
                        "the neck (the body's lowest point), or a TOML file of [[bodies]] tables")
    g.add_argument("--hair-hair", action="store_true",
                   help="hair-hair contacts on (friction 0.2, 2 + 10 projection sweeps; off by default)")
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
    s.add_argument("--schedule", choices=("auto", "stage", "strand", "lanes"), default=None,
                   help="admm launch schedule (SolverADMMConfig.schedule; default the scene's, else auto: on a CPU "
                        "lanes from 50,000 vertices, strand below): 'lanes' runs the iteration on lanes of eight "
                        "strands, 2-5x the ADMM throughput on a CPU after ~25 s of kernel compilation per groom size")
    s.add_argument("--rest-pose", choices=("authored", "sag-free", "file"), default=None,
                   help="rest pose of the groom: 'authored' (its shape; default), 'sag-free' (rest strains solved "
                        "so that the shape holds under gravity) or 'file' (the groom file's rest curve, e.g. from "
                        "taichi-hair rest-pose); ADMM only; the scene file's [groom] rest_pose")
    s.add_argument("--seed", type=int, default=None,
                   help="random seed of a procedural groom (default: the scene's, or 0)")
    s.add_argument("--vertices-per-strand", type=int, default=None,
                   help="a TOML scene's generated groom: vertices per strand (default: the scene's)")
    s.add_argument("--continuous", type=int, default=None, metavar="N",
                   help="ADMM contacts: continuous-time collision detections per substep (paper's CT runs: 3; "
                        "0: proximity only)")
    s.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="a scene file's key by its dotted name, e.g. --set solver.contacts.friction=0.3 or "
                        "--set colliders.0.friction=0.5 (VALUE read as TOML; repeatable)")
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
                        "below --equilibrium-tolerance, or, without contacts on straight round strands, one step and a "
                        "direct static Newton solve of the same energy; written as frame 1")
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
