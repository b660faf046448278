"""The native format ``.thair.npz``: every Groom field in an uncompressed NumPy ``.npz``.

Members: ``format_version`` (int64 scalar, currently 1), ``points``,
``strand_offsets`` and, when set, ``radius``, ``color``, ``region``, ``guide``,
``rest_points``, ``rest_twist``, ``pinned``, ``point_frames``, ``frame_times``; ``params`` is a
JSON string, ``units`` a string.  Loading uses ``allow_pickle=False``, and every
member's declared size is checked against the archive before it is read.
"""

from __future__ import annotations

import json
import zipfile

import numpy as np

from ._util import atomic_path, finish, prepare_write, read_bytes
from .errors import GroomFormatError
from .groom import Groom

FORMAT_VERSION = 1
ARRAY_FIELDS = ("points", "strand_offsets", "radius", "color", "region", "guide", "rest_points", "rest_twist",
                "pinned", "point_frames", "frame_times")
# Deflate cannot expand data more than ~1032 times; a member claiming more is corrupt.
MAX_DEFLATE_RATIO = 1100


def _read_members(path, data_size: int) -> dict:
    out = {}
    try:
        with zipfile.ZipFile(path) as zf:
            for info in zf.infolist():
                name = info.filename
                if not name.endswith(".npy"):
                    raise GroomFormatError(path, f"unexpected archive member {name!r}; expected .npy arrays")
                if info.compress_size > data_size or (
                        info.file_size > max(info.compress_size, 1) * MAX_DEFLATE_RATIO):
                    raise GroomFormatError(path, f"member {name!r} claims {info.file_size} bytes from "
                                                 f"{info.compress_size} stored; the archive has {data_size}")
                with zf.open(info) as fh:
                    version = np.lib.format.read_magic(fh)
                    if version == (1, 0):
                        shape, fortran, dtype = np.lib.format.read_array_header_1_0(fh, max_header_size=10000)
                    elif version == (2, 0):
                        shape, fortran, dtype = np.lib.format.read_array_header_2_0(fh, max_header_size=10000)
                    else:
                        raise GroomFormatError(path, f"member {name!r}: unsupported .npy version {version}")
                    header_len = fh.tell()
                    if dtype.hasobject:
                        raise GroomFormatError(path, f"member {name!r} holds Python objects; refusing to unpickle")
                    nbytes = int(np.prod(shape, dtype=object)) * dtype.itemsize
                    if nbytes != info.file_size - header_len:
                        raise GroomFormatError(path, f"member {name!r}: the header declares {shape} {dtype} "
                                                     f"({nbytes} bytes) but the member holds "
                                                     f"{info.file_size - header_len} bytes")
                    raw = fh.read(nbytes)
                    if len(raw) != nbytes:
                        raise GroomFormatError(path, f"member {name!r} is truncated")
                    arr = np.frombuffer(raw, dtype=dtype).reshape(shape, order="F" if fortran else "C")
                out[name[:-4]] = arr
    except GroomFormatError:
        raise
    except (zipfile.BadZipFile, zipfile.LargeZipFile, ValueError, OSError, EOFError, KeyError, TypeError,
            OverflowError, NotImplementedError, SyntaxError, RuntimeError) as exc:
        # RuntimeError: zipfile raises it for encrypted members; SyntaxError: a corrupt .npy header dict.
        raise GroomFormatError(path, f"not a readable .npz archive ({type(exc).__name__}: {exc})") from None
    return out


def read_native(path) -> Groom:
    size = len(read_bytes(path))
    m = _read_members(path, size)
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
    try:
        params = json.loads(str(m["params"][()])) if "params" in m else {}
        units = str(m["units"][()]) if "units" in m else ""
    except (ValueError, TypeError, IndexError) as exc:
        raise GroomFormatError(path, f"'params' is not a JSON string ({exc})") from None
    if not isinstance(params, dict):
        raise GroomFormatError(path, f"'params' is a JSON {type(params).__name__}; expected an object")
    kw = {k: np.array(m[k]) for k in ARRAY_FIELDS if k in m}
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
