"""Quasistatic stepping to an equilibrium, when only the equilibrium is asked for (issue 4 item 6).

Inertia and damping are dropped when only the equilibrium is asked for (``simulate SCENE --equilibrium``,
:func:`equilibrium`); the solver steps until the estimated distance to the
equilibrium is below a tolerance.  The constraint weight scale is w0 = 1 there (the grooming tool's
and the stick-slip validation's): measured on 20 hanging curly strands of the ``hang`` scene
(``python3 benchmarks/probes/quasistatic_w0.py``, steps of 10 iterations), w0 = 1 moves less than
0.1 um per step by step 300, w0 = 5 by step 1,000, and the paper's w0 = 25 still moved 15 mm between
steps 1,000 and 3,000 (ADMM's fixed point does not depend on w0; its speed does).
Same equilibrium as a long damped dynamic run, within the tolerance of the tests.

Few rods, or any number without contacts (issue 15, item 3): when the scene has no contacts and the static
solve models it exactly (:func:`taichi_hair.solvers.static_newton.static_newton_eligibility`: the Korner
strain) and the twist is dropped (straight round strands), ``method="auto"`` (the default) minimises the
same energy directly
with :class:`~taichi_hair.solvers.static_newton.SolverStaticNewton` (Gauss-Newton, every iteration in one
launch) after one quasistatic step that puts the roots on their bodies: the 10 cm rod of
``benchmarks/bench_admm.py`` in 11 Gauss-Newton iterations (0.2 ms) where the quasistatic ADMM takes 1,020
iterations (121 ms).  ``method="newton"`` takes it for curved strands too (the twist as unknowns: the
hang scene's 300 curly strands in 3.5 s against 13 s of stepping, but ~25 s of kernel compilation for every
new groom size); ``method="admm"`` keeps the stepping.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..config import Mode


@dataclass
class EquilibriumResult:
    steps: int
    iterations: int
    last_displacement: float   # largest vertex displacement of the last step [m]
    estimated_distance: float  # estimated distance left to the equilibrium [m] (see :func:`equilibrium`)
    converged: bool
    method: str = "admm"       # "admm" (quasistatic stepping) or "static Newton"


#: Steps over which :func:`equilibrium` measures the contraction rate of the iteration.
RATE_WINDOW = 10


def static_solve_choice(solver, method: str = "auto") -> tuple[bool, str]:
    """Whether :func:`equilibrium` with ``method`` ("auto" or "newton") solves ``solver``'s scene directly, and
    why (not).  "auto" takes the static solve only where the twist is dropped: with the twist as unknowns its
    kernel took ~25 s to compile for every new groom size (Taichi's cache keys on the fields), more than the
    stepping it saves on a first run (BENCHMARKS.md); "newton" takes it wherever it models the scene."""
    if solver.contacts is not None:
        return False, "contacts (hair-hair or bodies): quasistatic ADMM"
    from .static_newton import static_newton_eligibility
    from .static_newton_config import static_newton_twist

    ok, why = static_newton_eligibility(solver.model, solver.config)
    if not ok:
        return False, f"quasistatic ADMM: {why}"
    if method == "auto" and static_newton_twist(solver.model, solver.config):
        return False, "quasistatic ADMM: the twist is solved (the static solve is method='newton' there)"
    return True, "static Newton solve (no contacts)"


def _static_equilibrium(solver, state, control, tolerance: float, dt: float, callback) -> EquilibriumResult:
    from .static_newton import SolverStaticNewton, StaticNewtonConfig

    solver.step(state, control, dt)  # the roots on their bodies (and one quasistatic step)
    newton = getattr(solver, "_static_newton", None)
    if newton is None:
        newton = solver._static_newton = SolverStaticNewton(solver.model, solver.config)
    # Gauss-Newton converges linearly (a rate of ~0.1 per iteration on the 10 cm rod): stop at a tenth of the
    # tolerance, and judge by the distance left estimated from the last two moves, as the stepping does.
    newton.config = StaticNewtonConfig(tolerance=0.1 * tolerance)
    r = newton.solve(state, control)
    move = float(np.max(r.last_move)) if r.last_move.size else 0.0
    left = r.estimated_distance()
    its = int(np.max(r.iterations)) if r.iterations.size else 0
    if callback is not None:
        callback(1, move)
    return EquilibriumResult(1, solver.config.iterations + its, move, left,
                             bool(r.all_converged) and move < tolerance and left < tolerance, method="static Newton")


def equilibrium(solver, state, control, tolerance: float, max_steps: int = 2000, dt: float = 1.0,
                callback=None, method: str = "auto") -> EquilibriumResult:
    """Quasistatic steps until the equilibrium is within ``tolerance`` [m] of the current state.

    ``solver`` must be a :class:`~taichi_hair.solver_admm.SolverADMM` in the quasistatic mode; each step
    runs its iterations, the warm-started multipliers carrying the minimisation on from one step to the
    next.  A small displacement per step alone does not mean a small distance to the equilibrium when the
    iteration contracts slowly, so the distance left is estimated from the measured contraction rate
    r = (d_k / d_{k-w})^(1/w) of the largest displacement per step d over the last w =
    :data:`RATE_WINDOW` steps, as the geometric tail d_k r / (1 - r); the run stops when that estimate and
    d_k are both below ``tolerance`` (an estimate: it assumes the linear convergence ADMM shows near the
    solution).  ``callback(step, displacement)`` is called after each step (progress bars).  ``method``:
    "auto" (the static Newton solve where :func:`static_solve_choice` takes it, the stepping elsewhere),
    "newton" (the static solve wherever it models the scene, else a ValueError) or "admm" (the stepping);
    with the static solve ``steps`` is 1 and ``iterations`` counts that step's ADMM iterations plus the most
    Gauss-Newton iterations of a strand.
    """
    if solver.config.mode != Mode.QUASISTATIC:
        raise ValueError("equilibrium: the solver must be in the quasistatic mode (SolverADMMConfig.mode)")
    if not (math.isfinite(tolerance) and tolerance > 0):
        raise ValueError(f"equilibrium: tolerance must be a finite positive length [m], got {tolerance!r}")
    if method not in ("auto", "admm", "newton"):
        raise ValueError(f"equilibrium: method must be 'auto', 'admm' or 'newton', got {method!r}")
    if method != "admm":
        ok, why = static_solve_choice(solver, method)
        if ok:
            return _static_equilibrium(solver, state, control, tolerance, dt, callback)
        if method == "newton":
            raise ValueError(f"equilibrium: method='newton' does not apply: {why}")
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
