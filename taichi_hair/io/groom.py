"""Groom: a file-format-neutral set of hair strands, as flat NumPy arrays.

Strand ``s`` owns ``points[strand_offsets[s]:strand_offsets[s + 1]]``, root
first.  Every array is documented with its unit and shape below; lengths are in
the groom's ``units`` (metres once a reader was given the right ``scale``).
Floating-point data keeps the dtype it was read with (float32 for every binary
format), so reading then writing a file in the same format is bit-exact.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, fields, replace

import numpy as np


def _per(name: str, arr: np.ndarray, strands: int, vertices: int, width: int | None) -> str:
    """'strand' or 'vertex': the granularity of a per-strand-or-per-vertex array (raises on a bad shape)."""
    shape_tail = () if width is None else (width,)
    if arr.shape == (strands,) + shape_tail:
        return "strand"
    if arr.shape == (vertices,) + shape_tail:
        return "vertex"
    want = f"({strands}{', ' + str(width) if width else ''}) per strand or " \
           f"({vertices}{', ' + str(width) if width else ''}) per vertex"
    raise ValueError(f"Groom: field '{name}' has shape {arr.shape}; expected {want}")


#: Vertices converted to float64 at a time by :func:`strand_lengths` (bounds its temporary memory).
LENGTH_CHUNK_VERTICES = 1 << 15


def strand_lengths(points: np.ndarray, strand_offsets: np.ndarray, first: int = 0, last: int | None = None,
                   chunk: int = LENGTH_CHUNK_VERTICES) -> np.ndarray:
    """Arc length of strands ``first:last`` [units], float64, shape (last - first,).

    Works through the vertices ``chunk`` at a time (float64 differences of that many points), so the
    temporary memory is O(chunk) whatever the groom's size; the sums run in vertex order."""
    off = np.asarray(strand_offsets, dtype=np.int64)
    last = off.shape[0] - 1 if last is None else int(last)
    sub = off[first:last + 1]
    out = np.zeros(max(last - first, 0))
    v0, v1 = int(sub[0]), int(sub[-1])
    for e0 in range(v0, v1 - 1, chunk):
        e1 = min(e0 + chunk, v1 - 1)  # edges e0 .. e1 - 1; edge e joins vertices e and e + 1
        p = np.asarray(points[e0:e1 + 1], dtype=np.float64)
        d = p[1:] - p[:-1]
        seg = np.sqrt(np.einsum("ij,ij->i", d, d))
        lo, hi = np.searchsorted(sub, [e0, e1 - 1], side="right") - 1  # strands of the first and last edge
        joins = sub[lo + 1:hi + 2] - 1 - e0  # the fake edges joining a tip to the next root
        seg[joins[joins < e1 - e0]] = 0.0
        starts = sub[lo:hi + 1] - e0  # strictly increasing (a strand has >= 1 edge), the first clipped to 0
        starts[0] = 0
        out[lo:hi + 1] += np.add.reduceat(seg, starts)
    return out


@dataclass
class Groom:
    """Hair strands as polylines, with optional per-strand / per-vertex attributes.

    Attributes:
        points: vertex positions [units], shape (N, 3), float32 or float64,
            strands stored one after another, root first.
        strand_offsets: int64, shape (S + 1,), ``strand_offsets[0] == 0`` and
            ``strand_offsets[-1] == N``; strand s owns vertices
            ``strand_offsets[s]:strand_offsets[s + 1]`` (at least 2 each).
        radius: fibre radius [units], shape (S,) per strand or (N,) per vertex, or None.
        color: linear RGB in [0, 1] (not enforced), float32, shape (S, 3) or (N, 3), or None.
        region: integer region / clump / part id, int32, shape (S,), or None.
        guide: True for a guide (simulated) strand, bool, shape (S,), or None.
        rest_points: rest pose [units], shape (N, 3), dtype of ``points``, or None
            when the file carries none (then ``points`` is the rest pose).
        rest_twist: twist of the rest pose's material frame about its space-parallel reference frame [rad],
            float64, shape (N,), or None (zero); written beside ``rest_points`` by the sag-free rest pose
            (:mod:`taichi_hair.solvers.rest_curve`).
        pinned: True for a kinematically pinned vertex, bool, shape (N,), or None.
        point_frames: animated positions [units], shape (F, N, 3), dtype of
            ``points``, or None (a time-sampled cache, e.g. USD).
        frame_times: time of each frame [USD time codes / frames], float64, shape (F,), or None.
        params: JSON-able dict of parameters and file metadata (simulation
            settings, format version, header fields).
        units: length unit of every length above: ``"m"``, ``"cm"``, ``"mm"``...,
            or ``""`` when the file does not say.
    """

    points: np.ndarray
    strand_offsets: np.ndarray
    radius: np.ndarray | None = None
    color: np.ndarray | None = None
    region: np.ndarray | None = None
    guide: np.ndarray | None = None
    rest_points: np.ndarray | None = None
    rest_twist: np.ndarray | None = None
    pinned: np.ndarray | None = None
    point_frames: np.ndarray | None = None
    frame_times: np.ndarray | None = None
    params: dict = field(default_factory=dict)
    units: str = ""

    # ------------------------------------------------------------------ sizes
    @property
    def strand_count(self) -> int:
        """Number of strands S."""
        return int(len(self.strand_offsets) - 1)

    @property
    def vertex_count(self) -> int:
        """Number of vertices N."""
        return int(self.points.shape[0])

    def strand_vertex_counts(self) -> np.ndarray:
        """Vertices per strand, int64, shape (S,)."""
        return np.diff(np.asarray(self.strand_offsets, dtype=np.int64))

    def strand(self, i: int) -> np.ndarray:
        """Polyline of strand i, shape (m, 3) (a view into ``points``)."""
        s = self.strand_count
        if not (-s <= i < s):
            raise IndexError(f"Groom.strand: index {i} out of range for {s} strands")
        i %= s
        return self.points[self.strand_offsets[i]:self.strand_offsets[i + 1]]

    def lengths(self) -> np.ndarray:
        """Arc length of each strand [units], float64, shape (S,) (in float64 a chunk at a time, so a
        float32 groom is never copied whole)."""
        return strand_lengths(self.points, self.strand_offsets)

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_polylines(cls, polylines, dtype=None, **attrs) -> "Groom":
        """Build from a list of (m_s, 3) arrays; ``dtype`` defaults to the first array's float dtype."""
        arrs = [np.asarray(p) for p in polylines]
        if not arrs:
            raise ValueError("Groom.from_polylines: no strands given")
        for s, a in enumerate(arrs):
            if a.ndim != 2 or a.shape[1] != 3:
                raise ValueError(f"Groom.from_polylines: strand {s} has shape {a.shape}; expected (m, 3)")
        if dtype is None:
            dtype = arrs[0].dtype if arrs[0].dtype in (np.float32, np.float64) else np.float64
        counts = np.array([a.shape[0] for a in arrs], dtype=np.int64)
        offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        g = cls(points=np.concatenate(arrs).astype(dtype, copy=False), strand_offsets=offsets, **attrs)
        g.validate()
        return g

    def to_polylines(self) -> list[np.ndarray]:
        """List of S arrays of shape (m_s, 3) (copies)."""
        off = self.strand_offsets
        return [self.points[off[s]:off[s + 1]].copy() for s in range(self.strand_count)]

    def scaled(self, factor: float, units: str | None = None) -> "Groom":
        """A copy with every length (points, rest pose, frames, radius) multiplied by ``factor``.

        The float dtype is kept.  ``units`` names the new unit (default: unknown, ``""``,
        unless ``factor == 1``).
        """
        if not (isinstance(factor, (int, float, np.floating)) and math.isfinite(factor) and factor > 0):
            raise ValueError(f"Groom.scaled: factor must be a finite positive number, got {factor!r}")

        def mul(a):
            if a is None:
                return None
            return (a * a.dtype.type(factor)).astype(a.dtype, copy=False)

        new_units = units if units is not None else (self.units if factor == 1 else "")
        return replace(self, points=mul(self.points), rest_points=mul(self.rest_points),
                       point_frames=mul(self.point_frames), radius=mul(self.radius),
                       params=dict(self.params), units=new_units)

    def z_up_to_y_up(self) -> "Groom":
        """A copy turned from a z-up file's axes to the simulator's y-up ones: (x, y, z) -> (x, z, -y), a
        rotation of -90 deg about x (points, rest pose and frames; radii, twists and units unchanged)."""

        def turn(a):
            if a is None:
                return None
            return np.stack([a[..., 0], a[..., 2], -a[..., 1]], axis=-1).astype(a.dtype, copy=False)

        return replace(self, points=turn(self.points), rest_points=turn(self.rest_points),
                       point_frames=turn(self.point_frames), params=dict(self.params))

    def per_vertex(self, values: np.ndarray) -> np.ndarray:
        """Expand a per-strand array (S, ...) to per-vertex (N, ...); per-vertex arrays pass through."""
        values = np.asarray(values)
        if values.shape[0] == self.vertex_count:  # N >= 2 S, so never ambiguous
            return values
        return np.repeat(values, self.strand_vertex_counts(), axis=0)

    # ------------------------------------------------------------------ validation
    def validate(self) -> "Groom":
        """Check shapes, dtypes and values; raise ``ValueError`` naming the strand and field.

        Normalises dtypes in place (offsets to int64, region to int32, guide and
        pinned to bool) and returns ``self``.
        """
        pts = self.points
        if not isinstance(pts, np.ndarray) or pts.ndim != 2 or pts.shape[1] != 3:
            raise ValueError(f"Groom: field 'points' must be an (N, 3) array, got shape {np.shape(pts)}")
        if pts.dtype not in (np.float32, np.float64):
            raise ValueError(f"Groom: field 'points' must be float32 or float64, got {pts.dtype}")
        n = pts.shape[0]
        off = np.asarray(self.strand_offsets)
        if off.ndim != 1 or off.shape[0] < 2 or not np.issubdtype(off.dtype, np.integer):
            raise ValueError(f"Groom: field 'strand_offsets' must be an integer array of shape (S + 1,) with S >= 1, "
                             f"got {off.dtype} {off.shape}")
        off = off.astype(np.int64, copy=False)
        self.strand_offsets = off
        if off[0] != 0:
            raise ValueError(f"Groom: field 'strand_offsets' must start at 0, got {int(off[0])}")
        if off[-1] != n:
            raise ValueError(f"Groom: field 'strand_offsets' must end at the vertex count {n}, got {int(off[-1])}")
        counts = np.diff(off)
        bad = np.nonzero(counts < 2)[0]
        if bad.size:
            s = int(bad[0])
            if counts[s] <= 0:
                raise ValueError(f"Groom: strand {s}: field 'strand_offsets' is not increasing "
                                 f"({int(off[s])} then {int(off[s + 1])})")
            raise ValueError(f"Groom: strand {s}: has {int(counts[s])} vertex; a strand needs at least 2")
        ns = off.shape[0] - 1

        def strand_of(vertex: int) -> int:
            return int(np.searchsorted(off, vertex, side="right") - 1)

        def check_finite(name, arr, per):
            if np.isfinite(arr.reshape(-1)).all():  # one flat pass in the common case
                return
            finite = np.isfinite(arr)
            if finite.ndim > 1:
                finite = finite.reshape(finite.shape[0], -1).all(axis=1)
            bad = np.nonzero(~finite)[0]
            if bad.size:
                i = int(bad[0])
                if per == "vertex":
                    s = strand_of(i)
                    raise ValueError(f"Groom: strand {s}: field '{name}' has a non-finite value at vertex "
                                     f"{i - int(off[s])} (global vertex {i})")
                raise ValueError(f"Groom: strand {i}: field '{name}' has a non-finite value")

        check_finite("points", pts, "vertex")
        if self.radius is not None:
            r = np.asarray(self.radius)
            if r.dtype not in (np.float32, np.float64):
                r = r.astype(np.float64)
            self.radius = r
            per = _per("radius", r, ns, n, None)
            check_finite("radius", r, per)
            neg = np.nonzero(r < 0)[0]
            if neg.size:
                i = int(neg[0])
                s = strand_of(i) if per == "vertex" else i
                raise ValueError(f"Groom: strand {s}: field 'radius' is negative ({float(r[i])!r})")
        if self.color is not None:
            c = np.asarray(self.color, dtype=np.float32)
            self.color = c
            check_finite("color", c, _per("color", c, ns, n, 3))
        if self.region is not None:
            reg = np.asarray(self.region)
            if reg.shape != (ns,) or not (np.issubdtype(reg.dtype, np.integer) or reg.dtype == np.bool_):
                raise ValueError(f"Groom: field 'region' must be an integer array of shape ({ns},), "
                                 f"got {reg.dtype} {reg.shape}")
            if reg.size and (reg.min() < np.iinfo(np.int32).min or reg.max() > np.iinfo(np.int32).max):
                raise ValueError("Groom: field 'region' does not fit in int32")
            self.region = reg.astype(np.int32, copy=False)
        if self.guide is not None:
            gd = np.asarray(self.guide)
            if gd.shape != (ns,):
                raise ValueError(f"Groom: field 'guide' must have shape ({ns},), got {gd.shape}")
            self.guide = gd.astype(bool, copy=False)
        if self.pinned is not None:
            pn = np.asarray(self.pinned)
            if pn.shape != (n,):
                raise ValueError(f"Groom: field 'pinned' must have shape ({n},), got {pn.shape}")
            self.pinned = pn.astype(bool, copy=False)
        if self.rest_points is not None:
            rp = np.asarray(self.rest_points)
            if rp.shape != pts.shape:
                raise ValueError(f"Groom: field 'rest_points' must have the shape of 'points' {pts.shape}, "
                                 f"got {rp.shape}")
            self.rest_points = rp.astype(pts.dtype, copy=False)
            check_finite("rest_points", self.rest_points, "vertex")
        if self.rest_twist is not None:
            rt = np.asarray(self.rest_twist)
            if rt.shape != (n,) or rt.dtype.kind not in "fiu":
                raise ValueError(f"Groom: field 'rest_twist' must be numbers of shape ({n},), got {rt.dtype} {rt.shape}")
            self.rest_twist = rt.astype(np.float64, copy=False)
            check_finite("rest_twist", self.rest_twist[:, None], "vertex")
        if self.point_frames is not None:
            pf = np.asarray(self.point_frames)
            if pf.ndim != 3 or pf.shape[1:] != pts.shape:
                raise ValueError(f"Groom: field 'point_frames' must have shape (F, {n}, 3), got {pf.shape}")
            self.point_frames = pf.astype(pts.dtype, copy=False)
            for f in range(pf.shape[0]):
                try:
                    check_finite("point_frames", self.point_frames[f], "vertex")
                except ValueError as exc:
                    raise ValueError(f"{exc} (frame {f})") from None
            ft = np.arange(pf.shape[0], dtype=np.float64) if self.frame_times is None \
                else np.asarray(self.frame_times, dtype=np.float64)
            if ft.shape != (pf.shape[0],) or not np.all(np.isfinite(ft)) or np.any(np.diff(ft) <= 0):
                raise ValueError(f"Groom: field 'frame_times' must be {pf.shape[0]} finite increasing times, "
                                 f"got {ft!r}")
            self.frame_times = ft
        elif self.frame_times is not None:
            raise ValueError("Groom: field 'frame_times' is set but 'point_frames' is not")
        if not isinstance(self.params, dict):
            raise ValueError(f"Groom: field 'params' must be a dict, got {type(self.params).__name__}")
        try:
            json.dumps(self.params, allow_nan=False)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"Groom: field 'params' is not JSON-able ({exc})") from None
        if not isinstance(self.units, str):
            raise ValueError(f"Groom: field 'units' must be a string, got {self.units!r}")
        return self

    def add_to_builder(self, builder, material=None, root: str = "clamped", body: int = 0) -> list[int]:
        """Add every strand to a :class:`~taichi_hair.builder.GroomBuilder` (float64 polylines).

        ``material`` is one RodMaterial (or dict) for all strands, or a callable
        ``material(strand_index) -> RodMaterial``; the groom's lengths must be in metres.
        Returns the builder's strand indices.  The builder's own checks apply
        (at least 3 vertices, no repeated points) and name the builder's strand index.
        """
        out = []
        for s in range(self.strand_count):
            m = material(s) if callable(material) else material
            out.append(builder.add_strand(self.strand(s).astype(np.float64), m, root=root, body=body))
        return out

    # ------------------------------------------------------------------ misc
    def copy(self) -> "Groom":
        """A deep copy."""
        kw = {}
        for f in fields(self):
            v = getattr(self, f.name)
            kw[f.name] = v.copy() if isinstance(v, np.ndarray) else (json.loads(json.dumps(v)) if f.name == "params"
                                                                    else v)
        return Groom(**kw)

    def __repr__(self) -> str:
        extra = [f.name for f in fields(self) if f.name not in ("points", "strand_offsets", "params", "units")
                 and getattr(self, f.name) is not None]
        return (f"Groom({self.strand_count} strands, {self.vertex_count} vertices, {self.points.dtype}, "
                f"units={self.units!r}, attributes={extra}, params={sorted(self.params)})")
