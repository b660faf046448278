"""Slab-parallel Gauss-Seidel of the contacts on a CPU: the contact sweeps one by one, on several threads.

Solving the contacts one after the other (``projection.solve_contacts_sequential``) converges faster per sweep
than the paper's 8 Jacobi batches and, on a CPU, costs a third of a batched sweep (no per-batch gather passes),
but it runs on one thread.  Two contacts that share no vertex can be solved at the same time without changing
the result.  So the strands are cut into ``CONTACT_SLABS`` slabs along the principal axis of their roots
(:func:`vertex_slabs`: equal strand counts, the slab of every vertex), and each contact goes to a group
(:func:`group_contacts`, which sorts the detection's contacts by group): a slab's own contacts (all its vertices in
that slab), the contacts between slabs k and k + 1, and the rest (with the contacts appended later in the step:
continuous detection, late body contacts).  A sweep (``projection.solve_contacts_slabs``) runs in four phases,
each a parallel loop over groups whose vertex sets are disjoint, each group one by one in contact index order on
its thread:

1. the slabs' own groups;
2. the groups between slabs 0|1, 2|3, 4|5, 6|7;
3. the groups between slabs 1|2, 3|4, 5|6;
4. the rest, on one thread.

The order is fixed by the model and the contacts, not by the threads, so the result is the same bits on any
number of cores (it is not the plain index order of ``"sequential"``: another Gauss-Seidel order).  The slabs are
the model's (rest roots): where hair moves far from its roots' neighbours (a pile), more contacts fall to phase 4,
which only costs speed.  The threads of a phase run at full speed only where the slabs' vertices lie apart in
memory (else they write to shared cache lines): the grooming tool orders its guides along the same axis
(``groom.guides.GuideChoice``), and the pipeline uses the slabs only where each slab is one run of vertex indices
(``ContactPipeline.slabs_contiguous``).  On the 1,000-strand hairball (strands in the order of its Fibonacci cap,
not along the axis) the pile put 24-34 % of the contacts in the rest and the run was 5-25 % slower with slabs (two
runs each, 2026-12-06).  Measured on the grooming benchmark's 8,600 guides (153k hair-hair contacts, 2
cores, kernel profiler): 61 % of the contacts in the slabs' own groups, 28 % between neighbours, 11 % in the rest;
a sweep 3.2 ms one by one in index order, 2.6 ms in slabs with the guides in index order (random in space), 1.9
ms with the guides ordered (phase 1 at twice the serial rate).  From 0dcd407 to 2026-12-06 the grooming tool's
slabs came out as descending runs (the axis's sign, see :func:`principal_axis_order`) and the pipeline did not use
them; re-measured after the fix in one process (``benchmarks/probes/slab_sweeps.py``): a sweep 0.92-1.12x the
time of the same contacts one by one, a still step 1.04-1.08x, within this VM's drift.  After the sweeps one by one
got cheaper (2026-12-06) the phases on 2 threads took 1.4x the time of the same groups in the same order on one
in two of three probe runs, the same time in the third (``projection.SLAB_ORDER``, the same bits), which is what a CPU
with up to 2 threads now runs
(``pipeline._SLAB_THREADS``): the grouping stays for its order and its locality.
"""

import numpy as np
import taichi as ti

from ..fields import CONTACT_SLABS

#: The group of the contacts that fit no slab or pair of neighbouring slabs (phase 4).
REST_GROUP = 2 * CONTACT_SLABS - 1


def principal_axis_order(points: np.ndarray) -> np.ndarray:
    """The indices of ``points`` (k, 3) [m] sorted along their principal axis (the direction of largest spread;
    stable), int64 (k,).

    The axis is oriented so that its largest component is positive: the SVD's sign is arbitrary, and the same
    points in another order (the grooming tool orders its guides with this, the pipeline's slabs rank the Model's
    strands again) could otherwise come out reversed (they did on the grooming benchmark until 2026-12-06, so its
    slabs ran backwards through memory and the slab sweeps were off)."""
    p = np.asarray(points, np.float64)
    if p.shape[0] < 2:
        return np.arange(p.shape[0])
    centred = p - p.mean(axis=0)
    _, _, vt = np.linalg.svd(centred, full_matrices=False)
    axis = vt[0] if vt[0][np.argmax(np.abs(vt[0]))] > 0 else -vt[0]
    return np.argsort(centred @ axis, kind="stable")


def slabs_are_runs(slab: np.ndarray) -> bool:
    """Whether each slab of ``slab`` (vertex_count,) [-] is one run of vertex indices, in whatever order the runs
    come (the condition of ``ContactPipeline.slabs_contiguous``)."""
    slab = np.asarray(slab)
    if slab.size == 0:
        return True
    return int(np.count_nonzero(np.diff(slab))) == len(np.unique(slab)) - 1


def vertex_slabs(strand_root: np.ndarray, vertex_strand: np.ndarray) -> np.ndarray:
    """The slab of every vertex [-], int32 (vertex_count,): strands ranked along the principal axis of their
    roots ``strand_root`` (strand_count, 3) [m], then cut into ``CONTACT_SLABS`` runs of equal strand counts."""
    count = np.asarray(strand_root).shape[0]
    rank = np.empty(count, np.int64)
    rank[principal_axis_order(strand_root)] = np.arange(count)
    return (rank * CONTACT_SLABS // max(count, 1)).astype(np.int32)[np.asarray(vertex_strand)]


@ti.kernel
def group_contacts(vertex_slab: ti.template(), con: ti.template()):
    """Sort the detection's contacts by group (the module's four phases), each group in contact index order, and
    record where each group begins (``con.contact_group_start``).  Run after the detection writes its contacts and
    before ``narrow.build_adjacency`` (it moves the fields the detection writes, and uses ``contact_delta``,
    ``contact_accumulated``, ``contact_delassus`` and ``contact_penetration``, which that then sets, as scratch).
    Why move them, not index them: one group's contacts spread over the whole list, and the threads of a phase wrote
    neighbouring entries (cache lines shared between cores) and read them out of order; indexed, the sweep took 11
    ms on 2 threads against 3.2 ms in index order on one (measured on the grooming benchmark)."""
    nc = ti.min(con.contact_count[None], con.capacity)
    for c in range(nc):
        lo = CONTACT_SLABS
        hi = -1
        for k in ti.static(range(4)):
            v = con.contact_vertex[c][k]
            if v >= 0:
                lo = ti.min(lo, vertex_slab[v])
                hi = ti.max(hi, vertex_slab[v])
        g = REST_GROUP
        if hi == lo:
            g = lo
        elif hi == lo + 1:
            g = CONTACT_SLABS + lo
        con.contact_group[c] = g
    ti.loop_config(serialize=True)
    for _ in range(1):
        fill = ti.Vector([0] * (2 * CONTACT_SLABS), ti.i32)
        for c in range(nc):
            fill[con.contact_group[c]] += 1
        run = 0
        for g in ti.static(range(2 * CONTACT_SLABS)):
            con.contact_group_start[g] = run
            run += fill[g]
            fill[g] = con.contact_group_start[g]
        con.contact_group_start[2 * CONTACT_SLABS] = run
        for c in range(nc):
            g = con.contact_group[c]
            con.contact_order[fill[g]] = c
            fill[g] += 1
    # (each field the detection writes, and the scratch field of its type it passes through)
    moved = ti.static(((con.contact_vertex, con.contact_vertex_scratch), (con.contact_weight, con.contact_weight_scratch),
                       (con.contact_normal, con.contact_delta), (con.contact_kinematic, con.contact_accumulated),
                       (con.contact_friction, con.contact_delassus), (con.contact_thickness, con.contact_penetration),
                       (con.contact_collider, con.contact_group)))
    for j in range(nc):
        for k in ti.static(range(len(moved))):
            moved[k][1][j] = moved[k][0][con.contact_order[j]]
    for j in range(nc):
        for k in ti.static(range(len(moved))):
            moved[k][0][j] = moved[k][1][j]
