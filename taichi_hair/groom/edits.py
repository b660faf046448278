"""The shape edits of a grooming session as pure functions on NumPy arrays (Daviet 2023, Sec. 5.3).

Each takes the groom's flat arrays (``points`` the current pose, ``rest_points`` the rest pose, both
(vertex_count, 3) [m], ``offsets`` the (strand_count + 1,) strand offsets) and returns new arrays or
the new poses of the edited strands; nothing is changed in place.  Geometry in float64; results are
cast to the dtype of the arrays they replace.

* :func:`trim_strands`: cut the strands whose current polyline crosses a plane;
* :func:`scale_length_strands`: shorten or grow strands from the tip (growth continues the tip's
  curvature and torsion);
* :func:`scale_curl_strands`: multiply the rest turning angles (Bishop-frame curvature);
* :func:`replace_strands`: write edited strands into copies of both poses;
* :func:`rest_from_current`: rest pose <- current pose on chosen strands (a comb's result).

Trims and growths keep every strand's vertex count: the edited strand is *resampled* along its new
length (:func:`_batch_resample`: vertex i at the same arc fraction as before, linear between the old
vertices, so edges get shorter or longer by the length ratio).  The layout of the simulation then
never changes, and the Model is updated in place instead of rebuilt.  The price: a strong growth
coarsens the strand (curls finer than the new edge spacing are smoothed), a strong trim makes short
edges (slower ADMM convergence, Sec. 6.1).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np


# =========================================================================== geometry helpers (NumPy, float64)
def _min_rotation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Smallest rotation matrix taking unit a to unit b (a half turn about an axis across a when b = -a)."""
    v = np.cross(a, b)
    c = float(np.dot(a, b))
    if np.linalg.norm(v) < 1e-12:
        if c > 0:
            return np.eye(3)
        p = _batch_perpendicular(a[None])[0]
        return 2.0 * np.outer(p, p) - np.eye(3)  # the rotation by pi about p
    k = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + k + k @ k / (1.0 + c)


def _arc(p: np.ndarray) -> np.ndarray:
    """Cumulative arc length at every vertex of polyline p (m, 3), or of G polylines (G, m, 3) [m]: shape
    (m,) or (G, m)."""
    seg = np.cumsum(np.linalg.norm(np.diff(p, axis=-2), axis=-1), axis=-1)
    return np.concatenate([np.zeros(seg.shape[:-1] + (1,)), seg], axis=-1)


class EditedStrands(Mapping):
    """The new poses of edited strands, as the edits make them: blocks of the strands of one vertex count m,
    ``(strands (G,), current (G, m, 3), rest (G, m, 3))``, float64.  Read as a mapping strand -> (current,
    rest) of (m, 3) arrays; :func:`replace_strands` scatters the blocks whole (8,600 strands of 14 vertices:
    one mapping entry per strand cost ~0.08 s of an edit to build and concatenate again)."""

    def __init__(self) -> None:
        self.blocks: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self._where: dict | None = None

    def add(self, strands: np.ndarray, current: np.ndarray, rest: np.ndarray) -> None:
        if strands.size:
            self.blocks.append((np.asarray(strands, dtype=np.int64), current, rest))
            self._where = None

    def _index(self) -> dict:
        if self._where is None:
            self._where = {int(s): (b, r) for b, (group, _, _) in enumerate(self.blocks)
                           for r, s in enumerate(group.tolist())}
        return self._where

    def __getitem__(self, strand):
        b, r = self._index()[int(strand)]
        return self.blocks[b][1][r], self.blocks[b][2][r]

    def __iter__(self):
        for group, _, _ in self.blocks:
            yield from group.tolist()

    def __len__(self) -> int:
        return sum(int(group.size) for group, _, _ in self.blocks)


def _groups(offsets: np.ndarray, strands: np.ndarray):
    """The strands of one vertex count m together: (group, idx) per m, ``group`` the strand indices and
    ``idx`` (len(group), m) their vertex rows, to edit them as (strands, vertices, 3) arrays."""
    counts = offsets[strands + 1] - offsets[strands]
    for m in np.unique(counts):
        group = strands[counts == m]
        yield group, offsets[group][:, None] + np.arange(m)


def _sample(knots: np.ndarray, points: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Points of the polyline ``points`` at arc parameters ``s``, linear between the vertices
    (``knots`` is the parameter of each vertex, increasing).  s = knots[0] gives points[0] exactly."""
    idx = np.clip(np.searchsorted(knots, s, side="right") - 1, 0, len(knots) - 2)
    u = np.clip((s - knots[idx]) / (knots[idx + 1] - knots[idx]), 0.0, 1.0)
    return points[idx] + u[:, None] * (points[idx + 1] - points[idx])


def _batch_perpendicular(t: np.ndarray) -> np.ndarray:
    """A unit vector across each unit row of t (G, 3): t x z, or t x x where t is within ~25 degrees of z."""
    a = np.where((np.abs(t[:, 2]) < 0.9)[:, None], np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0]))
    return _batch_unit(np.cross(t, a))


def _batch_rotate(v: np.ndarray, axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rodrigues rotation of the rows of v about the unit rows of ``axis`` by ``angle`` (G,) [rad]."""
    c, s = np.cos(angle)[:, None], np.sin(angle)[:, None]
    return v * c + np.cross(axis, v) * s + axis * _dot(axis, v)[:, None] * (1.0 - c)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("gi,gi->g", a, b)


def _turning(p: np.ndarray):
    """Bishop-frame curvature of G polylines (G, m, 3): tangents, edge lengths, and per edge pair the turning
    angle and its axis's components (a.u, a.v) on the Bishop frame (u, v = t x u) carried along the strand."""
    e = np.diff(p, axis=1)
    le = np.linalg.norm(e, axis=2)
    t = e / le[:, :, None]
    G, n = t.shape[0], t.shape[1]
    u = _batch_perpendicular(t[:, 0])
    angles, comps = np.zeros((G, n - 1)), np.zeros((G, n - 1, 2))
    comps[:, :, 0] = 1.0
    for i in range(1, n):
        b = np.cross(t[:, i - 1], t[:, i])
        s = np.linalg.norm(b, axis=1)
        turn = s >= 1e-14  # a straight pair keeps angle 0, components (1, 0), and the frame
        a = b / np.where(turn, s, 1.0)[:, None]
        ang = np.where(turn, np.arctan2(s, _dot(t[:, i - 1], t[:, i])), 0.0)
        v = np.cross(t[:, i - 1], u)
        angles[:, i - 1] = ang
        comps[turn, i - 1, 0] = _dot(a, u)[turn]
        comps[turn, i - 1, 1] = _dot(a, v)[turn]
        un = _batch_rotate(u, a, ang)
        un = _batch_unit(un - _dot(un, t[:, i])[:, None] * t[:, i])
        u = np.where(turn[:, None], un, u)
    return t, le, angles, comps


def _scale_curl_polylines(p: np.ndarray, factor: float) -> np.ndarray:
    """G polylines (G, m, 3) with every Bishop turning angle multiplied by ``factor`` (edge lengths and the
    root edge kept): the turns of :func:`_turning` applied again, scaled, from the root edge."""
    t, le, angles, comps = _turning(p)
    out = np.empty_like(p)
    out[:, 0], out[:, 1] = p[:, 0], p[:, 1]
    ti_, u = t[:, 0].copy(), _batch_perpendicular(t[:, 0])
    for i in range(1, t.shape[1]):
        v = np.cross(ti_, u)
        a = comps[:, i - 1, 0:1] * u + comps[:, i - 1, 1:2] * v
        na = np.linalg.norm(a, axis=1)
        turn = (angles[:, i - 1] != 0.0) & (na > 0)
        a = a / np.where(turn, na, 1.0)[:, None]
        ang = factor * angles[:, i - 1]
        tn = _batch_unit(_batch_rotate(ti_, a, ang))
        un = _batch_rotate(u, a, ang)
        un = _batch_unit(un - _dot(un, tn)[:, None] * tn)
        ti_ = np.where(turn[:, None], tn, ti_)
        u = np.where(turn[:, None], un, u)
        out[:, i + 1] = out[:, i] + le[:, i, None] * ti_
    return out


# =========================================================================== the edits
def replace_strands(points: np.ndarray, rest_points: np.ndarray, offsets: np.ndarray,
                    new: dict) -> tuple[np.ndarray, np.ndarray]:
    """Copies of both poses with the strands s of ``new`` (s -> (current, rest), each with the
    strand's vertex count) swapped in, in the arrays' dtypes; the other strands bit for bit."""
    pts = points.copy()
    rest = rest_points.copy()
    if not new:
        return pts, rest
    off = np.asarray(offsets, dtype=np.int64)
    if isinstance(new, EditedStrands):  # whole blocks of one vertex count: one scatter each
        for group, cur, rst in new.blocks:
            m = cur.shape[1]
            count = off[group + 1] - off[group]
            bad = np.nonzero(count != m)[0]
            if bad.size:
                k = int(bad[0])
                raise ValueError(f"replace_strands: strand {int(group[k])} has {int(count[k])} vertices, its new poses "
                                 f"{m} and {rst.shape[1]}")
            idx = off[group][:, None] + np.arange(m)
            pts[idx] = cur.astype(pts.dtype)
            rest[idx] = rst.astype(rest.dtype)
        return pts, rest
    # One scatter of the concatenated poses instead of a copy per strand; the same values (8,600 of 86,000 strands x 14:
    # 21 -> 19 ms, most of it the two copies of the whole groom).
    ss = np.fromiter(new.keys(), dtype=np.int64, count=len(new))
    count = off[ss + 1] - off[ss]
    n_cur = np.fromiter((len(v[0]) for v in new.values()), dtype=np.int64, count=len(new))
    n_rest = np.fromiter((len(v[1]) for v in new.values()), dtype=np.int64, count=len(new))
    bad = np.nonzero((n_cur != count) | (n_rest != count))[0]
    if bad.size:
        k = int(bad[0])
        raise ValueError(f"replace_strands: strand {int(ss[k])} has {int(count[k])} vertices, its new poses "
                         f"{int(n_cur[k])} and {int(n_rest[k])}")
    from .binding import vertex_rows

    rows = vertex_rows(off[ss], count)
    pts[rows] = np.concatenate([np.asarray(v[0]).reshape(-1, 3) for v in new.values()]).astype(pts.dtype)
    rest[rows] = np.concatenate([np.asarray(v[1]).reshape(-1, 3) for v in new.values()]).astype(rest.dtype)
    return pts, rest


def trim_strands(points: np.ndarray, rest_points: np.ndarray, offsets: np.ndarray, plane_point: np.ndarray,
                 normal: np.ndarray, chosen: np.ndarray) -> EditedStrands:
    """New poses of the strands cut by the plane (``plane_point`` [m], unit ``normal``).

    A strand of ``chosen`` (bool, (strand_count,)) is cut when its current polyline crosses the
    plane, at its first crossing from the root; the part holding the root stays.  Both poses are
    resampled along the kept part (:func:`_batch_resample`), so the vertex count is kept, edges get
    shorter and the last vertex lies on the plane (the same rest arc length cuts the rest pose).
    Keeping the layout lets the solver update its Model in place (milliseconds) instead of
    building a new one (a kernel recompilation).

    Returns:
        :class:`EditedStrands` (strand -> (current, rest), float64 (m_s, 3) each), of the cut strands only.
    """
    off = np.asarray(offsets, dtype=np.int64)
    dist = (points.astype(np.float64) - plane_point) @ normal
    # Candidates: strands with a vertex on the other side of the plane from their root.
    side = np.repeat(np.sign(dist[off[:-1]]), np.diff(off))
    crosses = np.logical_or.reduceat(dist * side <= 0.0, off[:-1]) & (dist[off[:-1]] != 0.0) & chosen
    new = EditedStrands()
    for group, idx in _groups(off, np.nonzero(crosses)[0]):
        m = idx.shape[1]
        cur, rest, d = points[idx].astype(np.float64), rest_points[idx].astype(np.float64), dist[idx]
        k = np.argmax(d * np.sign(d[:, :1]) <= 0.0, axis=1)  # the first vertex across the plane
        j = k - 1
        rows = np.arange(group.size)
        u = d[rows, j] / (d[rows, j] - d[rows, k])
        c = _arc(rest)
        length = c[rows, j] + u * (c[rows, j + 1] - c[rows, j])
        new_cur, new_rest = _batch_resample(cur, rest, np.full(group.size, m), (c / c[:, -1:]) * length[:, None])
        # The last vertex exactly on the plane (the same rest arc length cuts the rest pose).
        new_cur[:, -1] = cur[rows, j] + u[:, None] * (cur[rows, j + 1] - cur[rows, j])
        new_rest[:, -1] = rest[rows, j] + u[:, None] * (rest[rows, j + 1] - rest[rows, j])
        new.add(group, new_cur, new_rest)
    return new


def scale_length_strands(points: np.ndarray, rest_points: np.ndarray, offsets: np.ndarray, strands,
                         factor: float) -> EditedStrands:
    """New poses of ``strands`` with their rest length multiplied by ``factor`` > 0, from the tip.

    Shorter: the strand is cut at the scaled rest arc length.  Longer: the rest polyline is
    continued beyond the tip with the tip's curvature and torsion (the screw motion taking the
    last-but-one edge pair to the last one, at the last rest edge length; the current pose
    continues rigidly with the tip's frame).  Either way the strand keeps its vertex count and
    both poses are resampled along the new length (:func:`_batch_resample`): edges scale by ``factor``,
    and the rest length is ``factor`` times the old one up to the chord shortening of the
    resampling.  A large growth of a curly strand therefore smooths curls finer than the new edge
    spacing; add vertices to the groom beforehand for that.

    Strands of one vertex count are edited together, as (strands, vertices, 3) arrays (8,600 strands
    at 14 vertices: 0.1 s, against 1.9 s strand by strand).

    Returns:
        :class:`EditedStrands` (strand -> (current, rest), float64 (m_s, 3) each); empty for ``factor`` 1.
    """
    f = float(factor)
    off = np.asarray(offsets, dtype=np.int64)
    strands = np.asarray(strands, dtype=np.int64).reshape(-1)
    new = EditedStrands()
    if f == 1.0 or strands.size == 0:
        return new
    for group, idx in _groups(off, strands):
        new.add(group, *_scale_length_group(points[idx].astype(np.float64), rest_points[idx].astype(np.float64), f))
    return new


def _batch_pair_frames(t0: np.ndarray, t1: np.ndarray):
    """Orthonormal frames (columns t0, n, t0 x n; n the part of t1 across t0) of rows of unit tangents
    (G, 3): frames (G, 3, 3), and which rows have one (t1 not parallel to t0)."""
    n = t1 - _dot(t1, t0)[:, None] * t0
    ln = np.linalg.norm(n, axis=1)
    ok = ln >= 1e-9
    n = n / np.where(ok, ln, 1.0)[:, None]
    return np.stack([t0, n, np.cross(t0, n)], axis=2), ok


def _batch_unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _scale_length_group(cur: np.ndarray, rest: np.ndarray, f: float):
    """:func:`scale_length_strands` of G strands of m vertices each, (G, m, 3) float64 -> both new poses."""
    G, m, _ = rest.shape
    c = _arc(rest)
    total = c[:, -1]
    ext_cur, ext_rest, n_valid = cur, rest, np.full(G, m)
    if f > 1.0:
        le = c[:, -1] - c[:, -2]
        k = np.maximum(1, np.ceil((f - 1.0) * total / le * (1.0 + 1e-12)).astype(np.int64))
        t = _batch_unit(np.diff(rest, axis=1))  # (G, m - 1, 3)
        # The screw motion taking the tip's last-but-one edge pair to the last one (a helix continues).
        q = np.empty((G, 3, 3))
        ok = np.zeros(G, bool)
        if m - 1 >= 3:
            a, oka = _batch_pair_frames(t[:, -3], t[:, -2])
            b, okb = _batch_pair_frames(t[:, -2], t[:, -1])
            ok = oka & okb
            q[ok] = b[ok] @ np.transpose(a[ok], (0, 2, 1))
        for g in np.nonzero(~ok)[0]:
            q[g] = _min_rotation(t[g, -2], t[g, -1])
        # The rotation of the rest tip frame (last two edges) to the current one: the current pose grows rigidly.
        tr, tc = _batch_unit(np.diff(rest[:, -3:], axis=1)), _batch_unit(np.diff(cur[:, -3:], axis=1))
        fr, okr = _batch_pair_frames(tr[:, 0], tr[:, 1])
        fc, okc = _batch_pair_frames(tc[:, 0], tc[:, 1])
        rot = fc @ np.transpose(fr, (0, 2, 1))
        for g in np.nonzero(~(okr & okc))[0]:
            rot[g] = _min_rotation(tr[g, 1], tc[g, 1])
        grown = np.empty((G, int(k.max()), 3))
        tg, tip = t[:, -1], rest[:, -1]
        for i in range(grown.shape[1]):  # rows past their own k grow on, unused: n_valid stops there
            tg = _batch_unit(np.einsum("gij,gj->gi", q, tg))
            tip = tip + le[:, None] * tg
            grown[:, i] = tip
        cur_grown = cur[:, -1:] + np.einsum("gkj,gij->gki", grown - rest[:, -1:], rot)
        ext_cur = np.concatenate([cur, cur_grown], axis=1)
        ext_rest = np.concatenate([rest, grown], axis=1)
        n_valid = m + k
    s = (c / total[:, None]) * (f * total)[:, None]  # vertex i at the rest arc length phi_i * f * total
    return _batch_resample(ext_cur, ext_rest, n_valid, s)


def _batch_resample(cur: np.ndarray, rest: np.ndarray, n_valid: np.ndarray, s: np.ndarray):
    """Both poses of G strands resampled at the rest arc lengths ``s`` (G, m) along the rest polylines ``rest``
    (G, n, 3; the strands, extended beyond their tips for a growth), of which the first ``n_valid`` (G,)
    vertices count.

    The edits put vertex i at the rest arc length phi_i * length, phi_i its old arc fraction, so the relative
    spacing is kept (uniform stays uniform) and every edge is scaled by length / old length.  Both poses are
    parametrised by the *rest* arc length and interpolated linearly, so vertex i of the current pose is the
    point that corresponds to vertex i of the rest pose; new vertices lie on the old polylines (a corner
    between two old vertices is cut by the new chord: the rest length is ``length`` minus that chord
    shortening, and a curl finer than the new edge spacing is smoothed).  The root vertex is kept bit for bit.
    """
    knots = _arc(rest)
    cols = np.arange(knots.shape[1])
    knots_valid = np.where(cols[None, :] < n_valid[:, None], knots, np.inf)
    j = np.count_nonzero(knots_valid[:, None, :] <= s[:, :, None], axis=2) - 1
    j = np.clip(j, 0, (n_valid - 2)[:, None])
    # Flat row indices instead of np.take_along_axis, which indexes every axis (the same values; 8,600 strands: the
    # six gathers 22 -> ~6 ms).
    flat = j + (np.arange(j.shape[0]) * knots.shape[1])[:, None]
    k0 = knots.reshape(-1)[flat]
    k1 = knots.reshape(-1)[flat + 1]
    u = np.clip((s - k0) / (k1 - k0), 0.0, 1.0)[:, :, None]

    def sample(p):
        rows = p.reshape(-1, 3)
        p0 = rows[flat]
        p1 = rows[flat + 1]
        return p0 + u * (p1 - p0)

    new_cur, new_rest = sample(cur), sample(rest)
    new_cur[:, 0], new_rest[:, 0] = cur[:, 0], rest[:, 0]
    return new_cur, new_rest


def scale_curl_strands(points: np.ndarray, rest_points: np.ndarray, offsets: np.ndarray, strands,
                       factor: float) -> tuple[np.ndarray, np.ndarray]:
    """Both poses with the rest turning angles of ``strands`` multiplied by ``factor`` >= 0 (edge
    lengths and the root edge kept, bit for bit) and their current pose set to the new rest pose.

    Returns:
        (points, rest_points), new arrays in the dtypes of the given ones.
    """
    off = np.asarray(offsets, dtype=np.int64)
    strands = np.asarray(strands, dtype=np.int64).reshape(-1)
    rest = rest_points.copy()
    pts = points.copy()
    for _, idx in _groups(off, strands):
        q = _scale_curl_polylines(rest_points[idx].astype(np.float64), float(factor))
        q[:, :2] = rest_points[idx[:, :2]]  # the clamped root edge, bit for bit
        rest[idx] = q.astype(rest.dtype)
        pts[idx] = rest[idx]
    return pts, rest


def rest_from_current(points: np.ndarray, rest_points: np.ndarray, offsets: np.ndarray,
                      strands: np.ndarray) -> np.ndarray:
    """A copy of ``rest_points`` with the current pose of the strands ``strands`` (bool,
    (strand_count,)) as their rest pose, the clamped root edge (local vertices 0, 1) kept."""
    counts = np.diff(np.asarray(offsets, dtype=np.int64))
    local = np.arange(points.shape[0]) - np.repeat(offsets[:-1], counts)
    mask = np.repeat(strands, counts) & (local >= 2)
    rest = rest_points.copy()
    rest[mask] = points[mask].astype(rest.dtype)
    return rest
