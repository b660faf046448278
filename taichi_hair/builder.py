"""GroomBuilder: strands from NumPy polylines, validated, then ``finalize()`` allocates every field once.

The input shape *is* the rest shape: rest lengths, Voronoi lengths, rest
frames (space-parallel transported from the root) and hence rest curvatures
and twists are computed from it, so a groom's curls are its rest state.
"""

from __future__ import annotations


import numpy as np

from .config import RodMaterial
from .model import Model

ROOT_MODES = ("clamped", "free")


def _root_directors(t0: np.ndarray, given, first: int) -> np.ndarray:
    """Unit root directors d1 of k strands, perpendicular to their unit root tangents t0 (k, 3): ``given``
    (k, 3) made perpendicular, or, when None, a stable perpendicular of t0.  One code path for
    :meth:`GroomBuilder.add_strand` and :meth:`GroomBuilder.add_strands`, so the two give the same bits
    (numpy may round a scalar dot product and a row sum differently).  ``first``: index of the first strand,
    for the message."""
    if given is None:
        a = np.where((np.abs(t0[:, 2]) < 0.9)[:, None], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
        d1 = np.cross(t0, a)
        return d1 / np.linalg.norm(d1, axis=1)[:, None]
    d1 = np.array(given, dtype=np.float64).reshape(t0.shape[0], 3)
    d1 = d1 - np.sum(d1 * t0, axis=1)[:, None] * t0
    n = np.linalg.norm(d1, axis=1)
    bad = np.nonzero(~np.isfinite(n) | (n < 1e-6))[0]
    if bad.size:
        raise ValueError(f"strand {first + int(bad[0])}: field 'root_director' must be finite and not "
                         "parallel to the root edge")
    return d1 / n[:, None]


def _transport(u: np.ndarray, t0: np.ndarray, t1: np.ndarray) -> np.ndarray:
    b = np.cross(t0, t1)
    c = float(np.dot(t0, t1))
    return c * u + np.cross(b, u) + (np.dot(b, u) / (1.0 + c)) * b


def space_parallel_directors(tangent: np.ndarray, starts: np.ndarray, counts: np.ndarray,
                             root_directors: np.ndarray) -> np.ndarray:
    """Rest reference directors: the root director of each strand space-parallel transported along it,
    advanced one local index at a time for all strands at once (float64).

    Args:
        tangent: (n, 3) unit edge tangents (ghost slots ignored).  starts, counts: (k,) strand layout.
        root_directors: (k, 3) unit directors of the root edges, perpendicular to them.
    Returns (n, 3) directors (zero on ghost slots)."""
    n = tangent.shape[0]
    dirs = np.zeros((n, 3))
    dirs[starts] = root_directors
    for j in range(1, int(counts.max()) - 1):
        idx = starts[counts - 1 > j] + j
        t0, t1, u = tangent[idx - 1], tangent[idx], dirs[idx - 1]
        b = np.cross(t0, t1)
        c = np.sum(t0 * t1, axis=1)
        d = c[:, None] * u + np.cross(b, u) + (np.sum(b * u, axis=1) / (1.0 + c))[:, None] * b
        d -= np.sum(d * t1, axis=1)[:, None] * t1
        dirs[idx] = d / np.linalg.norm(d, axis=1)[:, None]
    return dirs


def points_array(points, what: str, rows: str = "n") -> np.ndarray:
    """``points`` as a float64 (rows, 3) array, or a ValueError starting with ``what`` (e.g.
    "strand 3: field 'points'")."""
    try:
        pts = np.array(points, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{what} is not a numeric array ({exc})") from None
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"{what} must have shape ({rows}, 3), got {pts.shape}")
    return pts


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
        # Strands are kept in chunks (one per add_strand / add_strands call), each as flat arrays:
        # points (n, 3) [m], per-strand vertex counts (k,), materials (k,), bodies (k,),
        # rest twists (n,) [rad] and root directors (k, 3).
        self._points: list[np.ndarray] = []
        self._counts: list[np.ndarray] = []
        self._materials: list[RodMaterial] = []
        self._bodies: list[np.ndarray] = []
        self._twists: list[np.ndarray] = []
        self._directors: list[np.ndarray] = []
        self._strand_count = 0

    @property
    def strand_count(self) -> int:
        return self._strand_count

    def _material(self, where: str, material) -> RodMaterial:
        if material is None:
            return RodMaterial()
        if isinstance(material, dict):
            try:
                return RodMaterial(**material)
            except (TypeError, ValueError) as exc:
                raise ValueError(f"{where}: field 'material': {exc}") from None
        if not isinstance(material, RodMaterial):
            raise ValueError(f"{where}: field 'material' must be a RodMaterial or dict, got {type(material).__name__}")
        try:  # re-validate: the dataclass may have been mutated after construction
            material.__post_init__()
        except ValueError as exc:
            raise ValueError(f"{where}: field 'material': {exc}") from None
        return material

    def _root_body(self, where: str, root: str, body) -> int:
        if root not in ROOT_MODES:
            raise ValueError(f"{where}: field 'root' must be one of {ROOT_MODES}, got {root!r}")
        if root == "clamped":
            if not (isinstance(body, (int, np.integer)) and 0 <= body < self.body_count):
                raise ValueError(f"{where}: field 'body' must be in [0, {self.body_count}), got {body!r}")
            return int(body)
        return -1

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
        pts = points_array(points, f"{where}: field 'points'", "m")
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
        material = self._material(where, material)
        body = self._root_body(where, root, body)
        if twist is None:
            tw = np.zeros(m)
        else:
            tw = np.asarray(twist, dtype=np.float64).reshape(-1)
            if tw.shape[0] != m or not np.all(np.isfinite(tw)):
                raise ValueError(f"{where}: field 'twist' must hold {m} finite angles")
            tw = tw.copy()
            tw[-1] = 0.0
        t0 = (pts[1:2] - pts[0:1]) / lengths[0]
        d1 = _root_directors(t0, None if root_director is None else np.reshape(root_director, (1, 3)), idx)[0]
        self._points.append(pts)
        self._counts.append(np.array([m], dtype=np.int64))
        self._materials.append(material)
        self._bodies.append(np.array([body], dtype=np.int32))
        self._twists.append(tw)
        self._directors.append(d1[None, :])
        self._strand_count += 1
        return idx

    def add_strands(self, points, offsets, material: RodMaterial | dict | None = None, root: str = "clamped",
                    body: int = 0, twist=None, root_directors=None) -> np.ndarray:
        """Add many strands at once (vectorised); returns their indices.

        The same strands as :meth:`add_strand` called once per strand, and the same host arrays
        after :meth:`finalize`, bit for bit (tested), at a fraction of the cost for thousands.

        Args:
            points: (n, 3) vertices of all strands, each strand's root first [m].
            offsets: (k + 1,) start of each strand in ``points`` and n at the end (increasing).
            material, root, body: as :meth:`add_strand`, shared by the k strands.
            twist: optional (n,) rest twist angles [rad] (each strand's last entry is ignored).
            root_directors: optional (k, 3) root directors (see :meth:`add_strand`).

        Raises:
            ValueError naming the first bad strand (its index in this builder) and the field,
            as :meth:`add_strand` does.
        """
        first = self._strand_count
        where = f"strands {first}..: add_strands"
        pts = points_array(points, f"{where}: field 'points'")
        try:
            off = np.asarray(offsets).astype(np.int64, casting="safe").reshape(-1)
        except (TypeError, ValueError):
            raise ValueError(f"{where}: field 'offsets' must be integers, got {offsets!r}") from None
        if off.size < 2 or off[0] != 0 or off[-1] != pts.shape[0]:
            raise ValueError(f"{where}: field 'offsets' must start at 0 and end at the vertex count {pts.shape[0]}")
        counts = np.diff(off)
        ns = counts.size
        short = np.nonzero(counts < 3)[0]
        if short.size:
            k = int(short[0])
            raise ValueError(f"strand {first + k}: field 'points' has {int(counts[k])} vertices; "
                             "a strand needs at least 3")
        strand_of = np.repeat(np.arange(ns), counts)
        bad = np.nonzero(~np.all(np.isfinite(pts), axis=1))[0]
        if bad.size:
            v = int(bad[0])
            k = int(strand_of[v])
            raise ValueError(f"strand {first + k}: field 'points' has a non-finite coordinate at vertex "
                             f"{v - int(off[k])}")
        # Edge lengths on a padded (k, max edges) grid (NaN beyond each strand), as add_strand per strand.
        lengths = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        local = np.arange(pts.shape[0]) - off[strand_of]
        edge = np.nonzero(local[:-1] < np.repeat(counts - 1, counts)[:-1])[0]  # edge slots inside a strand
        grid = np.full((ns, int(counts.max()) - 1), np.nan)
        grid[strand_of[edge], local[edge]] = lengths[edge]
        median = np.nanmedian(grid, axis=1)
        tiny = np.nonzero((grid == 0) | (grid <= 1e-6 * median[:, None]))
        if tiny[0].size:
            k, j = int(tiny[0][0]), int(tiny[1][0])
            raise ValueError(f"strand {first + k}: field 'points' has a zero-length edge between vertices {j} and "
                             f"{j + 1} (repeated point)")
        material = self._material(where, material)
        body = self._root_body(where, root, body)
        if twist is None:
            tw = np.zeros(pts.shape[0])
        else:
            tw = np.array(twist, dtype=np.float64).reshape(-1)
            if tw.shape[0] != pts.shape[0] or not np.all(np.isfinite(tw)):
                raise ValueError(f"{where}: field 'twist' must hold {pts.shape[0]} finite angles")
            tw[off[1:] - 1] = 0.0
        t0 = (pts[off[:-1] + 1] - pts[off[:-1]]) / lengths[off[:-1]][:, None]
        d1 = _root_directors(t0, root_directors, first)
        self._points.append(pts)
        self._counts.append(counts)
        self._materials.extend([material] * ns)
        self._bodies.append(np.full(ns, body, dtype=np.int32))
        self._twists.append(tw)
        self._directors.append(d1)
        self._strand_count += ns
        return np.arange(first, first + ns)

    @classmethod
    def merged(cls, builders: list) -> "GroomBuilder":
        """One builder holding the strands of ``builders`` one after the other (their body counts equal):
        its Model's host arrays are theirs concatenated, strand for strand (``host_arrays`` is per strand
        and per vertex), which is what packing several runs into one Model relies on (cli/simulate_pack.py)."""
        if not builders:
            raise ValueError("GroomBuilder.merged: no builders")
        body_counts = {b.body_count for b in builders}
        if len(body_counts) != 1:
            raise ValueError(f"GroomBuilder.merged: the builders have different body counts {sorted(body_counts)}")
        out = cls(body_count=builders[0].body_count)
        for b in builders:
            for name in ("_points", "_counts", "_materials", "_bodies", "_twists", "_directors"):
                getattr(out, name).extend(getattr(b, name))
            out._strand_count += b._strand_count
        return out

    # ------------------------------------------------------------------ finalize
    def finalize(self) -> Model:
        """Compute the rest state in float64 (vectorised over strands) and allocate every field once."""
        return Model(*self.host_arrays())

    def host_arrays(self) -> tuple:
        """(host, materials, body_count) of the Model ``finalize`` makes, computed in float64 (vectorised over
        strands) without allocating any field."""
        if not self._points:
            raise ValueError("GroomBuilder.finalize: no strands were added")
        counts = np.concatenate(self._counts)
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        n = int(counts.sum())
        from .io.sizing import BYTES_PER_VERTEX, check_fits

        # The Model with the State and solver that will follow it (measured per vertex, io/sizing.py), before
        # any field is allocated.
        check_fits(float(n) * BYTES_PER_VERTEX, f"GroomBuilder.finalize: a Model of {n:,} vertices",
                   "use fewer strands or vertices per strand")
        ns = self._strand_count
        mats = self._materials
        strand_of = np.repeat(np.arange(ns), counts)
        local = np.arange(n) - np.repeat(starts, counts)
        last = local == np.repeat(counts - 1, counts)  # ghost edge slots
        pts = np.concatenate(self._points)

        # Per-strand material values, evaluated once per distinct material object (bulk strands share one).
        slot: dict = {}
        which = np.array([slot.setdefault(id(m), len(slot)) for m in mats], dtype=np.int64)
        distinct = list({id(m): m for m in mats}.values())

        def per_strand(values):
            return np.array(values, dtype=np.float64)[which]

        area = per_strand([m.area for m in distinct])
        density = per_strand([m.density for m in distinct])
        e_stretch = per_strand([m.youngs_modulus_stretch for m in distinct])
        e_bend = per_strand([m.youngs_modulus_bend for m in distinct])
        polar = per_strand([m.polar_inertia for m in distinct])
        radius = per_strand([m.radius for m in distinct])
        kdiag = np.array([m.stiffness_matrix_diag() for m in distinct], dtype=np.float64)[which]
        damping = per_strand([m.damping_time for m in distinct])
        bodies = np.concatenate(self._bodies)

        # Edges (slot i joins i and i+1; the last slot of each strand is a ghost).
        edge = np.zeros((n, 3))
        edge[:-1] = pts[1:] - pts[:-1]
        edge[last] = 0.0
        le = np.linalg.norm(edge, axis=1)
        tangent = np.zeros((n, 3))
        tangent[~last] = edge[~last] / le[~last, None]
        # Voronoi lengths: half of each adjacent edge.
        vor = 0.5 * le
        prev_le = np.zeros(n)
        prev_le[1:] = le[:-1]
        prev_le[local == 0] = 0.0
        vor = vor + 0.5 * prev_le
        interior = (local > 0) & ~last
        sA = area[strand_of]

        root_dirs = np.concatenate(self._directors)
        dirs = space_parallel_directors(tangent, starts, counts, root_dirs)

        clamped = bodies[strand_of] >= 0
        fixed_vertex = clamped & (local <= 1)
        h = {
            "vertex_mass": density[strand_of] * sA * vor,
            "vertex_voronoi_length": vor,
            "vertex_strand": strand_of.astype(np.int32),
            "vertex_local_index": local.astype(np.int32),
            "vertex_is_fixed": fixed_vertex.astype(np.int32),
            "vertex_body_position": np.where(fixed_vertex[:, None], pts, 0.0),
            "vertex_rest_position": pts,
            "edge_rest_length": le,
            "edge_stretch_stiffness": e_stretch[strand_of] * sA * le,
            "edge_rotational_inertia": density[strand_of] * polar[strand_of] * le,
            "edge_is_fixed": (last | (clamped & (local == 0))).astype(np.int32),
            "edge_rest_director": dirs,
            "edge_rest_twist": np.concatenate(self._twists),
            "edge_rest_tangent": tangent,
            "pair_is_active": interior.astype(np.int32),
            "pair_bending_modulus": np.where(interior[:, None], e_bend[strand_of, None] * kdiag[strand_of], 0.0),
            "pair_bending_rigidity": np.where(interior, e_bend[strand_of] * sA * radius[strand_of] ** 2 / 4.0, 0.0),
            "strand_vertex_start": starts.astype(np.int32),
            "strand_vertex_count": counts.astype(np.int32),
            "strand_body": bodies,
            "strand_root_director": root_dirs,
            "strand_damping_time": damping,
            # Host-only per-strand material summary.
            "strand_radius": radius, "strand_density": density, "strand_area": area,
            "strand_youngs_modulus_bend": e_bend,
        }
        return h, list(mats), self.body_count
