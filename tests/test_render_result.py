"""Pictures of results: Kajiya-Kay shading (closed forms), the result reader (every output ``simulate``
writes), and ``taichi-hair render`` of frames, sequences, movies and turntables with the body posed."""

import json
import os

import numpy as np
import pytest

from taichi_hair.cli.main import main
from taichi_hair.io import Groom, save_groom
from taichi_hair.io.errors import GroomFormatError
from taichi_hair.io.result import load_result
from taichi_hair.groom.shading import HairShading, arc_fraction, shade_strands, vertex_tangents


# --------------------------------------------------------------------------- shading (NumPy)
def test_tangents_and_arc_fraction_of_a_straight_and_a_bent_strand():
    """Straight strand along x: t = (1, 0, 0) everywhere, s = i / (n - 1); an L-shaped strand: the corner's
    central difference is (1, 1, 0) / sqrt(2), s = 0, 1/2, 1 (two unit edges)."""
    a = np.c_[np.linspace(0, 1, 5), np.zeros(5), np.zeros(5)]
    b = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0]])
    off = np.array([0, 5, 8])
    p = np.vstack([a, b])
    t = vertex_tangents(p, off)
    np.testing.assert_allclose(t[:5], np.tile([1.0, 0, 0], (5, 1)), atol=1e-12)
    np.testing.assert_allclose(t[6], [2 ** -0.5, 2 ** -0.5, 0], atol=1e-12)
    np.testing.assert_allclose(arc_fraction(p, off), [0, 0.25, 0.5, 0.75, 1, 0, 0.5, 1], atol=1e-12)


def test_kajiya_kay_diffuse_is_the_sine_of_tangent_and_light():
    """No specular, no darkening, ambient 0, k_d 1: colour = base sin(t, l).  Light along y on a strand
    along x: sin = 1; on a strand along (1, 1, 0) / sqrt(2): sin = 1 / sqrt(2) (tolerance 1e-6, f32)."""
    sh = HairShading(ambient=0.0, diffuse=1.0, specular_primary=0.0, specular_secondary=0.0, root_darkening=1.0)
    s = np.linspace(0, 1, 4)
    p = np.vstack([np.c_[s, 0 * s, 0 * s], np.c_[s, s, 0 * s]])
    c = shade_strands(p, np.array([0, 4, 8]), (0.5, 0.5, 0.5), eye=(0, 0, 5), light_direction=(0, 1, 0), shading=sh)
    np.testing.assert_allclose(c[:4], 0.5, atol=1e-6)
    np.testing.assert_allclose(c[4:], 0.5 * 2 ** -0.5, atol=1e-6)


def test_roots_are_darker_than_tips_and_highlights_brighten():
    """Root darkening 0.45: with only the diffuse term the root's colour is 0.45 x the tip's; the default
    speculars only add light (colour >= the diffuse-only colour, everywhere)."""
    s = np.linspace(0, 1, 11)
    p = np.c_[s, 0 * s, 0 * s]
    off = np.array([0, 11])
    diff = HairShading(specular_primary=0.0, specular_secondary=0.0)
    c = shade_strands(p, off, (0.4, 0.3, 0.2), eye=(0, 0, 3), shading=diff)
    np.testing.assert_allclose(c[0], 0.45 * c[-1], rtol=1e-5)
    full = shade_strands(p, off, (0.4, 0.3, 0.2), eye=(0, 0, 3))
    assert np.all(full >= c - 1e-7) and np.any(full > c + 1e-3)


def test_strain_colors_are_red_stretched_blue_compressed_white_at_rest():
    from taichi_hair.cli.render import strain_colors

    rest = np.c_[np.arange(4.0), np.zeros(4), np.zeros(4)]
    p = rest.copy()
    p[3, 0] = 2.0 + 1.02  # last edge +2 %: its vertices red
    p[0, 0] = 0.005  # first edge -0.5 %: blue, half way
    c = strain_colors(p, rest, np.array([0, 4]))
    np.testing.assert_allclose(c[3], [0.85, 0.1, 0.1], atol=1e-6)
    np.testing.assert_allclose(c[0], 1 + 0.5 * (np.array([0.1, 0.3, 0.9]) - 1), atol=1e-6)


# --------------------------------------------------------------------------- results
def _polylines():
    t = np.linspace(0.0, 1.0, 8)
    return [np.c_[0.02 * k + 0 * t, -0.1 * t, 0 * t] for k in range(-2, 3)]


def test_load_result_reads_a_groom_file_a_thair_with_frames_and_refuses_a_plain_folder(tmp_path):
    g = Groom.from_polylines(_polylines(), units="m")
    save_groom(g, tmp_path / "one.tfx")
    r = load_result(tmp_path / "one.tfx")
    assert r.frame_count == 1 and np.allclose(r.positions[0], g.points)
    g.point_frames = np.stack([g.points, g.points + np.float32(0.01)])
    g.frame_times = np.arange(2.0)
    save_groom(g, tmp_path / "anim.thair.npz")
    r = load_result(tmp_path / "anim.thair.npz")
    assert r.frame_count == 2 and np.allclose(r.positions[1] - r.positions[0], 0.01)
    with pytest.raises(GroomFormatError, match="without frames.npz"):
        load_result(tmp_path)
    np.savez(tmp_path / "x.npz", positions=np.zeros((1, 4, 3)))
    with pytest.raises(GroomFormatError, match="strand_vertex_start"):
        load_result(tmp_path / "x.npz")


# --------------------------------------------------------------------------- the command (GGUI)
@pytest.fixture(scope="module")
def vulkan():
    from taichi_hair.render import ViewerGGUI

    try:
        ViewerGGUI(16, 16, show_window=False).close()
    except Exception as exc:  # no Vulkan device at all: say so instead of a crash
        pytest.skip(f"GGUI needs a Vulkan device (mesa-vulkan-drivers on a CPU machine): {exc}")


@pytest.fixture(scope="module")
def result_dir(tmp_path_factory):
    """A hand-made simulate folder: 5 strands whose frame k is translated by k cm along x, and a body (a
    box mesh) turned by 90 deg about y at frame 2; contact states free at frames 0-1, and at frame 2 strand 0
    sticking, strand 1 sliding."""
    d = tmp_path_factory.mktemp("res")
    g = Groom.from_polylines(_polylines(), units="m")
    pos = np.stack([g.points + np.float32([0.01 * k, 0, 0]) for k in range(3)])
    import trimesh

    box = trimesh.creation.box(extents=(0.06, 0.06, 0.06))
    rot = np.stack([np.eye(3), np.eye(3), [[0, 0, 1], [0, 1, 0], [-1, 0, 0]]])[:, None]
    cst = np.zeros(pos.shape[:2], np.int8)
    off = g.strand_offsets
    cst[2, off[0]:off[1]], cst[2, off[1]:off[2]] = 1, 2
    np.savez(d / "frames.npz", positions=pos, fps=np.float64(24), vertex_contact_state=cst,
             strand_vertex_start=g.strand_offsets[:-1],
             strand_vertex_count=np.diff(g.strand_offsets), sphere_radius=np.float64(0),
             body_rotation=rot, body_translation=np.zeros((3, 1, 3)) + [0, 0.05, 0],
             collider_0_vertices=np.asarray(box.vertices, np.float32), collider_0_faces=np.asarray(box.faces),
             collider_0_body=np.int64(0))
    return d


def test_the_result_poses_its_body_at_each_frame(result_dir):
    """Body vertices at frame k: R_k v + T_k (frame 2: (x, y, z) -> (z, y, -x), lifted 5 cm)."""
    r = load_result(result_dir)
    v0 = r.meshes[0][0].astype(np.float64)
    (v2, _), = r.body_meshes(2)
    np.testing.assert_allclose(v2, np.c_[v0[:, 2], v0[:, 1] + 0.05, -v0[:, 0]], atol=1e-7)


def _drawn_columns(path):
    import matplotlib.image as mpimg

    img = (mpimg.imread(path)[:, :, :3] * 255).round().astype(int)
    return np.nonzero((np.abs(img - img[0, 0]).sum(axis=2) > 30).any(axis=0))[0]


CAM = ["--eye", "0", "-0.05", "0.5", "--target", "0", "-0.05", "0", "--fov", "40", "--size", "160", "120",
       "--head", "none", "--quiet"]


def test_render_draws_the_frame_asked_not_frame_zero(vulkan, result_dir, tmp_path, capsys):
    """Frame 2 is frame 0 moved 2 cm right: its drawn pixels sit right of frame 0's (2 cm at 0.5 m with a
    40 deg fov = 0.02 / (2 x 0.5 tan 20 deg) x 120 px = 6.6 px; the mean column moves by 4-9 px)."""
    a, b = tmp_path / "f0.png", tmp_path / "f2.png"
    assert main(["render", str(result_dir), "--frame", "0", "--out", str(a)] + CAM) == 0
    assert main(["render", str(result_dir), "--out", str(b)] + CAM) == 0  # the default: the last frame
    shift = _drawn_columns(b).mean() - _drawn_columns(a).mean()
    assert 4.0 < shift < 9.0, shift
    assert "frame 2 of 3" in capsys.readouterr().out


def test_render_sequences_movies_and_turntables(vulkan, result_dir, tmp_path):
    """--frames 0:3 --out DIR: 3 PNGs; a GIF holds 3 frames; an MP4 decodes to 3 frames of the asked size; a
    turntable of 4 views gives 4 images."""
    from PIL import Image

    assert main(["render", str(result_dir), "--frames", "0:3", "--out", str(tmp_path / "seq"),
                 "--movie", str(tmp_path / "m.gif")] + CAM) == 0
    assert sorted(os.listdir(tmp_path / "seq")) == [f"frame_{k:05d}.png" for k in range(3)]
    assert Image.open(tmp_path / "m.gif").n_frames == 3
    assert main(["render", str(result_dir), "--frames", "0:3", "--movie", str(tmp_path / "m.mp4")] + CAM) == 0
    import imageio.v2 as imageio

    # Iterated, not list()ed: the reader reports len() = inf for an mp4 and list() preallocates from it.
    frames = [f for f in imageio.get_reader(str(tmp_path / "m.mp4"), format="FFMPEG")]
    assert len(frames) == 3 and frames[0].shape[:2] == (120, 160)
    assert main(["render", str(result_dir), "--turntable", "4", "--out", str(tmp_path / "turn")] + CAM) == 0
    assert len(os.listdir(tmp_path / "turn")) == 4


def test_render_draws_the_body_by_default(vulkan, result_dir, tmp_path):
    """Without --head the result's box (6 cm, at y = 5 cm) is drawn: more pixels than with --head none."""
    cam = [c for c in CAM if c not in ("--head", "none")]
    a, b = tmp_path / "body.png", tmp_path / "nobody.png"
    assert main(["render", str(result_dir), "--out", str(a)] + cam) == 0
    assert main(["render", str(result_dir), "--out", str(b)] + CAM) == 0
    assert len(_drawn_columns(a)) > len(_drawn_columns(b)) + 10


@pytest.mark.parametrize("extra, message", [
    (["--fov", "0", "--out", "x.png"], "--fov must be in (0, 180)"),
    (["--frame", "7", "--out", "x.png"], "--frame 7: the result has 3 frames"),
    (["--frames", "5:9", "--out", "d"], "no frame of the 3"),
    (["--frames", "0:3", "--turntable", "3", "--out", "d"], "--turntable turns the camera around one frame"),
    (["--frames", "0:3"], "give --out DIR"),
    (["--hair-color", "purple-ish", "--out", "x.png"], "--hair-color: expected a name"),
    (["--movie", "x.avi"], "--movie: the file must end in"),
    (["--out", "x.jpg"], "name it .png"),
])
def test_render_refuses_bad_options_in_one_line(result_dir, extra, message, capsys):
    rc = main(["render", str(result_dir)] + extra)
    err = capsys.readouterr().err.strip()
    assert rc == 2 and message in err and "\n" not in err, err


def test_render_colours_sticking_blue_and_sliding_red(vulkan, result_dir, tmp_path, capsys):
    """--color contact (CONTACT_COLORS): frame 2 has a sticking and a sliding strand, so blue-dominant
    (b > r + 80) and red-dominant (r > b + 80) pixels; frame 0 is all free (grey): neither.  A result
    without contact states is refused in one line."""
    import matplotlib.image as mpimg

    counts = []
    for k in (0, 2):
        out = tmp_path / f"c{k}.png"
        assert main(["render", str(result_dir), "--frame", str(k), "--color", "contact", "--out", str(out)]
                    + CAM) == 0
        img = (mpimg.imread(out)[:, :, :3] * 255).astype(int)
        counts.append((int((img[..., 2] > img[..., 0] + 80).sum()), int((img[..., 0] > img[..., 2] + 80).sum())))
    assert counts[0] == (0, 0) and min(counts[1]) > 20, counts
    data = dict(np.load(result_dir / "frames.npz"))
    del data["vertex_contact_state"]
    np.savez(tmp_path / "frames.npz", **data)
    capsys.readouterr()
    assert main(["render", str(tmp_path / "frames.npz"), "--color", "contact", "--out", str(tmp_path / "x.png")]
                + CAM) == 2
    err = capsys.readouterr().err.strip()
    assert "has no contact states" in err and "\n" not in err, err


def test_render_of_a_simulate_folder_round_trip(vulkan, tmp_path, capsys):
    """The folder a real run writes renders as is (the README's main job's output: hang, 4 strands here),
    ``info`` reads it, and ``convert`` turns its frames into a USD file with the same frames, bit for bit."""
    out = tmp_path / "hang"
    assert main(["simulate", "hang", "--strands", "4", "--frames", "2", "--out", str(out), "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["frames"] == 2
    data = np.load(out / "frames.npz")
    assert data["body_rotation"].shape == (3, 1, 3, 3)
    assert main(["render", str(out), "--out", str(tmp_path / "h.png"), "--quiet", "--size", "64", "48"]) == 0
    assert (tmp_path / "h.png").stat().st_size > 100
    capsys.readouterr()
    assert main(["info", str(out)]) == 0 and "animation frames: 3" in capsys.readouterr().out
    usd = tmp_path / "not" / "yet" / "h.usda"  # convert makes the folder
    assert main(["convert", str(out / "frames.npz"), str(usd)]) == 0
    r = load_result(usd)
    assert r.frame_count == 3 and np.array_equal(r.positions, data["positions"])
