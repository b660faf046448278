"""Binding of render strands to guides (Daviet 2023, Sec. 5.3), host NumPy, float64, once.

Stage 2 of :mod:`taichi_hair.groom.skinning` (:func:`compute_binding`): each render strand is
bound to its k nearest guides by root distance, with normalised inverse-distance weights (a guide
binds to itself with weight 1).  Along the strand, binding is by normalised arc length: a render
vertex at arc fraction s follows, on every bound guide, the rest edge j that contains the guide's
own arc fraction s, at the edge parameter u in [0, 1].  The render vertex's rest position p is
stored in that edge's rest frame Q_j (columns t, d1, d2):  ``c = Q_j^T (p - o_j(u))``,
``o_j(u) = (1-u) x_j + u x_{j+1}``.

:func:`proxy_vertices` is the same correspondence reduced to one guide vertex: the vertex a
grooming session moves in place of a vertex of a skinned strand.
"""


import numpy as np

from ..model import Model
from .guides import FRAMES, _check_neighbours, _flat_polylines


def _arc_fractions(points: np.ndarray, counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Normalised arc length of every vertex and the length of every strand.

    Each strand's cumulative sum is taken on its own padded row, so two equal
    polylines get bitwise equal fractions wherever they sit in the flat array.
    """
    ns = counts.shape[0]
    mmax = int(counts.max())
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    local = np.arange(points.shape[0]) - np.repeat(starts, counts)
    strand_of = np.repeat(np.arange(ns), counts)
    grid = np.full((ns, mmax, 3), np.nan)
    grid[strand_of, local] = points
    seg = np.linalg.norm(np.diff(grid, axis=1), axis=2)
    seg = np.nan_to_num(seg, nan=0.0)
    cum = np.concatenate([np.zeros((ns, 1)), np.cumsum(seg, axis=1)], axis=1)
    length = cum[np.arange(ns), counts - 1]
    return cum[strand_of, local] / length[strand_of], length


def compute_binding(guide_model: Model, guide_indices, strands, neighbour_count: int = 4,
                    frame: str = "transport", guide_rest_frames=None, previous: dict | None = None) -> dict:
    """Bind render strands to guides (NumPy, float64).  See the module docstring.

    ``previous``: the binding of the same layout before an edit (same strands, vertex counts, guides,
    roots and ``frame="transport"``).  Only the render strands whose rest polyline changed, and those bound
    to a guide whose rest polyline changed, are bound again; the others keep their rows.  The result is
    equal, bit for bit, to a full binding of the same inputs (each vertex's arithmetic does not depend on
    which others are computed with it); where the layout or a root differs, the binding is done in full.
    ``previous``'s per-vertex arrays are updated in place and returned: it no longer describes the old inputs.

    Args:
        guide_model: the guide :class:`Model` (rest positions and frames from ``host``).
        guide_indices: (guide_count,) render strand index of each guide strand.
        strands: sequence of render polylines (m_s, 3) [m].
        neighbour_count: k (capped at the guide count).
        frame: ``"transport"`` or ``"material"`` (rest frames from ``guide_rest_frames``).
        guide_rest_frames: for ``"material"``: (tangent, d1, d2), each (guide_vertex_count, 3),
            of the rest State; ignored otherwise.

    Returns:
        dict of arrays; ``V`` render vertices, ``K`` = min(k, guide_count):
        ``render_strand_vertex_start/count`` (S,), ``render_vertex_rest_position`` (V, 3) [m],
        ``render_strand_guides`` (S, K) guide strand indices, ``render_strand_weights`` (S, K),
        ``render_vertex_bind_edge`` (V, K) guide edge (= start vertex) index,
        ``render_vertex_bind_param`` (V, K) u in [0, 1], ``render_vertex_bind_local`` (V, K, 3) [m],
        ``render_vertex_bind_weight`` (V, K), ``guide_vertex_rest_position`` (guide vertices, 3) [m] (what the
        binding was made against, for ``previous``).
    """
    from scipy.spatial import cKDTree

    _check_neighbours("compute_binding: field 'neighbour_count'", neighbour_count)
    if frame not in FRAMES:
        raise ValueError(f"compute_binding: field 'frame' must be one of {FRAMES}, got {frame!r}")
    if frame == "material" and guide_rest_frames is None:
        raise ValueError("compute_binding: field 'guide_rest_frames' is needed for frame='material'")
    P, counts = _flat_polylines(strands, "compute_binding: field 'strands'")
    h = guide_model.host
    gstart = h["strand_vertex_start"].astype(np.int64)
    gcount = h["strand_vertex_count"].astype(np.int64)
    ng = gstart.shape[0]
    gidx = np.asarray(guide_indices, dtype=np.int64).reshape(-1)
    if gidx.shape[0] != ng:
        raise ValueError(f"compute_binding: field 'guide_indices' has {gidx.shape[0]} entries but the guide model "
                         f"has {ng} strands (root count mismatch)")
    ns = counts.size
    if gidx.size and (gidx.min() < 0 or gidx.max() >= ns):
        raise ValueError(f"compute_binding: field 'guide_indices' must index the {ns} render strands")
    if np.unique(gidx).size != gidx.size:
        raise ValueError("compute_binding: field 'guide_indices' has repeated strands")
    X = h["vertex_rest_position"].astype(np.float64)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    mismatch = np.where(counts[gidx] != gcount)[0]
    if not mismatch.size:
        gp = P[_vertex_rows(starts[gidx], gcount)]
        far = np.any(np.abs(gp - X) > 1e-9, axis=1)
        mismatch = np.unique(np.repeat(np.arange(ng), gcount)[far])
    if mismatch.size:
        g = int(mismatch[0])
        raise ValueError(f"compute_binding: field 'guide_indices': guide {g} is not render strand {int(gidx[g])} "
                         "(different rest polyline)")

    nv = P.shape[0]
    strand_of = np.repeat(np.arange(ns), counts)
    local = np.arange(nv) - starts[strand_of]
    K = min(int(neighbour_count), ng)
    guide_of_strand = np.full(ns, -1, dtype=np.int64)
    guide_of_strand[gidx] = np.arange(ng)
    is_guide = guide_of_strand >= 0
    if frame == "transport":
        t = h["edge_rest_tangent"].astype(np.float64)
        d1 = h["edge_rest_director"].astype(np.float64)
        d2 = np.cross(t, d1)
    else:
        t, d1, d2 = (np.asarray(a, dtype=np.float64) for a in guide_rest_frames)
    f_g, _ = _arc_fractions(X, gcount)
    geometry = (X, gstart, gcount, f_g, t, d1, d2, guide_of_strand, is_guide)

    redo = _strands_to_rebind(previous, P, X, counts, starts, gstart, gcount, K, frame)
    if redo is not None:
        out = dict(previous)
        out["render_vertex_rest_position"] = P
        out["guide_vertex_rest_position"] = X
        if redo.size:
            nbr = previous["render_strand_guides"]
            v = _vertex_rows(starts[redo], counts[redo])
            j, u, c = _bind_vertices(P[v], counts[redo], local[v], strand_of[v], nbr, geometry)
            for key, val in (("render_vertex_bind_edge", j), ("render_vertex_bind_param", u),
                             ("render_vertex_bind_local", c)):
                out[key] = previous[key]  # in place: a copy of the 1.2M-vertex arrays cost 0.3-0.4 s
                out[key][v] = val
        return out

    # k nearest guides by root position, inverse-distance weights.
    groots = X[gstart]
    roots = P[starts]
    dist, nbr = cKDTree(groots).query(roots, k=K)
    dist = np.asarray(dist, dtype=np.float64).reshape(ns, K)
    nbr = np.asarray(nbr, dtype=np.int64).reshape(ns, K)
    scale = max(float(np.ptp(groots, axis=0).max()), 1e-12)
    zero = dist <= 1e-12 * scale
    with np.errstate(divide="ignore"):
        w = np.where(zero.any(axis=1, keepdims=True), zero.astype(np.float64), 1.0 / np.maximum(dist, 1e-300))
    # A guide follows itself only: slot 0 is itself with weight 1.
    gs = np.where(is_guide)[0]
    g_self = guide_of_strand[gs]
    # Move the guide itself to slot 0 (stable: the others keep their order); if it was not
    # among its k nearest (several roots at one point), it replaces slot 0.
    order = np.argsort(nbr[gs] != g_self[:, None], axis=1, kind="stable")
    nbr[gs] = np.take_along_axis(nbr[gs], order, axis=1)
    nbr[gs, 0] = g_self
    w[is_guide] = 0.0
    w[is_guide, 0] = 1.0
    w /= w.sum(axis=1, keepdims=True)

    j, u, local_c = _bind_vertices(P, counts, local, strand_of, nbr, geometry)
    return {
        "render_strand_vertex_start": starts,
        "render_strand_vertex_count": counts,
        "render_vertex_rest_position": P,
        "render_strand_guides": nbr,
        "render_strand_weights": w,
        "render_vertex_bind_edge": j,
        "render_vertex_bind_param": u,
        "render_vertex_bind_local": local_c,
        "render_vertex_bind_weight": w[strand_of],
        "guide_vertex_rest_position": X,
    }


def _vertex_rows(starts: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """The vertex rows of strands starting at ``starts`` with ``counts`` vertices, one strand after another."""
    return np.repeat(starts - np.cumsum(counts) + counts, counts) + np.arange(int(counts.sum()))


def _strands_to_rebind(previous, P, X, counts, starts, gstart, gcount, K, frame):
    """The render strands an edit changed, directly or through a bound guide (sorted), or None when
    ``previous`` cannot be reused: another layout, a moved root, or ``frame="material"``."""
    if previous is None or frame != "transport" or "guide_vertex_rest_position" not in previous:
        return None
    P0, X0 = previous["render_vertex_rest_position"], previous["guide_vertex_rest_position"]
    if (P0.shape != P.shape or X0.shape != X.shape or previous["render_strand_guides"].shape[1] != K
            or not np.array_equal(previous["render_strand_vertex_count"], counts)):
        return None
    if not (np.array_equal(P0[starts], P[starts]) and np.array_equal(X0[gstart], X[gstart])):
        return None  # a root moved: the nearest guides and the weights change
    moved_r = np.logical_or.reduceat(np.any(P0 != P, axis=1), starts)
    moved_g = np.logical_or.reduceat(np.any(X0 != X, axis=1), gstart) if gstart.size else np.zeros(0, bool)
    moved = moved_r | np.any(moved_g[previous["render_strand_guides"]], axis=1)
    return np.nonzero(moved)[0]


def _bind_vertices(P, counts, local, strand_of, nbr, geometry):
    """Edge j, parameter u and frame coordinates of the vertices ``P`` of whole render strands (their vertex
    counts ``counts``; ``local``, ``strand_of``: each vertex's index in its strand and its strand's index in
    the groom), each vertex independently of the others."""
    X, gstart, gcount, f_g, t, d1, d2, guide_of_strand, is_guide = geometry
    ng = gstart.shape[0]
    K = nbr.shape[1]
    nv = P.shape[0]
    # Arc-length correspondence: segment j of guide g holding fraction s, parameter u.
    s_r, _ = _arc_fractions(P, counts)
    gstrand_of = np.repeat(np.arange(ng), gcount)
    keys = 2.0 * gstrand_of + f_g  # sorted: fractions lie in [0, 1] and strands are contiguous
    g_v = nbr[strand_of]  # (V, K)
    q = 2.0 * g_v + s_r[:, None]
    j = np.searchsorted(keys, q, side="right") - 1
    j = np.clip(j, gstart[g_v], gstart[g_v] + gcount[g_v] - 2)
    fj, fj1 = f_g[j], f_g[j + 1]
    u = np.clip((s_r[:, None] - fj) / (fj1 - fj), 0.0, 1.0)
    # A guide's own vertices: edge = its own local index, u = 0 (u = 1 at the tip), exactly.
    own = is_guide[strand_of]
    if own.any():
        g_own = guide_of_strand[strand_of[own]]
        m_own = gcount[g_own]
        jl = np.minimum(local[own], m_own - 2)
        j[own, 0] = gstart[g_own] + jl
        u[own, 0] = np.where(local[own] == m_own - 1, 1.0, 0.0)

    # Frame coordinates in the rest frames of the guide edges (columns t, d1, d2).
    local_c = np.empty((nv, K, 3))
    for k in range(K):
        jk, uk = j[:, k], u[:, k][:, None]
        o = (1.0 - uk) * X[jk] + uk * X[jk + 1]
        d = P - o
        local_c[:, k, 0] = np.einsum("ij,ij->i", d, t[jk])
        local_c[:, k, 1] = np.einsum("ij,ij->i", d, d1[jk])
        local_c[:, k, 2] = np.einsum("ij,ij->i", d, d2[jk])
    if own.any():
        local_c[own, 0] = 0.0  # exactly zero (it is, up to rounding of p - o)
    return j, u, local_c


def proxy_vertices(rest_points: np.ndarray, strand_offsets: np.ndarray, guides: np.ndarray) -> np.ndarray:
    """Vertex simulated in place of each vertex, int64 (vertex_count,): itself on a guide strand; on
    another strand, the vertex of its nearest guide (by rest root) at the nearest rest arc fraction.

    Args:
        rest_points: (vertex_count, 3) rest positions of every strand, flat [m].
        strand_offsets: (strand_count + 1,) first vertex of each strand, then vertex_count.
        guides: sorted int64 indices of the guide strands.
    """
    off = np.asarray(strand_offsets, dtype=np.int64)
    strand_count = off.shape[0] - 1
    proxy = np.arange(rest_points.shape[0], dtype=np.int64)
    if guides.size < strand_count:
        rest = rest_points.astype(np.float64)
        roots = rest[off[:-1]]
        from scipy.spatial import cKDTree

        _, nearest = cKDTree(roots[guides]).query(roots)
        counts = np.diff(off)
        frac, _ = _arc_fractions(rest, counts)  # per vertex, each strand's own cumulative sum
        # Vectorised over vertices: the nearest rest arc fraction on the nearest guide, by a
        # search in keys 2 s + f (sorted: fractions lie in [0, 1], strands are contiguous).
        strand_of = np.repeat(np.arange(strand_count), counts)
        keys = 2.0 * strand_of + frac
        gs = guides[nearest[strand_of]]  # the guide strand each vertex follows
        first = off[gs]
        idx = np.searchsorted(keys, 2.0 * gs + frac, side="left") - first
        idx = np.clip(idx, 1, counts[gs] - 1)
        idx -= (frac - frac[first + idx - 1]) < (frac[first + idx] - frac)
        is_guide = np.zeros(strand_count, dtype=bool)
        is_guide[guides] = True
        skinned = ~is_guide[strand_of]
        proxy[skinned] = (first + idx)[skinned]
    return proxy
