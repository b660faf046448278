"""taichi_hair.rotation: the Taichi functions against their host twins and against scipy, on random rotations.

Order (x, y, z, w) everywhere, as scipy's ``Rotation.as_quat``.  Quaternions are compared up to sign
(q and -q are the same rotation).  Tolerances: the Taichi side runs in single precision (conftest), so
1e-6 on unit quantities (a few float32 ulps; measured errors are ~3e-7); the host twins are float64
and agree with scipy to 1e-12.
"""

import numpy as np
import pytest
import taichi as ti
from scipy.spatial.transform import Rotation

from taichi_hair import rotation as rot

K = 64
F32 = 1e-6
F64 = 1e-12


def _rotations(seed=0):
    R = Rotation.random(K, random_state=seed).as_matrix()
    # Every branch of Shepperd's method: pi about x, y, z (trace -1), and the identity.
    R[:4] = [np.diag([1.0, -1, -1]), np.diag([-1.0, 1, -1]), np.diag([-1.0, -1, 1]), np.eye(3)]
    return R


def _same_rotation(a, b, atol):
    """Quaternions equal up to sign, row by row."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    sign = np.where(np.sum(a * b, axis=-1, keepdims=True) < 0, -1.0, 1.0)
    np.testing.assert_allclose(a, sign * b, atol=atol)


class Scratch:
    def __init__(self):
        self.mat = ti.Matrix.field(3, 3, float, K)
        self.mat_out = ti.Matrix.field(3, 3, float, K)
        self.qa = ti.Vector.field(4, float, K)
        self.qb = ti.Vector.field(4, float, K)
        self.q_out = ti.Vector.field(4, float, K)
        self.q_mul = ti.Vector.field(4, float, K)
        self.q_slerp = ti.Vector.field(4, float, (K, 3))
        self.v = ti.Vector.field(3, float, K)
        self.v_rot = ti.Vector.field(3, float, K)
        self.v_inv = ti.Vector.field(3, float, K)
        self.d3 = ti.Vector.field(3, float, K)


@ti.kernel
def _evaluate(f: ti.template()):
    for k in range(K):
        q = rot.quat_from_matrix(f.mat[k])
        f.q_out[k] = q
        f.mat_out[k] = rot.quat_to_matrix(q)
        f.q_mul[k] = rot.quat_mul(f.qa[k], f.qb[k])
        f.v_rot[k] = rot.quat_rotate(f.qa[k], f.v[k])
        f.v_inv[k] = rot.quat_rotate_inverse(f.qa[k], f.v[k])
        f.d3[k] = rot.quat_d3(f.qa[k])
        f.q_slerp[k, 0] = rot.quat_slerp(f.qa[k], f.qb[k], 0.0)
        f.q_slerp[k, 1] = rot.quat_slerp(f.qa[k], f.qb[k], 0.5)
        f.q_slerp[k, 2] = rot.quat_slerp(f.qa[k], f.qb[k], 1.0)


@pytest.fixture(scope="module")
def evaluated():
    R = _rotations(0)
    qa = Rotation.random(K, random_state=1).as_quat()
    qb = Rotation.random(K, random_state=2).as_quat()
    qb[0] = -qa[0]  # the same rotation, opposite sign: slerp takes the short way (no motion)
    qb[1] = qa[1]
    v = np.random.default_rng(3).normal(size=(K, 3))
    f = Scratch()
    f.mat.from_numpy(R.astype(np.float32))
    f.qa.from_numpy(qa.astype(np.float32))
    f.qb.from_numpy(qb.astype(np.float32))
    f.v.from_numpy(v.astype(np.float32))
    _evaluate(f)
    out = {k: getattr(f, k).to_numpy().astype(np.float64) for k in
           ("q_out", "mat_out", "q_mul", "v_rot", "v_inv", "d3", "q_slerp")}
    return R, qa, qb, v, out


def test_host_twins_match_scipy():
    R = _rotations(0)
    q = rot.quat_from_matrix_np(R)
    assert q.shape == (K, 4)
    _same_rotation(q, Rotation.from_matrix(R).as_quat(), F64)
    np.testing.assert_allclose(rot.quat_to_matrix_np(q), R, atol=F64)
    for k in range(8):  # one matrix at a time: the same quaternion as the batch
        _same_rotation(rot.quat_from_matrix_np(R[k]), q[k], F64)
    a = Rotation.random(K, random_state=1)
    b = Rotation.random(K, random_state=2)
    _same_rotation(rot.quat_mul_np(a.as_quat(), b.as_quat()), (a * b).as_quat(), F64)
    _same_rotation(rot.quat_conjugate_np(a.as_quat()), a.inv().as_quat(), F64)
    v = np.random.default_rng(3).normal(size=(K, 3))
    np.testing.assert_allclose(rot.quat_rotate_np(a.as_quat(), v), a.apply(v), atol=F64)
    # slerp: the endpoints, and halfway is the half rotation from a to b (scipy's Slerp, per pair).
    qa, qb = a.as_quat(), b.as_quat()
    _same_rotation(rot.quat_slerp_np(qa, qb, 0.0), qa, F64)
    _same_rotation(rot.quat_slerp_np(qa, qb, 1.0), qb, F64)
    half = (a * Rotation.from_rotvec(0.5 * (a.inv() * b).as_rotvec())).as_quat()
    _same_rotation(rot.quat_slerp_np(qa, qb, 0.5), half, 1e-9)
    # Euler angles: R = Rz(z) Ry(y) Rx(x), scipy's extrinsic "xyz".
    e = np.array([10.0, -35.0, 120.0])
    np.testing.assert_allclose(rot.euler_to_matrix(e), Rotation.from_euler("xyz", e, degrees=True).as_matrix(),
                               atol=F64)
    # The file-format boundary: (w, x, y, z) <-> (x, y, z, w).
    assert np.array_equal(rot.quat_to_wxyz(rot.quat_from_wxyz([1.0, 2.0, 3.0, 4.0])), [1.0, 2.0, 3.0, 4.0])
    assert np.array_equal(rot.quat_from_wxyz([1.0, 2.0, 3.0, 4.0]), [2.0, 3.0, 4.0, 1.0])


def test_taichi_from_matrix_to_matrix_round_trip(evaluated):
    R, _, _, _, out = evaluated
    _same_rotation(out["q_out"], rot.quat_from_matrix_np(R), F32)
    _same_rotation(out["q_out"], Rotation.from_matrix(R).as_quat(), F32)
    np.testing.assert_allclose(out["mat_out"], R, atol=F32)


def test_taichi_mul_rotate_d3_match_the_twins_and_scipy(evaluated):
    _, qa, qb, v, out = evaluated
    qa32, qb32 = qa.astype(np.float32).astype(np.float64), qb.astype(np.float32).astype(np.float64)
    np.testing.assert_allclose(out["q_mul"], rot.quat_mul_np(qa32, qb32), atol=F32)
    _same_rotation(out["q_mul"], (Rotation.from_quat(qa) * Rotation.from_quat(qb)).as_quat(), F32)
    scale = np.linalg.norm(v, axis=1, keepdims=True)
    np.testing.assert_allclose(out["v_rot"] / scale, Rotation.from_quat(qa).apply(v) / scale, atol=F32)
    np.testing.assert_allclose(out["v_rot"] / scale, rot.quat_rotate_np(qa32, v.astype(np.float32)) / scale, atol=F32)
    np.testing.assert_allclose(out["v_inv"] / scale, Rotation.from_quat(qa).inv().apply(v) / scale, atol=F32)
    np.testing.assert_allclose(out["d3"], Rotation.from_quat(qa).as_matrix()[:, :, 2], atol=F32)


def test_taichi_slerp_endpoints_and_halfway(evaluated):
    _, qa, qb, _, out = evaluated
    s = out["q_slerp"]
    _same_rotation(s[:, 0], qa, F32)
    _same_rotation(s[:, 2], qb, F32)
    _same_rotation(s[:, 1], rot.quat_slerp_np(qa, qb, 0.5), F32)
    np.testing.assert_allclose(np.linalg.norm(s, axis=2), 1.0, atol=F32)
    _same_rotation(s[0, 1], qa[0], F32)  # b = -a: the short way does not move
