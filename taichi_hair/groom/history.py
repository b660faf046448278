"""Undo/redo history and the session log of a grooming session (Daviet 2023, Sec. 5.3).

* :class:`History`: the undo and redo stacks of snapshots (the groom, the parameters, the
  selection, the drag and the simulation switch, as :func:`snapshot` takes them), with a limit;
* :func:`what_changed`: how much of the simulation a restored snapshot invalidates;
* the log: :func:`write_log` (``session.json``, one action per line, atomically),
  :func:`parse_log` (entries with their line numbers) and :func:`check_entry` (the checks of
  :meth:`~taichi_hair.groom.session.GroomingSession.replay`), and the autosave file names.

Nothing here holds the session: the session passes what is needed and applies what comes back.
"""

from __future__ import annotations

import json
import os
import tempfile
from dataclasses import fields, replace

import numpy as np

from .config import LAYOUT_PARAMETERS, REBUILD_PARAMETERS


# =========================================================================== snapshots, undo and redo
def copy_drag(drag: dict | None) -> dict | None:
    """A deep copy of a drag state (its arrays copied), None for None."""
    return None if drag is None else {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in drag.items()}


def frozen(groom):
    """``groom`` with every array made read-only, in place, and returned.  A session's groom is never written
    into: every edit makes new arrays (``dataclasses.replace``), so undo snapshots can share the arrays
    (:func:`shared_copy`), and a write into one raises instead of changing the history behind its back."""
    for f in fields(groom):
        v = getattr(groom, f.name)
        if isinstance(v, np.ndarray):
            v.flags.writeable = False
    return groom


class ReadOnlyGroom:
    """The grooming session's ``groom`` attribute: the groom (:class:`taichi_hair.io.Groom`) is made read-only
    (:func:`frozen`) when it is assigned.  Every edit makes new arrays, and undo snapshots share them."""

    def __set_name__(self, owner, name: str) -> None:
        self._slot = "_" + name

    def __get__(self, obj, objtype=None):
        return self if obj is None else getattr(obj, self._slot)

    def __set__(self, obj, value) -> None:
        setattr(obj, self._slot, frozen(value))


def shared_copy(groom):
    """A new Groom holding the same (read-only, :func:`frozen`) arrays and a deep copy of ``params``.  Copying the
    arrays of an 86,000-strand groom for each undo step cost 0.13 s of an edit (fresh pages after a step)."""
    return replace(groom, params=json.loads(json.dumps(groom.params)))


def snapshot(groom, config, selection: np.ndarray, drag: dict | None, simulating: bool) -> dict:
    """Everything an undo restores: the groom's (read-only) arrays shared, the rest copied."""
    return {"groom": shared_copy(frozen(groom)), "config": replace(config), "selection": selection.copy(),
            "drag": copy_drag(drag), "simulating": simulating}


def what_changed(old_groom, old_config, groom, config) -> tuple[bool, bool]:
    """``(same_layout, same_rest)`` between the groom and config before and after a restore:
    ``same_layout`` the same strands, roots and layout parameters (the Model can be updated in
    place); ``same_rest`` also the same rest pose (bit for bit, same dtype) and Model parameters
    (nothing to update)."""
    same_layout = (np.array_equal(old_groom.strand_offsets, groom.strand_offsets)
                   and np.array_equal(old_groom.rest_points[old_groom.strand_offsets[:-1]],
                                      groom.rest_points[groom.strand_offsets[:-1]])
                   and all(getattr(old_config, k) == getattr(config, k) for k in LAYOUT_PARAMETERS))
    same_rest = (same_layout and old_groom.rest_points.dtype == groom.rest_points.dtype
                 and np.array_equal(old_groom.rest_points, groom.rest_points)
                 and all(getattr(old_config, k) == getattr(config, k) for k in REBUILD_PARAMETERS))
    return same_layout, same_rest


class _Rows:
    """The rows of a snapshot's array that differ from its newer neighbour's (:func:`compress`): ``rows`` (k,) int64
    and their ``values`` (k, ...), the other rows being the neighbour's."""

    __slots__ = ("rows", "values")

    def __init__(self, rows: np.ndarray, values: np.ndarray):
        self.rows, self.values = rows, values


_SAME = object()  # a snapshot's array that is the newer neighbour's own array (shared, nothing stored)


def _differing_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Indices of the rows (axis 0) of a and b, same shape and dtype, whose bits differ (so -0.0 against 0.0 differs,
    and a NaN equals itself): the exact test a bit-for-bit restore needs.  One flat comparison in the widest unsigned
    words the row width allows, then the differing words' rows (1.2 M rows x 3 float64 with 10 % changed: 11 ms,
    against 36 ms for a per-row ``any``)."""
    n = a.shape[0]
    ua = np.ascontiguousarray(a).view(np.uint8).reshape(n, -1)
    ub = np.ascontiguousarray(b).view(np.uint8).reshape(n, -1)
    width = ua.shape[1]
    for k in (8, 4, 2):
        if width % k == 0:
            ua, ub, width = ua.view(f"u{k}"), ub.view(f"u{k}"), width // k
            break
    rows = np.flatnonzero(ua.reshape(-1) != ub.reshape(-1)) // width  # non-decreasing
    if rows.size < 2:
        return rows
    first = np.empty(rows.size, dtype=bool)
    first[0] = True
    np.not_equal(rows[1:], rows[:-1], out=first[1:])
    return rows[first]


def compress(snap: dict, newer) -> None:
    """Store ``snap``'s groom, in place, as the rows of each array that differ from ``newer`` (the groom of the state
    right after it in time): an edit of 8,600 of 86,000 strands then keeps ~8-12 MB instead of two whole poses
    (57 MB at float64; ``benchmarks/probes/groom_edit_memory.py``).  Sets ``snap["bytes"]``, what the snapshot holds
    that ``newer`` does not share (for ``GroomingConfig.undo_memory_mb``).  An array shared with ``newer`` is stored
    as a reference; one with more than half its rows changed (a simulated frame moves every vertex), or of another
    shape or dtype, stays whole.  :func:`expand` undoes it."""
    g = snap.get("groom")
    if g is None or newer is None:
        return
    parts, kept = {}, {}
    own = snap["selection"].nbytes  # what this snapshot holds that its newer neighbour does not share
    for f in fields(g):
        v, w = getattr(g, f.name), getattr(newer, f.name)
        kept[f.name] = v
        if not isinstance(v, np.ndarray):
            continue
        if v is w:
            parts[f.name] = _SAME
            continue
        if (isinstance(w, np.ndarray) and v.shape == w.shape and v.dtype == w.dtype and v.ndim >= 1 and v.shape[0] > 0
                and v.dtype != object):
            rows = _differing_rows(v, w)
            if 2 * rows.size <= v.shape[0]:
                parts[f.name] = _Rows(rows, v[rows])
                own += rows.nbytes + parts[f.name].values.nbytes
                continue
        own += v.nbytes
    snap["bytes"] = own
    if parts:
        for name in parts:
            del kept[name]
        snap["groom"] = None
        snap["groom_delta"] = (type(g), kept, parts)


def expand(snap: dict, newer) -> None:
    """The whole groom of a :func:`compress`-ed ``snap`` again (read-only arrays), from ``newer``, the groom it was
    compressed against; nothing for a whole snapshot."""
    if snap.get("groom") is not None or "groom_delta" not in snap:
        return
    cls, kept, parts = snap.pop("groom_delta")
    values = dict(kept)
    for name, part in parts.items():
        w = getattr(newer, name)
        if part is _SAME:
            values[name] = w
        else:
            v = w.copy()
            v[part.rows] = part.values
            values[name] = v
    snap["groom"] = frozen(cls(**values))


class History:
    """Undo and redo stacks of snapshots (dicts of :func:`snapshot`).

    Only the snapshot on top of each stack holds its groom whole; each one below it holds the rows that differ
    from the snapshot above it (:func:`compress`), and is made whole again when it comes to the top
    (:func:`expand`).  The two tops are the states next to the current one, so every step of undo or redo
    restores the same bits as whole snapshots would (``tests/test_grooming.py``).

    Attributes:
        undo_stack: snapshots taken before each edit, oldest first.
        redo_stack: snapshots of the states undone, most recently undone last.
    """

    def __init__(self):
        self.undo_stack: list[dict] = []
        self.redo_stack: list[dict] = []

    @staticmethod
    def _put(stack: list, snap: dict) -> None:
        if stack:
            compress(stack[-1], snap["groom"])
        stack.append(snap)

    @staticmethod
    def _take(stack: list) -> dict:
        snap = stack.pop()
        if stack:
            expand(stack[-1], snap["groom"])
        return snap

    def push(self, snap: dict, limit: int, max_bytes: float = 0.0) -> None:
        """Record the state before a new edit; clears redo.  At most ``limit`` snapshots are kept, and with
        ``max_bytes`` > 0 the snapshots below the newest hold at most that many bytes (``snap["bytes"]``, set by
        :func:`compress`): the oldest beyond either are dropped."""
        self._put(self.undo_stack, snap)
        drop = max(0, len(self.undo_stack) - limit)
        if max_bytes > 0:
            held = sum(s.get("bytes", 0) for s in self.undo_stack[drop:-1])
            while drop < len(self.undo_stack) - 1 and held > max_bytes:
                held -= self.undo_stack[drop].get("bytes", 0)
                drop += 1
        del self.undo_stack[:drop]
        self.redo_stack.clear()

    def bytes_held(self) -> int:
        """Bytes the compressed snapshots of both stacks hold (the two whole ones on top not counted)."""
        return sum(s.get("bytes", 0) for s in self.undo_stack[:-1] + self.redo_stack[:-1])

    def undo(self, current: dict) -> dict:
        """The snapshot to restore for an undo; ``current`` (the state now) goes on the redo stack."""
        if not self.undo_stack:
            raise ValueError("undo: nothing to undo")
        self._put(self.redo_stack, current)
        return self._take(self.undo_stack)

    def redo(self, current: dict) -> dict:
        """The snapshot to restore for a redo; ``current`` goes back on the undo stack."""
        if not self.redo_stack:
            raise ValueError("redo: nothing to redo")
        self._put(self.undo_stack, current)
        return self._take(self.redo_stack)

    @property
    def can_undo(self) -> bool:
        return bool(self.undo_stack)

    @property
    def can_redo(self) -> bool:
        return bool(self.redo_stack)


# =========================================================================== the session log
def _strip_groom_ext(path: str) -> str:
    for ext in (".thair.npz", ".npz"):
        if path.lower().endswith(ext):
            return path[: -len(ext)]
    return os.path.splitext(path)[0]


def autosave_path_for(groom_path) -> str:
    """``<stem>.autosave.thair.npz`` beside a groom file."""
    return _strip_groom_ext(os.fspath(groom_path)) + ".autosave.thair.npz"


def autosave_log_path(autosave_path: str | None) -> str | None:
    """The log beside an autosave file (``<name>.session.json``), None for None."""
    if autosave_path is None:
        return None
    base = autosave_path
    for ext in (".thair.npz", ".npz"):
        if base.lower().endswith(ext):
            base = base[: -len(ext)]
            break
    return base + ".session.json"


def write_log(entries: list, path) -> None:
    """Write ``entries`` as a JSON list, one action per line (line i + 2 holds entry i), atomically."""
    path = os.fspath(path)
    text = "[\n" + ",\n".join(json.dumps(e, allow_nan=False) for e in entries) + "\n]\n"
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix=".tmp-", suffix=".json", dir=folder)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def parse_log(source) -> list:
    """Entries of a session log (a list, or a JSON file) as (entry, line or None)."""
    if isinstance(source, (list, tuple)):
        return [(e, None) for e in source]
    path = os.fspath(source)
    with open(path, "r", encoding="utf-8") as fh:
        text = fh.read()
    dec = json.JSONDecoder()
    pos = len(text) - len(text.lstrip())
    if not text[pos:pos + 1] == "[":
        raise ValueError(f"{path}: line {text.count(chr(10), 0, pos) + 1}: a session log is a JSON list")
    pos += 1
    out = []
    while True:
        while pos < len(text) and text[pos] in " \t\r\n,":
            pos += 1
        line = text.count("\n", 0, pos) + 1
        if pos >= len(text):
            raise ValueError(f"{path}: line {line}: unterminated JSON list")
        if text[pos] == "]":
            return out
        try:
            entry, pos = dec.raw_decode(text, pos)
        except json.JSONDecodeError as exc:
            raise ValueError(f"{path}: line {exc.lineno}, entry {len(out)}: invalid JSON ({exc.msg})") from None
        out.append((entry, line))


def check_entry(index: int, entry, line, actions) -> tuple[str, str, dict]:
    """``(where, action, params)`` of log entry ``index`` (``where`` names the entry and its line
    for error messages); raises ValueError for a non-object or an action not in ``actions``."""
    where = f"session entry {index}" + (f" (line {line})" if line is not None else "")
    if not isinstance(entry, dict) or "action" not in entry:
        raise ValueError(f"{where}: expected an object with an 'action' key, got {entry!r}")
    name = entry["action"]
    if name not in actions:
        raise ValueError(f"{where}: unknown action {name!r}; known: {', '.join(actions)}")
    return where, name, {k: v for k, v in entry.items() if k != "action"}


def warn_if_empty_select(source, where: str, name: str, params: dict, result) -> None:
    """A replayed select (replace or add) that matched no strand: a warning at its own entry, naming the file."""
    import os
    import warnings

    if name.startswith("select") and result == 0 and params.get("mode", "replace") in ("replace", "add"):
        src = f"{os.fspath(source)}: " if isinstance(source, (str, os.PathLike)) else ""
        warnings.warn(f"{src}{where}, action {name!r}: matched no strand (an edit after it finds nothing selected)",
                      UserWarning, stacklevel=3)

