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
