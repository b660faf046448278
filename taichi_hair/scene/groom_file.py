"""A scene made from a groom file alone: ``taichi-hair simulate GROOM_FILE [--units] [--up] [--body MESH]
[--animation ...]`` without writing a TOML first.

The scene is the TOML scene the options describe (:mod:`taichi_hair.scene.file`), built from the same
tables, so a scene file with the same keys gives the same run:

    [groom]      file = GROOM_FILE, units = UNITS, up = UP            (roots clamped to body 0)
    [[colliders]] type = "mesh", file = MESH, units = BODY_UNITS or UNITS, up = UP, body = 0
    [[bodies]]   preset = "still" | "nod" | "head_turn", pivot = the neck; or the [[bodies]] of a TOML file

Choices where the papers and the issue are silent (written here and in ``simulate --help``):

* The body's units follow the groom's unless ``body_units`` is given: a groom and the head it was made on
  share their units in every public asset tried (TressFX, CT2Hair, Blender's Sintel).
* The pivot of ``nod`` and ``turn`` is "the neck": the centre of the body's bounding box in x and z at its
  lowest y (without a body, the roots' bounding box).  A keyframes file sets its own ``pivot``.
* The ADMM solver at its defaults, hair-hair contacts off (``hair_hair=True`` turns them on at the
  hairball's settings: friction 0.2, 2 + 10 projection sweeps); the body's friction 0.3.
"""

from __future__ import annotations

import os

import numpy as np

from .schema import SceneError
from .setup import MESH_EXTENSIONS, UNITS, UP_AXES

#: ``animation`` values besides a TOML file of ``[[bodies]]`` tables.
ANIMATIONS = ("still", "nod", "turn")


def _neck_pivot(points: np.ndarray) -> list:
    """The centre of the points' bounding box in x and z at their lowest y [m]."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    return [float(0.5 * (lo[0] + hi[0])), float(lo[1]), float(0.5 * (lo[2] + hi[2]))]


def _bodies_from_file(path: str) -> list:
    from .file import read_toml

    bodies = read_toml(path, "the animation").get("bodies")
    if not isinstance(bodies, list) or not bodies:
        raise SceneError(f"{path}: an animation file needs [[bodies]] tables (a preset or keys; see "
                         "taichi_hair.scene.file)")
    return bodies


def groom_file_tables(groom_path: str, units: str | None = None, scale: float | None = None, up: str = "y",
                      body: str | None = None, body_units: str | None = None, animation: str = "still",
                      hair_hair: bool = False) -> dict:
    """The tables of the scene file that the options describe (see the module docstring).

    Raises:
        SceneError: a missing file or a bad option value (one line naming it).
    """
    if not os.path.isfile(groom_path):
        raise SceneError(f"{groom_path}: no such groom file")
    if units is not None and units not in UNITS:
        raise SceneError(f"--units must be one of {', '.join(UNITS)}, got {units!r}")
    if units is not None and scale is not None:
        raise SceneError("give --units or --scale, not both")
    if body_units is not None and body_units not in UNITS:
        raise SceneError(f"--body-units must be one of {', '.join(UNITS)}, got {body_units!r}")
    if up not in UP_AXES:
        raise SceneError(f"--up must be 'y' or 'z', got {up!r}")
    groom = {"file": os.path.abspath(groom_path), "up": up}
    if scale is not None:
        groom["scale"] = scale
    elif units is not None:
        groom["units"] = units
    data = {"scene": {"name": os.path.basename(groom_path).split(".")[0]}, "groom": groom}
    if body is not None:
        if not os.path.isfile(body):
            raise SceneError(f"{body}: no such body mesh")
        if not body.lower().endswith(MESH_EXTENSIONS):
            raise SceneError(f"{body}: not a body mesh this reads (extensions: {', '.join(MESH_EXTENSIONS)})")
        col = {"type": "mesh", "file": os.path.abspath(body), "up": up, "body": 0}
        if body_units is not None:
            col["units"] = body_units
        elif scale is not None:
            col["scale"] = scale
        elif units is not None:
            col["units"] = units
        data["colliders"] = [col]
    if hair_hair:
        data["solver"] = {"contacts": {"friction": 0.2, "hair_hair": True, "projection_iterations": 2,
                                       "correction_iterations": 10}}
    if animation in ANIMATIONS:
        data["bodies"] = [{"preset": {"turn": "head_turn"}.get(animation, animation)}]
    elif animation.lower().endswith(".toml"):
        data["bodies"] = _bodies_from_file(animation)
    else:
        raise SceneError(f"--animation must be one of {', '.join(ANIMATIONS)} or a .toml file of [[bodies]] "
                         f"tables, got {animation!r}")
    return data


def scene_from_groom_file(groom_path: str, overrides: dict | None = None, **options):
    """A :class:`~taichi_hair.scene.file.Scene` for a groom file (options: :func:`groom_file_tables`)."""
    from .file import mesh_box, scene_from_data

    data = groom_file_tables(groom_path, **options)
    neck = [k for k, b in enumerate(data["bodies"]) if "keys" not in b and "pivot" not in b]
    scene = scene_from_data(data, groom_path, os.getcwd(), overrides)
    if neck:  # the presets turn about the neck, known once the groom and the body are in metres
        mesh = next((c for c in scene.colliders if getattr(c, "sdf", None) is not None), None)
        if mesh is not None:  # the mesh's bounding box
            pts = np.array(mesh_box(mesh))
        else:
            pts = np.asarray(scene.groom.points, np.float64)[scene.groom.strand_offsets[:-1]]
        pivot = _neck_pivot(pts)
        for k in neck:
            scene.bodies[k].pivot = tuple(pivot)
            scene.bodies[k].description["pivot"] = pivot
            scene.description["bodies"][k] = scene.bodies[k].description
    return scene
