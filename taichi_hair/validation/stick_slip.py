"""Stick-slip validation (Daviet 2023 Sec. 5.1; Romero et al. 2021).

A naturally straight hair rod (L = 10 cm) is clamped vertically at its top,
its tip resting on a fixed horizontal plane with friction mu.  The clamp is
pushed down progressively (800 quasistatic substeps up to 0.6 L); the rod
buckles, and the tip, held by friction, starts to slide when the horizontal
reaction exceeds mu times the vertical one.  We record the clamp
displacement at which the tip starts to slide, for several mu, all rods in
one simulation (each rod has its own plane, a collision group of one strand).

Choice written down: like is compared with like by giving the reference the
rod's own weight (a heavy elastica), not by switching gravity off in the
simulation.  The rod's weight is not negligible: rho g A L = 1.0e-5 N against
a clamped-pinned buckling load k^2 E I / L^2 = 3.0e-5 N, i.e. a
gravito-bending parameter Gamma = rho g A L^3 / (E I) = 6.8 against k^2 = 20.2
(an earlier version of this docstring said 1/3000 and compared the heavy
simulated rod with the weightless elastica; that is the 9-21 % gap it
reported).  The paper's Fig. 2 set-up has gravity (||g|| = 9.81), so the
simulation keeps it and the reference carries it.  The weightless comparison
stays available: ``run_stick_slip(gravity=0)`` switches gravity off and uses
the Gamma = 0 reference (Romero et al.'s mu_c ~ 0.36).

Reference (the project's own, written down here): while the tip sticks, the
rod is a clamped-pinned heavy elastica with the pin directly below the clamp.
With s the arclength from the clamp (s in [0, 1] after scaling by L), phi the
angle of the tangent from the downward vertical, (h, v) the reaction of the
plane on the tip scaled by L^2/EI (v > 0 pushes up) and Gamma as above, the
section at s carries the tip reaction minus the weight of the rod below it,
(h, v - Gamma (1 - s)), so the moment balance reads

    phi'' = -((v - Gamma (1 - s)) sin phi + h cos phi),   phi(0) = 0,   phi'(1) = 0 (no moment at the tip),
    int_0^1 sin phi ds = 0 (tip below the clamp),  int_0^1 cos phi ds = 1 - delta/L.

(Without the plane, v = h = 0, this is the hanging rod phi'' = Gamma (1 - s)
sin phi: in tension, stable.)  It is solved by shooting on (phi'(0), h, v)
with continuation in delta from the linear weightless clamped-pinned buckling
mode (tan k = k, k = 4.4934), then in Gamma at the smallest delta, then in
delta again.  The tip sticks while |h| <= mu v, so the critical displacement
for mu is the first delta at which |h|/v reaches mu.  The pinned-tip shape is
admissible only while the tip tangent points down (|phi(1)| <= 90 degrees);
past that the end of the rod would cross the plane, so it lies down on it
instead, and the sticking tip configuration ends.  Weightless (Gamma = 0):
|h|/v = 0.3564 at |phi(1)| = 90 deg (delta = 0.330 L), the mu_c ~ 0.36 that
Romero et al. report.  With the 10 cm hair's weight (Gamma = 6.80):
mu_c = 0.3737 at delta = 0.317 L.

Measured (``taichi-hair validate stick-slip``, defaults, gravity on): see
BENCHMARKS.md "Validation runs" and ``benchmarks/results/validation/``.
"""

from __future__ import annotations

import csv
import math
import os
import time
from dataclasses import dataclass

import numpy as np

from .elasticity_params import HAIR

K_BUCKLE = 4.493409457909064  # first root of tan k = k


# --------------------------------------------------------------------------- reference
def _integrate(params, gamma):
    """(phi, phi', x, y) at s = 1 of the heavy elastica shot from the clamp with (phi'(0), h, v) = params."""
    from scipy.integrate import solve_ivp

    kappa0, h, v = params

    def rhs(s, y):
        phi, dphi, _, _ = y
        return [dphi, -((v - gamma * (1.0 - s)) * math.sin(phi) + h * math.cos(phi)), math.sin(phi),
                math.cos(phi)]

    sol = solve_ivp(rhs, (0.0, 1.0), [0.0, kappa0, 0.0, 0.0], rtol=1e-11, atol=1e-12, method="DOP853")
    return sol.y[:, -1]


def _shoot(params, delta, gamma=0.0):
    phi, dphi, x, y = _integrate(params, gamma)
    return np.array([dphi, x, y - (1.0 - delta)])


def stick_slip_gamma(length: float = 0.1, gravity: float = 9.81) -> float:
    """Gravito-bending parameter Gamma = rho g A L^3 / (E I) of the hair rod of the set-up (6.80 at 10 cm)."""
    from .elastica import cantilever_gamma

    if gravity == 0.0:
        return 0.0
    return cantilever_gamma(length, HAIR["radius"], HAIR["density"], HAIR["youngs_modulus_bend"], gravity)


def _solve(guess, delta, gamma):
    from scipy.optimize import fsolve

    sol, info, ier, msg = fsolve(_shoot, guess, args=(delta, gamma), full_output=True, xtol=1e-12)
    if ier != 1 or np.abs(_shoot(sol, delta, gamma)).max() > 1e-8:
        raise RuntimeError(f"stick-slip reference: shooting failed at delta/L = {delta:.4g}, "
                           f"Gamma = {gamma:.4g}: {msg}")
    return sol


def elastica_branch(deltas, gamma: float = 0.0):
    """Shooting parameters (phi'(0), h, v) (shape (n, 3), scaled by L and L^2/EI) and the tip angle
    |phi(1)| [rad] of the clamped-pinned heavy elastica (gravito-bending parameter ``gamma``, 0:
    weightless) at end shortenings delta/L (increasing, in (0, 0.95)).

    Raises RuntimeError if the shooting does not converge at some delta.
    """
    deltas = np.asarray(deltas, float)
    if np.any(np.diff(deltas) <= 0) or deltas[0] <= 0 or deltas[-1] >= 0.95:
        raise ValueError("deltas must increase within (0, 0.95)")
    # Linear mode phi = c (tan k sin ks + cos ks - 1), h/v = c; end shortening = 1/2 int phi^2.
    s = np.linspace(0, 1, 2001)
    mode = np.tan(K_BUCKLE) * np.sin(K_BUCKLE * s) + np.cos(K_BUCKLE * s) - 1.0
    half_sq = 0.5 * np.trapezoid(mode**2, s)
    v0 = K_BUCKLE**2
    params = np.empty((len(deltas), 3))
    angles = np.empty(len(deltas))
    guess = None
    # Continuation: start well inside the linear regime, march to each requested delta.
    path = np.unique(np.concatenate([np.geomspace(1e-5, deltas[0], 8), deltas]))
    # Weightless up to the first delta, then Gamma raised in steps at that delta, then on in delta.
    for d in path[path < deltas[0]]:
        if guess is None:
            c = math.sqrt(d / half_sq)
            guess = np.array([c * np.tan(K_BUCKLE) * K_BUCKLE, c * v0, v0])
        guess = _solve(guess, d, 0.0)
    if gamma > 0.0:
        for g in np.linspace(0.0, gamma, 1 + int(math.ceil(gamma)))[1:]:
            guess = _solve(guess, deltas[0], float(g))
    for i, d in enumerate(deltas):
        guess = _solve(guess, d, gamma)
        params[i] = guess
        angles[i] = abs(_integrate(guess, gamma)[0])
    return params, angles


def elastica_tip_force_ratio(deltas, gamma: float = 0.0):
    """|h|/v and the tip angle |phi(1)| [rad] along :func:`elastica_branch`."""
    params, angles = elastica_branch(deltas, gamma)
    return np.abs(params[:, 1]) / params[:, 2], angles


def reference_mu_critical(deltas, ratios, angles) -> tuple[float, float]:
    """(mu_c, delta_c/L): |h|/v and delta where the tip tangent becomes horizontal (interpolated)."""
    i = int(np.argmax(angles >= math.pi / 2))
    if angles[i] < math.pi / 2:
        return float(ratios.max()), float("nan")
    t = (math.pi / 2 - angles[i - 1]) / (angles[i] - angles[i - 1])
    return float(ratios[i - 1] + t * (ratios[i] - ratios[i - 1])), float(deltas[i - 1] + t * (deltas[i] - deltas[i - 1]))


def reference_critical_displacement(mu: float, deltas: np.ndarray, ratios: np.ndarray) -> float:
    """First delta/L at which |h|/v reaches mu (linear interpolation), NaN if it never does.

    Pass only the admissible part of the curve (tip angle <= 90 degrees).
    """
    above = np.where(ratios >= mu)[0]
    if mu <= 0:
        return 0.0
    if above.size == 0:
        return float("nan")
    i = above[0]
    if i == 0:
        return float(deltas[0] * mu / ratios[0])
    t = (mu - ratios[i - 1]) / (ratios[i] - ratios[i - 1])
    return float(deltas[i - 1] + t * (deltas[i] - deltas[i - 1]))


# --------------------------------------------------------------------------- simulation
@dataclass
class StickSlipResult:
    mus: np.ndarray
    critical: np.ndarray          # simulated delta/L at sliding onset (NaN: never slid)
    reference: np.ndarray         # elastica prediction (NaN: never slides)
    mu_critical_reference: float
    deltas: np.ndarray            # reference curve delta/L
    ratios: np.ndarray            # reference |h|/v
    seconds: float
    substeps: int
    gamma: float = 0.0            # gravito-bending parameter of the rod and of the reference
    max_displacement: float = 0.6

    @property
    def rel_error(self) -> np.ndarray:
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(np.isfinite(self.reference) & (self.reference > 0),
                            self.critical / self.reference - 1.0, np.nan)

    def median_abs_error(self, lo: float = 0.1, hi: float = 0.3) -> float:
        """Median of |rel error| over the mu in [lo, hi] (NaN if none; a rod that never slid counts as
        inf)."""
        sel = (self.mus >= lo - 1e-9) & (self.mus <= hi + 1e-9)
        if not sel.any():
            return float("nan")
        e = np.where(np.isfinite(self.critical[sel]), np.abs(self.rel_error[sel]), np.inf)
        return float(np.median(e))

    @property
    def mu_critical(self) -> tuple[float, float]:
        """Simulated mu_c as (estimate, half-width): the midpoint between the largest mu whose tip slid and
        the smallest mu above it whose tip never did.  (NaN, NaN) if the grid does not bracket a threshold,
        or if a rod slid above one that did not (the threshold would not be a single value)."""
        order = np.argsort(self.mus)
        mus, slid = self.mus[order], np.isfinite(self.critical[order])
        if not slid.any() or slid.all():
            return float("nan"), float("nan")
        k = int(np.where(slid)[0].max())
        if k + 1 >= len(mus) or not np.all(slid[:k + 1]):
            return float("nan"), float("nan")
        return float(0.5 * (mus[k] + mus[k + 1])), float(0.5 * (mus[k + 1] - mus[k]))


def reference_curve(gamma: float = 0.0, max_displacement: float = 0.6, count: int = 120):
    """(deltas, ratios, mu_c, delta_c) of the reference; deltas/ratios cut to the admissible (sticking) part.

    The deltas are spaced quadratically (|h|/v grows like sqrt(delta) from 0), which keeps the linear
    interpolation of :func:`reference_critical_displacement` accurate with few points.
    """
    deltas = 0.002 + (max_displacement - 0.002) * np.linspace(0.0, 1.0, count) ** 2
    ratios, angles = elastica_tip_force_ratio(deltas, gamma)
    mu_c, delta_c = reference_mu_critical(deltas, ratios, angles)
    ok = angles <= math.pi / 2
    return deltas[ok], ratios[ok], mu_c, delta_c


def default_mus(mu_c: float, coarse=None) -> np.ndarray:
    """``coarse`` (default 0..0.6 in steps of 0.05), plus a 0.01-step grid over mu_c +- 0.03 to locate the
    threshold."""
    coarse = np.linspace(0.0, 0.6, 13) if coarse is None else np.asarray(coarse, float)
    fine = np.round(mu_c, 2) + np.arange(-0.03, 0.0301, 0.01)
    return np.unique(np.round(np.concatenate([coarse, fine]), 4))


def run_stick_slip(mus=None, length: float = 0.1, edge_length: float = 2.5e-3, substeps: int = 800,
                   max_displacement: float = 0.6, iterations: int = 150, slide_threshold: float = 0.5,
                   baseline: float = 0.005, gravity: float = 9.81, w0: float = 1.0, coarse_mus=None,
                   progress=None) -> StickSlipResult:
    """Push the clamps down over ``substeps`` quasistatic steps up to ``max_displacement`` L.

    Sliding onset: the first clamp displacement at which the tip has moved
    horizontally by more than ``slide_threshold`` times the rod radius from
    where it was at a clamp displacement of ``baseline`` L (a sticking tip
    does not move at all).  The baseline skips the first substeps, where the
    quasistatic iterate is still far from equilibrium (the straight rod is
    compressed before it buckles) and the tip shifts by about one radius;
    the reference predicts sliding that early only for mu < 0.02.  The rods
    are given a lateral bow of 5e-3 L in their (rest) shape to pick the
    buckling direction.  ``gravity`` [m/s^2] is both the simulation's and the
    reference's (Gamma = rho g A L^3 / (E I); 0: weightless rod, weightless
    reference).  ``mus`` defaults to :func:`default_mus` (``coarse_mus`` plus
    a 0.01-step grid around the reference's mu_c).  ``w0`` is the ADMM weight scale, set here rather than
    taken from the SolverADMMConfig default.
    """
    from .. import GroomBuilder, RodMaterial, SolverADMM, SolverADMMConfig
    from ..contact.colliders import PlaneCollider
    from ..config import ContactConfig

    gamma = stick_slip_gamma(length, gravity)
    ref_deltas, ref_ratios, mu_c, _ = reference_curve(gamma, max_displacement)
    mus = default_mus(mu_c, coarse_mus) if mus is None else np.asarray(mus, float)
    mat = RodMaterial(radius=HAIR["radius"], density=HAIR["density"], youngs_modulus_bend=HAIR["youngs_modulus_bend"],
                      poisson_ratio=HAIR["poisson_ratio"])
    n = max(16, int(round(length / edge_length))) + 1
    spacing = 0.05
    b = GroomBuilder()
    colliders = []
    for k, mu in enumerate(mus):
        x0 = k * spacing
        # Root at the top, tip touching the plane y = 0 (centreline one radius above it).
        # A bow of 5e-3 L in the rest shape picks the buckling direction.
        y = np.linspace(length, 0.0, n)
        bow = 5e-3 * length * np.sin(np.pi * (length - y) / length)
        pts = np.c_[x0 + bow, mat.radius + y, np.zeros(n)]
        b.add_strand(pts, mat)
        colliders.append(PlaneCollider(point=(0, 0, 0), normal=(0, 1, 0), friction=float(mu), strands=(k, k + 1)))
    model = b.finalize()
    st, ctl = model.state(), model.control()
    ctl.gravity = (0.0, -float(gravity), 0.0)
    cfg = SolverADMMConfig(iterations=iterations, mode="quasistatic", w0=w0,
                           contacts=ContactConfig(hair_hair=False, margin=2e-4, correction_iterations=4))
    solver = SolverADMM(model, cfg, colliders=colliders)
    tips = model.host["strand_vertex_start"] + model.host["strand_vertex_count"] - 1
    tip0 = None
    critical = np.full(len(mus), np.nan)
    t0 = time.perf_counter()
    for j in range(1, substeps + 1):
        d = max_displacement * length * j / substeps
        ctl.set_body_transform(0, np.eye(3), (0.0, -d, 0.0))
        solver.step(st, ctl, 1.0)
        tip_x = st.positions()[tips, 0].astype(np.float64)
        if tip0 is None:
            if d < baseline * length:
                continue
            tip0 = tip_x
        slid = np.abs(tip_x - tip0) > slide_threshold * mat.radius
        newly = slid & np.isnan(critical)
        critical[newly] = d / length
        if progress is not None and j % 100 == 0:
            progress(j, d / length, int(np.sum(np.isfinite(critical))))
    seconds = time.perf_counter() - t0
    ref = np.array([reference_critical_displacement(mu, ref_deltas, ref_ratios) if mu < mu_c else float("nan")
                    for mu in mus])
    return StickSlipResult(mus, critical, ref, mu_c, ref_deltas, ref_ratios, seconds, substeps, gamma,
                           max_displacement)


def write_outputs(result: StickSlipResult, out_dir: str) -> tuple[str, str]:
    """``stick_slip.csv`` (mu, critical_displacement_over_L, reference, rel_error) and ``stick_slip.png``."""
    os.makedirs(out_dir, exist_ok=True)
    csv_path = os.path.join(out_dir, "stick_slip.csv")
    tmp = csv_path + ".tmp"
    with open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["mu", "critical_displacement_over_L", "reference", "rel_error"])
        for mu, c, r, e in zip(result.mus, result.critical, result.reference, result.rel_error):
            w.writerow([f"{mu:.4f}", "" if np.isnan(c) else f"{c:.5f}", "" if np.isnan(r) else f"{r:.5f}",
                        "" if np.isnan(e) else f"{e:.5f}"])
    os.replace(tmp, csv_path)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4.2))
    ax.plot(result.ratios, result.deltas, "k-",
            label=f"{'heavy ' if result.gamma > 0 else ''}elastica (Gamma = {result.gamma:.2f}), "
                  "tip sticks while |H| <= mu V")
    ax.axvline(result.mu_critical_reference, color="k", ls=":", lw=1,
               label=f"mu_c = {result.mu_critical_reference:.3f} (never slides above)")
    ok = np.isfinite(result.critical)
    ax.plot(result.mus[ok], result.critical[ok], "rx", ms=8, mew=2, label="taichi-hair (ADMM, f32)")
    never = ~ok
    if never.any():
        ax.plot(result.mus[never], np.full(never.sum(), result.deltas[-1]), "r^", ms=7,
                label=f"taichi-hair: no sliding up to {result.max_displacement:g} L")
    ax.set_xlabel("friction coefficient mu")
    ax.set_ylabel("clamp displacement at sliding onset / L")
    ax.set_title("Stick-slip: 10 cm hair rod pushed onto a plane")
    ax.legend(fontsize=8, loc="upper left")
    ax.grid(alpha=0.3)
    png_path = os.path.join(out_dir, "stick_slip.png")
    fig.tight_layout()
    fig.savefig(png_path + ".tmp.png", dpi=120)
    plt.close(fig)
    os.replace(png_path + ".tmp.png", png_path)
    return csv_path, png_path


def format_summary(result: StickSlipResult) -> str:
    mc, hw = result.mu_critical
    lines = [f"stick-slip: {len(result.mus)} friction coefficients, {result.substeps} quasistatic substeps, "
             f"{result.seconds:.1f} s; rod and reference Gamma = {result.gamma:.2f}",
             f"mu_c: simulated {mc:.3f} +- {hw:.3f}, reference {result.mu_critical_reference:.4f}; "
             f"median |rel error| over mu in 0.1-0.3: {100 * result.median_abs_error():.2f}%",
             f"{'mu':>6} {'sim delta/L':>12} {'reference':>10} {'rel error':>10}"]
    for mu, c, r, e in zip(result.mus, result.critical, result.reference, result.rel_error):
        cs = "never" if np.isnan(c) else f"{c:.4f}"
        rs = "never" if np.isnan(r) else f"{r:.4f}"
        es = "" if np.isnan(e) else f"{100 * e:+.1f}%"
        lines.append(f"{mu:6.3f} {cs:>12} {rs:>10} {es:>10}")
    return "\n".join(lines)
