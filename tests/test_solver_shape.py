"""SolverShape (Han & Harada 2012) on Taichi's CPU arch, single precision.

The math ``ti.func``s are checked alone against closed forms; the solver against
the paper's limit cases (S_G = 1 freezes a strand, Sec. 3.3; many local iterations
converge to the rest shape whatever the transform method, Sec. 3.4 and 4.2) and
against simple invariants (roots follow the head exactly, no penetration after the
collision stage, velocities are (x - x^t)/dt, identical runs give identical bits).
"""

import math

import numpy as np
import pytest
import taichi as ti

from taichi_hair import GroomBuilder, SimulationDivergedError
from taichi_hair import shape_constraints as sc
from taichi_hair.solver_shape import (ShapeCapsuleCollider, ShapeRegion, ShapeSphereCollider, SolverShape,
                                      SolverShapeConfig)

DT = 1.0 / 60.0


def curly(n=16, length=0.2, radius=0.02, pitch=0.06, origin=(0.0, 0.0, 0.0), phase=0.0):
    """A helix hanging along -y from ``origin``; the curl ramps in over the first fifth."""
    s = np.linspace(0.0, length, n)
    r = radius * np.minimum(1.0, s / (0.2 * length))
    ang = 2 * np.pi * s / pitch + phase
    pts = np.c_[r * np.cos(ang), -s, r * np.sin(ang)]
    return pts - pts[0] + np.asarray(origin, float)


def straight(n=11, length=0.2, direction=(1.0, 0.0, 0.0), origin=(0.0, 0.0, 0.0)):
    return np.asarray(origin, float) + np.linspace(0.0, length, n)[:, None] * np.asarray(direction, float)


class Rig:
    """A model with one State and one Control, reset in place between runs: kernels take the state and
    control fields as templates, so new fields would mean new compilations."""

    def __init__(self, strands, roots=None, body_count=1, bodies=None):
        b = GroomBuilder(body_count=body_count)
        for k, pts in enumerate(strands):
            b.add_strand(pts, root=(roots[k] if roots else "clamped"), body=(bodies[k] if bodies else 0))
        self.model = b.finalize()
        self.state = self.model.state()
        self.control = self.model.control()
        self.snapshot = self.state.to_numpy()
        self.rest = self.model.host["vertex_rest_position"]
        self.solvers = {}

    def solver(self, method) -> SolverShape:
        """One solver per method and rig, reconfigured by each test (see :meth:`configure`): each
        solver instance compiles its kernels, which dominates this file's run time."""
        if method not in self.solvers:
            cfg = SolverShapeConfig(method=method, regions=(ShapeRegion(), ShapeRegion()))
            self.solvers[method] = SolverShape(self.model, cfg, collider_capacity=2)
        return self.solvers[method]

    def configure(self, method, regions, strand_region=None, colliders=(), air_drag=1.0) -> SolverShape:
        """The ``method`` solver with the given regions (padded to two), strand regions and colliders."""
        solver = self.solver(method)
        regions = tuple(regions)
        solver.config.regions = regions + regions[:1] * (2 - len(regions))
        solver.config.colliders = tuple(colliders)
        solver.config.air_drag = air_drag
        solver.upload_regions()
        solver.upload_colliders()
        solver.set_strand_region(strand_region)
        return solver

    def vertices(self, strands):
        """Vertex indices of the given strands."""
        h = self.model.host
        return np.concatenate([np.arange(h["strand_vertex_start"][k], h["strand_vertex_start"][k]
                                         + h["strand_vertex_count"][k]) for k in strands])

    def reset(self, gravity=(0.0, -9.81, 0.0), positions=None):
        self.state.load(self.snapshot)
        if positions is not None:
            self.state.vertex_position.from_numpy(np.asarray(positions, np.float32))
        for body in range(self.model.body_count):
            self.control.set_body_transform(body, np.eye(3), np.zeros(3))
        self.control.gravity = gravity
        self.control.air_velocity = (0.0, 0.0, 0.0)
        return self.state, self.control

    def run(self, solver, steps, gravity=(0.0, -9.81, 0.0), positions=None, dt=DT):
        st, ctl = self.reset(gravity, positions)
        for _ in range(steps):
            solver.step(st, ctl, dt)
        return st.positions()


def edge_stretch(model, x, strands):
    """max |l / l0 - 1| over the real edges of the given strands."""
    h = model.host
    idx = np.concatenate([np.arange(h["strand_vertex_start"][k], h["strand_vertex_start"][k]
                                    + h["strand_vertex_count"][k] - 1) for k in strands])
    length = np.linalg.norm(x[idx + 1] - x[idx], axis=1)
    return float(np.max(np.abs(length / h["edge_rest_length"][idx] - 1.0)))


# --------------------------------------------------------------------------- ti.func math alone
class Scratch:
    """Small fields for calling the ``ti.func``s alone (created after the session's ti.init)."""

    def __init__(self):
        self.mat = ti.Matrix.field(3, 3, float, 8)
        self.a = ti.Vector.field(3, float, 8)
        self.b = ti.Vector.field(3, float, 8)
        self.out_a = ti.Vector.field(3, float, 8)
        self.out_b = ti.Vector.field(3, float, 8)
        self.out_s = ti.field(float, 16)
        self.args = ti.Vector.field(4, float, 16)


@pytest.fixture(scope="module")
def scratch():
    return Scratch()


@ti.kernel
def _rotate_by_matrix_quaternion(f: ti.template()):
    for k in range(8):
        q = sc.quat_from_matrix(f.mat[k])
        f.out_a[k] = sc.quat_rotate(q, f.a[k])
        f.out_b[k] = sc.quat_rotate_inverse(q, f.out_a[k])


@ti.kernel
def _between(f: ti.template()):
    for k in range(8):
        q = sc.quat_between(f.a[k], f.b[k])
        f.out_a[k] = sc.quat_rotate(q, f.a[k])
        p = sc.quat_mul(q, sc.quat_conjugate(q))  # identity
        f.out_s[k] = ti.abs(p[3] - 1.0) + ti.abs(p[0]) + ti.abs(p[1]) + ti.abs(p[2])


def _random_rotations(rng, k):
    out = []
    for _ in range(k):
        q, r = np.linalg.qr(rng.normal(size=(3, 3)))
        q = q @ np.diag(np.sign(np.diag(r)))
        if np.linalg.det(q) < 0:
            q[:, 0] *= -1
        out.append(q)
    # Include the branches of Shepperd's method: rotations by pi about x, y, z.
    out[5:8] = [np.diag([1.0, -1, -1]), np.diag([-1.0, 1, -1]), np.diag([-1.0, -1, 1])]
    return np.array(out)


def test_quaternion_functions_match_matrices(scratch):
    f = scratch
    rng = np.random.default_rng(1)
    R = _random_rotations(rng, 8)
    v = rng.normal(size=(8, 3))
    f.mat.from_numpy(R.astype(np.float32))
    f.a.from_numpy(v.astype(np.float32))
    _rotate_by_matrix_quaternion(f)
    np.testing.assert_allclose(f.out_a.to_numpy(), np.einsum("kij,kj->ki", R, v), atol=2e-6)
    np.testing.assert_allclose(f.out_b.to_numpy(), v, atol=2e-6)
    # Shortest arc: a -> b for random, equal and opposite pairs.
    a = rng.normal(size=(8, 3))
    a /= np.linalg.norm(a, axis=1)[:, None]
    b = rng.normal(size=(8, 3))
    b /= np.linalg.norm(b, axis=1)[:, None]
    b[0], b[1], b[2] = a[0], -a[1], [-1.0, 0.0, 0.0]
    a[2] = [1.0, 0.0, 0.0]
    f.a.from_numpy(a.astype(np.float32))
    f.b.from_numpy(b.astype(np.float32))
    _between(f)
    np.testing.assert_allclose(f.out_a.to_numpy(), b, atol=2e-6)
    assert np.all(f.out_s.to_numpy()[:8] < 1e-6)


@ti.kernel
def _ramp(f: ti.template(), n: ti.i32):
    for k in range(n):
        f.out_s[k] = sc.global_stiffness_at(f.args[k][0], f.args[k][1], f.args[k][2], f.args[k][3])


def test_global_stiffness_ramp(scratch):
    """S_G is full up to range (1 - falloff), linear to 0 at range, 0 beyond (Sec. 3.3)."""
    cases = [(0.8, 0.5, 1.0, 0.0), (0.8, 0.5, 1.0, 0.25), (0.8, 0.5, 1.0, 0.6), (0.8, 0.5, 0.5, 0.2),
             (0.8, 0.5, 0.5, 0.375), (1.0, 1.0, 0.0, 1.0), (1.0, 0.3, 0.0, 0.31), (0.5, 0.0, 1.0, 0.0)]
    expected = [0.8, 0.4, 0.0, 0.8, 0.4, 1.0, 0.0, 0.0]
    scratch.args.from_numpy(np.array(cases + [(0, 0, 0, 0)] * 8, np.float32))
    _ramp(scratch, len(cases))
    np.testing.assert_allclose(scratch.out_s.to_numpy()[: len(cases)], expected, atol=1e-6)


@ti.kernel
def _eq4(f: ti.template(), stiffness: float, w_prev: float, w_i: float):
    for _ in range(1):
        a, b = sc.local_shape_correction(f.a[0], f.a[1], f.a[2], stiffness, w_prev, w_i)
        f.out_a[0] = a
        f.out_a[1] = b


@ti.kernel
def _length(f: ti.template(), rest: float, w_a: float, w_b: float):
    for _ in range(1):
        a, b = sc.edge_length_correction(f.a[0], f.a[1], rest, w_a, w_b)
        f.out_a[0] = a
        f.out_a[1] = b


def _set(field, rows):
    arr = np.zeros((8, 3), np.float32)
    arr[: len(rows)] = rows
    field.from_numpy(arr)


def test_local_shape_and_length_corrections(scratch):
    f = scratch
    p, x, goal = np.array([0.0, 0, 0]), np.array([1.0, 0, 0]), np.array([0.0, 1.0, 0])
    for w_prev, s in ((1.0, 0.5), (0.0, 0.5), (1.0, 1.0)):
        _set(f.a, [p, x, goal])
        _eq4(f, s, w_prev, 1.0)
        a, b = f.out_a.to_numpy()[:2]
        d = s * (goal - x)
        # The edge vector moves by S_L d whoever moves (Eq. 4); a kinematic P_{i-1} stays.
        np.testing.assert_allclose(b - a, (x - p) + d, atol=1e-6)
        np.testing.assert_allclose(a, p - (0.5 * d if w_prev else 0.0), atol=1e-6)
    _set(f.a, [p, [3.0, 4.0, 0.0]])
    _length(f, 2.5, 1.0, 1.0)
    a, b = f.out_a.to_numpy()[:2]
    np.testing.assert_allclose(a, [0.75, 1.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(b, [2.25, 3.0, 0.0], atol=1e-6)
    _length(f, 2.5, 0.0, 1.0)
    a, b = f.out_a.to_numpy()[:2]
    np.testing.assert_allclose(a, p, atol=0)
    np.testing.assert_allclose(b, [1.5, 2.0, 0.0], atol=1e-6)


@ti.kernel
def _project(f: ti.template(), radius: float):
    for k in range(8):
        f.out_a[k] = sc.project_out_of_sphere(f.a[k], ti.math.vec3(0.0), radius)
        f.out_b[k] = sc.project_out_of_capsule(f.a[k], ti.math.vec3(0.0), ti.math.vec3(0.0, 1.0, 0.0), radius)


def test_sphere_and_capsule_projection(scratch):
    pts = np.array([[0.1, 0.2, 0.0], [0.0, -0.3, 0.0], [0.6, 0.0, 0.0], [0.2, 0.5, 0.1], [0.0, 1.2, 0.0],
                    [0.0, 1.6, 0.0], [0.0, 0.0, 0.0], [0.3, 0.3, 0.3]])
    scratch.a.from_numpy(pts.astype(np.float32))
    _project(scratch, 0.5)
    s = scratch.out_a.to_numpy()
    c = scratch.out_b.to_numpy()
    pts = pts.astype(np.float32).astype(np.float64)
    for p, ps, pc in zip(pts, s, c):
        r = np.linalg.norm(p)
        if r >= 0.5:
            np.testing.assert_allclose(ps, p, atol=0)
        elif r > 0:
            np.testing.assert_allclose(ps, 0.5 * p / r, atol=1e-6)
        else:
            np.testing.assert_allclose(ps, [0.0, 0.5, 0.0], atol=1e-6)  # documented +y choice
        axis = np.array([0.0, np.clip(p[1], 0.0, 1.0), 0.0])
        d = np.linalg.norm(p - axis)
        if d >= 0.5:
            np.testing.assert_allclose(pc, p, atol=0)
        elif d > 0:
            np.testing.assert_allclose(pc, axis + 0.5 * (p - axis) / d, atol=1e-6)
        else:
            np.testing.assert_allclose(pc, axis + [0.0, 0.5, 0.0], atol=1e-6)


# --------------------------------------------------------------------------- solver
def region(**kw):
    base = dict(global_stiffness=0.0, local_stiffness=0.0, local_iterations=3, length_iterations=2, damping=0.05)
    base.update(kw)
    return ShapeRegion(**base)


CURLY = slice(0, 4)  # clamped curly strands (20 vertices, 25 cm), phases 0, 0, 1, 1
FREE_CURLY = 4  # a free curly strand
SHORT = slice(5, 8)  # clamped short curly strands (8 vertices)


@pytest.fixture(scope="module")
def curly_rig():
    strands = [curly(20, 0.25, pitch=0.06, origin=(0.05 * k, 0, 0), phase=k // 2) for k in range(4)]
    strands += [curly(12, pitch=0.03, origin=(0.15, 0, 0))]
    strands += [curly(8, 0.1, pitch=0.05, origin=(0.3 + 0.05 * k, 0, 0), phase=k) for k in range(3)]
    return Rig(strands, roots=["clamped"] * 4 + ["free"] + ["clamped"] * 3)


SPHERE_DROP = [0, 1, 2]  # free horizontal strands above the sphere
HANGING = [3, 4, 5]  # clamped strands hanging along -y (capsule, wind)
HORIZONTAL = [6, 7, 8, 9]  # clamped horizontal strands (stretch, regions)


@pytest.fixture(scope="module")
def straight_rig():
    strands = [straight(16, 0.3, origin=(-0.15, 0.0, -0.01 + 0.01 * k)) for k in range(3)]
    strands += [straight(11, 0.2, direction=(0, -1, 0), origin=(0.5 + 0.01 * k, 0, 0)) for k in range(3)]
    strands += [straight(11, 0.2, origin=(1.0, 0, 0.02 * k)) for k in range(4)]
    return Rig(strands, roots=["free"] * 3 + ["clamped"] * 7, body_count=2)


@pytest.mark.parametrize("method", [1, 2, 3])
def test_curly_strands_hold_their_rest_shape_without_gravity(curly_rig, method):
    """No external force: the rest state is a fixed point of every stage (clamped and free strands)."""
    rig = curly_rig
    solver = rig.configure(method, [ShapeRegion(global_stiffness=0.3, local_stiffness=0.8)])
    x = rig.run(solver, 120, gravity=(0.0, 0.0, 0.0))
    assert np.max(np.abs(x - rig.rest)) < 2e-6
    assert np.max(np.abs(rig.state.vertex_velocity.to_numpy())) < 2e-4


@pytest.mark.parametrize("method", [1, 2, 3])
def test_free_strand_keeps_its_shape_when_turned(curly_rig, method):
    """A free curly strand turned rigidly (about an axis normal to its root edge) is at rest: its
    root frame, and for Method 3 its head rotation, turn with it."""
    rig = curly_rig
    free = rig.vertices([FREE_CURLY])
    x0 = rig.rest
    t0 = x0[free[1]] - x0[free[0]]
    axis = np.cross(t0, [0.3, 0.2, 1.0])
    R = _rotation(axis, 1.0)
    turned = x0.copy()
    turned[free] = (x0[free] - x0[free[0]]) @ R.T + x0[free[0]]
    solver = rig.configure(method, [region(local_stiffness=0.9, length_iterations=2)])
    x = rig.run(solver, 30, gravity=(0.0, 0.0, 0.0), positions=turned)
    assert np.abs(x[free] - turned[free]).max() < 2e-5
    assert np.abs(turned[free] - x0[free]).max() > 0.05


def test_global_stiffness_one_freezes_the_strand_under_gravity(curly_rig):
    """Sec. 3.3: S_G = 1 over the whole strand makes the hair rigid, frozen to the initial shape."""
    rig = curly_rig
    clamped = rig.vertices([0, 1, 2, 3, 5, 6, 7])
    frozen = region(global_stiffness=1.0, global_range=1.0, global_falloff=0.0, local_stiffness=0.5)
    solver = rig.configure(3, [frozen])
    assert np.max(np.abs(rig.run(solver, 60)[clamped] - rig.rest[clamped])) < 1e-6
    # Control: with S_G = 0 the same strands fall.
    solver = rig.configure(3, [region(local_stiffness=0.5)])
    assert np.max(np.abs(rig.run(solver, 60)[clamped] - rig.rest[clamped])) > 0.02


def test_methods_converge_to_the_same_shape_with_many_iterations(curly_rig):
    """With many local iterations Method 2 (Jacobi) and Method 3 (rest transforms) reach Method 1's shape:
    the rest shape, the common fixed point of Eq. 4 (Sec. 3.4, 4.2).  Eq. 4 anchors a strand through
    its root only, so convergence takes O(m^2) iterations: the test looks at the 8-vertex strands."""
    rig = curly_rig
    x0 = rig.rest
    short = rig.vertices(range(5, 8))
    rng = np.random.default_rng(3)
    # A deformed start: sheared and noisy; damping 1 and no gravity so the integration keeps it.
    deformed = x0 + np.c_[0.4 * (x0[:, 1] - x0[0, 1]), np.zeros(len(x0)), np.zeros(len(x0))]
    deformed += 0.003 * rng.normal(size=x0.shape)
    fixed = rig.model.host["vertex_is_fixed"] == 1
    deformed[fixed] = x0[fixed]
    results = {}
    for method in (1, 2, 3):
        results[method] = {}
        for iterations in (1, 300):
            reg = region(local_stiffness=1.0, local_iterations=iterations, length_iterations=0, damping=1.0)
            solver = rig.configure(method, [reg], air_drag=0.0)
            results[method][iterations] = rig.run(solver, 1, gravity=(0.0, 0.0, 0.0), positions=deformed)[short]
    for method in (1, 2, 3):
        assert np.max(np.abs(results[method][300] - x0[short])) < 1e-5, method
        assert np.max(np.abs(results[method][1] - x0[short])) > 1e-2, method  # the start really was deformed
    assert np.max(np.abs(results[2][300] - results[1][300])) < 1e-5
    # After one iteration the methods differ: Method 1's transforms are exact, Method 2's lag by one vertex.
    assert np.max(np.abs(results[2][1] - results[1][1])) > 1e-3


@pytest.mark.parametrize("method", [1, 2, 3])
def test_curly_strands_settle_under_gravity(curly_rig, method):
    """Damped clamped strands come to rest: the transforms do not feed a self-sustained motion."""
    rig = curly_rig
    clamped = rig.vertices([0, 1, 2, 3, 5, 6, 7])
    solver = rig.configure(method, [region(local_stiffness=0.8, damping=0.2)])
    x = rig.run(solver, 600)
    assert np.abs(rig.state.vertex_velocity.to_numpy()[clamped]).max() < 1e-3
    assert np.abs(x[clamped] - rig.rest[clamped]).max() > 1e-2  # it did sag


def _qmul(a, b):
    v = a[3] * b[:3] + b[3] * a[:3] + np.cross(a[:3], b[:3])
    return np.r_[v, a[3] * b[3] - a[:3] @ b[:3]]


def _qrot(q, v):
    t = 2 * np.cross(q[:3], v)
    return v + q[3] * t + np.cross(q[:3], t)


def test_jacobi_transforms_converge_to_the_serial_ones(curly_rig):
    """Algorithm 4's transforms, iterated on fixed positions (S_L = 0), equal Algorithm 3's chain
    ^wR_i = ^wR_{i-1} rot(e_x -> ^{i-1}x_i) of Eq. 1, computed here in NumPy."""
    rig = curly_rig
    x0 = rig.rest
    deformed = x0 + np.c_[0.4 * (x0[:, 1] - x0[0, 1]), np.zeros(len(x0)), 2.0 * (x0[:, 1] - x0[0, 1]) ** 2]
    fixed = rig.model.host["vertex_is_fixed"] == 1
    deformed[fixed] = x0[fixed]
    solver = rig.configure(2, [region(local_iterations=30, length_iterations=0, damping=1.0)], air_drag=0.0)
    x = rig.run(solver, 1, gravity=(0.0, 0.0, 0.0), positions=deformed).astype(np.float64)
    rot = solver.global_rotation.to_numpy().astype(np.float64)
    rest = solver.vertex_rest_rotation.to_numpy().astype(np.float64)
    start, count = rig.model.host["strand_vertex_start"][0], rig.model.host["strand_vertex_count"][0]
    q = rest[start + 1]
    for i in range(start + 2, start + count):
        local_x = _qrot(q * [-1, -1, -1, 1], (x[i] - x[i - 1]) / np.linalg.norm(x[i] - x[i - 1]))
        arc = np.r_[np.cross([1.0, 0.0, 0.0], local_x), 1.0 + local_x[0]]
        q = _qmul(q, arc / np.linalg.norm(arc))
        assert abs(abs(q @ rot[i]) - 1.0) < 1e-5, i  # same rotation (q and -q alike)
    # And the rest transforms reproduce the rest shape: P_i^0 = P_{i-1}^0 + R_{i-1}^0 ^{i-1}P_i^0.
    local = solver.vertex_rest_local_position.to_numpy().astype(np.float64)
    for i in range(start + 1, start + count):
        np.testing.assert_allclose(x0[i - 1] + _qrot(rest[i - 1], local[i]), x0[i], atol=1e-6)


def test_edge_length_constraints_limit_stretch(straight_rig):
    """Straight strands hanging under gravity: enough length iterations keep every edge within 1 %."""
    rig = straight_rig
    stretch = {}
    for iterations in (2, 100):
        solver = rig.configure(2, [region(length_iterations=iterations)])
        stretch[iterations] = edge_stretch(rig.model, rig.run(solver, 120), HORIZONTAL)
    assert stretch[100] < 0.01, stretch
    assert stretch[2] > 5 * stretch[100], stretch


def _rotation(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def test_rigid_head_motion_moves_roots_exactly_and_velocities_are_consistent(curly_rig):
    rig = curly_rig
    fixed = rig.model.host["vertex_is_fixed"] == 1
    clamped = rig.vertices([0, 1, 2, 3, 5, 6, 7])
    for sg, method in ((0.2, 2), (1.0, 1)):
        solver = rig.configure(method, [region(global_stiffness=sg, global_range=1.0, global_falloff=0.0,
                                               local_stiffness=0.5)])
        st, ctl = rig.reset()
        for k in range(1, 31):
            R = _rotation((1.0, 0.3, -0.2), 0.05 * k)
            T = np.array([0.01 * k, -0.004 * k, 0.002 * k])
            ctl.set_body_transform(0, R, T)
            before = st.positions().astype(np.float64)
            solver.step(st, ctl, DT)
            x = st.positions().astype(np.float64)
            goal = rig.rest @ R.T + T
            np.testing.assert_allclose(x[fixed], goal[fixed], atol=2e-7, rtol=0)
            np.testing.assert_allclose(st.vertex_velocity.to_numpy(), (x - before) / DT, atol=1e-3)
        if sg == 1.0:  # the frozen strands follow the head rigidly
            np.testing.assert_allclose(x[clamped], goal[clamped], atol=1e-6)
        else:
            assert np.abs(x[clamped] - goal[clamped]).max() > 1e-2


def test_strand_falling_onto_a_sphere_does_not_penetrate(straight_rig):
    """Free strands dropped above a sphere land on it; no vertex ends a step inside."""
    rig = straight_rig
    center, radius = np.array([0.0, -0.1, 0.0]), 0.08
    drop = rig.vertices(SPHERE_DROP)
    regions = [region(local_stiffness=0.3, length_iterations=4)]
    closest = {}
    for colliders in ((ShapeSphereCollider(center, radius),), ()):
        solver = rig.configure(2, regions, colliders=colliders)
        st, ctl = rig.reset()
        dist = []
        for _ in range(40):
            solver.step(st, ctl, DT)
            dist.append(np.linalg.norm(st.positions()[drop] - center, axis=1).min())
        closest[len(colliders)] = min(dist)
    assert closest[1] >= radius * (1 - 1e-6), closest
    assert closest[1] < radius * (1 + 1e-4), closest  # it did land on the sphere
    assert closest[0] < 0.5 * radius, closest  # control: without the collider it falls through


def test_capsule_attached_to_a_body_follows_it(straight_rig):
    """A capsule on body 1 moved into the hanging strands pushes every vertex out of it."""
    rig = straight_rig
    capsule = ShapeCapsuleCollider(p0=(0.0, 0.0, -0.05), p1=(0.0, 0.0, 0.05), radius=0.02, body=1)
    solver = rig.configure(1, [ShapeRegion()], colliders=[capsule])
    st, ctl = rig.reset(gravity=(0.0, 0.0, 0.0))
    ctl.set_body_transform(1, np.eye(3), (0.51, -0.12, 0.0))  # the capsule's axis now crosses the strands
    a, b = np.array([0.51, -0.12, -0.05]), np.array([0.51, -0.12, 0.05])
    hanging = rig.vertices(HANGING)
    for _ in range(5):
        solver.step(st, ctl, DT)
        x = st.positions()
        t = np.clip((x - a) @ (b - a) / np.dot(b - a, b - a), 0, 1)
        dist = np.linalg.norm(x - (a + t[:, None] * (b - a)), axis=1)
        assert dist.min() >= 0.02 * (1 - 1e-5)
    # The vertices that started inside were pushed out, by at least 5 mm.
    inside = hanging[np.linalg.norm(rig.rest[hanging, :2] - [0.51, -0.12], axis=1) < 0.015]
    assert inside.size >= 2
    assert np.all(np.linalg.norm(x[inside] - rig.rest[inside], axis=1) > 5e-3)


def test_per_region_parameters_take_effect(straight_rig):
    """Region 0 stiff, region 1 soft: the stiff strands sag less; a region's iteration count is its own."""
    rig = straight_rig
    stiff = region(global_stiffness=0.5, global_range=0.6, local_stiffness=0.9, local_iterations=4)
    soft = region(local_stiffness=0.05, local_iterations=1)
    strand_region = np.array([0] * 6 + [0, 1, 0, 1])
    tip = rig.model.host["strand_vertex_start"][HORIZONTAL] + 10
    for method in (1, 2):
        solver = rig.configure(method, [stiff, soft], strand_region=strand_region)
        drop = -rig.run(solver, 60)[tip, 1]
        assert drop[0] < 0.5 * drop[1] and drop[2] < 0.5 * drop[3], (method, drop)
    # A region with 0 local iterations equals one with S_L = 0, bit for bit, while the other region
    # runs its 4 iterations in the same launches (Method 2 loops to the largest count).
    zero_iterations = rig.run(rig.configure(2, [stiff, region(local_stiffness=0.9, local_iterations=0)],
                                            strand_region=strand_region), 20)
    zero_stiffness = rig.run(rig.configure(2, [stiff, region(local_stiffness=0.0, local_iterations=4)],
                                           strand_region=strand_region), 20)
    assert np.array_equal(zero_iterations, zero_stiffness)
    assert not np.array_equal(zero_iterations[tip[0]] - rig.rest[tip[0]], zero_iterations[tip[1]] - rig.rest[tip[1]])


def test_wind_blows_strands_downwind(straight_rig):
    rig = straight_rig
    solver = rig.configure(2, [region(local_stiffness=0.2)], air_drag=2.0)
    st, ctl = rig.reset(gravity=(0.0, 0.0, 0.0))
    ctl.air_velocity = (1.0, 0.0, 0.0)
    for _ in range(60):
        solver.step(st, ctl, DT)
    tip = rig.model.host["strand_vertex_start"][HANGING] + 10
    shift = st.positions()[tip, 0] - rig.rest[tip, 0]
    assert np.all(shift > 0.02), shift


@pytest.mark.parametrize(
    "make, name",
    [
        (lambda: ShapeRegion(global_stiffness=1.5), "global_stiffness"),
        (lambda: ShapeRegion(global_range=-0.1), "global_range"),
        (lambda: ShapeRegion(global_falloff=float("nan")), "global_falloff"),
        (lambda: ShapeRegion(local_stiffness=2), "local_stiffness"),
        (lambda: ShapeRegion(local_iterations=-1), "local_iterations"),
        (lambda: ShapeRegion(length_iterations=2.5), "length_iterations"),
        (lambda: ShapeRegion(damping=1.1), "damping"),
        (lambda: SolverShapeConfig(method=4), "method"),
        (lambda: SolverShapeConfig(regions=()), "regions"),
        (lambda: SolverShapeConfig(regions=("stiff",)), "regions[0]"),
        (lambda: SolverShapeConfig(air_drag=-1.0), "air_drag"),
        (lambda: SolverShapeConfig(colliders=(object(),)), "colliders[0]"),
        (lambda: ShapeSphereCollider(radius=0.0), "radius"),
        (lambda: ShapeCapsuleCollider(p0=(0, float("inf"), 0)), "p0"),
        (lambda: ShapeSphereCollider(body=-2), "body"),
    ],
)
def test_bad_config_values_raise_value_error_naming_the_field(make, name):
    with pytest.raises(ValueError, match=name.replace("[", r"\[").replace("]", r"\]")):
        make()


def test_bad_solver_arguments(straight_rig):
    rig = straight_rig
    with pytest.raises(ValueError, match="strand_region"):
        SolverShape(rig.model, SolverShapeConfig(), strand_region=[0, 1])
    with pytest.raises(ValueError, match=r"colliders\[0\].body"):
        SolverShape(rig.model, SolverShapeConfig(colliders=(ShapeSphereCollider(body=3),)))
    solver = rig.configure(2, [ShapeRegion()], air_drag=100.0)
    st, ctl = rig.reset()
    with pytest.raises(ValueError, match="dt"):
        solver.step(st, ctl, -1.0)
    with pytest.raises(ValueError, match="air_drag"):
        solver.step(st, ctl, 0.02)
    with pytest.raises(ValueError, match="collider_capacity"):
        solver.config.colliders = (ShapeSphereCollider(),) * 3
        solver.upload_colliders()


@pytest.mark.parametrize("method", [1, 2, 3])
def test_two_identical_runs_give_identical_bits(curly_rig, method):
    """Head motion, wind, regions and a collider; the same solver run twice from the same state."""
    rig = curly_rig
    solver = rig.configure(method, [ShapeRegion(), region(local_stiffness=0.3)], strand_region=[0, 1, 1, 0, 1, 0, 1, 0],
                           colliders=[ShapeSphereCollider((0.05, -0.12, 0.0), 0.05, body=0)])
    snaps = []
    for _ in range(2):
        st, ctl = rig.reset()
        ctl.air_velocity = (0.5, 0.0, 0.3)
        for k in range(40):
            ctl.set_body_transform(0, _rotation((0, 0, 1), 0.3 * math.sin(0.2 * k)), (0.0, 0.01 * k, 0.0))
            solver.step(st, ctl, DT)
        snaps.append((st.positions(), st.vertex_velocity.to_numpy()))
    assert np.array_equal(snaps[0][0], snaps[1][0]) and np.array_equal(snaps[0][1], snaps[1][1])
    assert np.abs(snaps[0][0] - rig.rest).max() > 1e-2  # it did move


def test_non_finite_values_stop_the_step_and_restore_the_state(straight_rig):
    rig = straight_rig
    solver = rig.configure(2, [ShapeRegion()])
    st, ctl = rig.reset()
    solver.step(st, ctl, DT)
    v = st.vertex_velocity.to_numpy()
    v[rig.model.host["strand_vertex_start"][7] + 4] = [np.nan, 0.0, 0.0]
    st.vertex_velocity.from_numpy(v)
    before = st.positions()
    with pytest.raises(SimulationDivergedError) as err:
        solver.step(st, ctl, DT)
    assert err.value.strand == 7 and err.value.field == "vertex_position"
    assert np.array_equal(st.positions(), before)


def test_step_allocates_no_fields(curly_rig, monkeypatch):
    """Every field is created in the constructor (STYLE habit 1)."""
    rig = curly_rig
    solvers = [rig.configure(m, [ShapeRegion()], colliders=[ShapeSphereCollider((0.0, -0.3, 0.0), 0.05)])
               for m in (1, 2, 3)]
    st, ctl = rig.reset()

    def forbidden(*args, **kwargs):
        raise AssertionError("a Taichi field was allocated inside step()")

    monkeypatch.setattr(ti, "field", forbidden)
    monkeypatch.setattr(ti.Vector, "field", forbidden)
    monkeypatch.setattr(ti.Matrix, "field", forbidden)
    for solver in solvers:
        for _ in range(3):
            solver.step(st, ctl, DT)
