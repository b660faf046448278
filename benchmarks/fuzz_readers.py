"""Fault injection for the groom readers: mutated files of every format, read in capped worker processes.

    python3 benchmarks/fuzz_readers.py                         # 1,000 files per format, 2 workers
    python3 benchmarks/fuzz_readers.py --per-format 200 --seed 7 --workers 1 --formats ply_ascii thair

Every file is a seeded mutation of a small valid file that the project wrote (truncations, byte flips in the
header and the body, counts set huge or negative, NaN / inf values, consistent files with bad content,
deflate bombs, deeply nested params JSON).  Long-lived worker processes (``multiprocessing`` spawn) read
the files; before each file a worker caps its address space (``RLIMIT_AS``) at its current size plus
``--memory-factor`` times the file size plus ``--memory-slack-mb``, and the parent kills a worker that takes
longer than ``--timeout`` seconds on one file and starts a new one (likewise after a crash).  Outcomes, per
format: ``ok`` (a valid groom), ``GroomFormatError`` (whose one-line message names the file), a foreign
exception by type, ``bad-message`` (a GroomFormatError not naming the file, or of several lines),
``invalid`` (a groom that fails ``validate``), ``timeout``, ``memory`` (MemoryError under the cap) and
``crash`` (the worker died).  Only ``ok`` and ``GroomFormatError`` are acceptable; the exit status is 1
otherwise.  USD is read in the worker itself (``isolate=False``: the worker is the isolation, and a child
process per file would cost ~0.5 s each); ``--usd-isolated`` uses the default child-process reader, whose
child caps itself (``usd.USD_READ_BASE_BYTES`` + 64 x the file), so the worker's cap is not applied then.
Prints the table and writes ``benchmarks/results/fuzz_readers.json`` (with up to ``--examples`` mutation
descriptions per unacceptable outcome, each reproducible from ``--seed``, the format and the index).
"""

from __future__ import annotations

import argparse
import io
import json
import multiprocessing as mp
import os
import shutil
import struct
import sys
import tempfile
import time
import zipfile
from multiprocessing.connection import wait

import numpy as np

from harness import ROOT, Bench, results_path  # benchmarks/harness.py (the script's folder is on sys.path)

try:
    import taichi_hair.io  # noqa: F401 - the one on the path (PYTHONPATH) if there is one
except ImportError:  # else this repository's, here and in the spawned workers
    sys.path.insert(0, ROOT)

FORMATS = ("hair", "data", "ct2hair", "ply_bin", "ply_ascii", "obj", "tfx2", "tfx3", "tfx4", "thair", "usda", "usdc",
           "tfxmesh")
EXT = {"hair": ".hair", "data": ".data", "ct2hair": ".bin", "ply_bin": ".ply", "ply_ascii": ".ply", "obj": ".obj",
       "tfx2": ".tfx", "tfx3": ".tfx", "tfx4": ".tfx", "thair": ".thair.npz", "usda": ".usda", "usdc": ".usdc",
       "tfxmesh": ".tfxmesh"}
TEXT = {"ply_ascii", "obj", "tfx2", "usda", "tfxmesh"}
#: Bytes of each binary format's fixed header (byte flips "in the header" land there).
HEADER = {"hair": 128, "data": 4, "ct2hair": 4, "tfx3": 296, "tfx4": 160, "thair": 128, "usdc": 88, "ply_bin": 0}
ACCEPTABLE = ("ok", "GroomFormatError")
SPECIAL_WORDS = (0, 1, 2, 0x7FFFFFFF, 0x80000000, 0xFFFFFFFF, 0xFFFFFFFE, 0xFFFF, 0x10000, 1 << 20, 1 << 30)
FLOAT_BITS = (0x7FC00000, 0x7F800000, 0xFF800000, 0xFFC00001, 0x7F7FFFFF)  # NaN, inf, -inf, -NaN, max float
TEXT_NUMBERS = (b"nan", b"inf", b"-inf", b"1e39", b"-1", b"0", b"2147483648", b"99999999999999999999", b"-2147483649",
                b"1.5", b"x", b"")
TFXMESH = (b"numOfBones 2\n0 root\n1 head\nnumOfVertices 4\n"
           b"0 0 0 0 0 0 1 0 1 0 0 1 0 0 0\n1 1 0 0 0 0 1 0 1 0 0 0.5 0.5 0 0\n"
           b"2 0 1 0 0 0 1 1 0 0 0 1 0 0 0\n3 1 1 0 0 0 1 1 0 0 0 1 0 0 0\n"
           b"numOfTriangles 2\n0 0 1 2\n1 1 3 2\n")


# ---------------------------------------------------------------- valid samples
def _groom(rng, strands: int, uniform: int | None, attributes: bool):
    from taichi_hair.io import Groom

    counts = np.full(strands, uniform) if uniform else rng.integers(2, 12, size=strands)
    polys = [np.cumsum(rng.normal(scale=0.01, size=(int(c), 3)), axis=0).astype(np.float32) for c in counts]
    g = Groom.from_polylines(polys)
    if attributes:
        g.radius = rng.uniform(1e-5, 1e-4, size=g.vertex_count).astype(np.float32)
        g.region = rng.integers(0, 3, size=g.strand_count)
        g.guide = rng.random(g.strand_count) < 0.5
        g.pinned = rng.random(g.vertex_count) < 0.2
        g.rest_points = g.points + np.float32(0.001)
        g.params = {"fuzz": {"seed": 1, "list": [1, 2.5, "x"]}}
        g.units = "m"
    return g.validate()


def _ct2hair(rng, strands: int) -> bytes:
    out = [struct.pack("<i", strands)]
    for _ in range(strands):
        n = int(rng.integers(2, 8))
        out.append(struct.pack("<i", n) + rng.normal(size=(n, 7)).astype("<f4").tobytes())
    return b"".join(out)


def samples(fmt: str, folder: str, seed: int) -> list:
    """Three valid files of ``fmt`` (bytes), of different sizes and attributes."""
    from taichi_hair.io import save_groom

    rng = np.random.default_rng([seed, FORMATS.index(fmt), 0])
    if fmt == "ct2hair":
        return [_ct2hair(rng, s) for s in (1, 6, 20)]
    if fmt == "tfxmesh":
        return [TFXMESH, TFXMESH.split(b"numOfVertices")[0].replace(b"numOfBones 2\n0 root\n1 head\n", b"")
                + b"numOfVertices" + TFXMESH.split(b"numOfVertices")[1]]
    out = []
    for k, (strands, attributes) in enumerate(((1, False), (12, True), (150, False))):
        uniform = 4 if fmt in ("tfx3", "tfx4") else None
        g = _groom(rng, strands, uniform, attributes and fmt not in ("tfx3", "tfx4"))
        opts = {"ply_ascii": {"ascii": True}, "tfx2": {"version": 2.0}, "tfx3": {"version": 3.0},
                "tfx4": {"version": 4.0}}.get(fmt, {})
        name = {"ply_bin": "ply", "ply_ascii": "ply", "tfx2": "tfx", "tfx3": "tfx", "tfx4": "tfx", "usda": "usd",
                "usdc": "usd"}.get(fmt, fmt)
        path = os.path.join(folder, f"sample{k}{EXT[fmt]}")
        save_groom(g, path, format=name, **opts)
        with open(path, "rb") as fh:
            out.append(fh.read())
    return out


# ---------------------------------------------------------------- mutations
def _header_end(fmt: str, data: bytes) -> int:
    if fmt in ("ply_bin", "ply_ascii"):
        return data.find(b"end_header") + 11
    return min(HEADER.get(fmt, 64), len(data))


def _flip(data: bytes, rng, lo: int, hi: int) -> bytes:
    b = bytearray(data)
    for _ in range(int(rng.integers(1, 5))):
        if hi > lo:
            b[int(rng.integers(lo, hi))] = int(rng.integers(0, 256))
    return bytes(b)


def _number_spans(data: bytes) -> list:
    """(start, end) of the numeric tokens of a text file (a sample of at most 4096)."""
    import re

    return [m.span() for m in re.finditer(rb"-?[0-9][0-9.eE+-]*", data[:1 << 16])][:4096]


def _replace_token(data: bytes, rng, choices) -> bytes:
    spans = _number_spans(data)
    if not spans:
        return data[:-1]
    a, b = spans[int(rng.integers(0, len(spans)))]
    return data[:a] + choices[int(rng.integers(0, len(choices)))] + data[b:]


def _count_lines(data: bytes, rng) -> bytes:
    """A text header's count (element N, numVerts n, numStrands, numOf..., l record length) set to another
    value: a count that disagrees with the data."""
    import re

    ms = list(re.finditer(rb"(element \w+ |numVerts |numStrands |numOf\w+ )(\d+)", data))
    if not ms:
        return _replace_token(data, rng, (b"0", b"1", b"-1", b"4294967295"))
    m = ms[int(rng.integers(0, len(ms)))]
    n = int(m.group(2))
    new = [0, 1, n - 1, n + 1, n - 2, n * 2, -1, -n, 1 << 31, 1 << 40][int(rng.integers(0, 10))]
    return data[:m.start(2)] + str(new).encode() + data[m.end(2):]


def _nested(depth: int) -> str:
    return "[" * depth + "]" * depth if depth % 2 else '{"a": ' * depth + "1" + "}" * depth


def _thair_raw(arrays: dict, compress: bool = False) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED if compress else zipfile.ZIP_STORED) as zf:
        for k, v in arrays.items():
            with zf.open(k + ".npy", "w", force_zip64=True) as fh:
                np.lib.format.write_array(fh, np.asanyarray(v), allow_pickle=False)
    return buf.getvalue()


def _thair_members(data: bytes) -> dict:
    with zipfile.ZipFile(io.BytesIO(data)) as zf:
        return {n[:-4]: np.lib.format.read_array(zf.open(n)) for n in zf.namelist()}


def _thair_bad_content(data: bytes, rng) -> bytes:
    """A well-formed archive whose arrays are wrong: every member readable, the groom invalid or odd."""
    m = _thair_members(data)
    n, off = m["points"].shape[0], m["strand_offsets"]
    k = int(rng.integers(0, 14))
    if k == 0:
        m["strand_offsets"] = off[::-1].copy()
    elif k == 1:
        m["strand_offsets"] = np.concatenate([off[:-1], [n + 5]])
    elif k == 2:
        m["points"] = m["points"].astype(np.int32)
    elif k == 3:
        m["points"] = m["points"][:, :2].copy()
    elif k == 4:
        m["points"] = m["points"].copy()
        m["points"][int(rng.integers(0, n))] = np.nan
    elif k == 5:
        m["radius"] = -np.ones(n, np.float32)
    elif k == 6:
        m["params"] = np.array("[1, 2]")
    elif k == 7:
        m["params"] = np.array("{not json")
    elif k == 8:
        m["region"] = np.zeros(len(off) + 3, np.float64)
    elif k == 9:
        m["point_frames"] = np.stack([m["points"]] * 3)
        m["frame_times"] = np.array([0.0, 2.0, 1.0])
    elif k == 10:
        m["points"] = np.asfortranarray(m["points"]).astype(">f4")
    elif k == 11:
        m["format_version"] = np.int64(int(rng.integers(2, 1 << 40)))
    elif k == 12:
        m["extra"] = np.zeros(3)
    else:
        m["units"] = np.zeros(2)
    return _thair_raw(m, compress=bool(rng.random() < 0.3))


def _thair_bomb(rng) -> bytes:
    """Deflated members of zeros: up to 1,032 x their stored size, within the per-member ratio check."""
    n = int(rng.choice([1 << 16, 1 << 20, 1 << 22]))
    arrays = {"points": np.zeros((n, 3), np.float32), "strand_offsets": np.array([0, n // 2, n]),
              "format_version": np.int64(1)}
    if rng.random() < 0.5:
        arrays["rest_points"] = arrays["points"]
    return _thair_raw(arrays, compress=True)


def _thair_nested(data: bytes, rng) -> bytes:
    m = _thair_members(data)
    m["params"] = np.array(_nested(int(rng.choice([65, 200, 1000, 5000, 100_000]))))
    return _thair_raw(m)


def _usda_nested(data: bytes, rng) -> bytes:
    depth = int(rng.choice([65, 200, 1000, 5000, 100_000]))
    key = b'string "taichiHair:params" = '
    i = data.find(key)
    text = json.dumps(_nested(depth)).encode()
    if i < 0:
        return data.replace(b"def BasisCurves \"Strands\"",
                            b'def BasisCurves "Strands" (\n customData = { dictionary taichiHair = { string params = '
                            + text + b" } }\n)", 1)
    j = data.find(b"\n", i)
    return data[:i] + key + text + data[j:]


def _ply_layout(lines: list) -> tuple:
    """(elements as [name, count, [header line of each property]], index of the 'end_header' line)."""
    h = lines.index(b"end_header")
    els = []
    for i in range(h):
        t = lines[i].split()
        if t[:1] == [b"element"]:
            els.append([t[1], int(t[2]), []])
        elif t[:1] == [b"property"]:
            els[-1][2].append(i)
    return els, h


def _ply_ascii_widen(data: bytes, rng, as_list: bool) -> bytes:
    """A scalar property declared twice (its column duplicated in every record) or declared as a list of
    one (a count 1 put before its value in every record): consistent files the reader must refuse."""
    lines = data.split(b"\n")
    els, h = _ply_layout(lines)
    e = int(rng.integers(0, len(els)))
    name, count, props = els[e]
    j = int(rng.integers(0, len(props)))
    first = h + 1 + sum(c for _, c, _ in els[:e])
    for r in range(first, first + count):
        t = lines[r].split()
        t[j:j + 1] = [b"1", t[j]] if as_list else [t[j], t[j]]
        lines[r] = b" ".join(t)
    parts = lines[props[j]].split()
    if as_list:
        lines[props[j]] = b"property list uchar " + parts[1] + b" " + parts[2]
    else:
        lines.insert(props[j] + 1, lines[props[j]])
    return b"\n".join(lines)


def _ply_binary_widen(data: bytes, rng, as_list: bool) -> bytes:
    """The binary form of :func:`_ply_ascii_widen` (every property of the project's writer is a scalar)."""
    h = data.index(b"end_header\n") + 11
    lines = data[:h].split(b"\n")
    els, hl = _ply_layout(lines)
    types = {b"float": "<f4", b"double": "<f8", b"int": "<i4", b"uchar": "u1"}
    e = int(rng.integers(0, len(els)))
    pos, blocks = h, []
    for k, (name, count, props) in enumerate(els):
        dt = np.dtype([(lines[i].split()[2].decode(), types[lines[i].split()[1]]) for i in props])
        rec = np.frombuffer(data, dt, count, pos)
        pos += count * dt.itemsize
        if k != e:
            blocks.append(rec.tobytes())
            continue
        j = int(rng.integers(0, len(props)))
        names = list(dt.names)
        fields = [(n, dt[n].str) for n in names]
        fields[j:j + 1] = [("_count", "u1"), fields[j]] if as_list else [fields[j], ("_copy", dt[names[j]].str)]
        out = np.zeros(count, np.dtype(fields))
        for n in names:
            out[n] = rec[n]
        if as_list:
            out["_count"] = 1
        else:
            out["_copy"] = rec[names[j]]
        blocks.append(out.tobytes())
        changed = props[j]
    parts = lines[changed].split()
    if as_list:
        lines[changed] = b"property list uchar " + parts[1] + b" " + parts[2]
    else:
        lines.insert(changed + 1, lines[changed])
    return b"\n".join(lines) + b"".join(blocks)


def _text_bad_content(fmt: str, data: bytes, rng) -> tuple:
    """(bytes, must_fail): a text file made consistent but wrong: duplicated or list properties, lines that a
    count does not cover, a strand of one point, indices out of range.  ``must_fail``: a reader that
    accepts it loses or invents data without a word."""
    lines = data.split(b"\n")
    k = int(rng.integers(0, 4))
    if fmt == "ply_ascii":
        if k < 2:
            return _ply_ascii_widen(data, rng, as_list=k == 1), True
        if k == 2:  # a record duplicated: one more line than the counts cover
            h = lines.index(b"end_header")
            j = int(rng.integers(h + 1, len(lines) - 1))
            lines.insert(j, lines[j])
            return b"\n".join(lines), True
        return data.replace(b"property int segments", b"property float segments"), False
    if fmt == "tfx2":
        starts = [i for i, ln in enumerate(lines) if ln.startswith(b"strand ")]
        i = starts[int(rng.integers(0, len(starts)))]
        if k == 0:  # a coordinate line added without raising numVerts
            lines.insert(i + 1, lines[i + 1])
            return b"\n".join(lines), True
        if k == 1:  # numVerts 1, the block cut to match
            n = int(lines[i].split()[3])
            lines[i] = lines[i].replace(b"numVerts %d" % n, b"numVerts 1")
            del lines[i + 2:i + 1 + n]
            return b"\n".join(lines), True
        if k == 2:  # numVerts one less than the lines that follow
            n = int(lines[i].split()[3])
            lines[i] = lines[i].replace(b"numVerts %d" % n, b"numVerts %d" % (n - 1))
            return b"\n".join(lines), True
        del lines[i]
        return b"\n".join(lines), True
    if fmt == "obj":
        ls = [i for i, ln in enumerate(lines) if ln.startswith(b"l ")]
        i = ls[int(rng.integers(0, len(ls)))]
        lines[i] = [b"l 0 1", b"l 1", b"l -99999 1", b"l 1/2/3 2//1"][k]
        return b"\n".join(lines), k < 3
    if fmt == "usda":
        bad = data.replace(b"int[] curveVertexCounts = [", b"int[] curveVertexCounts = [1, ", 1) if k < 2 \
            else data.replace(b"float[] widths = [", b"float[] widths = [-1, ", 1)
        return bad, bad != data
    return _count_lines(data, rng), False


def _binary_bad_content(fmt: str, data: bytes, rng) -> tuple:
    """(bytes, must_fail): the binary counterpart of :func:`_text_bad_content`."""
    b = bytearray(data)
    must = True
    if fmt == "hair":  # segment counts that do not sum to the point count, or strands of 0 segments
        ns = struct.unpack_from("<I", b, 4)[0]
        i = 128 + 2 * int(rng.integers(0, ns))
        old = struct.unpack_from("<H", b, i)[0]
        new = int(rng.choice([0, 1, 0xFFFF]))
        struct.pack_into("<H", b, i, new)
        must = new != old
    elif fmt in ("data", "ct2hair"):  # a strand of 0 or 1 points, the rest moved up to stay consistent
        ns = struct.unpack_from("<i", b, 0)[0]
        stride = 12 if fmt == "data" else 28
        n0 = struct.unpack_from("<i", b, 4)[0]
        keep = int(rng.integers(0, 2))
        return struct.pack("<ii", ns, keep) + bytes(b[8:8 + keep * stride]) + bytes(b[8 + n0 * stride:]), ns == 1
    elif fmt == "tfx4":
        ns = struct.unpack_from("<I", b, 4)[0]
        if rng.random() < 0.5 and ns > 1:  # a strand count smaller than the data: strands left unread
            struct.pack_into("<I", b, 4, int(rng.integers(1, ns)))
        else:  # inverse masses negative or NaN
            i = 160 + 16 * int(rng.integers(0, (len(b) - 160) // 16)) + 12
            struct.pack_into("<f", b, i, float(rng.choice([-1.0, np.nan])))
    elif fmt == "tfx3":
        ns = struct.unpack_from("<I", b, 4)[0]
        if rng.random() < 0.5 and ns > 1:
            struct.pack_into("<I", b, 4, int(rng.integers(1, ns)))
        else:  # a second array's offset pointing into the positions
            struct.pack_into("<I", b, 148 + 4 * int(rng.integers(0, 5)), 296)
            must = False
    elif fmt == "ply_bin":
        return _ply_binary_widen(data, rng, as_list=bool(rng.random() < 0.5)), True
    else:
        return _flip(data, rng, 0, len(data)), False
    return bytes(b), must


KINDS = ("truncate", "flip_header", "flip_body", "huge_count", "nan_inf", "insert_delete", "bad_content", "special")


def mutate(fmt: str, data: bytes, rng) -> tuple:
    """(kind, bytes): one seeded mutation of a valid file; kind "must_fail": a consistent file whose
    counts or declarations disagree with its data, which no reader may accept."""
    kind = KINDS[int(rng.integers(0, len(KINDS)))]
    n, h = len(data), _header_end(fmt, data)
    if kind == "truncate":
        return kind, data[:int(rng.integers(0, n))]
    if kind == "flip_header":
        return kind, _flip(data, rng, 0, max(h, 1))
    if kind == "flip_body":
        return kind, _flip(data, rng, min(h, n - 1), n)
    if kind == "huge_count":
        if fmt in TEXT or fmt == "ply_bin" and rng.random() < 0.7:
            return kind, _count_lines(data, rng)
        b = bytearray(data)
        i = 4 * int(rng.integers(0, max(min(h, n) // 4, 1)))
        b[i:i + 4] = struct.pack("<I", SPECIAL_WORDS[int(rng.integers(0, len(SPECIAL_WORDS)))])
        return kind, bytes(b)
    if kind == "nan_inf":
        if fmt in TEXT or fmt == "ply_ascii":
            return kind, _replace_token(data, rng, TEXT_NUMBERS)
        b = bytearray(data)
        i = 4 * int(rng.integers(h // 4, max(n // 4, h // 4 + 1)))
        b[i:i + 4] = struct.pack("<I", FLOAT_BITS[int(rng.integers(0, len(FLOAT_BITS)))])
        return kind, bytes(b[:n])
    if kind == "insert_delete":
        b = bytearray(data)
        i = int(rng.integers(0, n))
        if fmt in TEXT and rng.random() < 0.5:  # a whole line duplicated or deleted
            lines = data.split(b"\n")
            j = int(rng.integers(0, len(lines)))
            lines[j:j + 1] = [] if rng.random() < 0.5 else [lines[j], lines[j]]
            return kind, b"\n".join(lines)
        if rng.random() < 0.5:
            del b[i:i + int(rng.integers(1, 16))]
        else:
            b[i:i] = bytes(rng.integers(0, 256, size=int(rng.integers(1, 16))).astype(np.uint8))
        return kind, bytes(b)
    if kind == "bad_content":
        if fmt == "thair":
            return kind, _thair_bad_content(data, rng)
        bad, must_fail = (_text_bad_content if fmt in TEXT else _binary_bad_content)(fmt, data, rng)
        return ("must_fail" if must_fail else kind), bad
    # "special": what only some formats have: deflate bombs and nested JSON (thair, usda), else a mix
    if fmt == "thair":
        return ("deflate_bomb", _thair_bomb(rng)) if rng.random() < 0.5 else ("nested_json", _thair_nested(data, rng))
    if fmt == "usda":
        return "nested_json", _usda_nested(data, rng)
    return "flip_body", _flip(data, rng, 0, n)


# ---------------------------------------------------------------- workers
def _address_space() -> int:
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")


def _read_one(path: str, fmt: str, usd_isolated: bool):
    import warnings

    from taichi_hair.io import Groom, load_groom, read_tfxmesh

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if fmt == "tfxmesh":
            return read_tfxmesh(path)
        name = {"ply_bin": "ply", "ply_ascii": "ply", "tfx2": "tfx", "tfx3": "tfx", "tfx4": "tfx", "usda": "usd",
                "usdc": "usd"}.get(fmt, fmt)
        opts = {"isolate": usd_isolated} if name == "usd" else {}
        g = load_groom(path, format=name, **opts)
        assert isinstance(g, Groom)
        return g


def _warm_up_usd() -> None:
    """Read a valid .usda and .usdc once before any cap: usd-core loads its plugins and starts its thread
    pool on first use, which needs far more address space than a read does (under the cap it segfaults)."""
    try:
        import pxr  # noqa: F401
    except ImportError:
        return
    from taichi_hair.io import load_groom, save_groom

    g = _groom(np.random.default_rng(0), 3, None, True)
    with tempfile.TemporaryDirectory() as d:
        for ext in (".usda", ".usdc"):
            save_groom(g, os.path.join(d, "warm" + ext))
            load_groom(os.path.join(d, "warm" + ext), isolate=False)


def worker(conn, memory_factor: float, slack: int, usd_isolated: bool, quiet: bool) -> None:
    """Read the files the parent sends, one at a time, under an address-space cap; answer (outcome, detail)."""
    import resource

    from taichi_hair.io import Groom, GroomFormatError

    if quiet:  # usd-core's warnings go straight to file descriptor 2, one per mutated file
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 2)
    if usd_isolated is False:
        _warm_up_usd()
    _, hard = resource.getrlimit(resource.RLIMIT_AS)
    conn.send("ready")  # the start (imports, usd-core's warm-up) does not count against a file's timeout
    while True:
        try:
            job = conn.recv()
        except EOFError:
            return
        if job is None:
            return
        path, fmt = job
        size = os.path.getsize(path)
        resource.setrlimit(resource.RLIMIT_AS, (resource.RLIM_INFINITY, hard))
        if not (usd_isolated and fmt in ("usda", "usdc")):  # the isolated reader caps its own child (which
            # would inherit this cap, too small for a fresh interpreter loading usd-core: it segfaults)
            resource.setrlimit(resource.RLIMIT_AS, (_address_space() + int(memory_factor * size) + slack, hard))
        t0 = time.perf_counter()
        try:
            g = _read_one(path, fmt, usd_isolated)
            outcome, detail = "ok", ""
            if isinstance(g, Groom):
                try:
                    g.validate()
                    if not np.isfinite(g.points).all():
                        raise ValueError("non-finite points")
                except Exception as exc:  # noqa: BLE001 - an accepted groom that is not valid
                    outcome, detail = "invalid", f"{type(exc).__name__}: {exc}"
        except GroomFormatError as exc:
            msg = str(exc)
            ok = path in msg and "\n" not in msg
            outcome, detail = ("GroomFormatError" if ok else "bad-message"), msg[:300]
        except MemoryError:
            outcome, detail = "memory", f"MemoryError under a cap of {memory_factor:g} x {size} bytes + slack"
        except BaseException as exc:  # noqa: BLE001 - the point of the benchmark
            outcome, detail = type(exc).__name__, str(exc)[:300]
        finally:
            resource.setrlimit(resource.RLIMIT_AS, (resource.RLIM_INFINITY, hard))
        conn.send((outcome, detail, time.perf_counter() - t0))


class Pool:
    """Long-lived workers; a worker that times out is killed, and one that dies is replaced."""

    def __init__(self, count: int, args: tuple):
        self.ctx = mp.get_context("spawn")
        self.args = args
        self.slots = [self._start() for _ in range(count)]
        self.restarts = 0

    def _start(self):
        parent, child = self.ctx.Pipe()
        p = self.ctx.Process(target=worker, args=(child,) + self.args, daemon=True)
        p.start()
        child.close()
        if not parent.poll(300) or parent.recv() != "ready":
            raise RuntimeError("a fuzz worker did not start within 300 s")
        return {"proc": p, "conn": parent, "job": None, "t0": 0.0}

    def _replace(self, i: int) -> None:
        s = self.slots[i]
        if s["proc"].is_alive():
            s["proc"].kill()
        s["proc"].join()
        self.slots[i] = self._start()
        self.restarts += 1

    def run(self, jobs, timeout: float, on_result) -> None:
        jobs = iter(jobs)
        pending = True
        while True:
            for s in self.slots:
                if s["job"] is None and pending:
                    job = next(jobs, None)
                    if job is None:
                        pending = False
                        break
                    s["job"], s["t0"] = job, time.perf_counter()
                    s["conn"].send(job["send"])
            busy = [s for s in self.slots if s["job"] is not None]
            if not busy:
                return
            now = time.perf_counter()
            first_deadline = min(s["t0"] for s in busy) + timeout
            ready = wait([s["conn"] for s in busy] + [s["proc"].sentinel for s in busy],
                         timeout=max(first_deadline - now, 0.0))
            now = time.perf_counter()
            for i, s in enumerate(self.slots):
                if s["job"] is None:
                    continue
                job = s["job"]
                if s["conn"] in ready:
                    try:
                        outcome, detail, elapsed = s["conn"].recv()
                    except (EOFError, OSError):
                        outcome, detail = self._crash(i)
                    else:
                        s["job"] = None
                        on_result(job, outcome, detail, elapsed)
                        continue
                elif s["proc"].sentinel in ready or not s["proc"].is_alive():
                    outcome, detail = self._crash(i)
                elif now - s["t0"] >= timeout:
                    outcome, detail = "timeout", f"no answer within {timeout:g} s"
                    self._replace(i)
                else:
                    continue
                self.slots[i]["job"] = None
                on_result(job, outcome, detail, now - s["t0"])

    def _crash(self, i: int) -> tuple:
        p = self.slots[i]["proc"]
        p.join(5)
        code = p.exitcode
        self._replace(i)
        return "crash", f"the worker died (exit code {code})"

    def close(self) -> None:
        for s in self.slots:
            try:
                s["conn"].send(None)
            except (OSError, BrokenPipeError):
                pass
        for s in self.slots:
            s["proc"].join(5)
            if s["proc"].is_alive():
                s["proc"].kill()


# ---------------------------------------------------------------- main
def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--per-format", type=int, default=1000, help="mutated files per format")
    p.add_argument("--seed", type=int, default=20261203)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--formats", nargs="*", default=None, help=f"subset of {', '.join(FORMATS)}")
    p.add_argument("--timeout", type=float, default=10.0, help="seconds per file before the worker is killed")
    p.add_argument("--memory-factor", type=float, default=64.0,
                   help="address space a worker may add per byte of file (plus the slack)")
    p.add_argument("--memory-slack-mb", type=float, default=256.0)
    p.add_argument("--usd-isolated", action="store_true", help="USD through the default child-process reader")
    p.add_argument("--verbose", action="store_true", help="keep the workers' stderr (usd-core's warnings)")
    p.add_argument("--examples", type=int, default=5, help="examples kept per unacceptable outcome")
    p.add_argument("--keep", default=None, help="folder to copy the files of unacceptable outcomes to")
    p.add_argument("--out", default=results_path("fuzz_readers.json"))
    args = p.parse_args(argv)
    bench = Bench("fuzz_readers", argv)
    formats = args.formats or list(FORMATS)
    try:
        import pxr  # noqa: F401
    except ImportError:
        print("usd-core is not installed: usda and usdc skipped")
        formats = [f for f in formats if f not in ("usda", "usdc")]
    tmp = tempfile.mkdtemp(prefix="fuzz_readers_")
    table = {f: {} for f in formats}
    examples: dict = {}
    seconds = {f: 0.0 for f in formats}
    t_start = time.perf_counter()
    pool = Pool(max(args.workers, 1), (args.memory_factor, int(args.memory_slack_mb * (1 << 20)),
                                       args.usd_isolated, not args.verbose))

    def jobs():
        for fmt in formats:
            base = samples(fmt, tmp, args.seed)
            for i in range(args.per_format):
                rng = np.random.default_rng([args.seed, FORMATS.index(fmt), i + 1])
                kind, data = mutate(fmt, base[i % len(base)], rng)
                path = os.path.join(tmp, f"{fmt}_{i}{EXT[fmt]}")
                with open(path, "wb") as fh:
                    fh.write(data)
                yield {"send": (path, fmt), "fmt": fmt, "index": i, "kind": kind, "size": len(data)}

    def on_result(job, outcome, detail, elapsed):
        fmt = job["fmt"]
        if outcome == "ok" and job["kind"] == "must_fail":
            outcome, detail = "accepted-bad", "a count or declaration that disagrees with the data was accepted"
        table[fmt][outcome] = table[fmt].get(outcome, 0) + 1
        seconds[fmt] += elapsed
        if outcome not in ACCEPTABLE:
            ex = examples.setdefault(fmt, {}).setdefault(outcome, [])
            if len(ex) < args.examples:
                ex.append({"index": job["index"], "kind": job["kind"], "bytes": job["size"], "detail": detail})
            if args.keep:
                os.makedirs(args.keep, exist_ok=True)
                shutil.copy(job["send"][0], os.path.join(args.keep, f"{outcome}_{os.path.basename(job['send'][0])}"))
        if outcome != "timeout":
            os.remove(job["send"][0])

    try:
        pool.run(jobs(), args.timeout, on_result)
    finally:
        pool.close()
        shutil.rmtree(tmp, ignore_errors=True)
    wall = time.perf_counter() - t_start
    columns = ["ok", "GroomFormatError"] + sorted({o for t in table.values() for o in t} - set(ACCEPTABLE))
    print(f"\nfuzz_readers: {args.per_format} mutated files per format, seed {args.seed}, {args.workers} workers, "
          f"timeout {args.timeout:g} s, address space {args.memory_factor:g} x file + {args.memory_slack_mb:g} MB; "
          f"{wall:.1f} s")
    print(f"{'format':>10} " + " ".join(f"{c:>16}" for c in columns) + f" {'ms/file':>8}")
    for fmt in formats:
        n = sum(table[fmt].values())
        print(f"{fmt:>10} " + " ".join(f"{table[fmt].get(c, 0):>16}" for c in columns)
              + f" {1e3 * seconds[fmt] / max(n, 1):8.2f}")
    bad = {f: {o: c for o, c in t.items() if o not in ACCEPTABLE} for f, t in table.items()}
    bad = {f: t for f, t in bad.items() if t}
    for fmt, outcomes in examples.items():
        for outcome, ex in outcomes.items():
            for e in ex[:2]:
                print(f"  {fmt} {outcome}: #{e['index']} {e['kind']} ({e['bytes']} bytes): {e['detail'][:160]}")
    bench.write(args.out, dict(per_format=args.per_format, seed=args.seed, workers=args.workers,
                               timeout_s=args.timeout, memory_factor=args.memory_factor,
                               memory_slack_mb=args.memory_slack_mb, usd_isolated=args.usd_isolated,
                               wall_s=round(wall, 2), worker_restarts=pool.restarts, outcomes=table,
                               ms_per_file={f: 1e3 * seconds[f] / max(sum(table[f].values()), 1) for f in formats},
                               unacceptable=bad, examples=examples))
    print(f"wrote {args.out}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
