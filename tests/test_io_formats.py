"""Groom file formats: round trips, the real TressFX ponytail, hand-made files, bad input, atomic writes, CLI."""

import argparse
import os
import struct
import warnings

import numpy as np
import pytest

from taichi_hair.io import (Groom, GroomFormatError, detect_format, load_groom, read_tfxmesh, save_groom)
from taichi_hair.io import _util
from taichi_hair.io.cli import groom_stats, register

PONYTAIL = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "..", "shared", "data",
                        "ponytail")
PONYTAIL = os.environ.get("TAICHI_HAIR_PONYTAIL", os.path.normpath(PONYTAIL))
if not os.path.isdir(PONYTAIL):
    PONYTAIL = "/work/shared/data/ponytail"

EXT = {"hair": ".hair", "data": ".data", "ply": ".ply", "obj": ".obj", "tfx": ".tfx", "thair": ".thair.npz",
       "usd": ".usda"}


def has_pxr():
    try:
        import pxr  # noqa: F401
        return True
    except ImportError:
        return False


def random_groom(seed=0, strands=40, uniform=None, dtype=np.float32):
    """Random-walk strands of 2..30 vertices (or ``uniform``) in metres, every optional attribute set."""
    rng = np.random.default_rng(seed)
    counts = np.full(strands, uniform) if uniform else rng.integers(2, 31, size=strands)
    polys = [rng.normal(scale=0.1, size=3) + np.cumsum(rng.normal(scale=0.01, size=(int(c), 3)), axis=0)
             for c in counts]
    g = Groom.from_polylines([p.astype(dtype) for p in polys])
    g.radius = rng.uniform(2e-5, 8e-5, size=g.vertex_count).astype(np.float32)
    g.color = rng.random((g.strand_count, 3)).astype(np.float32)
    g.region = rng.integers(0, 4, size=g.strand_count)
    g.guide = rng.random(g.strand_count) < 0.3
    g.pinned = np.zeros(g.vertex_count, dtype=bool)
    g.pinned[g.strand_offsets[:-1]] = True
    g.rest_points = (g.points * dtype(0.5)).astype(dtype)
    g.params = {"stiffness": 0.5, "name": "random"}
    g.units = "m"
    return g.validate()


def bits(a):
    a = np.ascontiguousarray(a)
    return a.view(np.uint32 if a.dtype == np.float32 else np.uint64)


def assert_same_points(a: Groom, b: Groom):
    assert a.points.dtype == b.points.dtype
    np.testing.assert_array_equal(bits(a.points), bits(b.points))  # bit for bit
    np.testing.assert_array_equal(a.strand_offsets, b.strand_offsets)


WRITABLE = [("hair", {}), ("data", {}), ("ply", {}), ("ply", {"ascii": True}), ("obj", {}), ("thair", {}),
            ("tfx", {"version": 2.0}), ("tfx", {"version": 3.0}), ("tfx", {"version": 4.0}), ("usd", {}),
            ("usd", {"ext": ".usdc"})]


# ---------------------------------------------------------------------------- round trips
@pytest.mark.parametrize("fmt,opts", WRITABLE, ids=lambda v: str(v))
def test_round_trip_points_bit_for_bit(tmp_path, fmt, opts):
    if fmt == "usd" and not has_pxr():
        pytest.importorskip("pxr")
    opts = dict(opts)
    ext = opts.pop("ext", EXT[fmt])
    g = random_groom(seed=1, uniform=16 if fmt == "tfx" else None)
    p1, p2 = tmp_path / f"a{ext}", tmp_path / f"b{ext}"
    save_groom(g, p1, **opts)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a plausible groom in metres: no unit warning
        h1 = load_groom(p1)
    assert_same_points(g, h1)
    # Read -> write -> read in the same format is bit-exact, and for these writers the bytes too.
    save_groom(h1, p2, **opts)
    h2 = load_groom(p2)
    assert_same_points(h1, h2)
    if fmt in ("hair", "data", "ply", "obj", "tfx", "usd") and ext != ".usdc":
        assert p1.read_bytes() == p2.read_bytes()


def test_round_trip_attributes_native(tmp_path):
    g = random_groom(seed=2)
    g.point_frames = np.stack([g.points, g.points + np.float32(0.01)])
    g.frame_times = np.array([0.0, 2.0])
    g.validate()
    p = tmp_path / "g.thair.npz"
    save_groom(g, p)
    h = load_groom(p)
    for name in ("points", "strand_offsets", "radius", "color", "region", "guide", "rest_points", "pinned",
                 "point_frames", "frame_times"):
        a, b = getattr(g, name), getattr(h, name)
        assert a.dtype == b.dtype or name in ("strand_offsets", "region"), name
        np.testing.assert_array_equal(a, b, err_msg=name)
    assert h.params == g.params and h.units == "m"


def test_float64_kept_where_the_format_can(tmp_path):
    g = random_groom(seed=3, dtype=np.float64)
    for name, kw in (("g.thair.npz", {}), ("g.ply", {}), ("ga.ply", {"ascii": True})):
        save_groom(g, tmp_path / name, **kw)
        h = load_groom(tmp_path / name)
        assert h.points.dtype == np.float64
        assert_same_points(g, h)
    save_groom(g, tmp_path / "g.obj")
    h = load_groom(tmp_path / "g.obj", dtype=np.float64)
    assert_same_points(g, h)
    # float32-only formats round to float32, exactly as a cast would.
    save_groom(g, tmp_path / "g.hair")
    np.testing.assert_array_equal(load_groom(tmp_path / "g.hair").points, g.points.astype(np.float32))


def test_hair_and_ply_attributes(tmp_path):
    g = random_groom(seed=4)
    save_groom(g, tmp_path / "g.hair")
    h = load_groom(tmp_path / "g.hair")
    np.testing.assert_array_equal(h.radius, g.radius)  # thickness = 2 r is exact
    np.testing.assert_array_equal(h.color, g.per_vertex(g.color))
    save_groom(g, tmp_path / "g.ply")
    p = load_groom(tmp_path / "g.ply")
    np.testing.assert_array_equal(p.radius, g.radius)
    np.testing.assert_array_equal(p.region, g.region)
    np.testing.assert_array_equal(p.guide, g.guide)
    np.testing.assert_array_equal(p.pinned, g.pinned)
    np.testing.assert_array_equal(p.rest_points, g.rest_points)
    np.testing.assert_allclose(p.color, g.per_vertex(g.color), atol=0.5 / 255 + 1e-7)  # uchar colours


@pytest.mark.skipif(not has_pxr(), reason="usd-core not installed")
def test_usd_attributes_and_animation(tmp_path):
    from pxr import Usd, UsdGeom

    g = random_groom(seed=5)
    g.radius = np.linspace(1e-5, 5e-5, g.strand_count).astype(np.float32)  # per strand -> uniform widths
    rng = np.random.default_rng(0)
    g.point_frames = np.stack([g.points + rng.normal(scale=1e-3, size=g.points.shape).astype(np.float32)
                               for _ in range(3)])
    g.frame_times = np.array([1.0, 2.0, 3.0])
    g.validate()
    p = tmp_path / "anim.usdc"
    save_groom(g, p)
    stage = Usd.Stage.Open(str(p))
    curves = UsdGeom.BasisCurves(stage.GetPrimAtPath("/Groom/Strands"))
    assert list(curves.GetPointsAttr().GetTimeSamples()) == [1.0, 2.0, 3.0]
    assert curves.GetWidthsInterpolation() == "uniform"
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    h = load_groom(p)
    assert_same_points(g, h)
    np.testing.assert_array_equal(h.point_frames, g.point_frames)
    np.testing.assert_array_equal(h.frame_times, g.frame_times)
    np.testing.assert_array_equal(h.radius, g.radius)
    np.testing.assert_array_equal(h.rest_points, g.rest_points)
    np.testing.assert_array_equal(h.region, g.region)
    np.testing.assert_array_equal(h.guide, g.guide)
    np.testing.assert_array_equal(h.pinned, g.pinned)
    np.testing.assert_array_equal(h.color, g.color)
    assert h.params["stiffness"] == 0.5 and h.units == "m"


def test_cross_format_equality(tmp_path):
    """The same groom written as .hair, .data, .ply and USD reads back equal in all of them."""
    g = random_groom(seed=6)
    names = ["x.hair", "x.data", "x.ply", "x.obj"] + (["x.usda"] if has_pxr() else [])
    loaded = []
    for n in names:
        save_groom(g, tmp_path / n)
        loaded.append(load_groom(tmp_path / n))
    for n, h in zip(names, loaded):
        assert_same_points(g, h)
        np.testing.assert_array_equal(h.lengths(), loaded[0].lengths(), err_msg=n)


def test_convert_between_all_writable_formats(tmp_path):
    g = random_groom(seed=7, uniform=8)
    fmts = ["hair", "data", "ply", "obj", "tfx", "thair"] + (["usd"] if has_pxr() else [])
    cur = tmp_path / "start.thair.npz"
    save_groom(g, cur)
    for i, f in enumerate(fmts + fmts[:1]):
        nxt = tmp_path / f"step{i}{EXT[f]}"
        save_groom(load_groom(cur), nxt)
        cur = nxt
    assert_same_points(g, load_groom(cur))


# ---------------------------------------------------------------------------- the real ponytail
def _tfx3_header(path):
    with open(path, "rb") as fh:
        head = fh.read(296)
    version, strands, per_strand = struct.unpack_from("<fII", head, 0)
    (vertex_offset,) = struct.unpack_from("<I", head, 144)
    return version, strands, per_strand, vertex_offset


@pytest.mark.parametrize("name,strands,per_strand,both_ends", [
    ("back", 517, 16, True), ("front_top", 969, 16, False), ("side", 3066, 16, False), ("tail", 255, 16, False)])
def test_ponytail_loads(name, strands, per_strand, both_ends):
    path = os.path.join(PONYTAIL, f"{name}.tfx")
    if not os.path.exists(path):
        pytest.skip(f"{path} not present")
    version, s, v, off = _tfx3_header(path)
    assert (version, s, v, off) == (3.0, strands, per_strand, 296)  # counts as stated in the data README
    assert detect_format(path) == "tfx"
    with pytest.warns(UserWarning, match=r"scale=0\.01"):  # roughly centimetres
        g = load_groom(path)
    assert g.strand_count == strands and g.vertex_count == strands * per_strand
    assert g.params["tfx_version"] == 3.0 and g.params["tfx_both_ends_immovable"] is both_ends
    raw = np.fromfile(path, dtype="<f4", offset=296).reshape(-1, 3)  # independent parse of the positions
    np.testing.assert_array_equal(g.points, raw)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gm = load_groom(path, scale=0.01)
    assert gm.units == "m" and gm.points.dtype == np.float32
    med = float(np.median(gm.lengths()))
    assert 0.05 < med < 1.0  # 5 cm .. 1 m of hair
    if name == "tail":
        assert 0.6 < med < 0.8  # "about 71 units long"
    # "The top of the head is near y = 124": the roots of the front and side parts reach it.
    assert g.points[:, 1].max() < 130
    if name in ("front_top", "side"):
        assert 120 < g.points[:, 1].max()


def test_ponytail_converts_to_every_format(tmp_path):
    path = os.path.join(PONYTAIL, "back.tfx")
    if not os.path.exists(path):
        pytest.skip("ponytail not present")
    g = load_groom(path, scale=0.01)
    for f in ["hair", "data", "ply", "obj", "thair", "tfx"] + (["usd"] if has_pxr() else []):
        p = tmp_path / f"back{EXT[f]}"
        save_groom(g, p)
        assert_same_points(g, load_groom(p))


# ---------------------------------------------------------------------------- hand-made files (independent of the writers)
def test_tfx_v4_hand_made_pinned_from_w(tmp_path):
    ns, nv = 2, 4
    xyzw = np.zeros((ns * nv, 4), "<f4")
    xyzw[:, 0] = np.arange(ns * nv) * 0.01
    xyzw[:, 3] = 1.0
    xyzw[[0, 1, 4], 3] = 0.0
    data = struct.pack("<f7I", 4.0, ns, nv, 160, 0, 0, 0, 0) + bytes(128) + xyzw.tobytes()
    p = tmp_path / "h.tfx"
    p.write_bytes(data)
    g = load_groom(p)
    assert g.strand_count == 2 and g.vertex_count == 8
    np.testing.assert_array_equal(g.points, xyzw[:, :3])
    np.testing.assert_array_equal(g.pinned, [1, 1, 0, 0, 1, 0, 0, 0])
    p.write_bytes(data.replace(struct.pack("<f", 4.0), struct.pack("<f", 5.0), 1))
    with pytest.raises(GroomFormatError, match=r"h\.tfx.*unknown TressFX version 5\.0"):
        load_groom(p, format="tfx")


def test_tfx_v2_ascii_hand_made(tmp_path):
    text = ("version 2.0\nscale 1.0\nrotation 0 0 0\ntranslation 0 0 0\nbothEndsImmovable 0\n"
            "maxNumVerticesInStrand 3\nnumFollowHairsPerGuideHair 0\nmaxRadiusAroundGuideHair 0.1\n"
            "numStrands 2\nis sorted 1\n"
            "strand 0 numVerts 3 texcoord 0.5 0.5\n0 0 0\n0 -1 0\n0 -2 0.5\n"
            "strand 1 numVerts 2 texcoord 0.1 0.2\n1 0 0\n1 -1.5 0\n")
    p = tmp_path / "a.tfx"
    p.write_text(text)
    assert detect_format(p) == "tfx"
    g = load_groom(p, scale=0.1)
    np.testing.assert_array_equal(g.strand_offsets, [0, 3, 5])
    np.testing.assert_allclose(g.points[4], [0.1, -0.15, 0.0], rtol=1e-6)
    assert g.params["tfx_numFollowHairsPerGuideHair"] == 0 and g.params["tfx_is_sorted"] == 1
    p.write_text(text.replace("numStrands 2", "numStrands 3"))
    with pytest.raises(GroomFormatError, match="numStrands is 3 but the file holds 2 strands"):
        load_groom(p)
    p.write_text(text.replace("version 2.0", "version 7.0"))
    with pytest.raises(GroomFormatError, match=r"a\.tfx.*line 1.*unknown ASCII TressFX version 7\.0"):
        load_groom(p, format="tfx")


def test_tfxmesh(tmp_path):
    text = ("# TressFX collision mesh\nnumOfBones 2\n# bone index, name\n0 root\n1 head\n"
            "numOfVertices 3\n# i x y z nx ny nz b0 b1 b2 b3 w0 w1 w2 w3\n"
            "0 0 0 0 0 0 1 0 1 0 0 1 0 0 0\n1 1 0 0 0 0 1 1 0 0 0 0.5 0.5 0 0\n2 0 1 0 0 0 1 1 0 0 0 1 0 0 0\n"
            "numOfTriangles 1\n0 0 1 2\n")
    p = tmp_path / "m.tfxmesh"
    p.write_text(text)
    assert detect_format(p) == "tfxmesh"
    m = read_tfxmesh(p)
    assert m.vertices.shape == (3, 3) and m.normals.shape == (3, 3) and m.triangles.tolist() == [[0, 1, 2]]
    assert m.bone_names == ["root", "head"] and m.bone_weights[1].tolist() == [0.5, 0.5, 0, 0]
    p.write_text(text.replace("0 0 1 2\n", "0 0 1 7\n"))
    with pytest.raises(GroomFormatError, match=r"m\.tfxmesh.*triangle index is outside \[0, 3\)"):
        read_tfxmesh(p)
    p.write_text(text.replace("numOfVertices 3", "numOfVertices 300000000"))
    with pytest.raises(GroomFormatError, match="numOfVertices 300000000 is more than the file can hold"):
        read_tfxmesh(p)
    with pytest.raises(GroomFormatError, match="collision mesh"):
        load_groom(p)


def test_obj_hand_made_negative_and_slash_indices(tmp_path):
    text = ("# comment\no hair\nv 0 0 0\nv 0 1 0\nv 0 2 0\nl 1 2 3\n"
            "v 1 0 0\nv 1 1 0\nvt 0 0\nl -2/1 -1/1\nl 3 2\n")
    p = tmp_path / "h.obj"
    p.write_text(text)
    g = load_groom(p)
    np.testing.assert_array_equal(g.strand_offsets, [0, 3, 5, 7])
    np.testing.assert_array_equal(g.points[3:5], [[1, 0, 0], [1, 1, 0]])
    np.testing.assert_array_equal(g.points[5:7], [[0, 2, 0], [0, 1, 0]])
    p.write_text(text.replace("l 3 2", "l 3 9"))
    with pytest.raises(GroomFormatError, match=r"h\.obj: line 11, strand 2: 'l' index 9 refers to no vertex"):
        load_groom(p)
    p.write_text(text.replace("l 3 2", "l 0 1"))
    with pytest.raises(GroomFormatError, match="0 is invalid"):
        load_groom(p)


def test_ply_hand_made_ascii_with_colours_and_edges(tmp_path):
    text = ("ply\nformat ascii 1.0\ncomment hand made\nelement vertex 5\nproperty float x\nproperty float y\n"
            "property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n"
            "element strand 2\nproperty ushort segments\nelement edge 3\nproperty int vertex1\n"
            "property int vertex2\nend_header\n"
            "0 0 0 255 0 0\n0 1 0 255 0 0\n0 2 0 255 0 0\n1 0 0 0 0 255\n1 1 0 0 0 255\n2\n1\n0 1\n1 2\n3 4\n")
    p = tmp_path / "h.ply"
    p.write_text(text)
    g = load_groom(p)
    np.testing.assert_array_equal(g.strand_offsets, [0, 3, 5])
    np.testing.assert_array_equal(g.color[0], [1, 0, 0])
    # Without the strand element the edges define the strands.
    no_strand = text.replace("element strand 2\nproperty ushort segments\n", "").replace("2\n1\n0 1", "0 1")
    p.write_text(no_strand)
    np.testing.assert_array_equal(load_groom(p).strand_offsets, [0, 3, 5])
    # A list property in another element is parsed and skipped; big-endian binary is read too.
    pts = np.array([[0, 0, 0], [0, 1, 0], [0, 2, 0]], ">f4")
    head = ("ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
            "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
            "element strand 1\nproperty int segments\nend_header\n").encode()
    p.write_bytes(head + pts.tobytes() + bytes([3]) + np.array([0, 1, 2], ">i4").tobytes()
                  + np.array([2], ">i4").tobytes())
    np.testing.assert_array_equal(load_groom(p).points, pts.astype(np.float32))
    # hairutil's layout: per-vertex "thickness" (a diameter) and a strand element "nsegs".
    (tmp_path / "hu.ply").write_text(
        "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\nproperty float z\n"
        "property float thickness\nelement strand 2\nproperty ushort nsegs\nend_header\n"
        "0 0 0 0.5\n0 1 0 0.5\n0 2 0 0.5\n1 0 0 0.5\n1 1 0 0.5\n2\n1\n")
    g = load_groom(tmp_path / "hu.ply")
    np.testing.assert_array_equal(g.radius, [0.25] * 5)
    np.testing.assert_array_equal(g.strand_offsets, [0, 3, 5])
    p.write_text(text.replace("element strand 2", "element strand 3"))
    with pytest.raises(GroomFormatError, match=r"h\.ply"):
        load_groom(p)


@pytest.mark.parametrize("lengths", [(3, 3, 3, 3), (3, 4, 0, 3)], ids=["uniform", "mixed"])
def test_binary_ply_list_records_read_the_same_whether_uniform_or_walked(tmp_path, lengths):
    """An element with lists is read at once when every record's list has the first record's length
    (``ply._uniform_records``) and walked record by record otherwise; a scalar after the list (here a per-face
    "flags" int) and the strands that follow come out the same either way, and a record that breaks the
    uniformity late (the last one) sends the read down the walk."""
    pts = np.array([[0, 0, 0], [0, 1, 0], [0, 2, 0]], "<f4")
    head = ("ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
            f"property float z\nelement face {len(lengths)}\nproperty list uchar int vertex_indices\n"
            "property int flags\nelement strand 1\nproperty int segments\nend_header\n").encode()
    faces = b"".join(bytes([k]) + np.arange(k, dtype="<i4").tobytes() + np.array([7 + j], "<i4").tobytes()
                     for j, k in enumerate(lengths))
    p = tmp_path / "faces.ply"
    p.write_bytes(head + pts.tobytes() + faces + np.array([2], "<i4").tobytes())
    from taichi_hair.io import ply

    fmt, elements, body = ply._parse_header(p.read_bytes(), p)
    face = next(e for e in elements if e.name == "face")
    fast = ply._uniform_records(p.read_bytes(), face, body + pts.nbytes, "<", len(p.read_bytes()))
    assert (fast is not None) == (len(set(lengths)) == 1)
    if fast is not None:
        np.testing.assert_array_equal(fast[0]["flags"], [7, 8, 9, 10])
    g = load_groom(p)
    np.testing.assert_array_equal(g.points, pts)
    np.testing.assert_array_equal(g.strand_offsets, [0, 3])


def test_usc_skips_short_strands_with_a_warning(tmp_path):
    strands = [np.zeros((1, 3)), np.arange(6).reshape(2, 3), np.zeros((0, 3)), np.arange(9).reshape(3, 3) * 0.01]
    data = struct.pack("<i", len(strands)) + b"".join(
        struct.pack("<i", len(s)) + s.astype("<f4").tobytes() for s in strands)
    p = tmp_path / "h.data"
    p.write_bytes(data)
    with pytest.warns(UserWarning, match="skipped 2 of 4 strands with fewer than 2 points"):
        g = load_groom(p)
    assert g.strand_count == 2 and g.units == "m"
    np.testing.assert_array_equal(g.points, np.concatenate([strands[1], strands[3]]).astype(np.float32))


def test_ct2hair_bin(tmp_path):
    rng = np.random.default_rng(0)
    strands = [rng.normal(size=(n, 7)).astype("<f4") for n in (3, 5, 2)]
    data = struct.pack("<i", 3) + b"".join(struct.pack("<i", len(s)) + s.tobytes() for s in strands)
    p = tmp_path / "h.bin"
    p.write_bytes(data)
    assert detect_format(p) == "ct2hair"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        g = load_groom(p)
    np.testing.assert_array_equal(g.points, np.concatenate(strands)[:, :3])
    np.testing.assert_array_equal(g.strand_offsets, [0, 3, 8, 10])


# ---------------------------------------------------------------------------- detection
@pytest.mark.parametrize("fmt,opts", [("hair", {}), ("data", {}), ("ply", {}), ("obj", {}), ("thair", {}),
                                      ("tfx", {"version": 3.0}), ("tfx", {"version": 4.0}),
                                      ("tfx", {"version": 2.0}), ("usd", {})], ids=str)
def test_detect_by_content_with_a_wrong_extension(tmp_path, fmt, opts):
    if fmt == "usd":
        pytest.importorskip("pxr")
    g = random_groom(seed=8, uniform=8)
    right = tmp_path / f"g{EXT[fmt]}"
    save_groom(g, right, **opts)
    wrong_ext = ".ply" if fmt != "ply" else ".hair"
    wrong = tmp_path / f"misnamed{wrong_ext}"
    wrong.write_bytes(right.read_bytes())
    assert detect_format(wrong) == fmt
    assert_same_points(g, load_groom(wrong))


# ---------------------------------------------------------------------------- bad input
def _hair_bytes(tmp_path):
    g = random_groom(seed=9, strands=3)
    save_groom(g, tmp_path / "ok.hair")
    return bytearray((tmp_path / "ok.hair").read_bytes())


def test_bad_inputs_name_the_file_and_the_problem(tmp_path):
    p = tmp_path / "bad.hair"
    cases = []
    b = _hair_bytes(tmp_path)
    b[4:8] = struct.pack("<I", 10_000_000)
    cases.append(("hair", bytes(b), r"bad\.hair: byte 4: strand count 10000000 is more than the file can hold"))
    b = _hair_bytes(tmp_path)
    b[12:16] = struct.pack("<I", 0x23)
    cases.append(("hair", bytes(b), r"bad\.hair: byte 12: unknown array flags 0x20"))
    b = _hair_bytes(tmp_path)
    cases.append(("hair", bytes(b[:-5]), r"bad\.hair: byte 8: point count \d+ is more than the file can hold"))
    b = _hair_bytes(tmp_path)
    cases.append(("hair", bytes(b) + b"\0", r"bad\.hair: byte \d+: file size \d+ does not match the header"))
    b = _hair_bytes(tmp_path)
    b[128 + 6:128 + 10] = struct.pack("<f", float("nan"))  # first point's x, after 3 uint16 segment counts
    cases.append(("hair", bytes(b), r"bad\.hair: strand 0: field 'points' has a non-finite value at vertex 0"))
    b = _hair_bytes(tmp_path)
    b[0:4] = b"HAIX"
    cases.append(("hair", bytes(b), r"bad\.hair: byte 0: expected the magic 'HAIR'"))
    cases.append(("hair", b"", r"bad\.hair: the file is empty"))
    cases.append(("data", struct.pack("<ii", -5, 0), r"bad\.hair: byte 0: strand count is -5"))
    cases.append(("data", struct.pack("<iii", 1, -2, 0), r"byte 4, strand 0: point count is -2"))
    cases.append(("data", struct.pack("<ii", 1, 50) + bytes(24), r"byte 4, strand 0: point count 50 needs 600 bytes"))
    cases.append(("data", struct.pack("<ii", 1, 2) + np.array([0, 0, 0, 1, np.nan, 0], "<f4").tobytes(),
                  r"strand 0: field 'points' has a non-finite value at vertex 1"))
    cases.append(("data", struct.pack("<ii", 1, 2) + bytes(28), r"4 bytes follow the last of 1 strands"))
    cases.append(("tfx", struct.pack("<f", 9.0) + bytes(300), r"unknown TressFX version 9\.0"))
    cases.append(("tfx", struct.pack("<f4I", 3.0, 5000, 16, 0, 0) + bytes(124)
                  + struct.pack("<6I", 296, 0, 0, 0, 0, 0) + bytes(128 + 64),
                  r"byte 4: strand count 5000 is more than the file can hold"))
    cases.append(("tfx", struct.pack("<f7I", 4.0, 1, 12, 160, 0, 0, 0, 0) + bytes(128 + 192),
                  r"byte 8: vertices per strand is 12; expected a power of two"))
    cases.append(("ply", b"ply\nformat binary_little_endian 1.0\nelement vertex -3\nend_header\n",
                  r"line 3: element 'vertex' has a negative count -3"))
    cases.append(("ply", b"ply\nformat binary_big_endian 2.0\nend_header\n", r"line 2: unsupported format line"))
    cases.append(("ply", b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
                         b"property float z\nelement strand 1\nproperty int segments\nend_header\n"
                         b"0 0 0\n0 nan 0\n1\n", r"strand 0: field 'points' has a non-finite value at vertex 1"))
    cases.append(("obj", b"v 0 0 0\nv 1 1 1\n", r"no 'l' \(polyline\) records"))
    cases.append(("obj", b"v 0 0 0\nv 1 x 1\nl 1 2\n", r"'v' coordinate is not a number"))
    cases.append(("thair", b"PK\x03\x04garbage", r"not a readable \.npz archive"))
    for fmt, data, pattern in cases:
        p.write_bytes(data)
        with pytest.raises(GroomFormatError, match=pattern) as info:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                load_groom(p, format=fmt)
        assert isinstance(info.value, ValueError) and str(p) in str(info.value), (fmt, pattern)


def test_native_rejects_pickles_and_lying_headers(tmp_path):
    p = tmp_path / "x.thair.npz"
    np.savez(p, format_version=np.int64(1), points=np.zeros((2, 3), np.float32),
             strand_offsets=np.array([0, 2]), params=np.array([{"a": 1}], dtype=object))
    with pytest.raises(GroomFormatError, match="holds Python objects"):
        load_groom(p)
    np.savez(p, format_version=np.int64(7), points=np.zeros((2, 3), np.float32), strand_offsets=np.array([0, 2]))
    with pytest.raises(GroomFormatError, match="unknown format_version"):
        load_groom(p)


def test_empty_file_every_format(tmp_path):
    for fmt in ("hair", "data", "ct2hair", "ply", "tfx", "obj", "thair") + (("usd",) if has_pxr() else ()):
        p = tmp_path / f"empty.{fmt}"
        p.write_bytes(b"")
        with pytest.raises(GroomFormatError, match=rf"empty\.{fmt}: the file is empty"):
            load_groom(p, format=fmt)
    with pytest.raises(GroomFormatError, match="the file is empty"):
        detect_format(p)


# ---------------------------------------------------------------------------- atomic writes
class _FailingFile:
    """Accepts ``limit`` bytes, then raises like a full disk."""

    def __init__(self, fh, limit):
        self.fh, self.left = fh, limit

    def write(self, b):
        if len(b) > self.left:
            self.fh.write(bytes(b)[:self.left])
            self.left = 0
            raise OSError(28, "No space left on device (simulated)")
        self.left -= len(b)
        return self.fh.write(b)

    def close(self):
        self.fh.close()


@pytest.mark.parametrize("fmt", ["hair", "data", "ply", "obj", "tfx"])
def test_failing_write_leaves_no_partial_file(tmp_path, monkeypatch, fmt):
    g = random_groom(seed=10, uniform=8)
    target = tmp_path / f"out{EXT[fmt]}"
    target.write_bytes(b"previous content")
    real = _util._fdopen
    monkeypatch.setattr(_util, "_fdopen", lambda fd: _FailingFile(real(fd), 200))
    with pytest.raises(OSError, match="simulated"):
        save_groom(g, target)
    assert target.read_bytes() == b"previous content"
    assert sorted(os.listdir(tmp_path)) == [target.name]  # no temporary left behind
    new = tmp_path / f"new{EXT[fmt]}"
    with pytest.raises(OSError):
        save_groom(g, new)
    assert not new.exists()


@pytest.mark.parametrize("fmt", ["thair", "usd", "hair"])
def test_failing_rename_leaves_no_partial_file(tmp_path, monkeypatch, fmt):
    if fmt == "usd":
        pytest.importorskip("pxr")
    g = random_groom(seed=11)
    target = tmp_path / f"out{EXT[fmt]}"

    def boom(src, dst):
        assert os.path.dirname(os.path.abspath(src)) == str(tmp_path)  # same directory: an atomic rename
        raise OSError("rename failed (simulated)")

    monkeypatch.setattr(_util.os, "replace", boom)
    with pytest.raises(OSError, match="simulated"):
        save_groom(g, target)
    assert os.listdir(tmp_path) == []


# ---------------------------------------------------------------------------- Groom
def test_groom_helpers():
    polys = [np.array([[0, 0, 0], [0, 0, 1], [0, 1, 1]], np.float32), np.array([[1, 0, 0], [1, 0, 3]], np.float32)]
    g = Groom.from_polylines(polys, radius=np.array([1.0, 2.0], np.float32))
    assert g.strand_count == 2 and g.vertex_count == 5
    np.testing.assert_array_equal(g.lengths(), [2.0, 3.0])
    np.testing.assert_array_equal(g.strand(1), polys[1])
    np.testing.assert_array_equal(g.strand(-1), polys[1])
    assert all(np.array_equal(a, b) for a, b in zip(g.to_polylines(), polys))
    s = g.scaled(0.01, units="m")
    assert s.points.dtype == np.float32 and s.units == "m"
    np.testing.assert_allclose(s.lengths(), [0.02, 0.03], rtol=1e-6)
    np.testing.assert_allclose(s.radius, [0.01, 0.02], rtol=1e-6)
    np.testing.assert_array_equal(g.per_vertex(g.radius), [1, 1, 1, 2, 2])


@pytest.mark.parametrize("change,pattern", [
    (lambda g: g.points.__setitem__((3, 1), np.nan), r"strand 1: field 'points' has a non-finite value at vertex 0"),
    (lambda g: setattr(g, "radius", np.array([1.0, -1.0])), r"strand 1: field 'radius' is negative"),
    (lambda g: setattr(g, "strand_offsets", np.array([0, 3, 3, 5])), r"strand 1: field 'strand_offsets' is not "
                                                                        r"increasing"),
    (lambda g: setattr(g, "strand_offsets", np.array([0, 1, 5])), r"strand 0: has 1 vertex"),
    (lambda g: setattr(g, "strand_offsets", np.array([0, 3, 4])), r"must end at the vertex count 5"),
    (lambda g: setattr(g, "region", np.array([1, 2, 3])), r"field 'region' must be an integer array of shape"),
    (lambda g: setattr(g, "params", {"x": object()}), r"field 'params' is not JSON-able"),
    (lambda g: setattr(g, "rest_points", np.zeros((4, 3))), r"field 'rest_points' must have the shape"),
])
def test_groom_validate_names_strand_and_field(change, pattern):
    g = Groom.from_polylines([np.zeros((3, 3)) + np.arange(3)[:, None], np.ones((2, 3)) * [[1], [2]]])
    change(g)
    with pytest.raises(ValueError, match=pattern):
        g.validate()


def test_unit_warning_suggests_a_scale(tmp_path):
    g = random_groom(seed=12).scaled(1000.0)  # millimetres
    save_groom(g, tmp_path / "mm.hair")
    with pytest.warns(UserWarning, match=r"mm\.hair: median strand length .* pass scale=0\.001"):
        load_groom(tmp_path / "mm.hair")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        h = load_groom(tmp_path / "mm.hair", scale=0.001)
    np.testing.assert_allclose(h.points, g.points * 0.001, rtol=1e-6)


# ---------------------------------------------------------------------------- CLI
def _parser():
    p = argparse.ArgumentParser()
    register(p.add_subparsers(dest="command", required=True))
    return p


def test_cli_convert_and_info(tmp_path, capsys):
    g = random_groom(seed=13)
    src = tmp_path / "g.hair"
    save_groom(g, src)
    dst = tmp_path / "g.out"
    args = _parser().parse_args(["convert", str(src), str(dst), "--to", "ply", "--scale", "2"])
    assert args.func(args) == 0
    h = load_groom(dst, format="ply")
    np.testing.assert_array_equal(h.points, g.points * np.float32(2))
    args = _parser().parse_args(["info", str(src)])
    assert args.func(args) == 0
    out = capsys.readouterr().out
    s = groom_stats(g)
    assert f"strands {g.strand_count}, vertices {g.vertex_count}" in out
    assert f"median {np.median(g.lengths()):.6g}" in out and "curvature" in out
    # Turning angle of a quarter circle of k edges: each interior vertex turns by (pi/2)/k.
    k = 16
    t = np.linspace(0, np.pi / 2, k + 1)
    arc = Groom.from_polylines([np.c_[np.cos(t), np.sin(t), np.zeros_like(t)] * 0.1])
    st = groom_stats(arc)
    assert st["turning_angle_deg"]["mean"] == pytest.approx(90.0 / k, rel=1e-9)
    # Curvature of a circle of radius 0.1: 2 sin(theta/2) / chord -> 1 / 0.1 as k grows.
    assert st["curvature_per_unit"]["mean"] == pytest.approx(10.0, rel=2e-3)
    assert s["strands"] == g.strand_count


def test_cli_bad_file_raises_format_error(tmp_path):
    bad = tmp_path / "bad.hair"
    bad.write_bytes(b"HAIR" + bytes(20))
    args = _parser().parse_args(["info", str(bad)])
    with pytest.raises(GroomFormatError, match=r"bad\.hair"):
        args.func(args)
    from taichi_hair.io.cli import main
    assert main(["info", str(bad)]) == 2
    args = _parser().parse_args(["convert", str(bad), str(tmp_path / "out.xyz")])
    with pytest.raises(ValueError, match="pass --to"):
        args.func(args)


def test_cli_prints_the_unit_warning_as_one_line(tmp_path, capsys):
    g = random_groom(seed=14).scaled(100.0)  # centimetres
    save_groom(g, tmp_path / "cm.hair")
    args = _parser().parse_args(["info", str(tmp_path / "cm.hair")])
    assert args.func(args) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("warning: ") and "scale=0.01" in err[0]


def test_ponytail_into_the_builder():
    from taichi_hair import GroomBuilder, RodMaterial

    path = os.path.join(PONYTAIL, "tail.tfx")
    if not os.path.exists(path):
        pytest.skip("ponytail not present")
    g = load_groom(path, scale=0.01)
    b = GroomBuilder()
    idx = g.add_to_builder(b, RodMaterial(radius=4e-5))
    assert idx == list(range(255)) and b.strand_count == 255


def test_written_files_get_normal_permissions(tmp_path):
    g = random_groom(seed=15)
    mask = os.umask(0o022)
    os.umask(mask)
    save_groom(g, tmp_path / "new.hair")
    assert (tmp_path / "new.hair").stat().st_mode & 0o777 == 0o666 & ~mask  # not mkstemp's 0600
    (tmp_path / "kept.ply").write_bytes(b"x")
    os.chmod(tmp_path / "kept.ply", 0o640)
    save_groom(g, tmp_path / "kept.ply")
    assert (tmp_path / "kept.ply").stat().st_mode & 0o777 == 0o640  # an existing file keeps its mode


@pytest.mark.parametrize("fmt,opts,dtype", [("obj", {}, np.float32), ("obj", {}, np.float64),
                                            ("ply", {"ascii": True}, np.float32), ("ply", {"ascii": True}, np.float64),
                                            ("tfx", {"version": 2.0}, np.float32)], ids=str)
def test_text_formats_exact_for_extreme_values(tmp_path, fmt, opts, dtype):
    info = np.finfo(dtype)
    # No subnormals: ti.init (the session fixture) turns on flush-to-zero for the whole process,
    # so NumPy's text parsing returns 0 for them (binary formats copy their bits untouched).
    special = np.array([info.max, -info.max, info.tiny, -info.tiny, -0.0, 0.1, 1 / 3, -2.5e-7,
                        123456.789, np.nextafter(dtype(1), dtype(2))], dtype=dtype)
    rng = np.random.default_rng(3)
    vals = np.concatenate([special, (rng.normal(size=200) * 10.0 ** rng.integers(-30, 30, 200)).astype(dtype)])
    assert np.all((vals == 0) | (np.abs(vals) >= info.tiny))
    vals = vals[: len(vals) // 6 * 6]
    g = Groom(points=vals.reshape(-1, 3), strand_offsets=np.arange(0, len(vals) // 3 + 1, 2)).validate()
    p = tmp_path / f"x{EXT[fmt]}"
    save_groom(g, p, **opts)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        h = load_groom(p, **({"dtype": dtype} if fmt == "obj" else {}))
    assert_same_points(g, h)


def test_missing_usd_core_gives_a_clear_error(tmp_path, monkeypatch):
    import sys

    for name in [m for m in sys.modules if m == "pxr" or m.startswith("pxr.")]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, "pxr", None)  # "import pxr" now raises ImportError
    g = random_groom(seed=16)
    with pytest.raises(ImportError, match="pip install usd-core"):
        save_groom(g, tmp_path / "x.usda")
    assert not (tmp_path / "x.usda").exists()
    (tmp_path / "y.usda").write_text("#usda 1.0\n")
    with pytest.raises(ImportError, match="usd-core"):
        load_groom(tmp_path / "y.usda", isolate=False)
    save_groom(g, tmp_path / "g.hair")
    args = _parser().parse_args(["convert", str(tmp_path / "g.hair"), str(tmp_path / "g.usda")])
    with pytest.raises(ValueError, match="usd-core"):  # the CLI turns it into a one-line error
        args.func(args)
