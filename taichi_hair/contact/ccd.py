"""Continuous-time hair-hair collision detection (Daviet 2023, Sec. 4.5; ACCD of Li et al. 2021).

Algorithm 1 optionally runs continuous-time detection "at a subset of the ADMM
iterations" and before the geometric correction.  Each pass looks at the
motion of every edge from the begin-of-step positions x^t to the current
iterate x, linear in time, and finds the edge pairs whose centrelines come
within the contact thickness r_a + r_b during that motion:

1. ``swept_boxes``: the box of each edge's four positions (x^t and x of both
   vertices) grown by its radius; the largest vertex displacement.
2. ``grid.count_cells`` / ``grid.fill_entries``: each edge is entered in every
   cell of a spatial hash its swept box overlaps (multi-insert, so a fast edge
   does not widen every other edge's query), counting-sorted by bucket.
3. ``find_impacts``: each edge visits the cells of its own box; a pair is
   tested once, in the first cell both ranges share; boxes must overlap;
   pairs that are already contacts of this step, and neighbouring edges of a
   strand, are skipped; the rest go through additive CCD (ACCD, Li, Kaufman
   and Jiang 2021, "Codimensional Incremental Potential Contact", Alg. 1),
   which advances time by conservative steps s (d - xi) / l_p until the gap
   d - xi falls below a fraction of its initial value.  Each edge keeps its
   two earliest impacts, sorted by (time, other edge), as the paper does.
4. ``write_impact_contacts``: an impact (a, b) becomes a contact appended to
   the step's contact list (emitted once, by the lower index when both lists
   hold it), with the closest points and normal at the time of impact and
   u_kin = -r n - P_T (p_a^t - p_b^t): the normal component of u = H x + u_kin
   is the linearised gap along the impact normal, the tangential component
   the relative slip since the beginning of the step (as for proximity
   contacts, whose begin-of-step separation is purely normal).

Choices where the paper is silent, written down: ACCD's gap fraction s = 0.1,
and, since ACCD alone only guarantees a gap of s times the initial one (all a
barrier method's line search needs), a pair counts as an impact only once its
gap d - xi is also below ``ACCD_CONTACT_TOLERANCE`` xi (a quarter of the
thickness); a cap of ``ACCD_MAX_ITERATIONS`` conservative steps per pair (a capped
query is reported as an impact at the time reached, which only adds a
contact that stays inactive if the pair does not close; the count is in the
statistics); pairs already closer than their thickness at x^t are left to
proximity detection; body colliders keep the velocity-grown proximity reach
(no continuous test against bodies).
"""

import taichi as ti

from .grid import (bucket_of, cell_in_range, contact_normal, entry_pair_here, edges_adjacent,
                   edges_kinematic, exclusive_scan, row_holds, segment_closest_points)
from .narrow import pair_thickness

ivec4 = ti.types.vector(4, ti.i32)
vec4 = ti.types.vector(4, float)

ACCD_GAP_FRACTION = 0.1
ACCD_CONTACT_TOLERANCE = 0.25
ACCD_MAX_ITERATIONS = 256
NO_IMPACT = 2.0


@ti.kernel
def swept_boxes(edge: ti.template(), x0: ti.template(), x1: ti.template(), radius: ti.template(),
                boxes: ti.template(), ccd: ti.template()):
    """Swept boxes of real edges grown by their radius; the largest displacement, box side and edge [m]."""
    ccd.max_displacement[None] = 0.0
    ccd.max_box_side[None] = 0.0
    ccd.max_edge_length[None] = 0.0
    for i in x0:
        ti.atomic_max(ccd.max_displacement[None], (x1[i] - x0[i]).norm())
        if edge.edge_rest_length[i] > 0.0:
            r = radius[i]
            lo = ti.min(ti.min(x0[i], x0[i + 1]), ti.min(x1[i], x1[i + 1])) - r
            hi = ti.max(ti.max(x0[i], x0[i + 1]), ti.max(x1[i], x1[i + 1])) + r
            boxes.edge_box_lo[i] = lo
            boxes.edge_box_hi[i] = hi
            side = hi - lo
            ti.atomic_max(ccd.max_box_side[None], ti.max(side[0], side[1], side[2]))
            ti.atomic_max(ccd.max_edge_length[None], (x1[i + 1] - x1[i]).norm())


@ti.func
def accd_edge_edge(a0, a1, b0, b1, da0, da1, db0, db1, thickness: float, t_max: float):
    """Additive CCD of two moving segments (Li et al. 2021, Alg. 1), positions p + t dp, t in [0, 1].

    Returns (time of impact, capped): the time at which the gap d - thickness has
    shrunk below ``ACCD_GAP_FRACTION`` of its initial value and below
    ``ACCD_CONTACT_TOLERANCE`` times the thickness, ``NO_IMPACT`` when it
    stays open over the step; ``capped`` when ``ACCD_MAX_ITERATIONS`` steps were not
    enough (the time reached is then returned, conservatively).

    ``t_max`` (<= 1): the query stops, with ``NO_IMPACT``, once its next time passes t_max: every time it could
    still return is later (its times only grow).  1 is the whole step; ``find_impacts`` gives the latest time an
    edge's full list of earliest impacts still takes, so a pair that cannot enter the list is not followed to its
    impact (in the 1,000-strand hairball's pile: ~10 conservative steps per pair, 2 M of 12 M pairs impacting
    within an iterate, of which each edge keeps 2).
    """
    mean = 0.25 * (da0 + da1 + db0 + db1)
    da0 -= mean
    da1 -= mean
    db0 -= mean
    db1 -= mean
    lp = ti.max(da0.norm(), da1.norm()) + ti.max(db0.norm(), db1.norm())
    toi = NO_IMPACT
    capped = 0
    xi = thickness
    if lp > 0.0:
        s0, u0, d = segment_closest_points(a0, a1, b0, b1)
        if d > xi:
            # ACCD stops at a fraction s of the initial gap (a safe step for a barrier method); we want
            # the pair at touching distance, so the gap must also be below ACCD_CONTACT_TOLERANCE xi.
            g = ti.min(ACCD_GAP_FRACTION * (d - xi), ACCD_CONTACT_TOLERANCE * xi)
            t = 0.0
            tl = (1.0 - ACCD_GAP_FRACTION) * (d - xi) / lp
            done = False
            it = 0
            while not done:
                tn = t + tl
                if tn > t_max:
                    break  # (any impact still to come is later than t_max)
                s, u, d = segment_closest_points(a0 + tn * da0, a1 + tn * da1, b0 + tn * db0, b1 + tn * db1)
                if t > 0.0 and d - xi < g:
                    toi = tn
                    done = True
                else:
                    t = tn
                    if t > 1.0:
                        done = True
                    else:
                        tl = 0.9 * (d - xi) / lp
                        it += 1
                        if it >= ACCD_MAX_ITERATIONS:
                            toi = t
                            capped = 1
                            done = True
    return ti.min(toi, NO_IMPACT), capped


@ti.func
def is_contact_pair(con: ti.template(), a: ti.i32, b: ti.i32) -> bool:
    """Is the hair-hair pair of edges (a, b) already a contact of this step (either order)?"""
    found = False
    for e in range(con.vertex_contact_start[a], con.vertex_contact_start[a + 1]):
        cv = con.contact_vertex[con.vertex_contact_list[e]]
        if (cv[0] == a and cv[2] == b) or (cv[0] == b and cv[2] == a):
            found = True
    return found


@ti.func
def _insert_impact(ccd: ti.template(), a: ti.i32, b: ti.i32, toi: float, count: ti.i32, K: ti.template()) -> ti.i32:
    pos = count
    for k in range(count):
        tk = ccd.edge_impact_time[a, k]
        bk = ccd.edge_impact[a, k]
        if pos == count and (toi < tk or (toi == tk and b < bk)):
            pos = k
    new_count = count
    if pos < K:
        k = ti.min(count, K - 1)
        while k > pos:
            ccd.edge_impact[a, k] = ccd.edge_impact[a, k - 1]
            ccd.edge_impact_time[a, k] = ccd.edge_impact_time[a, k - 1]
            k -= 1
        ccd.edge_impact[a, pos] = b
        ccd.edge_impact_time[a, pos] = toi
        new_count = ti.min(count + 1, K)
    return new_count


@ti.kernel
def find_impacts(vertex: ti.template(), edge: ti.template(), x0: ti.template(), x1: ti.template(),
                 radius: ti.template(), boxes: ti.template(), ccd: ti.template(), con: ti.template(), h: float):
    """The ``impacts_per_edge`` earliest impacts of every edge (see the module docstring)."""
    t = boxes.table_size
    K = ti.static(ccd.impacts_per_edge)
    ccd.capped_queries[None] = 0
    for a in ccd.edge_impact_count:
        count = 0
        if edge.edge_rest_length[a] > 0.0:
            sa = vertex.vertex_strand[a]
            lo = boxes.edge_cell_lo[a]
            box_lo_a = boxes.edge_box_lo[a]
            box_hi_a = boxes.edge_box_hi[a]
            span = boxes.edge_cell_hi[a] - lo + 1
            for k in range(span[0] * span[1] * span[2]):
                cell = cell_in_range(lo, k, span)
                bkt = bucket_of(cell, t)
                for e in range(boxes.bucket_start[bkt], boxes.bucket_start[bkt + 1]):
                    if entry_pair_here(boxes, e, lo, box_lo_a, box_hi_a, cell, h):
                        b = boxes.entry_edge[e]
                        if b == a or edges_adjacent(vertex, a, b, sa):
                            continue
                        # A branch of its own: Taichi's ``and`` evaluates both sides, and this scans a's contacts.
                        if not is_contact_pair(con, a, b):
                            # Evaluate in a fixed order so both edges of a pair get the same time.
                            p = ti.min(a, b)
                            q = ti.max(a, b)
                            # The latest time a's list still takes (its K-th earliest impact, a tie with a lower
                            # edge index included: ``_insert_impact``); later impacts cannot enter it.
                            t_max = 1.0
                            if count == K:
                                t_max = ccd.edge_impact_time[a, K - 1]
                            toi, capped = accd_edge_edge(x0[p], x0[p + 1], x0[q], x0[q + 1],
                                                         x1[p] - x0[p], x1[p + 1] - x0[p + 1],
                                                         x1[q] - x0[q], x1[q + 1] - x0[q + 1],
                                                         radius[a] + radius[b], t_max)
                            if capped:
                                ti.atomic_add(ccd.capped_queries[None], 1)
                            if toi <= 1.0 and not edges_kinematic(vertex, a, b):
                                count = _insert_impact(ccd, a, b, toi, count, K)
        ccd.edge_impact_count[a] = count


@ti.func
def _impact_listed(ccd: ti.template(), a: ti.i32, b: ti.i32) -> bool:
    return row_holds(ccd.edge_impact, ccd.edge_impact_count, a, b)


@ti.kernel
def count_impact_contacts(ccd: ti.template(), con: ti.template()):
    """Contacts each edge emits (lower index when both lists hold the pair); prefix sum; new total."""
    for a in ccd.edge_impact_count:
        c = 0
        for k in range(ccd.edge_impact_count[a]):
            b = ccd.edge_impact[a, k]
            if a < b or not _impact_listed(ccd, b, a):
                c += 1
        ccd.edge_emit_count[a] = c
    ti.loop_config(serialize=True)
    for _ in range(1):
        exclusive_scan(ccd.edge_emit_count, ccd.edge_impact_count.shape[0])


@ti.kernel
def write_impact_contacts(vertex: ti.template(), x0: ti.template(), x1: ti.template(), radius: ti.template(),
                          ccd: ti.template(), con: ti.template(), first: ti.i32, friction: float,
                          keep_rest_overlaps: ti.template()):
    """Append the impact contacts at index ``first`` on (up to capacity); contact_count gets the exact total."""
    n = ccd.edge_impact_count.shape[0]
    con.contact_count[None] = first + ccd.edge_emit_count[n]
    cap = con.capacity
    for a in ccd.edge_impact_count:
        c = first + ccd.edge_emit_count[a]
        for k in range(ccd.edge_impact_count[a]):
            b = ccd.edge_impact[a, k]
            if a < b or not _impact_listed(ccd, b, a):
                if c < cap:
                    tau = ccd.edge_impact_time[a, k]
                    pa0 = x0[a] + tau * (x1[a] - x0[a])
                    pa1 = x0[a + 1] + tau * (x1[a + 1] - x0[a + 1])
                    pb0 = x0[b] + tau * (x1[b] - x0[b])
                    pb1 = x0[b + 1] + tau * (x1[b + 1] - x0[b + 1])
                    s, u, dist = segment_closest_points(pa0, pa1, pb0, pb1)
                    nrm = contact_normal((pa0 + s * (pa1 - pa0)) - (pb0 + u * (pb1 - pb0)), pa1 - pa0, pb1 - pb0)
                    # Begin-of-step separation of the same material points: its tangential part is
                    # removed so u_T measures the slip since the beginning of the step.
                    d0 = (x0[a] + s * (x0[a + 1] - x0[a])) - (x0[b] + u * (x0[b + 1] - x0[b]))
                    d0t = d0 - d0.dot(nrm) * nrm
                    con.contact_vertex[c] = ivec4(a, a + 1, b, b + 1)
                    con.contact_weight[c] = vec4(1.0 - s, s, -(1.0 - u), -u)
                    con.contact_normal[c] = nrm
                    r = pair_thickness(vertex, radius, a, b, keep_rest_overlaps)
                    con.contact_thickness[c] = r
                    con.contact_kinematic[c] = -r * nrm - d0t
                    con.contact_friction[c] = friction
                    con.contact_collider[c] = -1
                c += 1
