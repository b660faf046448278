"""Guides: the strands a grooming simulation actually simulates (Daviet 2023, Sec. 5.3).

Stage 1 of :mod:`taichi_hair.groom.skinning`: **guide selection** (:func:`select_guides`,
:func:`build_guides`): farthest-point sampling of the root positions from a seeded start, so the
guides cover the scalp evenly; the guide-only :class:`Model` is made by :class:`GroomBuilder` with
the same polylines and materials.  Also here: :class:`SkinningConfig` (the settings of guide
selection and skinning) and the validation of render polylines shared by binding and skinning.
NumPy on the host (scipy's k-d tree, imported when used).
"""


import math
from dataclasses import dataclass

import numpy as np

from ..builder import GroomBuilder, points_array
from ..config import RodMaterial

FRAMES = ("transport", "material")


# =========================================================================== configuration
@dataclass
class SkinningConfig:
    """Settings of guide selection and skinning (Sec. 5.3).

    Attributes:
        guide_ratio: fraction of the strands simulated as guides, in (0, 1] [-];
            the paper uses 10 %.  The guide count is round(ratio * strands), at least 1.
        neighbour_count: k, number of guides each render strand follows [-];
            capped at the number of guides.
        frame: ``"transport"`` (space-parallel transported frame from the
            positions) or ``"material"`` (the State's DER material frame); see
            the module docstring.
        seed: seed of the random start of farthest-point sampling [-].
    """

    guide_ratio: float = 0.1
    neighbour_count: int = 4
    frame: str = "transport"
    seed: int = 0

    def __post_init__(self):
        _check_ratio("SkinningConfig.guide_ratio", self.guide_ratio)
        _check_neighbours("SkinningConfig.neighbour_count", self.neighbour_count)
        if self.frame not in FRAMES:
            raise ValueError(f"SkinningConfig.frame must be one of {FRAMES}, got {self.frame!r}")
        if not isinstance(self.seed, (int, np.integer)):
            raise ValueError(f"SkinningConfig.seed must be an integer, got {self.seed!r}")


def _check_ratio(name: str, ratio) -> None:
    if not (isinstance(ratio, (int, float, np.floating)) and math.isfinite(ratio) and 0.0 < ratio <= 1.0):
        raise ValueError(f"{name} must lie in (0, 1], got {ratio!r}")


def _check_neighbours(name: str, k) -> None:
    if not (isinstance(k, (int, np.integer)) and not isinstance(k, bool) and k >= 1):
        raise ValueError(f"{name} must be an integer >= 1, got {k!r}")


# =========================================================================== guide selection
def select_guides(root_positions, guide_ratio: float = 0.1, seed: int = 0) -> np.ndarray:
    """Farthest-point sampling of strand roots.

    Starts from a root drawn with ``numpy.random.default_rng(seed)``, then
    repeatedly adds the root farthest (Euclidean) from every root chosen so far
    (ties: lowest index), so the result is deterministic and spreads the
    guides evenly over the scalp.

    Args:
        root_positions: (strand_count, 3) root positions [m].
        guide_ratio: fraction of strands to choose, in (0, 1].
        seed: seed of the starting root.

    Returns:
        (guide_count,) int64 strand indices in the order chosen,
        guide_count = max(1, round(guide_ratio * strand_count)).
    """
    _check_ratio("select_guides: field 'guide_ratio'", guide_ratio)
    roots = _as_points(root_positions, "select_guides: field 'root_positions'")
    n = roots.shape[0]
    if n == 0:
        raise ValueError("select_guides: field 'root_positions' is empty")
    from scipy.spatial import cKDTree

    count = min(n, max(1, int(round(guide_ratio * n))))
    chosen = np.empty(count, dtype=np.int64)
    chosen[0] = int(np.random.default_rng(seed).integers(n))
    dist2 = np.sum((roots - roots[chosen[0]]) ** 2, axis=1)
    tree = cKDTree(roots)
    for c in range(1, count):
        nxt = int(np.argmax(dist2))
        chosen[c] = nxt
        # Only roots closer to the new guide than the current maximum distance can get
        # closer: update those (a ball query) instead of all n; same result as brute force.
        near = np.asarray(tree.query_ball_point(roots[nxt], math.sqrt(dist2[nxt]) * (1.0 + 1e-9) + 1e-300),
                          dtype=np.int64)
        if near.size:
            d2 = np.sum((roots[near] - roots[nxt]) ** 2, axis=1)
            dist2[near] = np.minimum(dist2[near], d2)
    return chosen


def build_guides(strands, materials=None, config: SkinningConfig | None = None, root: str = "clamped",
                 body=0):
    """Choose guides among render strand polylines and build the guide-only Model.

    Args:
        strands: sequence of (m_s, 3) polylines, root first [m] (the full groom).
        materials: None (default :class:`RodMaterial`), one RodMaterial for all,
            or a sequence with one per strand.
        config: :class:`SkinningConfig` (guide_ratio and seed are used).
        root, body: passed to :meth:`GroomBuilder.add_strand` for every guide;
            ``body`` may be an int or a per-strand sequence.

    Returns:
        ``(guide_indices, model)``: the strand indices of the guides (guide
        strand g of ``model`` is ``strands[guide_indices[g]]``, same material)
        and the guide :class:`Model`.
    """
    config = config or SkinningConfig()
    flat, counts = _flat_polylines(strands, "build_guides: field 'strands'")
    polylines = np.split(flat, np.cumsum(counts)[:-1])
    ns = len(polylines)
    mats = _per_strand(materials, ns, "build_guides: field 'materials'", RodMaterial())
    bodies = _per_strand(body, ns, "build_guides: field 'body'", 0)
    roots = np.array([p[0] for p in polylines])
    guide_indices = select_guides(roots, config.guide_ratio, config.seed)
    body_count = 1 + max(int(b) for b in bodies)
    builder = GroomBuilder(body_count=body_count)
    for s in guide_indices:
        builder.add_strand(polylines[s], mats[s], root=root, body=int(bodies[s]))
    return guide_indices, builder.finalize()


def _as_points(a, name: str) -> np.ndarray:
    arr = points_array(a, name)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} has a non-finite coordinate")
    return arr


def _read_only_f64(a: np.ndarray) -> bool:
    """A C-contiguous float64 array that neither it nor any array it is a view of can be written through."""
    if a.dtype != np.float64 or not a.flags.c_contiguous:
        return False
    while isinstance(a, np.ndarray):
        if a.flags.writeable:
            return False
        a = a.base
    return a is None


def _flat_polylines(strands, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Validate render polylines (vectorised over strands): ``(P, counts)``, the vertices of all strands one
    after another as a (V, 3) float64 array [m] (new, or a read-only input's own) and each strand's vertex
    count (S,).  A (S, m, 3) array (strands of one vertex count) is taken whole, without a per-strand slice."""
    if isinstance(strands, np.ndarray) and strands.ndim == 3 and strands.shape[2] == 3:
        # A float64 array nobody can write into (it and every array it views read-only, as a grooming session's
        # groom) is taken without a copy (1.2M vertices: 70 ms of an edit's update); any other is copied.
        flat = strands.reshape(-1, 3) if _read_only_f64(strands) else np.array(strands, dtype=np.float64).reshape(-1, 3)
        counts = np.full(strands.shape[0], strands.shape[1], dtype=np.int64)
    else:
        out = []
        try:
            for i, p in enumerate(strands):
                out.append(points_array(p, f"{name}[{i}]", "m"))
        except TypeError:
            raise ValueError(f"{name} must be a sequence of (m, 3) polylines") from None
        counts = np.array([p.shape[0] for p in out], dtype=np.int64)
        flat = np.concatenate(out) if out else np.zeros((0, 3))
    if not counts.size:
        raise ValueError(f"{name} is empty")
    short = np.where(counts < 2)[0]
    if short.size:
        i = int(short[0])
        raise ValueError(f"{name}[{i}] has {counts[i]} vertices; a strand needs at least 2")
    starts = np.cumsum(counts) - counts  # (the strand of a bad row by a search: no per-vertex strand index)
    # Whole-array tests, then the three columns combined: NumPy's reductions along a short last axis were 4-15x
    # slower (26.5 ms for the finite test of 1.2 M render vertices, 26.9 ms for the repeated points; 1.8 and 6.3 ms).
    finite = np.isfinite(flat)
    if not finite.all():
        bad = np.flatnonzero(~(finite[:, 0] & finite[:, 1] & finite[:, 2]))
        raise ValueError(f"{name}[{int(np.searchsorted(starts, bad[0], 'right')) - 1}] has a non-finite coordinate")
    repeated = (flat[1:, 0] == flat[:-1, 0]) & (flat[1:, 1] == flat[:-1, 1]) & (flat[1:, 2] == flat[:-1, 2])
    repeated[starts[1:] - 1] = False  # (a strand's last vertex and the next strand's root)
    zero = np.flatnonzero(repeated)
    if zero.size:
        raise ValueError(f"{name}[{int(np.searchsorted(starts, zero[0], 'right')) - 1}] has a zero-length edge "
                         "(repeated point)")
    return flat, counts


def _per_strand(value, count: int, name: str, default):
    """None -> default for all; a scalar/object -> for all; a sequence -> checked length."""
    if value is None:
        return [default] * count
    if isinstance(value, (list, tuple, np.ndarray)):
        if len(value) != count:
            raise ValueError(f"{name} has {len(value)} entries for {count} strands")
        return list(value)
    return [value] * count


class GuideChoice:
    """The guide strands of a grooming session, cached on the rest roots and the settings (edits
    keep the roots, so the farthest-point sampling runs once per layout)."""

    def __init__(self):
        self._cached = None

    def strands(self, rest_points: np.ndarray, strand_offsets: np.ndarray, guide_ratio: float,
                seed: int) -> np.ndarray:
        """int64 indices of the guides (every strand, in order, for ``guide_ratio`` 1), a copy, ordered along the
        principal axis of their roots: the simulation's strands in that order put each slab of the contact sweeps
        (``contact.slabs``) in memory of its own (the sweeps 1.4x faster on 2 cores, measured there)."""
        if guide_ratio >= 1.0:
            return np.arange(len(strand_offsets) - 1)
        roots = rest_points[strand_offsets[:-1]].astype(np.float64)  # (the roots first: 1.2 M points cast took 16 ms)
        key = (roots.tobytes(), guide_ratio, seed)
        if self._cached is not None and self._cached[0] == key:
            return self._cached[1].copy()
        from ..contact.slabs import principal_axis_order

        guides = np.sort(select_guides(roots, guide_ratio, seed))
        guides = guides[principal_axis_order(roots[guides])]
        self._cached = (key, guides)
        return guides.copy()
