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

The pair buffer has a fixed size (``ContactConfig.pairs_per_edge`` per vertex, allocated once): where a step
finds more pairs, the search runs in rounds. An edge that meets a full buffer records where it stopped (the
index of the pair in its own search order) and the next round resumes it there; each round fills the
buffer, so a search takes ceil(pairs / capacity) rounds and a step allocates nothing. Measured on the same
pile, 1,052,746 pairs: 218-233 ms in one round, 218-226 ms in 3 to 12 rounds (the edges that finished do
not search again), the lists bit-identical.

Deterministic: the pairs are appended in any order (atomics), but each edge's list is ordered by
(distance, index) whatever the order it gathers them in, and in whichever round.  A pair's distance is
computed once, from its lower edge, so both of its edges rank it by the same number.
"""

import taichi as ti

from ..fields import PairFields
from .grid import (bucket_of, cell_in_range, dops_overlap, edges_adjacent, edges_kinematic, entry_pair_here,
                   exclusive_scan, insert_candidate, segment_closest_points)

ivec2 = ti.types.vector(2, ti.i32)
#: Pairs an edge holds before it appends them to the shared list [-].
HELD = 8


@ti.func
def _append_pairs(pairs: ti.template(), a: ti.i32, held_edge, held_distance, held: ti.i32) -> ti.i32:
    """Append the first ``held`` of edge a's held pairs (a, b) with their distances, one atomic for all; returns
    how many fitted in the buffer (fewer than ``held`` once it is full)."""
    base = ti.atomic_add(pairs.pair_count[None], held)
    stored = ti.max(0, ti.min(held, pairs.capacity - base))
    for j in ti.static(range(HELD)):
        if j < stored:
            pairs.pair_edge[base + j] = ivec2(a, held_edge[j])
            pairs.pair_distance[base + j] = held_distance[j]
    return stored


@ti.kernel
def find_pairs(vertex: ti.template(), edge: ti.template(), x: ti.template(), radius: ti.template(),
               grid: ti.template(), boxes: ti.template(), pairs: ti.template(), h: float, margin: float,
               sweep: float, fall: float, skin: ti.template()):
    """One round of the search: every pending edge a (``pairs.edge_pair_resume[a] >= 0``) appends the pairs
    (a, b), a < b, whose distance is below their reach r_a + r_b + margin + sweep (|v_a - v_b| + s_a + s_b) +
    fall, with v the edges' mean velocities, s their spreads, sweep = velocity_margin dt and
    fall = velocity_margin |g| dt^2 (one edge may be supported while the other falls): a bound on how much
    closer they can get during the step, from their *relative* motion (hair moving together needs little
    margin).  It also keeps the ``candidates_per_edge`` closest of its pairs in its own list
    (``grid.edge_candidate``, merged with what the list holds; ``gather_candidates`` adds the lower edges'
    pairs).  When the buffer is full, the edge records the index (in its own search order) of the first pair
    it could not store and stays pending for the next round, which skips the pairs before it: every round
    fills the buffer, so the search ends after ceil(pairs / capacity) rounds, in a buffer of fixed size.
    Edges of one strand that share a vertex, and pairs of kinematic edges (``grid.edges_kinematic``), are
    skipped.

    ``skin`` (:func:`find_candidates_skin`): only the edges marked ``pairs.edge_moved`` search, each against every
    edge except the moved ones below it (those find the pair themselves), appending after the pairs kept in the
    buffer; the lists are left to :func:`lists_from_pairs`."""
    if ti.static(not skin):
        pairs.pair_count[None] = 0
    pairs.pending_count[None] = 0
    t = boxes.table_size
    K = ti.static(grid.candidates_per_edge)
    for a in grid.edge_candidate_count:
        resume = pairs.edge_pair_resume[a]
        if ti.static(skin):
            resume = 0 if pairs.edge_moved[a] != 0 else -1
        if resume >= 0:
            own = grid.edge_candidate_count[a]
            stored_upto = resume  # a's pairs, in its search order, stored in this round or an earlier one
            full = pairs.pair_count[None] >= pairs.capacity  # nothing fits: the whole edge waits for the next round
            if edge.edge_rest_length[a] > 0.0 and not full:
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
                found = 0
                for k in range(span[0] * span[1] * span[2]):
                    cell = cell_in_range(lo, k, span)
                    bkt = bucket_of(cell, t)
                    for e in range(boxes.bucket_start[bkt], boxes.bucket_start[bkt + 1]):
                        b = boxes.entry_edge[e]
                        if ti.static(skin):
                            if full or b == a:
                                continue
                            if b < a:
                                if pairs.edge_moved[b] != 0:
                                    continue  # a moved lower edge finds the pair itself
                        elif full or b <= a:
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
                                        if ti.static(not skin):
                                            own = insert_candidate(grid, a, b, dist, own, K)  # a's side, in a's row
                                        if found >= resume:  # not stored by an earlier round
                                            held_edge[held] = b
                                            held_distance[held] = dist
                                            held += 1
                                            if held == HELD:
                                                stored = _append_pairs(pairs, a, held_edge, held_distance, held)
                                                stored_upto += stored
                                                full = stored < held
                                                held = 0
                                        found += 1
                if held > 0 and not full:
                    stored = _append_pairs(pairs, a, held_edge, held_distance, held)
                    stored_upto += stored
                    full = stored < held
            if full:
                ti.atomic_add(pairs.pending_count[None], 1)
                pairs.edge_pair_resume[a] = stored_upto
            else:
                pairs.edge_pair_resume[a] = -1
            if ti.static(not skin):
                grid.edge_candidate_count[a] = own


@ti.func
def _csr_starts(pairs: ti.template(), n: ti.i32):
    """The counts in ``edge_pair_start`` made starts (exclusive scan) and the fill cursors cleared (serial)."""
    exclusive_scan(pairs.edge_pair_start, n)
    for i in range(n):
        pairs.edge_pair_fill[i] = 0


@ti.kernel
def gather_candidates(grid: ti.template(), pairs: ti.template()):
    """Per edge, the ``candidates_per_edge`` closest of the pairs it is in, sorted by (distance, other edge),
    in ``grid.edge_candidate`` / ``edge_candidate_distance`` / ``edge_candidate_count``: the list ``find_pairs``
    left (the pairs the edge found itself, with higher edges) plus the pairs found by lower edges, gathered by
    their higher edge, for the pairs the last round of ``find_pairs`` stored.  Lists are merged, so the rounds
    of one search add up to the pairs of a single round with a buffer large enough (``insert_candidate`` skips
    a pair the list holds, and one it dropped for closer ones is dropped again)."""
    K = ti.static(grid.candidates_per_edge)
    n = grid.edge_candidate_count.shape[0]
    count = ti.min(pairs.pair_count[None], pairs.capacity)
    for i in range(n + 1):
        pairs.edge_pair_start[i] = 0
    for p in range(count):
        ti.atomic_add(pairs.edge_pair_start[pairs.pair_edge[p][1]], 1)
    ti.loop_config(serialize=True)
    for _ in range(1):
        _csr_starts(pairs, n)
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
                    fall: float) -> int:
    """Each edge's closest colliding edges (``find_pairs`` + ``gather_candidates``, in rounds until every edge
    has stored its pairs) with the boxes already in the grid of cells h [m].  Returns the number of rounds
    (1 when the buffer holds all the pairs within reach); nothing is allocated."""
    grid.edge_candidate_count.fill(0)
    pairs.edge_pair_resume.fill(0)
    rounds = 0
    while True:
        find_pairs(vertex, edge, x, radius, grid, boxes, pairs, h, margin, sweep, fall, False)
        gather_candidates(grid, pairs)
        rounds += 1
        if int(pairs.pending_count[None]) == 0:
            return rounds


# --------------------------------------------------------------------------- a Verlet skin (ContactConfig.pair_skin)
@ti.kernel
def mark_moved_edges(edge: ti.template(), x: ti.template(), pairs: ti.template(), tau: float, valid: ti.i32) -> ti.i32:
    """``pairs.edge_moved[a]`` = 1 for every edge a with a vertex farther than ``tau`` [m] from where it was at the
    edge's last search (every edge when ``valid`` is 0); returns how many."""
    moved = 0
    for a in pairs.edge_moved:
        m = 0
        if edge.edge_rest_length[a] > 0.0:
            if valid == 0:
                m = 1
            elif (x[a] - pairs.edge_anchor_start[a]).norm() > tau or (x[a + 1] - pairs.edge_anchor_end[a]).norm() > tau:
                m = 1
        pairs.edge_moved[a] = m
        moved += m
    return moved


@ti.kernel
def keep_unmoved_pairs(pairs: ti.template(), valid: ti.i32):
    """Drop the stored pairs with a moved edge (they are searched again), the others kept in their order;
    all of them when ``valid`` is 0."""
    ti.loop_config(serialize=True)
    for _ in range(1):
        kept = 0
        if valid != 0:
            for p in range(ti.min(pairs.pair_count[None], pairs.capacity)):
                e = pairs.pair_edge[p]
                if pairs.edge_moved[e[0]] == 0 and pairs.edge_moved[e[1]] == 0:
                    pairs.pair_edge[kept] = e
                    pairs.pair_distance[kept] = pairs.pair_distance[p]  # (a bound ``lists_from_pairs`` reads)
                    kept += 1
        pairs.pair_count[None] = kept


@ti.kernel
def anchor_moved_edges(x: ti.template(), pairs: ti.template()):
    """The moved edges searched at x: their anchors are their vertices now."""
    for a in pairs.edge_moved:
        if pairs.edge_moved[a] != 0:
            pairs.edge_anchor_start[a] = x[a]
            pairs.edge_anchor_end[a] = x[a + 1]


#: What a pair's distance bound leaves for rounding [m]: float32 positions of ~0.1 m carry ~1e-8 m, and the segment
#: test's parallel case (``grid.segment_closest_points``) may overstate a near-parallel pair's distance by ~1e-8 m.
_BOUND_SLACK = 1.0e-6


@ti.kernel
def lists_from_pairs(x: ti.template(), radius: ti.template(), grid: ti.template(), pairs: ti.template(),
                     margin: float):
    """Every edge's ``candidates_per_edge`` closest pairs within reach, from the stored pairs (a superset of them):
    each pair's distance at x (``segment_closest_points`` of the lower edge then the higher, as ``find_pairs``),
    then a CSR of the pairs within reach by edge, both sides, and the sorted insertion: the lists of a search
    without skin (the same set; the same distances to rounding: the segment test is compiled into this kernel,
    and with fast math it rounds differently from ``find_pairs``, 1 ulp of float32 on a few pairs measured).

    A pair is measured only where it may be within reach.  Its stored distance is its distance at the positions of
    the last call (``pairs.vertex_listed_position``) or a lower bound of it (a pair found since: its distance now),
    and a segment's distance moves by at most the largest displacement of each segment's vertices: with m the
    largest displacement of any vertex since, a pair whose stored distance less 2 m (and ``_BOUND_SLACK``) is still
    beyond reach is beyond reach now, and keeps that lower bound instead.  The same set, the same distances on the
    pairs within reach, so the same lists (the grooming benchmark's still step: 24 % of 665k pairs within reach).
    The pairs within reach are counted by edge where they are measured.  Measured in one process on that step's pairs,
    a vertex moved 20 um (scratch ``/tmp/p/s27/lfp_bench.py``, medians of 15, 2026-12-06): 21.4 -> 16.7 ms, the same
    lists.  A fill by one thread in pair order instead of the atomics was not faster (profiled in separate runs:
    10.2 ms against 9 ms for the two parallel loops)."""
    K = ti.static(grid.candidates_per_edge)
    n = grid.edge_candidate_count.shape[0]
    count = ti.min(pairs.pair_count[None], pairs.capacity)
    pairs.vertex_max_move[None] = 0.0
    for i in x:
        ti.atomic_max(pairs.vertex_max_move[None], (x[i] - pairs.vertex_listed_position[i]).norm())
    for i in range(n + 1):
        pairs.edge_pair_start[i] = 0
    for p in range(count):
        e = pairs.pair_edge[p]
        reach = radius[e[0]] + radius[e[1]] + margin
        bound = pairs.pair_distance[p] - (2.0 * pairs.vertex_max_move[None] + _BOUND_SLACK)
        within = 0
        if bound < reach:
            s, u, dist = segment_closest_points(x[e[0]], x[e[0] + 1], x[e[1]], x[e[1] + 1])
            pairs.pair_distance[p] = dist
            if dist < reach:  # (counted here, where the pair is loaded; the fill reads the flag)
                within = 1
                ti.atomic_add(pairs.edge_pair_start[e[0]], 1)
                ti.atomic_add(pairs.edge_pair_start[e[1]], 1)
        else:
            pairs.pair_distance[p] = bound
        pairs.pair_within[p] = ti.cast(within, ti.i8)
    for i in x:
        pairs.vertex_listed_position[i] = x[i]
    ti.loop_config(serialize=True)
    for _ in range(1):
        _csr_starts(pairs, n)
    for p in range(count):
        if pairs.pair_within[p] != 0:
            e = pairs.pair_edge[p]
            for side in ti.static(range(2)):
                a = e[side]
                pairs.edge_pair_both_list[pairs.edge_pair_start[a] + ti.atomic_add(pairs.edge_pair_fill[a], 1)] = p
    for a in range(n):
        c = 0
        for j in range(pairs.edge_pair_start[a], pairs.edge_pair_start[a + 1]):
            p = pairs.edge_pair_both_list[j]
            e = pairs.pair_edge[p]
            c = insert_candidate(grid, a, e[0] + e[1] - a, pairs.pair_distance[p], c, K)
        grid.edge_candidate_count[a] = c


def find_candidates_skin(vertex, edge, x, radius, grid, pairs: PairFields, margin: float, skin: float,
                         fill_grid) -> int:
    """The lists of :func:`find_candidates` (reach r_a + r_b + margin, no velocity part) from pairs kept between
    steps (a Verlet list): the buffer holds every pair within reach + ``skin`` of the edges where they were at
    their last search, and an edge searches again (``fill_grid()`` first fills the grid, with boxes grown by the
    skin, and returns its cell size and the box grid, which it may have grown) only once a vertex of it moved
    more than skin / 3 since.  Why a third: a
    pair not stored was at least reach + skin apart when the later of its edges searched; since then that edge
    moved at most skin / 3 and the other at most 2 skin / 3 (up to skin / 3 from its own anchor, which that search
    was at most skin / 3 from), and a segment distance changes by at most the endpoints' largest displacements.
    Returns how many edges searched, or -1 when the pairs within reach + skin do not fit the buffer (nothing is
    kept then: the caller searches without skin)."""
    valid = int(pairs.skin_valid)
    moved = int(mark_moved_edges(edge, x, pairs, skin / 3.0, valid))
    if moved > 0:
        keep_unmoved_pairs(pairs, valid)
        h, boxes = fill_grid()
        find_pairs(vertex, edge, x, radius, grid, boxes, pairs, h, margin + skin, 0.0, 0.0, True)
        if int(pairs.pending_count[None]) > 0:
            pairs.skin_valid = False
            return -1
        anchor_moved_edges(x, pairs)
        pairs.skin_valid = True
    lists_from_pairs(x, radius, grid, pairs, margin)
    return moved
