"""Model no more than a scene needs (issue 4, item 6): the simplifications the simulator makes by
itself, and the choice of a method by error or by budget.

Each simplification is exact, or within a stated tolerance, for the scenes it is applied to, and is
reported (``SolverADMM.model_choices``, the ``simulate`` summary).  Each has a switch that restores the
full model, which is how the tests measure what it changes (``tests/test_fidelity.py``):

* **Twist unknowns dropped** (``SolverADMMConfig.twist = "auto"``, default): when every strand is
  naturally straight (rest curvature and twist below :data:`STRAIGHT_TOLERANCE` rad per edge pair),
  of round section (equal bending stiffnesses) and nothing but its root holds its twist (no fixed
  edge past the root edge), the twisting energy is minimised exactly by frames with no twist (each
  edge's material frame the previous one's, parallel-transported along the centerline), whatever
  the centerline, and the bending energy of a round, straight-at-rest rod does not depend on the
  frame.  The twist Newton step (a tridiagonal solve per strand and iteration) is then replaced by
  that frame (:func:`taichi_hair.frames.twist_free_strand`), and the twist stiffness drops out of the
  local step (the energy minimised over theta has none).  Same equilibria; dynamic trajectories
  differ by the rotational inertia of the twist and by the ADMM iterate path, within the tolerance
  of the tests.  ``twist = "solve"`` keeps the paper's unknowns.
* **Hair-hair detection skipped** (``ContactConfig.skip_when_apart``, default on) in a step where
  no two strands come within reach (strand boxes: the union of the edges' detection boxes, which
  include the velocity reach) and no strand can touch itself (every edge makes an acute angle with
  the root-to-tip chord, and the shortest edge times the cosine of the largest such angle exceeds the
  reach of two of the strand's edges: ``grid.strand_boxes``).
  Exact: the full search would find no pair either (bit-identical results, tested).
* **Continuous detection skipped** (``ContactConfig.skip_slow_continuous``, default on) in a pass where
  twice the largest vertex displacement since the beginning of the step is within the proximity
  margin (so a pass runs only when some vertex moved more than half the margin: one hair radius with
  the default margin of 0.1 mm and radius of 0.05 mm): two edges that were out of proximity reach cannot
  then have met.  The pass could still add impacts between pairs already in contact; the difference is
  measured in the tests (none in the measured scene).
* **Quasistatic stepping when only the equilibrium is asked for** (``simulate SCENE --equilibrium``,
  :func:`equilibrium`): inertia and damping dropped; steps until the estimated distance to the
  equilibrium is below a tolerance.  The constraint weight scale is w0 = 1 there (the grooming tool's
  and the stick-slip validation's): measured on 20 hanging curly strands of the ``hang`` scene
  (``python3 benchmarks/probes/quasistatic_w0.py``, steps of 10 iterations), w0 = 1 moves less than
  0.1 um per step by step 300, w0 = 5 by step 1,000, and the paper's w0 = 25 still moved 15 mm between
  steps 1,000 and 3,000 (ADMM's fixed point does not depend on w0; its speed does).  Same equilibrium as a long damped dynamic run, within the tolerance of the tests.

The choice by error or budget (``simulate SCENE --max-error E`` / ``--budget-ms T``,
:func:`choose_for_scene`) reads the speed/accuracy points measured by ``taichi-hair bench pareto``
(shipped in ``taichi_hair/bench/data/pareto_cpu.csv``; ``--pareto-data`` reads a re-measured
``pareto.csv``).  The measured scenes stand in for the user's: a scene with one strand is matched to
``swing`` (a strand released from horizontal), any other to ``groom`` (wavy strands under a head
shake).  Only methods that can simulate the scene are considered: hair-hair contacts need SolverADMM;
body colliders exclude SolverXPBD (it has none); the precision must be the run's.  The errors are
those measured on the stand-in scene, not guarantees for the user's scene, and the costs are those of
the machine that measured them (the data's ``pareto_cpu.json``); the choice says so when it is made.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Largest rest curvature or twist component [rad per edge pair] of a "naturally straight" strand.
STRAIGHT_TOLERANCE = 1.0e-5
#: Largest relative difference of the two bending stiffnesses of a "round" section.
ROUND_TOLERANCE = 1.0e-6


# --------------------------------------------------------------------------- twist
def twist_choice(host: dict, rest_kappa: np.ndarray) -> tuple[bool, str]:
    """Whether the twist unknowns can be dropped, and why (or why not), naming a strand.

    Args:
        host: ``Model.host``.
        rest_kappa: rest strain of every pair (the solver's ``pair_rest_kappa``), shape (vertex_count, 3)
            [rad]: bending components 0 and 1, twist 2.
    """
    active = host["pair_is_active"].astype(bool)
    strand = host["vertex_strand"]
    k = np.abs(np.asarray(rest_kappa, np.float64))
    curved = active & (k.max(axis=1) > STRAIGHT_TOLERANCE)
    if curved.any():
        i = int(np.argmax(curved))
        return False, (f"twist solved: strand {int(strand[i])} is not naturally straight (rest curvature/twist "
                       f"{k[i].max():.3g} rad at vertex {i} > {STRAIGHT_TOLERANCE:g})")
    kb = np.asarray(host["pair_bending_modulus"], np.float64)
    big = np.maximum(np.abs(kb[:, 0]), np.abs(kb[:, 1]))
    flat = active & (np.abs(kb[:, 0] - kb[:, 1]) > ROUND_TOLERANCE * np.maximum(big, 1e-300))
    if flat.any():
        i = int(np.argmax(flat))
        return False, f"twist solved: strand {int(strand[i])} has an elliptic section (bending stiffnesses differ)"
    local = host["vertex_local_index"]
    count = host["strand_vertex_count"][strand]
    ghost = local == count - 1
    held = (host["edge_is_fixed"] != 0) & (local >= 1) & ~ghost
    if held.any():
        i = int(np.argmax(held))
        return False, (f"twist solved: strand {int(strand[i])} has a fixed edge past its root (edge {i}) that "
                       "holds its twist")
    return True, ("twist unknowns dropped: every strand is naturally straight, of round section and free to "
                  "untwist (exact; SolverADMMConfig.twist='solve' keeps them)")


# --------------------------------------------------------------------------- contacts
def strands_apart(box_lo: np.ndarray, box_hi: np.ndarray, self_clear: np.ndarray,
                  max_pairs: int = 2_000_000) -> bool:
    """True when no two strand boxes overlap and no strand can touch itself.

    Sweep and prune along the axis on which the box centres spread most (sorted box starts), then the
    overlap on the other two axes of the remaining pairs.  When the sweep leaves more than ``max_pairs``
    pairs the strands are taken to be within reach without testing further (a dense groom: the full
    search runs anyway).

    Args:
        box_lo, box_hi: strand boxes [m], shape (strand_count, 3); a strand with no real edge has
            lo = +inf, hi = -inf.
        self_clear: 1 where the strand cannot touch itself, shape (strand_count,).
    """
    if not np.all(self_clear):
        return False
    lo = np.asarray(box_lo, np.float64)
    hi = np.asarray(box_hi, np.float64)
    s = lo.shape[0]
    if s < 2:
        return True
    real = lo[:, 0] <= hi[:, 0]
    if real.sum() < 2:
        return True
    centre = 0.5 * (lo[real] + hi[real])
    axis = int(np.argmax(centre.max(axis=0) - centre.min(axis=0)))
    others = [k for k in range(3) if k != axis]
    order = np.argsort(lo[:, axis], kind="stable")
    lo, hi = lo[order], hi[order]
    end = np.searchsorted(lo[:, axis], hi[:, axis], side="right")
    counts = np.maximum(end - np.arange(s) - 1, 0)
    total = int(counts.sum())
    if total == 0:
        return True
    if total > max_pairs:
        return False
    a = np.repeat(np.arange(s), counts)
    start = np.repeat(np.cumsum(counts) - counts, counts)
    b = a + 1 + (np.arange(total) - start)
    overlap = np.all((lo[a][:, others] <= hi[b][:, others]) & (lo[b][:, others] <= hi[a][:, others]), axis=1)
    return not bool(overlap.any())


# --------------------------------------------------------------------------- equilibrium
@dataclass
class EquilibriumResult:
    steps: int
    iterations: int
    last_displacement: float   # largest vertex displacement of the last step [m]
    estimated_distance: float  # estimated distance left to the equilibrium [m] (see :func:`equilibrium`)
    converged: bool


#: Steps over which :func:`equilibrium` measures the contraction rate of the iteration.
RATE_WINDOW = 10


def equilibrium(solver, state, control, tolerance: float, max_steps: int = 2000, dt: float = 1.0,
                callback=None) -> EquilibriumResult:
    """Quasistatic steps until the equilibrium is within ``tolerance`` [m] of the current state.

    ``solver`` must be a :class:`~taichi_hair.solver_admm.SolverADMM` in the quasistatic mode; each step
    runs its iterations, the warm-started multipliers carrying the minimisation on from one step to the
    next.  A small displacement per step alone does not mean a small distance to the equilibrium when the
    iteration contracts slowly, so the distance left is estimated from the measured contraction rate
    r = (d_k / d_{k-w})^(1/w) of the largest displacement per step d over the last w =
    :data:`RATE_WINDOW` steps, as the geometric tail d_k r / (1 - r); the run stops when that estimate and
    d_k are both below ``tolerance`` (an estimate: it assumes the linear convergence ADMM shows near the
    solution).  ``callback(step, displacement)`` is called after each step (progress bars).
    """
    if solver.config.mode != "quasistatic":
        raise ValueError("equilibrium: the solver must be in the quasistatic mode (SolverADMMConfig.mode)")
    if not (math.isfinite(tolerance) and tolerance > 0):
        raise ValueError(f"equilibrium: tolerance must be a finite positive length [m], got {tolerance!r}")
    prev = state.vertex_position.to_numpy().astype(np.float64)
    history = []
    disp, left = math.inf, math.inf
    for k in range(1, max_steps + 1):
        solver.step(state, control, dt)
        x = state.vertex_position.to_numpy().astype(np.float64)
        disp = float(np.max(np.linalg.norm(x - prev, axis=1))) if x.size else 0.0
        prev = x
        history.append(disp)
        if callback is not None:
            callback(k, disp)
        if disp == 0.0:
            return EquilibriumResult(k, k * solver.config.iterations, 0.0, 0.0, True)
        if len(history) > RATE_WINDOW and history[-1 - RATE_WINDOW] > 0.0:
            r = (disp / history[-1 - RATE_WINDOW]) ** (1.0 / RATE_WINDOW)
            left = disp * r / (1.0 - r) if r < 1.0 else math.inf
            if disp < tolerance and left < tolerance:
                return EquilibriumResult(k, k * solver.config.iterations, disp, left, True)
    return EquilibriumResult(max_steps, max_steps * solver.config.iterations, disp, left, False)


# --------------------------------------------------------------------------- method choice
@dataclass
class MethodChoice:
    """A measured point chosen for a scene, and how it maps to the scene's solver settings."""

    point: object            # taichi_hair.bench.pareto.Point
    stand_in: str            # measured scene standing in for the user's
    solver: str              # "admm" | "shape" | "xpbd"
    substeps: int            # solver steps per frame
    estimated_ms_per_frame: float
    description: str


def _stand_in(strand_count: int) -> str:
    return "swing" if strand_count == 1 else "groom"


def eligible_methods(hair_hair: bool, colliders: bool) -> tuple[str, ...]:
    """Methods of the Pareto data that can simulate a scene with these features."""
    admm = ("admm", "admm_w1", "admm_bdf2", "admm_f64")
    if hair_hair:
        return admm
    if colliders:
        return admm + ("shape",)
    return admm + ("shape", "xpbd")


def choose_for_scene(points, strand_count: int, vertex_count: int, fps: float, precision: str, hair_hair: bool,
                     colliders: bool, max_error: float | None = None, budget_ms: float | None = None) -> MethodChoice:
    """The cheapest measured setting within ``max_error`` (fraction of strand length), or the most
    accurate within ``budget_ms`` of wall time per frame for this scene's vertex count.

    Raises ValueError naming what cannot be met and the measured range.
    """
    from .bench.pareto import choose

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
    from .bench.methods import ADMM_DESCRIPTIONS, is_admm

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

    from .bench.methods import ADMM_VARIANTS

    p = choice.point
    if choice.solver == "admm":
        from .config import SolverADMMConfig

        base = admm_config if admm_config is not None else SolverADMMConfig()
        return replace(base, iterations=int(p.iterations), **ADMM_VARIANTS[p.method])
    if choice.solver == "shape":
        from .solver_shape import ShapeRegion, SolverShapeConfig

        region = ShapeRegion(local_iterations=int(p.iterations), length_iterations=int(p.iterations))
        return SolverShapeConfig(method=int(p.shape_method), regions=(region,))
    from .solver_xpbd import SolverXPBDConfig

    return SolverXPBDConfig(substeps=int(p.substeps))
