"""Tests of the heavy-elastica reference (Romero et al. 2021 cantilever experiment).

The reference lives in ``taichi_hair/validation/elastica.py`` and uses numpy and
scipy only; these tests do not need Taichi.
"""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import numpy as np
import pytest


def _load_elastica():
    """Load the reference module from its file, without importing ``taichi_hair``.

    ``import taichi_hair`` imports Taichi and the whole simulator; the reference
    is meant to be independent of both (numpy + scipy only), so these tests must
    neither need Taichi nor break when the simulator does.
    """
    path = Path(__file__).resolve().parents[1] / "taichi_hair" / "validation" / "elastica.py"
    spec = importlib.util.spec_from_file_location("_elastica_reference", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up in sys.modules
    spec.loader.exec_module(module)
    return module


el = _load_elastica()


# --------------------------------------------------------------------------
# Small-Gamma limit: linear (Euler-Bernoulli) cantilever under uniform load
# --------------------------------------------------------------------------
@pytest.mark.parametrize("gamma", [1e-4, 1e-3])
def test_small_gamma_limit_h_over_w(gamma):
    # Tip deflection q L^4 / (8 E I)  =>  H/W -> Gamma/8, correction O(Gamma^2).
    sol = el.solve_heavy_elastica(gamma)
    assert sol.h_over_w == pytest.approx(gamma / 8.0, rel=1e-3)
    assert sol.h_over_w == pytest.approx(gamma / 8.0, rel=1e-6)


@pytest.mark.parametrize("gamma", [1e-4, 1e-3])
def test_small_gamma_root_curvature_and_tip_angle(gamma):
    # Root moment q L^2 / 2  =>  theta'(0) = Gamma/2; slope at the tip q L^3/(6 E I).
    sol = el.solve_heavy_elastica(gamma)
    assert sol.root_curvature == pytest.approx(gamma / 2.0, rel=1e-6)
    assert sol.tip_angle == pytest.approx(gamma / 6.0, rel=1e-6)
    # It bends downwards: z <= 0, theta increasing.
    assert np.all(sol.z <= 0.0)
    assert np.all(np.diff(sol.theta) > 0.0)


def test_zero_gamma_is_straight_and_negative_rejected():
    sol = el.solve_heavy_elastica(0.0)
    assert sol.h_over_w == 0.0
    np.testing.assert_allclose(sol.x, sol.s, atol=1e-14)
    np.testing.assert_allclose(sol.z, 0.0, atol=1e-14)
    with pytest.raises(ValueError):
        el.solve_heavy_elastica(-1.0)
    with pytest.raises(ValueError):
        el.heavy_elastica_h_over_w([1.0, float("nan")])


# --------------------------------------------------------------------------
# The returned solution satisfies the equations it claims to
# --------------------------------------------------------------------------
@pytest.mark.parametrize("gamma", [1e-2, 1.0, 10.0, 100.0, 1e3])
def test_ode_residual_small(gamma):
    # Finite-difference residual of theta'' + Gamma (1 - s) cos theta = 0 on the
    # uniform samples (h = 5e-4); the FD error is O(h^2 theta'''') ~ 4e-5 (1 + Gamma)
    # at Gamma = 1e3, the solution error itself is ~1e-12.
    sol = el.solve_heavy_elastica(gamma)
    assert el.heavy_elastica_residual(sol) < 1e-4
    assert sol.theta[0] == pytest.approx(0.0, abs=1e-13)           # clamp
    k = np.gradient(sol.theta, sol.s, edge_order=2)
    assert abs(k[-1]) < 1e-5 * (1.0 + gamma)                      # free end: no moment


@pytest.mark.parametrize("gamma", [0.3, 5.0, 50.0])
def test_moment_balance_integral_form(gamma):
    # Independent of the sign bookkeeping of the ODE: the bending moment
    # E I theta'(s) must equal the weight moment of the overhang, eq. (2):
    # theta'(sigma) = Gamma * int_sigma^1 (x(t) - x(sigma)) dt.
    sol = el.solve_heavy_elastica(gamma, n_points=4001)
    s, x = sol.s, sol.x
    h = s[1] - s[0]
    # int_sigma^1 x dt by cumulative trapezoid from the tip.
    seg = 0.5 * h * (x[1:] + x[:-1])
    tail = np.concatenate([np.cumsum(seg[::-1])[::-1], [0.0]])
    moment = gamma * (tail - (1.0 - s) * x)
    curvature = np.gradient(sol.theta, s, edge_order=2)
    scale = np.max(np.abs(curvature))
    np.testing.assert_allclose(curvature, moment, atol=1e-5 * scale)
    assert sol.root_curvature == pytest.approx(moment[0], rel=1e-5)


@pytest.mark.parametrize("gamma, n_points", [(1e-2, 2001), (1.0, 2001), (100.0, 2001),
                                             (1e3, 2001), (1e4, 20001)])
def test_arc_length_preserved(gamma, n_points):
    # Inextensible: the polyline through (x, z) has length 1 (L) up to the chord
    # deficit sum(kappa^2 h^3 / 24), which needs a finer sampling at 1e4 where
    # the root curvature is ~140.
    sol = el.solve_heavy_elastica(gamma, n_points=n_points)
    length = np.sum(np.hypot(np.diff(sol.x), np.diff(sol.z)))
    assert length == pytest.approx(1.0, abs=1e-6)
    assert sol.x[-1] == pytest.approx(sol.width, abs=1e-13)
    assert -sol.z[-1] == pytest.approx(sol.height, abs=1e-13)
    assert sol.h_over_w == pytest.approx(sol.height / sol.width, rel=1e-14)


# --------------------------------------------------------------------------
# Two independent methods agree
# --------------------------------------------------------------------------
@pytest.mark.parametrize("gamma", [1e-3, 0.1, 1.0, 10.0, 100.0, 1e3, 1e4, 1.4e4, 1e5])
def test_collocation_agrees_with_shooting(gamma):
    ref = el.solve_heavy_elastica(gamma)
    shot = el.solve_heavy_elastica_shooting(gamma)
    assert ref.h_over_w == pytest.approx(shot.h_over_w, rel=1e-6)
    assert ref.root_curvature == pytest.approx(shot.root_curvature, rel=1e-6)
    assert ref.tip_angle == pytest.approx(shot.tip_angle, abs=1e-8)


@pytest.mark.parametrize("gamma", [1.0, 1e3])
def test_collocation_agrees_with_scipy_solve_bvp(gamma):
    # A third, library method (4th-order collocation with mesh refinement),
    # reached by continuation from the linear solution.
    from scipy.integrate import solve_bvp

    def fun(s, y, g):
        return np.vstack([y[1], -g * (1.0 - s) * np.cos(y[0])])

    def bc(ya, yb):
        return np.array([ya[0], yb[1]])

    mesh = np.linspace(0.0, 1.0, 201)
    y = np.vstack([(1.0 - (1.0 - mesh) ** 3) / 6.0 * 1e-2, (1.0 - mesh) ** 2 / 2.0 * 1e-2])
    for g in np.geomspace(1e-2, gamma, 12):
        res = solve_bvp(lambda s, yy: fun(s, yy, g), bc, mesh, y, tol=1e-9, max_nodes=200000)
        assert res.success, res.message
        mesh, y = res.x, res.y
    s = np.linspace(0.0, 1.0, 20001)
    th = res.sol(s)[0]
    w = np.trapezoid(np.cos(th), s) if hasattr(np, "trapezoid") else np.trapz(np.cos(th), s)
    hgt = np.trapezoid(np.sin(th), s) if hasattr(np, "trapezoid") else np.trapz(np.sin(th), s)
    ref = el.solve_heavy_elastica(gamma)
    assert ref.h_over_w == pytest.approx(hgt / w, rel=1e-5)
    assert ref.root_curvature == pytest.approx(res.y[1, 0], rel=1e-5)


# --------------------------------------------------------------------------
# Global behaviour of the master curve
# --------------------------------------------------------------------------
def test_h_over_w_monotone_in_gamma():
    gammas = np.geomspace(1e-3, 1e5, 81)
    hw = el.heavy_elastica_h_over_w(gammas)
    assert np.all(np.isfinite(hw))
    assert np.all(np.diff(hw) > 0.0)


@pytest.mark.parametrize("gamma", [1e3, 1e4, 1e5])
def test_large_gamma_hangs_vertically(gamma):
    sol = el.solve_heavy_elastica(gamma)
    # Away from the root layer (width ~ Gamma^-1/2) the rod is vertical: the tip
    # angle from the vertical is ~exp(-2/3 sqrt(Gamma)).
    assert sol.tip_angle == pytest.approx(math.pi / 2.0, abs=1e-6)
    assert sol.height == pytest.approx(1.0, abs=3.0 / math.sqrt(gamma))
    # Root boundary layer: phi'' = Gamma sin(phi) has the first integral
    # phi'^2 = 2 Gamma (1 - cos phi), which gives theta'(0) -> sqrt(2 Gamma) and
    # W -> int_0^{pi/2} sin(phi) dphi / |phi'| = sqrt(2 / Gamma), i.e.
    # H/W -> sqrt(Gamma / 2), both with O(Gamma^-1/2) relative corrections.
    assert sol.root_curvature == pytest.approx(math.sqrt(2.0 * gamma), rel=3.0 / math.sqrt(gamma))
    assert sol.h_over_w == pytest.approx(math.sqrt(gamma / 2.0), rel=3.0 / math.sqrt(gamma))


def test_vectorised_matches_scalar():
    # (No time limit: it failed at 12.8 s against 5 s with a heavy job beside the suite; speed belongs in benchmarks.)
    gammas = np.geomspace(1e-3, 1.4e4, 100)
    hw = el.heavy_elastica_h_over_w(gammas)
    assert hw.shape == gammas.shape
    for i in (0, 37, 99):
        assert hw[i] == pytest.approx(el.solve_heavy_elastica(gammas[i]).h_over_w, rel=1e-10)
    # Any order, any shape, duplicates and Gamma = 0.
    grid = np.array([[10.0, 1e-3], [0.0, 10.0]])
    out = el.heavy_elastica_h_over_w(grid)
    assert out.shape == (2, 2)
    assert out[1, 0] == 0.0
    assert out[0, 0] == out[1, 1] == pytest.approx(el.solve_heavy_elastica(10.0).h_over_w, rel=1e-10)
    assert out[0, 1] == pytest.approx(1e-3 / 8.0, rel=1e-6)


# --------------------------------------------------------------------------
# Physical parameters -> Gamma
# --------------------------------------------------------------------------
@pytest.mark.parametrize("length, magnitude", [(0.005, 1e-3), (1.28, 1.4e4)])
def test_cantilever_gamma_hair(length, magnitude):
    radius, rho, young, g = 0.05e-3, 1300.0, 3.0e9, 9.81
    area = math.pi * radius**2
    inertia = math.pi * radius**4 / 4.0
    expected = rho * g * area * length**3 / (young * inertia)
    gamma = el.cantilever_gamma(length, radius, rho, young, gravity=g)
    assert gamma == pytest.approx(expected, rel=1e-12)
    assert gamma == pytest.approx(4.0 * rho * g * length**3 / (young * radius**2), rel=1e-12)
    # The Gamma range spanned by the simulator test (Romero et al. 2021, Fig. of
    # the cantilever): ~1e-3 for 0.5 cm, ~1.4e4 for 128 cm of human hair.
    assert gamma == pytest.approx(magnitude, rel=0.2)


def test_cantilever_gamma_elliptic_and_validation():
    radius, l = 0.05e-3, 0.2
    # Semi-axes (1 +- l) R (RodMaterial convention); soft-direction bending:
    # A = pi R^2 (1 - l^2), I = A R^2 (1 - l)^2 / 4.
    area = math.pi * radius**2 * (1 - l * l)
    inertia = math.pi * ((1 + l) * radius) * ((1 - l) * radius) ** 3 / 4.0
    expected = 1300.0 * 9.81 * area * 0.1**3 / (3e9 * inertia)
    assert el.cantilever_gamma(0.1, radius, 1300.0, 3e9, ellipticity=l) == pytest.approx(expected, rel=1e-12)
    with pytest.raises(ValueError):
        el.cantilever_gamma(0.1, radius, 1300.0, 3e9, ellipticity=1.0)
    with pytest.raises(ValueError):
        el.cantilever_gamma(-0.1, radius, 1300.0, 3e9)
