"""Per-stage wall-clock timing shared by the solvers (``profile=True``)."""

import time

import taichi as ti


class StageTimer:
    """Mixin: ``_tick`` starts a stage, ``_tock(stage, t0)`` ends it and adds its time to ``stage_seconds``.

    Both synchronise the device first, so the times are per stage (and the step is slower); without
    ``self.profile`` they cost nothing and return 0.
    """

    profile: bool = False
    stage_seconds: dict

    def _tick(self) -> float:
        if self.profile:
            ti.sync()
            return time.perf_counter()
        return 0.0

    def _tock(self, stage: str, t0: float) -> float:
        if self.profile:
            ti.sync()
            t1 = time.perf_counter()
            self.stage_seconds[stage] += t1 - t0
            return t1
        return 0.0
