"""Exact distances and inside/outside for triangle meshes, on the host (NumPy only).

    q = TriangleMeshQuery(vertices, faces)      # (V, 3) [m], (F, 3) int
    d = q.unsigned_distance(points)             # (N,) [m]: distance to the nearest triangle
    w = q.winding_number(points)                # (N,) [-]: 1 inside a closed surface, 0 outside
    s = q.signed_distance(points)               # (N,) [m]: -d where w >= 1/2, +d elsewhere

Used by :class:`~taichi_hair.contact.colliders.MeshCollider` to sign the voxel SDF of a mesh that is not
watertight, and by :mod:`taichi_hair.quality` to measure penetration against the true surface.

Inside/outside is the generalized winding number (Jacobson, Kavan and Sorkine-Hornung 2013, Eq. 2-3):
w(p) = (1/4 pi) sum_f Omega_f(p), the solid angle of each triangle by the formula of Van Oosterom and
Strackee (1983).  For a closed, consistently oriented mesh it is exactly 1 inside and 0 outside; a mesh
with holes gets a smooth w that passes 1/2 across a minimal "cap" over each hole, so points deep inside a
bust open at the neck are still inside.  Triangles are grouped in clusters (a grid cell each); a cluster
farther than ``FAR_FACTOR`` times its radius from the point enters through its dipole term (the first
order of the far-field expansion of Barill et al. 2018, Eq. 6: Omega ~= N . r / |r|^3 with N the sum of
area vectors), nearer ones triangle by triangle.  Distances prune clusters by the bound
|p - c| - radius against the exact distance to the nearest cluster's triangles, so they are exact.
"""

from __future__ import annotations

import numpy as np

#: A cluster is "far" from a point beyond this many cluster radii (dipole term) [-].
FAR_FACTOR = 2.0
#: Target triangles per cluster [-].
CLUSTER_TRIANGLES = 32
#: Largest number of (point, triangle) pairs evaluated at once (memory bound) [-].
PAIR_CHUNK = 1 << 21


def _dot(a, b):
    return np.einsum("ij,ij->i", a, b)


def point_triangle_distance_sq(p, a, b, c):
    """Squared distance [m^2] from points p to triangles (a, b, c), all (K, 3) [m] -> (K,).

    The closest point by Voronoi regions of the triangle (Ericson, Real-Time Collision Detection, 5.1.5);
    degenerate triangles fall back to their edges through the same region tests."""
    ab, ac = b - a, c - a
    ap, bp, cp = p - a, p - b, p - c
    d1, d2 = _dot(ab, ap), _dot(ac, ap)
    d3, d4 = _dot(ab, bp), _dot(ac, bp)
    d5, d6 = _dot(ab, cp), _dot(ac, cp)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        den = va + vb + vc
        v = np.where(den != 0, vb / den, 0.0)
        w = np.where(den != 0, vc / den, 0.0)
        q = a + ab * v[:, None] + ac * w[:, None]  # interior
        # Edge and vertex regions, lowest priority first so that Ericson's order wins where several hold.
        e = d4 - d3 + d5 - d6
        t = np.where(e != 0, (d4 - d3) / e, 0.0)
        m = (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0)
        q = np.where(m[:, None], b + (c - b) * t[:, None], q)
        e = d2 - d6
        t = np.where(e != 0, d2 / e, 0.0)
        m = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
        q = np.where(m[:, None], a + ac * t[:, None], q)
        m = (d6 >= 0) & (d5 <= d6)
        q = np.where(m[:, None], c, q)
        e = d1 - d3
        t = np.where(e != 0, d1 / e, 0.0)
        m = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
        q = np.where(m[:, None], a + ab * t[:, None], q)
        m = (d3 >= 0) & (d4 <= d3)
        q = np.where(m[:, None], b, q)
        m = (d1 <= 0) & (d2 <= 0)
        q = np.where(m[:, None], a, q)
    r = p - q
    return _dot(r, r)


def triangle_solid_angle(p, a, b, c):
    """Signed solid angle [sr] of triangles (a, b, c) seen from points p, all (K, 3) -> (K,).

    Van Oosterom and Strackee (1983): tan(Omega / 2) = a.(b x c) / (|a||b||c| + (a.b)|c| + (b.c)|a| +
    (c.a)|b|) with a, b, c relative to p; positive when p is on the side opposite the normal
    (b - a) x (c - a), i.e. inside an outward-oriented closed mesh."""
    a, b, c = a - p, b - p, c - p
    la, lb, lc = (np.sqrt(_dot(x, x)) for x in (a, b, c))
    num = _dot(a, np.cross(b, c))
    den = la * lb * lc + _dot(a, b) * lc + _dot(b, c) * la + _dot(c, a) * lb
    return 2.0 * np.arctan2(num, den)


class TriangleMeshQuery:
    """Clustered triangles of one mesh for exact distance and winding-number queries.

    Attributes:
        vertices: (V, 3) float64 [m].
        faces: (F, 3) int64 [-].
        cluster_center: (C, 3) area-weighted centroid of each cluster [m].
        cluster_radius: (C,) largest distance from the centre to a vertex of the cluster [m].
        cluster_area_vector: (C, 3) sum of the area vectors (b - a) x (c - a) / 2 of its triangles [m^2].
        cluster_start, cluster_count: (C,) the cluster's triangles in ``order`` [-].
        order: (F,) triangle indices sorted by cluster [-].
    """

    def __init__(self, vertices, faces):
        v = np.asarray(vertices, np.float64)
        f = np.asarray(faces, np.int64)
        if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3 or len(f) == 0:
            raise ValueError("TriangleMeshQuery: vertices must be (V, 3) and faces (F, 3) with F >= 1")
        self.vertices, self.faces = v, f
        tri = v[f]
        self._a, self._b, self._c = tri[:, 0], tri[:, 1], tri[:, 2]
        area_vec = 0.5 * np.cross(self._b - self._a, self._c - self._a)
        area = np.linalg.norm(area_vec, axis=1)
        centroid = tri.mean(axis=1)
        lo, hi = v.min(0), v.max(0)
        # Cell side for about CLUSTER_TRIANGLES triangles per cell on a surface of this area.
        total = max(float(area.sum()), 1e-300)
        side = max(np.sqrt(CLUSTER_TRIANGLES * total / len(f)), 1e-9 * max(float((hi - lo).max()), 1e-30))
        cell = np.floor((centroid - lo) / side).astype(np.int64)
        dims = cell.max(0) + 1
        key = (cell[:, 0] * dims[1] + cell[:, 1]) * dims[2] + cell[:, 2]
        self.order = np.argsort(key, kind="stable")
        uniq, start, count = np.unique(key[self.order], return_index=True, return_counts=True)
        self.cluster_start, self.cluster_count = start.astype(np.int64), count.astype(np.int64)
        cid = np.repeat(np.arange(len(uniq)), count)
        t = self.order
        w = area[t] + 1e-300
        wsum = np.bincount(cid, w, len(uniq))
        self.cluster_center = np.stack([np.bincount(cid, w * centroid[t, k], len(uniq)) for k in range(3)],
                                       1) / wsum[:, None]
        d = np.max(np.linalg.norm(tri[t] - self.cluster_center[cid][:, None, :], axis=2), axis=1)
        self.cluster_radius = np.zeros(len(uniq))
        np.maximum.at(self.cluster_radius, cid, d)
        self.cluster_area_vector = np.stack([np.bincount(cid, area_vec[t, k], len(uniq)) for k in range(3)], 1)

    # ------------------------------------------------------------------ helpers
    def _point_chunk(self) -> int:
        return max(1, PAIR_CHUNK // (4 * len(self.cluster_count)))

    def _expand(self, pi, ci):
        """(point, cluster) pairs -> (point, triangle) pairs."""
        cnt = self.cluster_count[ci]
        total = int(cnt.sum())
        first = np.repeat(self.cluster_start[ci] - np.cumsum(cnt) + cnt, cnt)
        return np.repeat(pi, cnt), self.order[first + np.arange(total)]

    def _pairs(self, pi, ti, fn, p):
        """``fn(p[pi], a[ti], b[ti], c[ti])`` over pair chunks."""
        out = np.empty(len(pi))
        for s in range(0, len(pi), PAIR_CHUNK):
            sl = slice(s, s + PAIR_CHUNK)
            t = ti[sl]
            out[sl] = fn(p[pi[sl]], self._a[t], self._b[t], self._c[t])
        return out

    # ------------------------------------------------------------------ queries
    def winding_number(self, points) -> np.ndarray:
        """Generalized winding number of each point, (N, 3) [m] -> (N,) [-]."""
        p = np.asarray(points, np.float64).reshape(-1, 3)
        out = np.zeros(len(p))
        m = self._point_chunk()
        for s in range(0, len(p), m):
            q = p[s:s + m]
            r = self.cluster_center[None, :, :] - q[:, None, :]
            dist = np.linalg.norm(r, axis=2)
            far = dist > FAR_FACTOR * self.cluster_radius[None, :]
            with np.errstate(divide="ignore", invalid="ignore"):
                dip = np.einsum("mck,ck->mc", r, self.cluster_area_vector) / dist ** 3
            out[s:s + m] = np.where(far, dip, 0.0).sum(1)
            pi, ci = np.nonzero(~far)
            if len(pi):
                pi, ti = self._expand(pi, ci)
                om = self._pairs(pi, ti, triangle_solid_angle, q)
                out[s:s + m] += np.bincount(pi, om, len(q))
        return out / (4.0 * np.pi)

    def unsigned_distance(self, points) -> np.ndarray:
        """Exact distance of each point to the nearest triangle, (N, 3) [m] -> (N,) [m]."""
        p = np.asarray(points, np.float64).reshape(-1, 3)
        out = np.empty(len(p))
        m = self._point_chunk()
        for s in range(0, len(p), m):
            q = p[s:s + m]
            dist = np.linalg.norm(self.cluster_center[None, :, :] - q[:, None, :], axis=2)
            lower = np.maximum(dist - self.cluster_radius[None, :], 0.0)
            # Upper bound: the exact distance to the triangles of the cluster with the lowest bound.
            best = np.argmin(lower, axis=1)
            pi, ti = self._expand(np.arange(len(q)), best)
            upper = np.full(len(q), np.inf)
            np.minimum.at(upper, pi, self._pairs(pi, ti, point_triangle_distance_sq, q))
            upper = np.sqrt(upper)
            pi, ci = np.nonzero(lower <= upper[:, None])
            pi, ti = self._expand(pi, ci)
            d2 = np.full(len(q), np.inf)
            np.minimum.at(d2, pi, self._pairs(pi, ti, point_triangle_distance_sq, q))
            out[s:s + m] = np.sqrt(d2)
        return out

    def signed_distance(self, points) -> np.ndarray:
        """Distance to the triangles, negative where the winding number is >= 1/2, (N, 3) -> (N,) [m]."""
        d = self.unsigned_distance(points)
        return np.where(self.winding_number(points) >= 0.5, -d, d)


def boundary_edges(faces) -> np.ndarray:
    """Edges used by exactly one face, (B, 2) vertex indices [-] (a watertight mesh has none)."""
    f = np.asarray(faces, np.int64)
    e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    u, c = np.unique(e, axis=0, return_counts=True)
    return u[c == 1]


def count_boundary_loops(edges) -> int:
    """Connected components of a set of edges (B, 2): the holes of a mesh from its boundary edges [-]."""
    e = np.asarray(edges, np.int64)
    if len(e) == 0:
        return 0
    verts, inv = np.unique(e, return_inverse=True)
    parent = np.arange(len(verts))

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for a, b in inv.reshape(-1, 2):
        ra, rb = find(a), find(b)
        if ra != rb:
            parent[ra] = rb
    return len({find(i) for i in range(len(verts))})


def grid_winding_number(query: TriangleMeshQuery, origin, spacing: float, resolution: int,
                        unsigned=None) -> np.ndarray:
    """Winding number at the nodes origin + spacing * (i, j, k) of a cubic grid, (res, res, res) [-].

    Exact (to the dipole approximation of far clusters) at every other node and at the nodes within two
    spacings of the surface (``unsigned``: the grid of unsigned distances [m], computed here if None);
    elsewhere trilinear between the coarse nodes.  A node two spacings from the surface sees no surface
    between it and its coarse neighbours (at most sqrt(3) spacings away), where w is smooth, so the
    interpolated value is on the right side of 1/2 except where w itself is close to 1/2 (over a hole)."""
    n = int(resolution)
    origin = np.asarray(origin, np.float64)
    axis = np.arange(n)

    def nodes(i, j, k):
        return origin + spacing * np.stack([i, j, k], -1).astype(np.float64)

    coarse = np.unique(np.r_[axis[::2], n - 1])
    ci, cj, ck = np.meshgrid(coarse, coarse, coarse, indexing="ij")
    wc = query.winding_number(nodes(ci, cj, ck).reshape(-1, 3)).reshape(ci.shape)
    # Trilinear between coarse nodes, axis by axis.
    hi = np.clip(np.searchsorted(coarse, axis, side="left"), 1, len(coarse) - 1)
    lo = hi - 1
    t = (axis - coarse[lo]) / (coarse[hi] - coarse[lo])
    w = wc[lo] * (1 - t)[:, None, None] + wc[hi] * t[:, None, None]
    w = w[:, lo] * (1 - t)[None, :, None] + w[:, hi] * t[None, :, None]
    w = w[:, :, lo] * (1 - t)[None, None, :] + w[:, :, hi] * t[None, None, :]
    ii, jj, kk = np.meshgrid(axis, axis, axis, indexing="ij")
    if unsigned is None:
        unsigned = query.unsigned_distance(nodes(ii, jj, kk).reshape(-1, 3)).reshape(n, n, n)
    near = np.abs(unsigned) < 2.0 * spacing
    on_coarse = np.zeros((n, n, n), bool)
    on_coarse[np.ix_(coarse, coarse, coarse)] = True
    todo = near & ~on_coarse
    w[todo] = query.winding_number(nodes(ii[todo], jj[todo], kk[todo]))
    return w
