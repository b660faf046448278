"""Strand PLY (``.ply``): ASCII, binary little-endian (and big-endian on read).

The reader follows the header's element and property lists instead of assuming
them.  Recognised content:

- ``element vertex N``: ``x y z`` (float or double; the dtype is kept),
  optional ``rest_x rest_y rest_z`` (rest pose), ``radius``, or ``width`` /
  ``thickness`` (diameters), ``red green blue`` (uchar /255, or float as is),
  ``pinned``.
- ``element strand S``: a count, read as a segment count (strand i owns
  segments + 1 consecutive vertices) unless named like a vertex count
  (``vertex_count``, ``num_vertices``, ``nverts``...); optional ``radius``,
  ``region``, ``guide``.
- without a strand element, an ``element edge`` with ``vertex1 vertex2``
  joining consecutive vertices defines the strands as its chains.

Other elements and properties are parsed, checked for size and ignored; a
list property is accepted wherever the reader does not need the value (a
``face`` element's ``vertex_indices``) and refused, naming its header line,
where it does (``x``, ``segments``, ``radius``...: one value per record).  The writer writes binary little-endian by default
(``ascii=True`` for text), colours as uchar.
"""

from __future__ import annotations

import numpy as np

from ._util import (ByteReader, atomic_open, finish, float_format, offsets_from_counts, prepare_write, read_bytes,
                    text_rows)
from .errors import GroomFormatError
from .groom import Groom

TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
FORMATS = {"ascii": None, "binary_little_endian": "<", "binary_big_endian": ">"}
SEGMENT_NAMES = ("segments", "segment_count", "num_segments", "nsegments", "nsegs")
VERTEX_COUNT_NAMES = ("vertex_count", "num_vertices", "nverts", "nvertices", "point_count", "num_points",
                      "npoints", "vertices")
MAX_HEADER_BYTES = 1 << 20
#: Properties the reader uses, per element: each must be a scalar (one value per record), not a list.
SCALAR_PROPERTIES = {
    "vertex": {"x", "y", "z", "rest_x", "rest_y", "rest_z", "radius", "width", "thickness", "red", "green", "blue",
               "r", "g", "b", "pinned"},
    "strand": set(SEGMENT_NAMES + VERTEX_COUNT_NAMES) | {"radius", "region", "guide"},
    "edge": {"vertex1", "vertex2", "v1", "v2"},
}


class _Element:
    def __init__(self, name: str, count: int, line: int):
        self.name = name
        self.count = count
        self.line = line
        self.props: list[tuple[str, str, str | None]] = []  # (name, value type, list count type or None)
        self.prop_lines: dict[str, int] = {}  # header line of each property

    def add(self, name: str, value_type: str, count_type: str | None, line: int, path) -> None:
        if name in self.prop_lines:
            raise GroomFormatError(path, f"element {self.name!r} declares property {name!r} twice (first on line "
                                         f"{self.prop_lines[name]})", line=line)
        self.props.append((name, value_type, count_type))
        self.prop_lines[name] = line

    def lists(self) -> set:
        return {n for n, _, c in self.props if c is not None}

    @property
    def has_list(self) -> bool:
        return any(p[2] is not None for p in self.props)


def _parse_header(data: bytes, path):
    if not (data.startswith(b"ply\n") or data.startswith(b"ply\r\n")):
        raise GroomFormatError(path, f"expected the PLY magic 'ply' on the first line, found {data[:8]!r}", offset=0)
    end = data.find(b"end_header", 0, MAX_HEADER_BYTES)
    if end < 0:
        raise GroomFormatError(path, "no 'end_header' line in the first 1 MiB", offset=0)
    nl = data.find(b"\n", end)
    body = len(data) if nl < 0 else nl + 1
    try:
        lines = data[:end].decode("ascii").splitlines()
    except UnicodeDecodeError as exc:
        raise GroomFormatError(path, f"the header is not ASCII text ({exc.reason})", offset=exc.start) from None
    fmt = None
    elements: list[_Element] = []
    for i, raw in enumerate(lines[1:], start=2):
        tok = raw.split()
        if not tok or tok[0] in ("comment", "obj_info"):
            continue
        if tok[0] == "format":
            if len(tok) != 3 or tok[1] not in FORMATS or tok[2] != "1.0":
                raise GroomFormatError(path, f"unsupported format line {raw.strip()!r}; expected 'format ascii 1.0' "
                                             f"or 'format binary_little_endian 1.0'", line=i)
            fmt = tok[1]
        elif tok[0] == "element":
            if len(tok) != 3:
                raise GroomFormatError(path, f"malformed element line {raw.strip()!r}", line=i)
            try:
                count = int(tok[2])
            except ValueError:
                raise GroomFormatError(path, f"element {tok[1]!r} count {tok[2]!r} is not an integer",
                                       line=i) from None
            if count < 0:
                raise GroomFormatError(path, f"element {tok[1]!r} has a negative count {count}", line=i)
            elements.append(_Element(tok[1], count, i))
        elif tok[0] == "property":
            if not elements:
                raise GroomFormatError(path, "a property line comes before any element", line=i)
            if len(tok) == 3 and tok[1] in TYPES:
                elements[-1].add(tok[2], TYPES[tok[1]], None, i, path)
            elif len(tok) == 5 and tok[1] == "list" and tok[2] in TYPES and tok[3] in TYPES:
                if TYPES[tok[2]][0] == "f":
                    raise GroomFormatError(path, f"list count type {tok[2]!r} is not an integer type", line=i)
                elements[-1].add(tok[4], TYPES[tok[3]], TYPES[tok[2]], i, path)
            else:
                raise GroomFormatError(path, f"unsupported property line {raw.strip()!r}", line=i)
        else:
            raise GroomFormatError(path, f"unknown header keyword {tok[0]!r}", line=i)
    if fmt is None:
        raise GroomFormatError(path, "the header has no 'format' line")
    return fmt, elements, body


def _read_binary(data: bytes, path, elements, offset: int, order: str) -> dict:
    r = ByteReader(data, path)
    out = {}
    for el in elements:
        if not el.props:
            out[el.name] = {}
            continue
        if not el.has_list:
            dt = np.dtype([(n, order + t) for n, t, _ in el.props])
            if el.count * dt.itemsize > r.size - offset:
                raise GroomFormatError(path, f"element {el.name!r} count {el.count} needs {el.count * dt.itemsize} "
                                             f"bytes but {r.size - offset} remain", offset=offset)
            arr = r.array(offset, dt, el.count, f"element {el.name!r}")
            offset += el.count * dt.itemsize
            out[el.name] = {n: arr[n].astype(arr[n].dtype.newbyteorder("=")) for n, _, _ in el.props}
            continue
        # Records with lists vary in size: walk them (each is at least the fixed part long).
        minimum = sum(np.dtype(c if c else t).itemsize for _, t, c in el.props)
        if el.count * minimum > r.size - offset:
            raise GroomFormatError(path, f"element {el.name!r} count {el.count} needs at least "
                                         f"{el.count * minimum} bytes but {r.size - offset} remain", offset=offset)
        uniform = _uniform_records(r.data, el, offset, order, r.size)
        if uniform is not None:
            # Every record's lists as long as the first one's (triangles only, say): one structured view.
            out[el.name], offset = uniform
            continue
        # Scalars go into arrays of the element's count (bounded by the size check above); lists, which the
        # reader never uses (a used property must be a scalar), are walked over, not kept.
        cols = {n: np.empty(el.count, order + t) for n, t, c in el.props if c is None}
        steps = [(cols.get(n), np.dtype(order + (c or t)), None if c is None else np.dtype(order + t), n)
                 for n, t, c in el.props]
        data_ = r.data
        for j in range(el.count):
            for col, dt, item, n in steps:
                r.need(offset, dt.itemsize, f"element {el.name!r} property {n!r}")
                v = np.frombuffer(data_, dt, 1, offset)[0]
                offset += dt.itemsize
                if item is None:
                    col[j] = v
                    continue
                k = int(v)
                if k < 0:
                    raise GroomFormatError(path, f"element {el.name!r} list {n!r} has a negative length {k}",
                                           offset=offset)
                r.need(offset, k * item.itemsize, f"element {el.name!r} list {n!r}")
                offset += k * item.itemsize
        out[el.name] = {n: c.astype(c.dtype.newbyteorder("=")) for n, c in cols.items()}
    if offset != r.size:
        raise GroomFormatError(path, f"{r.size - offset} bytes follow the last element; expected the file to end",
                               offset=offset)
    return out


def _uniform_records(data: bytes, el, offset: int, order: str, size: int):
    """The element read at once when each of its lists has, in every record, the length it has in the first
    (checked on every record); else None, and the caller walks the records one by one.

    Returns ({scalar property: array}, offset after the element).  Measured (a 3 MB binary PLY of 3 M
    records of an empty list, the fault-injection run's slow file): 3.6 s walked, milliseconds here."""
    if el.count == 0:
        return None
    fields, pos = [], offset
    for i, (n, t, c) in enumerate(el.props):
        if c is None:
            fields.append((f"p{i}", order + t))
            pos += np.dtype(t).itemsize
            continue
        ct = np.dtype(order + c)
        if pos + ct.itemsize > size:
            return None
        k = int(np.frombuffer(data, ct, 1, pos)[0])
        if k < 0:
            return None  # the walk reports it, naming the offset
        fields.append((f"p{i}", ct))
        if k > 0:
            fields.append((f"p{i}_items", order + t, (k,)))
        pos += ct.itemsize + k * np.dtype(t).itemsize
    rec = np.dtype(fields)
    if el.count * rec.itemsize > size - offset:
        return None
    arr = np.frombuffer(data, rec, el.count, offset)
    for i, (n, t, c) in enumerate(el.props):
        if c is not None and not np.all(arr[f"p{i}"] == arr[f"p{i}"][0]):
            return None
    cols = {n: arr[f"p{i}"].astype(arr[f"p{i}"].dtype.newbyteorder("=")) for i, (n, t, c) in enumerate(el.props)
            if c is None}
    return cols, offset + el.count * rec.itemsize


def _read_ascii(data: bytes, path, elements, offset: int) -> dict:
    lines = data[offset:].split(b"\n")
    out = {}
    li = 0
    for el in elements:
        if el.count > len(lines) - li:
            raise GroomFormatError(path, f"element {el.name!r} count {el.count} exceeds the {len(lines) - li} "
                                         f"lines left", line=el.line)
        if not el.has_list:
            chunk = lines[li:li + el.count]
            first_line = li
            li += el.count
            toks = b" ".join(chunk).split()
            k = len(el.props)
            if len(toks) != k * el.count:
                # Find the first line with the wrong number of values, for the message.
                for j, ln in enumerate(chunk):
                    if len(ln.split()) != k:
                        raise GroomFormatError(path, f"element {el.name!r} record has {len(ln.split())} values; "
                                                     f"expected {k}", line=_body_line(data, offset) + first_line + j)
            cols = {}
            for j, (n, t, _) in enumerate(el.props):
                try:
                    cols[n] = np.array(toks[j::k], dtype=t)
                except (ValueError, OverflowError) as exc:
                    raise GroomFormatError(path, f"element {el.name!r} property {n!r}: {exc}",
                                           line=_body_line(data, offset) + first_line) from None
            out[el.name] = cols
            continue
        cols = {n: np.empty(el.count, t) for n, t, c in el.props if c is None}
        for j in range(el.count):
            toks = lines[li].split()
            li += 1
            pos = 0
            try:
                for n, t, c in el.props:
                    if c is None:
                        cols[n][j] = np.array(toks[pos], dtype=t)
                        pos += 1
                    else:  # a list the reader does not use: its values checked, not kept
                        k = int(toks[pos])
                        if k < 0 or pos + 1 + k > len(toks):
                            raise ValueError(f"list {n!r} length {k} does not match the {len(toks) - pos - 1} "
                                             f"values left on the line")
                        np.array(toks[pos + 1:pos + 1 + k], dtype=t)
                        pos += 1 + k
                if pos != len(toks):
                    raise ValueError(f"{len(toks) - pos} extra values")
            except (ValueError, IndexError, OverflowError) as exc:
                raise GroomFormatError(path, f"element {el.name!r} record {j}: {exc}",
                                       line=_body_line(data, offset) + li - 1) from None
        out[el.name] = cols
    rest = b"".join(lines[li:]).strip()
    if rest:
        raise GroomFormatError(path, "data follows the last element; expected the file to end",
                               line=_body_line(data, offset) + li)
    return out


def _body_line(data: bytes, offset: int) -> int:
    return data.count(b"\n", 0, offset) + 1


def read_ply(path) -> Groom:
    data = read_bytes(path)
    fmt, elements, body = _parse_header(data, path)
    names = [e.name for e in elements]
    if "vertex" not in names:
        raise GroomFormatError(path, f"no 'vertex' element (elements: {names})")
    if len(set(names)) != len(names):
        raise GroomFormatError(path, f"an element is declared twice ({names})")
    for el in elements:  # a list where the reader needs one value per record: refused, naming its line
        for n in sorted(el.lists() & SCALAR_PROPERTIES.get(el.name, set())):
            raise GroomFormatError(path, f"element {el.name!r} property {n!r} is declared as a list; the strand "
                                         f"reader needs one value per {el.name}", line=el.prop_lines[n])
    if fmt == "ascii":
        els = _read_ascii(data, path, elements, body)
    else:
        els = _read_binary(data, path, elements, body, FORMATS[fmt])
    v = els["vertex"]
    for c in "xyz":
        if c not in v:
            raise GroomFormatError(path, f"the vertex element has no {c!r} property (has {sorted(v)})")
    dt = np.result_type(v["x"].dtype, v["y"].dtype, v["z"].dtype)
    dt = np.float32 if dt == np.float32 else np.float64
    points = np.stack([v["x"], v["y"], v["z"]], axis=1).astype(dt)
    nv = points.shape[0]
    if nv == 0:
        raise GroomFormatError(path, "the vertex element is empty")
    counts = None
    st = els.get("strand")
    if st is not None:
        cname = next((n for n in st if n in SEGMENT_NAMES + VERTEX_COUNT_NAMES), None)
        if cname is None:
            lists = next(e for e in elements if e.name == "strand").lists()
            scalar = [n for n in st if n not in lists and st[n].dtype.kind in "iu"]
            if len(scalar) != 1:
                raise GroomFormatError(path, f"cannot tell which strand property is the segment count "
                                             f"(properties: {sorted(st)}); expected one named 'segments'")
            cname = scalar[0]
        cnt = np.asarray(st[cname])
        if cnt.dtype.kind not in "iu" or cnt.ndim != 1:
            raise GroomFormatError(path, f"strand property {cname!r} must be an integer scalar")
        counts = cnt.astype(np.int64) + (0 if cname in VERTEX_COUNT_NAMES else 1)
        bad = np.nonzero(counts < 1)[0]
        if bad.size:
            raise GroomFormatError(path, f"negative {cname} ({int(cnt[bad[0]])})", strand=int(bad[0]))
        if int(counts.sum()) != nv:
            raise GroomFormatError(path, f"the strand {cname} give {int(counts.sum())} vertices but the vertex "
                                         f"element has {nv}")
        if counts.size == 0:
            raise GroomFormatError(path, "the strand element is empty")
    elif "edge" in els:
        counts = _counts_from_edges(els["edge"], nv, path)
    else:
        raise GroomFormatError(path, f"no 'strand' (or 'edge') element to split the {nv} vertices into strands")
    rest = None
    if all(k in v for k in ("rest_x", "rest_y", "rest_z")):
        rest = np.stack([v["rest_x"], v["rest_y"], v["rest_z"]], axis=1).astype(dt)
    radius = None
    if "radius" in v:
        radius = v["radius"].astype(np.float32 if v["radius"].dtype != np.float64 else np.float64)
    elif "width" in v or "thickness" in v:  # diameters (hairutil and the HAIR format use "thickness")
        d = v["width" if "width" in v else "thickness"]
        radius = d.astype(np.float64 if d.dtype == np.float64 else np.float32) * 0.5
    elif st is not None and "radius" in st:
        radius = np.asarray(st["radius"], dtype=np.float64 if st["radius"].dtype == np.float64 else np.float32)
    color = None
    cn = next((c for c in (("red", "green", "blue"), ("r", "g", "b")) if all(k in v for k in c)), None)
    if cn:
        col = np.stack([v[k] for k in cn], axis=1)
        color = col.astype(np.float32) / np.float32(255.0) if col.dtype == np.uint8 else col.astype(np.float32)
    pinned = v["pinned"].astype(bool) if "pinned" in v else None
    region = guide = None
    if st is not None and "region" in st:
        region = np.asarray(st["region"]).astype(np.int64)
    if st is not None and "guide" in st:
        guide = np.asarray(st["guide"]).astype(bool)
    keep = counts >= 2
    if not keep.all():
        s = int(np.nonzero(~keep)[0][0])
        raise GroomFormatError(path, f"has {int(counts[s])} vertex; a strand needs at least 2", strand=s)
    return finish(Groom(points=points, strand_offsets=offsets_from_counts(counts), radius=radius, color=color,
                        region=region, guide=guide, rest_points=rest, pinned=pinned,
                        params={"ply_format": fmt}), path)


def _counts_from_edges(e: dict, nv: int, path) -> np.ndarray:
    keys = [k for k in ("vertex1", "vertex2") if k in e] or [k for k in ("v1", "v2") if k in e]
    if len(keys) != 2:
        raise GroomFormatError(path, f"the edge element needs 'vertex1' and 'vertex2' properties (has {sorted(e)})")
    a = np.asarray(e[keys[0]]).astype(np.int64)
    b = np.asarray(e[keys[1]]).astype(np.int64)
    if a.size == 0:
        raise GroomFormatError(path, "the edge element is empty")
    bad = np.nonzero((b != a + 1) | (a < 0) | (b >= nv))[0]
    if bad.size:
        i = int(bad[0])
        raise GroomFormatError(path, f"edge {i} joins vertices {int(a[i])} and {int(b[i])}; only edges joining "
                                     f"consecutive vertices (i, i + 1) of the {nv} vertices are supported")
    linked = np.zeros(nv, dtype=bool)  # linked[i]: an edge joins i and i + 1
    linked[a] = True
    starts = np.nonzero(np.concatenate([[True], ~linked[:-1]]))[0]
    return np.diff(np.concatenate([starts, [nv]]))


def write_ply(groom: Groom, path, ascii: bool = False) -> None:
    """Write vertices (x y z, rest pose, per-vertex radius, colour, pinned) and a strand element."""
    g = prepare_write(groom, "write_ply")
    n, ns = g.vertex_count, g.strand_count
    ftype = "float" if g.points.dtype == np.float32 else "double"
    fdt = "<f4" if ftype == "float" else "<f8"
    vprops = [("x", fdt), ("y", fdt), ("z", fdt)]
    vcols = [g.points[:, 0], g.points[:, 1], g.points[:, 2]]
    if g.rest_points is not None:
        vprops += [("rest_x", fdt), ("rest_y", fdt), ("rest_z", fdt)]
        vcols += [g.rest_points[:, 0], g.rest_points[:, 1], g.rest_points[:, 2]]
    sprops = [("segments", "<i4")]
    scols = [g.strand_vertex_counts() - 1]
    if g.radius is not None:
        rdt = "<f4" if g.radius.dtype == np.float32 else "<f8"
        if g.radius.shape[0] == n:
            vprops.append(("radius", rdt))
            vcols.append(g.radius)
        else:
            sprops.append(("radius", rdt))
            scols.append(g.radius)
    if g.color is not None:
        c = np.clip(np.rint(g.per_vertex(g.color).astype(np.float64) * 255.0), 0, 255).astype(np.uint8)
        vprops += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
        vcols += [c[:, 0], c[:, 1], c[:, 2]]
    if g.pinned is not None:
        vprops.append(("pinned", "u1"))
        vcols.append(g.pinned.astype(np.uint8))
    if g.region is not None:
        sprops.append(("region", "<i4"))
        scols.append(g.region)
    if g.guide is not None:
        sprops.append(("guide", "u1"))
        scols.append(g.guide.astype(np.uint8))
    names = {"<f4": "float", "<f8": "double", "<i4": "int", "u1": "uchar"}
    head = ["ply", f"format {'ascii' if ascii else 'binary_little_endian'} 1.0", "comment taichi-hair strand PLY",
            f"element vertex {n}"] + [f"property {names[t]} {nm}" for nm, t in vprops] + \
           [f"element strand {ns}"] + [f"property {names[t]} {nm}" for nm, t in sprops] + ["end_header"]
    with atomic_open(path) as fh:
        fh.write(("\n".join(head) + "\n").encode("ascii"))
        for props, cols in ((vprops, vcols), (sprops, scols)):
            if ascii:
                fmts = [float_format(t) if t[-2] == "f" else "%d" for _, t in props]
                fh.write(text_rows([np.asarray(c).astype(t) for (_, t), c in zip(props, cols)], fmts).encode("ascii"))
            else:
                rec = np.empty(len(cols[0]), dtype=np.dtype(props))
                for (nm, _), c in zip(props, cols):
                    rec[nm] = c
                fh.write(rec.tobytes())

