"""The reader of the TOML scene format (:mod:`taichi_hair.scene.file`): typed, strict access to one table.

Every key of a table must be read, or :meth:`Table.done` names the unknown one; wrong types and bad values
raise :class:`SceneError` naming the file, the table and the key.
"""

from __future__ import annotations

import dataclasses
import math


class SceneError(ValueError):
    """A bad scene file: the message names the file, the table and the key."""


class Table:
    """Typed, strict access to one TOML table: every key must be read, or ``done`` names the unknown one."""

    def __init__(self, path: str, name: str, data):
        self.path, self.name = path, name
        if not isinstance(data, dict):
            self.fail(f"must be a table, got {type(data).__name__}")
        self.data = data
        self.used = set()

    def fail(self, msg: str, key: str | None = None):
        where = f"[{self.name}]" + (f" {key}" if key else "")
        raise SceneError(f"{self.path}: {where}: {msg}")

    def has(self, key) -> bool:
        return key in self.data

    def get(self, key, kind, default=None, check=None):
        """Value of ``key`` converted to ``kind`` ("float", "int", "str", "bool", "vec3", "list", "table")."""
        self.used.add(key)
        if key not in self.data:
            return default
        v = self.data[key]
        try:
            v = convert(v, kind)
        except (TypeError, ValueError) as exc:
            self.fail(str(exc), key)
        if check is not None:
            msg = check(v)
            if msg:
                self.fail(msg, key)
        return v

    def rest(self, exclude=()) -> dict:
        """The keys not read yet (for a dataclass), marked as read."""
        out = {k: v for k, v in self.data.items() if k not in self.used and k not in exclude}
        self.used.update(out)
        return out

    def done(self, known=()):
        unknown = [k for k in self.data if k not in self.used]
        if unknown:
            names = sorted(set(self.used) | set(known))
            self.fail(f"unknown key {unknown[0]!r} (known: {', '.join(names)})", None)


def convert(v, kind):
    if kind == "float":
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ValueError(f"expected a finite number, got {v!r}")
        return float(v)
    if kind == "int":
        if isinstance(v, bool) or not isinstance(v, int):
            raise ValueError(f"expected an integer, got {v!r}")
        return v
    if kind == "str":
        if not isinstance(v, str):
            raise ValueError(f"expected a string, got {v!r}")
        return v
    if kind == "bool":
        if not isinstance(v, bool):
            raise ValueError(f"expected true or false, got {v!r}")
        return v
    if kind in ("vec3", "vec4"):
        n = int(kind[-1])
        if not (isinstance(v, list) and len(v) == n and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                         and math.isfinite(x) for x in v)):
            raise ValueError(f"expected a list of {n} finite numbers, got {v!r}")
        return tuple(float(x) for x in v)
    if kind == "list":
        if not isinstance(v, list):
            raise ValueError(f"expected a list, got {v!r}")
        return v
    if kind == "table":
        if not isinstance(v, dict):
            raise ValueError(f"expected a table, got {v!r}")
        return v
    raise AssertionError(kind)


def positive(v):
    return None if v > 0 else f"must be > 0, got {v!r}"


def at_least(lo):
    return lambda v: None if v >= lo else f"must be >= {lo}, got {v!r}"


def dataclass_from(table: Table, cls, values: dict, what: str):
    """``cls(**values)`` with unknown keys and invalid values reported against the table."""
    names = {f.name for f in dataclasses.fields(cls)}
    for k in values:
        if k not in names:
            table.fail(f"unknown key {k!r} for {what} (known: {', '.join(sorted(names))})")
    try:
        return cls(**values)
    except (TypeError, ValueError) as exc:
        table.fail(str(exc))

