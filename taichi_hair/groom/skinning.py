"""Guides and linear blend skinning of render strands (Daviet 2023, Sec. 5.3).

Physics-based grooming simulates only a fraction (about 10 %) of the strands,
the *guides*, and deforms the remaining *render strands* by linear blend
skinning (LBS) of the guides' motion.  Three stages:

1. **Guide selection** (:func:`select_guides`, :func:`build_guides`, in
   :mod:`taichi_hair.groom.guides`): farthest-point sampling of the root
   positions from a seeded start, so the guides cover the scalp evenly; the
   guide-only :class:`Model` is made by :class:`GroomBuilder` with the same
   polylines and materials.
2. **Binding** (:func:`compute_binding`, in :mod:`taichi_hair.groom.binding`,
   float64, once per rest shape; its per-vertex part a Taichi kernel): each render strand is bound to its k nearest
   guides by root distance, with normalised inverse-distance weights (a guide
   binds to itself with weight 1).  Along the strand, binding is by normalised
   arc length: a render vertex at arc fraction s follows, on every bound guide,
   the rest edge j that contains the guide's own arc fraction s, at the edge
   parameter u in [0, 1].  The render vertex's rest position p is stored in
   that edge's rest frame Q_j (columns t, d1, d2):  ``c = Q_j^T (p - o_j(u))``,
   ``o_j(u) = (1-u) x_j + u x_{j+1}``.
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
allocates nothing.  The names of stages 1 and 2 are importable from here too.
"""


import math
from dataclasses import dataclass

import numpy as np
import taichi as ti

from ..model import Model
from ..state import Control, State
from ..strains import parallel_transport
from .binding import _arc_fractions, compute_binding
from .guides import FRAMES, SkinningConfig, _as_points, _per_strand, build_guides, select_guides

__all__ = ["FRAMES", "SkinningConfig", "select_guides", "build_guides", "compute_binding", "SkinningFields",
           "frame_matrix", "compute_guide_frames_transport", "compute_guide_frames_material", "apply_skinning",
           "SkinningLBS", "InterpolationError", "interpolation_error", "error_colors", "_arc_fractions"]

vec3 = ti.math.vec3


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
@ti.func
def _upload_vertex(sk: ti.template(), v, rest: ti.template(), edge: ti.template(), param: ti.template(),
                   local: ti.template()):
    """Render vertex v's rest position and binding (edge, parameter, frame coordinates) into ``sk``, each value cast
    to the field's type: the part of ``upload_binding`` that ``upload_binding_rows`` shares."""
    K = ti.static(sk.render_vertex_bind_edge.shape[1])
    sk.render_vertex_rest_position[v] = ti.Vector([rest[v, 0], rest[v, 1], rest[v, 2]], float)
    for k in ti.static(range(K)):
        sk.render_vertex_bind_edge[v, k] = ti.cast(edge[v, k], ti.i32)
        sk.render_vertex_bind_param[v, k] = ti.cast(param[v, k], float)
        sk.render_vertex_bind_local[v, k] = ti.Vector([local[v, k, 0], local[v, k, 1], local[v, k, 2]], float)


@ti.kernel
def upload_binding(sk: ti.template(), rest: ti.types.ndarray(dtype=ti.f64, ndim=2),
                   body: ti.types.ndarray(dtype=ti.i32, ndim=1), edge: ti.types.ndarray(dtype=ti.i64, ndim=2),
                   param: ti.types.ndarray(dtype=ti.f64, ndim=2), local: ti.types.ndarray(dtype=ti.f64, ndim=3),
                   weight: ti.types.ndarray(dtype=ti.f64, ndim=2)):
    """Copy the host binding (:func:`compute_binding`'s arrays, float64 / int64) into the SkinningFields ``sk``,
    each value cast to the field's type (round to nearest, as NumPy's ``astype``)."""
    K = ti.static(sk.render_vertex_bind_edge.shape[1])
    for v in sk.render_vertex_body:
        _upload_vertex(sk, v, rest, edge, param, local)
        sk.render_vertex_body[v] = body[v]
        for k in ti.static(range(K)):
            sk.render_vertex_bind_weight[v, k] = ti.cast(weight[v, k], float)


@ti.kernel
def upload_binding_rows(sk: ti.template(), rows: ti.types.ndarray(dtype=ti.i64, ndim=1),
                        rest: ti.types.ndarray(dtype=ti.f64, ndim=2), edge: ti.types.ndarray(dtype=ti.i64, ndim=2),
                        param: ti.types.ndarray(dtype=ti.f64, ndim=2), local: ti.types.ndarray(dtype=ti.f64, ndim=3)):
    """``upload_binding`` of the render vertices ``rows`` only, without the weights and bodies (a rebind keeps them):
    the same casts, so the fields equal a full upload of the same arrays."""
    for r in range(rows.shape[0]):
        _upload_vertex(sk, ti.cast(rows[r], ti.i32), rest, edge, param, local)  # (an i32 index: no cast warning)


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

    def _binding(self, strands, previous: dict | None = None, rebound: list | None = None) -> dict:
        rest_frames = None
        if self.config.frame == "material":
            rest = self.guide_model.state()
            rest_frames = (rest.edge_tangent.to_numpy(), rest.edge_material_d1.to_numpy(),
                           rest.edge_material_d2.to_numpy())
        h = compute_binding(self.guide_model, self.guide_indices, strands, self.config.neighbour_count,
                            self.config.frame, rest_frames, previous, rebound)
        ns = h["render_strand_vertex_count"].shape[0]
        bodies = np.asarray(_per_strand(self._strand_body, ns, "SkinningLBS: field 'strand_body'", 0),
                            dtype=np.int64)
        if bodies.size and (bodies.min() < -1 or bodies.max() >= self.guide_model.body_count):
            raise ValueError(f"SkinningLBS: field 'strand_body' must be -1 or in [0, {self.guide_model.body_count})")
        vertex_body = np.full(h["render_vertex_rest_position"].shape[0], -1, dtype=np.int32)
        vertex_body[h["render_strand_vertex_start"]] = bodies
        h["render_vertex_body"] = vertex_body
        return h

    def _upload(self, h: dict, strands=None) -> None:
        """The binding into the fields, cast to the fields' precision in one kernel (``upload_binding``; NumPy's
        ``astype`` of the 1.2 M-vertex arrays of the grooming benchmark took 0.16 s of an edit's update).  With
        ``strands`` (the render strands a rebind bound again; the other rows, their weights and bodies are as
        uploaded before), only their vertices' rest positions and bindings (``upload_binding_rows``; kernel profiler,
        the grooming benchmark's edit of 8,600 strands: 22.5 -> 11.9 ms)."""
        self.host = h
        if strands is not None:
            from .binding import vertex_rows

            rows = vertex_rows(h["render_strand_vertex_start"][strands], h["render_strand_vertex_count"][strands])
            if rows.size:
                self._upload_rows(rows)
            return
        upload_binding(self.fields, np.ascontiguousarray(h["render_vertex_rest_position"], np.float64),
                       np.ascontiguousarray(h["render_vertex_body"], np.int32),
                       np.ascontiguousarray(h["render_vertex_bind_edge"], np.int64),
                       np.ascontiguousarray(h["render_vertex_bind_param"], np.float64),
                       np.ascontiguousarray(h["render_vertex_bind_local"], np.float64),
                       np.ascontiguousarray(h["render_vertex_bind_weight"], np.float64))

    def rebind(self, strands) -> None:
        """Bind again, into the same fields, after the rest shapes changed in place (the guide
        Model updated by :meth:`Model.update`, the render strands edited) with the same layout:
        same render vertex counts per strand, same guides.  No field is allocated, so no kernel
        is compiled again; the result equals a new :class:`SkinningLBS` of the same inputs.
        (``frame="material"`` reads the rest frames from a new rest State of the guide Model:
        that allocates one State per call.)  With ``frame="transport"`` and no root moved, only the
        render strands that changed, or whose guides did, are bound again (``compute_binding(previous=)``)."""
        rebound = []
        h = self._binding(strands, self.host, rebound)
        if not (np.array_equal(h["render_strand_vertex_count"], self.host["render_strand_vertex_count"])
                and h["render_vertex_bind_edge"].shape == self.host["render_vertex_bind_edge"].shape):
            raise ValueError("SkinningLBS.rebind: the render strands' vertex counts (or the neighbour count) "
                             "differ from the bound ones; build a new SkinningLBS")
        self._upload(h, rebound[0])

    def prepare_rebind(self) -> None:
        """Launch the partial upload of :meth:`rebind` once on no rows, so that its machine code is made now and not
        in the first edit (Taichi's offline cache keeps kernels as LLVM IR: a process's first launch of each one
        compiles it to machine code).  The grooming session calls it at its build; a run that never edits has no
        need of it."""
        self._upload_rows(np.zeros(0, np.int64))

    def _upload_rows(self, rows: np.ndarray) -> None:
        """``upload_binding_rows`` of the render vertices ``rows`` (int64) from ``self.host``."""
        h = self.host
        upload_binding_rows(self.fields, np.ascontiguousarray(rows, np.int64),
                            np.ascontiguousarray(h["render_vertex_rest_position"], np.float64),
                            np.ascontiguousarray(h["render_vertex_bind_edge"], np.int64),
                            np.ascontiguousarray(h["render_vertex_bind_param"], np.float64),
                            np.ascontiguousarray(h["render_vertex_bind_local"], np.float64))

    def deform(self, guide_state: State, control: Control) -> None:
        """Skin the render strands to ``guide_state`` (positions, and frames for
        ``frame="material"``) with the body transforms of ``control``.  Result in
        ``fields.render_vertex_position``; allocates nothing."""
        m, sk = self.guide_model, self.fields
        if self.config.frame == "transport":
            compute_guide_frames_transport(m.vertex, m.strand, control.body_rotation, guide_state.vertex_position,
                                           sk.guide_edge_frame)
        else:
            compute_guide_frames_material(m.edge, guide_state, sk.guide_edge_frame)
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
