"""Quasistatic stepping to an equilibrium, when only the equilibrium is asked for (issue 4 item 6).

Inertia and damping are dropped when only the equilibrium is asked for (``simulate SCENE --equilibrium``,
:func:`equilibrium`); the solver steps until the estimated distance to the
equilibrium is below a tolerance.  The constraint weight scale is w0 = 1 there (the grooming tool's
and the stick-slip validation's): measured on 20 hanging curly strands of the ``hang`` scene
(``python3 benchmarks/probes/quasistatic_w0.py``, steps of 10 iterations), w0 = 1 moves less than
0.1 um per step by step 300, w0 = 5 by step 1,000, and the paper's w0 = 25 still moved 15 mm between
steps 1,000 and 3,000 (ADMM's fixed point does not depend on w0; its speed does).
Same equilibrium as a long damped dynamic run, within the tolerance of the tests.
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
    if solver.config.mode != Mode.QUASISTATIC:
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
