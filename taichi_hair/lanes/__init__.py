"""The "lanes" schedule of SolverADMM (CPU SIMD over eight strands): :mod:`.schedule` (the iteration, stage by
stage), :mod:`.layout` (the lane layout, gathers, scatters and lane arithmetic)."""

from .layout import LANES, LaneLayout
from .schedule import CONTACT_ITERATION, ITERATIONS, admm_iterations_lanes, lanes_gather, lanes_scatter

__all__ = ["CONTACT_ITERATION", "ITERATIONS", "LANES", "LaneLayout", "admm_iterations_lanes", "lanes_gather",
           "lanes_scatter"]
