"""Guides and linear blend skinning of render strands (Daviet 2023, Sec. 5.3).

Physics-based grooming simulates only a fraction (about 10 %) of the strands,
the *guides*, and deforms the remaining *render strands* by linear blend
skinning (LBS) of the guides' motion.  Three stages:

1. **Guide selection** (:func:`select_guides`, :func:`build_guides`): farthest-
   point sampling of the root positions from a seeded start, so the guides
   cover the scalp evenly; the guide-only :class:`Model` is made by
   :class:`GroomBuilder` with the same polylines and materials.
2. **Binding** (:func:`compute_binding`, host NumPy, float64, once): each render
   strand is bound to its k nearest guides by root distance, with normalised
   inverse-distance weights (a guide binds to itself with weight 1).  Along the
   strand, binding is by normalised arc length: a render vertex at arc
   fraction s follows, on every bound guide, the rest edge j that contains the
   guide's own arc fraction s, at the edge parameter u in [0, 1].  The render
   vertex's rest position p is stored in that edge's rest frame Q_j (columns
   t, d1, d2):  ``c = Q_j^T (p - o_j(u))``,  ``o_j(u) = (1-u) x_j + u x_{j+1}``.
3. **Deformation** (:meth:`SkinningLBS.deform`, two Taichi kernels per frame):
   the current frame Q'_j of every guide edge is computed, then each render
   vertex is placed at ``x = sum_k w_k [ o'_jk(u_k) + Q'_jk c_k ]``.  Each term
   is the rigid motion of edge j from rest to now (rotation Q'_j Q_j^T, origin
   carried with the edge), applied to p; the origin is interpolated on the
   *current* edge so that a stretched guide still carries its own vertices
   exactly (u = 0 or 1, c = 0).  The root vertex of a clamped render strand is
   placed by its body transform, x = R_b p + T_b, so roots stay on the scalp.

Frames (``SkinningConfig.frame``):

* ``"transport"`` (default): the root edge's director is the body-rotated rest
  root director (``R_b strand_root_director``; a free root transports the rest
  director from the rest to the current root tangent), then it is *space*-
  parallel transported along the current guide, as :class:`GroomBuilder` does
  at rest.  Space-parallel transport commutes with rotations, so a rigid
  motion of the guides is reproduced exactly (to float rounding) on every
  render strand; it needs positions only, so it works for any solver.  It
  ignores the rods' twist: a twisting guide does not swing its render strands
  around it.
* ``"material"``: the DER material frame of the State (``edge_tangent``,
  ``edge_material_d1``, ``edge_material_d2``), against the material frame of
  the rest State.  Follows the simulated twist, but needs a State whose frames
  are up to date with its positions (as after :meth:`SolverADMM.step`); the
  time-parallel transported reference frame makes rigid motions reproduced
  only as well as the solver keeps twist consistent.

4. **Interpolation error** (:func:`interpolation_error`, :func:`error_colors`):
   per-vertex distance to a reference (e.g. a full simulation of all strands),
   per-strand max and RMS [m], and an RGB ramp for an overlay.

Everything is allocated in :class:`SkinningLBS` ``__init__``; ``deform``
allocates nothing.
"""


import math
from dataclasses import dataclass

import numpy as np
import taichi as ti

from ..builder import GroomBuilder, points_array
from ..config import RodMaterial
from ..model import Model, _np_float
from ..state import Control, State
from ..strains import parallel_transport

vec3 = ti.math.vec3
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
    polylines = _as_polylines(strands, "build_guides: field 'strands'")
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


def _as_polylines(strands, name: str) -> list:
    """Validate render polylines (vectorised over strands); returns a list of (m_s, 3) float64 arrays."""
    if isinstance(strands, np.ndarray) and strands.ndim == 3 and strands.shape[2] == 3:
        out = list(np.asarray(strands, dtype=np.float64))
    else:
        out = []
        try:
            for i, p in enumerate(strands):
                out.append(points_array(p, f"{name}[{i}]", "m"))
        except TypeError:
            raise ValueError(f"{name} must be a sequence of (m, 3) polylines") from None
    if not out:
        raise ValueError(f"{name} is empty")
    counts = np.array([p.shape[0] for p in out], dtype=np.int64)
    short = np.where(counts < 2)[0]
    if short.size:
        i = int(short[0])
        raise ValueError(f"{name}[{i}] has {counts[i]} vertices; a strand needs at least 2")
    flat = np.concatenate(out)
    strand_of = np.repeat(np.arange(counts.size), counts)
    bad = np.where(~np.all(np.isfinite(flat), axis=1))[0]
    if bad.size:
        raise ValueError(f"{name}[{int(strand_of[bad[0]])}] has a non-finite coordinate")
    same = strand_of[1:] == strand_of[:-1]
    zero = np.where(same & np.all(flat[1:] == flat[:-1], axis=1))[0]
    if zero.size:
        raise ValueError(f"{name}[{int(strand_of[zero[0]])}] has a zero-length edge (repeated point)")
    return out


def _per_strand(value, count: int, name: str, default):
    """None -> default for all; a scalar/object -> for all; a sequence -> checked length."""
    if value is None:
        return [default] * count
    if isinstance(value, (list, tuple, np.ndarray)):
        if len(value) != count:
            raise ValueError(f"{name} has {len(value)} entries for {count} strands")
        return list(value)
    return [value] * count


# =========================================================================== binding (host)
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
                    frame: str = "transport", guide_rest_frames=None) -> dict:
    """Bind render strands to guides (NumPy, float64).  See the module docstring.

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
        ``render_vertex_bind_weight`` (V, K).
    """
    from scipy.spatial import cKDTree

    _check_neighbours("compute_binding: field 'neighbour_count'", neighbour_count)
    if frame not in FRAMES:
        raise ValueError(f"compute_binding: field 'frame' must be one of {FRAMES}, got {frame!r}")
    if frame == "material" and guide_rest_frames is None:
        raise ValueError("compute_binding: field 'guide_rest_frames' is needed for frame='material'")
    polylines = _as_polylines(strands, "compute_binding: field 'strands'")
    h = guide_model.host
    gstart = h["strand_vertex_start"].astype(np.int64)
    gcount = h["strand_vertex_count"].astype(np.int64)
    ng = gstart.shape[0]
    gidx = np.asarray(guide_indices, dtype=np.int64).reshape(-1)
    if gidx.shape[0] != ng:
        raise ValueError(f"compute_binding: field 'guide_indices' has {gidx.shape[0]} entries but the guide model "
                         f"has {ng} strands (root count mismatch)")
    ns = len(polylines)
    if gidx.size and (gidx.min() < 0 or gidx.max() >= ns):
        raise ValueError(f"compute_binding: field 'guide_indices' must index the {ns} render strands")
    if np.unique(gidx).size != gidx.size:
        raise ValueError("compute_binding: field 'guide_indices' has repeated strands")
    X = h["vertex_rest_position"].astype(np.float64)
    counts = np.array([p.shape[0] for p in polylines], dtype=np.int64)
    mismatch = np.where(counts[gidx] != gcount)[0]
    if not mismatch.size:
        gp = np.concatenate([polylines[s] for s in gidx])
        far = np.any(np.abs(gp - X) > 1e-9, axis=1)
        mismatch = np.unique(np.repeat(np.arange(ng), gcount)[far])
    if mismatch.size:
        g = int(mismatch[0])
        raise ValueError(f"compute_binding: field 'guide_indices': guide {g} is not render strand {int(gidx[g])} "
                         "(different rest polyline)")

    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    P = np.concatenate(polylines)
    nv = P.shape[0]
    strand_of = np.repeat(np.arange(ns), counts)
    local = np.arange(nv) - starts[strand_of]
    K = min(int(neighbour_count), ng)

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
    guide_of_strand = np.full(ns, -1, dtype=np.int64)
    guide_of_strand[gidx] = np.arange(ng)
    is_guide = guide_of_strand >= 0
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

    # Arc-length correspondence: segment j of guide g holding fraction s, parameter u.
    s_r, _ = _arc_fractions(P, counts)
    f_g, _ = _arc_fractions(X, gcount)
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

    # Rest frames of the guide edges (columns t, d1, d2).
    if frame == "transport":
        t = h["edge_rest_tangent"].astype(np.float64)
        d1 = h["edge_rest_director"].astype(np.float64)
        d2 = np.cross(t, d1)
    else:
        t, d1, d2 = (np.asarray(a, dtype=np.float64) for a in guide_rest_frames)
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
    }


# =========================================================================== fields
class SkinningFields:
    """Binding and output fields of the render strands, allocated once.

    ``V`` = render vertex count, ``K`` = neighbour count (guides per render strand).
    """

    def __init__(self, render_vertex_count: int, neighbour_count: int, guide_vertex_count: int):
        V, K = render_vertex_count, neighbour_count
        #: Rest (bind-pose) position p of each render vertex [m], shape (V,).
        self.render_vertex_rest_position = ti.Vector.field(3, float, V)
        #: Body a clamped render root is attached to, -1 for every other vertex [-], shape (V,).
        self.render_vertex_body = ti.field(ti.i32, V)
        #: Guide edge j followed in each slot: index of the edge's first vertex in the
        #: guide model's flat vertex array [-], shape (V, K).
        self.render_vertex_bind_edge = ti.field(ti.i32, (V, K))
        #: Parameter u of the bound point o = (1-u) x_j + u x_{j+1} on that edge [-], shape (V, K).
        self.render_vertex_bind_param = ti.field(float, (V, K))
        #: Local coordinates c = Q_j^T (p - o_j) of the rest render vertex in the rest
        #: frame of guide edge j, components along (t, d1, d2) [m], shape (V, K).
        self.render_vertex_bind_local = ti.Vector.field(3, float, (V, K))
        #: Blend weight w_k of each slot (sum over k is 1) [-], shape (V, K).
        self.render_vertex_bind_weight = ti.field(float, (V, K))
        #: Current frame Q'_j of each guide edge, columns (t, d1, d2) [-], shape
        #: (guide_vertex_count,); the ghost slot of each strand is unused.
        self.guide_edge_frame = ti.Matrix.field(3, 3, float, guide_vertex_count)
        #: Skinned render vertex positions x [m], shape (V,).  Output of deform().
        self.render_vertex_position = ti.Vector.field(3, float, V)


@ti.func
def frame_matrix(t: vec3, d1: vec3):
    """3x3 matrix with columns (t, d1, t x d1) after making d1 orthonormal to the unit t."""
    d = (d1 - d1.dot(t) * t).normalized()
    return ti.Matrix.cols([t, d, t.cross(d)])


# =========================================================================== kernels
@ti.kernel
def compute_guide_frames_transport(
    vertex: ti.template(),
    strand: ti.template(),
    body_rotation: ti.template(),
    x: ti.template(),
    guide_edge_frame: ti.template(),
):
    """Frames of the current guide edges: the root director rotated with the root body
    (or transported from the rest root tangent for a free root), then space-parallel
    transported along each guide, as GroomBuilder does at rest.  Parallel over guides."""
    for s in strand.strand_vertex_start:
        start = strand.strand_vertex_start[s]
        m = strand.strand_vertex_count[s]
        t_prev = (x[start + 1] - x[start]).normalized()
        d1 = strand.strand_root_director[s]
        b = strand.strand_body[s]
        if b >= 0:
            d1 = body_rotation[b] @ d1
        else:
            t_rest = (vertex.vertex_rest_position[start + 1] - vertex.vertex_rest_position[start]).normalized()
            d1 = parallel_transport(d1, t_rest, t_prev)
        Q = frame_matrix(t_prev, d1)
        guide_edge_frame[start] = Q
        d1 = ti.Vector([Q[0, 1], Q[1, 1], Q[2, 1]])
        for j in range(1, m - 1):
            t = (x[start + j + 1] - x[start + j]).normalized()
            Qj = frame_matrix(t, parallel_transport(d1, t_prev, t))
            guide_edge_frame[start + j] = Qj
            d1 = ti.Vector([Qj[0, 1], Qj[1, 1], Qj[2, 1]])
            t_prev = t


@ti.kernel
def compute_guide_frames_material(edge: ti.template(), es: ti.template(), guide_edge_frame: ti.template()):
    """Frames of the current guide edges from the State's DER material frame (t, m1, m2)."""
    for i in guide_edge_frame:
        if edge.edge_rest_length[i] > 0.0:
            guide_edge_frame[i] = frame_matrix(es.edge_tangent[i], es.edge_material_d1[i])


@ti.kernel
def apply_skinning(
    sk: ti.template(),
    neighbour_count: ti.template(),
    x: ti.template(),
    body_rotation: ti.template(),
    body_translation: ti.template(),
    out: ti.template(),
):
    """x = sum_k w_k [ (1-u_k) x_j + u_k x_{j+1} + Q'_j c_k ]  (linear blend skinning);
    clamped render roots: x = R_b p + T_b."""
    for i in out:
        b = sk.render_vertex_body[i]
        if b >= 0:
            out[i] = body_rotation[b] @ sk.render_vertex_rest_position[i] + body_translation[b]
        else:
            acc = vec3(0.0)
            for k in ti.static(range(neighbour_count)):
                e = sk.render_vertex_bind_edge[i, k]
                u = sk.render_vertex_bind_param[i, k]
                o = (1.0 - u) * x[e] + u * x[e + 1]
                acc += sk.render_vertex_bind_weight[i, k] * (o + sk.guide_edge_frame[e] @ sk.render_vertex_bind_local[i, k])
            out[i] = acc


# =========================================================================== skinning
class SkinningLBS:
    """Linear blend skinning of render strands by simulated guides (Sec. 5.3).

    Args:
        guide_model: the guide :class:`Model` (e.g. from :func:`build_guides`).
        guide_indices: (guide_count,) render strand index of each guide strand.
        strands: the render polylines (all strands, guides included), root first [m].
        config: :class:`SkinningConfig` (``neighbour_count`` and ``frame`` are used).
        strand_body: body each render root is clamped to: an int for all, a per-strand
            sequence, or -1 for free roots (no pinning; use -1 for guides built with
            ``root="free"``).  Default 0.

    Example::

        guides, guide_model = build_guides(strands, RodMaterial())
        skin = SkinningLBS(guide_model, guides, strands)
        state, control = guide_model.state(), guide_model.control()
        solver = SolverADMM(guide_model)
        solver.step(state, control, 1 / 96)
        skin.deform(state, control)          # skin.fields.render_vertex_position

    Attributes:
        fields: :class:`SkinningFields` (binding, guide frames, output positions).
        host: the NumPy binding of :func:`compute_binding` (float64).
        render_vertex_count, render_strand_count, neighbour_count: sizes [-].
    """

    def __init__(self, guide_model: Model, guide_indices, strands, config: SkinningConfig | None = None,
                 strand_body=0):
        self.config = config or SkinningConfig()
        self.guide_model = guide_model
        self._strand_body = strand_body
        self.guide_indices = np.asarray(guide_indices, dtype=np.int64)
        h = self._binding(strands)
        self.render_strand_count = int(h["render_strand_vertex_count"].shape[0])
        self.render_vertex_count = int(h["render_vertex_rest_position"].shape[0])
        self.neighbour_count = int(h["render_vertex_bind_edge"].shape[1])
        self.fields = SkinningFields(self.render_vertex_count, self.neighbour_count, guide_model.vertex_count)
        self._upload(h)

    def _binding(self, strands) -> dict:
        rest_frames = None
        if self.config.frame == "material":
            rest = self.guide_model.state()
            rest_frames = (rest.edge_tangent.to_numpy(), rest.edge_material_d1.to_numpy(),
                           rest.edge_material_d2.to_numpy())
        h = compute_binding(self.guide_model, self.guide_indices, strands, self.config.neighbour_count,
                            self.config.frame, rest_frames)
        ns = h["render_strand_vertex_count"].shape[0]
        bodies = np.asarray(_per_strand(self._strand_body, ns, "SkinningLBS: field 'strand_body'", 0),
                            dtype=np.int64)
        if bodies.size and (bodies.min() < -1 or bodies.max() >= self.guide_model.body_count):
            raise ValueError(f"SkinningLBS: field 'strand_body' must be -1 or in [0, {self.guide_model.body_count})")
        vertex_body = np.full(h["render_vertex_rest_position"].shape[0], -1, dtype=np.int32)
        vertex_body[h["render_strand_vertex_start"]] = bodies
        h["render_vertex_body"] = vertex_body
        return h

    def _upload(self, h: dict) -> None:
        self.host = h
        f = _np_float()
        sk = self.fields
        sk.render_vertex_rest_position.from_numpy(h["render_vertex_rest_position"].astype(f))
        sk.render_vertex_body.from_numpy(h["render_vertex_body"])
        sk.render_vertex_bind_edge.from_numpy(h["render_vertex_bind_edge"].astype(np.int32))
        sk.render_vertex_bind_param.from_numpy(h["render_vertex_bind_param"].astype(f))
        sk.render_vertex_bind_local.from_numpy(h["render_vertex_bind_local"].astype(f))
        sk.render_vertex_bind_weight.from_numpy(h["render_vertex_bind_weight"].astype(f))

    def rebind(self, strands) -> None:
        """Bind again, into the same fields, after the rest shapes changed in place (the guide
        Model updated by :meth:`Model.update`, the render strands edited) with the same layout:
        same render vertex counts per strand, same guides.  No field is allocated, so no kernel
        is compiled again; the result equals a new :class:`SkinningLBS` of the same inputs.
        (``frame="material"`` reads the rest frames from a new rest State of the guide Model:
        that allocates one State per call.)"""
        h = self._binding(strands)
        if not (np.array_equal(h["render_strand_vertex_count"], self.host["render_strand_vertex_count"])
                and h["render_vertex_bind_edge"].shape == self.host["render_vertex_bind_edge"].shape):
            raise ValueError("SkinningLBS.rebind: the render strands' vertex counts (or the neighbour count) "
                             "differ from the bound ones; build a new SkinningLBS")
        self._upload(h)

    def deform(self, guide_state: State, control: Control) -> None:
        """Skin the render strands to ``guide_state`` (positions, and frames for
        ``frame="material"``) with the body transforms of ``control``.  Result in
        ``fields.render_vertex_position``; allocates nothing."""
        m, sk = self.guide_model, self.fields
        if self.config.frame == "transport":
            compute_guide_frames_transport(m, m, control.body_rotation, guide_state.vertex_position,
                                           sk.guide_edge_frame)
        else:
            compute_guide_frames_material(m, guide_state, sk.guide_edge_frame)
        apply_skinning(sk, self.neighbour_count, guide_state.vertex_position, control.body_rotation,
                       control.body_translation, sk.render_vertex_position)

    def positions(self) -> np.ndarray:
        """Skinned render vertex positions, shape (render_vertex_count, 3) [m]."""
        return self.fields.render_vertex_position.to_numpy()


# =========================================================================== interpolation error
@dataclass
class InterpolationError:
    """Distance between skinned and reference render strands.

    Attributes:
        vertex_error: |x_skinned - x_reference| per vertex [m], shape (V,).
        strand_error_max: max of vertex_error over each strand [m], shape (S,).
        strand_error_rms: root mean square of vertex_error over each strand [m], shape (S,).
        strand_vertex_start: first vertex of each strand [-], shape (S,).
        strand_vertex_count: vertices of each strand [-], shape (S,).
    """

    vertex_error: np.ndarray
    strand_error_max: np.ndarray
    strand_error_rms: np.ndarray
    strand_vertex_start: np.ndarray
    strand_vertex_count: np.ndarray

    def vertex_strand_error(self, kind: str = "max") -> np.ndarray:
        """The per-strand error (``"max"`` or ``"rms"``) repeated on every vertex of the strand [m], shape (V,)."""
        if kind not in ("max", "rms"):
            raise ValueError(f"InterpolationError.vertex_strand_error: field 'kind' must be 'max' or 'rms', got {kind!r}")
        per = self.strand_error_max if kind == "max" else self.strand_error_rms
        return np.repeat(per, self.strand_vertex_count)


def interpolation_error(positions, reference_positions, strand_vertex_count) -> InterpolationError:
    """Per-vertex and per-strand distance of skinned render strands to a reference.

    Args:
        positions: (V, 3) skinned positions [m] (e.g. :meth:`SkinningLBS.positions`).
        reference_positions: (V, 3) reference positions [m] (e.g. a simulation of all strands,
            built in the same strand order).
        strand_vertex_count: (S,) vertices per strand, summing to V.
    """
    x = _as_points(positions, "interpolation_error: field 'positions'")
    r = _as_points(reference_positions, "interpolation_error: field 'reference_positions'")
    if r.shape != x.shape:
        raise ValueError(f"interpolation_error: field 'reference_positions' has shape {r.shape}, "
                         f"positions have {x.shape}")
    counts = np.asarray(strand_vertex_count, dtype=np.int64).reshape(-1)
    if counts.size == 0 or counts.min() < 1 or int(counts.sum()) != x.shape[0]:
        raise ValueError(f"interpolation_error: field 'strand_vertex_count' must be positive and sum to "
                         f"{x.shape[0]} vertices, got a sum of {int(counts.sum())}")
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    err = np.linalg.norm(x - r, axis=1)
    emax = np.maximum.reduceat(err, starts)
    erms = np.sqrt(np.add.reduceat(err**2, starts) / counts)
    return InterpolationError(err, emax, erms, starts, counts)


#: Colour ramp of :func:`error_colors`: dark blue, teal, green, yellow, red.
_RAMP = np.array([[0.05, 0.10, 0.45], [0.10, 0.55, 0.65], [0.30, 0.75, 0.30], [0.95, 0.85, 0.15],
                  [0.85, 0.10, 0.10]])


def error_colors(values, vmax: float | None = None) -> np.ndarray:
    """Map non-negative errors to RGB in [0, 1] for an overlay (NumPy).

    Args:
        values: (n,) errors [m] (e.g. ``InterpolationError.vertex_error``).
        vmax: error mapped to the top of the ramp (red) [m]; default the largest value.
            0 maps to dark blue; values above vmax are clamped.

    Returns:
        (n, 3) float32 RGB colours.
    """
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    if not np.all(np.isfinite(v)):
        raise ValueError("error_colors: field 'values' has a non-finite entry")
    top = float(v.max()) if vmax is None and v.size else (vmax if vmax is not None else 1.0)
    if not (math.isfinite(top) and top >= 0.0):
        raise ValueError(f"error_colors: field 'vmax' must be finite and >= 0, got {vmax!r}")
    a = np.clip(v / top, 0.0, 1.0) if top > 0 else np.zeros_like(v)
    pos = a * (len(_RAMP) - 1)
    i0 = np.minimum(pos.astype(np.int64), len(_RAMP) - 2)
    f = (pos - i0)[:, None]
    return ((1.0 - f) * _RAMP[i0] + f * _RAMP[i0 + 1]).astype(np.float32)
