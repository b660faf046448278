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

Every reader raises :class:`GroomFormatError` (a ``ValueError``) for a bad file, a
folder or an unreadable path, with a one-line message naming the file and the byte,
line or strand (a missing path: :class:`GroomFileNotFoundError`, also a
``FileNotFoundError``).  Readers check counts against the file size before
allocating, and a count that disagrees with the data is an error; what a reader
allocates is bounded by the file's size (a deflated ``.thair.npz`` may inflate to
``_util.READ_EXPANSION`` times it, ``max_bytes=`` to allow more).  Every writer writes a
temporary file in the target's directory and renames it into place.  USD files
are read by usd-core in a child process (``isolate=False`` to read in-process),
because usd-core can crash or exhaust memory on a corrupt binary file.
"""

from __future__ import annotations

import inspect
import math
import mmap
import os
import warnings
import zipfile

import numpy as np

from ._util import file_size
from .errors import GroomFileNotFoundError, GroomFormatError
from .groom import LENGTH_CHUNK_VERTICES, Groom, strand_lengths
from .hair import read_hair, write_hair
from .usc import _walk, read_usc, write_usc
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

__all__ = ["Groom", "GroomFormatError", "GroomFileNotFoundError", "UnitsWarning", "TfxMesh", "load_groom",
           "save_groom", "detect_format", "read_tfxmesh", "FORMAT_NAMES", "READERS", "WRITERS"]


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
    view = memoryview(data)
    words = view.cast("i") if np.little_endian else np.frombuffer(data, "<i4").tolist()
    try:
        ns, nw = words[0], len(words)
        if ns <= 0 or ns > nw - 1:
            return False
        n0, k = words[1], floats_per_point
        if n0 >= 0 and nw == 1 + ns * (1 + n0 * k):  # uniform strands: one vectorised check
            heads = 1 + np.arange(ns, dtype=np.int64) * (1 + n0 * k)
            if np.all(np.frombuffer(data, "<i4")[heads] == n0):
                return True
        return _walk(words, nw, ns, k) is not None
    finally:
        if np.little_endian:
            words.release()
        view.release()  # a memory map cannot close while a view of it is alive


def detect_format(path) -> str:
    """The format of ``path`` from its content (magic numbers, structure), else from its extension.

    Raises GroomFormatError for an empty file or one that matches no format, and
    OSError if it cannot be read.
    """
    by_ext = format_from_extension(path)
    size = file_size(path)
    if size == 0:
        raise GroomFormatError(path, "the file is empty")
    try:
        with open(path, "rb") as fh:
            head = fh.read(1 << 16)
    except OSError as exc:
        raise GroomFormatError(path, f"cannot read the file ({exc.strerror or exc})") from None
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
        # A memory map: the walk touches the strand headers only, and the reader's one read of the whole file
        # comes after (from the page cache).
        with open(path, "rb") as fh, mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as data:
            fits = [f for f, k in (("data", 3), ("ct2hair", 7)) if _fits_strand_walk(data, k)]
        if len(fits) == 1:
            return fits[0]
        if fits:
            return by_ext if by_ext in fits else fits[0]
    if by_ext is not None:
        return by_ext
    raise GroomFormatError(path, "cannot tell the groom format from the content or the extension (known: "
                                 f"{', '.join(FORMAT_NAMES)})")


#: Common length units of groom files and their factor to metres, most common first.
COMMON_UNITS = (("centimetres", "cm", 0.01), ("millimetres", "mm", 0.001), ("inches", "in", 0.0254))
#: What a groom in metres looks like: the median strand length [m] and the extent of its roots [m] (a
#: scalp is about 0.2 m across).
TYPICAL_LENGTH_M, TYPICAL_ROOT_EXTENT_M = 0.2, 0.2
#: Roots spread wider than this cannot be one head in metres [m].
PLAUSIBLE_ROOT_EXTENT_M = 3.0


class UnitsWarning(UserWarning):
    """A groom's size suggests it is not in metres (the message gives the likely unit and factor)."""


#: Strands sampled for the median length of a large groom, and the most vertices the sample may copy.
SIZE_SAMPLE_STRANDS, SIZE_SAMPLE_VERTICES = 4096, 1 << 20


def groom_size(groom: Groom) -> tuple:
    """(median strand length, extent of the roots or None with fewer than 16 strands), in the groom's units.

    The root extent is the diagonal of the bounding box of the strands' first points.  Nothing is copied
    whole: lengths are summed in float64 a chunk at a time (:func:`~.groom.strand_lengths`), and a groom of
    more than ``SIZE_SAMPLE_STRANDS`` strands is measured (lengths and root box) on an even sample of them."""
    off = groom.strand_offsets
    ns = groom.strand_count
    if ns > SIZE_SAMPLE_STRANDS:  # a median and a root box over an even sample of strands: plenty for a warning
        pick = np.linspace(0, ns - 1, SIZE_SAMPLE_STRANDS).astype(np.int64)
        counts = off[pick + 1] - off[pick]
        sample_off = np.concatenate([[0], np.cumsum(counts)])
        if int(sample_off[-1]) <= SIZE_SAMPLE_VERTICES:  # gather the sampled strands' points at once
            idx = np.arange(int(sample_off[-1])) + np.repeat(off[pick] - sample_off[:-1], counts)
            lengths = strand_lengths(groom.points[idx], sample_off)
        else:  # long strands: measure each in place
            lengths = np.concatenate([strand_lengths(groom.points, off, int(s), int(s) + 1) for s in pick])
        roots = groom.points[off[pick]]
    else:
        lengths = strand_lengths(groom.points, off)
        roots = groom.points[off[:-1]]
    med = float(np.median(lengths)) if lengths.size else 0.0
    extent = None
    if ns >= 16:
        cols = np.ascontiguousarray(roots.T)  # a reduction per row of (3, S): faster than along axis 0
        lo, hi = cols.min(1).astype(np.float64), cols.max(1).astype(np.float64)
        extent = float(np.linalg.norm(hi - lo))
    return med, extent


def _suggest_scale(median: float, root_extent: float | None = None) -> tuple:
    """(factor, unit name or None): the common unit whose factor makes the groom look most like hair in
    metres (median length near 0.2 m and, when known, roots spread like a scalp), by the sum of the
    log10 distances; inches pay 0.3 (rarer, and within a factor 2.5 of centimetres).  Without a common
    unit giving 2 cm to 2 m, the power of ten that brings the median near 0.2 m."""
    def score(f, name):
        s = abs(math.log10(median * f / TYPICAL_LENGTH_M))
        if root_extent is not None and root_extent > 0:
            s += abs(math.log10(root_extent * f / TYPICAL_ROOT_EXTENT_M))
        return s + (0.3 if name == "inches" else 0.0)

    name, _, f = min(COMMON_UNITS, key=lambda u: score(u[2], u[0]))
    if 0.02 <= median * f <= 2.0:
        return f, name
    return 10.0 ** round(math.log10(TYPICAL_LENGTH_M / median)), None


def units_warning(groom: Groom, path="", applied_scale: float | None = None, context: str = "api") -> str | None:
    """The unit warning for a groom read as metres, or None when its size is plausible for hair.

    Implausible: a median strand length outside ``PLAUSIBLE_LENGTH_M``, or roots spread wider than
    ``PLAUSIBLE_ROOT_EXTENT_M``.  ``applied_scale`` is the factor already applied (the hint then gives
    the total factor); ``context`` "api" (load_groom / --scale) or "scene" (a scene file's [groom] keys).
    """
    med, extent = groom_size(groom)
    lo, hi = PLAUSIBLE_LENGTH_M
    if lo <= med <= hi and (extent is None or extent <= PLAUSIBLE_ROOT_EXTENT_M):
        return None
    where = f"{os.fspath(path)}: " if path else ""
    if med <= 0 or not math.isfinite(med):
        return f"{where}median strand length is {med:g}; the strands are degenerate"
    f, name = _suggest_scale(med, extent)
    applied = applied_scale if applied_scale is not None else 1.0
    total = f * applied
    size = f"median strand length {med:.4g} m" + (f", roots spread over {extent:.3g} m" if extent else "")
    read = f"read with scale {applied:g}" if applied_scale not in (None, 1.0) else "read as metres"
    looks = f"it looks like {name}" if name and applied in (None, 1.0) else f"a factor {f:g} more looks right"
    if context == "scene":
        unit = next((u for n, u, _ in COMMON_UNITS if n == name), None) if applied == 1.0 else None
        fix = (f'set units = "{unit}" (or scale = {total:g})' if unit else f"set scale = {total:g}") + \
            " in [groom]"
    else:
        fix = f"pass scale={total:g}, e.g. load_groom(path, scale={total:g}) or --scale {total:g}"
    return (f"{where}{size} ({read}), implausible for hair (expected a median of {lo:g} to {hi:g} m); "
            f"{looks}: {fix} (giving a median of {med * f:.3g} m)")


def describe_groom_size(groom: Groom) -> str:
    """One sentence on whether a groom (in metres) is hair-sized, for a run that diverged at once."""
    msg = units_warning(groom, context="scene")
    if msg:
        return "the groom's size looked wrong: " + msg
    med, extent = groom_size(groom)
    return (f"the groom's size looked right for metres (median strand length {med:.3g} m"
            + (f", roots over {extent:.3g} m" if extent else "") + ")")


def check_plausible_units(groom: Groom, path="") -> None:
    """Warn (``UnitsWarning``) when the groom's size is implausible for hair in metres; when it is plausible,
    warn about implausible radii and degenerate edges (:func:`geometry_warnings`)."""
    msg = units_warning(groom, path)
    if msg:
        warnings.warn(msg, UnitsWarning, stacklevel=3)
        return
    for line in geometry_warnings(groom, path):
        warnings.warn(line, UserWarning, stacklevel=3)


#: Radii of human hair [m]: 17-90 um (fine to coarse); a radius outside 5 um to 0.25 mm is warned about.
PLAUSIBLE_RADIUS_M = (5e-6, 2.5e-4)
#: Edges shorter than this [m] are warned about: shorter than a hair is thick, they make the stretch
#: stiffness (E A / l) and the bending weights (~ 1 / l^3) extreme and cost vertices for no shape.
SHORT_EDGE_M = 2e-5


def geometry_warnings(groom: Groom, path="") -> list:
    """One-line warnings of a groom in metres: radii outside :data:`PLAUSIBLE_RADIUS_M` and edges shorter than
    :data:`SHORT_EDGE_M`, naming the first strand and the count."""
    where = f"{os.fspath(path)}: " if path else ""
    out = []
    if groom.radius is not None and groom.radius.size:
        r = np.asarray(groom.radius)  # compared in its own dtype: no float64 copy
        per_strand = r.shape[0] == groom.strand_count
        lo, hi = PLAUSIBLE_RADIUS_M
        bad = np.nonzero((r < lo) | (r > hi))[0]
        if bad.size:
            k = int(bad[0])
            s = k if per_strand else int(np.searchsorted(groom.strand_offsets, k, side="right") - 1)
            out.append(f"{where}strand {s}: radius {float(r[k]) * 1e6:.4g} um is implausible for hair (human hair: "
                       f"17-90 um; {bad.size} {'strands' if per_strand else 'vertices'} outside "
                       f"{lo * 1e6:g}-{hi * 1e6:g} um); set the radius in [material] or the file")
    off = groom.strand_offsets
    first, short_count = None, 0
    # Squared edge lengths in the points' own dtype, a chunk at a time (float32 resolves 20 um edges of a
    # metre-sized groom to ~1e-3 of the threshold; no float64 copy).
    threshold = np.asarray(SHORT_EDGE_M ** 2, groom.points.dtype)
    for e0 in range(0, groom.vertex_count - 1, LENGTH_CHUNK_VERTICES):  # edges e0 .. e1 - 1
        e1 = min(e0 + LENGTH_CHUNK_VERTICES, groom.vertex_count - 1)
        p = groom.points[e0:e1 + 1]
        d = p[1:] - p[:-1]
        sq = np.einsum("ij,ij->i", d, d)
        lo, hi = np.searchsorted(off, [e0, e1 - 1], side="right") - 1
        joins = off[lo + 1:hi + 2] - 1 - e0
        sq[joins[joins < e1 - e0]] = np.inf  # the fake edges joining a tip to the next root are not short
        short = np.nonzero(sq < threshold)[0]
        if short.size:
            first = e0 + int(short[0]) if first is None else first
            short_count += int(short.size)
    if first is not None:
        k = first
        length = float(np.linalg.norm(np.asarray(groom.points[k + 1], np.float64) - groom.points[k]))
        s = int(np.searchsorted(off, k, side="right") - 1)
        out.append(f"{where}strand {s}: edge {k - int(off[s])} is {length * 1e6:.3g} um long "
                   f"({short_count} edges shorter than {SHORT_EDGE_M * 1e6:g} um): such edges make the rods "
                   "extremely stiff; resample the strands")
    return out


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
            byte offset, line or strand, and what was expected), or the path is a
            folder or cannot be read; a missing path raises
            :class:`GroomFileNotFoundError`, which is both a GroomFormatError and a
            FileNotFoundError.
    """
    file_size(path)  # a missing path or a folder: GroomFormatError naming it, whatever the format
    fmt = normalize_format(format) if format else detect_format(path)
    if fmt == "tfxmesh":
        raise GroomFormatError(path, "is a TressFX collision mesh, not a groom; use taichi_hair.io.read_tfxmesh")
    reader = READERS[fmt]
    if not format and options:
        # Options name one format's reader (dtype for OBJ, isolate for USD); detection may pick another.
        accepted = inspect.signature(reader).parameters
        options = {k: v for k, v in options.items() if k in accepted}
    groom = reader(path, **options)
    if fmt == "data" and scale is None and units_warning(groom) is not None:
        # USC-HairSalon stores metres, but the format names no unit: a .data file whose size is not hair in
        # metres keeps unknown units (as CT2Hair's and TressFX's do) instead of a wrong "m" label.
        groom.units = ""
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
