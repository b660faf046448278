"""Solvers other than the main ADMM one (which lives at the top: :mod:`taichi_hair.solver_admm`), and
drivers that step any solver.

* :mod:`.shape`: :class:`SolverShape`, Han & Harada's TressFX-style solver (Verlet, global and local
  shape constraints, edge lengths);
* :mod:`.xpbd`: :class:`SolverXPBD`, extended position-based dynamics on Cosserat rods (a baseline);
* :mod:`.equilibrium`: quasistatic stepping to an equilibrium;
* :mod:`.static_newton`: :class:`SolverStaticNewton`, the direct static solve of the same energy for strands
  without contacts whose twist can be dropped (what :mod:`.equilibrium` uses there).
"""

from __future__ import annotations

#: The solvers :func:`make_solver` builds, by name.
SOLVER_NAMES = ("admm", "shape", "xpbd")


def make_solver(name: str, model, config=None, colliders=None, profile: bool = False):
    """The one place a solver is built by name (scenes, benchmarks, the stability atlas, method choice).

    Args:
        name: "admm" (:class:`~taichi_hair.solver_admm.SolverADMM`, Daviet 2023), "shape"
            (:class:`~taichi_hair.solvers.shape.solver.SolverShape`, Han & Harada) or "xpbd"
            (:class:`~taichi_hair.solvers.xpbd.solver.SolverXPBD`).
        model: the finalized Model.
        config: the solver's config dataclass (None: its defaults); its type must match ``name``.
        colliders: bodies (a list of colliders or a ColliderSet); SolverXPBD takes none.
        profile: per-stage wall times in ``solver.stage_seconds``.
    """
    if name == "admm":
        from ..config import SolverADMMConfig
        from ..solver_admm import SolverADMM as cls

        expected = SolverADMMConfig
    elif name == "shape":
        from .shape.solver import SolverShape as cls
        from .shape.solver import SolverShapeConfig as expected
    elif name == "xpbd":
        from .xpbd.solver import SolverXPBD as cls
        from .xpbd.solver import SolverXPBDConfig as expected
    else:
        raise ValueError(f"make_solver: unknown solver {name!r} (known: {', '.join(SOLVER_NAMES)})")
    if config is not None and not isinstance(config, expected):
        raise ValueError(f"make_solver: solver {name!r} takes a {expected.__name__}, got {type(config).__name__}")
    return cls(model, config, profile=profile, colliders=colliders or None)
