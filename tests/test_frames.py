"""Parallel transport and DER frame invariants."""

import numpy as np
import taichi as ti

from taichi_hair import GroomBuilder
from taichi_hair.strains import parallel_transport

N = 200


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def test_parallel_transport_invariants():
    rng = np.random.default_rng(0)
    t0 = _unit(rng.normal(size=(N, 3)))
    t1 = _unit(rng.normal(size=(N, 3)))
    t1[:10] = t0[:10]  # identity case
    # The minimal rotation is ill-conditioned for nearly opposite tangents (1 + t0.t1 -> 0);
    # time-parallel transport only sees small rotations, so keep turning angles below ~150 deg.
    keep = np.sum(t0 * t1, 1) > -0.85
    t0, t1 = t0[keep][:N], t1[keep][:N]
    while t0.shape[0] < N:
        t0, t1 = np.vstack([t0, t0]), np.vstack([t1, t1])
    t0, t1 = t0[:N], t1[:N]
    u = rng.normal(size=(N, 3))
    u = _unit(u - np.sum(u * t0, 1)[:, None] * t0)
    fa = ti.Vector.field(3, ti.f32, N)
    fb = ti.Vector.field(3, ti.f32, N)
    fu = ti.Vector.field(3, ti.f32, N)
    out = ti.Vector.field(3, ti.f32, N)
    out_t = ti.Vector.field(3, ti.f32, N)
    fa.from_numpy(t0.astype(np.float32))
    fb.from_numpy(t1.astype(np.float32))
    fu.from_numpy(u.astype(np.float32))

    @ti.kernel
    def run():
        for i in range(N):
            out[i] = parallel_transport(fu[i], fa[i], fb[i])
            out_t[i] = parallel_transport(fa[i], fa[i], fb[i])

    run()
    pu = out.to_numpy().astype(np.float64)
    pt = out_t.to_numpy().astype(np.float64)
    np.testing.assert_allclose(pt, t1, atol=2e-6)  # maps t0 to t1
    np.testing.assert_allclose(np.linalg.norm(pu, axis=1), 1.0, atol=2e-6)  # rotation: keeps length
    np.testing.assert_allclose(np.sum(pu * t1, 1), 0.0, atol=2e-6)  # normal stays normal
    np.testing.assert_allclose(pu[:10], u[:10], atol=1e-7)  # identity when t0 == t1
    # The binormal axis t0 x t1 is left unchanged (minimal rotation).
    b = np.cross(t0, t1)
    pb = np.array(b)
    fu.from_numpy(b.astype(np.float32))
    run()
    np.testing.assert_allclose(out.to_numpy(), pb, atol=2e-6)


def test_parallel_transport_of_a_reversed_tangent_is_a_finite_half_turn():
    """t1 = -t0 (an edge flipped in one step) has no minimal rotation; the transport is the half turn about
    u's part across t0: a director u across t0 maps to itself, t0 maps to -t0, and nothing is NaN (before,
    Rodrigues' formula gave 0 / 0).  Tolerance 1e-6 (f32)."""
    t0 = np.array([[0.0, 1.0, 0.0], [0.6, 0.0, 0.8], [0.0, 0.0, 1.0]], np.float32)
    u = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], np.float32)  # the last one along t0
    fa, fu = ti.Vector.field(3, ti.f32, 3), ti.Vector.field(3, ti.f32, 3)
    out, out_t = ti.Vector.field(3, ti.f32, 3), ti.Vector.field(3, ti.f32, 3)
    fa.from_numpy(t0)
    fu.from_numpy(u)

    @ti.kernel
    def run():
        for i in range(3):
            out[i] = parallel_transport(fu[i], fa[i], -fa[i])
            out_t[i] = parallel_transport(fa[i], fa[i], -fa[i])

    run()
    pu, pt = out.to_numpy(), out_t.to_numpy()
    assert np.all(np.isfinite(pu)) and np.all(np.isfinite(pt))
    np.testing.assert_allclose(pt, -t0, atol=1e-6)
    np.testing.assert_allclose(pu[:2], u[:2], atol=1e-6)
    np.testing.assert_allclose(pu[2], -u[2], atol=1e-6)  # u along t0 turns with it


def test_rest_frames_of_a_helix_are_orthonormal_and_twist_free():
    s = np.linspace(0, 4 * np.pi, 80)
    pts = np.c_[0.005 * np.cos(s), 0.005 * np.sin(s), 0.002 * s]
    b = GroomBuilder()
    b.add_strand(pts)
    model = b.finalize()
    st = model.state()
    t = st.edge_tangent.to_numpy()[:-1].astype(np.float64)
    d1 = st.edge_reference_director.to_numpy()[:-1].astype(np.float64)
    m1 = st.edge_material_d1.to_numpy()[:-1].astype(np.float64)
    m2 = st.edge_material_d2.to_numpy()[:-1].astype(np.float64)
    np.testing.assert_allclose(np.linalg.norm(d1, axis=1), 1, atol=1e-5)
    np.testing.assert_allclose(np.sum(d1 * t, 1), 0, atol=1e-5)
    np.testing.assert_allclose(np.cross(m1, m2), t, atol=1e-5)
    # Space-parallel rest frames have zero reference twist.
    np.testing.assert_allclose(st.edge_reference_twist.to_numpy(), 0, atol=1e-5)
    # Tangents agree with the polyline.
    e = np.diff(pts, axis=0)
    np.testing.assert_allclose(t, e / np.linalg.norm(e, axis=1)[:, None], atol=5e-6)
