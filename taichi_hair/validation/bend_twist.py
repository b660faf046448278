"""Bend-twist validation (Daviet 2023 Sec. 5.1 and Fig. 2 middle; Romero et al. 2021; Miller et al. 2014).

Rods with a natural curvature kappa (a planar circular arc at rest) are clamped at their top
with a vertical tangent and hang under gravity.  Short or strongly curved rods keep a planar
curl; long, weakly curved ones twist out of their plane into a helix.  We simulate a grid of
(kappa, phi = kappa L) in ONE Model (every rod its own strand, one SolverADMM), with the
paper's protocol -- damped dynamic steps, gravity tilted out of the rest plane for the first
``tilt_steps`` steps to seed a transverse perturbation -- and classify each equilibrium as
planar or not by a PCA of its vertex positions.  The reference is the project's own
linear-stability computation of the planar equilibrium, below.

Reference: linear stability of the planar heavy curl (derived here)
-------------------------------------------------------------------

Kirchhoff rod, inextensible and unshearable, isotropic section: bending stiffness EI, twisting
stiffness GJ = EI / (1 + nu) (``RodMaterial.stiffness_matrix_diag``, l = 0), weight per length
w = rho g A, natural Darboux vector (kappa, 0, 0) in the material frame (d1, d2, d3), d3 the
tangent.  Lengths are scaled by L and energies by EI / L, which leaves three parameters:

    phi = kappa L,   Gamma = rho g A L^3 / (EI) = (L / l_gb)^3,   c = GJ / EI = 1 / (1 + nu),

with l_gb = (EI / (rho g A))^(1/3) the gravito-bending length (5.28 cm for the hair of
Fig. 2).  With y up, the gravitational energy of the rod is int rho g A y(s) ds with
y(s) = int_0^s d3_y, and exchanging the integrals gives  int_0^1 Gamma (1 - s) d3(s).e_y ds:
each tangent is weighted by the weight hanging below it (the internal force of a rod with a
free end is known in closed form, whatever its shape).  The total energy is therefore local in
the frame field R(s) = [d1 d2 d3]:

    E[R] = int_0^1 1/2 ((u1 - phi)^2 + u2^2 + c u3^2) + Gamma (1 - s) d3.e_y ds,

u the Darboux vector of R in its own frame, R(0) fixed (clamp: d3(0) = -e_y).  We discretise it
with N segments of length h = 1/N and one frame per segment, u_i = log(R_i^T R_{i+1}) / h,
the gravity term at segment midpoints.

1. Planar equilibrium.  With d1 = e_z the rods stay in the x-y plane, R_i a rotation by
   theta_i about e_z, d3_i = (sin theta_i, -cos theta_i, 0) and u = ((theta_{i+1} -
   theta_i)/h, 0, 0).  E(theta) is minimised by damped Newton, with continuation in Gamma
   from 0 (where theta = phi s, the rest arc): the branch the simulation follows when gravity
   is switched on at the rest shape.
2. Out-of-plane stability.  Perturb every frame as R_i exp([psi_i]) with psi_i in material
   components.  By the mirror symmetry z -> -z the second variation splits into an in-plane
   block (psi_1, positive at the minimum of step 1) and an out-of-plane block (psi_2: the
   tangent leaves the plane, psi_3: twist).  Gravity gives, per segment, the exact 3x3 Hessian
   h Gamma (1 - s) (1/2 (a e3^T + e3 a^T) - a_3 I) with a = R_i^T e_y (from the second-order
   term 1/2 psi x (psi x e3) of d3); the bending-twisting term of each pair of segments is
   differentiated numerically (central differences on the rotation-vector log, per pair, so the
   Hessian is block tridiagonal).  The planar curl is linearly stable iff the smallest
   eigenvalue of the out-of-plane block is positive.
3. Threshold.  For each phi, the critical Gamma_c(phi) is found by bisection on the sign of
   that eigenvalue (on log Gamma), i.e. the critical length L_c = l_gb Gamma_c^(1/3) and
   curvature kappa_c = phi / L_c.

What the computation gives (nu = 0.45; map of ``benchmarks/results/bend_twist/bend_twist.png``,
32 x 32 points): the planar curl is stable (i) for every rod shorter than about phi = 1.8 pi
(less than one turn: no out-of-plane mode is soft enough), (ii) for weak curvatures
kappa < 0.31 cm^-1, i.e. kappa l_gb < 1.6, at every phi up to 25 pi (the rod hangs nearly
straight, its weight dominating the weak curl), and (iii) for strong curvatures above a line
that rises steeply with kappa (from phi ~ 2 pi at kappa ~ 0.55 cm^-1 to 25 pi at
2.2 cm^-1; the coil is stiff against its own weight).  In between the planar curl twists out of
its plane.  Boundary (ii) is vertical at large phi as expected: for long rods the curl lives
near the free end, where the tension is low, over a length set by kappa and l_gb alone.
Boundary (iii) follows phi_c ~ (kappa l_gb)^3 (a coil's weight moment Gamma/phi^2 against its
bending stiffness), e.g. phi_c grows by ~4x from kappa = 1.2 to 2 cm^-1 where (10.6/6.3)^3 = 4.8.
Miller et al. 2014 (PRL 112, 068103; the source of Romero et al.'s bend-twist test) describe
the same three regimes (planar curls, localised helices near the free end of long rods, global
helices).  We did not have the text of Romero et al. 2021 or Miller et al. at hand, so the
comparison with their plotted threshold is qualitative (the regimes and the asymptotes), not
number against number.

Simulation choices (where the paper is silent, written down):

* Discretisation: 2.5 mm edges and at least 16 edges per rod (the paper's), but at most
  ``max_edges`` edges per rod (the longest rods of the paper's grid are 4.4 m, 1,776 edges);
  above, the edges are L / max_edges long.  At the default 120 the coarsest rod has
  kappa h = 0.33 rad per edge.
* Time step ``dt`` = 0.02 s, ``iterations`` ADMM iterations per step (the paper: 100),
  strain-rate damping (``RodMaterial.damping_time`` = 0.05 s) and air drag
  (``air_viscosity``, a velocity relaxation rate of ``drag_rate`` = 2 /s) for the "damped"
  dynamics; gravity tilted by ``tilt`` = 0.3 rad towards +z (out of the rest plane) for the
  first ``tilt_steps`` = 100 steps, as in the paper.
* Classifier: PCA of the vertex positions of the equilibrium; eigenvalues l1 <= l2 <= l3 of
  the covariance; planar iff l1 / mean(l) < ``planarity_threshold`` (default 1e-4).  A planar
  curve has l1 = 0 exactly.  A localised helix at the end of a long rod gives a small ratio
  (the straight upper part dominates the covariance), so the threshold must sit well below
  1e-3.  A helix of radius r and pitch p over n whole turns has the covariance
  [[r^2/2, 0, 0], [0, r^2/2, -r p/(2 pi)], [0, -r p/(2 pi), (n p)^2/12]] (tests).
  Measured on the default 8 x 8 grid (2500 steps of 0.02 s, 50 iterations,
  ``benchmarks/results/bend_twist/bend_twist.json``): rods the reference calls planar gave
  ratios up to 7.2e-5, non-planar ones 2.2e-4 and above, and one rod near the boundary
  (kappa = 1 cm^-1, phi = 6.7 pi) gave 1.1e-4 (classified non-planar, the reference says
  planar: the one disagreement of 64).  The margin is thin.  All rods but one settled (final
  speeds below 8 mm/s); the 3.2 m rod (kappa = 0.25 cm^-1, phi = 25 pi, 120 edges of 2.6 cm)
  still moved at 0.49 m/s after 2500 steps despite the drag, and its ratio (7.2e-5) is the
  planar one closest to the threshold.  Candidate cause, not verified: the same
  unconverged-ADMM motion at w0 = 25 that :mod:`taichi_hair.bench.stability` measured on
  cantilevers.  Two runs of the default grid gave bit-identical CSVs (180 s and 270 s of
  stepping, depending on the machine's load).
"""

from __future__ import annotations

import csv
import math
import os
import time
from dataclasses import dataclass, field

import numpy as np

from .elasticity_params import GRAVITY, HAIR

EDGE_LENGTH = 2.5e-3
MIN_EDGES = 16


# --------------------------------------------------------------------------- material helpers
def hair_bending_stiffness() -> float:
    """EI of the hair of Fig. 2 [N m^2]."""
    return HAIR["youngs_modulus_bend"] * math.pi * HAIR["radius"] ** 4 / 4.0


def hair_weight_per_length() -> float:
    """rho g A of the hair of Fig. 2 [N/m]."""
    return HAIR["density"] * GRAVITY * math.pi * HAIR["radius"] ** 2


def gravito_bending_length() -> float:
    """l_gb = (EI / (rho g A))^(1/3) [m]."""
    return (hair_bending_stiffness() / hair_weight_per_length()) ** (1.0 / 3.0)


def gamma_of(length):
    """Gamma = (L / l_gb)^3 [-] for lengths [m]."""
    return (np.asarray(length, dtype=np.float64) / gravito_bending_length()) ** 3


# --------------------------------------------------------------------------- classifier
def planarity_ratio(points) -> float:
    """Smallest eigenvalue of the covariance of ``points`` (shape (n, 3) [m]) over their mean [-].

    0 for points in a plane; 1 for an isotropic cloud.
    """
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or p.shape[0] < 3:
        raise ValueError(f"planarity_ratio: points must have shape (n >= 3, 3), got {p.shape}")
    if not np.all(np.isfinite(p)):
        raise ValueError("planarity_ratio: points must be finite")
    c = np.cov((p - p.mean(axis=0)).T)
    ev = np.linalg.eigvalsh(c)
    mean = float(np.mean(ev))
    if mean <= 0:
        raise ValueError("planarity_ratio: all points coincide")
    return float(max(ev[0], 0.0) / mean)


def is_planar(points, threshold: float = 1e-3) -> bool:
    """PCA classifier of Daviet 2023 Sec. 5.1: min eigenvalue / mean eigenvalue < ``threshold``."""
    if not (isinstance(threshold, (int, float)) and math.isfinite(threshold) and 0 < threshold < 1):
        raise ValueError(f"is_planar: threshold must lie in (0, 1), got {threshold!r}")
    return planarity_ratio(points) < threshold


# --------------------------------------------------------------------------- reference
def _rot_z(theta):
    c, s = np.cos(theta), np.sin(theta)
    R = np.zeros(theta.shape + (3, 3))
    R[..., 0, 0], R[..., 0, 1], R[..., 1, 0], R[..., 1, 1], R[..., 2, 2] = c, -s, s, c, 1.0
    return R


#: Clamp frame: d1 = e_z (curl axis), d3 = -e_y (tangent pointing down), d2 = d3 x d1 = -e_x.
_R_CLAMP = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])


def _planar_newton(theta: np.ndarray, phi: float, gamma: float, max_iterations: int = 200) -> np.ndarray:
    """Minimise the discrete planar energy in theta_1..theta_{N-1} (theta_0 = 0: clamp) from ``theta``.

    Damped Newton: the tridiagonal Hessian is shifted until it is positive definite, so the iteration
    descends to a local minimum (a stable in-plane equilibrium).
    """
    from scipy.linalg import LinAlgError, solveh_banded

    N = theta.shape[0]
    h = 1.0 / N
    W = gamma * (1.0 - (np.arange(N) + 0.5) * h) * h
    theta = theta.copy()
    for _ in range(max_iterations):
        d = np.diff(theta) / h - phi
        grad = W * np.sin(theta)
        grad[1:] += d
        grad[:-1] -= d
        diag = W * np.cos(theta)
        diag[1:] += 1.0 / h
        diag[:-1] += 1.0 / h
        band = np.zeros((2, N - 1))
        band[0, 1:] = -1.0 / h
        band[1] = diag[1:]
        shift = 0.0
        while True:
            try:
                b = band.copy()
                b[1] += shift
                step = -solveh_banded(b, grad[1:])
                break
            except LinAlgError:
                shift = max(1e-6, 10 * shift)
        big = np.max(np.abs(step))
        if big > 0.2:  # trust region: Newton from far away overshoots when the weight term dominates
            step *= 0.2 / big
        theta[1:] += step
        if big < 1e-11 and shift == 0.0:
            break
    return theta


def planar_equilibrium(phi: float, gamma: float, segments: int = 200, steps: int = 40) -> np.ndarray:
    """Tangent angles theta_i (from the downward vertical) of the planar heavy curl, shape (segments,).

    Damped Newton on the discrete planar energy, continued in Gamma from 0 (theta = phi s, the rest
    arc) in ``steps`` geometric steps.
    """
    theta = phi * np.arange(int(segments)) / segments
    if gamma > 0:
        for G in np.geomspace(min(gamma, 1e-3), gamma, steps):
            theta = _planar_newton(theta, phi, G)
    return theta


def _pair_energy(psi_a, psi_b, theta_a, theta_b, phi, c, h):
    """Bending-twisting energy of consecutive segments perturbed by material rotation vectors (vectorised)."""
    from scipy.spatial.transform import Rotation as Rot

    Ea = Rot.from_rotvec(psi_a)
    Eb = Rot.from_rotvec(psi_b)
    rel = Rot.from_rotvec(np.c_[(theta_b - theta_a), np.zeros_like(theta_a), np.zeros_like(theta_a)])
    u = (Ea.inv() * rel * Eb).as_rotvec() / h
    return 0.5 * h * ((u[:, 0] - phi) ** 2 + u[:, 1] ** 2 + c * u[:, 2] ** 2)


def out_of_plane_hessian_band(theta: np.ndarray, phi: float, gamma: float, c: float) -> np.ndarray:
    """Second variation of E in the out-of-plane directions, upper band storage, shape (4, 2 (N - 1)).

    Unknowns: (psi_2, psi_3) of frames 1..N-1 (frame 0 is clamped), interleaved; the Hessian is
    block tridiagonal with 2x2 blocks, so its bandwidth is 3.
    """
    N = theta.shape[0]
    h = 1.0 / N
    nf = 2 * (N - 1)
    rows, cols, vals = [], [], []
    # Gravity: h Gamma (1 - s) [1/2 (a e3^T + e3 a^T) - a3 I] restricted to (psi_2, psi_3), a = R^T e_y.
    R = _rot_z(theta) @ _R_CLAMP
    a = R[:, 1, :]  # components of e_y in the material frame (R^T e_y) = second row of R
    Wg = gamma * (1.0 - (np.arange(N) + 0.5) * h) * h
    f = np.arange(1, N)
    k = 2 * (f - 1)
    rows += [k, k, k + 1]
    cols += [k, k + 1, k + 1]
    vals += [-Wg[f] * a[f, 2], 0.5 * Wg[f] * a[f, 1], np.zeros(N - 1)]
    # Bending and twisting: 4x4 Hessian of each pair (segments i, i+1) by central differences.
    ta, tb = theta[:-1], theta[1:]
    P = N - 1
    eps = 1e-4
    idx = [(0, 1), (0, 2), (1, 1), (1, 2)]  # (frame of the pair, material component)

    def energy(dvec):
        pa = np.zeros((P, 3))
        pb = np.zeros((P, 3))
        for j, (w, comp) in enumerate(idx):
            (pa if w == 0 else pb)[:, comp] += dvec[j]
        return _pair_energy(pa, pb, ta, tb, phi, c, h)

    pair = np.arange(P)
    for j in range(4):
        for m in range(j, 4):
            e = []
            for sj, sm in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
                d = np.zeros(4)
                d[j] += sj * eps
                d[m] += sm * eps
                e.append(energy(d))
            hjm = (e[0] - e[1] - e[2] + e[3]) / (4 * eps * eps)
            fj, fm = pair + idx[j][0], pair + idx[m][0]
            dj, dm = 2 * (fj - 1) + idx[j][1] - 1, 2 * (fm - 1) + idx[m][1] - 1
            ok = (fj > 0) & (fm > 0)
            lo, hi = np.minimum(dj, dm)[ok], np.maximum(dj, dm)[ok]
            rows.append(lo)
            cols.append(hi)
            vals.append(hjm[ok])
    r, cc, v = np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)
    band = np.zeros((4, nf))
    np.add.at(band, (3 + r - cc, cc), v)
    return band


def _min_eigenvalue(band: np.ndarray) -> float:
    from scipy.linalg import eig_banded

    return float(eig_banded(band, lower=False, eigvals_only=True, select="i", select_range=(0, 0))[0])


def reference_segments(phi: float) -> int:
    """Segments used for the reference at turning angle phi: 200, or 12 per radian of the rest curl."""
    return int(max(200, math.ceil(12 * phi)))


def out_of_plane_min_eigenvalues(phi: float, gammas, poisson_ratio: float = HAIR["poisson_ratio"],
                                 segments: int | None = None) -> np.ndarray:
    """Smallest eigenvalue of the out-of-plane second variation [EI/L] at each Gamma of ``gammas``.

    The planar equilibria are continued in Gamma (ascending) from the rest arc, so each is on the
    branch connected to the rest shape.  Positive: the planar curl is linearly stable.
    """
    g = np.asarray(gammas, dtype=np.float64).reshape(-1)
    order = np.argsort(g)
    N = reference_segments(phi) if segments is None else int(segments)
    c = 1.0 / (1.0 + poisson_ratio)
    theta = phi * np.arange(N) / N
    out = np.empty(g.shape[0])
    G_prev = 1e-3
    for i in order:
        G = g[i]
        if G > G_prev:
            for Gk in np.geomspace(G_prev, G, max(2, int(math.ceil(4 * math.log10(G / G_prev))) + 1))[1:]:
                theta = _planar_newton(theta, phi, Gk)
            G_prev = G
        else:
            theta = _planar_newton(theta, phi, G)
        out[i] = _min_eigenvalue(out_of_plane_hessian_band(theta, phi, G, c))
    return out


def out_of_plane_min_eigenvalue(phi: float, gamma: float, poisson_ratio: float = HAIR["poisson_ratio"],
                                segments: int | None = None) -> float:
    """:func:`out_of_plane_min_eigenvalues` at one Gamma."""
    return float(out_of_plane_min_eigenvalues(phi, [gamma], poisson_ratio, segments)[0])


def planar_reference(curvature, length, poisson_ratio: float = HAIR["poisson_ratio"]) -> np.ndarray:
    """Reference classification of hair rods (curvature [1/m], length [m], same shapes): True where the
    planar curl connected to the rest arc is linearly stable."""
    k = np.asarray(curvature, dtype=np.float64).reshape(-1)
    L = np.asarray(length, dtype=np.float64).reshape(-1)
    phi = k * L
    gam = gamma_of(L)
    out = np.zeros(k.shape[0], dtype=bool)
    for p in np.unique(np.round(phi, 12)):
        sel = np.where(np.abs(phi - p) <= 1e-9 * max(1.0, p))[0]
        out[sel] = out_of_plane_min_eigenvalues(p, gam[sel], poisson_ratio) > 0
    return out


def stability_map(curvatures, phis, poisson_ratio: float = HAIR["poisson_ratio"]) -> np.ndarray:
    """Smallest out-of-plane eigenvalue on the grid curvatures [1/m] x phis, shape (len(phis), len(curvatures)).

    Scaled by the continuum value's resolution (times N) so that grids of different N compare.
    """
    kap = np.asarray(curvatures, dtype=np.float64)
    out = np.empty((len(phis), len(kap)))
    for i, p in enumerate(phis):
        gam = gamma_of(p / kap)
        out[i] = out_of_plane_min_eigenvalues(p, gam, poisson_ratio) * reference_segments(p)
    return out


def threshold_curves(curvatures, phis, poisson_ratio: float = HAIR["poisson_ratio"]):
    """The sign map of :func:`stability_map` on a grid [1/m] x [-], for contouring: (curvatures, phis, map)."""
    return np.asarray(curvatures, float), np.asarray(phis, float), stability_map(curvatures, phis, poisson_ratio)


# --------------------------------------------------------------------------- simulation
def default_grid(count: int = 8):
    """``count`` log-spaced curvatures from 0.175 to 2 cm^-1 [1/m] and turning angles phi from 0.25 pi to
    25 pi [-] (Daviet 2023, Fig. 2 caption)."""
    if not (isinstance(count, (int, np.integer)) and count >= 2):
        raise ValueError(f"bend-twist: count must be an integer >= 2, got {count!r}")
    return np.geomspace(17.5, 200.0, count), np.geomspace(0.25, 25.0, count) * math.pi


def rod_edge_count(length: float, max_edges: int) -> int:
    """2.5 mm edges, at least 16, at most ``max_edges`` (see the module docstring)."""
    return int(min(max(MIN_EDGES, round(length / EDGE_LENGTH)), max_edges))


@dataclass
class BendTwistConfig:
    """Settings of the bend-twist simulation (defaults: Daviet 2023 Sec. 5.1 where it says, else ours).

    Attributes:
        steps: dynamic steps (the paper: 2500) [-].
        tilt_steps: first steps with gravity tilted out of the rest plane (the paper: 100) [-].
        tilt: angle of that tilt from the vertical, towards +z [rad].
        dt: time step [s].
        iterations: ADMM iterations per step (the paper: 100) [-].
        max_edges: most edges per rod (2.5 mm edges below that) [-].
        damping_time: strain-rate damping tau of the rods (``RodMaterial.damping_time``) [s].
        drag_rate: air drag as a velocity relaxation rate xi / (rho A) [1/s].
        planarity_threshold: PCA classifier threshold on min/mean eigenvalue [-].
    """

    steps: int = 2500
    tilt_steps: int = 100
    tilt: float = 0.3
    dt: float = 0.02
    iterations: int = 50
    max_edges: int = 120
    damping_time: float = 0.05
    drag_rate: float = 2.0
    planarity_threshold: float = 1e-4

    def __post_init__(self):
        for name, lo in (("steps", 1), ("tilt_steps", 0), ("iterations", 1), ("max_edges", MIN_EDGES)):
            v = getattr(self, name)
            if not (isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= lo):
                raise ValueError(f"BendTwistConfig.{name} must be an integer >= {lo}, got {v!r}")
        for name in ("dt", "damping_time", "drag_rate", "tilt"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ValueError(f"BendTwistConfig.{name} must be a finite number >= 0, got {v!r}")
        if self.dt <= 0:
            raise ValueError(f"BendTwistConfig.dt must be > 0, got {self.dt!r}")
        if not (0 < self.planarity_threshold < 1):
            raise ValueError("BendTwistConfig.planarity_threshold must lie in (0, 1), "
                             f"got {self.planarity_threshold!r}")


@dataclass
class BendTwistResult:
    curvatures: np.ndarray      # per rod [1/m]
    lengths: np.ndarray         # per rod [m]
    ratios: np.ndarray          # PCA min/mean eigenvalue of the final shape [-]
    planar: np.ndarray          # simulated classification
    reference: np.ndarray       # linear-stability reference
    config: BendTwistConfig
    seconds: float
    vertex_count: int
    final_speed: float          # largest vertex speed at the end [m/s]
    shapes: list = field(default_factory=list)
    rod_speeds: np.ndarray | None = None  # largest vertex speed of each rod at the end [m/s]

    @property
    def phis(self) -> np.ndarray:
        return self.curvatures * self.lengths

    @property
    def agreement(self) -> float:
        return float(np.mean(self.planar == self.reference))


def arc_points(curvature: float, length: float, edges: int) -> np.ndarray:
    """Rest arc: root at the origin, tangent -y, curling in the x-y plane, shape (edges + 1, 3) [m]."""
    s = np.linspace(0.0, length, edges + 1)
    return np.c_[(1.0 - np.cos(curvature * s)) / curvature, -np.sin(curvature * s) / curvature, np.zeros_like(s)]


def run_bend_twist(curvatures, lengths, config: BendTwistConfig | None = None, progress=None,
                   reference: bool = True) -> BendTwistResult:
    """Simulate every (curvature [1/m], length [m]) rod in one Model and classify its equilibrium.

    Args:
        curvatures, lengths: one entry per rod (same length).
        config: :class:`BendTwistConfig`.
        progress: optional callable(step, steps, max_speed) called every 100 steps.
        reference: also compute the linear-stability reference (a few seconds per distinct phi).
    """
    from ..builder import GroomBuilder
    from ..config import RodMaterial, SolverADMMConfig
    from ..solver_admm import SolverADMM

    cfg = config or BendTwistConfig()
    cfg.__post_init__()
    k = np.asarray(curvatures, dtype=np.float64).reshape(-1)
    L = np.asarray(lengths, dtype=np.float64).reshape(-1)
    if k.shape != L.shape or k.size == 0:
        raise ValueError(f"bend-twist: curvatures and lengths must have the same non-zero length, "
                         f"got {k.shape} and {L.shape}")
    if not (np.all(np.isfinite(k)) and np.all(k > 0) and np.all(np.isfinite(L)) and np.all(L > 0)):
        raise ValueError("bend-twist: curvatures and lengths must be finite and positive")
    mat = RodMaterial(radius=HAIR["radius"], density=HAIR["density"], youngs_modulus_bend=HAIR["youngs_modulus_bend"],
                      poisson_ratio=HAIR["poisson_ratio"], damping_time=cfg.damping_time)
    b = GroomBuilder()
    for kk, LL in zip(k, L):
        # d1 along z: the rest curl lies in the x-y plane (the director only fixes the material frame).
        b.add_strand(arc_points(kk, LL, rod_edge_count(LL, cfg.max_edges)), mat, root_director=(0.0, 0.0, 1.0))
    model = b.finalize()
    state, control = model.state(), model.control()
    xi = cfg.drag_rate * HAIR["density"] * math.pi * HAIR["radius"] ** 2
    solver = SolverADMM(model, SolverADMMConfig(iterations=cfg.iterations, mode="dynamic", air_viscosity=xi))
    g_tilt = (0.0, -GRAVITY * math.cos(cfg.tilt), GRAVITY * math.sin(cfg.tilt))
    t0 = time.perf_counter()
    speed = float("nan")
    for step in range(cfg.steps):
        control.gravity = g_tilt if step < cfg.tilt_steps else (0.0, -GRAVITY, 0.0)
        solver.step(state, control, cfg.dt)
        if progress is not None and ((step + 1) % 100 == 0 or step + 1 == cfg.steps):
            v = state.vertex_velocity.to_numpy()
            speed = float(np.sqrt(np.max(np.sum(v.astype(np.float64) ** 2, axis=1))))
            progress(step + 1, cfg.steps, speed)
    seconds = time.perf_counter() - t0
    v = state.vertex_velocity.to_numpy().astype(np.float64)
    speed = float(np.sqrt(np.max(np.sum(v**2, axis=1))))
    x = state.vertex_position.to_numpy().astype(np.float64)
    starts, counts = model.host["strand_vertex_start"], model.host["strand_vertex_count"]
    shapes = [x[s:s + c] for s, c in zip(starts, counts)]
    ratios = np.array([planarity_ratio(p) for p in shapes])
    planar = ratios < cfg.planarity_threshold
    ref = planar_reference(k, L) if reference else np.zeros(k.shape, bool)
    vnorm = np.sqrt(np.sum(v**2, axis=1))
    rod_speeds = np.array([vnorm[s:s + c].max() for s, c in zip(starts, counts)])
    return BendTwistResult(k, L, ratios, planar, ref, cfg, seconds, model.vertex_count, speed, shapes, rod_speeds)


# --------------------------------------------------------------------------- outputs
def write_outputs(result: BendTwistResult, out_dir: str, map_count: int = 32) -> tuple[str, str, str]:
    """Write ``bend_twist.csv``, ``bend_twist.png`` (phase diagram) and ``bend_twist.json`` (summary)."""
    import json

    os.makedirs(out_dir, exist_ok=True)
    csv_path = os.path.join(out_dir, "bend_twist.csv")
    with open(csv_path + ".tmp", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["curvature_per_m", "length_m", "planar", "planar_reference"])
        for k, L, p, r in zip(result.curvatures, result.lengths, result.planar, result.reference):
            w.writerow([f"{k:.6g}", f"{L:.6g}", int(bool(p)), int(bool(r))])
    os.replace(csv_path + ".tmp", csv_path)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    kmin, kmax = result.curvatures.min() / 1.15, result.curvatures.max() * 1.15
    pmin, pmax = result.phis.min() / 1.15, result.phis.max() * 1.15
    kk = np.geomspace(kmin, kmax, map_count)
    pp = np.geomspace(pmin, pmax, map_count)
    M = stability_map(kk, pp)
    fig, ax = plt.subplots(figsize=(7, 5.5))
    ax.contourf(kk / 100, pp / math.pi, (M > 0).astype(float), levels=[-0.5, 0.5, 1.5],
                colors=["#f6d5c8", "#d5e5f6"], alpha=0.8)
    ax.contour(kk / 100, pp / math.pi, M, levels=[0.0], colors="k", linewidths=1.5)
    ax.plot([], [], "k-", label="planar curl loses stability (our linear analysis)")
    agree = result.planar == result.reference
    for planar, marker, name in ((True, "o", "simulated: planar"), (False, "x", "simulated: not planar")):
        sel = result.planar == planar
        ax.scatter(result.curvatures[sel & agree] / 100, result.phis[sel & agree] / math.pi, marker=marker,
                   c="C0" if planar else "C3", s=36, label=name)
        bad = sel & ~agree
        if bad.any():
            ax.scatter(result.curvatures[bad] / 100, result.phis[bad] / math.pi, marker=marker, c="m", s=70,
                       linewidths=2, label=name + " (disagrees with reference)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("natural curvature kappa [1/cm]")
    ax.set_ylabel("phi / pi = kappa L / pi")
    ax.set_title(f"Bend-twist: hair rods, ADMM (f32), {result.config.steps} damped steps; "
                 f"agreement {100 * result.agreement:.0f}%", fontsize=9)
    ax.text(0.02, 0.02, "blue: planar stable (reference), red: unstable", transform=ax.transAxes, fontsize=8)
    ax.legend(fontsize=7, loc="upper left")
    ax.grid(True, which="both", alpha=0.2)
    fig.tight_layout()
    png_path = os.path.join(out_dir, "bend_twist.png")
    fig.savefig(png_path + ".tmp.png", dpi=120)
    plt.close(fig)
    os.replace(png_path + ".tmp.png", png_path)

    summary = {
        "rods": int(len(result.lengths)), "vertices": int(result.vertex_count), "seconds": round(result.seconds, 2),
        "agreement": result.agreement, "final_max_speed_m_per_s": result.final_speed,
        "gravito_bending_length_m": gravito_bending_length(),
        "config": {k: getattr(result.config, k) for k in result.config.__dataclass_fields__},
        "rods_detail": [{"curvature_per_m": float(k), "length_m": float(L), "phi_over_pi": float(k * L / math.pi),
                         "pca_ratio": float(r), "planar": bool(p), "planar_reference": bool(q),
                         "final_max_speed_m_per_s": float(sp)}
                        for k, L, r, p, q, sp in zip(result.curvatures, result.lengths, result.ratios, result.planar,
                                                     result.reference,
                                                     result.rod_speeds if result.rod_speeds is not None
                                                     else np.full(len(result.lengths), np.nan))],
    }
    json_path = os.path.join(out_dir, "bend_twist.json")
    with open(json_path + ".tmp", "w") as fh:
        json.dump(summary, fh, indent=1)
    os.replace(json_path + ".tmp", json_path)
    return csv_path, png_path, json_path


def format_summary(result: BendTwistResult) -> str:
    n = len(result.lengths)
    wrong = np.where(result.planar != result.reference)[0]
    lines = [f"bend-twist: {n} rods ({result.vertex_count} vertices), {result.config.steps} steps x "
             f"{result.config.iterations} ADMM iterations in {result.seconds:.1f} s; classification agrees with "
             f"the linear-stability reference for {n - len(wrong)}/{n} rods; final max speed "
             f"{result.final_speed:.3g} m/s"]
    for i in wrong:
        lines.append(f"  disagrees: kappa = {result.curvatures[i] / 100:.3f} /cm, phi = "
                     f"{result.phis[i] / math.pi:.2f} pi, L = {100 * result.lengths[i]:.1f} cm: simulated "
                     f"{'planar' if result.planar[i] else 'not planar'} (PCA ratio {result.ratios[i]:.2e})")
    return "\n".join(lines)
