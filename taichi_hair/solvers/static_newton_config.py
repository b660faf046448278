"""Settings, results and set-up of the direct static solve (:mod:`taichi_hair.solvers.static_newton`), in NumPy:
the config and result records, the scope check and the rest strains kappa_bar in float64."""

from dataclasses import dataclass

import numpy as np


@dataclass
class StaticNewtonConfig:
    """Settings of :class:`SolverStaticNewton`.

    Attributes:
        max_iterations: Gauss-Newton iterations at most per strand [-].
        tolerance: stop when the largest move of an iteration (a vertex, or a twist angle times its edge's
            length) is below this [m].
        line_search_steps: halvings of the step at most in the line search [-].
    """

    max_iterations: int = 200
    tolerance: float = 1.0e-10
    line_search_steps: int = 40

    def __post_init__(self):
        if not (isinstance(self.max_iterations, int) and self.max_iterations >= 1):
            raise ValueError(f"StaticNewtonConfig.max_iterations must be an integer >= 1, got {self.max_iterations!r}")
        if not (np.isfinite(self.tolerance) and self.tolerance > 0):
            raise ValueError(f"StaticNewtonConfig.tolerance must be a finite length > 0 [m], got {self.tolerance!r}")
        if not (isinstance(self.line_search_steps, int) and 1 <= self.line_search_steps <= 200):
            raise ValueError("StaticNewtonConfig.line_search_steps must be an integer in [1, 200], "
                             f"got {self.line_search_steps!r}")


@dataclass
class StaticNewtonResult:
    """What :meth:`SolverStaticNewton.solve` did, per strand (arrays of shape (strand_count,))."""

    iterations: np.ndarray     # Gauss-Newton iterations [-]
    converged: np.ndarray      # the last move was below the tolerance [bool]
    last_move: np.ndarray      # largest move of the last iteration [m]
    previous_move: np.ndarray  # the same for the iteration before (0 after one iteration) [m]
    energy: np.ndarray         # E at the end [J]

    @property
    def all_converged(self) -> bool:
        return bool(np.all(self.converged))

    def estimated_distance(self) -> float:
        """Largest estimated distance left to the equilibrium [m]: the geometric tail d r / (1 - r) of the last
        move d with the contraction rate r = d / d_previous of the last two iterations (Gauss-Newton converges
        linearly here); inf where the last move did not contract."""
        d, p = self.last_move, self.previous_move
        with np.errstate(divide="ignore", invalid="ignore"):
            r = np.where(p > 0.0, d / p, 0.0)
            tail = np.where(d == 0.0, 0.0, np.where(r < 1.0, d * r / (1.0 - r), np.inf))
        return float(np.max(tail)) if tail.size else 0.0


def static_newton_eligibility(model, solver_config=None) -> tuple:
    """Whether :class:`SolverStaticNewton` models ``model`` with ``solver_config`` exactly, and why not."""
    from ..config import SolverADMMConfig, StrainMeasure

    cfg = solver_config or SolverADMMConfig()
    if cfg.strain_measure != StrainMeasure.KORNER:
        return False, "the static Newton solve models the Korner strain measure only"
    return True, "Korner strain"


def _korner_np(m1a, m2a, ta, m1b, m2b, tb) -> np.ndarray:
    """The Korner strain 2 v (rows) of the frames' relative rotation: :func:`taichi_hair.strains.korner_quaternion`
    in NumPy float64."""
    def dot(u, v):
        return np.einsum("ij,ij->i", u, v)
    w = 0.5 * np.sqrt(np.maximum(1.0 + dot(m1a, m1b) + dot(m2a, m2b) + dot(ta, tb), 1e-12))
    v = np.stack([dot(ta, m2b) - dot(m2a, tb), dot(m1a, tb) - dot(ta, m1b), dot(m2a, m1b) - dot(m1a, m2b)], axis=1)
    return 2.0 * v / (4.0 * w[:, None])


def rest_strain(model, bend: np.ndarray) -> np.ndarray:
    """kappa_bar of every pair (vertex_count, 3) [-], float64: the Korner strain of the rest frames, minus
    mu / S for a sag-free rest pose (``pair_rest_moment``), zero on inactive pairs; ``bend`` = S (n, 3)."""
    h = model.host
    t = np.asarray(h["edge_rest_tangent"], np.float64)
    d = np.asarray(h["edge_rest_director"], np.float64)
    tw = np.asarray(h["edge_rest_twist"], np.float64)
    m1 = np.cos(tw)[:, None] * d + np.sin(tw)[:, None] * np.cross(t, d)
    m2 = np.cross(t, m1)
    k = np.zeros_like(t)
    k[1:] = _korner_np(m1[:-1], m2[:-1], t[:-1], m1[1:], m2[1:], t[1:])
    moment = h.get("pair_rest_moment")
    if moment is not None:
        safe = np.where(bend > 0.0, bend, 1.0)
        k = np.where(bend > 0.0, k - np.asarray(moment, np.float64) / safe, k)
    return np.where(np.asarray(h["pair_is_active"]).astype(bool)[:, None], k, 0.0)


def static_newton_twist(model, solver_config=None) -> bool:
    """Whether the static solve needs the twist angles as unknowns for ``model`` (curved, elliptic or sag-free
    strands), or drops them exactly (:func:`taichi_hair.frames.twist_choice`)."""
    from ..config import SolverADMMConfig
    from ..frames import twist_choice

    cfg = solver_config or SolverADMMConfig()
    h = model.host
    moment = h.get("pair_rest_moment")
    if moment is not None and np.any(np.asarray(moment) != 0.0):
        return True
    active = np.asarray(h["pair_is_active"]).astype(bool)
    vstar = model.pair_voronoi_length(cfg.voronoi_rescaling)
    bend = np.where(active[:, None], np.asarray(h["pair_bending_modulus"], np.float64) / vstar[:, None], 0.0)
    return not twist_choice(h, rest_strain(model, bend))[0]
