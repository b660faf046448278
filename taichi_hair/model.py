"""Model: everything about the groom that does not change in time.

A :class:`Model` is made by :meth:`GroomBuilder.finalize`.  It owns the static
field groups of :mod:`taichi_hair.fields`, one member per data role --
``model.vertex`` (:class:`VertexInfo`), ``model.edge`` (:class:`EdgeInfo`),
``model.pair`` (:class:`PairInfo`), ``model.strand`` (:class:`StrandInfo`) --
passed to kernels by role (``admm.begin_step(dyn, bdf2, m.vertex, m.edge, ...)``,
so a call site shows what a kernel reads), and NumPy copies of the same arrays for
host-side set-up (``model.host``).  Every field is also an attribute of the Model
itself (``model.vertex_mass is model.vertex.vertex_mass``), for host code and for
the kernels that take the whole Model.
"""

from __future__ import annotations

import numpy as np
import taichi as ti

from .fields import EdgeInfo, PairInfo, StrandInfo, VertexInfo, upload
from .frames import update_reference_frames
from .state import Control, State


class Model:
    """Static description of a groom (see :mod:`taichi_hair.fields` for every field).

    Attributes:
        vertex_count: total number of vertices n [-].
        strand_count: number of strands [-].
        body_count: number of rigid bodies roots can be clamped to [-].
        host: dict of NumPy arrays mirroring the fields (float64 where physical).
        materials: list of the per-strand :class:`RodMaterial`.
    """

    def __init__(self, host: dict, materials: list, body_count: int):
        n = int(host["vertex_strand"].shape[0])
        ns = int(host["strand_vertex_start"].shape[0])
        self.vertex_count = n
        self.strand_count = ns
        self.body_count = body_count
        self.host = host
        self.materials = materials
        #: Static data by role (see the module docstring).
        self.vertex = VertexInfo(n)
        self.edge = EdgeInfo(n)
        self.pair = PairInfo(n)
        self.strand = StrandInfo(ns)
        for role in (self.vertex, self.edge, self.pair, self.strand):
            for name, field in vars(role).items():
                setattr(self, name, field)
        #: Identity body transforms, used to build the rest state.
        self._rest_rotation = ti.Matrix.field(3, 3, float, body_count)
        self._upload(host, [(self._rest_rotation, np.tile(np.eye(3), (body_count, 1, 1)).astype(_np_float()))])

    # ------------------------------------------------------------------ in-place updates
    def update(self, host: dict, materials: list | None = None) -> None:
        """Replace the groom's static data *in place*, keeping every field object.

        ``host`` must have the same layout (vertex and strand counts, vertex-to-strand
        map) as the current one, e.g. from a :class:`GroomBuilder` fed the edited
        rest shape of the same strands.  Kernels are specialised per field object, so
        updating in place avoids recompiling them (the grooming tool edits rest
        shapes, lengths and parameters this way).  Solvers built on this Model must
        then call their ``refresh_model()``.
        """
        for key in ("vertex_strand", "strand_vertex_start", "strand_vertex_count"):
            if key not in host or not np.array_equal(np.asarray(host[key]), self.host[key]):
                raise ValueError(f"Model.update: host[{key!r}] differs from the model's; the layout "
                                 "(vertex and strand counts) must stay the same for an in-place update")
        if materials is not None and len(materials) != self.strand_count:
            raise ValueError(f"Model.update: {len(materials)} materials for {self.strand_count} strands")
        self._upload(host)
        self.host = host
        if materials is not None:
            self.materials = materials

    def _upload(self, host: dict, more=()) -> None:
        """Copy every host array that has a field of the same name into that field, and the (field, array) pairs
        ``more`` (one kernel per element type: ``fields.upload``)."""
        upload([(field, np.ascontiguousarray(value, dtype=_np_dtype(field))) for name, value in host.items()
                if isinstance(field := getattr(self, name, None), ti.Field)] + list(more))

    def reset_state(self, state: State) -> None:
        """Put ``state`` (allocated by :meth:`state`) back at rest, in place (no new fields)."""
        h, f, n = self.host, _np_float(), self.vertex_count
        # From the host arrays the Model's fields were cast from (the same values), in one kernel (fields.upload).
        upload([(state.vertex_position, h["vertex_rest_position"].astype(f)), (state.vertex_velocity, np.zeros((n, 3), f)),
                (state.edge_twist, h["edge_rest_twist"].astype(f)), (state.edge_angular_velocity, np.zeros(n, f)),
                (state.edge_tangent, h["edge_rest_tangent"].astype(f)),
                (state.edge_reference_director, h["edge_rest_director"].astype(f))])
        update_reference_frames(True, self.vertex, self.edge, self.pair, self.strand, self._rest_rotation, state.vertex_position,
                                state.edge_twist, state)

    # ------------------------------------------------------------------ factories
    def state(self) -> State:
        """A new State at rest: input positions, zero velocities, rest twists and frames."""
        s = State(self.vertex_count)
        self.reset_state(s)
        return s

    def control(self) -> Control:
        """A new Control: identity body transforms, gravity (0, -9.81, 0) m/s^2, still air."""
        return Control(self.body_count)

    # ------------------------------------------------------------------ helpers
    def strand_slices(self):
        """List of (start, count) per strand."""
        return list(zip(self.host["strand_vertex_start"].tolist(), self.host["strand_vertex_count"].tolist()))

    def pair_voronoi_length(self, rescaling: bool) -> np.ndarray:
        """Bending Voronoi length of every pair [m] (host, float64), shape (vertex_count,), 1 where inactive:
        :func:`pair_voronoi_length` of the Model's host arrays.  The one definition SolverADMM, SolverXPBD and
        the sag-free rest pose use."""
        return pair_voronoi_length(self.host, rescaling)


def pair_voronoi_length(host: dict, rescaling: bool, edge_rest_length=None) -> np.ndarray:
    """Bending Voronoi length of every pair [m], float64, shape (vertex_count,), 1 where inactive.

    Pair i (vertices i-1, i, i+1) owns half of each of its two edges; with ``rescaling`` (Daviet 2023
    Sec. 5.1, ``voronoi_rescaling`` of the solver configs) the second and penultimate vertices of a strand
    own the whole boundary edge instead of half of it.  ``edge_rest_length``: other rest lengths than the
    host's (the sag-free rest pose's, before they are applied).
    """
    h = host
    le = np.asarray(h["edge_rest_length"] if edge_rest_length is None else edge_rest_length, np.float64)
    n = le.shape[0]
    local = h["vertex_local_index"]
    count = h["strand_vertex_count"][h["vertex_strand"]]
    prev = np.zeros(n)
    prev[1:] = le[:-1]
    wprev = np.full(n, 0.5)
    wnext = np.full(n, 0.5)
    if rescaling:
        wprev[local == 1] = 1.0
        wnext[local == count - 2] = 1.0
    return np.where(h["pair_is_active"].astype(bool), wprev * prev + wnext * le, 1.0)


def _np_float():
    return np.float64 if ti.lang.impl.current_cfg().default_fp == ti.f64 else np.float32


def _np_dtype(field):
    dt = field.dtype
    if dt in (ti.i32,):
        return np.int32
    return _np_float()

