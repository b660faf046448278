"""Wavefront OBJ polylines: ``v x y z`` records and one ``l i j k ...`` record per strand.

Indices are 1-based; negative indices count back from the last vertex defined
so far.  ``l`` entries of the form ``v/vt`` use the vertex index.  Other records
(``vn``, ``vt``, ``f``, ``o``, ``g``, ``usemtl``...) are ignored.  Points are
read as float32 (``dtype=np.float64`` to keep more); the writer writes 9
significant digits for float32 and 17 for float64, enough for every value to
read back bit for bit.
"""

from __future__ import annotations

import numpy as np

from ._util import atomic_open, finish, float_format, offsets_from_counts, prepare_write, read_bytes, text_rows
from .errors import GroomFormatError
from .groom import Groom


def read_obj(path, dtype=np.float32) -> Groom:
    data = read_bytes(path)
    vtok: list[bytes] = []
    nverts = 0
    ltok: list[bytes] = []  # every 'l' index token, in order
    lcount: list[int] = []  # tokens per 'l' record
    lline: list[int] = []  # line number of each 'l' record
    lseen: list[int] = []  # vertices defined before each 'l' record (for negative indices)
    lines = data.split(b"\n")
    for k, raw in enumerate(lines, start=1):
        if not raw or raw[0] in b"#\r":
            continue
        tag, _, rest = raw.strip().partition(b" ")
        if tag == b"v":
            t = rest.split()
            if len(t) not in (3, 4, 6, 7):  # x y z [w] or x y z r g b [a] (vertex colours)
                raise GroomFormatError(path, f"'v' record has {len(t)} values; expected 'v x y z'", line=k)
            vtok.extend(t[:3])
            nverts += 1
        elif tag == b"l":
            t = rest.split()
            if len(t) < 2:
                raise GroomFormatError(path, f"'l' record has {len(t)} index; a polyline needs at least 2", line=k,
                                       strand=len(lcount))
            ltok.extend(t)
            lcount.append(len(t))
            lline.append(k)
            lseen.append(nverts)
        elif tag in (b"vn", b"vt", b"vp", b"f", b"o", b"g", b"s", b"usemtl", b"mtllib", b"p", b"") or \
                tag.startswith(b"#"):
            continue
        else:
            raise GroomFormatError(path, f"unknown OBJ record {tag[:20].decode('latin-1', 'replace')!r}", line=k)
    if not lcount:
        raise GroomFormatError(path, f"no 'l' (polyline) records among {len(lines)} lines; expected one per strand")
    counts = np.array(lcount, dtype=np.int64)
    owner = np.repeat(np.arange(len(lcount)), counts)  # strand of each index token
    if b"/" in b"".join(ltok):
        ltok = [x.split(b"/", 1)[0] for x in ltok]
    try:
        idx = np.array(ltok, dtype=np.int64)
    except (ValueError, OverflowError):
        for j, x in enumerate(ltok):
            try:
                int(x)
            except ValueError:
                s = int(owner[j])
                raise GroomFormatError(path, f"'l' index {x[:20]!r} is not an integer", line=lline[s],
                                       strand=s) from None
        raise GroomFormatError(path, "an 'l' index does not fit in 64 bits") from None
    seen = np.array(lseen, dtype=np.int64)[owner]
    idx = np.where(idx > 0, idx - 1, idx + seen)
    bad = np.nonzero((idx < 0) | (idx >= seen))[0]  # index 0 maps to `seen`, so it is caught here too
    if bad.size:
        j = int(bad[0])
        s = int(owner[j])
        raise GroomFormatError(path, f"'l' index {ltok[j][:20].decode('latin-1')} refers to no vertex (1-based, "
                                     f"{int(seen[j])} defined so far; 0 is invalid)", line=lline[s], strand=s)
    try:
        verts = np.array(vtok, dtype=dtype).reshape(nverts, 3)
    except (ValueError, OverflowError) as exc:
        raise GroomFormatError(path, f"a 'v' coordinate is not a number ({exc})") from None
    return finish(Groom(points=verts[idx], strand_offsets=offsets_from_counts(counts)), path)


def write_obj(groom: Groom, path) -> None:
    g = prepare_write(groom, "write_obj")
    f = float_format(g.points.dtype)
    with atomic_open(path) as fh:
        fh.write(f"# taichi-hair: {g.strand_count} strands, {g.vertex_count} vertices\n".encode("ascii"))
        fh.write(text_rows([g.points[:, 0], g.points[:, 1], g.points[:, 2]], [f, f, f], prefix="v ").encode("ascii"))
        idx = [str(i) for i in range(1, g.vertex_count + 1)]
        off = g.strand_offsets.tolist()
        lines = ["l " + " ".join(idx[off[s]:off[s + 1]]) for s in range(g.strand_count)]
        fh.write(("\n".join(lines) + "\n").encode("ascii"))
