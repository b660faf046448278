"""Broad phase of hair-hair collision detection (Daviet 2023, Sec. 4.5 "Collision detection").

1. ``compute_edge_bounds``: per edge, the 18-DOP (stored in 12 floats: the
   midpoint and 9 half-extents, since a segment's DOP is symmetric about its
   midpoint, as the paper notes), the largest edge length and speed.
2. ``build_hash_grid``: a counting sort of edge midpoints into the buckets of
   a spatial hash with cells of half the longest edge.
3. ``find_candidates``: each edge visits the cells its own bounding box,
   grown by half the longest edge plus the largest reach, overlaps (every
   edge within reach has its midpoint there), culls with
   the DOPs, computes the closest points of the two segments, and keeps the
   ``candidates_per_edge`` (6 in the paper) closest colliding edges, sorted by
   (distance, index) so the result does not depend on the order of the bucket
   fill (which uses atomics): detection is deterministic.

Departure from the paper, written down: the paper's grid is a sparse hash
grid with one dense subdivision level inside each occupied cell; we use a
single-level hash of cells of the same size (counting sort as in Genesis),
which finds the same pairs at a somewhat higher candidate count.
"""

import taichi as ti

from .fields import vec9

vec3 = ti.math.vec3

_DOP_AXES = (
    (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0),
    (1.0, 1.0, 0.0), (1.0, -1.0, 0.0), (1.0, 0.0, 1.0), (1.0, 0.0, -1.0), (0.0, 1.0, 1.0), (0.0, 1.0, -1.0),
)


@ti.func
def dop_extent(half):
    """Half-extents |half . a_k| of a segment along the 9 (unnormalised) DOP axes [m]."""
    e = vec9(0.0)
    for k in ti.static(range(9)):
        a = ti.static(_DOP_AXES[k])
        e[k] = ti.abs(half[0] * a[0] + half[1] * a[1] + half[2] * a[2])
    return e


@ti.func
def dops_overlap(ca, ea, cb, eb, reach: float) -> bool:
    """Do two segment DOPs, each inflated by ``reach`` [m] in total, overlap along all 9 axes?"""
    d = ca - cb
    ok = True
    for k in ti.static(range(9)):
        a = ti.static(_DOP_AXES[k])
        norm = ti.static((a[0] ** 2 + a[1] ** 2 + a[2] ** 2) ** 0.5)
        if ti.abs(d[0] * a[0] + d[1] * a[1] + d[2] * a[2]) > ea[k] + eb[k] + reach * norm:
            ok = False
    return ok


@ti.func
def segment_closest_points(p0, p1, q0, q1):
    """Closest points p0 + s (p1 - p0) and q0 + t (q1 - q0) of two segments; returns (s, t, distance).

    Ericson, Real-Time Collision Detection, Sec. 5.1.9, with clamping for parallel segments.
    """
    d1 = p1 - p0
    d2 = q1 - q0
    r = p0 - q0
    a = d1.dot(d1)
    e = d2.dot(d2)
    f = d2.dot(r)
    s = 0.0
    t = 0.0
    eps = 1e-20
    if a <= eps and e <= eps:
        s, t = 0.0, 0.0
    elif a <= eps:
        t = ti.math.clamp(f / e, 0.0, 1.0)
    else:
        c = d1.dot(r)
        if e <= eps:
            s = ti.math.clamp(-c / a, 0.0, 1.0)
        else:
            b = d1.dot(d2)
            denom = a * e - b * b
            if denom > 1e-12 * a * e:
                s = ti.math.clamp((b * f - c * e) / denom, 0.0, 1.0)
            t = (b * s + f) / e
            if t < 0.0:
                t = 0.0
                s = ti.math.clamp(-c / a, 0.0, 1.0)
            elif t > 1.0:
                t = 1.0
                s = ti.math.clamp((b - c) / a, 0.0, 1.0)
    dist = ((p0 + s * d1) - (q0 + t * d2)).norm()
    return s, t, dist


@ti.func
def cell_of(p, h: float):
    return ti.Vector([ti.cast(ti.floor(p[0] / h), ti.i32), ti.cast(ti.floor(p[1] / h), ti.i32),
                      ti.cast(ti.floor(p[2] / h), ti.i32)])


@ti.func
def bucket_of(cell, table_size: ti.i32) -> ti.i32:
    hsh = (cell[0] * 73856093) ^ (cell[1] * 19349663) ^ (cell[2] * 83492791)
    return hsh & (table_size - 1)


@ti.kernel
def compute_edge_bounds(edge: ti.template(), x: ti.template(), v: ti.template(), grid: ti.template()):
    """DOPs, mean velocities and velocity spreads of every real edge; the largest edge length [m] and
    edge speed |v_e| + spread [m/s] (atomic max: deterministic)."""
    grid.max_edge_length[None] = 0.0
    grid.max_speed[None] = 0.0
    for i in x:
        if edge.edge_rest_length[i] > 0.0:
            half = 0.5 * (x[i + 1] - x[i])
            grid.edge_dop_center[i] = x[i] + half
            grid.edge_dop_extent[i] = dop_extent(half)
            ti.atomic_max(grid.max_edge_length[None], 2.0 * half.norm())
            ve = 0.5 * (v[i] + v[i + 1])
            spread = 0.5 * (v[i + 1] - v[i]).norm()
            grid.edge_velocity[i] = ve
            grid.edge_velocity_spread[i] = spread
            ti.atomic_max(grid.max_speed[None], ve.norm() + spread)


@ti.kernel
def build_hash_grid(edge: ti.template(), grid: ti.template(), h: float):
    """Counting sort of edge midpoints into hash buckets (cell size h [m])."""
    t = grid.table_size
    for b in grid.grid_cell_count:
        grid.grid_cell_count[b] = 0
        grid.grid_cell_cursor[b] = 0
    for i in grid.edge_bucket:
        grid.edge_bucket[i] = -1
        if edge.edge_rest_length[i] > 0.0:
            b = bucket_of(cell_of(grid.edge_dop_center[i], h), t)
            grid.edge_bucket[i] = b
            ti.atomic_add(grid.grid_cell_count[b], 1)
    # Exclusive prefix sum over buckets (serial: the table is a few times the edge count).
    ti.loop_config(serialize=True)
    for b in range(t + 1):
        if b == 0:
            grid.grid_cell_start[0] = 0
        else:
            grid.grid_cell_start[b] = grid.grid_cell_start[b - 1] + grid.grid_cell_count[b - 1]
    for i in grid.edge_bucket:
        b = grid.edge_bucket[i]
        if b >= 0:
            slot = grid.grid_cell_start[b] + ti.atomic_add(grid.grid_cell_cursor[b], 1)
            grid.grid_entry[slot] = i
            grid.grid_entry_center[slot] = grid.edge_dop_center[i]
            grid.grid_entry_extent[slot] = grid.edge_dop_extent[i]
            ve = grid.edge_velocity[i]
            grid.grid_entry_velocity[slot] = ti.Vector([ve[0], ve[1], ve[2], grid.edge_velocity_spread[i]])


@ti.kernel
def find_candidates(vertex: ti.template(), edge: ti.template(), x: ti.template(), radius: ti.template(),
                    grid: ti.template(), h: float, margin: float, sweep: float, fall: float,
                    max_radius: float, extent: float):
    """Keep, per edge, the closest colliding edges, at most K, sorted by (distance, index).

    Two edges collide when their distance is below their reach
    r_a + r_b + margin + sweep (|v_a - v_b| + s_a + s_b) + fall, with v the
    edges' mean velocities, s their spreads, sweep = velocity_margin dt and
    fall = velocity_margin |g| dt^2 (one edge may be supported while the other
    falls): a bound on how much closer they can get during the step, from
    their *relative* motion (hair moving together needs little margin).  The cell size h must exceed the
    longest edge plus the largest reach (no longer: the query box adapts).

    Edges of the same strand that share a vertex are skipped.  A bucket reached
    twice (two neighbouring cells hashing alike) or an edge met twice is
    de-duplicated by the sorted insertion.
    """
    t = grid.table_size
    K = ti.static(grid.candidates_per_edge)
    for a in grid.edge_bucket:
        grid.edge_candidate_count[a] = 0
        if grid.edge_bucket[a] >= 0:
            ca = grid.edge_dop_center[a]
            ea = grid.edge_dop_extent[a]
            ra = radius[a]
            sa = vertex.vertex_strand[a]
            va = grid.edge_velocity[a]
            sa_spread = grid.edge_velocity_spread[a]
            # Cells whose midpoints can hold a colliding edge: a's box grown by half the longest edge plus
            # the largest reach (``extent``).  With cells of half an edge this box is ~2 x 1 x 1 edges for
            # an edge at rest, far less than 27 cells of two edges each.
            lo = cell_of(ti.min(x[a], x[a + 1]) - extent, h)
            hi = cell_of(ti.max(x[a], x[a + 1]) + extent, h)
            span = hi - lo + 1
            count = 0
            for nb in range(span[0] * span[1] * span[2]):
                off = ti.Vector([nb // (span[1] * span[2]), (nb // span[2]) % span[1], nb % span[2]])
                b_idx = bucket_of(lo + off, t)
                for e in range(grid.grid_cell_start[b_idx], grid.grid_cell_start[b_idx + 1]):
                    b = grid.grid_entry[e]
                    vb = grid.grid_entry_velocity[e]
                    rel = (va - vec3(vb[0], vb[1], vb[2])).norm() + sa_spread + vb[3]
                    # radius[b] <= max radius: bound the reach without loading edge b's data first.
                    reach_max = ra + max_radius + margin + sweep * rel + fall
                    if b != a and dops_overlap(ca, ea, grid.grid_entry_center[e], grid.grid_entry_extent[e], reach_max):
                        reach = ra + radius[b] + margin + sweep * rel + fall
                        if not (vertex.vertex_strand[b] == sa and ti.abs(b - a) <= 1):
                            s, u, dist = segment_closest_points(x[a], x[a + 1], x[b], x[b + 1])
                            if dist < reach:
                                count = _insert_candidate(grid, a, b, dist, count, K)
            grid.edge_candidate_count[a] = count


@ti.func
def _insert_candidate(grid: ti.template(), a: ti.i32, b: ti.i32, dist: float, count: ti.i32, K: ti.template()) -> ti.i32:
    """Sorted insertion of (dist, b) into edge a's list of at most K; returns the new count."""
    dup = False
    for k in range(count):
        if grid.edge_candidate[a, k] == b:
            dup = True
    new_count = count
    if not dup:
        # Position: first slot whose (distance, index) is larger.
        pos = count
        for k in range(count):
            dk = grid.edge_candidate_distance[a, k]
            bk = grid.edge_candidate[a, k]
            if pos == count and (dist < dk or (dist == dk and b < bk)):
                pos = k
        if pos < K:
            last = ti.min(count, K - 1)
            k = last
            while k > pos:
                grid.edge_candidate[a, k] = grid.edge_candidate[a, k - 1]
                grid.edge_candidate_distance[a, k] = grid.edge_candidate_distance[a, k - 1]
                k -= 1
            grid.edge_candidate[a, pos] = b
            grid.edge_candidate_distance[a, pos] = dist
            new_count = ti.min(count + 1, K)
    return new_count
