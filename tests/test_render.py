"""Off-screen rendering (GGUI on Mesa's software Vulkan with Taichi's CPU arch, and the Taichi rasteriser of
``taichi_hair.render.raster``): the NumPy camera equals GGUI's, the pixels an off-screen render draws lie where
the strands project (checked against the projection, not a stored picture), and the two drawings agree."""

import numpy as np
import pytest

from taichi_hair.io import Groom
from taichi_hair.render import (CameraConfig, ViewerGGUI, edge_indices, pick_ray, project, projection_matrix,
                                render_groom, sphere_mesh, strand_colors, view_matrix)

W, H = 160, 120
BACKGROUND = np.array([0.0, 0.0, 0.0])


def _viewer(drawing: str, **kw):
    try:
        return ViewerGGUI(W, H, show_window=False, background=tuple(BACKGROUND), drawing=drawing, **kw)
    except Exception as exc:  # no Vulkan device at all: say so instead of a crash
        pytest.skip(f"GGUI needs a Vulkan device (mesa-vulkan-drivers on a CPU machine): {exc}")


@pytest.fixture(scope="module", params=["lines", "raster"])
def viewer(request):
    """Both drawings: GGUI's lines on the Vulkan device and the Taichi rasteriser (``render.raster``) pass the
    same projection and depth tests."""
    v = _viewer(request.param)
    yield v
    v.close()


def scene():
    """Five horizontal strands, a diagonal one and a curly one in front of the origin."""
    lines = [np.c_[np.linspace(-0.1, 0.1, 15), np.full(15, 0.025 * k), np.zeros(15)] for k in range(-2, 3)]
    t = np.linspace(0.0, 1.0, 30)
    lines.append(np.c_[-0.08 + 0.16 * t, -0.07 + 0.14 * t, 0.02 * t])
    lines.append(np.c_[0.05 + 0.015 * np.cos(12 * t), 0.06 * t - 0.03, 0.015 * np.sin(12 * t) + 0.03])
    return Groom.from_polylines(lines, units="m")


CAMERA = CameraConfig(eye=(0.08, 0.06, 0.45), target=(0.0, 0.0, 0.0), fov=40.0, z_near=0.05, z_far=10.0)


def segment_distance(q, a, b):
    """Distance of each point q (n, 2) to the nearest of the segments a[k] b[k], shape (n,)."""
    u = b - a
    t = np.clip(np.einsum("nkj,kj->nk", q[:, None, :] - a[None], u) / np.maximum(np.sum(u * u, axis=1), 1e-30),
                0.0, 1.0)
    return np.linalg.norm(a[None] + t[..., None] * u[None] - q[:, None, :], axis=2).min(axis=1)


def test_numpy_camera_equals_the_ggui_camera(viewer):
    for cam in (CAMERA, CameraConfig(eye=(-0.3, 0.4, -0.2), target=(0.01, 0.02, 0.0), up=(0.0, 1.0, 0.2),
                                     fov=65.0, z_near=0.01, z_far=100.0)):
        c = viewer.ggui_camera(cam)  # as the viewer sets it for GGUI's scene
        np.testing.assert_allclose(np.array(c.get_view_matrix()).T, view_matrix(cam), atol=1e-6)
        np.testing.assert_allclose(np.array(c.get_projection_matrix(W / H)).T, projection_matrix(cam, W / H),
                                   rtol=1e-5, atol=1e-7)


def test_pick_ray_inverts_the_projection():
    rng = np.random.default_rng(0)
    p = rng.uniform(-0.1, 0.1, (50, 3))
    px, depth, vis = project(p, CAMERA, W, H)
    assert vis.all()
    for (col, row), x in zip(px, p):
        o, d = pick_ray(CAMERA, W, H, col, row)
        assert np.linalg.norm(np.cross(x - o, d)) < 1e-9  # x lies on the ray through its own pixel


def test_offscreen_render_draws_where_the_strands_project(viewer, tmp_path):
    g = scene()
    img = render_groom(g, tmp_path / "still.png", camera=CAMERA, color="strand", viewer=viewer)
    assert img.shape == (H, W, 3) and img.dtype == np.uint8 and (tmp_path / "still.png").stat().st_size > 0
    drawn = np.abs(img.astype(np.float64) - 255 * BACKGROUND).sum(axis=2) > 24
    rows, cols = np.nonzero(drawn)
    assert drawn.sum() > 300  # non-empty: about 7 strands x ~100 pixels
    px, _, vis = project(g.points, CAMERA, W, H)
    assert vis.all()
    e = edge_indices(g.strand_offsets).reshape(-1, 2)
    a, b = px[e[:, 0]], px[e[:, 1]]
    # Every drawn pixel's centre lies within a pixel of a projected edge...
    d = segment_distance(np.c_[cols + 0.5, rows + 0.5], a, b)
    assert d.max() <= 1.0, d.max()
    # ...and the projected edges are drawn: points along them have a drawn pixel within a pixel.
    t = np.linspace(0.0, 1.0, 7)[1:-1]
    q = (a[:, None, :] + t[None, :, None] * (b - a)[:, None, :]).reshape(-1, 2)
    near = np.zeros(len(q), dtype=bool)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            r = np.clip(np.floor(q[:, 1]).astype(int) + dr, 0, H - 1)
            c = np.clip(np.floor(q[:, 0]).astype(int) + dc, 0, W - 1)
            near |= drawn[r, c]
    assert near.mean() > 0.97, near.mean()
    # A different camera moves the drawing with the projection (not a fixed picture).
    moved = CameraConfig(eye=(-0.2, -0.1, 0.4), target=(0.02, 0.0, 0.0), fov=50.0, z_near=0.05, z_far=10.0)
    img2 = render_groom(g, None, camera=moved, color="strand", viewer=viewer)
    drawn2 = np.abs(img2.astype(np.float64) - 255 * BACKGROUND).sum(axis=2) > 24
    r2, c2 = np.nonzero(drawn2)
    px2, _, _ = project(g.points, moved, W, H)
    assert segment_distance(np.c_[c2 + 0.5, r2 + 0.5], px2[e[:, 0]], px2[e[:, 1]]).max() <= 1.0
    assert (drawn2 != drawn).sum() > 100


def test_head_mesh_hides_strands_behind_it(viewer):
    """A sphere between the camera and a strand: the strand's pixels inside the sphere's silhouette
    show the sphere, those outside show the strand (depth test)."""
    behind = [np.c_[np.linspace(-0.12, 0.12, 25), np.zeros(25), np.full(25, -0.1)]]
    g = Groom.from_polylines(behind, units="m")
    head = sphere_mesh((0.0, 0.0, 0.0), 0.04, rings=16, segments=32)
    cam = CameraConfig(eye=(0.0, 0.0, 0.4), target=(0.0, 0.0, 0.0), fov=40.0, z_near=0.05, z_far=10.0)
    viewer.head_vertex = None
    img = render_groom(g, None, camera=cam, color="uniform", head=head, viewer=viewer, head_color=(0.2, 0.4, 0.95))
    viewer.head_vertex = None  # later tests draw no head
    px, _, _ = project(g.points, cam, W, H)
    row = int(np.floor(px[0, 1]))
    centre_col = W // 2
    sphere_px, _, _ = project(np.array([[0.0, 0.0, 0.0], [0.04, 0.0, 0.0]]), cam, W, H)
    radius_px = sphere_px[1, 0] - sphere_px[0, 0]
    band = img[row - 1:row + 2].astype(int)  # the line's row, give or take the rasteriser's rounding
    inside = band[:, centre_col][np.argmax(band[:, centre_col].sum(axis=1))]
    outside = band[:, int(centre_col + radius_px + 8)][np.argmax(band[:, int(centre_col + radius_px + 8)].sum(axis=1))]
    brown = np.array([0.45, 0.3, 0.18]) * 255
    assert np.abs(outside - brown).sum() < 60  # the strand, unlit hair brown
    assert inside[2] > inside[0] + 40  # the (lit, blue) sphere


def test_strand_colors_modes_and_errors():
    g = scene()
    counts = g.strand_vertex_counts()
    for mode in ("region", "strand", "uniform", "groom"):
        c = strand_colors(g, mode)
        assert c.shape == (g.vertex_count, 3) and c.dtype == np.float32 and c.min() >= 0 and c.max() <= 1
    per_strand = strand_colors(g, "strand")
    assert np.array_equal(per_strand[0], per_strand[counts[0] - 1])  # one colour along a strand
    err = strand_colors(g, "error", values=np.arange(g.strand_count, dtype=float))
    assert not np.array_equal(err[0], err[-1])
    sel = np.zeros(g.vertex_count, dtype=bool)
    sel[3] = True
    c = strand_colors(g, "region", selection=sel)
    assert np.allclose(c[3], (1.0, 0.55, 0.05)) and not np.allclose(c[4], (1.0, 0.55, 0.05))
    with pytest.raises(ValueError, match="colour mode"):
        strand_colors(g, "rainbow")
    with pytest.raises(ValueError, match="error values"):
        strand_colors(g, "error")
    with pytest.raises(ValueError, match="fov"):
        CameraConfig(fov=200.0)
    with pytest.raises(ValueError, match="eye and target"):
        CameraConfig(eye=(0, 0, 0), target=(0, 0, 0))


def test_error_overlay_measures_the_distance_to_the_skinned_strands():
    """``--color error``: per strand, the largest distance between the strand and its reconstruction by
    skinning from the guides; 0 at rest, the displacement of a moved tip on that strand only."""
    from taichi_hair.cli.groom import skinning_error
    from taichi_hair.groom.skinning import select_guides

    rng = np.random.default_rng(3)
    lines = []
    for s in range(40):
        root = np.array([0.01 * (s % 8), 0.0, 0.01 * (s // 8)])
        t = np.linspace(0.0, 0.06, 8)[:, None]
        lines.append(root + t * np.array([0.0, -1.0, 0.0]) + rng.normal(scale=1e-3, size=(8, 3)) * t)
    g = Groom.from_polylines(lines, units="m")
    assert skinning_error(g, 0.25).max() < 1e-6
    guides = set(select_guides(g.points[g.strand_offsets[:-1]], 0.25, 0).tolist())
    k = next(s for s in range(40) if s not in guides)
    moved = g.copy()
    moved.rest_points = g.points.copy()
    moved.points[g.strand_offsets[k + 1] - 1] += (0.0, 0.0, 0.004)
    err = skinning_error(moved, 0.25)
    assert abs(err[k] - 0.004) < 1e-6 and np.delete(err, k).max() < 1e-6


def test_the_rasteriser_draws_the_picture_ggui_draws():
    """The same groom and head, drawn by GGUI's lines and by the rasteriser: the drawn pixels agree (IoU of
    the masks >= 0.95, measured 0.997 on the 86,000-strand groom at 960 x 720) and so do the colours
    (mean |difference| <= 4 of 255 per channel over the image; 0.11 measured there)."""
    from taichi_hair.groom.generators import HEAD_MESH_PATH, GeneratorConfig, generate_groom, load_head, read_obj_groups

    g = generate_groom(load_head(), GeneratorConfig(style="wavy", strands=300, vertices_per_strand=14, length=0.25,
                                                    seed=0))
    mesh = read_obj_groups(HEAD_MESH_PATH)[:2]
    cam = CameraConfig.framing(np.vstack([g.points, mesh[0]]), direction=(0.55, 0.25, 1.0))
    images = []
    for drawing in ("lines", "raster"):
        v = _viewer(drawing)
        images.append(render_groom(g, None, camera=cam, color="region", head=mesh, viewer=v).astype(np.int64))
        v.close()
    masks = [np.abs(img - 255 * BACKGROUND).sum(axis=2) > 24 for img in images]
    iou = (masks[0] & masks[1]).sum() / (masks[0] | masks[1]).sum()
    assert masks[0].sum() > 2000, masks[0].sum()  # the head and strands fill a good part of the image
    assert iou >= 0.95, iou
    assert np.abs(images[0] - images[1]).mean() <= 4.0, np.abs(images[0] - images[1]).mean()


def test_the_rasteriser_draws_lines_of_the_given_width_and_points_of_the_projected_radius():
    """A horizontal strand drawn 3 pixels wide covers 3 rows at each column it crosses; a point of radius r [m]
    at distance w covers a disk of f r / w pixels (f = (H / 2) / tan(fov / 2)), area pi (f r / w)^2 within 15 %."""
    v = _viewer("raster", line_width=3.0)
    cam = CameraConfig(eye=(0.0, 0.0, 0.4), target=(0.0, 0.0, 0.0), fov=40.0, z_near=0.05, z_far=10.0)
    g = Groom.from_polylines([np.c_[np.linspace(-0.05, 0.05, 5), np.full(5, 0.03), np.zeros(5)]], units="m")
    v.set_camera(cam)
    v.set_strands(g.points, g.strand_offsets, np.ones((g.vertex_count, 3)))
    r = 0.01
    v.set_points(np.array([[0.0, -0.03, 0.0]]), radius=r)
    v.render()
    img = v.image().astype(np.int64)
    v.close()
    drawn = np.abs(img - 255 * BACKGROUND).sum(axis=2) > 24
    px, _, _ = project(g.points, cam, W, H)
    row = int(np.floor(px[0, 1]))
    strand_band = drawn[row - 4:row + 5]
    cols = range(int(px[0, 0]) + 2, int(px[-1, 0]) - 2)
    assert all(strand_band[:, c].sum() == 3 for c in cols), [strand_band[:, c].sum() for c in cols]
    f = (H / 2) / np.tan(np.radians(cam.fov) / 2)
    expected = np.pi * (f * r / 0.4) ** 2
    disk = drawn[H // 2:].sum()  # the lower half holds the point alone
    assert abs(disk / expected - 1.0) <= 0.15, (disk, expected)


def test_a_viewer_on_the_cpu_arch_draws_with_the_rasteriser_and_names_a_bad_drawing():
    """``drawing="auto"`` under Taichi's CPU arch (this suite's) picks the rasteriser; an unknown drawing is a
    ValueError naming the choices, before any window opens."""
    v = _viewer("auto")
    assert v.drawing == "raster"
    v.close()
    with pytest.raises(ValueError, match="drawing must be one of auto, lines, raster"):
        ViewerGGUI(W, H, drawing="points")


def test_set_strands_again_with_the_same_strands_moves_them_and_takes_new_colours(viewer):
    """The grooming window calls ``set_strands`` every frame; with the same strand offsets it uploads the
    positions alone (and the colours only when a new array comes): the picture follows both."""
    g = scene()
    red = np.tile([[1.0, 0.0, 0.0]], (g.vertex_count, 1))
    viewer.set_camera(CAMERA)
    viewer.set_strands(g.points, g.strand_offsets, red)
    viewer.render()
    a = viewer.image().astype(np.int64)
    moved = g.points + np.array([0.03, 0.0, 0.0])
    viewer.set_strands(moved, g.strand_offsets, red)  # same offsets, same colour array
    viewer.render()
    b = viewer.image().astype(np.int64)
    viewer.set_strands(moved, g.strand_offsets, np.tile([[0.0, 1.0, 0.0]], (g.vertex_count, 1)))
    viewer.render()
    c = viewer.image().astype(np.int64)
    drawn = [np.abs(img - 255 * BACKGROUND).sum(axis=2) > 24 for img in (a, b, c)]
    px, _, _ = project(moved, CAMERA, W, H)
    rows, cols = np.nonzero(drawn[1])
    e = edge_indices(g.strand_offsets).reshape(-1, 2)
    assert segment_distance(np.c_[cols + 0.5, rows + 0.5], px[e[:, 0]], px[e[:, 1]]).max() <= 1.0  # where it moved
    assert (drawn[0] != drawn[1]).sum() > 100
    assert (b[drawn[1]][:, 0] > b[drawn[1]][:, 1]).all()  # still red
    assert (c[drawn[2]][:, 1] > c[drawn[2]][:, 0]).all()  # now green
