"""The sag-free rest pose after an edit: only the strands whose inputs changed are solved again.

Without a body support the rest pose of a strand depends on that strand alone: its shape, materials, root and
gravity (:mod:`taichi_hair.solvers.rest_pose`: the moments follow from its own weights, tip to root).  So after
an edit of a few strands (a grooming session's ``scale_length`` on 860 of 8,600 guides) the others keep the
moments, rest strains and rest lengths they had, and the changed strands are solved as a Model of their own
(:func:`resolve_rest_pose`).  Measured on the grooming benchmark's 8,600 guides: 0.35 s for all of them again
(BENCHMARKS.md, issue 15 item 4).

The result equals a solve of the whole Model to rounding, not bit for bit: the edge loads are a reversed
cumulative sum over the flat vertex array (``rest_pose._edge_loads``), whose rounding depends on the strands
that follow in it (tested to 1e-9 of the moments' scale).
"""

from __future__ import annotations

import time
from types import SimpleNamespace

import numpy as np

from .rest_pose import RestPoseResult, solve_rest_pose


def _sizes(host: dict) -> tuple[int, int]:
    return int(host["vertex_strand"].shape[0]), int(host["strand_vertex_start"].shape[0])


def changed_strands(old_host: dict, new_host: dict) -> np.ndarray | None:
    """Strands whose rows differ between two authored hosts of one layout (``Model.host`` before a rest pose
    is applied: per-vertex and per-strand arrays compared row by row), sorted int64; None when anything else
    differs (the layout, a per-body or scalar entry, a key), which needs a solve of the whole Model."""
    n, ns = _sizes(new_host)
    if set(old_host) != set(new_host) or _sizes(old_host) != (n, ns) \
            or not np.array_equal(old_host["strand_vertex_count"], new_host["strand_vertex_count"]):
        return None
    changed = np.zeros(ns, bool)
    strand_of = np.asarray(new_host["vertex_strand"], np.int64)
    for key, new in new_host.items():
        old = old_host[key]
        if isinstance(new, np.ndarray) and new.ndim >= 1 and new.shape[0] in (n, ns):
            if not isinstance(old, np.ndarray) or old.shape != new.shape or old.dtype != new.dtype:
                return None
            differ = (old != new).reshape(new.shape[0], -1).any(axis=1)
            if new.shape[0] == n:
                changed[strand_of[differ]] = True
            else:
                changed |= differ
        elif not (np.array_equal(old, new) if isinstance(new, np.ndarray) else old == new):
            return None
    return np.nonzero(changed)[0]


def strand_subset_host(host: dict, strands: np.ndarray) -> tuple[dict, np.ndarray]:
    """The host arrays of ``strands`` (sorted, unique) as a Model of those strands alone would hold them, and the
    rows of their vertices in ``host``: per-vertex and per-strand arrays restricted, ``vertex_strand`` and
    ``strand_vertex_start`` renumbered (the only index arrays of a host besides per-strand ``strand_body``)."""
    n, ns = _sizes(host)
    starts = np.asarray(host["strand_vertex_start"], np.int64)[strands]
    counts = np.asarray(host["strand_vertex_count"], np.int64)[strands]
    first = np.cumsum(counts) - counts
    rows = np.repeat(starts - first, counts) + np.arange(int(counts.sum()))
    sub = {}
    for key, v in host.items():
        if isinstance(v, np.ndarray) and v.ndim >= 1 and v.shape[0] == n:
            sub[key] = v[rows]
        elif isinstance(v, np.ndarray) and v.ndim >= 1 and v.shape[0] == ns:
            sub[key] = v[strands]
        else:
            sub[key] = v
    sub["vertex_strand"] = np.repeat(np.arange(strands.size), counts).astype(host["vertex_strand"].dtype)
    sub["strand_vertex_start"] = first.astype(host["strand_vertex_start"].dtype)
    return sub, rows


def resolve_rest_pose(model, previous: RestPoseResult, strands, solver_config=None, gravity=(0.0, -9.81, 0.0),
                      config=None) -> RestPoseResult:
    """:func:`~taichi_hair.solvers.rest_pose.solve_rest_pose` of the Model, computed for ``strands`` only: the
    other strands keep ``previous`` (a result for the same Model layout, solver config, gravity and rest-pose
    config, without a body support), the listed ones are solved from the Model's (authored) host as a Model of
    their own.  Stability results (``check_stability``) are dropped for the strands solved again."""
    t0 = time.perf_counter()
    if previous.vertex_support_force is not None:
        raise ValueError("resolve_rest_pose: the previous rest pose had a body support; solve the whole Model")
    strands = np.unique(np.asarray(strands, np.int64).reshape(-1))
    if strands.size and (strands[0] < 0 or strands[-1] >= model.strand_count):
        raise ValueError(f"resolve_rest_pose: field 'strands' must index the Model's {model.strand_count} strands")
    out = RestPoseResult(pair_rest_moment=previous.pair_rest_moment.copy(),
                         pair_rest_strain=previous.pair_rest_strain.copy(),
                         edge_rest_length=previous.edge_rest_length.copy(),
                         strand_rest_turn=previous.strand_rest_turn.copy(),
                         strand_residual=previous.strand_residual.copy(), measure=previous.measure)
    again = set(strands.tolist())
    out.unheld = [u for u in previous.unheld if u[0] not in again]
    out.friction_limited = [s for s in previous.friction_limited if s not in again]
    out.unstable = [u for u in previous.unstable if u[0] not in again]
    if strands.size:
        host, rows = strand_subset_host(model.host, strands)
        part = solve_rest_pose(SimpleNamespace(host=host, vertex_count=rows.size, strand_count=strands.size),
                               solver_config, gravity, config)
        if part.measure != previous.measure:
            raise ValueError(f"resolve_rest_pose: the previous rest pose was solved for the {previous.measure!r} "
                             f"strain, this solver uses {part.measure!r}")
        out.pair_rest_moment[rows] = part.pair_rest_moment
        out.pair_rest_strain[rows] = part.pair_rest_strain
        out.edge_rest_length[rows] = part.edge_rest_length
        out.strand_rest_turn[strands] = part.strand_rest_turn
        out.strand_residual[strands] = part.strand_residual
        out.unheld = sorted(out.unheld + [(int(strands[s]), why) for s, why in part.unheld])
    out.seconds = time.perf_counter() - t0
    return out
