"""Finite-difference checks of the DER strain measures (both Korner and Bergou).

The checks run in double precision in a subprocess (``_derivative_worker.py``)
because the test session itself runs in single precision.  They cover: the
3x6 edge Jacobian of the strain under parallel-transported frames, the first
and second twist derivatives, the energy gradient (bending + stretching, in
edges and twists) away from rest, and the Gauss-Newton Hessian of the local
step, which must equal the true Hessian at a rest configuration.
"""

import json
import os
import subprocess
import sys

import pytest

HERE = os.path.dirname(os.path.abspath(__file__))


@pytest.fixture(scope="module")
def fd_errors():
    proc = subprocess.run([sys.executable, os.path.join(HERE, "_derivative_worker.py")], capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("measure", ["korner", "bergou"])
def test_edge_jacobian_matches_finite_differences(fd_errors, measure):
    assert fd_errors[measure]["edge_jacobian"] < 1e-6
    assert fd_errors[measure + "_at_rest"]["edge_jacobian"] < 1e-6


@pytest.mark.parametrize("measure", ["korner", "bergou"])
def test_twist_derivatives_match_finite_differences(fd_errors, measure):
    assert fd_errors[measure]["twist_jacobian"] < 1e-6
    assert fd_errors[measure]["twist_second"] < 1e-4


@pytest.mark.parametrize("measure", ["korner", "bergou"])
def test_energy_gradient_matches_finite_differences(fd_errors, measure):
    assert fd_errors[measure]["energy_gradient"] < 1e-6


@pytest.mark.parametrize("measure", ["korner", "bergou"])
def test_gauss_newton_hessian_is_exact_at_rest(fd_errors, measure):
    # At rest the residual term of the Hessian vanishes, so J^T K J + stretch = d2E/de2.
    assert fd_errors[measure + "_at_rest"]["gauss_newton_hessian"] < 1e-5
    # Away from rest it is only an approximation (the paper's Gauss-Newton step).
    assert fd_errors[measure]["gauss_newton_hessian"] > 1e-6


def test_the_local_steps_rank5_woodbury_solve_matches_a_dense_float64_solve():
    """strains.proximal_step5 against numpy's float64 solve of the local step's 6x6 system
    (w I + V E V^T) delta = -w lam - V E f, V = [J^T | (g_a, 0) | (0, g_b)]: relative error < 1e-4 (f32).
    Three cases: stiffnesses of the order of w; a stiff stretch (E_s / w ~ 4e7, past single precision's
    1.7e7, where a dense f32 LDL^T of the 6x6 matrix loses the bending part); and a zero twist stiffness."""
    import numpy as np
    import taichi as ti

    from taichi_hair.strains import mat36, proximal_step5, vec5, vec6

    rng = np.random.default_rng(5)
    out = ti.Vector.field(6, float, 3)

    @ti.kernel
    def run(k: ti.i32, J: mat36, ga: ti.math.vec3, gb: ti.math.vec3, wie: vec5, lam: vec6, f: vec5):
        out[k] = proximal_step5(J, ga, gb, wie, lam, f)

    w = 2.0
    cases = [np.array([3.0, 5.0, 1.0, 4.0, 2.0]), np.array([3.0, 5.0, 1.0, 8e7, 9e7]),
             np.array([3.0, 5.0, 0.0, 4.0, 2.0])]
    want = []
    for k, e in enumerate(cases):
        J = rng.normal(size=(3, 6))
        ga, gb = rng.normal(size=3), rng.normal(size=3)
        lam, f = rng.normal(size=6), 1e-3 * rng.normal(size=5)
        V = np.zeros((6, 5))
        V[:, :3] = J.T
        V[:3, 3] = ga
        V[3:, 4] = gb
        want.append(np.linalg.solve(w * np.eye(6) + V @ np.diag(e) @ V.T, -w * lam - V @ (e * f)))
        wie = np.minimum(w / np.maximum(e, 1e-300), 1e30)  # as local_elasticity_at writes it
        run(k, mat36(J.tolist()), ti.math.vec3(ga.tolist()), ti.math.vec3(gb.tolist()), vec5(wie.tolist()),
            vec6(lam.tolist()), vec5(f.tolist()))
    got = out.to_numpy().astype(np.float64)
    for k in range(3):
        assert np.linalg.norm(got[k] - want[k]) < 1e-4 * np.linalg.norm(want[k]), k
