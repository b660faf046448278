"""``taichi-hair groom``, ``render`` and ``variants``: the grooming tool from the command line (Sec. 5.3).

    taichi-hair groom [GROOM]                                   # the window (apps/groom.py)
    taichi-hair groom GROOM --offscreen --script SESSION.json --out DIR
    taichi-hair render GROOM --out still.png --eye 0 0.1 0.6 --target 0 0 0 --fov 35 --size 800 600  (cli/render.py)
    taichi-hair variants GROOM --count 12 --out DIR

GROOM is any file :func:`taichi_hair.io.load_groom` reads; left out, a procedural groom
(:mod:`taichi_hair.groom.generators`) on the default head ``assets/head.obj``.  Errors are one line on
stderr and a non-zero exit: a groom that fails to load gives the loader's message; a session file
with an unknown action or a bad value names the entry, its line and the action.
"""

from __future__ import annotations

import json
import os
import time

import numpy as np

from .common import CLIError, _init_taichi

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


# =========================================================================== shared set-up
def _add_groom_source(p, optional: bool, head_default: str | None = "default") -> None:
    if optional:
        p.add_argument("groom", nargs="?", default=None,
                       help="groom file (any format taichi-hair reads); default: a generated groom on the default head")
    else:
        p.add_argument("groom", help="groom file (any format taichi-hair reads), or 'default' for a generated one")
    p.add_argument("--scale", type=float, default=None, help="file units to metres (0.01 for centimetres)")
    p.add_argument("--style", default="wavy", choices=["straight", "wavy", "curly"],
                   help="style of the generated default groom")
    p.add_argument("--strands", type=int, default=1000, help="strands of the generated default groom")
    p.add_argument("--vertices", type=int, default=16, help="vertices per strand of the generated default groom")
    p.add_argument("--seed", type=int, default=0, help="seed of the generated default groom")
    p.add_argument("--head", default=head_default,
                   help="head mesh: 'default' (assets/head.obj), 'none', or an OBJ/PLY/STL path [m]"
                        + ("" if head_default else "; default: the result's own bodies (none for a groom file, "
                                                   "the default head for a generated groom)"))


def load_groom_arg(args):
    """The groom of the command line: a file (the loader's message on failure) or a generated default."""
    from ..io import load_groom

    if args.groom in (None, "default"):
        from ..groom.generators import GeneratorConfig, generate_groom

        if args.strands < 1 or args.vertices < 3:
            raise CLIError("--strands must be >= 1 and --vertices >= 3")
        surface = _default_surface(args.head)
        return generate_groom(surface, GeneratorConfig(style=args.style, strands=args.strands,
                                                       vertices_per_strand=args.vertices, seed=args.seed,
                                                       length=0.18))
    if not os.path.exists(args.groom):
        raise CLIError(f"{args.groom}: no such file")
    g = load_groom(args.groom, scale=args.scale)
    return g


def _default_surface(head_arg):
    from ..groom.generators import HEAD_MESH_PATH, load_head, sphere_surface

    if head_arg == "none":
        return sphere_surface(0.09)
    path = HEAD_MESH_PATH if head_arg == "default" else head_arg
    if not os.path.exists(path):
        raise CLIError(f"{path}: head mesh not found")
    return load_head(path)


def load_head_mesh(head_arg):
    """(vertices, triangles, path) of the --head argument, or None for 'none'."""
    if head_arg == "none":
        return None
    from ..groom.generators import HEAD_MESH_PATH, read_obj_groups

    path = HEAD_MESH_PATH if head_arg == "default" else head_arg
    if not os.path.exists(path):
        raise CLIError(f"{path}: head mesh not found")
    if path.lower().endswith(".obj"):
        v, f, _ = read_obj_groups(path)
    else:
        import trimesh

        try:
            m = trimesh.load(path, force="mesh")
        except Exception as exc:  # trimesh raises many types for a bad file
            raise CLIError(f"{path}: cannot read the head mesh ({exc})") from None
        v, f = np.asarray(m.vertices), np.asarray(m.faces)
    return np.asarray(v, np.float64), np.asarray(f, np.int64), path


def _add_camera(p, color_modes=("region", "strand", "groom", "uniform", "error"), default_color="region") -> None:
    p.add_argument("--eye", type=float, nargs=3, default=None, metavar=("X", "Y", "Z"),
                   help="camera position [m]; default: framing the groom from the front-right")
    p.add_argument("--target", type=float, nargs=3, default=None, metavar=("X", "Y", "Z"),
                   help="point looked at [m]; default: the centre of the groom's bounding box")
    p.add_argument("--fov", type=float, default=35.0, help="vertical field of view [degrees]")
    p.add_argument("--size", type=int, nargs=2, default=(640, 480), metavar=("W", "H"), help="image size [pixels]")
    p.add_argument("--color", default=default_color, choices=list(color_modes),
                   help="strand colours: " + ("shaded hair (Kajiya-Kay, the default), or for debugging: "
                                              if "shaded" in color_modes else "")
                        + "by region, by strand, the file's colours, uniform, the skinning interpolation error "
                          "(distance of each strand to its skinned reconstruction from the guides)"
                        + (", edge strain against frame 0" if "strain" in color_modes else ""))


def camera_from_args(args, points, head=None):
    from ..render import CameraConfig

    pts = np.asarray(points, np.float64).reshape(-1, 3)
    if head is not None:
        pts = np.vstack([pts, head[0]])
    try:
        framed = CameraConfig.framing(pts, direction=(0.55, 0.25, 1.0), fov=args.fov)
        if args.eye is None and args.target is None:
            return framed
        eye = framed.eye if args.eye is None else tuple(args.eye)
        target = framed.target if args.target is None else tuple(args.target)
        dist = float(np.linalg.norm(np.subtract(eye, target)))
        return CameraConfig(eye=eye, target=target, fov=args.fov, z_near=max(dist * 1e-3, 1e-4),
                            z_far=dist * 10 + 1.0)
    except ValueError as exc:
        raise CLIError(str(exc)) from None


def _check_size(args):
    w, h = args.size
    if not (8 <= w <= 8192 and 8 <= h <= 8192):
        raise CLIError(f"--size must be two integers in [8, 8192], got {w} {h}")
    return w, h


def skinning_error(groom, guide_ratio: float = 0.1, neighbour_count: int = 4, seed: int = 0) -> np.ndarray:
    """Per-strand interpolation error [m]: max distance between each strand of ``groom.points`` and its
    reconstruction by linear blend skinning from the guides (the strands a session would simulate),
    bound in the rest pose (``rest_points``, else ``points``).  Guides are 0 by construction."""
    from ..builder import GroomBuilder
    from ..config import RodMaterial
    from ..groom.skinning import SkinningConfig, SkinningLBS, interpolation_error, select_guides

    rest = (groom.rest_points if groom.rest_points is not None else groom.points).astype(np.float64)
    off = groom.strand_offsets
    guides = np.sort(select_guides(rest[off[:-1]], guide_ratio, seed))
    b = GroomBuilder()
    for s in guides:
        b.add_strand(rest[off[s]:off[s + 1]], RodMaterial(), root="clamped", body=0)
    model = b.finalize()
    skin = SkinningLBS(model, guides, [rest[off[s]:off[s + 1]] for s in range(groom.strand_count)],
                       SkinningConfig(neighbour_count=min(neighbour_count, guides.size)))
    state, control = model.state(), model.control()
    gv = np.concatenate([np.arange(off[s], off[s + 1]) for s in guides])
    state.vertex_position.from_numpy(groom.points[gv].astype(state.vertex_position.to_numpy().dtype))
    skin.deform(state, control)
    err = interpolation_error(skin.positions(), groom.points, groom.strand_vertex_counts())
    return err.strand_error_max


def _colors_for(groom, mode, selection=None):
    from ..render import strand_colors

    values = skinning_error(groom) if mode == "error" else None
    return strand_colors(groom, mode, values, selection=selection)


# =========================================================================== render
def _make_parent(path):
    d = os.path.dirname(os.path.abspath(path))
    os.makedirs(d, exist_ok=True)


# =========================================================================== groom (window / off screen)
def session_config(groom, args):
    """GroomingConfig: the groom's saved ``params['grooming']``, else defaults, then the command line."""
    from dataclasses import replace

    from ..groom.session import GroomingConfig

    stored = groom.params.get("grooming") if isinstance(groom.params, dict) else None
    try:
        cfg = GroomingConfig(**stored) if isinstance(stored, dict) else GroomingConfig()
        over = {}
        if args.guide_ratio is not None:
            over["guide_ratio"] = args.guide_ratio
        if args.iterations is not None:
            over["iterations"] = args.iterations
        if args.contacts is not None:
            over["contacts"] = args.contacts == "on"
        if getattr(args, "rest_pose", None) is not None:
            over["rest_pose"] = args.rest_pose
        if getattr(args, "rest_max_change", None) is not None:
            over["rest_max_change"] = args.rest_max_change
        if getattr(args, "unheld_shape_weight", None) is not None:
            over["unheld_shape_weight"] = args.unheld_shape_weight
        return replace(cfg, **over)
    except (TypeError, ValueError) as exc:
        raise CLIError(str(exc)) from None


def head_colliders(head, cfg_contacts: bool):
    """A static MeshCollider of the head when contacts are on (proximity only, as the session sets)."""
    if head is None or not cfg_contacts:
        return []
    from ..contact.colliders import MeshCollider

    return [MeshCollider(head[2], body=-1, friction=0.3)]


def cmd_groom(args) -> int:
    if args.offscreen:
        return run_offscreen(args)
    path = os.path.join(REPO_ROOT, "apps", "groom.py")
    if not os.path.exists(path):
        raise CLIError(f"the grooming window lives in the repository's apps/groom.py, not found at {path}")
    import importlib.util

    spec = importlib.util.spec_from_file_location("taichi_hair_groom_app", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.run_window(args)


def run_offscreen(args) -> int:
    """Replay ``--script`` on the groom and write PNG frames, the edited groom and the log to ``--out``."""
    from ..groom.session import EDIT_ACTIONS, GroomingSession
    from ..render import ViewerGGUI, save_png, strand_colors

    if not args.script:
        raise CLIError("--offscreen needs --script SESSION.json")
    if not args.out:
        raise CLIError("--offscreen needs --out DIR")
    if not os.path.exists(args.script):
        raise CLIError(f"{args.script}: no such session file")
    w, h = _check_size(args)
    if args.every < 0:
        raise CLIError("--every must be >= 0")
    groom = load_groom_arg(args)
    head = load_head_mesh(args.head)
    cfg = session_config(groom, args)
    ti, arch = _init_taichi(args.arch, "f32")
    session = GroomingSession(groom, cfg, colliders=head_colliders(head, cfg.contacts))
    os.makedirs(args.out, exist_ok=True)
    cam = camera_from_args(args, groom.points, head)
    viewer = ViewerGGUI(w, h, show_window=False)
    viewer.set_camera(cam)
    if head is not None:
        viewer.set_head(head[0], head[1])
    frames = []

    def draw(tag):
        g = session.groom
        mode = "region" if args.color == "error" else args.color
        viewer.set_strands(g.points, g.strand_offsets, strand_colors(g, mode, selection=session.vertex_selection))
        viewer.render()
        name = os.path.join(args.out, f"frame_{len(frames):04d}.png")
        save_png(name, viewer.image())
        frames.append({"file": os.path.basename(name), "after": tag})

    draw("start")
    counter = {"n": 0}

    def after(i, entry):
        if entry["action"] in EDIT_ACTIONS + ("advance", "undo", "redo"):
            counter["n"] += 1
            if args.every and counter["n"] % args.every == 0:
                draw(f"entry {i}: {entry['action']}")

    t0 = time.perf_counter()
    try:
        session.replay(args.script, after_each=after)
        replay_s = time.perf_counter() - t0
        draw("end")
    except ValueError as exc:
        raise CLIError(f"{args.script}: {exc}") from None
    finally:
        viewer.close()
    out_groom = os.path.join(args.out, "groom.thair.npz")
    session.save(out_groom)
    session.write_log(os.path.join(args.out, "session.json"))
    summary = {"groom": args.groom or "default", "script": args.script, "arch": arch, "frames": frames,
               "strands": session.groom.strand_count, "vertices": session.groom.vertex_count,
               "replay_s": replay_s, "rebuilds": session.rebuild_count, "updates": session.update_count,
               "timings": {k: [float(x) for x in v] for k, v in session.timings.items()}}
    held = ""
    if session.config.rest_pose == "sag-free":  # the equilibrium residual, guides held, drift (issue 14 item 2)
        rep = session.rest_pose_report()
        summary["rest_pose"] = rep
        held = (f"; sag-free: {rep['strands_held']}/{rep['guides']} guides held"
                + (f" ({rep['held_by_springs']} more by shape springs)" if rep["held_by_springs"] else "")
                + f", drift p90 {1e3 * rep['drift_p90_m']:.3f} mm")
    q = summary["quality"] = session.quality()  # the guides at the end, and their worst step (hair pairs)
    with open(os.path.join(args.out, "summary.json"), "w", encoding="utf-8") as fh:
        json.dump(summary, fh, indent=1, default=lambda v: v.tolist() if hasattr(v, "tolist") else str(v))
    print(f"replayed {len(session.log)} actions in {replay_s:.2f} s ({session.rebuild_count} builds, "
          f"{session.update_count} in-place updates); wrote {len(frames)} frames, {out_groom}{held}")
    print(quality_line(q))
    return 0


def quality_line(q: dict) -> str:
    """One line of a grooming session's ``quality()``: the guides' strain and hair pairs at the end, the worst step."""
    body = (f"; {q['vertices_inside']} vertices inside the head (deepest {1e3 * q['body_penetration_max_m']:.2f} mm)"
            if "vertices_inside" in q else "")
    p99, deepest = q.get("hair_penetration_p99_m", 0.0), q.get("hair_penetration_max_m", 0.0)
    pairs = (f"hair pairs p99 {1e6 * p99:.1f} um, max {1e6 * deepest:.0f} um, {q.get('crossed_pairs', 0)} crossed"
             if q["hair_contacts"] else "no hair-hair contacts")
    worst = (f"; worst of {q['steps']} steps: {q['crossed_pairs_worst']} crossed, deepest hair pair "
             f"{1e6 * q['hair_penetration_max_m_worst']:.0f} um" if q["hair_contacts"] else "")
    return (f"guides at the end: strain p99 {100 * q['strain_p99']:.3f} % (max {100 * q['strain_max']:.3f} %), {pairs}"
            f"{body}, largest move of the last step {1e3 * q['max_step_motion_m']:.3f} mm{worst}")


# =========================================================================== variants
def cmd_variants(args) -> int:
    from ..scene.variants import VariantConfig, make_variants

    if args.count < 1:
        raise CLIError("--count must be >= 1")
    groom = load_groom_arg(args)
    head = load_head_mesh(args.head)
    cfg = session_config(groom, args)
    ti, arch = _init_taichi(args.arch, "f32")
    try:
        vcfg = VariantConfig(count=args.count, seed=args.variant_seed, actions=args.actions, frames=args.frames,
                             thumbnail=tuple(args.thumbnail))
    except ValueError as exc:
        raise CLIError(str(exc)) from None
    result = make_variants(groom, vcfg, cfg, args.out, head=head,
                           colliders=head_colliders(head, cfg.contacts), log=print)
    print(f"wrote {len(result['variants'])} variants and {result['contact_sheet']} in {result['seconds']:.1f} s")
    return 0


# =========================================================================== registration
def _add_session_options(p) -> None:
    p.add_argument("--guide-ratio", type=float, default=None, help="fraction of strands simulated (default 0.1)")
    p.add_argument("--iterations", type=int, default=None, help="ADMM iterations per frame (default 10)")
    p.add_argument("--contacts", choices=["on", "off"], default=None,
                   help="hair-hair and head proximity contacts (default on; compiling the contact kernels "
                        "takes 20-180 s on a 2-core CPU)")
    p.add_argument("--rest-pose", choices=["authored", "sag-free"], default=None,
                   help="rest pose of the guides: 'authored' (default; they sag under gravity) or 'sag-free' "
                        "(the rest shape is solved to be an equilibrium, re-solved after every edit)")
    p.add_argument("--rest-max-change", type=float, default=None,
                   help="with --rest-pose sag-free: the largest change of a rest strain from the authored one for a "
                        "guide to be held (default 1.9 in grooming; 1.0 is ~60 degrees per vertex); the guides not "
                        "held keep their authored rest pose, held to their shape by springs (--unheld-shape-weight)")
    p.add_argument("--unheld-shape-weight", type=float, default=None,
                   help="with --rest-pose sag-free: the springs that hold the guides the rest pose does not hold to "
                        "their authored shape, in contact weights (default 10; 0 lets them sag)")
    p.add_argument("--arch", default="cpu", help="Taichi arch: cpu (default), cuda, gpu, vulkan")


def register(sub) -> None:
    """Add ``groom``, ``render`` and ``variants`` to an argparse subparsers object."""
    p = sub.add_parser("groom", help="the grooming tool: a window, or --offscreen replay of a session")
    _add_groom_source(p, optional=True)
    _add_camera(p)
    _add_session_options(p)
    p.add_argument("--offscreen", action="store_true", help="no window: replay --script and write frames to --out")
    p.add_argument("--script", default=None, help="session file to replay (a JSON list of actions)")
    p.add_argument("--out", default=None, help="output folder (frames, edited groom, session log)")
    p.add_argument("--every", type=int, default=1,
                   help="off screen: write a frame after every N-th edit or advance (0: first and last only)")
    p.add_argument("--autosave", default=None, help="window: autosave path (default: beside the groom file)")
    p.set_defaults(func=cmd_groom)


    v = sub.add_parser("variants", help="procedural variants of a groom (Sec. 5.3) and a contact sheet")
    _add_groom_source(v, optional=False)
    _add_session_options(v)
    v.add_argument("--count", type=int, default=8, help="number of variants")
    v.add_argument("--out", required=True, help="output folder")
    v.add_argument("--variant-seed", type=int, default=0, help="seed of the random action sequences")
    v.add_argument("--actions", type=int, default=3, help="basic actions per variant")
    v.add_argument("--frames", type=int, default=6, help="quasistatic frames after each action")
    v.add_argument("--thumbnail", type=int, nargs=2, default=(240, 240), metavar=("W", "H"),
                   help="thumbnail size [pixels]")
    v.set_defaults(func=cmd_variants)
