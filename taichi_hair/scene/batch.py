"""Batch specifications: many ``simulate`` runs of one base scene, as a TOML file (``taichi-hair batch``).

    [batch]                      # defaults for every run
    scene = "assets/scenes/hairball.toml"   # a built-in scene name or a scene file (relative to this file)
    frames = 24                  # any simulate option by its long name (strands, frames, seed, ...)
    set = { "solver.iterations" = 10 }      # scene-file keys by dotted name (simulate --set)

    [[runs]]                     # named runs
    name = "soft"
    strands = 50
    set = { "solver.contacts.friction" = 0.1 }

    [sweep]                      # the cross product of its lists, one run per combination
    seed = [0, 1, 2]
    "solver.contacts.friction" = [0.1, 0.3]  # a dotted key is a scene-file key

Each run is a name, the base scene, simulate options and scene-file sets; :func:`read_batch` checks
the names (unique, safe as folder names) and that options and sets are well formed, naming the file and the
run.  Which option names exist is the caller's knowledge (the CLI passes simulate's), so this module stays
free of the command line and of Dask.  With ``[[runs]]`` and ``[sweep]`` both present, the sweep is taken
over each named run (names joined with ``_``).
"""

from __future__ import annotations

import itertools
import os
import re
from dataclasses import dataclass, field

from .file import SceneError, read_toml

#: Options a spec may not set: the batch decides them per run.
RESERVED = ("out", "resume", "quiet", "func", "command", "scene")
#: Most runs one batch may expand to (a sweep's cross product grows fast).
MAX_RUNS = 10000
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,99}$")


@dataclass
class BatchRun:
    """One run: ``simulate SCENE --<option> <value> ... --set KEY=VALUE ... --out DIR/<name>``."""

    name: str
    scene: str
    options: dict = field(default_factory=dict)
    sets: dict = field(default_factory=dict)


def _value_name(v) -> str:
    text = str(v).replace("/", "-").replace(" ", "")
    return re.sub(r"[^A-Za-z0-9.-]", "", text)[:24] or "x"


def _split(path: str, where: str, table: dict, known: set) -> tuple:
    """(options, sets) of one table: ``set`` is the sets table; every other key must be a known option."""
    options, sets = {}, {}
    for k, v in table.items():
        if k == "set":
            if not isinstance(v, dict):
                raise SceneError(f"{path}: {where}: 'set' must be a table of dotted scene-file keys")
            sets.update(_flatten(v))
            continue
        if k == "name" and where.startswith("runs"):
            continue
        opt = k.replace("-", "_")
        if opt in RESERVED:
            raise SceneError(f"{path}: {where}: {k!r} is decided by the batch (each run writes DIR/<name>)")
        if opt not in known:
            raise SceneError(f"{path}: {where}: unknown simulate option {k!r} (a scene-file key goes in set = "
                             "{ ... } or as a dotted key of [sweep])")
        if isinstance(v, (dict, list)):
            raise SceneError(f"{path}: {where}: {k} must be a single value, got {type(v).__name__}")
        options[opt] = v
    return options, sets


def _flatten(table: dict, prefix: str = "") -> dict:
    """{"solver": {"contacts": {"friction": 0.3}}} (TOML's reading of dotted keys) -> {"solver.contacts.friction": 0.3};
    a quoted dotted key stays as it is."""
    out = {}
    for k, v in table.items():
        key = prefix + k
        if isinstance(v, dict):
            out.update(_flatten(v, key + "."))
        else:
            out[key] = v
    return out


def read_batch(path: str, known_options) -> list:
    """The runs of a batch file (:class:`BatchRun`), in order: the named runs, or the sweep's combinations,
    or both (the sweep over each named run).

    Args:
        path: the TOML file.
        known_options: the simulate option names a run may set (argparse ``dest`` names).

    Raises:
        SceneError: one line naming the file, the table or run, and the key.
    """
    path = os.fspath(path)
    data = read_toml(path, "the batch")
    known = set(known_options)
    for k in data:
        if k not in ("batch", "runs", "sweep"):
            raise SceneError(f"{path}: unknown table {k!r} (known: batch, runs, sweep)")
    base = data.get("batch", {})
    if not isinstance(base, dict):
        raise SceneError(f"{path}: [batch] must be a table")
    base = dict(base)
    scene = base.pop("scene", None)
    if not isinstance(scene, str) or not scene:
        raise SceneError(f"{path}: [batch]: 'scene' is required (a built-in scene name or a scene file)")
    if scene.lower().endswith(".toml") and not os.path.isabs(scene):
        scene = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(path)), scene))
    base_opts, base_sets = _split(path, "[batch]", base, known)

    runs = data.get("runs", [])
    if not isinstance(runs, list) or not all(isinstance(r, dict) for r in runs):
        raise SceneError(f"{path}: 'runs' must be an array of tables ([[runs]])")
    named = []
    for i, r in enumerate(runs):
        name = r.get("name")
        if not isinstance(name, str) or not _NAME.match(name):
            raise SceneError(f"{path}: runs[{i}]: 'name' must be a folder-safe name (letters, digits, . _ -; at "
                             f"most 100), got {name!r}")
        opts, sets = _split(path, f"runs[{i}] ({name})", r, known)
        named.append(BatchRun(name, scene, {**base_opts, **opts}, {**base_sets, **sets}))

    sweep = data.get("sweep")
    if sweep is not None:
        if not isinstance(sweep, dict) or not sweep:
            raise SceneError(f"{path}: [sweep] must be a table of lists")
        flat = {}
        for k, v in sweep.items():
            if isinstance(v, dict):  # an unquoted dotted key: TOML made it a table
                flat.update({kk: vv for kk, vv in _flatten(v, k + ".").items()})
            else:
                flat[k] = v
        axes = []
        for k, v in flat.items():
            if not isinstance(v, list) or not v:
                raise SceneError(f"{path}: [sweep]: {k} must be a non-empty list of values")
            if "." not in k:
                opt = k.replace("-", "_")
                if opt in RESERVED or opt not in known:
                    raise SceneError(f"{path}: [sweep]: unknown simulate option {k!r} (a scene-file key is "
                                     "dotted, e.g. \"solver.contacts.friction\")")
            axes.append((k, v))
        count = len(named or [None])
        for _, v in axes:
            count *= len(v)
        if count > MAX_RUNS:
            raise SceneError(f"{path}: [sweep] makes {count:,} runs (at most {MAX_RUNS:,})")
        parents = named or [BatchRun("sweep", scene, dict(base_opts), dict(base_sets))]
        out = []
        for parent in parents:
            for combo in itertools.product(*[v for _, v in axes]):
                opts, sets, parts = dict(parent.options), dict(parent.sets), [parent.name]
                for (k, _), v in zip(axes, combo):
                    if "." in k:
                        sets[k] = v
                    else:
                        opts[k.replace("-", "_")] = v
                    parts.append(f"{k.split('.')[-1]}-{_value_name(v)}")
                out.append(BatchRun("_".join(parts), scene, opts, sets))
        named = out
    if not named:
        raise SceneError(f"{path}: no runs: give [[runs]] tables and/or a [sweep] table")
    if len(named) > MAX_RUNS:
        raise SceneError(f"{path}: {len(named):,} runs (at most {MAX_RUNS:,})")
    seen = set()
    for r in named:
        if r.name in seen:
            raise SceneError(f"{path}: two runs are named {r.name!r}")
        seen.add(r.name)
    return named
