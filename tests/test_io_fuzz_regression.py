"""Regression tests of the readers' fault-injection run (issue 17; ``benchmarks/fuzz_readers.py``).

Each test states one claim about a bad file: the reader raises GroomFormatError, whose one-line message names
the file and where; or, for a valid layout, reads it.  ``tests/data/fuzz/`` keeps a fixed sample of the
mutated files on which the previous readers raised a foreign exception, allocated out of proportion to the
file, or lost data without a word; the rest are built here.
"""

import json
import os
import struct
import subprocess
import sys
import tracemalloc
import warnings
import zipfile

import numpy as np
import pytest

from taichi_hair.io import (READERS, Groom, GroomFileNotFoundError, GroomFormatError, geometry_warnings, groom_size,
                            load_groom, read_tfxmesh, save_groom, units_warning)
from taichi_hair.io._util import MAX_PARAMS_DEPTH, READ_EXPANSION
from taichi_hair.io.groom import strand_lengths

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FUZZ = os.path.join(ROOT, "tests", "data", "fuzz")

#: file in tests/data/fuzz -> (what the previous readers did, what the message must say)
FIXED = {
    "thair_npy_header_byte_flipped.thair.npz": ("tokenize.TokenError", r"member 'points\.npy': corrupt \.npy header"),
    "thair_params_nested.thair.npz": ("RecursionError", r"'params' nests lists or objects \d+ levels deep"),
    "usda_params_nested_1000_deep.usda": ("RecursionError", r"taichiHair:params nests lists or objects 1000 levels"),
    "thair_deflate_bomb.thair.npz": ("48 MB allocated for a 49 kB file",
                                     r"members would inflate to 50332064 bytes, more than"),
    "ply_ascii_x_declared_as_list.ply": ("AttributeError", r"line 5: element 'vertex' property 'x' is declared as a list"),
    "ply_ascii_rest_x_declared_as_list.ply": ("ValueError from numpy", r"line 8: element 'vertex' property 'rest_x'"),
    "ply_binary_z_declared_as_list.ply": ("AttributeError", r"line 7: element 'vertex' property 'z' is declared as a list"),
    "ply_binary_segments_declared_twice.ply": ("ValueError from numpy",
                                               r"line 10: element 'strand' declares property 'segments' twice"),
    "ply_ascii_segments_declared_twice.ply": ("the last column kept, no warning",
                                              r"line 10: element 'strand' declares property 'segments' twice"),
    "tfx_ascii_numverts_below_its_lines.tfx": ("the extra coordinate line read as a header key",
                                               r"line 9, strand 0: expected 'strand 1 numVerts \.\.\.'"),
    "tfx4_strand_count_below_the_data.tfx": ("3 of 4 strands dropped silently",
                                             r"byte 4: the header's 1 strands x 4 vertices end at byte 224"),
}


def _read(path, **options):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_groom(path, **options)


def _one_line_error(path, match, **options) -> GroomFormatError:
    with pytest.raises(GroomFormatError, match=match) as info:
        _read(path, **options)
    msg = str(info.value)
    assert msg.startswith(f"{os.fspath(path)}: "), msg
    assert "\n" not in msg
    return info.value


def _groom(strands=40, vertices=8, seed=0) -> Groom:
    """Random walks of 1 cm steps, float32."""
    rng = np.random.default_rng(seed)
    pts = np.cumsum(rng.normal(scale=0.01, size=(strands, vertices, 3)), axis=1).astype(np.float32)
    return Groom(points=pts.reshape(-1, 3), strand_offsets=np.arange(strands + 1, dtype=np.int64) * vertices).validate()


@pytest.mark.parametrize("name", sorted(FIXED))
def test_fuzzed_file_that_broke_the_previous_readers_is_a_one_line_error_naming_it(name):
    if name.endswith(".usda"):
        pytest.importorskip("pxr")
    _one_line_error(os.path.join(FUZZ, name), FIXED[name][1])


def test_fixed_fuzz_sample_stays_small():
    """The kept sample is a regression set, not a corpus: under 300 kB."""
    total = sum(os.path.getsize(os.path.join(FUZZ, f)) for f in os.listdir(FUZZ))
    assert total < 300_000, total
    assert set(os.listdir(FUZZ)) == set(FIXED)


# ---------------------------------------------------------------- foreign exceptions
def test_thair_npy_header_with_an_unclosed_bracket_is_a_groom_format_error_not_a_token_error(tmp_path):
    """One byte of a .npy header ')' -> ' ' sent NumPy's Python-2 header fallback into tokenize, whose
    TokenError escaped (on members over 4 kB, read before zipfile's CRC check)."""
    p = tmp_path / "g.thair.npz"
    save_groom(_groom(500), p)
    data = bytearray(p.read_bytes())
    i = data.index(b"'shape': (4000, 3)") + len(b"'shape': (4000, 3")
    data[i] = ord(" ")
    p.write_bytes(bytes(data))
    err = _one_line_error(p, r"member 'points\.npy': corrupt \.npy header")
    assert err.offset == 0  # the member's local header in the archive


def _nested(depth: int) -> str:
    return '{"a": ' * depth + "1" + "}" * depth


@pytest.mark.parametrize("ext", [".thair.npz", ".usda", ".usdc"])
def test_params_json_nested_100k_deep_is_a_groom_format_error_naming_the_file(tmp_path, ext):
    """Deeply nested params JSON raised RecursionError (a one-line error naming no file)."""
    p = tmp_path / ("g" + ext)
    g = _groom(4)
    if ext == ".thair.npz":
        arrays = {"points": g.points, "strand_offsets": g.strand_offsets, "format_version": np.int64(1),
                  "params": np.array(_nested(100_000)), "units": np.array("")}
        with open(p, "wb") as fh:
            np.savez(fh, **arrays)
        options = {}
    else:
        pytest.importorskip("pxr")
        from pxr import Usd

        save_groom(g, p)
        stage = Usd.Stage.Open(str(p))
        stage.GetPrimAtPath("/Groom/Strands").SetCustomDataByKey("taichiHair:params", _nested(100_000))
        stage.GetRootLayer().Save()
        options = {"isolate": False}
    _one_line_error(p, r"nests lists or objects 100000 levels deep; at most 64", **options)


def test_params_nested_to_the_limit_read_back_unchanged(tmp_path):
    p = tmp_path / "g.thair.npz"
    g = _groom(4)
    g.params = json.loads(_nested(MAX_PARAMS_DEPTH - 1))
    save_groom(g, p)
    assert _read(p).params == g.params


PLY_HEAD = "ply\nformat {fmt} 1.0\nelement vertex 4\n{vprops}element strand 2\n{sprops}{more}end_header\n"


def _ply(tmp_path, fmt="ascii", vprops=("float x", "float y", "float z"), sprops=("int segments",), more="",
         body=b"0 0 0\n0 1 0\n0 0 1\n1 1 1\n1\n1\n"):
    head = PLY_HEAD.format(fmt=fmt, vprops="".join(f"property {p}\n" for p in vprops),
                           sprops="".join(f"property {p}\n" for p in sprops), more=more)
    p = tmp_path / "g.ply"
    p.write_bytes(head.encode() + body)
    return p


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian"])
def test_ply_list_where_one_value_per_record_is_needed_is_refused_naming_its_line(tmp_path, fmt):
    """'property list uchar float x' (a valid PLY layout) raised AttributeError; the strand reader needs one x
    per vertex, so it refuses the file, naming the property's header line."""
    body = b"1 0 0 0\n1 0 1 0\n1 0 0 1\n1 1 1 1\n1\n1\n" if fmt == "ascii" else bytes(100)
    p = _ply(tmp_path, fmt, vprops=("list uchar float x", "float y", "float z"), body=body)
    err = _one_line_error(p, r"line 4: element 'vertex' property 'x' is declared as a list")
    assert err.line == 4


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian"])
def test_ply_list_property_of_an_element_the_reader_ignores_is_read_and_ignored(tmp_path, fmt):
    """Lists elsewhere (a face element, an unused vertex property) are a valid layout: the strands are read."""
    rows = [((0, 0, 0), (0,)), ((0, 1, 0), (7, 8)), ((0, 0, 1), (5,)), ((1, 1, 1), ())]
    if fmt == "ascii":
        body = b"0 0 0 0\n0 1 0 2 7 8\n0 0 1 1 5\n1 1 1 0\n1\n1\n3 0 1 2\n"
    else:
        body = b"".join(struct.pack("<3fB", *xyz, len(tags)) + struct.pack(f"<{len(tags)}i", *tags)
                        for xyz, tags in rows)
        body += struct.pack("<2i", 1, 1) + struct.pack("<B3i", 3, 0, 1, 2)
    p = _ply(tmp_path, fmt, vprops=("float x", "float y", "float z", "list uchar int tags"),
             more="element face 1\nproperty list uchar int vertex_indices\n", body=body)
    g = _read(p)
    assert g.strand_count == 2
    np.testing.assert_array_equal(g.points, [[0, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]])


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian"])
def test_ply_property_declared_twice_is_refused_naming_both_lines(tmp_path, fmt):
    """A duplicated property kept the last column silently (ASCII) or raised numpy's ValueError (binary)."""
    body = b"0 0 0 5\n0 1 0 5\n0 0 1 5\n1 1 1 5\n1\n1\n" if fmt == "ascii" else bytes(4 * 16 + 8)
    p = _ply(tmp_path, fmt, vprops=("float x", "float y", "float z", "float x"), body=body)
    err = _one_line_error(p, r"line 7: element 'vertex' declares property 'x' twice \(first on line 4\)")
    assert err.line == 7


# ---------------------------------------------------------------- paths
def test_load_groom_on_a_folder_is_a_groom_format_error_naming_it(tmp_path):
    """Was IsADirectoryError from open()."""
    _one_line_error(tmp_path, "is a folder, not a groom file")


def test_load_groom_on_a_missing_path_is_a_groom_format_error_and_a_file_not_found_error(tmp_path):
    """GroomFileNotFoundError is both, so `except GroomFormatError` and `except FileNotFoundError` catch it."""
    p = tmp_path / "nowhere.hair"
    err = _one_line_error(p, "no such file")
    assert isinstance(err, GroomFileNotFoundError) and isinstance(err, FileNotFoundError)
    assert str(err) == f"{p}: no such file"


@pytest.mark.parametrize("fmt", sorted(READERS) + ["tfxmesh"])
def test_every_reader_on_a_missing_path_or_a_folder_raises_groom_format_error(tmp_path, fmt):
    read = read_tfxmesh if fmt == "tfxmesh" else READERS[fmt]
    with pytest.raises(GroomFileNotFoundError, match="nowhere: no such file"):
        read(tmp_path / "nowhere")
    with pytest.raises(GroomFormatError, match="is a folder"):
        read(tmp_path)


def test_cli_info_on_a_missing_file_prints_one_error_line_and_exits_2(tmp_path):
    p = tmp_path / "nowhere.ply"
    r = subprocess.run([sys.executable, "-m", "taichi_hair.io.cli", "info", str(p)], capture_output=True, text=True,
                       cwd=ROOT, timeout=60)
    assert r.returncode == 2
    assert r.stderr.strip().splitlines()[-1] == f"error: {p}: no such file"
    assert "Traceback" not in r.stderr


# ---------------------------------------------------------------- counts that disagree with the data
def test_tfx_ascii_numverts_smaller_than_its_lines_is_an_error_naming_line_and_strand(tmp_path):
    """The extra coordinate lines used to become header keys ('tfx_-0.0117...'): vertices lost, exit 0."""
    p = tmp_path / "g.tfx"
    save_groom(_groom(5), p, version=2.0)
    text = p.read_bytes().replace(b"strand 3 numVerts 8", b"strand 3 numVerts 6")
    p.write_bytes(text)
    line = text.split(b"\n").index(b"strand 3 numVerts 6 texcoord 0.0 0.0") + 1 + 6 + 1
    err = _one_line_error(p, r"expected 'strand 4 numVerts \.\.\.' or the end of the file after the 6 points of "
                             r"strand 3 \(its numVerts\)")
    assert (err.line, err.strand) == (line, 3)


def test_tfx_ascii_numverts_larger_than_its_lines_is_an_error(tmp_path):
    p = tmp_path / "g.tfx"
    save_groom(_groom(5), p, version=2.0)
    p.write_bytes(p.read_bytes().replace(b"strand 1 numVerts 8", b"strand 1 numVerts 9"))
    _one_line_error(p, r"strand 1: expected 3 coordinates")


@pytest.mark.parametrize("version", [3.0, 4.0])
def test_binary_tfx_strand_count_smaller_than_the_data_is_an_error(tmp_path, version):
    """TressFX 4 dropped the strands past the header's count silently (3 already refused it)."""
    p = tmp_path / "g.tfx"
    save_groom(_groom(10, 4), p, version=version)
    data = bytearray(p.read_bytes())
    struct.pack_into("<I", data, 4, 7)
    p.write_bytes(bytes(data))
    _one_line_error(p, r"byte \d+: .*(does not match the header|end at byte)")


# ---------------------------------------------------------------- memory
def _bomb(path, vertices: int) -> None:
    """A deflated .thair.npz of one zero-length strand of ``vertices`` zeros (~1,000 x its size)."""
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, arr in (("strand_offsets", np.array([0, vertices])), ("format_version", np.int64(1))):
            with zf.open(name + ".npy", "w") as fh:
                np.lib.format.write_array(fh, arr)
        with zf.open("points.npy", "w", force_zip64=True) as fh:
            np.lib.format.write_array_header_1_0(fh, {"descr": "<f4", "fortran_order": False,
                                                      "shape": (vertices, 3)})
            zeros = bytes(1 << 20)
            for _ in range(vertices * 12 >> 20):
                fh.write(zeros)


def test_thair_deflate_bomb_is_refused_from_the_zip_directory_before_inflating(tmp_path):
    """A bomb within the per-member ratio check used to be inflated (and copied: ~5,000 x the file size)."""
    p = tmp_path / "bomb.thair.npz"
    _bomb(p, 1 << 21)  # 24 MiB of zeros in ~25 kB
    size = os.path.getsize(p)
    tracemalloc.start()
    try:
        _one_line_error(p, rf"members would inflate to \d+ bytes, more than the {READ_EXPANSION * size + (1 << 20)} "
                           r"bytes allowed")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 2 << 20, peak
    g = _read(p, max_bytes=64 << 20)  # the cap is the caller's to raise
    assert g.points.shape == (1 << 21, 3) and not g.points.any()


def test_thair_read_allocates_its_file_size_plus_a_fixed_working_set(tmp_path):
    """Members are read straight into their arrays, and the checks work a chunk at a time: the peak is the
    file size (the arrays) + a quarter (validate's finite mask) + under 8 MB, not a multiple of the file."""
    p = tmp_path / "g.thair.npz"
    save_groom(_groom(100_000, 16), p)  # 19 MB
    size = os.path.getsize(p)
    tracemalloc.start()
    try:
        _read(p)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 1.3 * size + 8e6, (peak, size)


TINY_CASES = [("hair", {}, ".hair"), ("data", {}, ".data"), ("ply", {}, ".ply"), ("ply", {"ascii": True}, ".ply"),
              ("obj", {}, ".obj"), ("tfx", {"version": 4.0}, ".tfx"), ("tfx", {"version": 3.0}, ".tfx"),
              ("tfx", {"version": 2.0}, ".tfx"), ("thair", {}, ".thair.npz")]


@pytest.mark.parametrize("fmt,opts,ext", TINY_CASES, ids=[f"{f}{o.get('version', '')}{'-ascii' if o.get('ascii') else ''}"
                                                           for f, o, _ in TINY_CASES])
def test_every_reader_allocates_at_most_12_times_its_file_size_on_tiny_strands(tmp_path, fmt, opts, ext):
    """20,000 strands of 4 vertices, the per-strand worst case: the peak of NumPy and Python allocations
    (tracemalloc; usd-core's own are capped by read_usd instead) within 12 x the file + 4 MB of working set.
    Measured: binary 2.3-3.8 x, text (token lists) 7.8-9.7 x."""
    p = tmp_path / ("g" + ext)
    save_groom(_groom(20_000, 4), p, format=fmt, **opts)
    _read(p, format=fmt)  # first-use imports out of the measurement
    size = os.path.getsize(p)
    tracemalloc.start()
    try:
        _read(p, format=fmt)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak <= 12 * size + (4 << 20), (peak, size)


def test_units_check_does_not_copy_the_groom_to_float64():
    """One straight strand of 2M float32 vertices (24 MB): the median length is (N - 1) h (closed form) and
    the checks (groom_size, geometry_warnings) allocate less than 8 MB (a float64 copy would be 48 MB)."""
    n, h = 2_000_000, 1e-7
    pts = np.zeros((n, 3), np.float32)
    pts[:, 0] = np.arange(n) * h
    g = Groom(points=pts, strand_offsets=np.array([0, n])).validate()
    tracemalloc.start()
    try:
        med, extent = groom_size(g)
        units_warning(g)
        geometry_warnings(g)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 8e6, peak
    exact = float(np.float64(pts[-1, 0]) - np.float64(pts[0, 0]))
    assert abs(med - exact) <= 1e-6 * exact
    assert extent is None


def test_chunked_strand_lengths_equal_the_one_pass_sum():
    """strand_lengths in chunks of 7 vertices (strands cut across chunks) equals the whole-array sum to 1e-12."""
    rng = np.random.default_rng(3)
    counts = rng.integers(2, 30, size=300)
    off = np.concatenate([[0], np.cumsum(counts)])
    pts = rng.normal(size=(int(off[-1]), 3)).astype(np.float32)
    seg = np.linalg.norm(np.diff(pts.astype(np.float64), axis=0), axis=1)
    ref = np.array([seg[off[s]:off[s + 1] - 1].sum() for s in range(300)])
    np.testing.assert_allclose(strand_lengths(pts, off, chunk=7), ref, rtol=1e-12)
    np.testing.assert_allclose(strand_lengths(pts, off, 100, 140, chunk=5), ref[100:140], rtol=1e-12)


# ---------------------------------------------------------------- the benchmark itself
def test_fuzz_benchmark_reports_only_ok_and_groom_format_error_on_a_small_run(tmp_path):
    """benchmarks/fuzz_readers.py end to end: 25 mutations of 3 formats in one capped worker."""
    out = tmp_path / "fuzz.json"
    r = subprocess.run([sys.executable, os.path.join(ROOT, "benchmarks", "fuzz_readers.py"), "--per-format", "25",
                        "--workers", "1", "--formats", "ply_ascii", "tfx4", "thair", "--out", str(out)],
                       capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    doc = json.loads(out.read_text())
    assert doc["unacceptable"] == {}
    for fmt in ("ply_ascii", "tfx4", "thair"):
        assert sum(doc["outcomes"][fmt].values()) == 25
        assert doc["outcomes"][fmt].get("GroomFormatError", 0) > 0
