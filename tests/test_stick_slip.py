"""Stick-slip validation: the elastica reference, and a reduced simulation."""

import math

import numpy as np

from taichi_hair.validation.stick_slip import (K_BUCKLE, elastica_tip_force_ratio, reference_critical_displacement,
                                               reference_mu_critical, run_stick_slip)


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


def test_reduced_stick_slip_simulation_slides_below_mu_c_and_sticks_above():
    r = run_stick_slip(mus=[0.1, 0.6], substeps=160, max_displacement=0.3, iterations=60)
    assert math.isnan(r.critical[1])                      # mu above mu_c: never slides
    assert np.isfinite(r.critical[0])                     # mu = 0.1 slides ...
    assert abs(r.critical[0] / r.reference[0] - 1) < 0.35  # ... near the elastica prediction (0.047 L)
