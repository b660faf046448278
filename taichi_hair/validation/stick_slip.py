"""Stick-slip validation (Daviet 2023 Sec. 5.1; Romero et al. 2021).

A naturally straight hair rod (L = 10 cm) is clamped vertically at its top,
its tip resting on a fixed horizontal plane with friction mu.  The clamp is
pushed down progressively (800 quasistatic substeps up to 0.6 L); the rod
buckles, and the tip, held by friction, starts to slide when the horizontal
reaction exceeds mu times the vertical one.  We record the clamp
displacement at which the tip starts to slide, for several mu, all rods in
one simulation (each rod has its own plane, a collision group of one strand).

Reference (the project's own, written down here): the rod is weightless
(its weight, ~1e-5 N, is 1/3000 of its buckling load) and, while the tip
sticks, it is a clamped-pinned elastica with the pin directly below the
clamp.  With s the arclength from the clamp (s in [0, 1] after scaling by L),
phi the angle of the tangent from the downward vertical, and (h, v) the
reaction of the plane on the tip scaled by L^2/EI (v > 0 pushes up):

    phi'' = -(v sin phi + h cos phi),   phi(0) = 0,   phi'(1) = 0 (no moment at the tip),
    int_0^1 sin phi ds = 0 (tip below the clamp),  int_0^1 cos phi ds = 1 - delta/L.

It is solved by shooting on (phi'(0), h, v) with continuation in delta from
the linear clamped-pinned buckling mode (tan k = k, k = 4.4934).  The tip
sticks while |h| <= mu v, so the critical displacement for mu is the first
delta at which |h|/v reaches mu.  The pinned-tip shape is admissible only
while the tip tangent points down (|phi(1)| <= 90 degrees); past that the end
of the rod would cross the plane, so it lies down on it instead, and the
sticking tip configuration ends.  We find |h|/v = 0.3565 at |phi(1)| = 90 deg
(delta = 0.330 L): that is mu_c, above which the tip never slides, which
matches the mu_c ~ 0.36 that Romero et al. report.
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
def _shoot(params, delta):
    from scipy.integrate import solve_ivp

    kappa0, h, v = params

    def rhs(s, y):
        phi, dphi, _, _ = y
        return [dphi, -(v * math.sin(phi) + h * math.cos(phi)), math.sin(phi), math.cos(phi)]

    sol = solve_ivp(rhs, (0.0, 1.0), [0.0, kappa0, 0.0, 0.0], rtol=1e-11, atol=1e-12, method="DOP853")
    phi, dphi, x, y = sol.y[:, -1]
    return np.array([dphi, x, y - (1.0 - delta)])


def elastica_tip_force_ratio(deltas):
    """|h|/v and the tip angle |phi(1)| [rad] of the clamped-pinned weightless elastica at end shortenings
    delta/L (increasing, in (0, 0.95)).

    Raises RuntimeError if the shooting does not converge at some delta.
    """
    from scipy.integrate import solve_ivp
    from scipy.optimize import fsolve

    deltas = np.asarray(deltas, float)
    if np.any(np.diff(deltas) <= 0) or deltas[0] <= 0 or deltas[-1] >= 0.95:
        raise ValueError("deltas must increase within (0, 0.95)")
    # Linear mode phi = c (tan k sin ks + cos ks - 1), h/v = c; end shortening = 1/2 int phi^2.
    s = np.linspace(0, 1, 2001)
    mode = np.tan(K_BUCKLE) * np.sin(K_BUCKLE * s) + np.cos(K_BUCKLE * s) - 1.0
    half_sq = 0.5 * np.trapezoid(mode**2, s)
    v0 = K_BUCKLE**2
    ratios = np.empty(len(deltas))
    angles = np.empty(len(deltas))
    guess = None
    # Continuation: start well inside the linear regime, march to each requested delta.
    path = np.unique(np.concatenate([np.geomspace(1e-5, deltas[0], 8), deltas]))
    for d in path:
        if guess is None:
            c = math.sqrt(d / half_sq)
            guess = np.array([c * np.tan(K_BUCKLE) * K_BUCKLE, c * v0, v0])
        sol, info, ier, msg = fsolve(_shoot, guess, args=(d,), full_output=True, xtol=1e-12)
        if ier != 1 or np.abs(_shoot(sol, d)).max() > 1e-8:
            raise RuntimeError(f"stick-slip reference: shooting failed at delta/L = {d:.4g}: {msg}")
        guess = sol
        idx = np.where(deltas == d)[0]
        if idx.size:
            k0, h, v = sol
            end = solve_ivp(lambda t, y: [y[1], -(v * math.sin(y[0]) + h * math.cos(y[0]))], (0.0, 1.0),
                            [0.0, k0], rtol=1e-11, atol=1e-12, method="DOP853").y[0, -1]
            ratios[idx] = abs(h) / v
            angles[idx] = abs(end)
    return ratios, angles


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

    @property
    def rel_error(self) -> np.ndarray:
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(np.isfinite(self.reference) & (self.reference > 0),
                            self.critical / self.reference - 1.0, np.nan)


def run_stick_slip(mus=None, length: float = 0.1, edge_length: float = 2.5e-3, substeps: int = 800,
                   max_displacement: float = 0.6, iterations: int = 150, slide_threshold: float = 0.5,
                   baseline: float = 0.005,
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
    buckling direction; their weight is negligible against their buckling
    load, as in the reference.
    """
    from .. import GroomBuilder, RodMaterial, SolverADMM, SolverADMMConfig
    from ..colliders import PlaneCollider
    from ..config import ContactConfig

    mus = np.linspace(0.0, 0.6, 13) if mus is None else np.asarray(mus, float)
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
    ctl.gravity = (0.0, -9.81, 0.0)
    cfg = SolverADMMConfig(iterations=iterations, mode="quasistatic", w0=1.0,
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
    deltas = np.linspace(0.002, max_displacement, 300)
    ratios, angles = elastica_tip_force_ratio(deltas)
    mu_c, delta_c = reference_mu_critical(deltas, ratios, angles)
    ok = angles <= math.pi / 2
    ref = np.array([reference_critical_displacement(mu, deltas[ok], ratios[ok]) if mu < mu_c else float("nan")
                    for mu in mus])
    return StickSlipResult(mus, critical, ref, mu_c, deltas[ok], ratios[ok], seconds, substeps)


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
    ax.plot(result.ratios, result.deltas, "k-", label="elastica, tip sticks while |H| <= mu V")
    ax.axvline(result.mu_critical_reference, color="k", ls=":", lw=1,
               label=f"mu_c = {result.mu_critical_reference:.3f} (never slides above)")
    ok = np.isfinite(result.critical)
    ax.plot(result.mus[ok], result.critical[ok], "rx", ms=8, mew=2, label="taichi-hair (ADMM, f32)")
    never = ~ok
    if never.any():
        ax.plot(result.mus[never], np.full(never.sum(), result.deltas[-1]), "r^", ms=7,
                label="taichi-hair: no sliding up to 0.6 L")
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
    lines = [f"stick-slip: {len(result.mus)} friction coefficients, {result.substeps} quasistatic substeps, "
             f"{result.seconds:.1f} s; reference mu_c = {result.mu_critical_reference:.3f}",
             f"{'mu':>6} {'sim delta/L':>12} {'reference':>10} {'rel error':>10}"]
    for mu, c, r, e in zip(result.mus, result.critical, result.reference, result.rel_error):
        cs = "never" if np.isnan(c) else f"{c:.4f}"
        rs = "never" if np.isnan(r) else f"{r:.4f}"
        es = "" if np.isnan(e) else f"{100 * e:+.1f}%"
        lines.append(f"{mu:6.3f} {cs:>12} {rs:>10} {es:>10}")
    return "\n".join(lines)
