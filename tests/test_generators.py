"""Procedural grooms (taichi_hair.groom.generators) and the head mesh (assets/head.obj).

Geometry is checked independently of the generator's voxel SDF: inside/outside
by the exact generalised winding number of the closed mesh, distances by
brute-force point-triangle distances.
"""

import os

import numpy as np
import pytest

from taichi_hair.groom.generators import (HEAD_MESH_PATH, STYLES, GeneratorConfig, generate_groom, load_head,
                                    read_obj_groups, sphere_surface)


def winding_number(points, vertices, faces):
    """Generalised winding number (Van Oosterom-Strackee solid angles): 1 inside a closed mesh, 0 outside."""
    tri = vertices[faces]
    out = np.zeros(len(points))
    for i, p in enumerate(points):
        a, b, c = (tri[:, k] - p for k in range(3))
        la, lb, lc = (np.linalg.norm(v, axis=1) for v in (a, b, c))
        det = np.einsum("ij,ij->i", a, np.cross(b, c))
        den = (la * lb * lc + np.einsum("ij,ij->i", a, b) * lc + np.einsum("ij,ij->i", b, c) * la
               + np.einsum("ij,ij->i", c, a) * lb)
        out[i] = np.sum(2 * np.arctan2(det, den)) / (4 * np.pi)
    return out


def _segment_distance(p, a, b):
    ab = b - a
    t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.einsum("ij,ij->i", ab, ab), 0, 1)
    return np.linalg.norm(p - (a + t[:, None] * ab), axis=1)


def surface_distance(points, vertices, faces):
    """Unsigned distance from each point to the nearest triangle (brute force)."""
    A, B, C = (vertices[faces][:, k] for k in range(3))
    n = np.cross(B - A, C - A)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    out = np.empty(len(points))
    for i, p in enumerate(points):
        d = np.einsum("ij,ij->i", p - A, n)
        q = p - d[:, None] * n
        inside = np.ones(len(A), bool)
        for u, v in ((A, B), (B, C), (C, A)):
            inside &= np.einsum("ij,ij->i", np.cross(v - u, q - u), n) >= 0
        edge = np.minimum(np.minimum(_segment_distance(p, A, B), _segment_distance(p, B, C)),
                          _segment_distance(p, C, A))
        out[i] = np.min(np.where(inside, np.abs(d), edge))
    return out


@pytest.fixture(scope="module")
def head():
    return load_head()


def test_head_mesh_is_closed_plausible_and_has_a_scalp(head):
    import trimesh

    m = trimesh.load(HEAD_MESH_PATH, force="mesh")  # as MeshCollider loads it
    assert m.is_watertight and 1000 < len(m.faces) < 20000
    assert 0.003 < m.volume < 0.008  # head and neck: a few litres [m^3]
    lo, hi = m.bounds
    assert 0.14 < hi[0] - lo[0] < 0.20 and 0.25 < hi[1] - lo[1] < 0.40  # width, height [m]
    # The scalp group: the top of the head, a plausible area (a human scalp is ~500-700 cm^2).
    assert 0.03 < head.scalp_area() < 0.08
    c = head.vertices[head.faces].mean(axis=1)
    assert c[head.scalp, 1].min() > 0.0 and c[~head.scalp, 1].min() < -0.1
    assert np.argmax(head.vertices[:, 1]) in np.unique(head.faces[head.scalp])
    # make_head.py reproduces the committed file.
    import sys
    sys.path.insert(0, os.path.dirname(HEAD_MESH_PATH))
    import make_head

    v, f, mask = make_head.make_head()
    assert len(f) == len(head.faces) and int(mask.sum()) == int(head.scalp.sum())


@pytest.mark.parametrize("style", STYLES)
def test_head_groom_counts_lengths_radii_and_roots(head, style):
    cfg = GeneratorConfig(style=style, strands=120, vertices_per_strand=24, length=0.2, length_spread=0.25,
                          radius=4e-5, radius_spread=0.3, seed=3)
    g = generate_groom(head, cfg)
    assert g.strand_count == 120 and g.vertex_count == 120 * 24 and g.units == "m"
    assert np.all(g.strand_vertex_counts() == 24)
    lengths = g.lengths()
    assert lengths.min() >= 0.15 * (1 - 1e-3) and lengths.max() <= 0.25 * (1 + 1e-3)
    assert lengths.std() > 0.02  # spread over the distribution, not all equal
    assert g.radius.shape == (120,) and g.radius.min() >= 2.8e-5 and g.radius.max() <= 5.2e-5
    roots = g.points[g.strand_offsets[:-1]]
    # Roots sit root_lift (0.5 mm) off the surface, on the scalp (above the hairline's lowest point).
    d = surface_distance(roots, head.vertices, head.faces)
    assert np.all(np.abs(d - cfg.root_lift) < 1e-5), (d.min(), d.max())
    assert roots[:, 1].min() > 0.0
    # No vertex of any strand is inside the head (exact winding number).
    w = winding_number(g.points[::3], head.vertices, head.faces)
    assert np.all(w < 0.5), w.max()
    # Hair falls: tips are below roots on average.
    tips = g.points[g.strand_offsets[1:] - 1]
    assert np.mean(tips[:, 1] - roots[:, 1]) < -0.05


def test_styles_differ_in_curvature(head):
    def turning(g):
        t = np.diff(g.points.reshape(g.strand_count, -1, 3), axis=1)
        t /= np.linalg.norm(t, axis=2, keepdims=True)
        return float(np.mean(np.arccos(np.clip(np.sum(t[:, 1:] * t[:, :-1], axis=2), -1, 1))))

    k = {s: turning(generate_groom(head, GeneratorConfig(style=s, strands=30, vertices_per_strand=64, seed=1)))
         for s in STYLES}
    assert k["straight"] < k["wavy"] < k["curly"], k


def test_strands_leave_the_scalp_at_root_angle_and_none_stands_up_at_the_crown(head):
    # Claim: the first edge leaves at root_angle (30 deg) above the tangent plane at its root, give or take the
    # turn toward gravity over that edge (2 deg here), and no strand climbs more than 1 cm above its root.  With
    # root_angle = 90 (along the normal) the crown's strands grow up where gravity has no sideways pull: 5+ cm.
    def rise(cfg):
        from taichi_hair.groom.generators import sample_roots

        g = generate_groom(head, cfg)
        _, n = sample_roots(head, cfg.strands, np.random.default_rng(cfg.seed))  # the same draws as the generator
        p = g.points.reshape(cfg.strands, -1, 3)
        e = p[:, 1] - p[:, 0]
        angle = np.degrees(np.arcsin(np.sum(e * n, axis=1) / np.linalg.norm(e, axis=1)))
        return angle, (p[:, :, 1] - p[:, :1, 1]).max(axis=1)

    angle, climb = rise(GeneratorConfig(style="straight", strands=300, vertices_per_strand=24, length=0.18, seed=1))
    assert np.all(angle < 30.0 + 2.0) and np.median(angle) > 20.0, (angle.min(), np.median(angle), angle.max())
    assert climb.max() < 0.01, climb.max()
    _, climb90 = rise(GeneratorConfig(style="straight", strands=300, vertices_per_strand=24, length=0.18, seed=1,
                                      root_angle=90.0))
    assert climb90.max() > 0.05, climb90.max()


def test_deterministic_by_seed(head):
    cfg = GeneratorConfig(style="curly", strands=40, vertices_per_strand=12, seed=7)
    a, b = generate_groom(head, cfg), generate_groom(head, cfg)
    assert np.array_equal(a.points, b.points) and np.array_equal(a.radius, b.radius)
    c = generate_groom(head, GeneratorConfig(style="curly", strands=40, vertices_per_strand=12, seed=8))
    assert not np.allclose(a.points, c.points)


def test_root_sampling_is_area_weighted(head):
    # Density: strands per scalp area.  Roots over the scalp faces follow area: compare two halves (x<0, x>0)
    # of the symmetric scalp, and the front and back halves against their areas.
    g = generate_groom(head, GeneratorConfig(density=4e4, vertices_per_strand=3, length=0.02, seed=2))
    assert abs(g.strand_count - 4e4 * head.scalp_area()) <= 1
    roots = g.points[g.strand_offsets[:-1]]
    c = head.vertices[head.faces].mean(axis=1)
    area = head.face_areas() * head.scalp
    front = area[c[:, 2] > 0].sum() / area.sum()
    n = g.strand_count
    sd = np.sqrt(n * front * (1 - front))
    assert abs(np.sum(roots[:, 2] > 0) - n * front) < 4 * sd
    assert abs(np.sum(roots[:, 0] > 0) - n / 2) < 4 * np.sqrt(n / 4)


def test_sphere_groom():
    s = sphere_surface(radius=0.09, scalp_min_y=0.2)
    g = generate_groom(s, GeneratorConfig(style="wavy", strands=50, vertices_per_strand=16, length=0.1,
                                          length_spread=0.0, seed=0))
    roots = g.points[g.strand_offsets[:-1]]
    r = np.linalg.norm(roots, axis=1)
    assert np.all(r > 0.09 - 2e-4) and np.all(r < 0.09 + 6e-4)  # on the icosphere, lifted by 0.5 mm
    assert roots[:, 1].min() > 0.2 * 0.09 - 0.01
    assert np.linalg.norm(g.points, axis=1).min() > 0.09
    assert np.allclose(g.lengths(), 0.1, rtol=1e-3)


def test_groom_builds_a_model(taichi_cpu, head):
    import taichi_hair as th

    g = generate_groom(head, GeneratorConfig(style="wavy", strands=5, vertices_per_strand=8, seed=0))
    b = th.GroomBuilder()
    g.add_to_builder(b, th.RodMaterial())
    m = b.finalize()
    assert m.strand_count == 5 and m.vertex_count == 40


def test_bad_configs_and_meshes_are_clear_errors(tmp_path):
    with pytest.raises(ValueError, match="GeneratorConfig.style"):
        GeneratorConfig(style="frizzy")
    with pytest.raises(ValueError, match="GeneratorConfig.length_spread"):
        GeneratorConfig(length_spread=1.5)
    with pytest.raises(ValueError, match="GeneratorConfig.vertices_per_strand"):
        GeneratorConfig(vertices_per_strand=2)
    for angle in (0.0, 91.0, float("nan")):
        with pytest.raises(ValueError, match="GeneratorConfig.root_angle"):
            GeneratorConfig(root_angle=angle)
    with pytest.raises(ValueError, match="GeneratorConfig.back"):
        GeneratorConfig(back=(0.0, float("inf"), 0.0))
    bad = tmp_path / "bad.obj"
    bad.write_text("v 0 0 0\nv 1 0 0\nf 1 2 x\n")
    with pytest.raises(ValueError, match=r"bad.obj: line 3"):
        read_obj_groups(bad)
    with pytest.raises(ValueError, match="cannot open"):
        load_head(tmp_path / "missing.obj")
