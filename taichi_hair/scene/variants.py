"""Procedural edits (Daviet 2023, Sec. 5.3): variants of one base groom from sequences of basic actions.

Each variant is a seeded random sequence of ``VariantConfig.actions`` basic actions, applied inside one
running quasistatic :class:`~taichi_hair.groom.session.GroomingSession` (``frames`` frames after each action):

* ``force``: an animated external force -- a region is selected and dragged toward a target that moves
  linearly from 0 to a random offset over ``frames`` frames; the dragged vertices are then pinned where
  the force left them (a clip) and released, so the edit survives in the saved groom;
* ``grow``: the region's strands get ``scale_length`` by a factor in [1.1, 1.5];
* ``curl``: the region's rest curvature is scaled by a factor in [0.3, 2.0] (``scale_curl``);
* ``trim``: a plane whose normal is tilted at most 30 degrees from up, at the height below which a
  fraction in [5 %, 30 %] of the vertices lie, cuts the strands crossing it.

A region is every strand within a radius (15-35 % of the groom's size) of a point on a random strand.
All variants share one session and one Model: after a variant is written, undo brings the groom back to
the base bit for bit, and the next variant's edits update the Model in place (no recompilation).  Each
variant's actions are written as a session file that :meth:`GroomingSession.replay` reproduces on the
base groom.  Thumbnails are rendered off screen (:mod:`taichi_hair.render`) and tiled in a contact sheet.
"""

from __future__ import annotations

import json
import math
import os
import time
from dataclasses import dataclass

import numpy as np

BASIC_ACTIONS = ("force", "grow", "curl", "trim")


@dataclass
class VariantConfig:
    """Settings of :func:`make_variants`.

    Attributes:
        count: number of variants [-].
        seed: seed of the random action sequences (variant k uses ``default_rng([seed, k])``) [-].
        actions: basic actions per variant [-].
        frames: quasistatic frames run after each action (and over which a force is animated) [-].
        thumbnail: (width, height) of each thumbnail [pixels].
        columns: thumbnails per row of the contact sheet; 0 picks ceil(sqrt(count)) [-].
        kinds: the basic actions drawn from (a subset of ``BASIC_ACTIONS``).
    """

    count: int = 8
    seed: int = 0
    actions: int = 3
    frames: int = 6
    thumbnail: tuple = (240, 240)
    columns: int = 0
    kinds: tuple = BASIC_ACTIONS

    def __post_init__(self):
        for name, lo in (("count", 1), ("actions", 1), ("frames", 1), ("columns", 0), ("seed", 0)):
            v = getattr(self, name)
            if not (isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= lo):
                raise ValueError(f"VariantConfig.{name} must be an integer >= {lo}, got {v!r}")
        t = tuple(self.thumbnail)
        if len(t) != 2 or not all(isinstance(x, (int, np.integer)) and 16 <= x <= 2048 for x in t):
            raise ValueError(f"VariantConfig.thumbnail must be two integers in [16, 2048] pixels, got {self.thumbnail!r}")
        self.thumbnail = (int(t[0]), int(t[1]))
        kinds = tuple(self.kinds)
        if not kinds or any(k not in BASIC_ACTIONS for k in kinds):
            raise ValueError(f"VariantConfig.kinds must be a non-empty subset of {BASIC_ACTIONS}, got {self.kinds!r}")
        self.kinds = kinds


def _region(session, rng) -> tuple[np.ndarray, float]:
    g = session.groom
    p = g.points.astype(np.float64)
    size = float(np.linalg.norm(p.max(axis=0) - p.min(axis=0)))
    s = int(rng.integers(g.strand_count))
    a, b = g.strand_offsets[s], g.strand_offsets[s + 1]
    centre = p[a + int(rng.integers(max(1, (b - a) // 3), b - a))]  # away from the (clamped) root
    return centre, size * float(rng.uniform(0.15, 0.35))


def apply_action(session, kind: str, rng, frames: int) -> dict:
    """Apply one basic action (see the module docstring) and run ``frames`` frames; returns what was done."""
    if kind == "trim":
        p = session.groom.points.astype(np.float64)
        tilt, az = math.radians(float(rng.uniform(0.0, 30.0))), float(rng.uniform(0.0, 2 * math.pi))
        normal = np.array([math.sin(tilt) * math.cos(az), math.cos(tilt), math.sin(tilt) * math.sin(az)])
        q = float(rng.uniform(0.05, 0.30))
        height = float(np.quantile(p @ normal, q))
        cut = session.trim((height * normal).tolist(), normal.tolist())
        session.advance(frames)
        return {"kind": kind, "normal": normal.tolist(), "quantile": q, "strands_cut": cut}
    centre, radius = _region(session, rng)
    count = session.select(centre.tolist(), radius)
    if kind == "grow":
        f = float(rng.uniform(1.1, 1.5))
        session.scale_length(f)
        session.advance(frames)
        return {"kind": kind, "factor": f, "strands": count}
    if kind == "curl":
        f = float(rng.uniform(0.3, 2.0))
        session.scale_curl(f)
        session.advance(frames)
        return {"kind": kind, "factor": f, "strands": count}
    # force: an animated drag, then clip (pin) the dragged vertices where they are.
    d = rng.normal(size=3)
    d /= np.linalg.norm(d)
    offset = d * radius * float(rng.uniform(0.5, 1.0))
    try:
        for k in range(1, frames + 1):
            session.drag((offset * k / frames).tolist(), stiffness=0.5)
            session.advance(1)
    except ValueError:  # nothing grabbable (only clamped roots in the region): a no-op action
        return {"kind": kind, "strands": 0}
    session.release()
    session.pin()
    session.advance(1)
    return {"kind": kind, "offset": offset.tolist(), "strands": count}


def contact_sheet(images: list, columns: int = 0, gap: int = 4, background=(24, 24, 28)) -> np.ndarray:
    """Tile (H, W, 3) uint8 images of one size in rows of ``columns`` (0: ceil(sqrt(n)))."""
    n = len(images)
    if n == 0:
        raise ValueError("contact_sheet: no image")
    h, w = images[0].shape[:2]
    cols = columns or int(math.ceil(math.sqrt(n)))
    rows = int(math.ceil(n / cols))
    sheet = np.empty((rows * h + (rows + 1) * gap, cols * w + (cols + 1) * gap, 3), dtype=np.uint8)
    sheet[:] = np.asarray(background, dtype=np.uint8)
    for i, img in enumerate(images):
        r, c = divmod(i, cols)
        y, x = gap + r * (h + gap), gap + c * (w + gap)
        sheet[y:y + h, x:x + w] = img
    return sheet


def make_variants(groom, config: VariantConfig, grooming_config=None, out_dir=".", head=None, colliders=None,
                  log=None) -> dict:
    """Write ``config.count`` variants of ``groom`` to ``out_dir`` and a contact sheet.

    Files: ``variant_KK.thair.npz`` (the edited groom with its rest pose, pins and parameters),
    ``variant_KK.session.json`` (its actions, replayable on the base groom), ``variant_KK.png``
    (thumbnail), ``contact_sheet.png`` (the base first, then the variants) and ``variants.json``.
    Taichi must be initialised.  ``head`` is an optional (vertices, triangles, ...) mesh for drawing.

    Returns:
        dict with ``variants`` (per variant: files, actions, seconds), ``contact_sheet``, ``seconds``.
    """
    from ..groom.session import GroomingSession
    from ..render import CameraConfig, ViewerGGUI, save_png, strand_colors

    from dataclasses import replace

    from ..groom.session import GroomingConfig

    t_start = time.perf_counter()
    os.makedirs(out_dir, exist_ok=True)
    cfg = grooming_config or GroomingConfig()
    # Every edit of a variant must stay undoable to get back to the base (a force is frames + 2 edits).
    cfg = replace(cfg, undo_limit=max(cfg.undo_limit, config.actions * (config.frames + 2) + 1), undo_memory_mb=0.0,
                  autosave_every=0)  # (every variant is undone back to the base groom: no snapshot may be dropped)
    session = GroomingSession(groom, cfg, colliders=colliders)
    w, h = config.thumbnail
    viewer = ViewerGGUI(w, h, show_window=False)
    pts = session.groom.points.astype(np.float64)
    if head is not None:
        viewer.set_head(head[0], head[1])
        pts = np.vstack([pts, np.asarray(head[0], np.float64)])
    viewer.set_camera(CameraConfig.framing(pts, direction=(0.55, 0.25, 1.0), fov=35.0, margin=0.9))

    def thumb(g):
        viewer.set_strands(g.points, g.strand_offsets, strand_colors(g, "region"))
        viewer.render()
        return viewer.image()

    try:
        images, variants = _run_variants(session, config, out_dir, thumb, log)
    finally:
        viewer.close()
    sheet_path = os.path.join(out_dir, "contact_sheet.png")
    save_png(sheet_path, contact_sheet(images, config.columns))
    result = {"variants": variants, "contact_sheet": sheet_path, "seconds": time.perf_counter() - t_start,
              "rebuilds": session.rebuild_count, "updates": session.update_count,
              "config": {"count": config.count, "seed": config.seed, "actions": config.actions,
                         "frames": config.frames, "kinds": list(config.kinds)}}
    with open(os.path.join(out_dir, "variants.json"), "w", encoding="utf-8") as fh:
        json.dump(result, fh, indent=1)
    return result


def _run_variants(session, config: VariantConfig, out_dir, thumb, log):
    """The variants' loop of :func:`make_variants`: returns (thumbnails, base first; per-variant records)."""
    from ..render import save_png

    images = [thumb(session.groom)]
    variants = []
    for k in range(config.count):
        t0 = time.perf_counter()
        rng = np.random.default_rng([config.seed, k])
        start_log, start_undo = len(session.log), len(session.history.undo_stack)
        done = [apply_action(session, str(rng.choice(config.kinds)), rng, config.frames)
                for _ in range(config.actions)]
        actions = session.log[start_log:]
        name = f"variant_{k:02d}"
        session.save(os.path.join(out_dir, name + ".thair.npz"))
        with open(os.path.join(out_dir, name + ".session.json"), "w", encoding="utf-8") as fh:
            fh.write("[\n" + ",\n".join(json.dumps(e) for e in actions) + "\n]\n")
        img = thumb(session.groom)
        save_png(os.path.join(out_dir, name + ".png"), img)
        images.append(img)
        while len(session.history.undo_stack) > start_undo:  # back to the base groom, bit for bit
            session.undo()
        entry = {"name": name, "actions": done, "seconds": time.perf_counter() - t0}
        variants.append(entry)
        if log is not None:
            log(f"{name}: " + ", ".join(a["kind"] for a in done) + f" ({entry['seconds']:.1f} s)")
    return images, variants

