"""Broad phase of hair-hair collision detection (Daviet 2023, Sec. 4.5 "Collision detection").

1. ``compute_edge_bounds``: per edge, the 18-DOP (stored in 12 floats: the
   midpoint and 9 half-extents, since a segment's DOP is symmetric about its
   midpoint, as the paper notes), mean velocity and velocity spread; the
   longest edge and the largest speed.
2. ``proximity_boxes``: each edge's box grown by its share of the reach (its
   radius, half the margin, its own sweep), so two edges within reach of each
   other have overlapping boxes.
3. ``count_cells`` / ``fill_entries``: a multi-insert spatial hash with cells
   of the longest edge (the paper's size): each edge is entered in every cell
   its box overlaps, and the entries are counting-sorted by bucket.
4. ``pairs.find_candidates``: each edge visits its own cells only and tests
   the edges of higher index it meets, in the first cell both boxes share;
   boxes, then DOPs cull; the closest points of the two segments decide; each
   pair within reach is found once, and each edge keeps the
   ``candidates_per_edge`` (6 in the paper) closest colliding edges, sorted by
   (distance, index) so the result does not depend on the order of the bucket
   fill or the pair list (which use atomics): detection is deterministic.

Departure from the paper, written down: the paper's grid is a sparse hash
grid with one dense subdivision level inside each occupied cell; we use one
level of cells of the longest edge, with each edge entered in all the cells
its box overlaps, so a query visits ~1-8 cells and no neighbourhood.
"""

import numpy as np
import taichi as ti

from ..fields import vec9

vec3 = ti.math.vec3
ivec3 = ti.types.vector(3, ti.i32)

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
def contact_normal(d, ea, eb):
    """Unit normal from the separation d of two edges' closest points; for touching centrelines, the
    common normal of the edges ea x eb (any unit vector if they are also parallel)."""
    nrm = vec3(0.0, 1.0, 0.0)
    dn = d.norm()
    if dn > 1e-12:
        nrm = d / dn
    else:
        cr = ea.cross(eb)
        if cr.norm() > 1e-12:
            nrm = cr.normalized()
    return nrm


@ti.func
def row_holds(table: ti.template(), count: ti.template(), a: ti.i32, b: ti.i32) -> bool:
    """Does row a of a per-edge list ``table[a, k]`` (``count[a]`` entries) hold b?"""
    found = False
    for k in range(count[a]):
        if table[a, k] == b:
            found = True
    return found


@ti.func
def exclusive_scan(a: ti.template(), n: ti.i32):
    """a[0:n] <- its exclusive prefix sum, a[n] <- the total (serial: call from a serialised loop)."""
    run = 0
    for i in range(n):
        c = a[i]
        a[i] = run
        run += c
    a[n] = run


@ti.func
def cell_of(p, h: float):
    return ti.Vector([ti.cast(ti.floor(p[0] / h), ti.i32), ti.cast(ti.floor(p[1] / h), ti.i32),
                      ti.cast(ti.floor(p[2] / h), ti.i32)])


@ti.func
def bucket_of(cell, table_size: ti.i32) -> ti.i32:
    hsh = (cell[0] * 73856093) ^ (cell[1] * 19349663) ^ (cell[2] * 83492791)
    return hsh & (table_size - 1)


@ti.kernel
def strand_velocity_moments(strand: ti.template(), x: ti.template(), v: ti.template(), out: ti.template()):
    """Per strand s, about its first vertex p: out[s] = (n, p, sum r, sum v, sum r x v, sum r r^T row by row)
    with r = x - p, n its vertex count (22 numbers; :func:`rigid_velocity_fit` combines them).  Each strand's
    sums are taken in vertex order by one thread, so the fit is deterministic."""
    for s in strand.strand_vertex_start:
        start = strand.strand_vertex_start[s]
        m = strand.strand_vertex_count[s]
        p = x[start]
        sr = vec3(0.0)
        sv = vec3(0.0)
        sc = vec3(0.0)
        sm = ti.math.mat3(0.0)
        for k in range(m):
            r = x[start + k] - p
            vk = v[start + k]
            sr += r
            sv += vk
            sc += r.cross(vk)
            sm += r.outer_product(r)
        out[s, 0] = ti.cast(m, float)
        for j in ti.static(range(3)):
            out[s, 1 + j] = p[j]
            out[s, 4 + j] = sr[j]
            out[s, 7 + j] = sv[j]
            out[s, 10 + j] = sc[j]
            for k in ti.static(range(3)):
                out[s, 13 + 3 * j + k] = sm[j, k]


def rigid_velocity_fit(moments: np.ndarray):
    """The rigid velocity field v_ref(x) = v0 + omega x (x - c) closest to the hair's vertex velocities (least
    squares, every vertex weighted alike) from the per-strand sums of :func:`strand_velocity_moments`, in
    float64.  Returns (v0 [m/s], omega [rad/s], c [m]); all zero for a groom at rest (omega by least squares,
    the minimum-norm solution where the inertia is singular, e.g. one straight strand)."""
    a = np.asarray(moments, np.float64)
    n, p, sr, sv, sc = a[:, 0], a[:, 1:4], a[:, 4:7], a[:, 7:10], a[:, 10:13]
    sm = a[:, 13:22].reshape(-1, 3, 3)
    total = n.sum()
    if total <= 0 or (not np.any(sv) and not np.any(sc)):
        return np.zeros(3), np.zeros(3), np.zeros(3)
    c = (n[:, None] * p + sr).sum(0) / total
    v0 = sv.sum(0) / total
    d = p - c  # r' = x - c = r + d per vertex; sum r' = 0
    moment = (sc + np.cross(d, sv)).sum(0)  # sum r' x (v - v0) = sum r' x v
    rr = (sm.sum(0) + np.einsum("si,sj->ij", sr, d) + np.einsum("si,sj->ij", d, sr)
          + np.einsum("s,si,sj->ij", n, d, d))  # sum r' r'^T
    inertia = np.trace(rr) * np.eye(3) - rr
    omega = np.linalg.lstsq(inertia, moment, rcond=1e-9)[0]
    if not np.all(np.isfinite(omega)):
        omega = np.zeros(3)
    return v0, omega, c


@ti.kernel
def compute_edge_bounds(edge: ti.template(), x: ti.template(), v: ti.template(), grid: ti.template(),
                        v0: vec3, omega: vec3, c: vec3):
    """DOPs, mean velocities and velocity spreads of every real edge; the largest edge length [m] and
    edge speed |v_e| + spread [m/s] (atomic max: deterministic).  The velocities are taken relative to the
    rigid field v0 + omega x (x - c) (zero: the world's; ``ContactConfig.rigid_reach``): a rigid motion does
    not change the distance of two points (d/dt |p_a - p_b| gets nothing from omega x (p_a - p_b), which is
    normal to p_a - p_b), so the reach of ``pairs.find_pairs`` holds for the relative velocities as well."""
    grid.max_edge_length[None] = 0.0
    grid.max_speed[None] = 0.0
    for i in x:
        if edge.edge_rest_length[i] > 0.0:
            half = 0.5 * (x[i + 1] - x[i])
            grid.edge_dop_center[i] = x[i] + half
            grid.edge_dop_extent[i] = dop_extent(half)
            ti.atomic_max(grid.max_edge_length[None], 2.0 * half.norm())
            va = v[i] - v0 - omega.cross(x[i] - c)
            vb = v[i + 1] - v0 - omega.cross(x[i + 1] - c)
            ve = 0.5 * (va + vb)
            spread = 0.5 * (vb - va).norm()
            grid.edge_velocity[i] = ve
            grid.edge_velocity_spread[i] = spread
            ti.atomic_max(grid.max_speed[None], ve.norm() + spread)


@ti.kernel
def proximity_boxes(edge: ti.template(), x: ti.template(), radius: ti.template(), grid: ti.template(),
                    boxes: ti.template(), margin: float, sweep: float, fall: float):
    """Box of each real edge grown by r + margin/2 + sweep (|v_e| + spread) + fall/2 [m]: two edges whose
    distance is below their reach (``pairs.find_pairs``) have overlapping boxes."""
    for i in x:
        if edge.edge_rest_length[i] > 0.0:
            grow = radius[i] + 0.5 * margin + sweep * (grid.edge_velocity[i].norm() + grid.edge_velocity_spread[i]) \
                + 0.5 * fall
            boxes.edge_box_lo[i] = ti.min(x[i], x[i + 1]) - grow
            boxes.edge_box_hi[i] = ti.max(x[i], x[i + 1]) + grow


@ti.kernel
def strand_boxes(strand: ti.template(), edge: ti.template(), x: ti.template(), radius: ti.template(),
                 grid: ti.template(), boxes: ti.template(), out: ti.template(), margin: float, sweep: float,
                 fall: float):
    """Per strand: the union of its edges' detection boxes (``proximity_boxes`` first), and whether the
    strand can touch itself (``grid.strands_apart``).

    It cannot when every edge tangent t_k makes an acute angle with the chord direction d
    (c = min_k t_k . d > 0): along d the strand then advances monotonically, so two non-adjacent edges
    are at least L_min c apart, and when that exceeds the largest reach of two of its edges in
    ``pairs.find_pairs``, bounded by 2 r_max + margin + sweep (2 max_e |v_e - v_mean| + 2 max spread) + fall
    (edges of one strand moving together need little reach), no such pair is a candidate.
    """
    for s in strand.strand_vertex_start:
        start = strand.strand_vertex_start[s]
        m = strand.strand_vertex_count[s]
        lo = vec3(1e30)
        hi = vec3(-1e30)
        chord = x[start + m - 1] - x[start]
        length = chord.norm()
        c = -1.0
        if length > 0.0:
            c = 1.0
            chord /= length
        shortest = 1e30
        r_max = 0.0
        spread_max = 0.0
        v_sum = vec3(0.0)
        n_real = 0
        for k in range(m - 1):
            i = start + k
            if edge.edge_rest_length[i] > 0.0:
                lo = ti.min(lo, boxes.edge_box_lo[i])
                hi = ti.max(hi, boxes.edge_box_hi[i])
                e = x[i + 1] - x[i]
                le = e.norm()
                shortest = ti.min(shortest, le)
                r_max = ti.max(r_max, radius[i])
                spread_max = ti.max(spread_max, grid.edge_velocity_spread[i])
                v_sum += grid.edge_velocity[i]
                n_real += 1
                if le > 0.0:
                    c = ti.min(c, e.dot(chord) / le)
                else:
                    c = -1.0
        dev = 0.0
        if n_real > 0:
            v_mean = v_sum / n_real
            for k in range(m - 1):
                i = start + k
                if edge.edge_rest_length[i] > 0.0:
                    dev = ti.max(dev, (grid.edge_velocity[i] - v_mean).norm())
        reach = 2.0 * r_max + margin + sweep * (2.0 * dev + 2.0 * spread_max) + fall
        out.strand_box_lo[s] = lo
        out.strand_box_hi[s] = hi
        out.strand_self_clear[s] = 1 if (c > 0.0 and shortest * c > (1.0 + 1e-4) * reach) else 0


@ti.kernel
def count_cells(edge: ti.template(), boxes: ti.template(), h: float):
    """Cell range and cell count of every edge's box, then the exclusive prefix sum (entry n: the total)."""
    for i in boxes.edge_cell_lo:
        cnt = 0
        if edge.edge_rest_length[i] > 0.0:
            lo = cell_of(boxes.edge_box_lo[i], h)
            hi = cell_of(boxes.edge_box_hi[i], h)
            boxes.edge_cell_lo[i] = lo
            boxes.edge_cell_hi[i] = hi
            span = hi - lo + 1
            cnt = span[0] * span[1] * span[2]
        else:
            boxes.edge_cell_lo[i] = ivec3(0)
            boxes.edge_cell_hi[i] = ivec3(-1)
        boxes.edge_entry_start[i] = cnt
    ti.loop_config(serialize=True)
    for _ in range(1):
        exclusive_scan(boxes.edge_entry_start, boxes.edge_cell_lo.shape[0])


@ti.func
def cell_in_range(lo, k: ti.i32, span):
    """The k-th cell of the range starting at ``lo`` with ``span`` cells per axis."""
    return lo + ivec3(k // (span[1] * span[2]), (k // span[2]) % span[1], k % span[2])


@ti.kernel
def fill_entries(boxes: ti.template()):
    """Counting sort of the (edge, cell) entries by bucket (requires total entries <= capacity)."""
    t = boxes.table_size
    for b in boxes.bucket_count:
        boxes.bucket_count[b] = 0
        boxes.bucket_cursor[b] = 0
    for i in boxes.edge_cell_lo:
        lo = boxes.edge_cell_lo[i]
        span = boxes.edge_cell_hi[i] - lo + 1
        for k in range(boxes.edge_entry_start[i + 1] - boxes.edge_entry_start[i]):
            ti.atomic_add(boxes.bucket_count[bucket_of(cell_in_range(lo, k, span), t)], 1)
    ti.loop_config(serialize=True)
    for b in range(t + 1):
        if b == 0:
            boxes.bucket_start[0] = 0
        else:
            boxes.bucket_start[b] = boxes.bucket_start[b - 1] + boxes.bucket_count[b - 1]
    for i in boxes.edge_cell_lo:
        lo = boxes.edge_cell_lo[i]
        span = boxes.edge_cell_hi[i] - lo + 1
        for k in range(boxes.edge_entry_start[i + 1] - boxes.edge_entry_start[i]):
            cell = cell_in_range(lo, k, span)
            b = bucket_of(cell, t)
            slot = boxes.bucket_start[b] + ti.atomic_add(boxes.bucket_cursor[b], 1)
            boxes.entry_edge[slot] = i
            boxes.entry_box_lo[slot] = boxes.edge_box_lo[i]
            boxes.entry_box_hi[slot] = boxes.edge_box_hi[i]


@ti.func
def entry_pair_here(boxes: ti.template(), e: ti.i32, lo_a, box_lo_a, box_hi_a, cell, h: float) -> bool:
    """Does entry e of the bucket of ``cell`` hold an edge whose box overlaps a's box, with ``cell`` the
    lowest cell both box ranges share?  Then the pair is tested here and in no other cell (and entries of
    other cells that hash to the same bucket are skipped).  Reads only the entry (sequential memory)."""
    blo = boxes.entry_box_lo[e]
    bhi = boxes.entry_box_hi[e]
    lo_b = cell_of(blo, h)
    hi_b = cell_of(bhi, h)
    first = ti.max(lo_a, lo_b)
    return (first == cell).all() and (cell <= hi_b).all() and (box_lo_a <= bhi).all() and (blo <= box_hi_a).all()


@ti.func
def edges_adjacent(vertex: ti.template(), a: ti.i32, b: ti.i32, strand_a: ti.i32) -> bool:
    """Edges a and b of one strand share a vertex (no contact between them)."""
    return vertex.vertex_strand[b] == strand_a and ti.abs(b - a) <= 1


@ti.func
def edges_kinematic(vertex: ti.template(), a: ti.i32, b: ti.i32) -> bool:
    """All four vertices of edges a and b are fixed (e.g. two clamped root edges): they move with their bodies,
    nothing can separate them, so they get no contact (one could never be resolved: the correction would sweep
    to its cap every step; a wavy groom on the head whose two root edges overlapped at x* by 45 um ran 175 ms
    of correction per step instead of 22 ms).  Tested only for pairs within reach (four reads, rare path)."""
    return vertex.vertex_is_fixed[a] != 0 and vertex.vertex_is_fixed[a + 1] != 0 and \
        vertex.vertex_is_fixed[b] != 0 and vertex.vertex_is_fixed[b + 1] != 0


@ti.func
def insert_candidate(grid: ti.template(), a: ti.i32, b: ti.i32, dist: float, count: ti.i32, K: ti.template()) -> ti.i32:
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


# --------------------------------------------------------------------------- strand-level broad phase (host)
# * **Hair-hair detection skipped** (``ContactConfig.skip_when_apart``, default on) in a step where
# no two strands come within reach (strand boxes: the union of the edges' detection boxes, which
# include the velocity reach) and no strand can touch itself (every edge makes an acute angle with
# the root-to-tip chord, and the shortest edge times the cosine of the largest such angle exceeds the
# reach of two of the strand's edges: ``grid.strand_boxes``).
# Exact: the full search would find no pair either (bit-identical results, tested).

def strands_apart(box_lo: np.ndarray, box_hi: np.ndarray, self_clear: np.ndarray,
                  max_pairs: int = 2_000_000) -> bool:
    """True when no two strand boxes overlap and no strand can touch itself.

    Sweep and prune along the axis on which the box centres spread most (sorted box starts), then the
    overlap on the other two axes of the remaining pairs.  When the sweep leaves more than ``max_pairs``
    pairs the strands are taken to be within reach without testing further (a dense groom: the full
    search runs anyway).

    Args:
        box_lo, box_hi: strand boxes [m], shape (strand_count, 3); a strand with no real edge has
            lo = +inf, hi = -inf.
        self_clear: 1 where the strand cannot touch itself, shape (strand_count,).
    """
    if not np.all(self_clear):
        return False
    lo = np.asarray(box_lo, np.float64)
    hi = np.asarray(box_hi, np.float64)
    s = lo.shape[0]
    if s < 2:
        return True
    real = lo[:, 0] <= hi[:, 0]
    if real.sum() < 2:
        return True
    centre = 0.5 * (lo[real] + hi[real])
    axis = int(np.argmax(centre.max(axis=0) - centre.min(axis=0)))
    others = [k for k in range(3) if k != axis]
    order = np.argsort(lo[:, axis], kind="stable")
    lo, hi = lo[order], hi[order]
    end = np.searchsorted(lo[:, axis], hi[:, axis], side="right")
    counts = np.maximum(end - np.arange(s) - 1, 0)
    total = int(counts.sum())
    if total == 0:
        return True
    if total > max_pairs:
        return False
    a = np.repeat(np.arange(s), counts)
    start = np.repeat(np.cumsum(counts) - counts, counts)
    b = a + 1 + (np.arange(total) - start)
    overlap = np.all((lo[a][:, others] <= hi[b][:, others]) & (lo[b][:, others] <= hi[a][:, others]), axis=1)
    return not bool(overlap.any())


def _segment_distances(p1, q1, p2, q2) -> np.ndarray:
    """Distances between segments p1-q1 and p2-q2 of positive length, row by row (Ericson 2005, 5.1.9)."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a, e = np.einsum("ij,ij->i", d1, d1), np.einsum("ij,ij->i", d2, d2)
    b, c, f = np.einsum("ij,ij->i", d1, d2), np.einsum("ij,ij->i", d1, r), np.einsum("ij,ij->i", d2, r)
    den = a * e - b * b
    s = np.where(den > 1e-12 * a * e, np.clip((b * f - c * e) / np.where(den > 0, den, 1.0), 0.0, 1.0), 0.0)
    t = (b * s + f) / e
    s = np.where(t < 0, np.clip(-c / a, 0, 1), np.where(t > 1, np.clip((b - c) / a, 0, 1), s))
    t = np.clip(t, 0.0, 1.0)
    return np.linalg.norm(p1 + s[:, None] * d1 - p2 - t[:, None] * d2, axis=1)


def warn_overlapping_root_edges(model) -> None:
    """A warning when kinematic edges of two strands on one body (clamped root edges: vertices 0 and 1 fixed)
    overlap, closer than their radii's sum: nothing can move them apart, so they get no hair-hair contact
    (:func:`edges_kinematic`) and stay overlapped; the run's hair-pair figures do not see them."""
    h = model.host
    fixed = np.asarray(h["vertex_is_fixed"]) != 0
    strand = np.asarray(h["vertex_strand"])
    e = np.nonzero(fixed[:-1] & fixed[1:] & (strand[:-1] == strand[1:]))[0]  # kinematic edges
    if e.size < 2:
        return
    from scipy.spatial import cKDTree

    x = np.asarray(h["vertex_body_position"], np.float64)  # body frame: fixed while the bodies move
    p, q = x[e], x[e + 1]
    se = strand[e]
    radius = np.asarray(h["strand_radius"], np.float64)[se]
    body = np.asarray(h["strand_body"])[se]
    reach = float(np.max(np.linalg.norm(q - p, axis=1))) + 2.0 * float(radius.max())
    pairs = cKDTree(0.5 * (p + q)).query_pairs(reach, output_type="ndarray")
    pairs = pairs[(se[pairs[:, 0]] != se[pairs[:, 1]]) & (body[pairs[:, 0]] == body[pairs[:, 1]])]
    if pairs.size == 0:
        return
    i, j = pairs[:, 0], pairs[:, 1]
    depth = radius[i] + radius[j] - _segment_distances(p[i], q[i], p[j], q[j])
    over = np.nonzero(depth > 0.0)[0]
    if over.size:
        import warnings

        k = over[np.argmax(depth[over])]
        warnings.warn(f"{over.size} pair{'s' if over.size > 1 else ''} of clamped root edges overlap (deepest: strands "
                      f"{se[i[k]]} and {se[j[k]]}, {1e6 * depth[k]:.0f} um into each other): nothing can move them "
                      "apart, so they get no hair-hair contact and stay so", stacklevel=4)
