"""Groom file formats: read and write hair strands as a :class:`Groom`.

    from taichi_hair.io import load_groom, save_groom
    groom = load_groom("ponytail/back.tfx", scale=0.01)   # file units (cm) -> metres
    save_groom(groom, "back.thair.npz")

Formats (name: extensions, read/write):

=========  ==========================  =====  ==================================
name       extensions                  write  notes
=========  ==========================  =====  ==================================
hair       .hair                       yes    Cem Yuksel's HAIR
data       .data                       yes    USC-HairSalon (metres)
ct2hair    .bin                        no     CT2Hair (7 floats per point)
ply        .ply                        yes    strand PLY, ASCII or binary LE
tfx        .tfx                        yes    TressFX ASCII 2, binary 3 and 4
obj        .obj                        yes    OBJ ``l`` polylines
usd        .usd .usda .usdc            yes    USD BasisCurves (needs usd-core)
thair      .thair.npz .npz             yes    native: every Groom field
tfxmesh    .tfxmesh                    no     TressFX collision mesh:
                                              :func:`read_tfxmesh`
=========  ==========================  =====  ==================================

Every reader raises :class:`GroomFormatError` (a ``ValueError``) for a bad file,
checking counts against the file size before allocating; every writer writes a
temporary file in the target's directory and renames it into place.  USD files
are read by usd-core in a child process (``isolate=False`` to read in-process),
because usd-core can crash or exhaust memory on a corrupt binary file.
"""

from __future__ import annotations

import inspect
import math
import os
import warnings
import zipfile

import numpy as np

from .errors import GroomFormatError
from .groom import Groom
from .hair import read_hair, write_hair
from .usc import read_usc, write_usc
from .ct2hair import read_ct2hair
from .ply import read_ply, write_ply
from .tfx import TfxMesh, read_tfx, read_tfxmesh, write_tfx
from .obj import read_obj, write_obj
from .native import read_native, write_native
from .usd import read_usd, write_usd

READERS = {"hair": read_hair, "data": read_usc, "ct2hair": read_ct2hair, "ply": read_ply, "tfx": read_tfx,
           "obj": read_obj, "usd": read_usd, "thair": read_native}
WRITERS = {"hair": write_hair, "data": write_usc, "ply": write_ply, "tfx": write_tfx, "obj": write_obj,
           "usd": write_usd, "thair": write_native}
EXTENSIONS = {".thair.npz": "thair", ".npz": "thair", ".hair": "hair", ".data": "data", ".bin": "ct2hair",
              ".ply": "ply", ".tfx": "tfx", ".tfxmesh": "tfxmesh", ".obj": "obj", ".usd": "usd", ".usda": "usd",
              ".usdc": "usd", ".usdz": "usd"}
ALIASES = {"usc": "data", "bin": "ct2hair", "native": "thair", "npz": "thair", "usda": "usd", "usdc": "usd"}
FORMAT_NAMES = tuple(READERS) + ("tfxmesh",)

# Plausible median strand length for hair in metres.
PLAUSIBLE_LENGTH_M = (1e-3, 5.0)

__all__ = ["Groom", "GroomFormatError", "TfxMesh", "load_groom", "save_groom", "detect_format", "read_tfxmesh",
           "FORMAT_NAMES", "READERS", "WRITERS"]


def normalize_format(name: str) -> str:
    """Canonical format name for ``name`` (case-insensitive; aliases and a leading dot accepted)."""
    key = str(name).lower().lstrip(".")
    key = ALIASES.get(key, key)
    if key not in FORMAT_NAMES:
        raise ValueError(f"unknown groom format {name!r}; known: {', '.join(FORMAT_NAMES)}")
    return key


def format_from_extension(path) -> str | None:
    low = os.fspath(path).lower()
    for ext in sorted(EXTENSIONS, key=len, reverse=True):
        if low.endswith(ext):
            return EXTENSIONS[ext]
    return None


def _fits_strand_walk(data: bytes, floats_per_point: int) -> bool:
    """True when ``data`` parses exactly as int32 S, then S x (int32 n, n * k float32) (USC / CT2Hair)."""
    size = len(data)
    if size < 4 or size % 4:
        return False
    words = memoryview(data).cast("i") if np.little_endian else np.frombuffer(data, "<i4").tolist()
    ns, nw, h = words[0], len(words), 1
    if ns <= 0 or ns > nw - 1:
        return False
    for _ in range(ns):
        if h >= nw:
            return False
        n = words[h]
        if n < 0:
            return False
        h += 1 + n * floats_per_point
        if h > nw:
            return False
    return h == nw


def detect_format(path) -> str:
    """The format of ``path`` from its content (magic numbers, structure), else from its extension.

    Raises GroomFormatError for an empty file or one that matches no format, and
    OSError if it cannot be read.
    """
    by_ext = format_from_extension(path)
    size = os.path.getsize(path)
    if size == 0:
        raise GroomFormatError(path, "the file is empty")
    with open(path, "rb") as fh:
        head = fh.read(1 << 16)
    if head[:4] == b"HAIR":
        return "hair"
    if head.startswith(b"ply\n") or head.startswith(b"ply\r\n"):
        return "ply"
    if head.startswith(b"PXR-USDC") or head.startswith(b"#usda"):
        return "usd"
    if head.startswith(b"PK\x03\x04"):
        try:
            with zipfile.ZipFile(path) as zf:
                names = zf.namelist()
        except Exception:  # noqa: BLE001 - any failure to list it: not an archive we can use; the reader reports
            names = []
        if names and all(n.endswith(".npy") for n in names):
            return "thair"
        if any(n.lower().endswith((".usd", ".usda", ".usdc")) for n in names):
            return "usd"
    if size >= 160:
        version = np.frombuffer(head[:4], "<f4")[0]
        vps = int(np.frombuffer(head[8:12], "<u4")[0])
        if version == 3.0 and size >= 296 or 4.0 <= version < 5.0 and vps in (4, 8, 16, 32, 64):
            return "tfx"
    text = head.lstrip()
    if text.startswith(b"version") or (text.startswith(b"#") and b"numStrands" in head):
        if b"numStrands" in head or b"numVerts" in head:
            return "tfx"
    if b"numOfVertices" in head and (text.startswith(b"numOfBones") or text.startswith(b"#")
                                     or text.startswith(b"numOfVertices")):
        return "tfxmesh"
    lines = [ln.strip() for ln in head.split(b"\n")[:200] if ln.strip()]
    if lines and all(ln[:1] == b"#" or ln.split(b" ", 1)[0] in (b"v", b"vn", b"vt", b"l", b"o", b"g", b"s",
                                                                   b"usemtl", b"mtllib") for ln in lines[:-1]) \
            and any(ln.startswith(b"v ") for ln in lines):
        return "obj"
    if size % 4 == 0:
        with open(path, "rb") as fh:
            data = fh.read()
        fits = [f for f, k in (("data", 3), ("ct2hair", 7)) if _fits_strand_walk(data, k)]
        if len(fits) == 1:
            return fits[0]
        if fits:
            return by_ext if by_ext in fits else fits[0]
    if by_ext is not None:
        return by_ext
    raise GroomFormatError(path, "cannot tell the groom format from the content or the extension (known: "
                                 f"{', '.join(FORMAT_NAMES)})")


def _suggest_scale(median: float) -> float:
    """A power of ten bringing the median length near 20 cm (common units first)."""
    for f in (0.01, 0.001, 0.0254, 1000.0):  # cm, mm, inches, km?!
        if 0.02 <= median * f <= 2.0:
            return f
    return 10.0 ** round(math.log10(0.2 / median))


def check_plausible_units(groom: Groom, path="") -> None:
    """Warn when the median strand length is implausible for hair in metres."""
    if groom.strand_count > 4096:  # a median over an even sample of strands is plenty for a warning
        pick = np.linspace(0, groom.strand_count - 1, 4096).astype(np.int64)
        off = groom.strand_offsets
        groom = Groom(points=np.concatenate([groom.points[off[s]:off[s + 1]] for s in pick]),
                      strand_offsets=np.concatenate([[0], np.cumsum(off[pick + 1] - off[pick])]))
    med = float(np.median(groom.lengths()))
    lo, hi = PLAUSIBLE_LENGTH_M
    if lo <= med <= hi:
        return
    where = f"{os.fspath(path)}: " if path else ""
    if med <= 0 or not math.isfinite(med):
        warnings.warn(f"{where}median strand length is {med:g}; the strands are degenerate", stacklevel=3)
        return
    f = _suggest_scale(med)
    warnings.warn(f"{where}median strand length is {med:.4g} file units, implausible for hair in metres "
                  f"(expected {lo:g} to {hi:g} m); if the file is not in metres pass scale={f:g} "
                  f"(giving {med * f:.3g} m), e.g. load_groom(path, scale={f:g}) or --scale {f:g}",
                  stacklevel=3)


def load_groom(path, format: str | None = None, scale: float | None = None, **options) -> Groom:
    """Read a groom file.

    Args:
        path: the file.
        format: a format name (see :data:`FORMAT_NAMES`); default: :func:`detect_format`.
        scale: factor converting the file's length unit to metres (0.01 for
            centimetres); the groom's ``units`` becomes ``"m"``.  Without it the
            file's units are kept, and a warning is issued when the median strand
            length is implausible for hair in metres.
        options: passed to the reader (e.g. ``dtype`` for OBJ).

    Raises:
        GroomFormatError: the file is malformed (the message names the file, the
            byte offset, line or strand, and what was expected).
    """
    fmt = normalize_format(format) if format else detect_format(path)
    if fmt == "tfxmesh":
        raise GroomFormatError(path, "is a TressFX collision mesh, not a groom; use taichi_hair.io.read_tfxmesh")
    reader = READERS[fmt]
    if not format and options:
        # Options name one format's reader (dtype for OBJ, isolate for USD); detection may pick another.
        accepted = inspect.signature(reader).parameters
        options = {k: v for k, v in options.items() if k in accepted}
    groom = reader(path, **options)
    if scale is not None:
        if not (isinstance(scale, (int, float)) and math.isfinite(scale) and scale > 0):
            raise ValueError(f"load_groom: scale must be a finite positive number, got {scale!r}")
        groom = groom.scaled(float(scale), units="m")
    check_plausible_units(groom, path)
    return groom


def save_groom(groom: Groom, path, format: str | None = None, **options) -> None:
    """Write ``groom`` atomically (a temporary file in the same directory, then ``os.replace``).

    Args:
        format: a writable format name; default: from the extension.
        options: passed to the writer (``ascii=True`` for PLY, ``version=3.0`` for TFX).
    """
    fmt = normalize_format(format) if format else format_from_extension(path)
    if fmt is None:
        raise ValueError(f"save_groom: cannot tell the format from the file name {os.fspath(path)!r}; pass format= "
                         f"one of {', '.join(WRITERS)}")
    if fmt not in WRITERS:
        raise ValueError(f"save_groom: format {fmt!r} is read-only; writable: {', '.join(WRITERS)}")
    WRITERS[fmt](groom, path, **options)
