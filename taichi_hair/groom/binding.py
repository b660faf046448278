"""Binding of render strands to guides (Daviet 2023, Sec. 5.3), float64, once per rest shape.

Stage 2 of :mod:`taichi_hair.groom.skinning` (:func:`compute_binding`): each render strand is
bound to its k nearest guides by root distance, with normalised inverse-distance weights (a guide
binds to itself with weight 1).  Along the strand, binding is by normalised arc length: a render
vertex at arc fraction s follows, on every bound guide, the rest edge j that contains the guide's
own arc fraction s, at the edge parameter u in [0, 1].  The render vertex's rest position p is
stored in that edge's rest frame Q_j (columns t, d1, d2):  ``c = Q_j^T (p - o_j(u))``,
``o_j(u) = (1-u) x_j + u x_{j+1}``.

Where it runs: the nearest guides and the weights in NumPy (scipy's k-d tree); the per-vertex part (arc
fractions, edge, parameter, frame coordinates) in one Taichi kernel, float64, a thread per render strand
(:func:`_bind_kernel`; Taichi must be initialised, as for everything that makes fields).  Measured on the
grooming benchmark's 86,000 strands (1.2 M vertices, k = 4): an edit's in-place update 1.0-1.2 s -> 0.3-0.5 s,
of which the kernel ~0.07 s, against 0.88 s for the same part vectorised in NumPy (BENCHMARKS.md, issue 15).

:func:`proxy_vertices` is the same correspondence reduced to one guide vertex: the vertex a
grooming session moves in place of a vertex of a skinned strand.
"""


import numpy as np
import taichi as ti

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
                    frame: str = "transport", guide_rest_frames=None, previous: dict | None = None,
                    rebound: list | None = None) -> dict:
    """Bind render strands to guides (float64; arrays on the host).  See the module docstring.

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
        rebound: a list, or None; a list gets one item appended: the render strands bound again (sorted int64)
            when ``previous`` was reused, None when the binding was done in full (every row may differ).

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
        gp = P[vertex_rows(starts[gidx], gcount)]
        far = np.any(np.abs(gp - X) > 1e-9, axis=1)
        mismatch = np.unique(np.repeat(np.arange(ng), gcount)[far])
    if mismatch.size:
        g = int(mismatch[0])
        raise ValueError(f"compute_binding: field 'guide_indices': guide {g} is not render strand {int(gidx[g])} "
                         "(different rest polyline)")

    nv = P.shape[0]
    strand_of = np.repeat(np.arange(ns), counts)
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
    geometry = (X, gstart, gcount, f_g, t, d1, d2, guide_of_strand)

    rebind = _strands_to_rebind(previous, P, X, counts, starts, gstart, gcount, K, frame)
    redo, slots = rebind if rebind is not None else (None, None)
    if rebound is not None:
        rebound.append(redo)
    if redo is not None:
        out = dict(previous)
        out["render_vertex_rest_position"] = P
        out["guide_vertex_rest_position"] = X
        if redo.size:
            # In place, the kernel writing the rows of the strands bound again (a copy of the 1.2M-vertex
            # arrays cost 0.3-0.4 s, and a gather and scatter of their rows 0.1 s).
            arrays = []
            for key, dtype in (("render_vertex_bind_edge", np.int64), ("render_vertex_bind_param", np.float64),
                               ("render_vertex_bind_local", np.float64)):
                a = previous[key]
                if not (a.flags.c_contiguous and a.flags.writeable and a.dtype == dtype):
                    a = np.ascontiguousarray(a, dtype=dtype).copy()
                out[key] = a
                arrays.append(a)
            _bind_vertices(P, starts[redo], counts[redo], redo, previous["render_strand_guides"], geometry, *arrays,
                           slots=slots)
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

    j = np.empty((nv, K), dtype=np.int64)
    u = np.empty((nv, K))
    local_c = np.empty((nv, K, 3))
    _bind_vertices(P, starts, counts, np.arange(ns), nbr, geometry, j, u, local_c)
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


def vertex_rows(starts: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """The vertex rows of strands starting at ``starts`` with ``counts`` vertices, one strand after another, int64
    (vectorised: no per-strand slices; the binding, the skinning's partial upload, the edits and the guides use it)."""
    return np.repeat(starts - np.cumsum(counts) + counts, counts) + np.arange(int(counts.sum()))


def _strands_differ(a: np.ndarray, b: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """Strands of two (V, 3) arrays (the same layout, strand s from row ``starts[s]``, every strand at least one row)
    with any coordinate different, (S,) bool: ``np.any(a != b)`` over each strand's rows.  One comparison of the flat
    arrays and one ``reduceat`` over the strands' first coordinates: on the 86,000-strand groom's 1.2 M rows 6.6-7.0 ms
    against 17-19 ms for a comparison per column and a reduction per row (NumPy reduces along a short last axis
    slowly), the same result (scratch probe 2026-12-07)."""
    if not starts.size:
        return np.zeros(0, bool)
    return np.logical_or.reduceat((a != b).reshape(-1), 3 * np.asarray(starts, np.int64))


def _strands_to_rebind(previous, P, X, counts, starts, gstart, gcount, K, frame):
    """``(strands, slots)``: the render strands an edit changed, directly or through a bound guide (sorted int64),
    and which of their K guide slots to bind again ((len(strands), K) bool: every slot of a strand whose own rest
    polyline changed, else the slots of its guides that changed); or None when ``previous`` cannot be reused: another
    layout, a moved root, or ``frame="material"``.  A slot's rows depend on the strand's own polyline and that one
    guide's only (``_bind_kernel``), so the slots left keep their rows bit for bit: in the grooming benchmark's edit,
    34,587 strands are bound again, most of them for one changed guide of their four."""
    if previous is None or frame != "transport" or "guide_vertex_rest_position" not in previous:
        return None
    P0, X0 = previous["render_vertex_rest_position"], previous["guide_vertex_rest_position"]
    if (P0.shape != P.shape or X0.shape != X.shape or previous["render_strand_guides"].shape[1] != K
            or not np.array_equal(previous["render_strand_vertex_count"], counts)):
        return None
    if not (np.array_equal(P0[starts], P[starts]) and np.array_equal(X0[gstart], X[gstart])):
        return None  # a root moved: the nearest guides and the weights change
    moved_r = _strands_differ(P0, P, starts)
    moved_g = _strands_differ(X0, X, gstart)
    slots = moved_r[:, None] | moved_g[previous["render_strand_guides"]]
    redo = np.nonzero(slots.any(axis=1))[0]
    return redo, slots[redo]


def _bind_vertices(P, first, counts, strand_ids, nbr, geometry, j, u, local_c, slots=None) -> None:
    """Edge j, parameter u and frame coordinates (written into ``j`` (V, K) int64, ``u`` (V, K) and ``local_c``
    (V, K, 3), float64, C-contiguous) of the vertices of the render strands ``strand_ids``, whose rows in ``P``
    (V, 3) start at ``first`` and number ``counts``, in the guide slots ``slots`` ((len(strand_ids), K) bool; None:
    all); the other rows and slots are left as they are.  Each vertex and slot independently of the others: the
    kernel :func:`_bind_kernel`, float64, in parallel over the strands."""
    X, gstart, gcount, f_g, t, d1, d2, guide_of_strand = geometry
    if slots is None:
        slots = np.ones((counts.size, nbr.shape[1]), dtype=bool)
    if counts.size:
        f64, i64 = np.float64, np.int64
        _bind_kernel(np.ascontiguousarray(P, f64), np.ascontiguousarray(first, i64), np.ascontiguousarray(counts, i64),
                     np.ascontiguousarray(strand_ids, i64), np.ascontiguousarray(nbr, i64),
                     np.ascontiguousarray(X, f64), gstart, gcount, np.ascontiguousarray(f_g, f64),
                     np.ascontiguousarray(t, f64), np.ascontiguousarray(d1, f64), np.ascontiguousarray(d2, f64),
                     np.ascontiguousarray(guide_of_strand, i64), np.ascontiguousarray(slots, bool).view(np.uint8),
                     j, u, local_c)


_F64_2 = ti.types.ndarray(dtype=ti.f64, ndim=2)
_F64_1 = ti.types.ndarray(dtype=ti.f64, ndim=1)
_I64_1 = ti.types.ndarray(dtype=ti.i64, ndim=1)


@ti.func
def _row3(a: ti.template(), i):
    return ti.Vector([a[i, 0], a[i, 1], a[i, 2]], ti.f64)


@ti.kernel
def _bind_kernel(P: _F64_2, first: _I64_1, counts: _I64_1, strand_ids: _I64_1, nbr: ti.types.ndarray(dtype=ti.i64, ndim=2),
                 X: _F64_2, gstart: _I64_1, gcount: _I64_1, f_g: _F64_1, t: _F64_2, d1: _F64_2, d2: _F64_2,
                 guide_of_strand: _I64_1, slot: ti.types.ndarray(dtype=ti.u8, ndim=2),
                 j_out: ti.types.ndarray(dtype=ti.i64, ndim=2), u_out: _F64_2,
                 c_out: ti.types.ndarray(dtype=ti.f64, ndim=3)):
    """Per render strand (in parallel), per bound guide g, vertex after vertex: its normalised arc fraction s
    (running sum of the edge lengths over the strand's length, in the order of ``_arc_fractions``); the last
    vertex j of g with f_g[j] <= s, clamped to g's edges, and u = clamp((s - f_j) / (f_{j+1} - f_j), 0, 1); a
    guide's own vertices (slot 0 of a guide strand) take edge = their own index and u = 0 (u = 1 at the tip),
    exactly; then c = Q_j^T (p - o_j(u)) in the guide edge's rest frame (columns t, d1, d2), with c_t = 0
    exactly on a guide's own vertices.  Only the guide slots k with ``slot[i, k]`` nonzero are written (an edit's
    rebinding: the slots of the guides it changed); the arithmetic of a slot is its own, so the others keep their
    rows and equal what a full binding writes.

    j is found by a walk, not a search: s does not decrease along the strand (a running sum of norms over one
    length) and g's fractions do not decrease along g, so the first vertex of g past s only moves forward, and
    the walk meets it where a binary search would (the same j, u and c, bit for bit).  So the guides are the
    outer loop and s is summed again for each (m norms per guide, in the same order: the same bits).  Walk
    against binary search, the 86,000-strand groom's edit (34,587 strands bound again, k = 4; scratch probe
    2026-12-07, median of 5): 89-94 ms against 139-202 ms on the 2-core VM, the outputs identical."""
    K = nbr.shape[1]
    for i in range(counts.shape[0]):
        s0 = ti.cast(first[i], ti.i32)
        m = ti.cast(counts[i], ti.i32)
        r = strand_ids[i]
        length = ti.f64(0.0)
        for q in range(m - 1):
            length += (_row3(P, s0 + q + 1) - _row3(P, s0 + q)).norm()
        own_guide = guide_of_strand[r]
        for k in range(K):
            if slot[i, k] == 0:  # a guide slot this edit did not change: its rows stay
                continue
            g = nbr[r, k]
            gs = ti.cast(gstart[g], ti.i32)
            gc = ti.cast(gcount[g], ti.i32)
            own = own_guide >= 0 and k == 0
            lo = gs  # the first vertex of g whose fraction is > s (gs + gc: none); moves forward only
            cum = ti.f64(0.0)
            for q in range(m):
                if q > 0:
                    cum += (_row3(P, s0 + q) - _row3(P, s0 + q - 1)).norm()
                s = cum / length
                p = _row3(P, s0 + q)
                # (Not `while lo < gs + gc and f_g[lo] <= s`: Taichi's `and` evaluates both sides, which would read
                # one past the last guide's fractions.)
                while lo < gs + gc:
                    if f_g[lo] > s:
                        break
                    lo += 1
                j = ti.min(ti.max(lo - 1, gs), gs + gc - 2)
                u = ti.min(ti.max((s - f_g[j]) / (f_g[j + 1] - f_g[j]), 0.0), 1.0)
                if own:
                    m_own = ti.cast(gcount[own_guide], ti.i32)
                    j = ti.cast(gstart[own_guide], ti.i32) + ti.min(q, m_own - 2)
                    u = ti.f64(0.0)
                    if q == m_own - 1:
                        u = 1.0
                d = p - ((1.0 - u) * _row3(X, j) + u * _row3(X, j + 1))
                row = s0 + q
                j_out[row, k] = j
                u_out[row, k] = u
                c_out[row, k, 0] = d.dot(_row3(t, j))
                if own:
                    c_out[row, k, 0] = 0.0
                c_out[row, k, 1] = d.dot(_row3(d1, j))
                c_out[row, k, 2] = d.dot(_row3(d2, j))


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
