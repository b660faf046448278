"""Bend-twist validation: the PCA classifier on analytic shapes, the linear-stability reference against
closed forms, and a small simulated grid against the reference away from the threshold."""

import math

import numpy as np
import pytest

from taichi_hair.validation.bend_twist import (BendTwistConfig, arc_points, gamma_of, gravito_bending_length,
                                               is_planar, out_of_plane_min_eigenvalues, planar_equilibrium,
                                               planar_reference, planarity_ratio, run_bend_twist)


def helix(radius, pitch, turns, n=20001):
    t = np.linspace(0.0, 2 * math.pi * turns, n)
    return np.c_[radius * np.cos(t), radius * np.sin(t), pitch * t / (2 * math.pi)]


def test_classifier_on_analytic_shapes():
    # A planar arc of many turns, turned into a general plane: ratio at round-off level.
    arc = arc_points(50.0, 3.0, 2000)
    Q, _ = np.linalg.qr(np.random.default_rng(0).normal(size=(3, 3)))
    assert planarity_ratio(arc @ Q.T + 0.3) < 1e-12
    assert is_planar(arc @ Q.T)
    # Helix (r cos t, r sin t, p t / 2 pi) over n whole turns: its covariance in closed form is
    # [[r^2/2, 0, 0], [0, r^2/2, -r p / 2 pi], [0, -r p / 2 pi, (n p)^2 / 12]] (from int t sin t = -2 pi n).
    for r, p, turns in ((0.01, 0.05, 4), (0.005, 0.002, 10), (0.02, 0.3, 3)):
        C = np.array([[r * r / 2, 0, 0], [0, r * r / 2, -r * p / (2 * math.pi)],
                      [0, -r * p / (2 * math.pi), (turns * p) ** 2 / 12]])
        ev = np.linalg.eigvalsh(C)
        expected = ev[0] / np.mean(ev)
        assert planarity_ratio(helix(r, p, turns)) == pytest.approx(expected, rel=2e-3)
        assert not is_planar(helix(r, p, turns))
    # A localised helix at the end of a long straight part (what long rods do) is still caught at 1e-4.
    straight = np.c_[np.zeros(400), -np.linspace(0, 2.0, 400), np.zeros(400)]
    tail = helix(0.01, 0.02, 3, 300)[:, [0, 2, 1]] * [1, -1, 1] + [0, -2.0, 0]
    assert 1e-4 < planarity_ratio(np.r_[straight, tail]) < 1e-2
    with pytest.raises(ValueError, match="points must have shape"):
        planarity_ratio(np.zeros((5, 2)))
    with pytest.raises(ValueError, match="threshold"):
        is_planar(arc, threshold=2.0)


def test_reference_nearly_straight_rod_has_the_free_twist_mode():
    # phi -> 0: the hanging rod is straight; out of plane, the softest mode is the clamped-free twist
    # mode, c (pi/2)^2 in units of EI/L (c = GJ/EI = 1/(1+nu)), whatever the weight.  Discretely: a
    # chain of n = N - 1 free frames joined by twist springs c/h (the first to the clamp), whose lowest
    # Hessian eigenvalue is (c/h) 4 sin^2(pi / (4n + 2)).
    N = 200
    c = 1 / 1.45
    lam = out_of_plane_min_eigenvalues(1e-4, [1e-2, 1.0, 1e2, 1e4], segments=N)
    exact = c * N * 4 * math.sin(math.pi / (4 * (N - 1) + 2)) ** 2
    assert np.allclose(lam, exact, rtol=1e-4)
    assert lam[0] * N == pytest.approx(c * math.pi**2 / 4, rel=1e-2)  # the continuum value


def test_reference_planar_equilibrium_is_the_heavy_curl():
    # Gamma = 0: the rest arc; a heavy rod is pulled towards the vertical (theta smaller near the root).
    theta0 = planar_equilibrium(2 * math.pi, 0.0, 100)
    assert np.allclose(theta0, 2 * math.pi * np.arange(100) / 100)
    theta = planar_equilibrium(2 * math.pi, 50.0, 100)
    assert np.all(np.abs(theta[1:50]) < theta0[1:50])
    # Stationary: the discrete Euler-Lagrange residual vanishes.
    h = 0.01
    W = 50.0 * (1 - (np.arange(100) + 0.5) * h) * h
    d = np.diff(theta) / h - 2 * math.pi
    grad = W * np.sin(theta)
    grad[1:] += d
    grad[:-1] -= d
    assert np.max(np.abs(grad[1:])) < 1e-8


def test_reference_is_converged_in_the_discretisation_and_has_both_phases():
    phi = 5 * math.pi
    gammas = [1.0, 100.0, 1e4]
    a = out_of_plane_min_eigenvalues(phi, gammas, segments=200) * 200
    b = out_of_plane_min_eigenvalues(phi, gammas, segments=400) * 400
    assert np.allclose(a, b, rtol=0.02)
    # Short (light) curl: planar; heavier: the planar curl is unstable; much heavier (the rod hangs
    # nearly straight, weakly curved against gravity): planar again.
    assert a[0] > 0 and a[1] < 0 and a[2] > 0
    assert gravito_bending_length() == pytest.approx(0.0528, rel=1e-2)


def test_small_grid_matches_the_reference_away_from_the_threshold():
    # Two rods well inside the planar region, two well inside the non-planar one (see the reference
    # map in benchmarks/results/bend_twist): (kappa [1/m], phi).
    rods = [(150.0, math.pi), (20.0, 3 * math.pi), (70.0, 10 * math.pi), (50.0, 6 * math.pi)]
    k = np.array([r[0] for r in rods])
    L = np.array([r[1] for r in rods]) / k
    ref = planar_reference(k, L)
    assert list(ref) == [True, True, False, False]
    assert np.all(gamma_of(L) > 0)
    r = run_bend_twist(k, L, BendTwistConfig(steps=1500, iterations=30, max_edges=80))
    assert list(r.planar) == list(ref), r.ratios
    assert np.all(r.ratios[ref] < 1e-6) and np.all(r.ratios[~ref] > 1e-3)


def test_reference_stiffer_twist_stabilises_the_planar_curl():
    # Leaving the plane needs the rod to twist: the softest out-of-plane mode stiffens monotonically with
    # GJ/EI = 1/(1 + nu), and at phi = 5 pi, Gamma = 100 the curl that is unstable for hair (nu = 0.45)
    # becomes stable for a twist-stiff rod.
    lam = [out_of_plane_min_eigenvalues(5 * math.pi, [100.0], poisson_ratio=nu)[0] for nu in (0.45, 0.0, -0.5, -0.9)]
    assert np.all(np.diff(lam) > 0)
    assert lam[0] < 0 < lam[-1]
