"""The hair-hair candidate search, each pair tested once (Sec. 4.5 "Collision detection", step 4 of ``grid``).

Each edge walks the cells its box overlaps (``grid.count_cells`` / ``fill_entries``) and tests only the edges
of higher index that it meets there, in the first cell both boxes share: boxes, then the pair's reach and the
18-DOPs, then the closest points of the two segments. A pair within reach is appended once, lower edge first,
with its distance, and the lower edge keeps it in its own list of the ``candidates_per_edge`` closest, sorted
by (distance, other edge) (``find_pairs``). Then every edge adds the pairs its lower partners found
(``gather_candidates``): the same lists a search from both sides of every pair keeps, with half the pair tests
(the search before this module tested each pair twice, once from each side). Measured on the 1,000-strand
hairball's pile after its impact (``benchmarks/probes/find_candidates_split.py``, which keeps the search from
both sides for the comparison): 262-302 ms against 565-601 ms, the same lists on every edge. The test
``b <= a`` is a branch of its own: Taichi's ``and`` does not short-circuit, and with
``b > a and entry_pair_here(...)`` the entry test ran on every entry (375 ms).

Deterministic: the pairs are appended in any order (atomics), but each edge's list is ordered by
(distance, index) whatever the order it gathers them in.  A pair's distance is computed once, from its
lower edge, so both of its edges rank it by the same number.
"""

import taichi as ti

from ..fields import PairFields
from .grid import (bucket_of, cell_in_range, dops_overlap, edges_adjacent, edges_kinematic, entry_pair_here,
                   exclusive_scan, insert_candidate, segment_closest_points)

ivec2 = ti.types.vector(2, ti.i32)
#: Pairs an edge holds before it appends them to the shared list [-].
HELD = 8


@ti.func
def _append_pairs(pairs: ti.template(), a: ti.i32, held_edge, held_distance, held: ti.i32):
    """Append the first ``held`` of edge a's held pairs (a, b) with their distances: one atomic for all."""
    base = ti.atomic_add(pairs.pair_count[None], held)
    for j in ti.static(range(HELD)):
        if j < held and base + j < pairs.capacity:
            pairs.pair_edge[base + j] = ivec2(a, held_edge[j])
            pairs.pair_distance[base + j] = held_distance[j]


@ti.kernel
def find_pairs(vertex: ti.template(), edge: ti.template(), x: ti.template(), radius: ti.template(),
               grid: ti.template(), boxes: ti.template(), pairs: ti.template(), h: float, margin: float,
               sweep: float, fall: float):
    """Append every pair (a, b), a < b, whose distance is below its reach
    r_a + r_b + margin + sweep (|v_a - v_b| + s_a + s_b) + fall, with v the edges' mean velocities, s their
    spreads, sweep = velocity_margin dt and fall = velocity_margin |g| dt^2 (one edge may be supported while
    the other falls): a bound on how much closer they can get during the step, from their *relative* motion
    (hair moving together needs little margin); and keep the ``candidates_per_edge`` closest of a's pairs in
    a's own list (``grid.edge_candidate``; ``gather_candidates`` adds the lower edges' pairs).  ``pair_count``
    gets the number found, which may exceed the capacity (the pairs past it are not stored; a's list is whole
    either way).  Edges of one strand that share a vertex, and pairs of kinematic edges
    (``grid.edges_kinematic``), are skipped."""
    pairs.pair_count[None] = 0
    t = boxes.table_size
    K = ti.static(grid.candidates_per_edge)
    for a in grid.edge_candidate_count:
        own = 0
        if edge.edge_rest_length[a] > 0.0:
            ca = grid.edge_dop_center[a]
            ea = grid.edge_dop_extent[a]
            ra = radius[a]
            sa = vertex.vertex_strand[a]
            va = grid.edge_velocity[a]
            sa_spread = grid.edge_velocity_spread[a]
            lo = boxes.edge_cell_lo[a]
            box_lo_a = boxes.edge_box_lo[a]
            box_hi_a = boxes.edge_box_hi[a]
            span = boxes.edge_cell_hi[a] - lo + 1
            # The pairs found, appended HELD at a time: one atomic per HELD pairs instead of one per pair (the
            # counter is shared by all threads; measured on the 1,000-strand pile: 213 against 234 ms).
            held_edge = ti.Vector([0] * HELD, ti.i32)
            held_distance = ti.Vector([0.0] * HELD, float)
            held = 0
            for k in range(span[0] * span[1] * span[2]):
                cell = cell_in_range(lo, k, span)
                bkt = bucket_of(cell, t)
                for e in range(boxes.bucket_start[bkt], boxes.bucket_start[bkt + 1]):
                    b = boxes.entry_edge[e]
                    if b <= a:
                        continue  # a branch of its own: Taichi's ``and`` evaluates both sides (no short circuit)
                    if entry_pair_here(boxes, e, lo, box_lo_a, box_hi_a, cell, h):
                        if not edges_adjacent(vertex, a, b, sa):
                            rel = (va - grid.edge_velocity[b]).norm() + sa_spread + grid.edge_velocity_spread[b]
                            reach = ra + radius[b] + margin + sweep * rel + fall
                            if dops_overlap(ca, ea, grid.edge_dop_center[b], grid.edge_dop_extent[b], reach):
                                s, u, dist = segment_closest_points(x[a], x[a + 1], x[b], x[b + 1])
                                if dist < reach:
                                    if edges_kinematic(vertex, a, b):
                                        continue
                                    own = insert_candidate(grid, a, b, dist, own, K)  # a's side, in a's own row
                                    held_edge[held] = b
                                    held_distance[held] = dist
                                    held += 1
                                    if held == HELD:
                                        _append_pairs(pairs, a, held_edge, held_distance, held)
                                        held = 0
            if held > 0:
                _append_pairs(pairs, a, held_edge, held_distance, held)
        grid.edge_candidate_count[a] = own


@ti.kernel
def gather_candidates(grid: ti.template(), pairs: ti.template()):
    """Per edge, the ``candidates_per_edge`` closest of the pairs it is in, sorted by (distance, other edge),
    in ``grid.edge_candidate`` / ``edge_candidate_distance`` / ``edge_candidate_count``: the list ``find_pairs``
    left (the pairs the edge found itself, with higher edges) plus the pairs found by lower edges, gathered by
    their higher edge (requires ``pair_count`` <= capacity)."""
    K = ti.static(grid.candidates_per_edge)
    n = grid.edge_candidate_count.shape[0]
    count = pairs.pair_count[None]
    for i in range(n + 1):
        pairs.edge_pair_start[i] = 0
    for p in range(count):
        ti.atomic_add(pairs.edge_pair_start[pairs.pair_edge[p][1]], 1)
    ti.loop_config(serialize=True)
    for _ in range(1):
        exclusive_scan(pairs.edge_pair_start, n)
    for i in range(n):
        pairs.edge_pair_fill[i] = 0
    for p in range(count):
        b = pairs.pair_edge[p][1]
        pairs.edge_pair_list[pairs.edge_pair_start[b] + ti.atomic_add(pairs.edge_pair_fill[b], 1)] = p
    for b in range(n):
        c = grid.edge_candidate_count[b]  # b's own side, from find_pairs
        for j in range(pairs.edge_pair_start[b], pairs.edge_pair_start[b + 1]):
            p = pairs.edge_pair_list[j]
            c = insert_candidate(grid, b, pairs.pair_edge[p][0], pairs.pair_distance[p], c, K)
        grid.edge_candidate_count[b] = c


def find_candidates(vertex, edge, x, radius, grid, boxes, pairs: PairFields, h: float, margin: float, sweep: float,
                    fall: float) -> tuple:
    """Each edge's closest colliding edges (``find_pairs`` + ``gather_candidates``) with the boxes already in the
    grid of cells h [m].  Returns ``(pairs, grown)``: the pair buffer, a larger one where the search found more
    pairs than ``pairs`` holds (it then searched again), and whether it grew."""
    grown = False
    while True:
        find_pairs(vertex, edge, x, radius, grid, boxes, pairs, h, margin, sweep, fall)
        found = int(pairs.pair_count[None])
        if found <= pairs.capacity:
            break
        pairs = PairFields(grid.edge_candidate_count.shape[0], max(2 * pairs.capacity, int(1.25 * found)))
        grown = True
    gather_candidates(grid, pairs)
    return pairs, grown
