"""The one exception every groom reader raises for a bad file."""

from __future__ import annotations

import errno
import os


class GroomFormatError(ValueError):
    """A groom file is malformed, truncated, of an unsupported version, or holds invalid data.

    The message names the file, where the problem is (a byte offset, a line or a
    strand) and what was expected, e.g.::

        back.hair: byte 4: strand count 1000000 needs at least 2000000 bytes of segment
        counts but the file has 40 bytes after the header

    Attributes:
        path: the file's path (a string; ``"<memory>"`` for in-memory data).
        offset: byte offset of the problem, or ``None``.
        line: 1-based line number of the problem (text formats), or ``None``.
        strand: index of the offending strand, or ``None``.
        reason: the bare description, without the location prefix.
    """

    def __init__(self, path, reason: str, *, offset: int | None = None, line: int | None = None,
                 strand: int | None = None):
        self.path = os.fspath(path) if path is not None else "<memory>"
        self.offset = offset
        self.line = line
        self.strand = strand
        self.reason = reason
        where = []
        if offset is not None:
            where.append(f"byte {offset}")
        if line is not None:
            where.append(f"line {line}")
        if strand is not None:
            where.append(f"strand {strand}")
        prefix = f"{self.path}: " + (", ".join(where) + ": " if where else "")
        super().__init__(prefix + reason)


class GroomFileNotFoundError(GroomFormatError, FileNotFoundError):
    """The groom path does not exist.  Both a :class:`GroomFormatError` (what every reader raises, so one
    ``except GroomFormatError`` covers every bad path) and a ``FileNotFoundError`` (what ``open`` raises, so
    code catching that keeps working); ``errno`` is ``ENOENT``."""

    def __init__(self, path, reason: str = "no such file", **where):
        super().__init__(path, reason, **where)
        self.errno = errno.ENOENT
        self.strerror = reason
        self.filename = self.path

    def __str__(self) -> str:  # the one-line message, not OSError's "[Errno 2] ..." form
        return self.args[0]
