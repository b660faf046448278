"""``taichi-hair render``: pictures and movies of grooms and of simulation results, off screen.

    taichi-hair render out/hang --out hang.png                       # the last frame of a simulate folder
    taichi-hair render out/tail.usd --frame 12 --out f12.png         # one time sample of a USD result
    taichi-hair render out/hang --frames 0:48 --movie hang.mp4       # a movie (imageio + ffmpeg; .gif: Pillow)
    taichi-hair render groom.tfx --turntable 36 --movie turn.gif     # the camera around one frame
    taichi-hair render out/hang --color strain --out strain.png      # debug colourings

INPUT is anything :func:`taichi_hair.io.result.load_result` reads: the folder ``simulate`` writes (or its
``frames.npz``), a ``.thair.npz`` or USD file with frames, or any groom file (one frame); ``default`` draws
a generated groom on the default head.  Bodies are drawn posed at each frame (the meshes and transforms
``simulate`` wrote; the hairball's ball).  Hair is shaded (:mod:`taichi_hair.groom.shading`: Kajiya-Kay
highlights, root-to-tip darkening) in the file's colour or ``--hair-color``; ``--color`` picks a debug
colouring instead: region, strand, groom, uniform, error (skinning interpolation), strain (edge strain
against frame 0 of the result, on a blue-white-red ramp up to +-1 %), contact (each vertex's Coulomb state
at the frame's last step, from a simulate folder with contacts: blue sticking, red sliding, grey free).

The camera frames every frame drawn (and the bodies), so a movie does not jump; ``--eye``, ``--target``
and ``--fov`` override it.  Line width follows the hair's radius at the target's distance, at least one
pixel (a software Vulkan device may draw every line one pixel wide).
"""

from __future__ import annotations

import math
import os
import time

import numpy as np

from .common import CLIError, _init_taichi

HAIR_COLOR_NAMES = {"brown": (0.36, 0.22, 0.12), "black": (0.06, 0.05, 0.05), "blonde": (0.78, 0.62, 0.38),
                    "red": (0.55, 0.18, 0.07), "grey": (0.6, 0.6, 0.6), "white": (0.9, 0.88, 0.85)}
RENDER_COLOR_MODES = ("shaded", "region", "strand", "groom", "uniform", "error", "strain", "contact")
#: --color contact: free, sticking, sliding and unknown (frames before a --resume) vertices [RGB].
CONTACT_COLORS = np.array([(0.55, 0.55, 0.55), (0.15, 0.45, 1.0), (1.0, 0.3, 0.1), (0.25, 0.25, 0.25)],
                          np.float32)
MOVIE_EXTENSIONS = (".mp4", ".gif", ".webm", ".mkv", ".mov")
#: Refuse to render more images than this in one command (a typo like --frames 0:1000000).
MAX_IMAGES = 20000


def parse_hair_color(text: str) -> tuple:
    """``brown`` (a name), ``#5c381f`` or ``0.36,0.22,0.12`` -> RGB in [0, 1]."""
    t = text.strip().lower()
    if t in HAIR_COLOR_NAMES:
        return HAIR_COLOR_NAMES[t]
    try:
        if t.startswith("#") and len(t) == 7:
            return tuple(int(t[i:i + 2], 16) / 255.0 for i in (1, 3, 5))
        v = tuple(float(x) for x in t.split(","))
        if len(v) == 3 and all(0.0 <= x <= 1.0 for x in v):
            return v
    except ValueError:
        pass
    raise CLIError(f"--hair-color: expected a name ({', '.join(HAIR_COLOR_NAMES)}), #rrggbb or r,g,b in [0, 1]; "
                   f"got {text!r}")


def parse_frames(text: str, count: int) -> range:
    """``A:B`` (Python slice: B excluded, either may be empty or negative) of ``count`` frames."""
    parts = text.split(":")
    if len(parts) not in (2, 3):
        raise CLIError(f"--frames: expected A:B (or A:B:STEP), got {text!r}")
    try:
        vals = [int(p) if p.strip() else None for p in parts]
    except ValueError:
        raise CLIError(f"--frames: expected integers A:B, got {text!r}") from None
    if len(vals) == 3 and vals[2] is not None and vals[2] <= 0:
        raise CLIError(f"--frames: the step must be >= 1, got {vals[2]}")
    r = range(count)[slice(*vals)]
    if len(r) == 0:
        raise CLIError(f"--frames {text}: no frame of the {count} in the result")
    return r


def _frame_index(k: int, count: int) -> int:
    if not -count <= k < count:
        raise CLIError(f"--frame {k}: the result has {count} frames (0 to {count - 1}, or -1 for the last)")
    return k % count


def strain_colors(points, rest_points, strand_offsets, vmax: float = 0.01) -> np.ndarray:
    """Per-vertex RGB of the edge strain |e| / |e_rest| - 1 (the larger of the vertex's two edges by
    magnitude): blue (-vmax) - white (0) - red (+vmax)."""
    p, r = np.asarray(points, np.float64), np.asarray(rest_points, np.float64)
    off = np.asarray(strand_offsets, np.int64)
    n = p.shape[0]
    e = np.linalg.norm(p[1:] - p[:-1], axis=1)
    e0 = np.linalg.norm(r[1:] - r[:-1], axis=1)
    strain = np.where(e0 > 0, e / np.where(e0 > 0, e0, 1.0) - 1.0, 0.0)
    strain[off[1:-1] - 1] = 0.0  # no edge across strands
    a = np.zeros(n)
    a[:-1] = strain
    b = np.zeros(n)
    b[1:] = strain
    b[off[:-1]] = 0.0
    a[off[1:] - 1] = 0.0
    v = np.where(np.abs(a) >= np.abs(b), a, b)
    u = np.clip(v / vmax, -1.0, 1.0)[:, None]
    white = np.ones((n, 3))
    red, blue = np.array([0.85, 0.1, 0.1]), np.array([0.1, 0.3, 0.9])
    return np.where(u >= 0, white + u * (red - white), white - u * (blue - white)).astype(np.float32)


def _line_width(radius, cam, height: int) -> float:
    """Pixels across a hair at the target's distance (twice the median radius), at least 1, at most 4."""
    if radius is None or not np.size(radius):
        return 1.0
    dist = float(np.linalg.norm(np.subtract(cam.eye, cam.target)))
    px = 2.0 * float(np.median(radius)) / (2.0 * dist * math.tan(math.radians(cam.fov) / 2.0)) * height
    return float(min(max(px, 1.0), 4.0))


def _write_movie(path: str, images: list, fps: float) -> None:
    low = path.lower()
    if low.endswith(".gif"):
        from PIL import Image

        frames = [Image.fromarray(im) for im in images]
        frames[0].save(path, save_all=True, append_images=frames[1:], duration=max(int(round(1000.0 / fps)), 20),
                       loop=0)
        return
    try:
        import imageio.v2 as imageio
    except ImportError:  # pragma: no cover - a declared dependency
        raise CLIError("--movie: imageio is not installed (pip install imageio imageio-ffmpeg)") from None
    try:
        with imageio.get_writer(path, fps=fps, macro_block_size=2, quality=8) as w:
            for im in images:
                w.append_data(im)
    except Exception as exc:  # noqa: BLE001 - ffmpeg's errors come in many types
        raise CLIError(f"--movie {path}: the encoder failed ({str(exc).splitlines()[0] if str(exc) else exc})") \
            from None


def _body_arg(args, result):
    """The meshes to draw per frame: a callable k -> [(V, T)]."""
    from ..render import sphere_mesh
    from .groom import load_head_mesh

    head = args.head
    if head in (None, "auto"):
        if result.meshes:
            return result.body_meshes
        if result.sphere_radius > 0:
            v, t = sphere_mesh(radius=result.sphere_radius * 0.995)
            return lambda k: [(v, t)]
        return lambda k: []
    mesh = load_head_mesh(head)
    if mesh is None:
        return lambda k: []
    return lambda k: [(mesh[0], mesh[1])]


def _merge(meshes):
    if not meshes:
        return None
    vs, ts, base = [], [], 0
    for v, t in meshes:
        vs.append(np.asarray(v, np.float64))
        ts.append(np.asarray(t, np.int64) + base)
        base += len(v)
    return np.vstack(vs), np.vstack(ts)


def cmd_render(args) -> int:
    from ..io.result import load_result
    from ..render import CameraConfig, ViewerGGUI, save_png
    from ..groom.shading import HAIR_BROWN, shade_strands
    from ..progress import Progress
    from .groom import _check_size, _colors_for, camera_from_args, load_groom_arg

    w, h = _check_size(args)
    if not (0.0 < args.fov < 180.0):
        raise CLIError(f"--fov must be in (0, 180) degrees, got {args.fov:g}")
    if args.color not in RENDER_COLOR_MODES:
        raise CLIError(f"--color must be one of {', '.join(RENDER_COLOR_MODES)}, got {args.color!r}")
    hair_color = parse_hair_color(args.hair_color) if args.hair_color else None
    if args.movie and not args.movie.lower().endswith(MOVIE_EXTENSIONS):
        raise CLIError(f"--movie: the file must end in one of {', '.join(MOVIE_EXTENSIONS)}, got {args.movie!r}")
    if args.movie and args.movie.lower().endswith((".mp4", ".webm", ".mkv", ".mov")) and (w % 2 or h % 2):
        raise CLIError(f"--movie {args.movie}: video needs an even --size, got {w} {h}")
    if args.turntable is not None and not (1 <= args.turntable <= 3600):
        raise CLIError(f"--turntable must be in [1, 3600] views, got {args.turntable}")
    if args.turntable is not None and args.frames is not None:
        raise CLIError("--turntable turns the camera around one frame: give --frame, not --frames")
    if args.frame is not None and args.frames is not None:
        raise CLIError("give --frame K or --frames A:B, not both")

    generated = args.groom in (None, "default")
    if generated:
        if args.head is None:
            args.head = "default"
        g = load_groom_arg(args)
        from ..io.result import SimulationResult

        result = SimulationResult(positions=g.points[None].astype(np.float32), strand_offsets=g.strand_offsets,
                                  radius=g.radius, color=g.color, region=g.region, source="default")
    else:
        if not os.path.exists(args.groom):
            raise CLIError(f"{args.groom}: no such file or folder")
        result = load_result(args.groom)
        if args.scale is not None:
            if not (math.isfinite(args.scale) and args.scale > 0):
                raise CLIError(f"--scale must be a finite positive number, got {args.scale!r}")
            result.positions = result.positions * np.float32(args.scale)
            result.radius = None if result.radius is None else result.radius * args.scale
    count = result.frame_count
    if args.frames is not None:
        frames = list(parse_frames(args.frames, count))
    else:
        frames = [_frame_index(args.frame if args.frame is not None else -1, count)]
    views = args.turntable or 1
    n_images = len(frames) * views
    if n_images > MAX_IMAGES:
        raise CLIError(f"{n_images} images asked (at most {MAX_IMAGES}); render fewer frames or views")
    sequence = n_images > 1
    if sequence and not args.movie and not args.out:
        raise CLIError("several images: give --out DIR (PNG files) and/or --movie FILE")
    if not sequence and not args.movie and not args.out:
        raise CLIError("--out PNG (or --movie FILE) is required")
    if args.out and not sequence and not args.out.lower().endswith(".png"):
        raise CLIError(f"--out {args.out}: one image is written as PNG (name it .png)")
    bodies = _body_arg(args, result)

    _init_taichi(args.arch, "f32")
    pts_all = [result.positions[k] for k in frames] + [v for k in frames for v, _ in bodies(k)]
    cam0 = camera_from_args(args, np.vstack([np.asarray(p, np.float64).reshape(-1, 3) for p in pts_all]))
    fps = args.fps or result.fps or 24.0
    viewer = ViewerGGUI(w, h, show_window=False, line_width=_line_width(result.radius, cam0, h))
    groom0 = result.groom(frames[0])
    if args.color == "shaded":
        base = hair_color or (result.color if result.color is not None else HAIR_BROWN)
    elif args.color in ("strain", "contact"):
        base = None
        if args.color == "contact" and result.contact_state is None:
            raise CLIError(f"--color contact: {args.groom} has no contact states (a simulate folder of a run with "
                           "contacts keeps them in frames.npz)")
    else:
        debug = _colors_for(groom0, args.color)
    images = []
    bar = Progress(total=n_images, label="images", enabled=sequence and not args.quiet)
    t0 = time.perf_counter()
    if args.out and sequence:
        os.makedirs(args.out, exist_ok=True)
    done = 0
    try:
        for k in frames:
            points = result.positions[k]
            body = _merge(bodies(k))
            for view in range(views):
                cam = cam0
                if views > 1:  # the eye turned about the vertical axis through the target
                    a = 2.0 * math.pi * view / views
                    rel = np.subtract(cam0.eye, cam0.target)
                    c, s = math.cos(a), math.sin(a)
                    eye = np.asarray(cam0.target) + np.array([c * rel[0] + s * rel[2], rel[1], -s * rel[0] + c * rel[2]])
                    cam = CameraConfig(eye=tuple(eye), target=cam0.target, up=cam0.up, fov=cam0.fov,
                                       z_near=cam0.z_near, z_far=cam0.z_far)
                if args.color == "shaded":
                    colors = shade_strands(points, result.strand_offsets, base, cam.eye)
                elif args.color == "strain":
                    colors = strain_colors(points, result.positions[0], result.strand_offsets)
                elif args.color == "contact":
                    colors = CONTACT_COLORS[np.where(result.contact_state[k] < 0, 3, result.contact_state[k])]
                else:
                    colors = debug
                viewer.set_camera(cam)
                viewer.set_strands(points, result.strand_offsets, colors)
                if body is not None:
                    viewer.set_head(body[0], body[1])
                viewer.render()
                img = viewer.image()
                if args.out:
                    path = args.out if not sequence else os.path.join(args.out, f"frame_{done:05d}.png")
                    if not sequence:
                        d = os.path.dirname(os.path.abspath(path))
                        os.makedirs(d, exist_ok=True)
                    save_png(path, img)
                if args.movie:
                    images.append(img)
                done += 1
                bar.update(done)
    finally:
        bar.close()
        viewer.close()
    if args.movie:
        os.makedirs(os.path.dirname(os.path.abspath(args.movie)), exist_ok=True)
        _write_movie(args.movie, images, fps)
    wrote = [p for p in (args.out, args.movie) if p]
    what = f"frame {frames[0]}" if len(frames) == 1 else f"frames {frames[0]}-{frames[-1]}"
    print(f"wrote {' and '.join(wrote)}: {n_images} image(s) of {what} of {count}, {result.strand_offsets.shape[0] - 1} "
          f"strands, {w}x{h}, colour {args.color}, eye {tuple(round(c, 4) for c in cam0.eye)}, fov {cam0.fov:g}, "
          f"{time.perf_counter() - t0:.2f} s")
    return 0


def register(sub) -> None:
    from .groom import _add_camera, _add_groom_source

    r = sub.add_parser("render", help="render a groom or a simulation result off screen: a PNG, a sequence "
                                      "or a movie",
                       description=__doc__.split("\n\n")[0])
    _add_groom_source(r, optional=False, head_default=None)
    _add_camera(r, color_modes=RENDER_COLOR_MODES, default_color="shaded")
    r.add_argument("--frame", type=int, default=None, metavar="K",
                   help="frame of a result to draw (default: the last; -1 the last, -2 the one before)")
    r.add_argument("--frames", default=None, metavar="A:B",
                   help="frames A to B-1 (Python slice; A:B:STEP), as PNGs in --out DIR and/or a --movie")
    r.add_argument("--movie", default=None, metavar="FILE",
                   help="write the images as a movie: .mp4/.webm/.mkv/.mov (imageio + ffmpeg) or .gif (Pillow)")
    r.add_argument("--turntable", type=int, default=None, metavar="N",
                   help="N views with the camera turned once around the frame")
    r.add_argument("--fps", type=float, default=None, help="movie frame rate (default: the result's, else 24)")
    r.add_argument("--hair-color", default=None, metavar="COLOR",
                   help="hair colour for --color shaded: a name (brown, black, blonde, red, grey, white), "
                        "#rrggbb or r,g,b in [0, 1] (default: the file's colours, else brown)")
    r.add_argument("--out", default=None, help="PNG file (one image) or folder (a sequence)")
    r.add_argument("--quiet", action="store_true", help="no progress bar")
    r.add_argument("--arch", default="cpu", help="Taichi arch: cpu (default), cuda, gpu, vulkan")
    r.set_defaults(func=cmd_render)
