"""Rotations: unit quaternions and 3x3 matrices, as Taichi functions and their host (NumPy) twins.

**One component order: (x, y, z, w)** -- the vector part first, the scalar part last, as scipy's
``Rotation.as_quat``, TressFX's ``float4`` and Eigen's ``coeffs()``.  A quaternion is a ``vec4`` in
kernels and a float64 array of shape (..., 4) on the host.  File formats that spell a quaternion
(w, x, y, z) -- a scene file's ``quaternion = [w, x, y, z]`` -- keep their order; convert at the boundary
with :func:`quat_from_wxyz` / :func:`quat_to_wxyz`.

Conventions: the Hamilton product ``a * b`` applies b first, then a; ``R(q) v = q v conj(q)``; a
matrix's columns are the rotated axes (``R e_k``).

Taichi functions (call them inside kernels; unit quaternions assumed unless said):
:func:`quat_identity`, :func:`quat_mul`, :func:`quat_conjugate`, :func:`quat_pure`,
:func:`quat_rotate`, :func:`quat_rotate_inverse`, :func:`quat_d3`, :func:`quat_between`,
:func:`quat_from_matrix`, :func:`quat_from_frame`, :func:`quat_to_matrix`, :func:`quat_slerp`.

Host twins (float64, broadcasting over leading axes): :func:`quat_mul_np`, :func:`quat_conjugate_np`,
:func:`quat_rotate_np`, :func:`quat_from_matrix_np`, :func:`quat_to_matrix_np`, :func:`quat_slerp_np`,
and :func:`euler_to_matrix`.  ``tests/test_rotation.py`` checks the twins against each other and
against scipy.
"""

import math

import numpy as np
import taichi as ti

vec3 = ti.math.vec3
vec4 = ti.math.vec4


# =========================================================================== Taichi functions
@ti.func
def quat_identity() -> vec4:
    return vec4(0.0, 0.0, 0.0, 1.0)


@ti.func
def quat_mul(a: vec4, b: vec4) -> vec4:
    """Hamilton product a * b (apply b first, then a)."""
    av = vec3(a[0], a[1], a[2])
    bv = vec3(b[0], b[1], b[2])
    v = a[3] * bv + b[3] * av + av.cross(bv)
    return vec4(v[0], v[1], v[2], a[3] * b[3] - av.dot(bv))


@ti.func
def quat_conjugate(q: vec4) -> vec4:
    return vec4(-q[0], -q[1], -q[2], q[3])


@ti.func
def quat_pure(v: vec3) -> vec4:
    """The pure quaternion (v, 0)."""
    return vec4(v[0], v[1], v[2], 0.0)


@ti.func
def quat_rotate(q: vec4, v: vec3) -> vec3:
    """R(q) v for a unit quaternion q."""
    u = vec3(q[0], q[1], q[2])
    t = 2.0 * u.cross(v)
    return v + q[3] * t + u.cross(t)


@ti.func
def quat_rotate_inverse(q: vec4, v: vec3) -> vec3:
    """R(q)^T v for a unit quaternion q."""
    return quat_rotate(quat_conjugate(q), v)


@ti.func
def quat_d3(q: vec4) -> vec3:
    """Third column R(q) e3 of a unit quaternion's matrix (the director d3 of a rod frame)."""
    x, y, z, w = q[0], q[1], q[2], q[3]
    return vec3(2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y))


@ti.func
def quat_between(a: vec3, b: vec3) -> vec4:
    """Shortest-arc rotation taking unit vector a to unit vector b.

    For b = -a (the arc is not unique) it turns by pi about an axis perpendicular to a.
    """
    d = a.dot(b)
    q = quat_identity()
    if d < -1.0 + 1e-6:
        axis = a.cross(vec3(1.0, 0.0, 0.0))
        if axis.norm_sqr() < 1e-6:
            axis = a.cross(vec3(0.0, 1.0, 0.0))
        axis = axis.normalized()
        q = vec4(axis[0], axis[1], axis[2], 0.0)
    else:
        c = a.cross(b)
        q = vec4(c[0], c[1], c[2], 1.0 + d).normalized()
    return q


@ti.func
def quat_from_matrix(r) -> vec4:
    """Unit quaternion of a 3x3 rotation matrix (Shepperd's method: divide by the largest term)."""
    tr = r[0, 0] + r[1, 1] + r[2, 2]
    q = quat_identity()
    if tr > 0.0:
        s = 2.0 * ti.sqrt(tr + 1.0)  # 4 w
        q = vec4((r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s, 0.25 * s)
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        s = 2.0 * ti.sqrt(ti.max(1.0 + r[0, 0] - r[1, 1] - r[2, 2], 1e-12))  # 4 x
        q = vec4(0.25 * s, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s, (r[2, 1] - r[1, 2]) / s)
    elif r[1, 1] > r[2, 2]:
        s = 2.0 * ti.sqrt(ti.max(1.0 + r[1, 1] - r[0, 0] - r[2, 2], 1e-12))  # 4 y
        q = vec4((r[0, 1] + r[1, 0]) / s, 0.25 * s, (r[1, 2] + r[2, 1]) / s, (r[0, 2] - r[2, 0]) / s)
    else:
        s = 2.0 * ti.sqrt(ti.max(1.0 + r[2, 2] - r[0, 0] - r[1, 1], 1e-12))  # 4 z
        q = vec4((r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, 0.25 * s, (r[1, 0] - r[0, 1]) / s)
    return q.normalized()


@ti.func
def quat_from_frame(d1: vec3, d2: vec3, d3: vec3) -> vec4:
    """Quaternion of the frame whose columns are (d1, d2, d3)."""
    return quat_from_matrix(ti.Matrix.cols([d1, d2, d3]))


@ti.func
def quat_to_matrix(q: vec4):
    """3x3 rotation matrix of a unit quaternion (its columns are the rotated axes)."""
    return ti.Matrix.cols([quat_rotate(q, vec3(1.0, 0.0, 0.0)), quat_rotate(q, vec3(0.0, 1.0, 0.0)),
                           quat_rotate(q, vec3(0.0, 0.0, 1.0))])


@ti.func
def quat_slerp(a: vec4, b: vec4, u: float) -> vec4:
    """Spherical interpolation from unit quaternion a (u = 0) to b (u = 1), along the shorter arc."""
    d = a.dot(b)
    bb = b
    if d < 0.0:
        bb = -b
        d = -d
    out = bb
    if d > 0.9995:  # nearly equal: linear interpolation, renormalised
        out = (a + u * (bb - a)).normalized()
    else:
        theta = ti.acos(ti.min(d, 1.0))
        out = ((ti.sin((1.0 - u) * theta) * a + ti.sin(u * theta) * bb) / ti.sin(theta)).normalized()
    return out


# =========================================================================== host twins (NumPy, float64)
def quat_from_wxyz(q) -> np.ndarray:
    """(w, x, y, z) -> (x, y, z, w), for file formats that write the scalar first."""
    q = np.asarray(q, np.float64)
    return np.concatenate([q[..., 1:], q[..., :1]], axis=-1)


def quat_to_wxyz(q) -> np.ndarray:
    """(x, y, z, w) -> (w, x, y, z)."""
    q = np.asarray(q, np.float64)
    return np.concatenate([q[..., 3:], q[..., :3]], axis=-1)


def quat_mul_np(a, b) -> np.ndarray:
    """Hamilton product a * b, shapes (..., 4)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    av, aw, bv, bw = a[..., :3], a[..., 3:], b[..., :3], b[..., 3:]
    v = aw * bv + bw * av + np.cross(av, bv)
    w = aw[..., 0] * bw[..., 0] - np.sum(av * bv, axis=-1)
    return np.concatenate([v, w[..., None]], axis=-1)


def quat_conjugate_np(q) -> np.ndarray:
    return np.asarray(q, np.float64) * np.array([-1.0, -1.0, -1.0, 1.0])


def quat_rotate_np(q, v) -> np.ndarray:
    """R(q) v for unit quaternions q (..., 4) and vectors v (..., 3)."""
    q, v = np.asarray(q, np.float64), np.asarray(v, np.float64)
    u = q[..., :3]
    t = 2.0 * np.cross(u, v)
    return v + q[..., 3:] * t + np.cross(u, t)


def quat_to_matrix_np(q) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of quaternions (..., 4); q is normalised first."""
    q = np.asarray(q, np.float64)
    q = q / np.linalg.norm(q) if q.ndim == 1 else q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    rows = [[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def quat_from_matrix_np(R) -> np.ndarray:
    """Unit quaternions (..., 4) of rotation matrices (..., 3, 3) (Shepperd's method).

    Where the trace is not positive it divides by the largest diagonal term (the first of equal ones).
    """
    R = np.asarray(R, np.float64)
    lead = R.shape[:-2]
    R = R.reshape(-1, 3, 3)
    n = R.shape[0]
    tr = R[:, 0, 0] + R[:, 1, 1] + R[:, 2, 2]
    wxyz = np.zeros((n, 4))
    pos = tr > 0
    s = 2 * np.sqrt(np.where(pos, tr, 0.0) + 1)
    wxyz[pos] = np.stack([0.25 * s, (R[:, 2, 1] - R[:, 1, 2]) / s, (R[:, 0, 2] - R[:, 2, 0]) / s,
                          (R[:, 1, 0] - R[:, 0, 1]) / s], axis=1)[pos]
    rest = np.nonzero(~pos)[0]
    if rest.size:
        diag = R[rest][:, [0, 1, 2], [0, 1, 2]]
        i = np.argmax(diag, axis=1)
        j, k = (i + 1) % 3, (i + 2) % 3
        m = R[rest]
        r = np.arange(rest.size)
        s = 2 * np.sqrt(1 + m[r, i, i] - m[r, j, j] - m[r, k, k])
        q = np.zeros((rest.size, 4))
        q[r, 0] = (m[r, k, j] - m[r, j, k]) / s
        q[r, 1 + i] = 0.25 * s
        q[r, 1 + j] = (m[r, j, i] + m[r, i, j]) / s
        q[r, 1 + k] = (m[r, k, i] + m[r, i, k]) / s
        wxyz[rest] = q
    if not lead:  # one matrix: normalised as a vector (the scene files' keys have always been)
        wxyz = wxyz[0] / np.linalg.norm(wxyz[0])
    else:
        wxyz = (wxyz / np.linalg.norm(wxyz, axis=1, keepdims=True)).reshape(lead + (4,))
    return quat_from_wxyz(wxyz)


def quat_slerp_np(a, b, u: float) -> np.ndarray:
    """Spherical interpolation of unit quaternions (..., 4) from a (u = 0) to b (u = 1), shorter arc."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    d = np.sum(a * b, axis=-1, keepdims=True)
    b = np.where(d < 0, -b, b)
    d = np.abs(d)
    near = d > 0.9995
    lin = a + u * (b - a)
    lin = lin / np.linalg.norm(lin, axis=-1, keepdims=True)
    th = np.arccos(np.minimum(d, 1.0))
    sin_th = np.where(near, 1.0, np.sin(th))
    arc = (np.sin((1 - u) * th) * a + np.sin(u * th) * b) / sin_th
    return np.where(near, lin, arc)


def euler_to_matrix(euler_deg) -> np.ndarray:
    """R = Rz(z) Ry(y) Rx(x) for ``euler_deg = (x, y, z)`` [deg]."""
    x, y, z = (math.radians(a) for a in euler_deg)
    cx, sx, cy, sy, cz, sz = math.cos(x), math.sin(x), math.cos(y), math.sin(y), math.cos(z), math.sin(z)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx
