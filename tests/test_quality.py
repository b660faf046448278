"""Run quality (taichi_hair.quality), exact mesh queries (taichi_hair.contact.mesh_query) and meshes with holes.

Each figure is checked on a hand-made frame whose answer has a closed form, stated in the test."""

import math
import warnings

import numpy as np
import pytest

from taichi_hair.contact.colliders import MeshCollider, PlaneCollider, SphereCollider
from taichi_hair.contact.mesh_query import (TriangleMeshQuery, boundary_edges, count_boundary_loops,
                                    point_triangle_distance_sq)
from taichi_hair.quality import (body_penetration, frame_quality, quality_warnings,
                                 strain_statistics)


def _icosphere(subdivisions=3, radius=0.1):
    import trimesh

    return trimesh.creation.icosphere(subdivisions, radius)


def _holed_icosphere(hole_radius=0.03, radius=0.1, subdivisions=3, at=(1.0, 0.0, 0.0)):
    """An icosphere with the faces whose centre is within ``hole_radius`` of the point radius * at removed."""
    import trimesh

    m = _icosphere(subdivisions, radius)
    keep = np.linalg.norm(m.triangles_center - radius * np.asarray(at), axis=1) > hole_radius
    return trimesh.Trimesh(m.vertices, m.faces[keep], process=False)


@pytest.fixture(scope="module")
def holed_sphere_collider():
    """A 10 cm icosphere with a 3 cm hole at +x (about 20 faces removed), as a MeshCollider at 32^3."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        col = MeshCollider(_holed_icosphere(), resolution=32, body=-1)
    return col, [str(w.message) for w in caught]


# --------------------------------------------------------------------------- point-triangle distance
@pytest.mark.parametrize("point, expected", [
    ((0.2, 0.2, 0.3), 0.3),                    # above the interior: the height
    ((2.0, 0.0, 0.0), 1.0),                    # beyond vertex B = (1, 0, 0): |p - B|
    ((0.5, -1.0, 0.0), 1.0),                   # below edge AB: distance to the line y = 0
    ((1.0, 1.0, 0.0), math.sqrt(0.5)),         # beyond the hypotenuse x + y = 1: |x + y - 1| / sqrt(2)
    ((-1.0, -1.0, 0.0), math.sqrt(2.0)),       # beyond vertex A = origin
    ((0.0, 2.0, 1.0), math.sqrt(2.0)),         # beyond vertex C = (0, 1, 0), 1 above the plane
])
def test_point_triangle_distance_by_region(point, expected):
    tri = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    d = math.sqrt(point_triangle_distance_sq(np.array([point]), tri[None, 0], tri[None, 1], tri[None, 2])[0])
    assert d == pytest.approx(expected, abs=1e-12)


def test_clustered_distance_equals_the_brute_force_minimum():
    # The cluster pruning (lower bound |p - c| - r against an exact upper bound) may skip no triangle:
    # the result must be the minimum over all triangles, to rounding.
    m = _icosphere(3, 0.1)
    q = TriangleMeshQuery(m.vertices, m.faces)
    rng = np.random.default_rng(0)
    p = rng.uniform(-0.15, 0.15, (300, 3))
    a, b, c = (np.repeat(m.triangles[None, :, k], len(p), 0).reshape(-1, 3) for k in range(3))
    brute = np.sqrt(point_triangle_distance_sq(np.repeat(p, len(m.faces), 0), a, b, c)
                    .reshape(len(p), -1).min(1))
    np.testing.assert_allclose(q.unsigned_distance(p), brute, rtol=0, atol=1e-12)


def test_winding_number_is_one_inside_and_zero_outside_a_closed_mesh():
    # Closed, outward-oriented mesh: w = 1 inside, 0 outside (Jacobson et al. 2013); the dipole term of
    # far clusters is an approximation, measured within 0.011 here: tolerance 0.02.
    m = _icosphere(3, 0.1)
    q = TriangleMeshQuery(m.vertices, m.faces)
    rng = np.random.default_rng(1)
    p = rng.uniform(-0.2, 0.2, (1000, 3))
    r = np.linalg.norm(p, axis=1)
    w = q.winding_number(p)
    inner = r < 0.095  # inside the inscribed sphere of the polytope (face planes >= 0.098 from the centre)
    assert np.all(np.abs(w[inner] - 1.0) < 0.02) and np.all(np.abs(w[r > 0.1]) < 0.02)


def test_boundary_edges_and_holes_of_a_cut_sphere():
    m = _icosphere(3, 0.1)
    assert len(boundary_edges(m.faces)) == 0
    two = _holed_icosphere(at=(1.0, 0.0, 0.0))
    two = two.__class__(two.vertices, two.faces[np.linalg.norm(two.triangles_center - [-0.1, 0, 0], axis=1) > 0.03],
                        process=False)
    e = boundary_edges(two.faces)
    assert count_boundary_loops(e) == 2 and len(e) > 0


# --------------------------------------------------------------------------- strain
def test_strain_statistics_of_one_stretched_edge():
    # Two straight strands of 11 vertices, 1 cm edges; edge 3 of strand 1 is stretched by 10 % (vertices
    # 4..10 shifted by 1 mm).  Strains: 19 zeros and one 0.1.  p50 = 0; numpy's linear p99 of 20 sorted
    # values sits at rank 0.99 * 19 = 18.81, between 0 and 0.1: 0.081; max 0.1 on strand 1.
    n, h = 11, 0.01
    s0 = np.c_[np.arange(n) * h, np.zeros(n), np.zeros(n)]
    s1 = s0 + [0.0, 0.05, 0.0]
    s1[4:, 0] += 0.1 * h
    x = np.r_[s0, s1]
    rest = np.tile(np.r_[np.full(n - 1, h), 0.0], 2)
    strand = np.repeat([0, 1], n)
    s = strain_statistics(x, rest, strand)
    assert s["strain_p50"] == pytest.approx(0.0, abs=1e-12)
    assert s["strain_p99"] == pytest.approx(0.081, abs=1e-9)
    assert s["strain_max"] == pytest.approx(0.1, abs=1e-9) and s["strain_worst_strand"] == 1
    # A compression of 10 % counts as much as a stretch: |strain|.
    s1[4:, 0] -= 0.2 * h
    assert strain_statistics(np.r_[s0, s1], rest, strand)["strain_max"] == pytest.approx(0.1, abs=1e-9)


# --------------------------------------------------------------------------- penetration
def _host(x, fixed=None):
    """A Model.host-like dict for strands of 2 vertices each (edge j = j -> j + 1 within a pair)."""
    v = len(x)
    rest = np.zeros(v)
    rest[0::2] = np.linalg.norm(x[1::2] - x[0::2], axis=1)
    return dict(edge_rest_length=rest, vertex_strand=np.repeat(np.arange(v // 2), 2),
                vertex_is_fixed=np.zeros(v, np.int32) if fixed is None else fixed)


def test_sphere_and_plane_penetration_in_a_moved_body():
    # A sphere of radius 0.1 on body 0 translated by T and rotated 90 deg about z: a world point at
    # T + (0, 0.07, 0) is 0.03 deep (0.1 - 0.07), at T + (0, 0.12, 0) outside (0).  Plane y >= -0.5 (static):
    # the point at y = -0.502 is 2 mm deep.
    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    T = np.array([0.3, 0.2, -0.1])
    x = np.array([T + [0, 0.07, 0], T + [0, 0.12, 0], [1.0, -0.502, 0.0], [1.0, -0.40, 0.0]])
    cols = [SphereCollider(center=(0.0, 0.0, 0.0), radius=0.1, body=0), PlaneCollider(point=(0, -0.5, 0))]
    d = body_penetration(x, cols, R[None], T[None], np.array([0, 0, 1, 1]), np.ones(4, bool))
    np.testing.assert_allclose(d, [0.03, 0.0, 0.002, 0.0], atol=1e-12)
    q = frame_quality(x, np.zeros_like(x), _host(x), cols, R[None], T[None])
    assert q["vertices_inside"] == 2 and q["body_penetration_max_m"] == pytest.approx(0.03, abs=1e-12)
    assert q["penetration_worst_strand"] == 0
    # Fixed vertices (clamped roots) are left out.
    q = frame_quality(x, np.zeros_like(x), _host(x, fixed=np.array([1, 0, 0, 0])), cols, R[None], T[None])
    assert q["vertices_inside"] == 1 and q["body_penetration_max_m"] == pytest.approx(0.002, abs=1e-12)
    assert any("1 vertices deeper than 0.5 mm" in line for line in quality_warnings(q))


def test_mesh_penetration_is_the_distance_to_the_triangles():
    # A closed icosphere (radius 0.1, subdivision 3).  From the centre, the nearest boundary point of a
    # convex polytope is the foot on the nearest face plane: depth = min_f n_f . a_f.  A point at 0.09
    # from the centre along a vertex direction is inside by the exact distance to the triangles.
    m = _icosphere(3, 0.1)
    col = MeshCollider(m, resolution=32)
    n = np.cross(m.triangles[:, 1] - m.triangles[:, 0], m.triangles[:, 2] - m.triangles[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    inscribed = float(np.min(np.einsum("ij,ij->i", n, m.triangles[:, 0])))
    x = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.13], [0.0, 0.0, 0.14]])
    d = body_penetration(x, [col], np.eye(3)[None], np.zeros((1, 3)), np.array([0, 0, 1, 1]), np.ones(4, bool))
    assert d[0] == pytest.approx(inscribed, abs=1e-12) and d[2] == 0.0 and d[3] == 0.0


def test_mesh_with_a_hole_is_signed_by_winding_numbers_and_warns(holed_sphere_collider):
    col, messages = holed_sphere_collider
    assert col.sign_method == "winding" and not col.watertight and col.hole_count == 1
    assert len(messages) == 1 and "not watertight" in messages[0] and "boundary edges in 1 holes" in messages[0]
    # Probe points: inside (centre, 5 cm towards -x / +y / -z, 5 cm towards the hole), outside (12 cm out).
    inside = np.array([[0, 0, 0], [-0.05, 0, 0], [0, 0.05, 0], [0, 0, -0.05], [0.05, 0, 0]], float)
    outside = np.array([[0, 0.12, 0], [-0.12, 0, 0], [0.0, 0.0, 0.125], [0.12, 0.0, 0.0]], float)
    assert np.all(col.sdf_numpy(inside) < 0) and np.all(col.sdf_numpy(outside) > 0)


def test_hair_twenty_mm_inside_an_open_mesh_is_reported(holed_sphere_collider):
    # The case that motivated the exact check: hair 20 mm inside a non-watertight body.  Depth = the exact
    # distance to the remaining triangles (brute force over all of them), between 0.1 - 0.08 minus the
    # polytope's flattening and 0.02.
    col, _ = holed_sphere_collider
    x = np.array([[-0.08, 0.0, 0.0], [0.0, -0.08, 0.0]])
    q = frame_quality(x, np.zeros_like(x), _host(x), [col], np.eye(3)[None], np.zeros((1, 3)))
    m = col.mesh
    a, b, c = (np.repeat(m.triangles[None, :, k], len(x), 0).reshape(-1, 3) for k in range(3))
    exact = np.sqrt(point_triangle_distance_sq(np.repeat(x, len(m.faces), 0), a, b, c).reshape(2, -1).min(1))
    assert q["vertices_inside"] == 2
    assert q["body_penetration_max_m"] == pytest.approx(exact.max(), abs=1e-12) and 0.015 < exact.max() <= 0.02


def test_open_sheet_falls_back_to_the_unsigned_shell():
    import trimesh

    sheet = trimesh.Trimesh([[0, 0, 0], [0.02, 0, 0], [0, 0.02, 0], [0.02, 0.02, 0]], [[0, 1, 2], [1, 3, 2]])
    with pytest.warns(UserWarning, match="encloses no volume"):
        col = MeshCollider(sheet, resolution=16, thickness=5e-4)
    assert col.sign_method == "unsigned-shell" and col.sdf.min() >= -5e-4 - 1e-12


def test_hair_keys_pass_through_when_the_solver_gives_them():
    x = np.array([[0.0, 0, 0], [0.01, 0, 0]])
    q = frame_quality(x, np.zeros_like(x), _host(x), contact_stats={"contacts": 3})
    assert "crossed_pairs" not in q
    q = frame_quality(x, np.zeros_like(x), _host(x), contact_stats={"hair_penetration_p99_m": 1e-6,
                                                                       "hair_penetration_max_m": 2e-6,
                                                                       "crossed_pairs": 4})
    assert q["crossed_pairs"] == 4 and q["hair_penetration_max_m"] == 2e-6



def test_hair_dropped_on_a_hole_stays_outside():
    # Three free 2 cm strands dropped from 1 cm above the top of a 10 cm sphere with a 3 cm hole at the top
    # (the hole's rim is at y = sqrt(0.1^2 - 0.03^2) = 0.0954).  Unobstructed they would fall 22 cm in the
    # 0.21 s simulated, through the hole onto the inner bottom (y = -0.1); with the winding-number SDF they
    # rest on the cap over the hole.  Checked by the exact measure (winding number and triangle distance).
    from taichi_hair import GroomBuilder, RodMaterial, SolverADMM, SolverADMMConfig
    from taichi_hair.config import ContactConfig

    with pytest.warns(UserWarning, match="not watertight"):
        col = MeshCollider(_holed_icosphere(at=(0.0, 1.0, 0.0)), resolution=32, friction=0.3)
    b = GroomBuilder()
    for z in (-0.005, 0.0, 0.005):
        t = np.linspace(-0.01, 0.01, 9)
        b.add_strand(np.c_[t, np.full(9, 0.11), np.full(9, z)], RodMaterial(), root="free")
    model = b.finalize()
    st, ctl = model.state(), model.control()
    solver = SolverADMM(model, SolverADMMConfig(iterations=10, contacts=ContactConfig(friction=0.3)),
                        colliders=[col])
    for _ in range(50):
        solver.step(st, ctl, 1 / 240)
    x = st.positions().astype(np.float64)
    q = frame_quality(x, st.vertex_velocity.to_numpy(), model.host, [col], np.eye(3)[None], np.zeros((1, 3)))
    assert q["vertices_inside"] == 0, q
    assert x[:, 1].min() > 0.085 and x[:, 1].max() < 0.105  # fell onto the cap, not through it


def test_shape_drift_is_measured_in_the_body_frame():
    """shape_drift: |x - (R x* + T)| over free vertices of clamped strands; a groom carried rigidly by its body
    has zero drift, one vertex moved by 3 mm gives max 3 mm (float64, 1e-12)."""
    import numpy as np

    from taichi_hair.quality import shape_drift

    rest = np.array([[0, 0, 0], [0, -0.01, 0], [0, -0.02, 0], [0, -0.03, 0]], float)
    host = dict(vertex_strand=np.zeros(4, int), strand_body=np.array([0]), vertex_rest_position=rest,
                vertex_is_fixed=np.array([1, 1, 0, 0]))
    c, s_ = np.cos(0.3), np.sin(0.3)
    R = np.array([[[c, 0, s_], [0, 1, 0], [-s_, 0, c]]])
    T = np.array([[0.1, 0.2, 0.0]])
    x = rest @ R[0].T + T[0]
    assert shape_drift(x, host, R, T)["drift_max_m"] < 1e-12
    x[3] += [0.003, 0, 0]
    assert abs(shape_drift(x, host, R, T)["drift_max_m"] - 0.003) < 1e-12
    assert shape_drift(x, {"vertex_strand": host["vertex_strand"]}) == {}


def test_segment_set_distance_equals_the_brute_force_minimum():
    """segment_set_distance: exact point-to-nearest-segment distance, against the brute-force minimum over all
    segments (float64, 1e-12), with segments of very different lengths (the ball search path), k = 2 and the points
    in chunks."""
    from taichi_hair.quality import segment_set_distance

    rng = np.random.default_rng(3)
    a = rng.uniform(-1, 1, (60, 3))
    b = a + rng.normal(0, 1, (60, 3)) * rng.choice([0.01, 1.0], (60, 1))
    p = rng.uniform(-1.5, 1.5, (200, 3))
    ab = b - a
    t = np.clip(np.einsum("pj,sj->ps", p, ab) - np.einsum("sj,sj->s", a, ab), 0, None) / np.einsum("sj,sj->s", ab, ab)
    t = np.minimum(t, 1.0)
    brute = np.linalg.norm(p[:, None, :] - (a[None] + t[..., None] * ab[None]), axis=2).min(axis=1)
    for k, chunk in ((2, 7), (16, 1 << 16)):  # (chunks of 7 points: the last one short)
        assert np.max(np.abs(segment_set_distance(p, a, b, k=k, chunk=chunk) - brute)) < 1e-12


def test_shape_distance_ignores_strands_trading_places_but_not_a_moved_envelope():
    """shape_distance: two parallel authored strands at x = 0 and 2 mm.  Their free vertices trading places give a
    drift of 2 mm and a shape distance of 0 (the same courses, 1e-12).  Both moved 3 mm sideways (to x = 3 and
    5 mm): the first is 1 mm from the authored course at 2 mm, the second 3 mm, and the authored ones 3 and 1 mm
    from the moved ones, so the p90 both ways is 3 mm (1e-12)."""
    from taichi_hair.quality import shape_distance, shape_drift

    y = -np.arange(5) * 0.01
    s0 = np.c_[np.zeros(5), y, np.zeros(5)]
    s1 = s0 + [0.002, 0, 0]
    rest = np.r_[s0, s1]
    rl = np.tile(np.r_[np.full(4, 0.01), 0.0], 2)
    host = dict(vertex_strand=np.repeat([0, 1], 5), strand_body=np.array([0, 0]), vertex_rest_position=rest,
                vertex_is_fixed=np.tile([1, 0, 0, 0, 0], 2), edge_rest_length=rl)
    swapped = np.r_[s1, s0]
    swapped[[0, 5]] = rest[[0, 5]]  # the roots stay clamped; the free vertices trade places
    assert shape_drift(swapped, host)["drift_p90_m"] > 0.0019
    assert shape_distance(swapped, host)["shape_distance_p90_m"] < 1e-12
    moved = rest + [0.003, 0, 0]
    assert abs(shape_distance(moved, host)["shape_distance_p90_m"] - 0.003) < 1e-12
