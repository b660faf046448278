"""Simulation checkpoints: everything a run needs to continue exactly where it stopped.

A checkpoint is one uncompressed ``.npz`` written to a temporary name, flushed to disk and renamed into
place (a crash while writing leaves the previous checkpoint).  Members:

- ``state/<field>``: :meth:`State.to_numpy` (positions, velocities, twists, frames),
- ``solver/<key>``: :meth:`SolverADMM.checkpoint` (warm-started duals, counters, collider transforms),
- ``frame_positions``: positions of frames 0..frame [m], float, shape (frame + 1, N, 3),
- ``meta``: JSON string: ``frame`` (last completed frame), ``stats`` (one dict per frame),
  ``fingerprint`` (what the result depends on: the scene description, arch, precision,
  dt), ``version`` (of this layout), ``project_version`` (``taichi_hair.__version__`` that wrote it),
  ``members`` (every array member: dtype, shape and the SHA-256 of its bytes).

Reading trusts nothing (:func:`read_checkpoint`): a file that is not a readable zip, a member missing or
extra, a checksum that fails (corruption, or an edit such as frames shifted by hand), a dtype or shape that
is not the one recorded, or a non-finite value is refused with one :class:`CheckpointError` line naming the
file and what is wrong; :func:`check_layout` then compares the shapes with the Model's before anything is
loaded into a field.  Restoring state and solver from a sound checkpoint and stepping on gives the same
bits as a run that never stopped (``tests/test_scenes.py`` checks it with contacts).
"""

from __future__ import annotations

import hashlib
import json
import os

import numpy as np

VERSION = 2
#: Solver members that may legitimately hold NaN ("no BDF2 history yet").
MAY_BE_NAN = ("solver/history_dt",)
#: What every refusal ends with: how to start over.
START_OVER = "delete it (or run without --resume) to start from frame 0"


class CheckpointError(ValueError):
    """A checkpoint that cannot be trusted: one line naming the file and what is wrong."""

    def __init__(self, path, reason: str):
        self.path, self.reason = os.fspath(path), reason
        super().__init__(f"{self.path}: {reason}; {START_OVER}")


def _digest(a: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(a).view(np.uint8).reshape(-1)).hexdigest() if a.size else \
        hashlib.sha256(b"").hexdigest()


def _meta_digest(meta: dict) -> str:
    """SHA-256 of the record itself (every key but ``sha256``, keys sorted): the frame, stats and
    fingerprint are as trusted as the arrays."""
    body = {k: v for k, v in meta.items() if k != "sha256"}
    return hashlib.sha256(json.dumps(body, sort_keys=True).encode()).hexdigest()


def write_checkpoint(path: str, state_snapshot: dict, solver_snapshot: dict, frame: int, frame_positions,
                     stats: list, fingerprint: dict) -> None:
    """Write the checkpoint atomically (``path + '.tmp.npz'``, fsync, then ``os.replace``)."""
    from .. import __version__

    arrays = {f"state/{k}": np.asarray(v) for k, v in state_snapshot.items()}
    arrays.update({f"solver/{k}": np.asarray(v) for k, v in solver_snapshot.items()})
    arrays["frame_positions"] = np.asarray(frame_positions)
    members = {k: {"dtype": a.dtype.str, "shape": list(a.shape), "sha256": _digest(a)} for k, a in arrays.items()}
    meta = {"version": VERSION, "project_version": __version__, "frame": int(frame), "stats": stats,
            "fingerprint": fingerprint, "members": members}
    meta["sha256"] = _meta_digest(meta)
    arrays["meta"] = np.array(json.dumps(meta))
    tmp = path + ".tmp.npz"
    with open(tmp, "wb") as fh:
        np.savez(fh, **arrays)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def _read_meta(z, path) -> dict:
    if "meta" not in z.files:
        raise CheckpointError(path, "not a checkpoint (no 'meta' member)")
    meta_arr = z["meta"]
    if meta_arr.dtype.kind != "U" or meta_arr.shape != ():
        raise CheckpointError(path, "'meta' is not a JSON string")
    try:
        meta = json.loads(str(meta_arr))
    except (ValueError, RecursionError) as exc:
        raise CheckpointError(path, f"'meta' is not valid JSON ({str(exc)[:80]})") from None
    if not isinstance(meta, dict):
        raise CheckpointError(path, "'meta' is not a JSON object")
    if meta.get("version") != VERSION:
        raise CheckpointError(path, f"checkpoint layout version {meta.get('version')!r} (written by taichi-hair "
                                    f"{meta.get('project_version', 'before 0.1.0')}); this build reads {VERSION}")
    if meta.get("sha256") != _meta_digest(meta):
        raise CheckpointError(path, "'meta' fails its SHA-256 checksum (the file was corrupted or edited)")
    kinds = {"frame": int, "stats": list, "fingerprint": dict, "members": dict}
    for key, kind in kinds.items():
        if not isinstance(meta.get(key), kind) or isinstance(meta.get(key), bool):
            raise CheckpointError(path, f"'meta' lacks {key!r} (or it is not a {kind.__name__})")
    if meta["frame"] < 0:
        raise CheckpointError(path, f"'meta' frame {meta['frame']} is negative")
    return meta


def read_checkpoint(path: str) -> dict:
    """``{"state": {...}, "solver": {...}, "frame_positions": array, "frame", "stats", "fingerprint",
    "project_version"}``, every member checked against its recorded dtype, shape and SHA-256 and for
    non-finite values.

    Raises:
        CheckpointError: naming the file and what is wrong (never another exception).
    """
    import zipfile

    try:
        with np.load(path, allow_pickle=False) as z:
            meta = _read_meta(z, path)
            members = meta["members"]
            present = set(z.files) - {"meta"}
            missing = sorted(set(members) - present)
            if missing:
                raise CheckpointError(path, f"lacks the member {missing[0]!r}" +
                                      (f" and {len(missing) - 1} more" if len(missing) > 1 else ""))
            extra = sorted(present - set(members))
            if extra:
                raise CheckpointError(path, f"holds a member its record does not list: {extra[0]!r}")
            arrays = {}
            for name in sorted(members):
                rec = members[name]
                a = z[name]
                if not isinstance(rec, dict) or a.dtype.str != rec.get("dtype") or list(a.shape) != rec.get("shape"):
                    raise CheckpointError(path, f"member {name!r} is {a.dtype.str} {tuple(a.shape)}, its record says "
                                                f"{rec.get('dtype') if isinstance(rec, dict) else rec!r} "
                                                f"{tuple(rec.get('shape', ())) if isinstance(rec, dict) else ''}")
                if _digest(a) != rec.get("sha256"):
                    raise CheckpointError(path, f"member {name!r} fails its SHA-256 checksum (the file was "
                                                "corrupted or edited)")
                if a.dtype.kind == "f" and name not in MAY_BE_NAN and not np.all(np.isfinite(a)):
                    bad = int(np.count_nonzero(~np.isfinite(a)))
                    raise CheckpointError(path, f"member {name!r} holds {bad} non-finite value(s)")
                if a.dtype.kind not in "fiub":
                    raise CheckpointError(path, f"member {name!r} has the non-numeric dtype {a.dtype.str}")
                arrays[name] = a
    except CheckpointError:
        raise
    except FileNotFoundError:
        raise CheckpointError(path, "no such file") from None
    except (OSError, ValueError, KeyError, EOFError, RecursionError, MemoryError, zipfile.BadZipFile,
            zipfile.LargeZipFile, NotImplementedError, RuntimeError, TypeError) as exc:
        # Truncated or bit-flipped zips fail in many ways (BadZipFile, zlib/CRC errors, npy header errors).
        raise CheckpointError(path, f"not a readable checkpoint ({type(exc).__name__}: {str(exc)[:100]})") from None
    if "frame_positions" not in arrays:
        raise CheckpointError(path, "lacks the member 'frame_positions'")
    fp = arrays["frame_positions"]
    if fp.ndim != 3 or fp.shape[2] != 3 or fp.shape[0] != meta["frame"] + 1:
        raise CheckpointError(path, f"frame_positions has the shape {fp.shape}, expected ({meta['frame'] + 1}, N, 3) "
                                    f"for frame {meta['frame']}")
    out = {"state": {k[6:]: v for k, v in arrays.items() if k.startswith("state/")},
           "solver": {k[7:]: v for k, v in arrays.items() if k.startswith("solver/")},
           "frame_positions": fp, "frame": meta["frame"], "stats": meta["stats"],
           "fingerprint": meta["fingerprint"], "project_version": meta.get("project_version")}
    return out


def check_layout(path: str, ckpt: dict, state_snapshot: dict, solver_snapshot: dict) -> None:
    """Refuse (CheckpointError) a checkpoint whose members do not have the shapes of this run's State and
    solver (``State.to_numpy()`` / ``SolverADMM.checkpoint()`` of the freshly built run), before any
    ``from_numpy`` reads them.  Members of the solver that only some steps have (the BDF2 history) may be
    absent; present ones must match in shape."""
    for kind, expected in (("state", state_snapshot), ("solver", solver_snapshot)):
        got = ckpt[kind]
        for key, ref in expected.items():
            ref = np.asarray(ref)
            if key not in got:
                if kind == "solver" and key.startswith(("history_", "collider_")):
                    continue
                raise CheckpointError(path, f"lacks {kind}/{key}, which this run needs")
            if np.asarray(got[key]).shape != ref.shape:
                raise CheckpointError(path, f"{kind}/{key} has the shape {np.asarray(got[key]).shape}, this run's is "
                                            f"{ref.shape} (made for another groom or size)")
    n = next(iter(state_snapshot.values())).shape[0] if state_snapshot else None
    if n is not None and ckpt["frame_positions"].shape[1] != n:
        raise CheckpointError(path, f"frame_positions holds {ckpt['frame_positions'].shape[1]} vertices, this run has "
                                    f"{n}")


def fingerprint_difference(a: dict, b: dict, prefix: str = "") -> str | None:
    """The first key path where two fingerprints differ (None when equal)."""
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if k not in a or k not in b:
                return prefix + k
            d = fingerprint_difference(a[k], b[k], prefix + k + ".")
            if d:
                return d
        return None
    return None if a == b else prefix.rstrip(".")
