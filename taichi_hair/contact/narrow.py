"""Narrow phase and contact buffers (Daviet 2023, Sec. 4.5), run once at the beginning of a step.

From the per-edge candidate lists of :mod:`taichi_hair.contact.grid` and the body
colliders of :mod:`taichi_hair.contact.colliders`, build the contact list:

* hair-hair: the pair (a, b) is a contact when b is among the 6 closest of a
  or a among the 6 closest of b (the paper discards a contact "not among the 6
  closest ones for any of the colliding edges"); it is emitted once, by the
  lower edge index when both lists hold it.  Closest points
  p_a = (1-s) x_a + s x_{a+1} and p_b = (1-t) x_b + t x_{b+1} give weights
  h = (1-s, s, -(1-t), -t), normal n = (p_a - p_b)/|p_a - p_b|, contact
  thickness r = r_a + r_b and u_kin = -r n, so that u = H x + u_kin has normal
  component n . (p_a - p_b) - r (the gap, with the begin-of-step normal) and
  tangential component the relative slip since the beginning of the step.
* body: each free vertex within reach of a collider (at the begin-of-step
  body transform; the reach is r + margin + the vertex's own motion allowance +
  how far the body moves at that point within the step) gets a contact with
  h = 1 against the body surface point s, carried rigidly to the end-of-step
  transform: u = x - s_end - r n_end.

Then the vertex-to-contact adjacency (CSR, each list sorted by batch then index, so the
projection sums in a fixed order, bitwise deterministic, and reads a batch's entries alone), the collision weights
W_z,i = m_i / dt~_i^2 on vertices with contacts (zero elsewhere; dt~ of
Sec. 4.5 from dimensional analysis, per strand), and the mass-split Delassus
diagonal D_hat_c = sum_i n_i h_ci^2 / W_z,i (n_i: the contacts of vertex i, or by default only those in
c's batch, ``ContactConfig.mass_splitting``).

Emission writes contact c only when c < capacity; the count is always exact,
so the caller detects an overflow, grows the buffers and detects again: no
contact is ever dropped silently.
"""

import taichi as ti

from ..solver_base import on_gpu
from .colliders import acts_on, body_transform, collider_distance
from .grid import contact_normal, exclusive_scan, row_holds, segment_closest_points
from .projection import BATCHES

vec3 = ti.math.vec3
ivec4 = ti.types.vector(4, ti.i32)
vec4 = ti.types.vector(4, float)


@ti.func
def _in_list(grid: ti.template(), a: ti.i32, b: ti.i32) -> bool:
    return row_holds(grid.edge_candidate, grid.edge_candidate_count, a, b)


@ti.func
def _emits(grid: ti.template(), a: ti.i32, k: ti.i32) -> bool:
    """Does edge a emit the contact with its k-th candidate b: a < b, or b does not hold a (each pair once)?"""
    b = grid.edge_candidate[a, k]
    emits = True
    if a > b:  # (a branch: Taichi's ``or`` evaluates both sides, and b's list was scanned for every pair)
        emits = not _in_list(grid, b, a)
    return emits


@ti.func
def _body_reach(cs: ti.template(), k: ti.i32, p):
    """Point p [m] in collider k's body frame at the begin-of-step transform, its signed distance to the collider
    [m] and the outward normal there (body frame)."""
    R, T = body_transform(cs.body_rotation_begin, cs.body_translation_begin, cs.collider_body[k])
    q = R.transpose() @ (p - T)
    d, nq = collider_distance(cs, k, q)
    return q, d, nq


@ti.func
def _body_sweep(cs: ti.template(), k: ti.i32, q) -> float:
    """How far collider k's body carries its point q (body frame) from the begin- to the end-of-step
    transform [m]: the reach a vertex needs for a body that moves into it within the step (a comb tooth
    swept 1 mm per step reaches vertices 1 mm away).  The motion is given, so all of it is added, not a
    ``velocity_margin`` share of it; zero for a still body."""
    b = cs.collider_body[k]
    Rb, Tb = body_transform(cs.body_rotation_begin, cs.body_translation_begin, b)
    Re, Te = body_transform(cs.body_rotation_end, cs.body_translation_end, b)
    return ((Re @ q + Te) - (Rb @ q + Tb)).norm()


@ti.kernel
def count_contacts(vertex: ti.template(), x: ti.template(), v: ti.template(), radius: ti.template(),
                   grid: ti.template(), cs: ti.template(), margin: float, sweep: float, fall: float):
    """Per edge: hair-hair contacts it emits; per vertex: body contacts.  Then both prefix sums."""
    for a in x:
        c = 0
        for k in range(grid.edge_candidate_count[a]):
            if _emits(grid, a, k):
                c += 1
        grid.edge_emit_count[a] = c
        nb = 0
        if vertex.vertex_is_fixed[a] == 0:
            for k in range(cs.count_field[None]):
                if acts_on(cs, k, vertex.vertex_strand[a]):
                    q, d, nq = _body_reach(cs, k, x[a])
                    if d < radius[a] + margin + sweep * v[a].norm() + fall + _body_sweep(cs, k, q):
                        nb += 1
        grid.vertex_body_emit_count[a] = nb
    # Exclusive prefix sums in place (serial; one pass over the vertices); entry n gets the total.
    ti.loop_config(serialize=True)
    for _ in range(1):
        n = x.shape[0]
        run_e = 0
        run_b = 0
        for i in range(n):
            ce = grid.edge_emit_count[i]
            cb = grid.vertex_body_emit_count[i]
            grid.edge_emit_count[i] = run_e
            grid.vertex_body_emit_count[i] = run_b
            run_e += ce
            run_b += cb
        grid.edge_emit_count[n] = run_e
        grid.vertex_body_emit_count[n] = run_b


@ti.kernel
def write_contacts(vertex: ti.template(), strand: ti.template(), x: ti.template(), v: ti.template(),
                   radius: ti.template(), grid: ti.template(), cs: ti.template(), con: ti.template(),
                   hair_friction: float, margin: float, sweep: float, fall: float, keep_rest_overlaps: ti.template()):
    """Fill the contact arrays (up to capacity); contact_count gets the exact total."""
    n = x.shape[0]
    n_hair = grid.edge_emit_count[n]
    con.contact_count[None] = n_hair + grid.vertex_body_emit_count[n]
    cap = con.capacity
    for a in x:
        c = grid.edge_emit_count[a]
        for k in range(grid.edge_candidate_count[a]):
            if _emits(grid, a, k):
                if c < cap:
                    b = grid.edge_candidate[a, k]
                    con.contact_thickness[c] = pair_thickness(vertex, radius, a, b, keep_rest_overlaps)
                    con.contact_vertex[c] = ivec4(a, a + 1, b, b + 1)
                    con.contact_collider[c] = -1
                    measure_hair_contact(x, con, c, a, b, hair_friction)
                c += 1
        cb = n_hair + grid.vertex_body_emit_count[a]
        # Only where ``count_contacts`` counted body contacts (the same tests, so the same ones): the collider
        # distances of every vertex were evaluated again here.  With ``_emits``' branch, the grooming benchmark's
        # still step (kernel profiler, 2026-12-06, runs of a VM whose speed varies): this kernel 11.9-13.5 -> 5.9-7.0
        # ms, ``count_contacts`` 5.1-5.3 -> 3.2-3.9 ms; the same bits.
        if grid.vertex_body_emit_count[a + 1] > grid.vertex_body_emit_count[a]:
            for k in range(cs.count_field[None]):
                q, d, nq = _body_reach(cs, k, x[a])
                if (d < radius[a] + margin + sweep * v[a].norm() + fall + _body_sweep(cs, k, q)
                        and acts_on(cs, k, vertex.vertex_strand[a])):
                    if cb < cap:
                        con.contact_vertex[cb] = ivec4(a, -1, -1, -1)
                        con.contact_weight[cb] = vec4(1.0, 0.0, 0.0, 0.0)
                        con.contact_thickness[cb] = radius[a]
                        con.contact_collider[cb] = k
                        measure_body_contact(radius, cs, con, cb, a, k, q, d, nq)
                    cb += 1


@ti.func
def measure_hair_contact(x: ti.template(), con: ti.template(), c: ti.i32, a: ti.i32, b: ti.i32, hair_friction: float):
    """Hair pair c of edges a and b at x: its closest points' weights, the normal (``grid.contact_normal``), u_kin =
    -thickness n and the friction (the detection's, and a kept contact's again: ``contact.reuse``)."""
    s, t, dist = segment_closest_points(x[a], x[a + 1], x[b], x[b + 1])
    pa = x[a] + s * (x[a + 1] - x[a])
    pb = x[b] + t * (x[b + 1] - x[b])
    nrm = contact_normal(pa - pb, x[a + 1] - x[a], x[b + 1] - x[b])
    con.contact_weight[c] = vec4(1.0 - s, s, -(1.0 - t), -t)
    con.contact_normal[c] = nrm
    con.contact_kinematic[c] = -con.contact_thickness[c] * nrm
    con.contact_friction[c] = hair_friction


@ti.func
def measure_body_contact(radius: ti.template(), cs: ti.template(), con: ti.template(), c: ti.i32, a: ti.i32, k: ti.i32,
                         q, d, nq):
    """Body contact c of vertex a with collider k, from its point q in the body frame, distance d and normal nq at the
    begin-of-step transform (``_body_reach``): the body point and normal carried to the end-of-step transform, u_kin
    and the collider's friction (the detection's, and a kept contact's again: ``contact.reuse``)."""
    Re, Te = body_transform(cs.body_rotation_end, cs.body_translation_end, cs.collider_body[k])
    n_end = Re @ nq
    con.contact_normal[c] = n_end
    con.contact_kinematic[c] = -(Re @ (q - d * nq) + Te) - radius[a] * n_end
    con.contact_friction[c] = cs.collider_friction[k]


@ti.func
def pair_thickness(vertex: ti.template(), radius: ti.template(), a: ti.i32, b: ti.i32,
                   keep_rest_overlaps: ti.template()) -> float:
    """Contact thickness of edges a and b: r_a + r_b, or, with ``keep_rest_overlaps``, their distance at rest
    (x*, ``vertex_rest_position``) where that is less: a groom's strands authored closer than two radii (a
    ponytail's tail, a guide standing for a wisp) keep that separation instead of being pushed apart from
    the first step, so the authored shape stays an equilibrium with contacts on."""
    r = radius[a] + radius[b]
    if ti.static(keep_rest_overlaps):
        xr = ti.static(vertex.vertex_rest_position)
        s, t, d = segment_closest_points(xr[a], xr[a + 1], xr[b], xr[b + 1])
        r = ti.min(r, d)
    return r


@ti.func
def _has_body_contact(con: ti.template(), i: ti.i32, k: ti.i32) -> bool:
    """Does vertex i already have a contact with collider k (its CSR list of ``build_adjacency``)?"""
    has = False
    for e in range(con.vertex_contact_start[i], con.vertex_contact_start[i + 1]):
        if con.contact_collider[con.vertex_contact_list[e]] == k:
            has = True
    return has


@ti.func
def _late_body_hit(vertex: ti.template(), x: ti.template(), radius: ti.template(), cs: ti.template(),
                   con: ti.template(), margin: float, a: ti.i32, k: ti.i32):
    """Does free vertex a need a late contact with collider k (within r + margin of it at the end-of-step
    transforms, and no contact with it yet)?  Also returns the body point and normal at the end of the step."""
    Re, Te = body_transform(cs.body_rotation_end, cs.body_translation_end, cs.collider_body[k])
    q = Re.transpose() @ (x[a] - Te)
    d, nq = collider_distance(cs, k, q)
    hit = (vertex.vertex_is_fixed[a] == 0 and acts_on(cs, k, vertex.vertex_strand[a]) and d < radius[a] + margin
           and not _has_body_contact(con, a, k))
    return hit, Re @ (q - d * nq) + Te, Re @ nq


@ti.kernel
def count_late_body_contacts(vertex: ti.template(), x: ti.template(), radius: ti.template(), cs: ti.template(),
                             con: ti.template(), margin: float, out_count: ti.template()):
    """Per vertex: the colliders it needs a late contact with (``_late_body_hit``); then the exclusive prefix
    sum (entry n: the total)."""
    for a in x:
        nb = 0
        for k in range(cs.count_field[None]):
            hit, s_end, n_end = _late_body_hit(vertex, x, radius, cs, con, margin, a, k)
            if hit:
                nb += 1
        out_count[a] = nb
    ti.loop_config(serialize=True)
    for _ in range(1):
        exclusive_scan(out_count, x.shape[0])


@ti.kernel
def write_late_body_contacts(vertex: ti.template(), x: ti.template(), radius: ti.template(), cs: ti.template(),
                             con: ti.template(), margin: float, first: ti.i32, start: ti.template()):
    """Append the contacts ``count_late_body_contacts`` counted at index ``first`` on, in vertex order (so the
    contact list, and with it the batches, is deterministic), up to capacity; contact_count gets the total.
    The same contact as ``write_contacts``' body contacts, taken at the end-of-step transforms, and
    frictionless: where the vertex first touched the body within the step is not known, so there is no slip
    to resist; the contact only pushes it out."""
    n = x.shape[0]
    con.contact_count[None] = first + start[n]
    cap = con.capacity
    for a in x:
        cb = first + start[a]
        for k in range(cs.count_field[None]):
            hit, s_end, n_end = _late_body_hit(vertex, x, radius, cs, con, margin, a, k)
            if hit:
                if cb < cap:
                    con.contact_vertex[cb] = ivec4(a, -1, -1, -1)
                    con.contact_weight[cb] = vec4(1.0, 0.0, 0.0, 0.0)
                    con.contact_normal[cb] = n_end
                    con.contact_kinematic[cb] = -s_end - radius[a] * n_end
                    con.contact_thickness[cb] = radius[a]
                    con.contact_friction[cb] = 0.0
                    con.contact_collider[cb] = k
                cb += 1


#: ``_delassus``'s third choice (after True: by batch, False: by vertex): no mass splitting (n_i = 1).
SPLIT_NONE = 2

#: ``build_adjacency``'s ``bending_time``: where W_z's dt~ takes the edge's bending time (ContactConfig.weight_time):
#: on no vertex ("step", dynamic mode), on every vertex ("paper", or the quasistatic mode), or on the vertices
#: with a body contact only ("hair-step", dynamic mode).
BEND_NONE, BEND_ALL, BEND_BODY = 0, 1, 2


#: Where a contact touches a clamped vertex, no free vertex moves by more than this many times the contact's gap
#: in one projection: see ``_delassus``.
CLAMPED_LEVER_BOUND = 1.0


@ti.func
def _delassus(con: ti.template(), c: ti.i32, split_by_batch: ti.template()) -> float:
    """Mass-split Delassus diagonal D_hat_c of contact c (Sec. 4.5): D_hat_c = sum_i n_i h_ci^2 / W_z,i over its
    free vertices.

    ``split_by_batch``: True (n_i = c's batch's contacts on i), False (n_i = all of i's contacts), or
    ``SPLIT_NONE`` (n_i = 1: the plain Delassus diagonal D of Eq. 6, no splitting; the correction's option
    ``ContactConfig.correction_mass_splitting = "none"``).

    Clamped vertices do not move (1/W_z = 0).  A projection moves free vertex i by Delta u h_ci / (W_z,i
    D_hat_c) (``apply_batch_corrections``).  Where the contact point lies near a clamped vertex (h ~ 1 there,
    h ~ 0.01 on the free one) that is ~ Delta u / h, a lever amplified a hundredfold: measured, 8,600 clamped
    strands generated on a head (roots 2.5 mm apart, 103k contacts at rest) moved by 56 mm then 1 m in two
    quasistatic iterations and diverged.  So where c touches a clamped vertex, D_hat_c is at least
    max_i |h_ci| / (A W_z,i) over its free vertices, A = ``CLAMPED_LEVER_BOUND`` = 1: no free vertex moves by
    more than the gap.  For a free edge against a clamped one (equal weights, closest point at t on the free
    edge) the paper's D_hat is (1 - t)^2 + t^2 against the bound's max(t, 1 - t): the bound under-relaxes such
    a contact by at most 17 % (at t = 1/sqrt(2)), not at all at t = 0, 1/2 or 1.  A = 2 (never acting there)
    gave the same speed-up but a little more strain on the ponytail scene (24 frames: strain p99 / max 0.004 /
    0.06 % against 0.003 / 0.07 %, hair-pair max 83 against 42 um, 1 crossed pair against 0; one run each).
    Contacts without a clamped vertex are unchanged.

    (Until this rule, the clamped vertices counted in D_hat with the weight a free vertex would have there.
    That bounded the lever too, but under-relaxed every contact with a clamped vertex, also those the free
    vertices could resolve alone: a free edge against a neighbour's clamped root edge closed a fraction of
    its gap per sweep (a light clamped vertex, of a strand with longer edges, counted most), and the head
    turn's end-of-step correction needed 100-200 sweeps: 474 ms per frame against 255 with this rule, measured
    on ``assets/scenes/head_turn.toml``, 24 frames.)
    """
    dh = 0.0
    lever = 0.0
    clamped = False
    for k in ti.static(range(4)):
        v = con.contact_vertex[c][k]
        if v >= 0:
            h = con.contact_weight[c][k]
            iw = con.vertex_contact_inv_weight[v]
            if iw > 0.0:
                # Virtual copies of vertex v: all its contacts (the paper's n_i), or only those of c's
                # batch, the ones updated at the same time as c (see ContactConfig.mass_splitting).
                copies = con.vertex_contact_count[v]
                if ti.static(split_by_batch == SPLIT_NONE):
                    copies = 1
                elif ti.static(split_by_batch):
                    # (v's list is sorted by batch, ``build_adjacency``: the batch's entries are one run.)
                    b = c % BATCHES
                    stop = con.vertex_contact_start[v + 1]
                    if b + 1 < BATCHES:
                        stop = con.vertex_batch_start[v, b + 1]
                    copies = stop - con.vertex_batch_start[v, b]
                dh += copies * h * h * iw
                lever = ti.max(lever, ti.abs(h) * iw)
            else:
                clamped = True
    if clamped:
        dh = ti.max(dh, lever / CLAMPED_LEVER_BOUND)
    return dh


@ti.kernel
def relinearize_contacts(x: ti.template(), x0: ti.template(), radius: ti.template(), cs: ti.template(),
                         con: ti.template(), split_by_batch: ti.template(), frictionless_hair: ti.template(),
                         coefficients: ti.template()):
    """Re-linearise every contact at the current x, before the geometric correction.

    Contacts are linearised at the beginning of the step (closest points, normal, body tangent plane).
    When hair slides by centimetres in a step, the frozen plane of a pair that has moved apart can be
    "violated" by millimetres although the two edges are millimetres away from each other (measured on
    the hairball), and projecting x onto it stretches edges by tens of percent.  Here each hair-hair contact
    takes the closest points of its two edges at x, with the normal of their separation, kept on the side
    of the begin-of-step normal (a pair that crossed is pushed back, not through); each body contact takes
    the collider's distance and normal at x.  The tangential part still measures the slip since the
    beginning of the step (x^t for hair pairs, the begin-of-step body point carried by the body).
    ``split_by_batch``: the mass splitting of D_hat (``_delassus``); ``frictionless_hair``: zero the hair-hair
    friction coefficients (``ContactConfig.correction_hair_friction`` off; the next detection rewrites them).
    ``coefficients``: store the entry coefficients of the batched sweeps (``store_entry_coefficients``; only they
    read them: ``ContactPipeline.uses_batches``).
    """
    nc = ti.min(con.contact_count[None], con.capacity)
    for c in range(nc):
        vtx = con.contact_vertex[c]
        n_old = con.contact_normal[c]
        k = con.contact_collider[c]
        if k < 0:
            a = vtx[0]
            b = vtx[2]
            s, t, dist = segment_closest_points(x[a], x[a + 1], x[b], x[b + 1])
            d = (x[a] + s * (x[a + 1] - x[a])) - (x[b] + t * (x[b + 1] - x[b]))
            nrm = n_old
            if d.dot(n_old) > 0.0 and dist > 1e-12:
                nrm = d / dist
            d0 = (x0[a] + s * (x0[a + 1] - x0[a])) - (x0[b] + t * (x0[b + 1] - x0[b]))
            con.contact_weight[c] = vec4(1.0 - s, s, -(1.0 - t), -t)
            con.contact_normal[c] = nrm
            con.contact_kinematic[c] = -con.contact_thickness[c] * nrm - (d0 - d0.dot(nrm) * nrm)
            if ti.static(frictionless_hair):
                con.contact_friction[c] = 0.0
        else:
            i = vtx[0]
            R, T = body_transform(cs.body_rotation_end, cs.body_translation_end, cs.collider_body[k])
            q = R.transpose() @ (x[i] - T)
            dq, nq = collider_distance(cs, k, q)
            nrm = R @ nq
            surf = x[i] - dq * nrm
            # Old u_kin = -s_end - r n_end: recover the body point s_end carried from the beginning.
            s_end = -con.contact_kinematic[c] - radius[i] * n_old
            ref = nrm.dot(surf) * nrm + (s_end - nrm.dot(s_end) * nrm)
            con.contact_normal[c] = nrm
            con.contact_kinematic[c] = -ref - radius[i] * nrm
    for c in range(nc):
        con.contact_delassus[c] = _delassus(con, c, split_by_batch)
        store_push(con, c)
    if ti.static(coefficients):
        store_entry_coefficients(con)


@ti.func
def store_push(con: ti.template(), c: ti.i32):
    """``con.contact_push[c]``: W_z,i^-1 h_ci / D_hat_c for each vertex slot of contact c (0 where D_hat_c = 0 or the
    slot is unused), what the sweeps one by one (``projection._solve_one``) multiply the contact's correction by.
    Run wherever D_hat_c, the weights or W_z change; stored, not gathered, because a sweep read the vertices'
    1/W_z and divided by D_hat_c for every contact again."""
    dh = con.contact_delassus[c]
    push = vec4(0.0)
    if dh > 0.0:
        for k in ti.static(range(4)):
            v = con.contact_vertex[c][k]
            if v >= 0:
                push[k] = con.vertex_contact_inv_weight[v] * (con.contact_weight[c][k] / dh)
    con.contact_push[c] = push


@ti.func
def entry_coefficient(con: ti.template(), i: ti.i32, c: ti.i32) -> float:
    """h_ci / D_hat_c of contact c at its vertex i (the sum of c's weights on i), 0 where D_hat_c = 0: the factor by
    which c's accumulated r~ pushes vertex i (times W_z,i^-1)."""
    dh = con.contact_delassus[c]
    coef = 0.0
    if dh > 0.0:
        h = 0.0
        for j in ti.static(range(4)):
            if con.contact_vertex[c][j] == i:
                h += con.contact_weight[c][j]
        coef = h / dh
    return coef


@ti.func
def store_entry_coefficients(con: ti.template()):
    """h_ci / D_hat_c of every CSR entry (vertex i, contact c), 0 where D_hat_c = 0: what the batch updates
    (``projection.apply_batch_corrections``) multiply each correction by, read in entry order instead of
    gathered from the contact's four vertices, weights and D_hat.  Run wherever weights or D_hat change, when a sweep
    in batches may follow (the sweeps one by one read the weights and D_hat themselves)."""
    for k in range(con.active_vertex_count[None]):
        i = con.active_vertex[k]
        for e in range(con.vertex_contact_start[i], con.vertex_contact_start[i + 1]):
            con.vertex_contact_coefficient[e] = entry_coefficient(con, i, con.vertex_contact_list[e])


@ti.func
def _batch_order_after(c: ti.i32, d: ti.i32) -> bool:
    """Does contact c come after d in a vertex's list (ordered by batch c % BATCHES, then index)?"""
    return c % BATCHES > d % BATCHES or (c % BATCHES == d % BATCHES and c > d)


@ti.kernel
def build_adjacency(vertex: ti.template(), con: ti.template(), vertex_weight_base: ti.template(),
                    vertex_typical_length: ti.template(), vertex_dt_bend: ti.template(), dt: float,
                    gravity_norm: float, dynamic: ti.template(), first_new: ti.i32, split_by_batch: ti.template(),
                    bending_time: ti.i32, coefficients: ti.template()):
    """CSR vertex -> contacts (sorted), W_z (Sec. 4.5 "Collision constraint weights"), D_hat.

    Contacts from ``first_new`` on start from zero; with ``first_new`` = 0 (the proximity detection at the
    beginning of a step) the collision duals lambda_z are zeroed too.  Contacts appended later in the step
    (continuous-time detection) keep the earlier contacts' progress: their accumulated corrections
    r~ = D_hat r are rescaled to the new D_hat (more contacts on a vertex split its mass further), so the
    impulses r they stand for are unchanged, and lambda_z is kept.  ``coefficients``: as in ``relinearize_contacts``.
    """
    nc = ti.min(con.contact_count[None], con.capacity)
    for i in con.vertex_contact_count:
        con.vertex_contact_count[i] = 0
    for c in range(nc):
        for k in ti.static(range(4)):
            v = con.contact_vertex[c][k]
            if v >= 0:
                ti.atomic_add(con.vertex_contact_count[v], 1)
    ti.loop_config(serialize=True)
    for _ in range(1):
        run = 0
        na = 0
        for i in range(con.vertex_contact_count.shape[0]):
            con.vertex_contact_start[i] = run
            run += con.vertex_contact_count[i]
            if con.vertex_contact_count[i] > 0:
                con.active_vertex[na] = i
                na += 1
        con.vertex_contact_start[con.vertex_contact_count.shape[0]] = run
        con.active_vertex_count[None] = na
    for i in con.vertex_contact_count:
        con.vertex_contact_count[i] = 0
    # Each vertex's list sorted by batch, then contact index: a batch's corrections then read only its own entries.
    if ti.static(on_gpu()):
        for c in range(nc):  # (in any order: sorted below)
            for k in ti.static(range(4)):
                v = con.contact_vertex[c][k]
                if v >= 0:
                    slot = ti.atomic_add(con.vertex_contact_count[v], 1)
                    con.vertex_contact_list[con.vertex_contact_start[v] + slot] = c
    else:
        # On a CPU one thread fills the lists in that order, batch by batch, with no sort after: the fill and the
        # per-vertex loop 7.8 + 11 ms with the atomics and the sort, 8.0 + 5.3 ms so (grooming benchmark, 153k
        # contacts; kernel profiler, 2026-12-06).
        ti.loop_config(serialize=True)
        for b in range(BATCHES):
            for j in range((nc - b + BATCHES - 1) // BATCHES):
                c = j * BATCHES + b
                for k in ti.static(range(4)):
                    v = con.contact_vertex[c][k]
                    if v >= 0:
                        con.vertex_contact_list[con.vertex_contact_start[v] + con.vertex_contact_count[v]] = c
                        con.vertex_contact_count[v] += 1
    for i in con.vertex_contact_count:
        beg = con.vertex_contact_start[i]
        end = con.vertex_contact_start[i + 1]
        if ti.static(on_gpu()):
            for j in range(beg + 1, end):  # (insertion sort)
                key = con.vertex_contact_list[j]
                k = j - 1
                # (A break, not ``k >= beg and ...``: Taichi's ``and`` evaluates both sides, which read entry beg - 1.)
                while k >= beg:
                    if not _batch_order_after(con.vertex_contact_list[k], key):
                        break
                    con.vertex_contact_list[k + 1] = con.vertex_contact_list[k]
                    k -= 1
                con.vertex_contact_list[k + 1] = key
        e = beg
        for b in ti.static(range(BATCHES)):
            while e < end:
                if con.vertex_contact_list[e] % BATCHES >= b:
                    break
                e += 1
            con.vertex_batch_start[i, b] = e
        # W_z,i = m_i / dt~^2 with dt~ = min(dt, sqrt(L~/|g|), 2 L~^2/R sqrt(rho/E_b)) (Sec. 4.5), the bending
        # time left out where ``bending_time`` says (BEND_NONE: everywhere, BEND_BODY: on a vertex whose
        # contacts are all hair-hair).
        # Kinematic (clamped) vertices do not move (1/W_z = 0): see ``_delassus`` for their contacts' D_hat.
        inv_w = 0.0
        if con.vertex_contact_count[i] > 0:
            bend = bending_time == BEND_ALL
            if bending_time == BEND_BODY:
                for j in range(beg, end):
                    if con.contact_collider[con.vertex_contact_list[j]] >= 0:
                        bend = True
            dtt = vertex_dt_bend[i] if bend else 1e30
            if gravity_norm > 0.0:
                dtt = ti.min(dtt, ti.sqrt(vertex_typical_length[i] / gravity_norm))
            if ti.static(dynamic):
                dtt = ti.min(dtt, dt)
            inv_w = dtt * dtt / vertex_weight_base[i]
        if vertex.vertex_is_fixed[i] != 0:
            inv_w = 0.0
        con.vertex_contact_inv_weight[i] = inv_w
        if first_new == 0:
            con.vertex_contact_dual[i] = vec3(0.0)
    for c in range(nc):
        dh = _delassus(con, c, split_by_batch)
        if c < first_new:
            old = con.contact_delassus[c]
            if old > 0.0:
                con.contact_accumulated[c] *= dh / old
        else:
            con.contact_accumulated[c] = vec3(0.0)
            con.contact_delta[c] = vec3(0.0)
            con.contact_status[c] = 0
        con.contact_delassus[c] = dh
        store_push(con, c)
    if ti.static(coefficients):
        store_entry_coefficients(con)
