"""Stick-slip validation: the elastica references (weightless and heavy), and a reduced simulation against the
heavy one (the simulated rod has its weight: Gamma = rho g A L^3 / (E I) = 6.80 for the 10 cm hair)."""

import math

import numpy as np
import pytest
import scipy.linalg

from taichi_hair.validation.stick_slip import (K_BUCKLE, default_mus, elastica_branch, elastica_tip_force_ratio,
                                               reference_critical_displacement, reference_curve,
                                               reference_mu_critical, run_stick_slip, stick_slip_gamma)


def test_reference_matches_linear_buckling_and_gives_mu_c():
    deltas = np.linspace(0.001, 0.45, 200)
    ratios, angles = elastica_tip_force_ratio(deltas)
    # Linear regime: phi = c (tan k sin ks + cos ks - 1) with h/v = c and delta = c^2/2 int(...)^2.
    s = np.linspace(0, 1, 4001)
    mode = np.tan(K_BUCKLE) * np.sin(K_BUCKLE * s) + np.cos(K_BUCKLE * s) - 1.0
    c = math.sqrt(deltas[0] / (0.5 * np.trapezoid(mode**2, s)))
    assert abs(ratios[0] / c - 1) < 0.01
    assert np.all(np.diff(ratios) > 0) and np.all(np.diff(angles) > 0)
    mu_c, delta_c = reference_mu_critical(deltas, ratios, angles)
    # Romero et al. 2021 report mu_c ~ 0.36.
    assert abs(mu_c - 0.36) < 0.01 and 0.3 < delta_c < 0.36
    ok = angles <= math.pi / 2
    crit = [reference_critical_displacement(mu, deltas[ok], ratios[ok]) for mu in (0.1, 0.2, 0.3)]
    assert crit[0] < crit[1] < crit[2] < delta_c


def _heavy_column_buckling_load(gamma, n=800):
    """Smallest v with a non-trivial solution of the linearised heavy clamped-pinned column,
    phi'' + (v - Gamma (1 - s)) phi + h = 0, phi(0) = 0, phi'(1) = 0, int_0^1 phi = 0,
    by second-order finite differences (a generalised eigenproblem in v; unknowns phi_1..phi_n and h)."""
    ds = 1.0 / n
    s = np.linspace(0.0, 1.0, n + 1)
    a = np.zeros((n + 1, n + 1))
    b = np.zeros((n + 1, n + 1))
    for i in range(1, n + 1):
        r = i - 1
        a[r, r] = -2.0 / ds**2 - gamma * (1.0 - s[i])
        if i > 1:
            a[r, r - 1] += 1.0 / ds**2
        if i < n:
            a[r, r + 1] += 1.0 / ds**2
        else:
            a[r, r - 1] += 1.0 / ds**2  # phi'(1) = 0: ghost phi_{n+1} = phi_{n-1}
        a[r, n] = 1.0
        b[r, r] = -1.0
    a[n, :n] = ds
    a[n, n - 1] = ds / 2  # trapezoid rule, phi_0 = 0
    ev = scipy.linalg.eig(a, b, right=False)
    ev = ev[np.isfinite(ev)].real
    return float(ev[ev > 0].min())


def test_heavy_reference_starts_at_the_heavy_column_buckling_load():
    # Closed form at Gamma = 0: v = k^2 with tan k = k (20.19); with the 10 cm hair's weight (Gamma = 6.80) the
    # buckling load rises (the top of the rod is in less compression), by finite differences independent of the
    # shooting.  Tolerance 0.1 %: the FD error at n = 800 is ~1e-5 relative, the post-buckling rise of v at
    # delta = 1e-4 L is O(1e-4).
    gamma = stick_slip_gamma(0.1)
    assert gamma == pytest.approx(6.8016, rel=1e-4)  # 4 rho g L^3 / (E R^2)
    assert _heavy_column_buckling_load(0.0) == pytest.approx(K_BUCKLE**2, rel=1e-4)
    v_c = _heavy_column_buckling_load(gamma)
    assert v_c > K_BUCKLE**2 + 1.0
    params, _ = elastica_branch([1e-4], gamma)
    assert params[0, 2] == pytest.approx(v_c, rel=1e-3)


# Reduced simulation for the tests: the same 10 cm rods, step and iteration counts (measured with
# benchmarks/probes/stick_slip_resolution.py) that keep the onset within the bounds below at a fraction of
# the 800 x 150 of the full run (measured there: median 0.13 %, mu_c 0.375; 120 x 60 fails: every tip moves
# at the first substeps, before the iterate has buckled); pushed to 0.36 L, past the delta_c = 0.317 L of the reference.
SUBSTEPS, ITERATIONS, MAX_DISPLACEMENT = 240, 60, 0.36


@pytest.fixture(scope="module")
def reduced_run():
    # All friction coefficients in one Model: mu = 0.1..0.3 (step 0.05) and a 0.01-step grid over the
    # reference's mu_c +- 0.02.
    _, _, mu_c, _ = reference_curve(stick_slip_gamma(0.1), MAX_DISPLACEMENT)
    mus = default_mus(mu_c, coarse=np.arange(0.1, 0.301, 0.05))
    mus = mus[(mus <= 0.3 + 1e-9) | (np.abs(mus - np.round(mu_c, 2)) <= 0.02 + 1e-9)]
    return run_stick_slip(mus=mus, substeps=SUBSTEPS, max_displacement=MAX_DISPLACEMENT, iterations=ITERATIONS)


def test_stick_slip_onset_median_error_within_5_percent_of_heavy_elastica_for_mu_0p1_to_0p3(reduced_run):
    # Reference: the clamped-pinned heavy elastica (stick_slip.py docstring), onset = first delta with
    # |h|/v = mu.  Tolerance: median |rel error| <= 5 % over mu in {0.1, 0.15, 0.2, 0.25, 0.3}.
    r = reduced_run
    assert r.gamma == pytest.approx(6.8016, rel=1e-4)
    sel = r.mus <= 0.3 + 1e-9
    assert np.all(np.isfinite(r.critical[sel]))  # every one of them slides
    assert r.median_abs_error(0.1, 0.3) <= 0.05


def test_stick_slip_mu_c_within_0p02_of_heavy_elastica_mu_c(reduced_run):
    # Reference mu_c: |h|/v of the heavy elastica when the tip tangent turns horizontal (0.3737 at Gamma = 6.80).
    # Simulated mu_c: midpoint between the largest mu that slid and the next, which did not slide up to 0.36 L,
    # on the 0.01 grid (half-width 0.005).  Tolerance 0.02.
    r = reduced_run
    mc, half_width = r.mu_critical
    assert math.isfinite(mc) and half_width <= 0.005 + 1e-9
    assert abs(mc - r.mu_critical_reference) <= 0.02
    assert abs(r.mu_critical_reference - 0.3737) < 1e-3
