"""Simulation checkpoints: everything a run needs to continue exactly where it stopped.

A checkpoint is one uncompressed ``.npz`` written to a temporary name and
renamed into place (a crash while writing leaves the previous checkpoint).
Members:

- ``state/<field>``: :meth:`State.to_numpy` (positions, velocities, twists, frames),
- ``solver/<key>``: :meth:`SolverADMM.checkpoint` (warm-started duals, counters, collider transforms),
- ``frame_positions``: positions of frames 0..frame [m], float, shape (frame + 1, N, 3),
- ``meta``: JSON string: ``frame`` (last completed frame), ``stats`` (one dict per frame),
  ``fingerprint`` (what the result depends on: the scene description, arch, precision,
  dt), ``version``.

Restoring state and solver from it and stepping on gives the same bits as a
run that never stopped (``tests/test_scenes.py`` checks it with contacts).
"""

from __future__ import annotations

import json
import os

import numpy as np

VERSION = 1


def write_checkpoint(path: str, state_snapshot: dict, solver_snapshot: dict, frame: int, frame_positions,
                     stats: list, fingerprint: dict) -> None:
    """Write the checkpoint atomically (``path + '.tmp.npz'`` then ``os.replace``)."""
    arrays = {f"state/{k}": v for k, v in state_snapshot.items()}
    arrays.update({f"solver/{k}": np.asarray(v) for k, v in solver_snapshot.items()})
    arrays["frame_positions"] = np.asarray(frame_positions)
    meta = {"version": VERSION, "frame": int(frame), "stats": stats, "fingerprint": fingerprint}
    arrays["meta"] = np.array(json.dumps(meta))
    tmp = path + ".tmp.npz"
    with open(tmp, "wb") as fh:
        np.savez(fh, **arrays)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def read_checkpoint(path: str) -> dict:
    """``{"state": {...}, "solver": {...}, "frame_positions": array, "frame", "stats", "fingerprint"}``.

    Raises ValueError naming the file when it is not a readable checkpoint.
    """
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            out = {"state": {}, "solver": {}}
            for k in z.files:
                if k.startswith("state/"):
                    out["state"][k[6:]] = z[k]
                elif k.startswith("solver/"):
                    out["solver"][k[7:]] = z[k]
            out["frame_positions"] = z["frame_positions"]
    except (OSError, KeyError, ValueError, EOFError) as exc:
        raise ValueError(f"{path}: not a readable checkpoint ({exc})") from None
    if meta.get("version") != VERSION:
        raise ValueError(f"{path}: checkpoint version {meta.get('version')!r}, this build reads {VERSION}")
    out.update(frame=int(meta["frame"]), stats=meta["stats"], fingerprint=meta["fingerprint"])
    if out["frame_positions"].shape[0] != out["frame"] + 1:
        raise ValueError(f"{path}: holds {out['frame_positions'].shape[0]} frames for frame index {out['frame']}")
    return out


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
