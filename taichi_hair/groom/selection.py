"""Selection of a grooming session: which vertices the hits of a brush, a pick ray or a list of
strands are, and how they combine with the current selection (Daviet 2023, Sec. 5.3).

Pure functions on NumPy arrays: ``points`` (vertex_count, 3) [m] the current pose, ``offsets`` the
(strand_count + 1,) strand offsets, a selection a bool (vertex_count,) mask.  An edge within the
radius selects both its vertices; a strand is selected when any of its vertices is.  ``mode`` is
"replace", "add" or "remove" (:data:`MODES`).
"""

from __future__ import annotations

import numpy as np

from .config import MODES


def edge_mask(offsets: np.ndarray, n: int) -> np.ndarray:
    """True for edge k (vertices k, k+1) when both lie on the same strand, shape (n - 1,)."""
    m = np.ones(max(n - 1, 0), dtype=bool)
    m[offsets[1:-1] - 1] = False
    return m


def _edges(points: np.ndarray, offsets: np.ndarray):
    p = points.astype(np.float64)
    mask = edge_mask(offsets, p.shape[0])
    k = np.nonzero(mask)[0]
    return p, k, p[k], p[k + 1] - p[k]


def _hit_from_edges(p: np.ndarray, k: np.ndarray, close: np.ndarray) -> np.ndarray:
    hit = np.zeros(p.shape[0], dtype=bool)
    hit[k[close]] = True
    hit[k[close] + 1] = True
    return hit


def combine(selection: np.ndarray, hit: np.ndarray, mode: str) -> np.ndarray:
    """The selection after ``hit`` (bool, (vertex_count,)) in ``mode``; raises for an unknown mode."""
    if mode not in MODES:
        raise ValueError(f"'mode' must be one of {MODES}, got {mode!r}")
    if mode == "replace":
        return hit
    if mode == "add":
        return selection | hit
    return selection & ~hit


def strands_of(selection: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Selected strands (any vertex selected), bool, shape (strand_count,)."""
    return np.logical_or.reduceat(selection, offsets[:-1])


def sphere_hits(points: np.ndarray, offsets: np.ndarray, center: np.ndarray, radius: float) -> np.ndarray:
    """Vertices of every edge within ``radius`` [m] of ``center`` [m], bool (vertex_count,)."""
    c, r = center, radius
    p, k, a, u = _edges(points, offsets)
    s = np.clip(np.einsum("ij,ij->i", c - a, u) / np.einsum("ij,ij->i", u, u), 0.0, 1.0)
    d = np.linalg.norm(a + s[:, None] * u - c, axis=1)
    return _hit_from_edges(p, k, d <= r)


def ray_hits(points: np.ndarray, offsets: np.ndarray, origin: np.ndarray, direction: np.ndarray,
             radius: float) -> np.ndarray:
    """Vertices of every edge within ``radius`` [m] of the half-line origin + t direction, t >= 0
    (``direction`` a unit vector), bool (vertex_count,)."""
    o, d, r = origin, direction, radius
    p, k, a, u = _edges(points, offsets)
    w = a - o
    aa = np.einsum("ij,ij->i", u, u)
    b = u @ d
    dd = np.einsum("ij,ij->i", u, w)
    e = w @ d

    def dist(s, t, i=slice(None)):
        return np.linalg.norm(w[i] + s[:, None] * u[i] - t[:, None] * d, axis=1)

    # Convex in (s, t): the minimum over s in [0, 1], t >= 0 is interior or on a boundary.
    best = dist(np.zeros_like(e), np.maximum(e, 0.0))
    best = np.minimum(best, dist(np.ones_like(e), np.maximum(e + b, 0.0)))
    best = np.minimum(best, dist(np.clip(-dd / aa, 0.0, 1.0), np.zeros_like(e)))
    den = aa - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        s_in = (b * e - dd) / den
    t_in = e + s_in * b
    ok = np.nonzero((den > 1e-14 * aa) & (s_in >= 0) & (s_in <= 1) & (t_in >= 0))[0]
    best[ok] = np.minimum(best[ok], dist(s_in[ok], t_in[ok], ok))
    return _hit_from_edges(p, k, best <= r)


def strand_indices(strands, strand_count: int) -> np.ndarray:
    """Strand indices as int64 (n,), checked to lie in [0, strand_count)."""
    try:
        idx = np.asarray(strands, dtype=np.int64).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f"'strands' must be a list of strand indices, got {strands!r}") from None
    if idx.size and (idx.min() < 0 or idx.max() >= strand_count):
        raise ValueError(f"'strands' must lie in [0, {strand_count}), got {idx.tolist()}")
    return idx


def strand_hits(idx: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Every vertex of the strands ``idx``, bool (vertex_count,)."""
    counts = np.diff(np.asarray(offsets, dtype=np.int64))
    strand_hit = np.zeros(counts.shape[0], dtype=bool)
    strand_hit[idx] = True
    return np.repeat(strand_hit, counts)


def grabbable(mask: np.ndarray, offsets: np.ndarray, proxy: np.ndarray) -> np.ndarray:
    """Vertices that move for ``mask`` (their ``proxy``: a guide vertex), without clamped root
    vertices (local index 0, 1), sorted int64."""
    counts = np.diff(np.asarray(offsets, dtype=np.int64))
    local = np.arange(mask.shape[0]) - np.repeat(offsets[:-1], counts)
    v = np.unique(proxy[mask & (local > 1)])
    local_v = local[v]
    return v[local_v > 1]
