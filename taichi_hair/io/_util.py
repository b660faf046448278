"""Shared reader/writer machinery: bounded byte access, atomic writes, float text formatting."""

from __future__ import annotations

import contextlib
import json
import os
import re
import stat
import struct
import tempfile
import warnings

import numpy as np

from .errors import GroomFileNotFoundError, GroomFormatError
from .groom import Groom

#: What a reader may allocate per byte of file when the format can expand (a deflated ``.thair.npz``):
#: checked from the headers before anything is decompressed; ``max_bytes=`` overrides it per call.
READ_EXPANSION = 16
#: Slack on top of ``READ_EXPANSION`` times the file size, for small files [bytes].
READ_SLACK_BYTES = 1 << 20


def read_budget(size: int, max_bytes: int | None = None) -> int:
    """Bytes a reader may allocate for a file of ``size`` bytes (``max_bytes`` when given)."""
    return int(max_bytes) if max_bytes is not None else READ_EXPANSION * int(size) + READ_SLACK_BYTES


def file_size(path) -> int:
    """The size of a regular file; GroomFormatError naming the path for a missing path, a folder or
    something that cannot be read (``GroomFileNotFoundError``, also a FileNotFoundError, when missing)."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise GroomFileNotFoundError(path) from None
    except (OSError, ValueError) as exc:  # ValueError: a NUL in the name
        raise GroomFormatError(path, f"cannot read the file ({_os_reason(exc)})") from None
    if stat.S_ISDIR(st.st_mode):
        raise GroomFormatError(path, "is a folder, not a groom file")
    if not stat.S_ISREG(st.st_mode):
        raise GroomFormatError(path, "is not a regular file")
    return int(st.st_size)


def _os_reason(exc: BaseException) -> str:
    return getattr(exc, "strerror", None) or str(exc)


def read_bytes(path) -> bytes:
    """The whole file in one read (its size bounds every later allocation); an empty file, a missing path
    or a folder is a GroomFormatError naming the path."""
    file_size(path)
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError as exc:
        raise GroomFormatError(path, f"cannot read the file ({_os_reason(exc)})") from None
    if not data:
        raise GroomFormatError(path, "the file is empty")
    return data


class ByteReader:
    """Little-endian access to a byte string that checks every range against its size first."""

    def __init__(self, data: bytes, path):
        self.data = data
        self.size = len(data)
        self.path = path

    def need(self, offset: int, nbytes: int, what: str) -> None:
        if offset < 0 or nbytes < 0 or offset + nbytes > self.size:
            have = max(self.size - offset, 0)
            raise GroomFormatError(self.path, f"{what} needs {nbytes} bytes but the file has {have} bytes left "
                                              f"(file size {self.size})", offset=offset)

    def unpack(self, fmt: str, offset: int, what: str):
        n = struct.calcsize("<" + fmt)
        self.need(offset, n, what)
        return struct.unpack_from("<" + fmt, self.data, offset)

    def array(self, offset: int, dtype, count: int, what: str) -> np.ndarray:
        """A read-only view of ``count`` items at ``offset`` (no allocation)."""
        dt = np.dtype(dtype)  # callers spell the byte order ("<f4")
        if count < 0:
            raise GroomFormatError(self.path, f"{what}: negative count {count}", offset=offset)
        self.need(offset, count * dt.itemsize, what)
        return np.frombuffer(self.data, dtype=dt, count=count, offset=offset)


def check_count(path, value: int, what: str, upper: int, offset: int | None = None, line: int | None = None,
                minimum: int = 0) -> int:
    """A count from a header: within [minimum, upper], else GroomFormatError (before any allocation)."""
    if value < minimum:
        raise GroomFormatError(path, f"{what} is {value}; expected at least {minimum}", offset=offset, line=line)
    if value > upper:
        raise GroomFormatError(path, f"{what} {value} is more than the file can hold (at most {upper})",
                               offset=offset, line=line)
    return int(value)


def finish(groom: Groom, path) -> Groom:
    """Validate a freshly read groom, turning ValueError into GroomFormatError naming the file."""
    try:
        groom.validate()
    except (ValueError, RecursionError) as exc:
        msg = str(exc)
        if msg.startswith("Groom: "):
            msg = msg[len("Groom: "):]
        raise GroomFormatError(path, msg) from None
    return groom


#: The deepest nesting of lists and objects accepted in a file's params JSON (a file that nests deeper is
#: refused instead of exhausting Python's recursion limit while decoding it or writing it back).
MAX_PARAMS_DEPTH = 64


def json_depth(text: str) -> int:
    """The deepest nesting of ``[`` and ``{`` in a JSON text, strings left out (vectorised: no recursion)."""
    bare = _JSON_STRING.sub("", text).encode("utf-8", "replace")
    if not bare:
        return 0
    c = np.frombuffer(bare, np.uint8)
    step = np.isin(c, _OPENS).astype(np.int64) - np.isin(c, _CLOSES)
    return int(np.cumsum(step).max(initial=0))


_JSON_STRING = re.compile(r'"(?:[^"\\]|\\.)*"')
_OPENS, _CLOSES = np.frombuffer(b"[{", np.uint8), np.frombuffer(b"]}", np.uint8)


def parse_params(path, text, what: str = "'params'", objects_only: bool = True) -> dict:
    """A params JSON object from a file: GroomFormatError naming ``what`` when it is not JSON, not an
    object (``objects_only=False``: anything else reads as ``{}``), or nests deeper than
    :data:`MAX_PARAMS_DEPTH`."""
    if not isinstance(text, str):
        raise GroomFormatError(path, f"{what} is a {type(text).__name__}; expected a JSON string")
    depth = json_depth(text)
    if depth > MAX_PARAMS_DEPTH:
        raise GroomFormatError(path, f"{what} nests lists or objects {depth} levels deep; at most "
                                     f"{MAX_PARAMS_DEPTH} are accepted")
    try:
        value = json.loads(text)
    except (ValueError, RecursionError) as exc:
        raise GroomFormatError(path, f"{what} is not JSON ({type(exc).__name__}: {str(exc)[:200]})") from None
    if not isinstance(value, dict):
        if not objects_only:
            return {}
        raise GroomFormatError(path, f"{what} is a JSON {type(value).__name__}; expected an object")
    return value


def offsets_from_counts(counts: np.ndarray) -> np.ndarray:
    off = np.zeros(len(counts) + 1, dtype=np.int64)
    np.cumsum(counts, out=off[1:])
    return off


def warn_skipped(path, skipped: int, total: int, why: str = "fewer than 2 points") -> None:
    if skipped:
        warnings.warn(f"{os.fspath(path)}: skipped {skipped} of {total} strands with {why}", stacklevel=4)


# ---------------------------------------------------------------- text
def float_format(dtype) -> str:
    """printf format that round-trips a value of ``dtype`` exactly: 9 significant digits for
    float32, 17 for float64 (shortest-repr formatting is ~4x slower in NumPy)."""
    return "%.9g" if np.dtype(dtype) == np.float32 else "%.17g"


def text_rows(columns, formats, prefix: str = "") -> str:
    """Lines ``prefix c0 c1 ...``, one per row, with a printf format per column."""
    n = len(columns[0])
    if n == 0:
        return ""
    line = prefix + " ".join(formats) + "\n"
    values = [c.tolist() for c in columns]
    flat = [v for row in zip(*values) for v in row] if len(values) > 1 else values[0]
    return (line * n) % tuple(flat)


# ---------------------------------------------------------------- atomic writes
def _fdopen(fd: int):
    """Open the temporary file's descriptor for writing (a seam for the atomic-write tests)."""
    return os.fdopen(fd, "wb")


def _umask() -> int:
    mask = os.umask(0o022)  # the only way to read it is to set it; put it straight back
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(path, suffix: str = ""):
    """Yield a temporary path in the target's directory; ``os.replace`` it onto ``path`` on success.

    On any exception the temporary file is removed and ``path`` is left as it was.
    """
    path = os.fspath(path)
    d = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(dir=d, prefix="." + os.path.basename(path) + ".", suffix=".tmp" + suffix)
    os.close(fd)
    try:
        yield tmp
        # mkstemp creates the file 0600: give it the target's mode, or what open() would (0666 & ~umask).
        try:
            mode = os.stat(path).st_mode & 0o7777
        except FileNotFoundError:
            mode = 0o666 & ~_umask()
        os.chmod(tmp, mode)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


@contextlib.contextmanager
def atomic_open(path):
    """Yield a binary file object on a temporary file; flushed and renamed onto ``path`` on success."""
    with atomic_path(path) as tmp:
        fh = _fdopen(os.open(tmp, os.O_WRONLY | os.O_TRUNC))
        try:
            yield fh
        finally:
            fh.close()


def prepare_write(groom: Groom, what: str) -> Groom:
    """Validate a groom before writing (raises ValueError naming the strand and field)."""
    if not isinstance(groom, Groom):
        raise TypeError(f"{what}: expected a Groom, got {type(groom).__name__}")
    return groom.validate()
