"""The ADMM variants the studies compare, defined once (stability atlas, Pareto chart, method choice).

Each name maps to the :class:`~taichi_hair.config.SolverADMMConfig` fields it changes:

* ``admm``: w0 = 25 (Daviet 2023's weight scale), backward Euler, the plain iteration (the paper's);
* ``admm_w1``: w0 = 1, plain iteration, backward Euler: the project's default where the twist is solved
  (curved rods) and with contacts (issue 12);
* ``admm_aa``: w0 = 1 with Anderson acceleration (window 5, from 10 iterations per step): the project's
  default on straight, twist-free rods without contacts (``anderson.anderson_auto_window``);
* ``admm_bdf2``: w0 = 1, BDF2 (second order in dt; ``SolverADMMConfig.integrator = "bdf2"``);
* ``admm_f64``: w0 = 1 in double precision (Pareto only: run in the f64 worker process);
* ``admm_ref``: the Pareto reference (w0 = 25, f64, 50 iterations at small dt).
"""

from __future__ import annotations

#: name -> SolverADMMConfig overrides.
ADMM_VARIANTS = {
    "admm": {"w0": 25.0, "integrator": "backward_euler", "anderson_window": 0},
    "admm_w1": {"w0": 1.0, "integrator": "backward_euler", "anderson_window": 0},
    "admm_aa": {"w0": 1.0, "integrator": "backward_euler", "anderson_window": 5},
    "admm_bdf2": {"w0": 1.0, "integrator": "bdf2", "anderson_window": 0},
    "admm_f64": {"w0": 1.0, "integrator": "backward_euler", "anderson_window": 0},
    "admm_ref": {"w0": 25.0, "integrator": "backward_euler", "anderson_window": 0},
}

#: One line per variant, for help texts and method-choice descriptions.
ADMM_DESCRIPTIONS = {
    "admm": "w0 = 25 (paper), backward Euler, plain iteration",
    "admm_w1": "w0 = 1, backward Euler, plain iteration (default on curved rods)",
    "admm_aa": "w0 = 1, Anderson acceleration (default on straight rods), backward Euler",
    "admm_bdf2": "w0 = 1, BDF2",
    "admm_f64": "w0 = 1, backward Euler, f64",
    "admm_ref": "w0 = 25, backward Euler, f64 reference",
}


def is_admm(method: str) -> bool:
    return method in ADMM_VARIANTS


def admm_config(method: str, **fields):
    """A SolverADMMConfig of variant ``method`` with ``fields`` (iterations, drag, ...) set."""
    from ..config import SolverADMMConfig

    return SolverADMMConfig(**{**ADMM_VARIANTS[method], **fields})
