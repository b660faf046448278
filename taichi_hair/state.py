"""State (what changes every step) and Control (what the user drives)."""

from __future__ import annotations

import numpy as np
import taichi as ti

from .fields import EdgeStateFields, VertexStateFields, download, field_numpy_shape, upload


def _np_float():
    return np.float64 if ti.lang.impl.current_cfg().default_fp == ti.f64 else np.float32


class State(VertexStateFields, EdgeStateFields):
    """Positions, velocities, twists and DER frames (fields documented in :mod:`taichi_hair.fields`).

    Solvers update a State in place.  ``copy_from`` and ``to_numpy``/``load``
    make snapshots (checkpoints, undo, determinism tests).
    """

    FIELDS = (
        "vertex_position", "vertex_velocity", "edge_twist", "edge_angular_velocity", "edge_tangent",
        "edge_reference_director", "edge_material_d1", "edge_material_d2", "edge_reference_twist",
    )

    def __init__(self, vertex_count: int):
        self.vertex_count = vertex_count
        VertexStateFields.__init__(self, vertex_count)
        EdgeStateFields.__init__(self, vertex_count)

    def copy_from(self, other: "State") -> None:
        for name in self.FIELDS:
            getattr(self, name).copy_from(getattr(other, name))

    def to_numpy(self) -> dict:
        """Snapshot of every state field as NumPy arrays (in one kernel: ``fields.download``)."""
        return dict(zip(self.FIELDS, download([getattr(self, name) for name in self.FIELDS])))

    def load(self, snapshot: dict) -> None:
        """Load a :meth:`to_numpy` snapshot; every member is checked for presence and shape first (a short
        array would make ``from_numpy`` read past its end), so a bad snapshot changes nothing."""
        for name in self.FIELDS:
            field = getattr(self, name)
            if name not in snapshot:
                raise ValueError(f"State.load: the snapshot lacks {name!r}")
            want = field_numpy_shape(field)
            got = np.shape(snapshot[name])
            if got != want:
                raise ValueError(f"State.load: {name} has the shape {got}, expected {want}")
        upload([(getattr(self, name), snapshot[name]) for name in self.FIELDS])  # (cast as from_numpy casts)

    def positions(self) -> np.ndarray:
        """Vertex positions, shape (vertex_count, 3) [m]."""
        return self.vertex_position.to_numpy()


class Control:
    """Inputs of a step.

    Attributes:
        body_rotation: rotation R_b of each rigid body at the *end* of the step,
            field of 3x3 matrices, shape (body_count,) [-].  Clamped roots follow
            x = R_b x_body + T_b.
        body_translation: translation T_b, field of 3-vectors, shape (body_count,) [m].
        gravity: external acceleration g, 3-tuple [m/s^2]; y is up by default.
        air_velocity: ambient air velocity v_air for linear drag, 3-tuple [m/s].
    """

    def __init__(self, body_count: int):
        self.body_count = body_count
        self.body_rotation = ti.Matrix.field(3, 3, float, body_count)
        self.body_translation = ti.Vector.field(3, float, body_count)
        upload([(self.body_rotation, np.tile(np.eye(3), (body_count, 1, 1)).astype(_np_float()))])
        self.gravity = (0.0, -9.81, 0.0)
        self.air_velocity = (0.0, 0.0, 0.0)

    def set_body_transform(self, body: int, rotation, translation) -> None:
        """Set R_b (3x3, orthonormal) and T_b (3,) [m] of one body."""
        R = np.asarray(rotation, dtype=np.float64).reshape(3, 3)
        if not np.allclose(R @ R.T, np.eye(3), atol=1e-5) or np.linalg.det(R) < 0:
            raise ValueError(f"Control.body_rotation[{body}] must be a proper rotation matrix")
        T = np.asarray(translation, dtype=np.float64).reshape(3)
        if not (np.all(np.isfinite(R)) and np.all(np.isfinite(T))):
            raise ValueError(f"Control body transform {body} has non-finite entries")
        self.body_rotation[body] = R.tolist()
        self.body_translation[body] = T.tolist()
