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


def test_ldlt_solve6_and_the_woodbury_stretch_step_match_a_dense_float64_solve():
    """The local step's 6x6 solves against numpy's float64 solve, relative error < 1e-4 (f32): plain LDL^T of
    a random SPD matrix, and the Woodbury form (A + U C U^T)^-1 r with C ~ 1e4 A (stiff stretch) as
    elasticity.local_elasticity_at writes it: delta = A^-1 r - A^-1 U S^-1 U^T A^-1 r, S = C^-1 + U^T A^-1 U."""
    import numpy as np
    import taichi as ti

    from taichi_hair.strains import ldlt_factor6, ldlt_solve6, ldlt_substitute6

    rng = np.random.default_rng(5)
    M = rng.normal(size=(6, 6))
    A = M @ M.T + 6 * np.eye(6)
    r = rng.normal(size=6)
    U = np.zeros((6, 2))
    U[:3, 0] = rng.normal(size=3)
    U[3:, 1] = rng.normal(size=3)
    C = np.diag([3e4, 5e4])
    mat6 = ti.types.matrix(6, 6, float)
    vec6 = ti.types.vector(6, float)
    out = ti.Vector.field(6, float, 2)

    @ti.kernel
    def run(a: mat6, rhs: vec6, ua: vec6, ub: vec6, ka: float, kb: float):
        out[0] = ldlt_solve6(a, rhs)
        L, D = ldlt_factor6(a)
        a0 = ldlt_substitute6(L, D, rhs)
        ba = ldlt_substitute6(L, D, ua)
        bb = ldlt_substitute6(L, D, ub)
        saa = 1.0 / ka + ua.dot(ba)
        sbb = 1.0 / kb + ub.dot(bb)
        sab = ua.dot(bb)
        pa = ua.dot(a0)
        pb = ub.dot(a0)
        det = saa * sbb - sab * sab
        out[1] = a0 - ((sbb * pa - sab * pb) / det) * ba - ((saa * pb - sab * pa) / det) * bb

    run(mat6(A.tolist()), vec6(r.tolist()), vec6(U[:, 0].tolist()), vec6(U[:, 1].tolist()), C[0, 0], C[1, 1])
    got = out.to_numpy().astype(np.float64)
    dense = np.linalg.solve(A, r)
    stiff = np.linalg.solve(A + U @ C @ U.T, r)
    assert np.linalg.norm(got[0] - dense) < 1e-4 * np.linalg.norm(dense)
    assert np.linalg.norm(got[1] - stiff) < 1e-4 * np.linalg.norm(stiff)
