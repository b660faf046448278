"""Cem Yuksel's HAIR format (``.hair``): a 128-byte header, then optional arrays.

Layout (little-endian, no padding)::

    0   char[4]    "HAIR"
    4   uint32     strand count S
    8   uint32     point count N
    12  uint32     arrays present: 1 segments, 2 points, 4 thickness, 8 transparency, 16 colours
    16  uint32     default segment count (when bit 1 is absent)
    20  float32    default thickness
    24  float32    default transparency
    28  float32[3] default colour
    40  char[88]   free text
    then: uint16 segments[S], float32 points[N, 3], float32 thickness[N],
          float32 transparency[N], float32 colours[N, 3] (each only if its bit is set)

Mapping: thickness is a diameter, so ``radius = thickness / 2`` (exact in binary);
transparency is read, checked and dropped; the free text goes to ``params["hair_info"]``.
"""

from __future__ import annotations

import struct

import numpy as np

from ._util import (ByteReader, atomic_open, check_count, finish, offsets_from_counts, prepare_write, read_bytes,
                    warn_skipped)
from .errors import GroomFormatError
from .groom import Groom

MAGIC = b"HAIR"
HEADER_SIZE = 128
BIT_SEGMENTS, BIT_POINTS, BIT_THICKNESS, BIT_TRANSPARENCY, BIT_COLORS = 1, 2, 4, 8, 16
KNOWN_BITS = 31


def read_hair(path) -> Groom:
    data = read_bytes(path)
    r = ByteReader(data, path)
    r.need(0, HEADER_SIZE, "the 128-byte HAIR header")
    if data[:4] != MAGIC:
        raise GroomFormatError(path, f"expected the magic 'HAIR', found {data[:4]!r}", offset=0)
    ns, npts, bits, dseg = r.unpack("4I", 4, "header counts")
    dthick, dtransp = r.unpack("2f", 20, "header defaults")
    info = data[40:128].split(b"\0", 1)[0].decode("latin-1")
    if bits & ~KNOWN_BITS:
        raise GroomFormatError(path, f"unknown array flags 0x{bits & ~KNOWN_BITS:x} in the bit field 0x{bits:x} "
                                     f"(known: 1 segments, 2 points, 4 thickness, 8 transparency, 16 colours)",
                               offset=12)
    if not bits & BIT_POINTS:
        raise GroomFormatError(path, f"the bit field 0x{bits:x} has no points array (bit 2)", offset=12)
    body = r.size - HEADER_SIZE
    # Bytes per point of the arrays present, then check both counts against the file size.
    per_point = 12 + 4 * bool(bits & BIT_THICKNESS) + 4 * bool(bits & BIT_TRANSPARENCY) + 12 * bool(bits & BIT_COLORS)
    seg_bytes = 2 if bits & BIT_SEGMENTS else 0
    if ns == 0:
        raise GroomFormatError(path, "strand count is 0; expected at least 1", offset=4)
    check_count(path, ns, "strand count", body // (seg_bytes + per_point), offset=4, minimum=1)
    check_count(path, npts, "point count", (body - seg_bytes * ns) // per_point, offset=8, minimum=1)
    expected = HEADER_SIZE + seg_bytes * ns + per_point * npts
    if r.size != expected:
        raise GroomFormatError(path, f"file size {r.size} does not match the header ({ns} strands, {npts} points, "
                                     f"flags 0x{bits:x}: expected {expected} bytes)", offset=r.size)
    off = HEADER_SIZE
    if bits & BIT_SEGMENTS:
        segs = r.array(off, "<u2", ns, "segment counts").astype(np.int64)
        off += 2 * ns
    else:
        if dseg > npts:
            raise GroomFormatError(path, f"default segment count {dseg} exceeds the point count {npts}", offset=16)
        segs = np.full(ns, dseg, dtype=np.int64)
    counts = segs + 1
    total = int(counts.sum())
    if total != npts:
        raise GroomFormatError(path, f"the segment counts give {total} points (sum of segments + 1) but the header "
                                     f"says {npts}", offset=HEADER_SIZE if bits & BIT_SEGMENTS else 16)
    points = r.array(off, "<f4", 3 * npts, "points").reshape(npts, 3).astype(np.float32)
    off += 12 * npts
    radius = color = None
    if bits & BIT_THICKNESS:
        thick = r.array(off, "<f4", npts, "thickness")
        off += 4 * npts
        radius = thick.astype(np.float32) * np.float32(0.5)
    elif np.isfinite(dthick) and dthick > 0:
        radius = np.full(ns, dthick * 0.5, dtype=np.float32)
    if bits & BIT_TRANSPARENCY:
        tr = r.array(off, "<f4", npts, "transparency")
        if not np.all(np.isfinite(tr)):
            raise GroomFormatError(path, "the transparency array has a non-finite value", offset=off)
        off += 4 * npts
    if bits & BIT_COLORS:
        color = r.array(off, "<f4", 3 * npts, "colours").reshape(npts, 3).astype(np.float32)
        off += 12 * npts
    offsets = offsets_from_counts(counts)
    keep = counts >= 2
    params = {"hair_info": info} if info.strip() else {}
    g = Groom(points=points, strand_offsets=offsets, radius=radius, color=color, params=params)
    if not keep.all():  # strands of 0 segments: a bare root sample
        g = _drop_strands(g, keep, path)
        warn_skipped(path, int((~keep).sum()), ns)
    return finish(g, path)


def _drop_strands(g: Groom, keep: np.ndarray, path) -> Groom:
    counts = np.diff(g.strand_offsets)
    vkeep = np.repeat(keep, counts)
    if not keep.any():
        raise GroomFormatError(path, "no strand has at least 2 points")

    def sel(a):
        if a is None:
            return None
        return a[keep] if a.shape[0] == len(keep) else a[vkeep]

    return Groom(points=g.points[vkeep], strand_offsets=offsets_from_counts(counts[keep]), radius=sel(g.radius),
                 color=sel(g.color), params=g.params)


def write_hair(groom: Groom, path) -> None:
    """Write points as float32, ``thickness = 2 * radius`` and colours when present."""
    g = prepare_write(groom, "write_hair")
    counts = g.strand_vertex_counts()
    if counts.max() - 1 > 0xFFFF:
        s = int(np.argmax(counts))
        raise ValueError(f"write_hair: strand {s} has {int(counts[s]) - 1} segments; the HAIR format stores at most "
                         f"65535 per strand")
    if g.vertex_count > 0xFFFFFFFF or g.strand_count > 0xFFFFFFFF:
        raise ValueError("write_hair: more than 2^32 - 1 points or strands")
    bits = BIT_SEGMENTS | BIT_POINTS
    thick = None
    if g.radius is not None:
        bits |= BIT_THICKNESS
        thick = (g.per_vertex(g.radius).astype(np.float32) * np.float32(2.0)).astype("<f4")
    if g.color is not None:
        bits |= BIT_COLORS
    info = str(g.params.get("hair_info", "taichi-hair")).encode("latin-1", "replace")[:87]
    header = struct.pack("<4s4I2f3f88s", MAGIC, g.strand_count, g.vertex_count, bits, 0, 0.0, 0.0, 0.0, 0.0, 0.0,
                         info)
    assert len(header) == HEADER_SIZE
    with atomic_open(path) as fh:
        fh.write(header)
        fh.write((counts - 1).astype("<u2").tobytes())
        fh.write(np.ascontiguousarray(g.points, dtype="<f4").tobytes())
        if thick is not None:
            fh.write(thick.tobytes())
        if g.color is not None:
            fh.write(np.ascontiguousarray(g.per_vertex(g.color), dtype="<f4").tobytes())
