"""The "lanes" schedule of SolverADMM (CPU SIMD over eight strands): :mod:`.schedule` (the iteration, stage by
stage), :mod:`.layout` (the lane layout, gathers, scatters and lane arithmetic)."""

from ..config import Schedule
from .layout import LANES, LaneLayout
from .schedule import CONTACT_ITERATION, ITERATIONS, admm_iterations_lanes, lanes_frames, lanes_gather, lanes_scatter

__all__ = ["AUTO_LANES_VERTICES", "CONTACT_ITERATION", "ITERATIONS", "LANES", "LaneLayout", "admm_iterations_lanes",
           "auto_schedule", "lanes_frames", "lanes_gather", "lanes_scatter"]

#: Vertices from which ``SolverADMMConfig.schedule = "auto"`` runs the lanes on a CPU [-].  The lanes were faster at
#: every size measured (``simulate hang`` 300 strands: 57.9 against 171 ms per frame; the grooming benchmark's 8,600
#: guides, 120k vertices: the ADMM kernel 42 against 193 ms per step; BENCHMARKS.md), but each of their kernel variants
#: compiles in ~12-25 s cold against ~6 s, per model size, and their trajectories differ from the strand schedule's
#: by rounding.  So this is a choice for start-up, not a crossover: large grooms (a grooming session's guides) get
#: the lanes, the scenes and tests under it keep the strand schedule.
AUTO_LANES_VERTICES = 50_000


def auto_schedule(gpu: bool, pcr: bool, korner: bool, vertex_count: int) -> Schedule:
    """The schedule ``"auto"`` runs: ``"stage"`` on a GPU or with the PCR solve; on a CPU ``"lanes"`` for a Model of at
    least ``AUTO_LANES_VERTICES`` vertices with Korner strains (what the lanes implement), else ``"strand"``."""
    if gpu or pcr:
        return Schedule.STAGE
    return Schedule.LANES if korner and vertex_count >= AUTO_LANES_VERTICES else Schedule.STRAND
