"""The results ``taichi-hair simulate`` writes, read back for a render or a look: every frame of the hair and
the bodies posed at each frame.

    res = load_result("out/hang")              # a simulate folder (frames.npz), a frames.npz,
    res = load_result("out/head_turn.usd")     # a USD file with time samples, a .thair.npz with
    g = res.groom(res.frame_count - 1)         # point_frames, or any groom file (one frame)
    body = res.body_meshes(k)                  # [(vertices (V, 3) [m], triangles (T, 3))] posed at frame k

Bodies come from ``frames.npz`` (``body_rotation``, ``body_translation``, ``collider_K_vertices`` /
``_faces`` / ``_body``) or, for a file output, from the ``<file>.bodies.npz`` written beside it.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from .errors import GroomFormatError


@dataclass
class SimulationResult:
    """Frames of a simulation (or one frame of a groom file).

    Attributes:
        positions: vertex positions of every frame [m], float32, shape (F, N, 3).
        strand_offsets: vertex offsets of the strands, int64, shape (S + 1,).
        fps: frames per second [1/s] (0 when unknown).
        radius: per-strand radius [m], shape (S,), or None.
        color: per-strand (S, 3) or per-vertex (N, 3) RGB in [0, 1], or None.
        body_rotation: (F, B, 3, 3) [-] or None; body_translation: (F, B, 3) [m] or None.
        meshes: [(vertices (V, 3) [m, body frame], triangles (T, 3), body index (-1: static world))].
        sphere_radius: the hairball's ball (a sphere of this radius [m] about the origin), 0 when none.
        contact_state: per frame and vertex 0 free, 1 sticking, 2 sliding, -1 unknown [-], int8, shape (F, N),
            or None (a run without contacts, or a file output).
        source: the path read.
    """

    positions: np.ndarray
    strand_offsets: np.ndarray
    fps: float = 0.0
    radius: np.ndarray | None = None
    color: np.ndarray | None = None
    region: np.ndarray | None = None
    body_rotation: np.ndarray | None = None
    body_translation: np.ndarray | None = None
    meshes: list = field(default_factory=list)
    sphere_radius: float = 0.0
    contact_state: np.ndarray | None = None
    source: str = ""

    @property
    def frame_count(self) -> int:
        return int(self.positions.shape[0])

    def groom(self, k: int):
        """Frame ``k`` as a :class:`~taichi_hair.io.groom.Groom` (the file's radii and colours)."""
        from .groom import Groom

        return Groom(points=np.ascontiguousarray(self.positions[k], np.float32), strand_offsets=self.strand_offsets,
                     radius=self.radius, color=self.color, region=self.region, units="m")

    def body_meshes(self, k: int) -> list:
        """Every body mesh posed at frame ``k``: [(vertices (V, 3) [m], triangles (T, 3))]."""
        out = []
        for v, f, body in self.meshes:
            v = np.asarray(v, np.float64)
            if body >= 0 and self.body_rotation is not None and body < self.body_rotation.shape[1]:
                R, T = self.body_rotation[k, body], self.body_translation[k, body]
                v = v @ R.T + T
            out.append((v, np.asarray(f, np.int64)))
        return out


def _bodies_from(data) -> dict:
    out = {}
    if "body_rotation" in data and "body_translation" in data:
        out["body_rotation"] = np.asarray(data["body_rotation"], np.float64)
        out["body_translation"] = np.asarray(data["body_translation"], np.float64)
    meshes, k = [], 0
    keys = set(data.keys()) if hasattr(data, "keys") else set(data.files)
    for key in sorted(keys):
        if key.startswith("collider_") and key.endswith("_vertices"):
            k = key[len("collider_"):-len("_vertices")]
            meshes.append((np.asarray(data[key]), np.asarray(data[f"collider_{k}_faces"]),
                           int(data[f"collider_{k}_body"])))
    out["meshes"] = meshes
    return out


def _frames_npz(path: str) -> SimulationResult:
    try:
        data = np.load(path)
    except (OSError, ValueError) as exc:
        raise GroomFormatError(path, f"cannot read ({exc})") from None
    need = ("positions", "strand_vertex_start", "strand_vertex_count")
    missing = [k for k in need if k not in data.files]
    if missing:
        raise GroomFormatError(path, f"not a simulate frames file (no {missing[0]!r})")
    pos = np.asarray(data["positions"], np.float32)
    start, count = np.asarray(data["strand_vertex_start"], np.int64), np.asarray(data["strand_vertex_count"], np.int64)
    if pos.ndim != 3 or pos.shape[2] != 3 or pos.shape[0] < 1:
        raise GroomFormatError(path, f"'positions' must have the shape (frames, vertices, 3), got {pos.shape}")
    off = np.r_[start, start[-1] + count[-1]] if start.size else np.zeros(1, np.int64)
    if not (np.array_equal(start, off[:-1]) and off[-1] == pos.shape[1] and np.all(count >= 2)):
        raise GroomFormatError(path, "the strands do not tile the vertices (strand_vertex_start / _count)")
    extra = _bodies_from(data)
    if "vertex_contact_state" in data.files:
        cst = np.asarray(data["vertex_contact_state"])
        if cst.shape != pos.shape[:2]:
            raise GroomFormatError(path, f"'vertex_contact_state' must have the shape {pos.shape[:2]}, got {cst.shape}")
        extra["contact_state"] = cst.astype(np.int8)
    return SimulationResult(positions=pos, strand_offsets=off, fps=float(data["fps"]) if "fps" in data.files else 0.0,
                            sphere_radius=float(data["sphere_radius"]) if "sphere_radius" in data.files else 0.0,
                            source=path, **extra)


def sidecar_bodies_path(path: str) -> str:
    """``<file>.bodies.npz`` beside a file output (``out.usd`` -> ``out.usd.bodies.npz``: the whole file name, so
    outputs with the same stem keep their own)."""
    return path + ".bodies.npz"


def _legacy_sidecar_bodies_path(path: str) -> str:
    """Where results written before the whole-name rule kept it (``out.usd`` -> ``out.bodies.npz``)."""
    low = path.lower()
    base = path[: -len(".thair.npz")] if low.endswith(".thair.npz") else os.path.splitext(path)[0]
    return base + ".bodies.npz"


def load_result(path) -> SimulationResult:
    """Read a simulation result or a groom file (see the module docstring).

    Raises:
        GroomFormatError: naming the path and what is wrong.
    """
    path = os.fspath(path)
    if os.path.isdir(path):
        f = os.path.join(path, "frames.npz")
        if not os.path.isfile(f):
            raise GroomFormatError(path, "is a folder without frames.npz (not a taichi-hair simulate output)")
        return _frames_npz(f)
    if not os.path.exists(path):
        raise GroomFormatError(path, "no such file or folder")
    if path.lower().endswith(".npz") and not path.lower().endswith(".thair.npz"):
        with np.load(path) as probe:
            if "positions" in probe.files:
                return _frames_npz(path)
    from . import load_groom

    g = load_groom(path)
    frames = g.point_frames if g.point_frames is not None and len(g.point_frames) else g.points[None]
    extra = {}
    side = sidecar_bodies_path(path)
    if not os.path.isfile(side):
        side = _legacy_sidecar_bodies_path(path)
    if os.path.isfile(side):
        with np.load(side) as data:
            extra = _bodies_from(data)
    fps = float(g.params.get("fps", 0.0)) if isinstance(g.params, dict) else 0.0
    return SimulationResult(positions=np.asarray(frames, np.float32), strand_offsets=g.strand_offsets, fps=fps,
                            radius=g.radius, color=g.color, region=g.region, source=path, **extra)
