"""USC-HairSalon ``.data``: int32 strand count, then per strand int32 n and n float32[3].

Units are metres in the USC head frame (``units = "m"``); the format does not name them, so
:func:`taichi_hair.io.load_groom` leaves a file whose size is implausible for hair in metres unlabelled
(``units = ""``, with the unit warning).  Strands with fewer
than 2 points (bare scalp samples, n = 0 or 1) are skipped with one warning
giving their count.  CT2Hair's ``.bin`` has the same layout with 7 floats per
point (see :mod:`taichi_hair.io.ct2hair`); both share :func:`walk_strands`.
"""

from __future__ import annotations

import numpy as np

from ._util import atomic_open, finish, offsets_from_counts, prepare_write, read_bytes, warn_skipped
from .errors import GroomFormatError
from .groom import Groom


def walk_strands(data: bytes, path, floats_per_point: int):
    """Walk the strand headers; return (points float32 (N, floats_per_point), counts of all strands).

    Every count is checked against the bytes left before anything is allocated;
    the file must end exactly after the last strand.
    """
    size = len(data)
    if size < 4:
        raise GroomFormatError(path, f"the file has {size} bytes; expected at least the 4-byte strand count",
                               offset=0)
    if size % 4:
        raise GroomFormatError(path, f"file size {size} is not a multiple of 4 (every field is 4 bytes)",
                               offset=size - size % 4)
    # memoryview indexing is the fastest per-strand access from Python; it reads native order.
    words = memoryview(data).cast("i") if np.little_endian else np.frombuffer(data, "<i4").tolist()
    nw = len(words)
    ns = words[0]
    if ns < 0:
        raise GroomFormatError(path, f"strand count is {ns}; expected a non-negative int32", offset=0)
    if ns == 0:
        raise GroomFormatError(path, "strand count is 0; expected at least 1", offset=0)
    if ns > nw - 1:
        raise GroomFormatError(path, f"strand count {ns} needs at least {4 * ns} bytes of strand headers but the "
                                     f"file has {size - 4} bytes after the count", offset=0)
    stride = floats_per_point
    all_words = np.frombuffer(data, dtype="<i4")
    n0 = words[1]
    if n0 >= 0 and nw == 1 + ns * (1 + n0 * stride):  # every strand as long as the first: checked at once
        heads = 1 + np.arange(ns, dtype=np.int64) * (1 + n0 * stride)
        if not np.all(all_words[heads] == n0):
            heads = None
    else:
        heads = None
    if heads is None:
        heads = _walk(words, nw, ns, stride)
        if heads is None:  # a count that does not fit: walk again with the checks that name the strand
            _walk_checked(words, nw, ns, stride, size, path)
    counts = all_words[heads].astype(np.int64)
    starts = heads + 1
    # Every word but the count and the strand headers is a coordinate: drop those with one mask.
    keep = np.ones(nw, dtype=bool)
    keep[0] = False
    keep[starts - 1] = False
    pts = np.frombuffer(data, dtype="<f4")[keep].reshape(-1, stride).astype(np.float32, copy=False)
    return pts, counts


def _walk(words, nw: int, ns: int, stride: int):
    """Word index of each strand header (int64 array), or None when a count is negative or runs past the end
    of the file or the strands end before it; the loop does nothing else (it is the per-strand cost)."""
    heads = []
    append = heads.append
    h = 1
    for _ in range(ns):
        if h >= nw:
            return None
        n = words[h]
        if n < 0:
            return None
        append(h)
        h += 1 + n * stride
    if h != nw:
        return None
    return np.array(heads, dtype=np.int64)


def _walk_checked(words, nw: int, ns: int, stride: int, size: int, path) -> None:
    """The walk again, raising GroomFormatError naming the first strand whose count does not fit."""
    h = 1
    for s in range(ns):
        if h >= nw:
            raise GroomFormatError(path, f"the file ends before the header of strand {s} of {ns} "
                                         f"(expected 4 more bytes)", offset=4 * h, strand=s)
        n = words[h]
        if n < 0:
            raise GroomFormatError(path, f"point count is {n}; expected a non-negative int32", offset=4 * h, strand=s)
        if n * stride > nw - h - 1:
            raise GroomFormatError(path, f"point count {n} needs {4 * n * stride} bytes but the file has "
                                         f"{4 * (nw - h - 1)} bytes left", offset=4 * h, strand=s)
        h += 1 + n * stride
    raise GroomFormatError(path, f"{4 * (nw - h)} bytes follow the last of {ns} strands; expected the file to "
                                 f"end there", offset=4 * h)


def groom_from_walk(path, pts: np.ndarray, counts: np.ndarray, **attrs) -> Groom:
    keep = counts >= 2
    if not keep.any():
        raise GroomFormatError(path, f"none of the {len(counts)} strands has at least 2 points")
    if not keep.all():
        warn_skipped(path, int((~keep).sum()), len(counts))
        pts = pts[np.repeat(keep, counts)]
        counts = counts[keep]
    return finish(Groom(points=np.ascontiguousarray(pts[:, :3]), strand_offsets=offsets_from_counts(counts),
                        **attrs), path)


def read_usc(path) -> Groom:
    pts, counts = walk_strands(read_bytes(path), path, 3)
    return groom_from_walk(path, pts, counts, units="m")


def write_usc(groom: Groom, path) -> None:
    """Write points as float32 (the format carries nothing else)."""
    g = prepare_write(groom, "write_usc")
    counts = g.strand_vertex_counts()
    if g.strand_count > 0x7FFFFFFF or counts.max() > 0x7FFFFFFF:
        raise ValueError("write_usc: counts exceed int32")
    ns, n = g.strand_count, g.vertex_count
    out = np.empty(1 + ns + 3 * n, dtype="<u4")
    out[0] = ns
    heads = 1 + g.strand_offsets[:-1] * 3 + np.arange(ns)  # word index of each strand header
    out[heads] = counts.astype(np.uint32)
    mask = np.ones(out.shape[0], dtype=bool)
    mask[0] = False
    mask[heads] = False
    out[mask] = np.ascontiguousarray(g.points, dtype="<f4").reshape(-1).view("<u4")
    with atomic_open(path) as fh:
        fh.write(out.tobytes())
