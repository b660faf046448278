"""Method choice by error or by budget (issue 4 item 6), from the measured Pareto data.

The choice by error or budget (``simulate SCENE --max-error E`` / ``--budget-ms T``,
:func:`choose_for_scene`) reads the speed/accuracy points measured by ``taichi-hair bench pareto``
(shipped in ``taichi_hair/bench/data/pareto_cpu.csv``; ``--pareto-data`` reads a re-measured
``pareto.csv``).  The measured scenes stand in for the user's: a scene with one strand is matched to
``swing`` (a strand released from horizontal), any other to ``groom`` (wavy strands under a head
shake).  Only methods that can simulate the scene are considered: hair-hair contacts need SolverADMM;
body colliders exclude SolverXPBD (it has none); ADMM with BDF2 (``admm_bdf2``) is offered only to
scenes without contacts, the only ones it was measured on; the precision must be the run's.  The errors are
those measured on the stand-in scene, not guarantees for the user's scene, and the costs are those of
the machine that measured them (the data's ``pareto_cpu.json``); the choice says so when it is made.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass
class MethodChoice:
    """A measured point chosen for a scene, and how it maps to the scene's solver settings."""

    point: object            # taichi_hair.bench.pareto_data.Point
    stand_in: str            # measured scene standing in for the user's
    solver: str              # "admm" | "shape" | "xpbd"
    substeps: int            # solver steps per frame
    estimated_ms_per_frame: float
    description: str


def _stand_in(strand_count: int) -> str:
    return "swing" if strand_count == 1 else "groom"


def eligible_methods(hair_hair: bool, colliders: bool) -> tuple[str, ...]:
    """Methods of the Pareto data that can simulate a scene with these features."""
    # BDF2 was measured without contacts only (the Pareto scenes have none): not offered with them.
    # Anderson acceleration is not applied with contacts (SolverADMM): not offered with them either.
    admm = ("admm", "admm_w1", "admm_f64")
    if hair_hair:
        return admm
    if colliders:
        return admm + ("shape",)
    return admm + ("admm_aa", "admm_bdf2", "shape", "xpbd")


def choose_for_scene(points, strand_count: int, vertex_count: int, fps: float, precision: str, hair_hair: bool,
                     colliders: bool, max_error: float | None = None, budget_ms: float | None = None) -> MethodChoice:
    """The cheapest measured setting within ``max_error`` (fraction of strand length), or the most
    accurate within ``budget_ms`` of wall time per frame for this scene's vertex count.

    Raises ValueError naming what cannot be met and the measured range.
    """
    from .pareto_data import choose

    if (max_error is None) == (budget_ms is None):
        raise ValueError("give exactly one of max_error and budget_ms")
    if max_error is not None and not (math.isfinite(max_error) and max_error > 0):
        raise ValueError(f"max_error must be a positive fraction of the strand length, got {max_error!r}")
    if budget_ms is not None and not (math.isfinite(budget_ms) and budget_ms > 0):
        raise ValueError(f"budget_ms must be a positive number of milliseconds per frame, got {budget_ms!r}")
    stand_in = _stand_in(strand_count)
    methods = eligible_methods(hair_hair, colliders)
    pts = [p for p in points if p.scene == stand_in and p.method in methods and p.precision == precision]
    if not pts:
        raise ValueError(f"no measured point of scene {stand_in!r} for methods {', '.join(methods)} in {precision}")
    per_frame = vertex_count / fps  # ms per frame = cost [s/s/kvertex] * vertex_count / fps
    max_cost = None if budget_ms is None else budget_ms / per_frame
    try:
        p = choose(pts, stand_in, max_error=max_error, max_cost=max_cost)
    except ValueError as exc:
        if budget_ms is not None:
            cheapest = min(q.cost for q in pts if math.isfinite(q.error)) * per_frame
            raise ValueError(f"no measured setting fits {budget_ms:g} ms per frame for {vertex_count} vertices at "
                             f"{fps:g} fps (the cheapest measured would take about {cheapest:.3g} ms)") from None
        raise ValueError(str(exc).replace("choose: ", "")) from None
    from .methods import ADMM_DESCRIPTIONS, is_admm

    solver = "admm" if is_admm(p.method) else p.method
    substeps = max(1, int(round(1.0 / (fps * p.dt))))
    est = p.cost * per_frame
    knobs = {**{name: f"{d}, {p.iterations} iterations" for name, d in ADMM_DESCRIPTIONS.items()},
             "shape": f"Method {p.shape_method}, {p.iterations} local/length iterations",
             "xpbd": f"{p.substeps} substeps"}[p.method]
    desc = (f"method chosen from the measured speed/accuracy data: {p.method} ({knobs}), dt = 1/{1 / p.dt:.0f} s "
            f"({substeps} steps per frame); on the stand-in scene {stand_in!r} it measured an error of "
            f"{100 * p.error:.2g} % of the strand length at {p.cost:.3g} s per simulated s per 1k vertices, about "
            f"{est:.0f} ms per frame for this scene on the machine that measured it (a stand-in's figures, not a "
            f"guarantee for this scene)")
    return MethodChoice(point=p, stand_in=stand_in, solver=solver, substeps=substeps, estimated_ms_per_frame=est,
                        description=desc)


def solver_config_for(choice: MethodChoice, admm_config=None):
    """The solver configuration of a choice; an ADMM choice keeps ``admm_config``'s other settings
    (contacts, mode, drag) and changes only the iterations, w0 and the integrator."""
    from dataclasses import replace

    from .methods import ADMM_VARIANTS

    p = choice.point
    if choice.solver == "admm":
        from ..config import SolverADMMConfig

        base = admm_config if admm_config is not None else SolverADMMConfig()
        return replace(base, iterations=int(p.iterations), **ADMM_VARIANTS[p.method])
    if choice.solver == "shape":
        from ..solvers.shape.solver import ShapeRegion, SolverShapeConfig

        region = ShapeRegion(local_iterations=int(p.iterations), length_iterations=int(p.iterations))
        return SolverShapeConfig(method=int(p.shape_method), regions=(region,))
    from ..solvers.xpbd.solver import SolverXPBDConfig

    return SolverXPBDConfig(substeps=int(p.substeps))
