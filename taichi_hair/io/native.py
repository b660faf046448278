"""The native format ``.thair.npz``: every Groom field in an uncompressed NumPy ``.npz``.

Members: ``format_version`` (int64 scalar, currently 1), ``points``,
``strand_offsets`` and, when set, ``radius``, ``color``, ``region``, ``guide``,
``rest_points``, ``rest_twist``, ``pinned``, ``point_frames``, ``frame_times``; ``params`` is a
JSON string (at most ``_util.MAX_PARAMS_DEPTH`` levels deep), ``units`` a string.  No
member may hold Python objects, and what the members inflate to (from the archive's
directory, before anything is read) may not exceed ``read_budget`` of the file size;
each member is read straight into its array.
"""

from __future__ import annotations

import ast
import json
import zipfile

import numpy as np

from ._util import (READ_EXPANSION, READ_SLACK_BYTES, atomic_path, file_size, finish, parse_params, prepare_write,
                    read_budget)
from .errors import GroomFormatError
from .groom import Groom

FORMAT_VERSION = 1
ARRAY_FIELDS = ("points", "strand_offsets", "radius", "color", "region", "guide", "rest_points", "rest_twist",
                "pinned", "point_frames", "frame_times")
# Deflate cannot expand data more than ~1032 times; a member claiming more is corrupt.
MAX_DEFLATE_RATIO = 1100
#: The longest .npy header accepted [bytes] (NumPy writes ~120).
MAX_NPY_HEADER = 10000
_CHUNK = 1 << 22  # bytes decompressed or copied at a time into a member's array


def _npy_header(fh, path, name: str, at: int):
    """(shape, fortran, dtype, header bytes) of a .npy member, parsed without NumPy's Python-2 fallback (whose
    tokenizer lets TokenError through on one corrupt byte)."""
    magic = fh.read(8)
    if len(magic) < 8 or magic[:6] != b"\x93NUMPY":
        raise GroomFormatError(path, f"member {name!r} is not a .npy array (magic {magic[:6]!r})", offset=at)
    major = magic[6]
    if major not in (1, 2, 3):
        raise GroomFormatError(path, f"member {name!r}: unsupported .npy version {major}.{magic[7]}", offset=at)
    width = 2 if major == 1 else 4
    raw = fh.read(width)
    hlen = int.from_bytes(raw, "little") if len(raw) == width else -1
    if not 0 < hlen <= MAX_NPY_HEADER:
        raise GroomFormatError(path, f"member {name!r}: .npy header length {hlen}; expected 1 to {MAX_NPY_HEADER}",
                               offset=at + 8)
    text = fh.read(hlen)
    if len(text) != hlen:
        raise GroomFormatError(path, f"member {name!r}: the .npy header is truncated", offset=at + 8)
    try:
        d = ast.literal_eval(text.decode("utf-8" if major == 3 else "latin-1"))
        if not isinstance(d, dict) or set(d) != {"descr", "fortran_order", "shape"}:
            raise ValueError("not a dict of descr, fortran_order and shape")
        shape, fortran = d["shape"], d["fortran_order"]
        if not (isinstance(shape, tuple) and all(isinstance(x, int) and x >= 0 for x in shape)) \
                or not isinstance(fortran, bool):
            raise ValueError(f"shape {shape!r}, fortran_order {fortran!r}")
        dtype = np.lib.format.descr_to_dtype(d["descr"])
    except Exception as exc:  # noqa: BLE001 - a bounded literal: any failure to parse it is a corrupt header
        raise GroomFormatError(path, f"member {name!r}: corrupt .npy header ({type(exc).__name__}: "
                                     f"{str(exc)[:120]})", offset=at) from None
    if dtype.hasobject:
        raise GroomFormatError(path, f"member {name!r} holds Python objects; refusing to unpickle", offset=at)
    return shape, fortran, dtype, 8 + width + hlen


def _read_member(zf, info, path) -> np.ndarray:
    name, at = info.filename, info.header_offset
    with zf.open(info) as fh:
        shape, fortran, dtype, header_len = _npy_header(fh, path, name, at)
        nbytes = int(np.prod(shape, dtype=object)) * dtype.itemsize
        if nbytes != info.file_size - header_len:
            raise GroomFormatError(path, f"member {name!r}: the header declares {shape} {dtype} ({nbytes} bytes) "
                                         f"but the member holds {info.file_size - header_len} bytes", offset=at)
        # One allocation, the array itself: the member is read (inflated) into it a chunk at a time.
        buf = np.empty(nbytes, np.uint8)
        view = memoryview(buf)
        pos = 0
        while pos < nbytes:
            got = fh.readinto(view[pos:pos + _CHUNK])
            if not got:
                raise GroomFormatError(path, f"member {name!r} is truncated ({pos} of {nbytes} bytes)", offset=at)
            pos += got
        fh.read(1)  # to the end of the member: zipfile checks its CRC there
    if dtype.itemsize == 0:
        raise GroomFormatError(path, f"member {name!r} has the empty dtype {dtype}", offset=at)
    return buf.view(dtype).reshape(shape, order="F" if fortran else "C")


def _read_members(path, data_size: int, max_bytes: int | None = None) -> dict:
    out = {}
    budget = read_budget(data_size, max_bytes)
    try:
        with open(path, "rb") as raw, zipfile.ZipFile(raw) as zf:
            infos = zf.infolist()
            for info in infos:
                name = info.filename
                if not name.endswith(".npy"):
                    raise GroomFormatError(path, f"unexpected archive member {name!r}; expected .npy arrays",
                                           offset=info.header_offset)
                if info.compress_size > data_size or (
                        info.file_size > max(info.compress_size, 1) * MAX_DEFLATE_RATIO):
                    raise GroomFormatError(path, f"member {name!r} claims {info.file_size} bytes from "
                                                 f"{info.compress_size} stored; the archive has {data_size}",
                                           offset=info.header_offset)
            # What the arrays will take, from the central directory, before anything is inflated.
            total = sum(info.file_size for info in infos)
            if total > budget:
                why = f"max_bytes={max_bytes}" if max_bytes is not None else \
                    f"{READ_EXPANSION} x the file size + {READ_SLACK_BYTES >> 20} MiB; pass max_bytes= to allow more"
                raise GroomFormatError(path, f"the members would inflate to {total} bytes, more than the {budget} "
                                             f"bytes allowed for a {data_size}-byte archive ({why})")
            for info in infos:
                out[info.filename[:-4]] = _read_member(zf, info, path)
    except GroomFormatError:
        raise
    except (zipfile.BadZipFile, zipfile.LargeZipFile, ValueError, OSError, EOFError, KeyError, TypeError,
            OverflowError, NotImplementedError, RuntimeError, IndexError, UnicodeDecodeError) as exc:
        # RuntimeError: zipfile raises it for encrypted members; NotImplementedError: an unknown compression.
        raise GroomFormatError(path, f"not a readable .npz archive ({type(exc).__name__}: {str(exc)[:200]})") \
            from None
    return out


def _text(m: dict, key: str, path) -> str | None:
    if key not in m:
        return None
    a = m[key]
    if a.shape != () or a.dtype.kind not in "US":
        raise GroomFormatError(path, f"{key!r} is a {a.dtype} array of shape {a.shape}; expected a string")
    v = a[()]
    return v.decode("utf-8", "replace") if isinstance(v, bytes) else str(v)


def read_native(path, max_bytes: int | None = None) -> Groom:
    """Read a ``.thair.npz``.

    Args:
        max_bytes: the most the members may expand to (default ``READ_EXPANSION`` times the file size plus
            1 MiB, see :func:`taichi_hair.io._util.read_budget`), checked from the archive's directory
            before anything is inflated.
    """
    size = file_size(path)
    if size == 0:
        raise GroomFormatError(path, "the file is empty")
    m = _read_members(path, size, max_bytes)
    if "format_version" not in m:
        raise GroomFormatError(path, "no 'format_version' member; not a taichi-hair groom archive")
    fv = m["format_version"]
    if fv.shape != () or fv.dtype.kind not in "iu" or int(fv) != FORMAT_VERSION:
        raise GroomFormatError(path, f"unknown format_version {fv!r}; expected {FORMAT_VERSION}")
    for req in ("points", "strand_offsets"):
        if req not in m:
            raise GroomFormatError(path, f"no {req!r} member")
    unknown = set(m) - set(ARRAY_FIELDS) - {"format_version", "params", "units"}
    if unknown:
        raise GroomFormatError(path, f"unknown members {sorted(unknown)}")
    params_text = _text(m, "params", path)
    params = parse_params(path, params_text) if params_text is not None else {}
    units = _text(m, "units", path) or ""
    kw = {k: m[k] for k in ARRAY_FIELDS if k in m}
    return finish(Groom(params=params, units=units, **kw), path)


def write_native(groom: Groom, path) -> None:
    g = prepare_write(groom, "write_native")
    arrays = {k: getattr(g, k) for k in ARRAY_FIELDS if getattr(g, k) is not None}
    arrays["format_version"] = np.int64(FORMAT_VERSION)
    arrays["params"] = np.array(json.dumps(g.params, allow_nan=False))
    arrays["units"] = np.array(g.units)
    with atomic_path(path, suffix=".npz") as tmp:
        with open(tmp, "wb") as fh:  # a file object: np.savez must not append '.npz' to the name
            np.savez(fh, **arrays)
