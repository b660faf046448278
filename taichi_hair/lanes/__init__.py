"""The "lanes" schedule of SolverADMM (CPU SIMD over eight strands): :mod:`.schedule` (the iteration, stage by
stage), :mod:`.layout` (the lane layout, gathers, scatters and lane arithmetic)."""

from .layout import LANES, LaneLayout
from .schedule import admm_iterations_lanes

__all__ = ["LANES", "LaneLayout", "admm_iterations_lanes"]
