"""Reference solution of the heavy elastica: the "cantilever" experiment.

Romero et al. 2021, "Physical validation of simulators in computer graphics:
a new framework dedicated to slender elastic structures and frictional
contact", ACM TOG 40(4), in their cantilever experiment (a heavy rod
bending under its own weight; section number not checked here), compare
simulators on a naturally straight, inextensible, unshearable rod of length L
that is clamped horizontally at one end and left free at the other, under
uniform gravity g.  At equilibrium the shape of the
centerline depends on a single dimensionless number, the gravito-bending
parameter

    Gamma = rho g A L^3 / (E I)                                           (1)

(rho: density [kg/m^3], A: cross-section area [m^2], E: Young modulus [Pa],
I: second moment of area about the bending axis [m^4]; Gamma is the ratio of
the weight torque q L^2, q = rho g A [N/m], to the bending stiffness E I / L),
and the observable is the aspect ratio H/W of the centerline, H being the
vertical drop from root to tip and W the horizontal distance from root to tip.
This module computes the master curve H/W(Gamma) independently of the
simulator (numpy + scipy only), so that a simulator can be checked against it.

Formulation (Kirchhoff rod, planar, inextensible, unshearable)
---------------------------------------------------------------
Let s in [0, L] be the arc length, sigma = s/L, and theta(sigma) the angle of
the tangent measured *downwards* from the horizontal, so that the (dimensional)
centerline is

    x'(s) = cos theta,    z'(s) = -sin theta     (z upwards, root at (0, 0)).

Bending moment (about the horizontal axis normal to the plane, counted positive
when it bends the rod downwards) carried by the section at s: it equilibrates
the weight of the overhanging part [s, L], each element ds' of which hangs at
the lever arm x(s') - x(s):

    M(s) = q * integral_s^L (x(s') - x(s)) ds'.                           (2)

The constitutive law of an elastica is M = E I theta'(s).  Differentiating (2)
(the boundary term vanishes because the lever arm is zero at s' = s),

    E I theta''(s) = -q * integral_s^L x'(s) ds' = -q (L - s) cos theta(s),

i.e. in dimensionless form, with Gamma from (1),

    theta''(sigma) = -Gamma (1 - sigma) cos theta(sigma),                 (3)
    theta(0) = 0           (horizontal clamp),
    theta'(1) = 0          (free end: M(L) = 0).

Note the minus sign: the curvature theta' (> 0, bending down) is largest at the
root and decreases to zero at the tip.  Check against linear beam theory
(cos theta ~ 1): theta'(sigma) = Gamma (1 - sigma)^2 / 2, so the dimensionless
root curvature is theta'(0) = Gamma / 2 (root moment q L^2 / 2), and
theta(sigma) = Gamma/6 (1 - (1 - sigma)^3) integrates to the classical tip
deflection q L^4 / (8 E I), i.e. H/W -> Gamma/8 for Gamma -> 0 (with a relative
correction O(Gamma^2)).  For Gamma -> infinity the rod hangs vertically except
in a root boundary layer of width O(Gamma^{-1/2}).  There, with
phi = pi/2 - theta, (3) reduces to phi'' = Gamma sin phi, whose first integral
phi'^2 = 2 Gamma (1 - cos phi) gives theta'(0) -> sqrt(2 Gamma) and
W = int sin(phi) dphi / |phi'| -> sqrt(2 / Gamma); with H -> L,
H/W -> sqrt(Gamma / 2), all with O(Gamma^{-1/2}) relative corrections.

Numerical methods
-----------------
* :func:`solve_heavy_elastica` (the reference): Chebyshev spectral collocation
  of (3) on N+1 Chebyshev-Lobatto points, solved by a damped Newton method with
  continuation in Gamma (geometric ladder from Gamma = 1, each solution being
  the initial guess of the next).  The root boundary layer of width
  Gamma^{-1/2} is resolved because Chebyshev points cluster like 1/N^2 at the
  ends; N grows like Gamma^{1/4} and the decay of the Chebyshev coefficients is
  checked (N is doubled if the tail is not at round-off level).  H and W are
  the exact integrals of the Chebyshev interpolants of sin theta and cos theta,
  and x(s), z(s) their exact antiderivatives.
* :func:`solve_heavy_elastica_shooting` (independent check): shooting from the
  *free end* towards the clamp.  Forward shooting on theta'(0) is hopeless for
  large Gamma (the linearisation of (3) about the hanging state grows like
  exp(2/3 Gamma^{1/2}), i.e. e^210 at Gamma = 1e5); integrated backwards from
  the tip, the wanted solution is the *dominant* mode and the problem is well
  conditioned.  The unknown is the log of the tip angle from the vertical,
  phi(1) = pi/2 - theta(1), which is exponentially small for large Gamma; it is
  found by Brent's method with an adaptive 8th-order Runge-Kutta integrator
  (scipy ``DOP853``, rtol 1e-12).

The two methods share nothing but equation (3); the tests check that they
agree to better than 1e-6 (relative) on H/W for Gamma up to 1e5.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.polynomial import chebyshev as npcheb
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

__all__ = [
    "HeavyElasticaSolution",
    "ShootingSolution",
    "solve_heavy_elastica",
    "solve_heavy_elastica_shooting",
    "heavy_elastica_h_over_w",
    "heavy_elastica_residual",
    "cantilever_gamma",
]

#: Gamma range on which the reference is validated (relative error of H/W well
#: below 1e-6 there; see tests/test_elastica_reference.py).
GAMMA_VALIDATED_RANGE = (1.0e-4, 1.0e5)


# --------------------------------------------------------------------------
# Result containers
# --------------------------------------------------------------------------
@dataclass(frozen=True)
class HeavyElasticaSolution:
    """Equilibrium of the horizontally clamped heavy elastica, eq. (3).

    All lengths are in units of the rod length L; angles in radians.

    Attributes:
        gamma: gravito-bending parameter Gamma = rho g A L^3 / (E I) [-].
        s: arc-length parameter sigma = s/L, uniform in [0, 1], shape (n,) [-].
        theta: tangent angle below the horizontal at ``s``, shape (n,) [rad];
            theta(0) = 0 (clamp), increasing towards the tip.
        x: horizontal coordinate of the centerline, x(0) = 0, shape (n,) [L].
        z: vertical coordinate (up is positive, so z <= 0 along the rod),
            z(0) = 0, shape (n,) [L].
        h_over_w: aspect ratio H/W with H = -z(1) (drop of the tip below the
            root, positive) and W = x(1) (horizontal reach of the tip) [-].
        tip_angle: theta(1), the tangent angle at the free end [rad]; tends to
            pi/2 (vertical) for Gamma -> infinity.
        root_curvature: dimensionless curvature theta'(0) = M(0) L / (E I) at
            the clamp [-]; Gamma/2 for Gamma -> 0.
        height: H [L].
        width: W [L].
    """

    gamma: float
    s: np.ndarray
    theta: np.ndarray
    x: np.ndarray
    z: np.ndarray
    h_over_w: float
    tip_angle: float
    root_curvature: float
    height: float
    width: float


@dataclass(frozen=True)
class ShootingSolution:
    """Scalars of the heavy elastica obtained by :func:`solve_heavy_elastica_shooting`.

    Same meaning and units as the fields of :class:`HeavyElasticaSolution`.
    """

    gamma: float
    h_over_w: float
    tip_angle: float
    root_curvature: float
    height: float
    width: float


# --------------------------------------------------------------------------
# Chebyshev spectral collocation (reference method)
# --------------------------------------------------------------------------
@lru_cache(maxsize=16)
def _cheb_grid(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Chebyshev-Lobatto grid on sigma in [0, 1] with derivative matrices.

    Returns (sigma, D1, D2) with sigma_j = (1 - cos(pi j / n)) / 2, so that
    j = 0 is the clamp and j = n the free end, and D1, D2 the first and second
    derivative matrices with respect to sigma (Trefethen, "Spectral Methods in
    MATLAB", program cheb.m, with the chain rule d/dsigma = -2 d/dx).
    """
    j = np.arange(n + 1)
    xc = np.cos(np.pi * j / n)
    c = np.ones(n + 1)
    c[0] = c[-1] = 2.0
    c *= (-1.0) ** j
    dx = xc[:, None] - xc[None, :]
    d = np.outer(c, 1.0 / c) / (dx + np.eye(n + 1))
    # Diagonal by the "negative sum trick": rows of D annihilate constants,
    # which is markedly more accurate than the closed-form diagonal.
    d -= np.diag(d.sum(axis=1))
    d1 = -2.0 * d
    d2 = d1 @ d1
    sigma = 0.5 * (1.0 - xc)
    for a in (sigma, d1, d2):
        a.flags.writeable = False
    return sigma, d1, d2


def _cheb_coeffs(values: np.ndarray) -> np.ndarray:
    """Chebyshev coefficients (in x = 1 - 2 sigma) of the interpolant through
    values given at the Lobatto points x_j = cos(pi j / n) (type-I DCT via FFT)."""
    n = values.shape[0] - 1
    ext = np.concatenate([values, values[-2:0:-1]])
    coef = np.real(np.fft.fft(ext))[: n + 1] / n
    coef[0] *= 0.5
    coef[-1] *= 0.5
    return coef


def _n_for_gamma(gamma: float) -> int:
    """Number of Chebyshev intervals needed for eq. (3) at this Gamma.

    The root boundary layer behaves like exp(-sqrt(Gamma) sigma); the Chebyshev
    coefficients of exp(-a sigma) decay like exp(-k^2 / a) so k ~ sqrt(35 a)
    terms reach round-off, i.e. N ~ 6 Gamma^{1/4}.  We take a margin of ~3 and
    round up to a multiple of 16; the tail check in :func:`_newton_collocation`
    doubles N if this was not enough.
    """
    n = 32.0 + 16.0 * max(gamma, 0.0) ** 0.25
    return int(16 * math.ceil(n / 16.0))


def _newton_collocation(gamma: float, theta0: np.ndarray, n: int, *, tol: float = 1e-9,
                        max_iter: int = 60) -> np.ndarray:
    """Solve the collocation equations of (3) on the n-grid by damped Newton.

    Unknowns: theta at the n + 1 Lobatto points.  Equations:
        row 0:          theta_0 = 0                                (clamp)
        rows 1..n-1:    (D2 theta)_j + Gamma (1 - sigma_j) cos theta_j = 0
        row n:          (D1 theta)_n = 0                           (free end)
    The interior rows are divided by (1 + Gamma) and the last by
    (1 + sqrt(Gamma)) only to measure convergence on a common scale.
    """
    sigma, d1, d2 = _cheb_grid(n)
    load = gamma * (1.0 - sigma)
    w_int = 1.0 / (1.0 + gamma)
    w_end = 1.0 / (1.0 + math.sqrt(gamma))

    def residual(th: np.ndarray) -> np.ndarray:
        r = d2 @ th + load * np.cos(th)
        r *= w_int
        r[0] = th[0]
        r[-1] = (d1[-1] @ th) * w_end
        return r

    th = theta0.copy()
    r = residual(th)
    rnorm = np.max(np.abs(r))
    for _ in range(max_iter):
        jac = d2 - np.diag(load * np.sin(th))
        jac *= w_int
        jac[0, :] = 0.0
        jac[0, 0] = 1.0
        jac[-1, :] = d1[-1] * w_end
        step = np.linalg.solve(jac, -r)
        if np.max(np.abs(step)) < tol:
            # Quadratic regime: the error left after this step is O(|step|^2),
            # far below the round-off floor of the collocation residual.
            return th + step
        # Backtracking on the scaled residual: full Newton steps are taken in
        # the quadratic regime, shorter ones only if continuation was too bold.
        lam = 1.0
        while True:
            trial = th + lam * step
            r_trial = residual(trial)
            rn_trial = np.max(np.abs(r_trial))
            if rn_trial < (1.0 - 1e-4 * lam) * rnorm or lam < 1e-3:
                break
            lam *= 0.5
        th, r, rnorm = trial, r_trial, rn_trial
    raise RuntimeError(
        f"heavy elastica: Newton did not converge at Gamma={gamma:g} (N={n}, residual {rnorm:.3e})"
    )


def _interp_to_grid(theta: np.ndarray, n_new: int) -> np.ndarray:
    """Evaluate the Chebyshev interpolant of ``theta`` on the Lobatto grid of size n_new."""
    if theta.shape[0] == n_new + 1:
        return theta.copy()
    coef = _cheb_coeffs(theta)
    return npcheb.chebval(np.cos(np.pi * np.arange(n_new + 1) / n_new), coef)


def _linear_guess(gamma: float, n: int) -> np.ndarray:
    """Small-Gamma (linear beam) solution theta = Gamma/6 (1 - (1 - sigma)^3)."""
    sigma, _, _ = _cheb_grid(n)
    return gamma / 6.0 * (1.0 - (1.0 - sigma) ** 3)


# Largest ratio between successive Gamma values of the continuation ladder.
_CONTINUATION_RATIO = 2.0
# Below this Gamma the linear-beam guess is close enough for Newton directly.
_GAMMA_LINEAR_START = 1.0


def _solve_collocation(gamma: float, guess: tuple[float, np.ndarray] | None = None
                       ) -> tuple[np.ndarray, int]:
    """Collocation solution (values of theta on the Lobatto grid) at ``gamma``.

    ``guess`` = (gamma_prev, theta_prev) is a previously converged solution
    used to start the continuation ladder; without it the ladder starts from
    the linear solution at Gamma = min(gamma, 1).  Returns (theta, n).
    """
    n = _n_for_gamma(gamma)
    if guess is not None and guess[0] <= gamma:
        g_prev, th = guess[0], _interp_to_grid(guess[1], n)
    else:
        g_prev = min(gamma, _GAMMA_LINEAR_START)
        th = _newton_collocation(g_prev, _linear_guess(g_prev, n), n)
    # Geometric continuation ladder g_prev -> gamma.
    if gamma > g_prev > 0.0:
        k = max(1, math.ceil(math.log(gamma / g_prev) / math.log(_CONTINUATION_RATIO)))
        for g in np.geomspace(g_prev, gamma, k + 1)[1:]:
            th = _newton_collocation(float(g), th, n)
    elif gamma != g_prev:
        th = _newton_collocation(gamma, th, n)
    # Resolution check: the Chebyshev tail of theta must be at round-off level.
    for _ in range(3):
        coef = _cheb_coeffs(th)
        tail = np.max(np.abs(coef[-4:]))
        if tail <= 1e-13 * max(1.0, np.max(np.abs(coef))) or gamma == 0.0:
            return th, n
        n *= 2
        th = _newton_collocation(gamma, _interp_to_grid(th, n), n)
    raise RuntimeError(f"heavy elastica: Chebyshev series not resolved at Gamma={gamma:g}")


def _scalars(gamma: float, th: np.ndarray, n: int) -> dict:
    """H, W, H/W, tip angle and root curvature from a collocation solution."""
    _, d1, _ = _cheb_grid(n)
    # Integrals over sigma in [0, 1] of the interpolants (Clenshaw-Curtis):
    # with x = 1 - 2 sigma, int_0^1 f dsigma = (F(1) - F(-1)) / 2.
    c_cos = npcheb.chebint(_cheb_coeffs(np.cos(th)))
    c_sin = npcheb.chebint(_cheb_coeffs(np.sin(th)))
    width = 0.5 * (npcheb.chebval(1.0, c_cos) - npcheb.chebval(-1.0, c_cos))
    height = 0.5 * (npcheb.chebval(1.0, c_sin) - npcheb.chebval(-1.0, c_sin))
    return dict(
        width=float(width),
        height=float(height),
        h_over_w=float(height / width),
        tip_angle=float(th[-1]),
        root_curvature=float(d1[0] @ th),
        c_cos=c_cos,
        c_sin=c_sin,
    )


def _check_gamma(gamma: float) -> float:
    gamma = float(gamma)
    if not (math.isfinite(gamma) and gamma >= 0.0):
        raise ValueError(f"Gamma must be a finite non-negative number, got {gamma!r}")
    return gamma


def solve_heavy_elastica(gamma: float, n_points: int = 2001) -> HeavyElasticaSolution:
    """Equilibrium of the horizontally clamped heavy elastica (Romero et al. 2021, cantilever).

    Solves eq. (3) of the module docstring,

        theta''(sigma) = -Gamma (1 - sigma) cos theta(sigma),
        theta(0) = 0,  theta'(1) = 0,

    by Chebyshev collocation + Newton + continuation in Gamma, then samples the
    solution at ``n_points`` uniformly spaced arc-length parameters and
    integrates the centerline x' = cos theta, z' = -sin theta exactly (spectral
    antiderivative).

    Args:
        gamma: gravito-bending parameter Gamma = rho g A L^3 / (E I) >= 0 [-]
            (see :func:`cantilever_gamma`).  Validated on [1e-4, 1e5]; larger
            values work while the grid (N ~ 16 Gamma^{1/4}) stays moderate.
        n_points: number of uniform samples of the returned centerline (>= 2).

    Returns:
        :class:`HeavyElasticaSolution` in units of L.
    """
    gamma = _check_gamma(gamma)
    if n_points < 2:
        raise ValueError(f"n_points must be >= 2, got {n_points!r}")
    th, n = _solve_collocation(gamma)
    sc = _scalars(gamma, th, n)
    s = np.linspace(0.0, 1.0, n_points)
    xs = 1.0 - 2.0 * s  # Chebyshev variable of each sample
    theta = npcheb.chebval(xs, _cheb_coeffs(th))
    # x(sigma) = int_0^sigma cos theta = (F(1) - F(1 - 2 sigma)) / 2, idem z with -sin.
    x = 0.5 * (npcheb.chebval(1.0, sc["c_cos"]) - npcheb.chebval(xs, sc["c_cos"]))
    z = -0.5 * (npcheb.chebval(1.0, sc["c_sin"]) - npcheb.chebval(xs, sc["c_sin"]))
    x[0] = z[0] = 0.0
    return HeavyElasticaSolution(
        gamma=gamma, s=s, theta=theta, x=x, z=z,
        h_over_w=sc["h_over_w"], tip_angle=sc["tip_angle"],
        root_curvature=sc["root_curvature"], height=sc["height"], width=sc["width"],
    )


def heavy_elastica_h_over_w(gammas) -> np.ndarray:
    """Aspect ratio H/W of the heavy elastica for an array of Gamma values.

    Vectorised over ``gammas`` (any shape; the result has the same shape): the
    values are solved in increasing order, each collocation solution serving
    as the initial guess of the next (continuation), so a sweep of ~100 values
    over [1e-3, 1.4e4] costs a fraction of a second.

    Args:
        gammas: Gamma values (>= 0) [-], scalar or array-like.

    Returns:
        H/W [-] as a float ndarray of the same shape (0 where Gamma = 0).
    """
    g = np.asarray(gammas, dtype=float)
    flat = g.ravel()
    for v in flat:
        _check_gamma(v)
    out = np.empty_like(flat)
    guess = None  # (gamma, theta on its Lobatto grid) of the last solved value
    last = 0.0
    for i in np.argsort(flat, kind="stable"):
        gi = float(flat[i])
        if guess is None or guess[0] != gi:  # duplicates are solved once
            th, n = _solve_collocation(gi, guess if (guess is not None and guess[0] > 0.0) else None)
            last = 0.0 if gi == 0.0 else _scalars(gi, th, n)["h_over_w"]
            guess = (gi, th)
        out[i] = last
    return out.reshape(g.shape)


def heavy_elastica_residual(sol: HeavyElasticaSolution) -> float:
    """Max over the interior samples of |theta'' + Gamma (1 - sigma) cos theta| / (1 + Gamma).

    theta'' is estimated by second-order central finite differences of the
    uniformly sampled ``sol.theta``, so the value measures both the solution
    error and the O(h^2 theta'''') discretisation error of the check itself.
    """
    s, th = sol.s, sol.theta
    h = s[1] - s[0]
    d2 = (th[2:] - 2.0 * th[1:-1] + th[:-2]) / h**2
    r = d2 + sol.gamma * (1.0 - s[1:-1]) * np.cos(th[1:-1])
    return float(np.max(np.abs(r)) / (1.0 + sol.gamma))


# --------------------------------------------------------------------------
# Shooting from the free end (independent check)
# --------------------------------------------------------------------------
def solve_heavy_elastica_shooting(gamma: float, rtol: float = 1e-12) -> ShootingSolution:
    """Heavy elastica (3) by shooting from the free end; an independent check.

    With phi = pi/2 - theta (angle from the downward vertical), (3) reads
    phi'' = Gamma (1 - sigma) sin phi, phi'(1) = 0, phi(0) = pi/2.  Writing
    phi = exp(u) psi, with exp(u) = phi(1) the unknown tip angle from the
    vertical, the initial value problem

        psi'' = Gamma (1 - sigma) sin(e^u psi) / e^u,   psi(1) = 1, psi'(1) = 0,
        X' = sin(e^u psi) (= cos theta),   Z' = cos(e^u psi) (= sin theta),

    is integrated from sigma = 1 down to sigma = 0 (``DOP853``, rtol given,
    tiny atol); psi = O(1) at the start whatever the size of phi(1) (which is
    ~exp(-2/3 sqrt(Gamma)), 1e-91 at Gamma = 1e5).  phi increases monotonically
    from the tip to the root; the root condition phi(0) = pi/2 is solved for u
    by Brent's method on the continuous, increasing function

        g(u) = sigma*            if phi reaches pi/2 at some sigma* in (0, 1]
             = phi(0) - pi/2     otherwise.

    (The overshooting branch is cut at sigma*: past pi/2 the backward problem
    is a pendulum and phi(0) is no longer monotone in u.)

    Works for 0 < Gamma <~ 1e5 (phi(1) must stay above the double underflow).
    Costs ~ 0.1-1 s per Gamma value; use :func:`heavy_elastica_h_over_w` for
    sweeps.

    Returns:
        :class:`ShootingSolution` in units of L.
    """
    gamma = _check_gamma(gamma)
    if gamma == 0.0:
        return ShootingSolution(gamma, 0.0, 0.0, 0.0, 0.0, 1.0)
    half_pi = 0.5 * math.pi

    def integrate(u: float):
        eu = math.exp(u)

        def rhs(sig, y):
            ph = eu * y[0]
            return [y[1], gamma * (1.0 - sig) * math.sin(ph) / eu, math.sin(ph), math.cos(ph)]

        def reach_vertical(sig, y):
            return eu * y[0] - half_pi

        reach_vertical.terminal = True
        reach_vertical.direction = 1.0
        return solve_ivp(rhs, (1.0, 0.0), [1.0, 0.0, 0.0, 0.0], method="DOP853",
                         rtol=rtol, atol=[1e-14 * rtol, 1e-14 * rtol, 1e-3 * rtol, 1e-3 * rtol],
                         events=reach_vertical)

    def g(u: float) -> float:
        if u >= math.log(half_pi):
            return 1.0  # the tip is already vertical (or past): sigma* = 1
        sol = integrate(u)
        if sol.t_events[0].size:
            return float(sol.t_events[0][0])
        return math.exp(u) * sol.y[0, -1] - half_pi

    # Bracket around the WKB estimate phi(1) ~ exp(-2/3 sqrt(Gamma)) (the root
    # is ~2 above it for large Gamma); a tight bracket saves Brent iterations.
    u_max = math.log(half_pi)
    u_wkb = -2.0 / 3.0 * math.sqrt(gamma)
    u_lo, u_hi = min(u_max - 1.0, u_wkb - 1.0), min(u_max, u_wkb + 5.0)
    while g(u_lo) >= 0.0:
        u_hi, u_lo = u_lo, u_lo - 5.0
        if u_lo < -740.0:
            raise RuntimeError(f"shooting: tip angle underflows at Gamma={gamma:g}")
    while g(u_hi) <= 0.0:
        u_lo, u_hi = u_hi, min(u_max, u_hi + 5.0)
    u = brentq(g, u_lo, u_hi, xtol=1e-15, rtol=4 * np.finfo(float).eps, maxiter=200)
    sol = integrate(u)
    eu = math.exp(u)
    width, height = -sol.y[2, -1], -sol.y[3, -1]
    return ShootingSolution(
        gamma=gamma,
        h_over_w=float(height / width),
        tip_angle=float(half_pi - eu),
        root_curvature=float(-eu * sol.y[1, -1]),
        height=float(height),
        width=float(width),
    )


# --------------------------------------------------------------------------
# Physical parameters -> Gamma
# --------------------------------------------------------------------------
def cantilever_gamma(length_m: float, radius_m: float, density: float, youngs_modulus: float,
                     gravity: float = 9.81, ellipticity: float = 0.0) -> float:
    """Gravito-bending parameter Gamma = rho g A L^3 / (E I) of eq. (1).

    Cross-section convention of :class:`taichi_hair.config.RodMaterial`: an
    ellipse of mean radius R and flatness l in [0, 1), semi-axes (1 + l) R and
    (1 - l) R, so

        A = pi R^2 (1 - l^2),
        I = A R^2 (1 - l)^2 / 4     (bending about the major axis, i.e. the
                                     soft direction; I = pi R^4 / 4 for l = 0),

    and Gamma = 4 rho g L^3 / (E R^2 (1 - l)^2).  For a circular section
    (l = 0): Gamma = 4 rho g L^3 / (E R^2).

    Args:
        length_m: rod length L [m].
        radius_m: (mean) radius R [m].
        density: rho [kg/m^3].
        youngs_modulus: bending Young modulus E [Pa].
        gravity: g [m/s^2].
        ellipticity: l [-]; the rod is assumed to bend in its soft direction.

    Returns:
        Gamma [-].
    """
    for name, v in (("length_m", length_m), ("radius_m", radius_m), ("density", density),
                    ("youngs_modulus", youngs_modulus), ("gravity", gravity)):
        if not (math.isfinite(v) and v > 0.0):
            raise ValueError(f"{name} must be a finite positive number, got {v!r}")
    if not (math.isfinite(ellipticity) and 0.0 <= ellipticity < 1.0):
        raise ValueError(f"ellipticity must lie in [0, 1), got {ellipticity!r}")
    area = math.pi * radius_m**2 * (1.0 - ellipticity**2)
    inertia = area * radius_m**2 * (1.0 - ellipticity) ** 2 / 4.0
    return density * gravity * area * length_m**3 / (youngs_modulus * inertia)
