"""AMD TressFX grooms (``.tfx``: ASCII 1.x/2.x, binary 3.0 and 4.x) and collision meshes (``.tfxmesh``).

Binary 3.0 (296-byte header)::

    0   float32 version (3.0)          4  uint32 strand count S
    8   uint32 vertices per strand V   12 uint32 follow hairs per guide
    16  uint32 bothEndsImmovable       20 uint32[31] reserved
    144 uint32 offsets: vertices, strand thickness, strand texcoord, vertex colour,
        guide strand, vertex texcoord (0 = absent)
    168 uint32[32] reserved
    positions: float32[S * V, 3] at the vertex offset

Binary 4.x (160-byte header)::

    0  float32 version (4.x)   4 uint32 S   8 uint32 V (power of two, 4..64)
    12 uint32 offsets: vertex positions, strand UV, vertex UV, strand thickness, vertex colour
    32 uint32[32] reserved
    positions: float32[S * V, 4]; w is the inverse mass (0 pinned, 1 free) -> ``pinned = (w == 0)``

ASCII 1.x/2.x: header lines (``version 2.0``, ``scale``, ``rotation``,
``translation``, ``bothEndsImmovable``, ``numStrands N``...), then per strand a
line ``strand i numVerts n texcoord u v`` and n lines ``x y z``.  Header values
go to ``params`` (``tfx_scale``, ``tfx_rotation``... are recorded, not applied).

TressFX grooms have no stated unit (the AMD samples are roughly centimetres).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

from ._util import (ByteReader, atomic_open, check_count, finish, offsets_from_counts, prepare_write, read_bytes,
                    text_rows)
from .errors import GroomFormatError
from .groom import Groom

V3_HEADER = 296
V4_HEADER = 160
V3_OFFSET_NAMES = ("vertices", "strand thickness", "strand texcoord", "vertex colour", "guide strand",
                   "vertex texcoord")
V4_OFFSET_NAMES = ("vertex positions", "strand UV", "vertex UV", "strand thickness", "vertex colour")


def read_tfx(path) -> Groom:
    data = read_bytes(path)
    head = data.lstrip()[:16]
    if head.startswith(b"version") or head.startswith(b"#"):
        return _read_tfx_ascii(data, path)
    r = ByteReader(data, path)
    (version,) = r.unpack("f", 0, "the version number")
    if version == 3.0:
        return _read_tfx_v3(r, path)
    if 4.0 <= version < 5.0:
        return _read_tfx_v4(r, path, version)
    raise GroomFormatError(path, f"unknown TressFX version {version!r}; expected binary 3.0 or 4.x, or an ASCII file "
                                 f"starting with 'version 2.0'", offset=0)


def _read_tfx_v3(r: ByteReader, path) -> Groom:
    r.need(0, V3_HEADER, "the 296-byte TressFX 3 header")
    ns, nv, follow, both = r.unpack("4I", 4, "header counts")
    offs = r.unpack("6I", 144, "array offsets")
    if both not in (0, 1):
        raise GroomFormatError(path, f"bothEndsImmovable is {both}; expected 0 or 1", offset=16)
    if nv < 2:
        raise GroomFormatError(path, f"vertices per strand is {nv}; expected at least 2", offset=8)
    _check_offsets(r, path, offs, V3_OFFSET_NAMES, V3_HEADER, 144)
    vo = offs[0]
    check_count(path, ns, "strand count", (r.size - vo) // (12 * nv), offset=4, minimum=1)
    end = vo + ns * nv * 12
    if not any(offs[1:]) and end != r.size:
        raise GroomFormatError(path, f"file size {r.size} does not match the header ({ns} strands x {nv} vertices "
                                     f"of 12 bytes from byte {vo}: expected {end} bytes)", offset=min(end, r.size))
    pts = r.array(vo, "<f4", ns * nv * 3, "vertex positions").reshape(-1, 3).astype(np.float32)
    params = {"tfx_version": 3.0, "tfx_follow_hairs_per_guide": int(follow), "tfx_both_ends_immovable": bool(both)}
    return finish(Groom(points=pts, strand_offsets=np.arange(ns + 1, dtype=np.int64) * nv, params=params), path)


def _read_tfx_v4(r: ByteReader, path, version: float) -> Groom:
    r.need(0, V4_HEADER, "the 160-byte TressFX 4 header")
    ns, nv = r.unpack("2I", 4, "header counts")
    offs = r.unpack("5I", 12, "array offsets")
    if nv not in (4, 8, 16, 32, 64):
        raise GroomFormatError(path, f"vertices per strand is {nv}; expected a power of two from 4 to 64", offset=8)
    _check_offsets(r, path, offs, V4_OFFSET_NAMES, V4_HEADER, 12)
    vo = offs[0]
    check_count(path, ns, "strand count", (r.size - vo) // (16 * nv), offset=4, minimum=1)
    n = ns * nv
    sizes = (16 * n, 8 * ns, 8 * n, 4 * ns, 16 * n)
    for k, (o, sz) in enumerate(zip(offs, sizes)):
        if o:
            r.need(o, sz, f"the {V4_OFFSET_NAMES[k]} array")
    end = max(o + sz for o, sz in zip(offs, sizes) if o)
    if end != r.size:  # the loader reads S * V records from each offset: a smaller S would drop strands
        raise GroomFormatError(path, f"the header's {ns} strands x {nv} vertices end at byte {end} but the file has "
                                     f"{r.size} bytes ({r.size - end} bytes not read); is the strand count wrong?",
                               offset=4)
    xyzw = r.array(vo, "<f4", 4 * n, "vertex positions").reshape(n, 4)
    w = xyzw[:, 3]
    bad = np.nonzero(~np.isfinite(w) | (w < 0))[0]
    if bad.size:
        i = int(bad[0])
        raise GroomFormatError(path, f"vertex {i % nv} has inverse mass w = {float(w[i])!r}; expected a finite value "
                                     f">= 0 (0 pinned, 1 free)", offset=vo + 16 * i + 12, strand=i // nv)
    pts = np.ascontiguousarray(xyzw[:, :3], dtype=np.float32)
    params = {"tfx_version": float(version)}
    return finish(Groom(points=pts, strand_offsets=np.arange(ns + 1, dtype=np.int64) * nv, pinned=w == 0,
                        params=params), path)


def _check_offsets(r: ByteReader, path, offs, names, header: int, at: int) -> None:
    if offs[0] == 0:
        raise GroomFormatError(path, f"the {names[0]} offset is 0; the file has no positions", offset=at)
    for k, o in enumerate(offs):
        if o and (o < header or o >= r.size or o % 4):
            raise GroomFormatError(path, f"the {names[k]} offset {o} is outside the data (expected a multiple of 4 "
                                         f"in [{header}, {r.size}))", offset=at + 4 * k)


def _read_tfx_ascii(data: bytes, path) -> Groom:
    lines = data.split(b"\n")
    params: dict = {}
    counts: list[int] = []
    coords: list[bytes] = []
    declared = None
    i = 0
    nl = len(lines)
    version_seen = False
    while i < nl:
        tok = lines[i].split()
        i += 1
        if not tok or tok[0].startswith(b"#"):
            continue
        key = tok[0].decode("latin-1")
        if key == "strand":
            # strand <i> numVerts <n> texcoord <u> <v>
            if len(tok) < 4 or tok[2] != b"numVerts":
                raise GroomFormatError(path, "expected 'strand <i> numVerts <n> ...'", line=i)
            try:
                n = int(tok[3])
            except ValueError:
                raise GroomFormatError(path, f"numVerts {tok[3]!r} is not an integer", line=i) from None
            check_count(path, n, "numVerts", nl - i, line=i, minimum=0)
            block = lines[i:i + n]
            toks = b" ".join(block).split()
            if len(toks) != 3 * n:
                for j, ln in enumerate(block):
                    if len(ln.split()) != 3:
                        raise GroomFormatError(path, f"expected 3 coordinates 'x y z', found {len(ln.split())} "
                                                     f"values", line=i + j + 1, strand=len(counts))
            coords.append(b" ".join(toks))
            counts.append(n)
            i += n
            continue
        if counts:  # after the strands only strands follow: a count too small leaves coordinates here
            s = len(counts) - 1
            raise GroomFormatError(path, f"expected 'strand {s + 1} numVerts ...' or the end of the file after "
                                         f"the {counts[-1]} points of strand {s} (its numVerts), found "
                                         f"{lines[i - 1].strip()[:40].decode('latin-1')!r}; is numVerts too small?",
                                   line=i, strand=s)
        if not (tok[0][:1].isalpha() or tok[0][:1] == b"_"):
            raise GroomFormatError(path, f"expected a header keyword ('version', 'numStrands', ...), found "
                                         f"{lines[i - 1].strip()[:40].decode('latin-1')!r}", line=i)
        if not version_seen and key != "version":
            raise GroomFormatError(path, f"expected the first line to be 'version 2.0', found {key!r}", line=i)
        val = [t.decode("latin-1") for t in tok[1:]]
        if key == "version":
            version_seen = True
            try:
                ver = float(val[0])
            except (ValueError, IndexError):
                raise GroomFormatError(path, f"malformed version line {lines[i - 1][:40]!r}", line=i) from None
            if not 1.0 <= ver < 3.0:
                raise GroomFormatError(path, f"unknown ASCII TressFX version {ver!r}; expected 1.x or 2.x", line=i)
            params["tfx_version"] = ver
        elif key == "numStrands":
            try:
                declared = int(val[0])
            except (ValueError, IndexError):
                raise GroomFormatError(path, "numStrands is not an integer", line=i) from None
            check_count(path, declared, "numStrands", nl, line=i, minimum=1)
        else:
            if key == "is" and val[:1] == ["sorted"]:
                key, val = "is_sorted", val[1:]
            nums = []
            for v in val:
                try:
                    x = float(v)
                    nums.append(x if np.isfinite(x) else v)
                except ValueError:
                    nums.append(v)
            params["tfx_" + key] = nums[0] if len(nums) == 1 else nums
    if not version_seen:
        raise GroomFormatError(path, "no 'version' line")
    if not counts:
        raise GroomFormatError(path, "no 'strand' records")
    if declared is not None and declared != len(counts):
        raise GroomFormatError(path, f"numStrands is {declared} but the file holds {len(counts)} strands")
    try:
        pts = np.array(b" ".join(coords).split(), dtype=np.float32).reshape(-1, 3)
    except ValueError as exc:
        raise GroomFormatError(path, f"a coordinate is not a number ({exc})") from None
    cnt = np.array(counts, dtype=np.int64)
    bad = np.nonzero(cnt < 2)[0]
    if bad.size:
        raise GroomFormatError(path, f"numVerts is {int(cnt[bad[0]])}; a strand needs at least 2",
                               strand=int(bad[0]))
    return finish(Groom(points=pts, strand_offsets=offsets_from_counts(cnt), params=params), path)


def write_tfx(groom: Groom, path, version: float = 4.0) -> None:
    """Write TressFX 4.0 (default), 3.0 binary or 2.0 ASCII; every strand needs the same vertex count.

    Version 4 stores ``w = 0`` for pinned vertices and 1 otherwise and needs a
    power-of-two vertex count from 4 to 64 (resample first if needed).
    """
    g = prepare_write(groom, "write_tfx")
    counts = g.strand_vertex_counts()
    if version in (3.0, 4.0) and np.any(counts != counts[0]):
        s = int(np.nonzero(counts != counts[0])[0][0])
        raise ValueError(f"write_tfx: strand {s} has {int(counts[s])} vertices but strand 0 has {int(counts[0])}; "
                         f"binary TressFX needs the same count on every strand")
    ns, nv = g.strand_count, int(counts[0])
    pts = np.ascontiguousarray(g.points, dtype="<f4")
    with atomic_open(path) as fh:
        if version == 4.0:
            if nv not in (4, 8, 16, 32, 64):
                raise ValueError(f"write_tfx: TressFX 4 needs 4, 8, 16, 32 or 64 vertices per strand, got {nv}")
            fh.write(struct.pack("<f7I", 4.0, ns, nv, V4_HEADER, 0, 0, 0, 0) + bytes(128))
            xyzw = np.ones((g.vertex_count, 4), dtype="<f4")
            xyzw[:, :3] = pts
            if g.pinned is not None:
                xyzw[g.pinned, 3] = 0.0
            fh.write(xyzw.tobytes())
        elif version == 3.0:
            both = int(bool(g.params.get("tfx_both_ends_immovable", False)))
            follow = int(g.params.get("tfx_follow_hairs_per_guide", 0))
            head = struct.pack("<f4I", 3.0, ns, nv, follow, both) + bytes(124) + \
                struct.pack("<6I", V3_HEADER, 0, 0, 0, 0, 0) + bytes(128)
            fh.write(head)
            fh.write(pts.tobytes())
        elif version == 2.0:
            out = ["version 2.0", f"numStrands {ns}", "is sorted 1"]
            p32 = g.points.astype(np.float32)
            rows = text_rows([p32[:, 0], p32[:, 1], p32[:, 2]], ["%.9g"] * 3).splitlines()
            for s in range(ns):
                a, b = int(g.strand_offsets[s]), int(g.strand_offsets[s + 1])
                out.append(f"strand {s} numVerts {b - a} texcoord 0.0 0.0")
                out.extend(rows[a:b])
            fh.write(("\n".join(out) + "\n").encode("ascii"))
        else:
            raise ValueError(f"write_tfx: version must be 2.0, 3.0 or 4.0, got {version!r}")


# ------------------------------------------------------------------ .tfxmesh
@dataclass
class TfxMesh:
    """A TressFX collision mesh (skinned to bones).

    Attributes:
        vertices: positions [file units], float32, shape (V, 3).
        normals: unit normals, float32, shape (V, 3).
        bone_indices: int32, shape (V, 4), into ``bone_names``.
        bone_weights: float32, shape (V, 4).
        triangles: vertex indices, int32, shape (T, 3).
        bone_names: list of the bone names, in index order.
    """

    vertices: np.ndarray
    normals: np.ndarray
    bone_indices: np.ndarray
    bone_weights: np.ndarray
    triangles: np.ndarray
    bone_names: list


def read_tfxmesh(path) -> TfxMesh:
    data = read_bytes(path)
    lines = [(k + 1, ln.split()) for k, ln in enumerate(data.split(b"\n"))]
    lines = [(k, t) for k, t in lines if t and not t[0].startswith(b"#")]
    pos = 0

    def expect(key: str) -> int:
        nonlocal pos
        if pos >= len(lines):
            raise GroomFormatError(path, f"the file ends before '{key}'")
        k, t = lines[pos]
        if t[0].decode("latin-1") != key or len(t) != 2:
            raise GroomFormatError(path, f"expected '{key} <count>', found {b' '.join(t)[:40]!r}", line=k)
        try:
            c = int(t[1])
        except ValueError:
            raise GroomFormatError(path, f"{key} {t[1]!r} is not an integer", line=k) from None
        pos += 1
        return check_count(path, c, key, len(lines) - pos, line=k)

    def table(count: int, width: int, what: str, dtype) -> np.ndarray:
        nonlocal pos
        block = lines[pos:pos + count]
        for j, (k, t) in enumerate(block):
            if len(t) != width:
                raise GroomFormatError(path, f"{what} row has {len(t)} values; expected {width}", line=k)
            if t[0] != str(j).encode():
                raise GroomFormatError(path, f"{what} row index {t[0]!r}; expected {j}", line=k)
        pos += count
        toks = [x for _, t in block for x in t]
        try:
            return np.array(toks, dtype=dtype).reshape(count, width)
        except (ValueError, OverflowError) as exc:
            raise GroomFormatError(path, f"{what}: {exc}", line=block[0][0] if block else None) from None

    if lines and lines[0][1][0] == b"numOfBones":
        nb = expect("numOfBones")
        names = []
        for j in range(nb):
            k, t = lines[pos]
            if len(t) < 2 or t[0] != str(j).encode():
                raise GroomFormatError(path, f"expected bone row '{j} <name>'", line=k)
            names.append(b" ".join(t[1:]).decode("latin-1"))
            pos += 1
    else:
        names = []
    nvert = expect("numOfVertices")
    vt = table(nvert, 15, "vertex", np.float64)
    ntri = expect("numOfTriangles")
    tri = table(ntri, 4, "triangle", np.int64)[:, 1:]
    if pos != len(lines):
        raise GroomFormatError(path, "unexpected data after the triangles", line=lines[pos][0])
    if not np.all(np.isfinite(vt)):
        raise GroomFormatError(path, f"vertex {int(np.nonzero(~np.isfinite(vt).all(axis=1))[0][0])} has a "
                                     f"non-finite value")
    bones = vt[:, 7:11]
    if np.any(bones != np.round(bones)) or np.any(bones < 0) or (names and np.any(bones >= len(names))):
        raise GroomFormatError(path, f"bone indices must be integers in [0, {len(names)})")
    if tri.size and (tri.min() < 0 or tri.max() >= nvert):
        raise GroomFormatError(path, f"a triangle index is outside [0, {nvert})")
    return TfxMesh(vertices=vt[:, 1:4].astype(np.float32), normals=vt[:, 4:7].astype(np.float32),
                   bone_indices=bones.astype(np.int32), bone_weights=vt[:, 11:15].astype(np.float32),
                   triangles=tri.astype(np.int32), bone_names=names)
