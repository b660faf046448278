"""GroomBuilder: strands from NumPy polylines, validated, then ``finalize()`` allocates every field once.

The input shape *is* the rest shape: rest lengths, Voronoi lengths, rest
frames (space-parallel transported from the root) and hence rest curvatures
and twists are computed from it, so a groom's curls are its rest state.
"""

from __future__ import annotations

import math

import numpy as np

from .config import RodMaterial
from .model import Model

ROOT_MODES = ("clamped", "free")


def _perpendicular(t: np.ndarray) -> np.ndarray:
    """A unit vector perpendicular to unit t (stable choice)."""
    a = np.array([0.0, 0.0, 1.0]) if abs(t[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    d = np.cross(t, a)
    return d / np.linalg.norm(d)


def _transport(u: np.ndarray, t0: np.ndarray, t1: np.ndarray) -> np.ndarray:
    b = np.cross(t0, t1)
    c = float(np.dot(t0, t1))
    return c * u + np.cross(b, u) + (np.dot(b, u) / (1.0 + c)) * b


class GroomBuilder:
    """Collects strands, validates them, and builds a :class:`Model`.

    Example::

        b = GroomBuilder()
        b.add_strand(np.c_[np.linspace(0, .1, 41), np.zeros(41), np.zeros(41)], RodMaterial())
        model = b.finalize()
    """

    def __init__(self, body_count: int = 1):
        if not (isinstance(body_count, int) and body_count >= 1):
            raise ValueError(f"GroomBuilder.body_count must be an integer >= 1, got {body_count!r}")
        self.body_count = body_count
        self._points: list[np.ndarray] = []
        self._materials: list[RodMaterial] = []
        self._bodies: list[int] = []
        self._twists: list[np.ndarray] = []
        self._directors: list[np.ndarray] = []

    @property
    def strand_count(self) -> int:
        return len(self._points)

    def add_strand(self, points, material: RodMaterial | dict | None = None, root: str = "clamped",
                   body: int = 0, twist=None, root_director=None) -> int:
        """Add one strand; returns its index.

        Args:
            points: (m, 3) polyline, root first, m >= 3 [m].
            material: a :class:`RodMaterial` (or a dict of its fields); default human hair.
            root: ``"clamped"`` (root vertices 0, 1 and the root twist follow ``body``)
                or ``"free"``.
            body: index of the body the root is clamped to.
            twist: optional (m,) rest twist angles of the material frame about the
                space-parallel reference frame [rad]; the last entry (ghost edge) is ignored.
            root_director: optional unit vector d1 of the root edge (the major axis of an
                elliptic cross-section); default: any vector perpendicular to the root edge.

        Raises:
            ValueError naming the strand and the field for NaN/inf coordinates,
            repeated points, fewer than 3 vertices or bad material values.
        """
        idx = len(self._points)
        where = f"strand {idx}"
        try:
            pts = np.array(points, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{where}: field 'points' is not a numeric array ({exc})") from None
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise ValueError(f"{where}: field 'points' must have shape (m, 3), got {pts.shape}")
        m = pts.shape[0]
        if m < 3:
            raise ValueError(f"{where}: field 'points' has {m} vertices; a strand needs at least 3")
        bad = np.where(~np.all(np.isfinite(pts), axis=1))[0]
        if bad.size:
            raise ValueError(f"{where}: field 'points' has a non-finite coordinate at vertex {int(bad[0])}")
        lengths = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        # Repeated points: zero edges, or edges a million times shorter than the typical one.
        tiny = np.where((lengths == 0) | (lengths <= 1e-6 * float(np.median(lengths))))[0]
        if tiny.size:
            k = int(tiny[0])
            raise ValueError(
                f"{where}: field 'points' has a zero-length edge between vertices {k} and {k + 1} (repeated point)")
        if material is None:
            material = RodMaterial()
        elif isinstance(material, dict):
            try:
                material = RodMaterial(**material)
            except (TypeError, ValueError) as exc:
                raise ValueError(f"{where}: field 'material': {exc}") from None
        elif not isinstance(material, RodMaterial):
            raise ValueError(f"{where}: field 'material' must be a RodMaterial or dict, got {type(material).__name__}")
        else:
            try:  # re-validate: the dataclass may have been mutated after construction
                material.__post_init__()
            except ValueError as exc:
                raise ValueError(f"{where}: field 'material': {exc}") from None
        if root not in ROOT_MODES:
            raise ValueError(f"{where}: field 'root' must be one of {ROOT_MODES}, got {root!r}")
        if root == "clamped":
            if not (isinstance(body, (int, np.integer)) and 0 <= body < self.body_count):
                raise ValueError(f"{where}: field 'body' must be in [0, {self.body_count}), got {body!r}")
            body = int(body)
        else:
            body = -1
        if twist is None:
            tw = np.zeros(m)
        else:
            tw = np.asarray(twist, dtype=np.float64).reshape(-1)
            if tw.shape[0] != m or not np.all(np.isfinite(tw)):
                raise ValueError(f"{where}: field 'twist' must hold {m} finite angles")
            tw = tw.copy()
            tw[-1] = 0.0
        t0 = (pts[1] - pts[0]) / lengths[0]
        if root_director is None:
            d1 = _perpendicular(t0)
        else:
            d1 = np.asarray(root_director, dtype=np.float64).reshape(3)
            d1 = d1 - np.dot(d1, t0) * t0
            n = np.linalg.norm(d1)
            if not math.isfinite(n) or n < 1e-6:
                raise ValueError(f"{where}: field 'root_director' must be finite and not parallel to the root edge")
            d1 = d1 / n
        self._points.append(pts)
        self._materials.append(material)
        self._bodies.append(body)
        self._twists.append(tw)
        self._directors.append(d1)
        return idx

    # ------------------------------------------------------------------ finalize
    def finalize(self) -> Model:
        """Compute the rest state in float64 and allocate every Taichi field once."""
        if not self._points:
            raise ValueError("GroomBuilder.finalize: no strands were added")
        counts = np.array([p.shape[0] for p in self._points], dtype=np.int64)
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        n = int(counts.sum())
        ns = len(self._points)
        h = {
            "vertex_mass": np.zeros(n), "vertex_voronoi_length": np.zeros(n),
            "vertex_strand": np.zeros(n, np.int32), "vertex_local_index": np.zeros(n, np.int32),
            "vertex_is_fixed": np.zeros(n, np.int32), "vertex_body_position": np.zeros((n, 3)),
            "vertex_rest_position": np.zeros((n, 3)),
            "edge_rest_length": np.zeros(n), "edge_stretch_stiffness": np.zeros(n),
            "edge_rotational_inertia": np.zeros(n), "edge_is_fixed": np.zeros(n, np.int32),
            "edge_rest_director": np.zeros((n, 3)), "edge_rest_twist": np.zeros(n),
            "edge_rest_tangent": np.zeros((n, 3)),
            "pair_is_active": np.zeros(n, np.int32), "pair_bending_modulus": np.zeros((n, 3)),
            "pair_bending_rigidity": np.zeros(n),
            "strand_vertex_start": starts.astype(np.int32), "strand_vertex_count": counts.astype(np.int32),
            "strand_body": np.array(self._bodies, np.int32), "strand_root_director": np.zeros((ns, 3)),
            "strand_damping_time": np.zeros(ns),
            # Host-only per-strand material summary.
            "strand_radius": np.zeros(ns), "strand_density": np.zeros(ns), "strand_area": np.zeros(ns),
            "strand_youngs_modulus_bend": np.zeros(ns),
        }
        for s, (pts, mat, body, tw, d1) in enumerate(
                zip(self._points, self._materials, self._bodies, self._twists, self._directors)):
            a, m = int(starts[s]), int(counts[s])
            sl = slice(a, a + m)
            edges = np.diff(pts, axis=0)
            le = np.linalg.norm(edges, axis=1)
            t = edges / le[:, None]
            vor = np.zeros(m)
            vor[:-1] += 0.5 * le
            vor[1:] += 0.5 * le
            A = mat.area
            Kd = np.array(mat.stiffness_matrix_diag())
            h["vertex_mass"][sl] = mat.density * A * vor
            h["vertex_voronoi_length"][sl] = vor
            h["vertex_strand"][sl] = s
            h["vertex_local_index"][sl] = np.arange(m)
            h["vertex_rest_position"][sl] = pts
            h["edge_rest_length"][a:a + m - 1] = le
            h["edge_stretch_stiffness"][a:a + m - 1] = mat.youngs_modulus_stretch * A * le
            h["edge_rotational_inertia"][a:a + m - 1] = mat.density * mat.polar_inertia * le
            h["edge_is_fixed"][a + m - 1] = 1  # ghost edge
            h["edge_rest_tangent"][a:a + m - 1] = t
            h["edge_rest_twist"][sl] = tw
            # Space-parallel transport of the root director gives the rest reference frames.
            dirs = np.zeros((m, 3))
            dirs[0] = d1
            for j in range(1, m - 1):
                dj = _transport(dirs[j - 1], t[j - 1], t[j])
                dj -= np.dot(dj, t[j]) * t[j]
                dirs[j] = dj / np.linalg.norm(dj)
            h["edge_rest_director"][sl] = dirs
            h["pair_is_active"][a + 1:a + m - 1] = 1
            h["pair_bending_modulus"][a + 1:a + m - 1] = mat.youngs_modulus_bend * Kd
            h["pair_bending_rigidity"][a + 1:a + m - 1] = mat.youngs_modulus_bend * A * mat.radius**2 / 4.0
            h["strand_root_director"][s] = d1
            h["strand_damping_time"][s] = mat.damping_time
            h["strand_radius"][s] = mat.radius
            h["strand_density"][s] = mat.density
            h["strand_area"][s] = A
            h["strand_youngs_modulus_bend"][s] = mat.youngs_modulus_bend
            if body >= 0:
                h["vertex_is_fixed"][a:a + 2] = 1
                h["vertex_body_position"][a:a + 2] = pts[:2]
                h["edge_is_fixed"][a] = 1
        return Model(h, list(self._materials), self.body_count)
