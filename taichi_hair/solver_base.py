"""What every solver shares (the chassis): the dt check, the finite check with rollback, the stage
timer, one way to take colliders, and the notice that the Model changed.

A solver subclasses :class:`SolverBase` and provides

* ``_set_coefficients()``: everything it derives from the Model (called at construction and by
  :meth:`SolverBase.refresh_model` after :meth:`Model.update`);
* ``_non_finite_code(state) -> int``: -1 when every value it steps is finite, else
  ``vertex * len(FIELD_NAMES) + field``;
* ``_restore_begin(state)``: put ``state`` back to the beginning of the step;

and sets ``FIELD_NAMES`` (the fields the finite check reads, in its code order) and ``STAGES`` (the
profiled stages).  The solvers are built by name through :func:`taichi_hair.solvers.make_solver`.
"""

from __future__ import annotations

import math
import time

import taichi as ti

from .errors import SimulationDivergedError


#: Taichi arches that run kernels on a GPU (where the "auto" choices pick the per-element stage layouts).
GPU_ARCHS = (ti.cuda, ti.vulkan, ti.metal, ti.opengl, ti.amdgpu)


def on_gpu() -> bool:
    """Does the current Taichi runtime run on a GPU (``ti.init``'s arch in :data:`GPU_ARCHS`)?"""
    return ti.lang.impl.current_cfg().arch in GPU_ARCHS


class SolverBase:
    """Base of SolverADMM, SolverShape and SolverXPBD (see the module docstring)."""

    #: Fields the finite check reads, in the order of ``_non_finite_code``'s field index.
    FIELD_NAMES: tuple = ()
    #: Profiled stages (``profile=True``: ``stage_seconds[stage]`` [s]).
    STAGES: tuple = ()
    profile: bool = False
    stage_seconds: dict

    def _init_base(self, model, profile: bool) -> None:
        self.model = model
        self.profile = bool(profile)
        self.stage_seconds = {k: 0.0 for k in self.STAGES}
        #: Steps completed [-].
        self.step_count = 0

    # ------------------------------------------------------------------ checks
    def _check_dt(self, dt) -> None:
        """Raise ValueError naming the solver unless dt is a finite positive number [s]."""
        if not (isinstance(dt, (int, float)) and not isinstance(dt, bool) and math.isfinite(dt) and dt > 0):
            raise ValueError(f"{type(self).__name__}.step: dt must be a finite positive number, got {dt!r}")

    def check_finite(self, state) -> None:
        """Raise SimulationDivergedError (after restoring the begin-of-step state) on NaN/inf."""
        code = int(self._non_finite_code(state))
        if code >= 0:
            self._restore_begin(state)
            k = len(self.FIELD_NAMES)
            raise SimulationDivergedError(code // k, self.FIELD_NAMES[code % k], self.step_count)

    def _non_finite_code(self, state) -> int:
        raise NotImplementedError

    def _restore_begin(self, state) -> None:
        raise NotImplementedError

    # ------------------------------------------------------------------ the Model changed
    def _set_coefficients(self) -> None:
        raise NotImplementedError

    def refresh_model(self) -> None:
        """Recompute everything derived from the Model after :meth:`Model.update` (no new fields)."""
        self._set_coefficients()

    # ------------------------------------------------------------------ colliders
    def _collider_set(self, colliders):
        """The one way a solver takes colliders: None or empty -> None; a list of colliders -> a new
        :class:`~taichi_hair.contact.colliders.ColliderSet`; a ColliderSet -> itself, after checking
        that it was made for this Model's bodies."""
        from .contact.colliders import ColliderSet

        if colliders is None or (not isinstance(colliders, ColliderSet) and len(colliders) == 0):
            return None
        if not isinstance(colliders, ColliderSet):
            return ColliderSet(colliders, self.model.body_count)
        if colliders.body_count != self.model.body_count:
            raise ValueError(f"{type(self).__name__}: the ColliderSet has {colliders.body_count} bodies, the model "
                             f"{self.model.body_count}")
        return colliders

    # ------------------------------------------------------------------ stage timer
    def _tick(self) -> float:
        """Start a stage: synchronise and read the clock when profiling (else free, 0)."""
        if self.profile:
            ti.sync()
            return time.perf_counter()
        return 0.0

    def _tock(self, stage: str, t0: float) -> float:
        """End a stage begun at ``t0``: add its wall time to ``stage_seconds[stage]``; returns the clock."""
        if self.profile:
            ti.sync()
            t1 = time.perf_counter()
            self.stage_seconds[stage] += t1 - t0
            return t1
        return 0.0
