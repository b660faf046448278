"""Feasible contact projection: the z-step of Algorithm 1 (Daviet 2023, Sec. 4.5, Eq. 5-6).

Problem (5): W_z z = W_z (x - lambda_z) + H^T r, u = H z + u_kin, (u, r) in C_mu,n.

Hybrid Gauss-Seidel / Jacobi: contacts are split into ``BATCHES`` = 8
batches (contact c in batch c mod 8: the contact list is sorted by edge, so
neighbouring contacts, which share vertices, land in different batches);
batches are processed one after the other, the contacts of a batch in
parallel, in the paper's two deterministic steps:

1. ``solve_batch_contacts``: for each contact c of the batch,
   u*_c = (H z)_c + u_kin_c, solve the local Signorini-Coulomb problem for
   Delta u_c with (u*_c + Delta u_c, r~_c + Delta u_c) in C_mu,n, and
   accumulate r~_c += Delta u_c (r~ = D r, footnote 3);
2. ``apply_batch_corrections``: z_i += W_z,i^-1 sum_c h_ci Delta u_c / D_hat_c,
   each vertex gathering its own contacts in index order (no atomics: the
   sum has a fixed order, so runs are bitwise reproducible).

D_hat is the mass-split Delassus diagonal (each vertex split into n_i virtual
copies), which keeps the Jacobi updates inside a batch from overshooting.

The local solve (Daviet 2020, Sec. 5.2, isotropic case): with the scalar
Delassus D_hat the contact's problem is u = w + r~ with w = u* - r~_old (the
relative displacement without this contact's correction) and (u, r~) in
C_mu: r~ in the friction cone, u_N >= 0, r~_N u_N = 0, and either u_T = 0
(stick) or r~_T = -mu r~_N u_T/|u_T| (slide).  Its solution is explicit:

* take-off, w_N >= 0: r~ = 0;
* stick, |w_T| <= mu (-w_N): r~ = -w, u = 0;
* slide: r~ = -w_N n - mu (-w_N) w_T/|w_T|, u = w_T (1 - mu (-w_N)/|w_T|).
"""

import taichi as ti

from ..fields import CONTACT_BATCHES, CONTACT_SLABS
from .colliders import body_transform, collider_distance

vec3 = ti.math.vec3

BATCHES = CONTACT_BATCHES  # contact c is in batch c % BATCHES (Sec. 4.5)
SEPARATE, STICK, SLIDE = 0, 1, 2


@ti.func
def coulomb_local_solve(w, n, mu: float):
    """Solution r~ of u = w + r~, (u, r~) in C_mu,n for an isotropic (scalar) Delassus operator.

    Args:
        w: relative displacement without this contact's correction [m].
        n: unit contact normal [-].
        mu: friction coefficient [-].

    Returns:
        (r~, status): the correction [m] and SEPARATE, STICK or SLIDE.
    """
    wn = w.dot(n)
    r = vec3(0.0)
    status = SEPARATE
    if wn < 0.0:
        wt = w - wn * n
        wt_norm = wt.norm()
        if wt_norm <= mu * (-wn):
            r = -w
            status = STICK
        else:
            r = -wn * n - (mu * (-wn) / wt_norm) * wt
            status = SLIDE
    return r, status


@ti.func
def begin_projection(x: ti.template(), con: ti.template()):
    """z = x - lambda_z + W_z^-1 H^T D_hat^-1 r~ on contact vertices (warm start from the corrections so far),
    which is z = x: lambda_z is the sum of the pushes, W_z^-1 H^T D_hat^-1 r~.

    Why, by induction over the projections of a step: the detection zeroes lambda_z and r~ (``build_adjacency``),
    so the two are equal at first.  A projection starts at z_0 = x - lambda + P(r~) (P: the pushes the
    accumulated corrections stand for) and every contact update adds its push to z and to P alike
    (``solve_contacts_sequential``, ``apply_batch_corrections``), so it ends at z = x - lambda + P_new, and the
    dual update lambda <- lambda + z - x (``update_contact_duals``, with the same x) gives lambda = P_new.  Contacts
    appended within the step (continuous detection) keep their impulses, so P does not change then either (their
    r~ is rescaled with D_hat; W_z of a vertex depends only on the vertex and, with ``WeightTime.HAIR_STEP``, on
    whether it has a body contact, which the continuous passes never add).  So z = x to rounding, and summing
    the pushes (~5 random reads per contact entry, 5.5 ms of each projection on the 120k-vertex groom, measured)
    only added that rounding.  ``tests/test_contacts.py`` checks lambda_z = P after a step's projections.
    """
    for k in range(con.active_vertex_count[None]):
        i = con.active_vertex[k]
        con.vertex_z[i] = x[i]


@ti.func
def _contact_u(con: ti.template(), z: ti.template(), c: ti.i32):
    u = con.contact_kinematic[c]
    for k in ti.static(range(4)):
        v = con.contact_vertex[c][k]
        if v >= 0:
            u += con.contact_weight[c][k] * z[v]
    return u


@ti.func
def solve_batch_contacts(con: ti.template(), z: ti.template(), batch: ti.template(), serial: ti.template()):
    """Step (1) for the contacts of one batch, in parallel."""
    nc = ti.min(con.contact_count[None], con.capacity)
    nb = (nc - batch + 7) // 8
    ti.loop_config(serialize=serial)
    for j in range(nb):
        c = j * 8 + batch
        if con.contact_delassus[c] > 0.0:
            u_star = _contact_u(con, z, c)
            r_old = con.contact_accumulated[c]
            r_new, status = coulomb_local_solve(u_star - r_old, con.contact_normal[c], con.contact_friction[c])
            con.contact_delta[c] = r_new - r_old
            con.contact_accumulated[c] = r_new
            con.contact_status[c] = status
        else:
            con.contact_delta[c] = vec3(0.0)


#: ``serial`` of ``correction_sweep``: every contact in turn on one thread, each applied before the next is solved.
SEQUENTIAL = 2


@ti.func
def _solve_one(con: ti.template(), z: ti.template(), c: ti.i32):
    """Steps (1) and (2) for contact c alone: its local solve, its push applied to z at once."""
    dh = con.contact_delassus[c]
    if dh > 0.0:
        u_star = _contact_u(con, z, c)
        r_old = con.contact_accumulated[c]
        r_new, status = coulomb_local_solve(u_star - r_old, con.contact_normal[c], con.contact_friction[c])
        d = r_new - r_old  # (applied here: no ``contact_delta`` for a vertex pass to read)
        # Only what changed is written: most contacts stay apart (r~ = 0 before and after: 85 % of the grooming benchmark's
        # 153k), and storing r~, status and z + 0 d cost 20 % of a sweep (2.33 -> 1.86 ms, the same bits; 2026-12-06).
        if status != con.contact_status[c]:
            con.contact_status[c] = status
        if d[0] != 0.0 or d[1] != 0.0 or d[2] != 0.0:
            con.contact_accumulated[c] = r_new
            push = con.contact_push[c]  # (W_z,i^-1 h_ci / D_hat_c, ``narrow.store_push``)
            for k in ti.static(range(4)):
                v = con.contact_vertex[c][k]
                if v >= 0 and push[k] != 0.0:
                    # (Not ``+=``: in a parallel loop (``solve_contacts_slabs``) Taichi makes that an atomic add,
                    # a compare-and-swap loop per component; no other thread touches v here.)
                    z[v] = z[v] + push[k] * d


@ti.func
def solve_contacts_sequential(con: ti.template(), z: ti.template()):
    """Steps (1) and (2) for every contact in index order on the launching thread: a true Gauss-Seidel sweep,
    each contact seeing the pushes of those before it (no Jacobi sum within a batch)."""
    nc = ti.min(con.contact_count[None], con.capacity)
    ti.loop_config(serialize=True)
    for c in range(nc):
        _solve_one(con, z, c)


#: ``serial`` of the sweeps: the contacts one by one in slab groups, groups with disjoint vertices in parallel; or the
#: same groups in the same order on the launching thread (the same bits: ``ContactPipeline.sweep_order`` says where).
SLABS, SLAB_ORDER = 3, 4
#: Loop iterations per slab group in ``solve_contacts_slabs`` [-]: Taichi 1.7's CPU threads take a parallel loop in
#: blocks of >= 512 iterations (``block_dim`` did not change it), so a loop over 8 groups ran on one thread; 512 per
#: group, all but the first empty, give each group a block of its own.
_TASK_STRIDE = 512


@ti.func
def _solve_range(con: ti.template(), z: ti.template(), begin: ti.i32, end: ti.i32):
    for c in range(begin, end):
        _solve_one(con, z, c)


@ti.func
def solve_contacts_slabs(con: ti.template(), z: ti.template(), parallel: ti.template()):
    """Steps (1) and (2) for every contact one by one, in the four phases of ``contact.slabs`` (the groups sorted by
    ``slabs.group_contacts``): the slabs' own groups, those between slabs 0|1, 2|3, ..., those between 1|2, 3|4, ...,
    then the rest.  ``parallel``: each of the first three a parallel loop over its groups (disjoint vertex sets), one
    group per task; else every group on the launching thread, in the same order (so the same bits)."""
    S = ti.static(CONTACT_SLABS)
    T = ti.static(_TASK_STRIDE)
    start = ti.static(con.contact_group_start)
    for first, step, count in ti.static(((0, 1, S), (S, 2, S // 2), (S + 1, 2, (S - 1) // 2))):
        if ti.static(parallel):
            for k in range(count * T):  # (one group per T iterations: see _TASK_STRIDE)
                if k % T == 0:
                    g = first + step * (k // T)
                    _solve_range(con, z, start[g], start[g + 1])
        else:
            ti.loop_config(serialize=True)
            for k in range(count):
                g = first + step * k
                _solve_range(con, z, start[g], start[g + 1])
    ti.loop_config(serialize=True)
    for _ in range(1):  # the rest, and the contacts appended since the detection
        _solve_range(con, z, start[2 * S - 1], ti.min(con.contact_count[None], con.capacity))


@ti.func
def apply_batch_corrections(con: ti.template(), z: ti.template(), batch: ti.template(), serial: ti.template()):
    """Step (2): z_i += W_z,i^-1 sum_{c in batch} h_ci Delta u_c / D_hat_c, vertices in parallel.

    Each vertex's list is sorted by batch (``contacts.build_adjacency``): only the batch's entries are read,
    with their factors h_ci / D_hat_c (``narrow.store_entry_coefficients``)."""
    ti.loop_config(serialize=serial)
    for k in range(con.active_vertex_count[None]):
        i = con.active_vertex[k]
        iw = con.vertex_contact_inv_weight[i]
        if iw > 0.0:
            begin = con.vertex_batch_start[i, batch]
            stop = con.vertex_contact_start[i + 1]
            if ti.static(batch + 1 < BATCHES):
                stop = con.vertex_batch_start[i, batch + 1]
            if stop > begin:  # else no contact of i in this batch: z_i stays (and is neither read nor written)
                dz = vec3(0.0)
                for e in range(begin, stop):
                    dz += con.vertex_contact_coefficient[e] * con.contact_delta[con.vertex_contact_list[e]]
                z[i] += iw * dz


@ti.func
def update_contact_duals(x: ti.template(), con: ti.template(), buf: ti.template()):
    """lambda_z += z - x; hand W_z and the target lambda_z + z to the global step (Eq. 3)."""
    for k in range(con.active_vertex_count[None]):
        i = con.active_vertex[k]
        iw = con.vertex_contact_inv_weight[i]
        if iw > 0.0:
            lam = con.vertex_contact_dual[i] + con.vertex_z[i] - x[i]
            con.vertex_contact_dual[i] = lam
            buf.vertex_contact_weight[i] = 1.0 / iw
            buf.vertex_contact_target[i] = lam + con.vertex_z[i]


@ti.kernel
def clear_contact_terms(con: ti.template(), buf: ti.template()):
    """Zero W_z and the targets of the global step on the vertices that had contacts."""
    for k in range(con.active_vertex_count[None]):
        i = con.active_vertex[k]
        buf.vertex_contact_weight[i] = 0.0
        buf.vertex_contact_target[i] = vec3(0.0)


@ti.func
def begin_correction(x: ti.template(), con: ti.template()):
    """Geometric correction: project x itself (z = x on every vertex, fresh corrections, lambda_z ignored)."""
    for i in x:
        con.vertex_z[i] = x[i]
    nc = ti.min(con.contact_count[None], con.capacity)
    for c in range(nc):
        con.contact_accumulated[c] = vec3(0.0)


@ti.func
def end_correction(vertex: ti.template(), x: ti.template(), con: ti.template()):
    """x = z on every free vertex (the edge-length passes may have moved vertices without contacts)."""
    for i in x:
        if vertex.vertex_is_fixed[i] == 0:
            x[i] = con.vertex_z[i]


@ti.func
def _inverse_mass(vertex: ti.template(), i: ti.i32) -> float:
    """1/m_i, 0 on kinematic vertices [1/kg]."""
    w = 0.0
    if vertex.vertex_is_fixed[i] == 0:
        w = 1.0 / vertex.vertex_mass[i]
    return w


@ti.func
def _hold_pair(edge: ti.template(), length: ti.template(), j: ti.i32, za, zb, wa: float, wb: float):
    """Project edge j, with end points za = z_j and zb = z_{j+1} and inverse masses wa, wb, back to its held
    length; returns the moved end points.

    C = |z_{j+1} - z_j| - l_j moves them along the edge by w_j / (w_j + w_{j+1}) C and
    w_{j+1} / (w_j + w_{j+1}) C, with w = 1/m (0 on kinematic vertices), the position-based projection of an
    inextensibility constraint (Mueller et al. 2007).
    """
    if edge.edge_rest_length[j] > 0.0:
        d = zb - za
        dn = d.norm()
        if wa + wb > 0.0 and dn > 0.0:
            corr = ((dn - length[j]) / ((wa + wb) * dn)) * d
            za += wa * corr
            zb -= wb * corr
    return za, zb


@ti.func
def _hold_edge(vertex: ti.template(), edge: ti.template(), z: ti.template(), length: ti.template(), j: ti.i32):
    """``_hold_pair`` on edge j of z, in place (only real edges are written: a ghost edge's j + 1 is the next
    strand's root, which an edge of the same colour may be moving)."""
    if edge.edge_rest_length[j] > 0.0:
        za, zb = _hold_pair(edge, length, j, z[j], z[j + 1], _inverse_mass(vertex, j), _inverse_mass(vertex, j + 1))
        z[j] = za
        z[j + 1] = zb


@ti.func
def hold_edge_lengths(vertex: ti.template(), edge: ti.template(), z: ti.template(), length: ti.template(),
                      colour: ti.template()):
    """Project the edges of one colour (local edge index parity) back to their held lengths (``_hold_edge``).
    Edges of one colour share no vertex, so they are projected in parallel without atomics (bitwise
    reproducible)."""
    for j in z:
        if vertex.vertex_local_index[j] % 2 == colour:
            _hold_edge(vertex, edge, z, length, j)


#: Strands a thread holds in lockstep in ``hold_strand_lengths`` [-].  One strand's edge projections form a chain
#: of dependent square roots and divisions (latency-bound); 8 independent chains interleaved keep the core busy.
#: Measured (scratch probe, 8,600 strands x 14 vertices, 8 passes, 2 cores): 12.1-13.1 ms with one strand per
#: iteration, 6.5 with 2 lanes, 4.0-7.5 with 4 and 3.2 with 8, the same bits in each.
HOLD_LANES = 8


@ti.func
def hold_strand_lengths(vertex: ti.template(), edge: ti.template(), strand: ti.template(), z: ti.template(),
                        length: ti.template(), serial: ti.template(), passes: ti.template()):
    """Project every edge back to its held length (``_hold_edge``) root to tip and then tip to root, one
    strand per thread (bitwise reproducible): a symmetric Gauss-Seidel pass that carries a contact's push
    along the whole strand in one sweep, where the two colours carry it one edge per sweep.  ``passes`` such
    passes, each strand's one after the other on its thread (strands do not share edges: the same operations as
    ``passes`` launches, with the strand in cache).  Each thread steps :data:`HOLD_LANES` consecutive strands
    in lockstep (each strand's operations and their order unchanged)."""
    n = strand.strand_vertex_start.shape[0]
    ti.loop_config(serialize=serial)
    for g in range((n + HOLD_LANES - 1) // HOLD_LANES):
        for _ in range(passes):
            _hold_strand_lanes(vertex, edge, strand, z, length, g * HOLD_LANES, n)


@ti.func
def _hold_strand_lanes(vertex: ti.template(), edge: ti.template(), strand: ti.template(), z: ti.template(),
                       length: ti.template(), s0: ti.i32, n: ti.i32):
    """One symmetric pass of ``hold_strand_lengths`` on strands s0, ..., s0 + HOLD_LANES - 1 (those below n).
    ``_hold_pair`` on edges start, ..., start + m - 2 and back, the vertex two edges share kept in registers from
    one edge to the next (not stored and loaded again)."""
    start = ti.Vector([0] * HOLD_LANES, ti.i32)
    m = ti.Vector([0] * HOLD_LANES, ti.i32)
    za = ti.Matrix([[0.0] * 3] * HOLD_LANES, float)
    wa = ti.Vector([0.0] * HOLD_LANES, float)
    longest = 0
    for lane in ti.static(range(HOLD_LANES)):
        if s0 + lane < n:
            start[lane] = strand.strand_vertex_start[s0 + lane]
            m[lane] = strand.strand_vertex_count[s0 + lane]
            longest = ti.max(longest, m[lane])
            p = z[start[lane]]
            for c in ti.static(range(3)):
                za[lane, c] = p[c]
            wa[lane] = _inverse_mass(vertex, start[lane])
    for k in range(longest - 1):
        for lane in ti.static(range(HOLD_LANES)):
            if k < m[lane] - 1:
                j = start[lane] + k
                wb = _inverse_mass(vertex, j + 1)
                a, b = _hold_pair(edge, length, j, vec3(za[lane, 0], za[lane, 1], za[lane, 2]), z[j + 1], wa[lane],
                                  wb)
                z[j] = a
                for c in ti.static(range(3)):
                    za[lane, c] = b[c]
                wa[lane] = wb
    for k in range(longest - 1):  # back, tip to root: za, wa hold each strand's last vertex
        for lane in ti.static(range(HOLD_LANES)):
            if k < m[lane] - 1:
                j = start[lane] + m[lane] - 2 - k
                w_j = _inverse_mass(vertex, j)
                a, b = _hold_pair(edge, length, j, z[j], vec3(za[lane, 0], za[lane, 1], za[lane, 2]), w_j,
                                  wa[lane])
                z[j + 1] = b
                for c in ti.static(range(3)):
                    za[lane, c] = a[c]
                wa[lane] = w_j
    for lane in ti.static(range(HOLD_LANES)):
        if s0 + lane < n:
            z[start[lane]] = vec3(za[lane, 0], za[lane, 1], za[lane, 2])


@ti.func
def hold_lengths(vertex: ti.template(), edge: ti.template(), strand: ti.template(), z: ti.template(),
                 length: ti.template(), along_strands: ti.template(), serial: ti.template(), passes: ti.template()):
    """``passes`` passes of the edge lengths: along each strand (``hold_strand_lengths``) or both colours."""
    if ti.static(along_strands):
        hold_strand_lengths(vertex, edge, strand, z, length, serial, passes)
    else:
        for _ in ti.static(range(passes)):
            for colour in ti.static(range(2)):
                hold_edge_lengths(vertex, edge, z, length, colour)


@ti.kernel
def store_edge_lengths(edge: ti.template(), x: ti.template(), out_length: ti.template(), rest: ti.template()):
    """The lengths the correction holds on real edges [m]: the rest lengths, or (``rest`` False) the
    current |x_{j+1} - x_j|."""
    for j in x:
        length = 0.0
        if edge.edge_rest_length[j] > 0.0:
            if ti.static(rest):
                length = edge.edge_rest_length[j]
            else:
                length = (x[j + 1] - x[j]).norm()
        out_length[j] = length


#: ``with_status`` of ``contact_statistics``: also count the hair pairs thinner than r_a + r_b (no status).
OVERLAPS = 2


@ti.kernel
def contact_penetrations(con: ti.template(), n: ti.i32, penetration: ti.types.ndarray(), hair: ti.types.ndarray()):
    """The first n contacts' penetrations [m] and whether each is hair-hair (1) or a body's (0), to the host in one
    kernel (two ``to_numpy`` calls were two kernel instances and copied the whole capacity)."""
    for c in range(n):
        penetration[c] = con.contact_penetration[c]
        hair[c] = ti.cast(con.contact_collider[c] < 0, ti.i8)


@ti.kernel
def contact_statistics(x: ti.template(), radius: ti.template(), cs: ti.template(), con: ti.template(),
                       out: ti.template(), with_status: ti.template()):
    """Counts of the last projection and the penetrations of every contact at the current x.

    out = (sticking, sliding, separating, deepest body penetration [m], deepest hair-pair penetration [m],
    hair pairs crossed [-], hair pairs thinner than r_a + r_b (only with ``with_status`` = ``OVERLAPS``, else 0) [-]);
    ``con.contact_penetration`` gets each contact's penetration.  ``with_status`` True: only the status counts
    (out[0:3]) and each status copied to ``con.contact_status_admm`` (the step's statistics measure penetrations).

    Hair pair: the signed gap g = n . (p_a - p_b) - (r_a + r_b) at the contact's barycentric points with its
    normal n, which points from b to a at the beginning of the step (or, after the correction's
    re-linearisation, along the current closest points while the pair has not crossed); a pair that passed
    through each other has n . (p_a - p_b) < 0, counts as crossed, and as penetrating by more than
    r_a + r_b.  Body contact: r minus the signed distance to the collider (the solver's distance: exact for
    planes, spheres and capsules, the voxel SDF for meshes) at the end-of-step transform.
    """
    nc = ti.min(con.contact_count[None], con.capacity)
    con.contact_tally[None] = ti.Vector([0.0] * 5)
    if ti.static(with_status == 1):
        for c in range(nc):
            st = con.contact_status[c]
            con.contact_status_admm[c] = st
            con.contact_tally[None] += ti.Vector([st == STICK, st == SLIDE, st != STICK and st != SLIDE, 0, 0], float)
        for j in ti.static(range(3)):
            out[j] = con.contact_tally[None][j]
    else:
        _penetrations(x, radius, cs, con, out)
    if ti.static(with_status == OVERLAPS):  # hair pairs closer at rest than r_a + r_b (``keep_rest_overlaps``)
        for c in range(nc):
            vtx = con.contact_vertex[c]  # (vtx[2] is -1 on a body contact, and ``and`` evaluates both sides)
            r_ab = radius[vtx[0]] + radius[ti.max(vtx[2], 0)]
            thin = con.contact_collider[c] < 0 and con.contact_thickness[c] < r_ab * (1.0 - 1e-6)
            con.contact_tally[None] += ti.Vector([0.0, 0.0, 0.0, 0.0, ti.select(thin, 1.0, 0.0)])
        out[6] = con.contact_tally[None][4]


@ti.func
def _penetrations(x: ti.template(), radius: ti.template(), cs: ti.template(), con: ti.template(), out: ti.template()):
    nc = ti.min(con.contact_count[None], con.capacity)  # (out[3:7] and the penetrations of ``contact_statistics``)
    for j in ti.static(range(3, 7)):
        out[j] = 0.0
    for c in range(nc):
        pen = 0.0
        k = con.contact_collider[c]
        vtx = con.contact_vertex[c]
        if k < 0:
            w = con.contact_weight[c]
            d = w[0] * x[vtx[0]] + w[1] * x[vtx[1]] + w[2] * x[vtx[2]] + w[3] * x[vtx[3]]
            side = con.contact_normal[c].dot(d)
            pen = con.contact_thickness[c] - side
            if pen > out[4]:  # (read first: the maximum only grows, and most contacts are below it)
                ti.atomic_max(out[4], pen)
            if side < 0.0:
                ti.atomic_add(out[5], 1.0)
        else:
            R, T = body_transform(cs.body_rotation_end, cs.body_translation_end, cs.collider_body[k])
            dist, nrm = collider_distance(cs, k, R.transpose() @ (x[vtx[0]] - T))
            pen = radius[vtx[0]] - dist
            if pen > out[3]:
                ti.atomic_max(out[3], pen)
        con.contact_penetration[c] = ti.max(pen, 0.0)


@ti.kernel
def projection_begin(x: ti.template(), con: ti.template(), correction: ti.template()):
    """Start a z-step: z = x - lambda_z + W_z^-1 H^T D_hat^-1 r~ (or, for the correction, z = x and r~ = 0)."""
    if ti.static(correction):
        begin_correction(x, con)
    else:
        begin_projection(x, con)


@ti.func
def sweep_contacts(con: ti.template(), serial: ti.template()):
    """Every contact once on z: the 8 batches in turn (``serial``: each loop on the launching thread), or with
    ``serial = SEQUENTIAL`` each contact in index order, its push applied before the next is solved, or with
    ``SLABS`` one by one in the slab groups of ``contact.slabs``, on several threads (``SLAB_ORDER``: on one)."""
    if ti.static(serial == SEQUENTIAL):
        solve_contacts_sequential(con, con.vertex_z)
    elif ti.static(serial == SLABS or serial == SLAB_ORDER):
        solve_contacts_slabs(con, con.vertex_z, serial == SLABS)
    else:
        for batch in ti.static(range(BATCHES)):
            solve_batch_contacts(con, con.vertex_z, batch, serial)
            apply_batch_corrections(con, con.vertex_z, batch, serial)


@ti.kernel
def projection_sweep(con: ti.template(), serial: ti.template()):
    """One Gauss-Seidel sweep over the 8 batches, each in the paper's two deterministic steps.

    Each step is a top-level loop of the kernel; Taichi runs top-level loops
    one after the other, so the batches stay sequential within one launch.  ``serial``: every loop runs on
    the launching thread (``ContactPipeline._serial_contacts``: where the contacts are few, the 16 dispatches to the
    thread pool cost more than the work; the same operations in the same order, so the same bits), or
    ``SEQUENTIAL`` (the contacts one by one, ``ContactConfig.projection_contact_order``) or ``SLABS`` (the same in
    slab groups, ``contact.slabs``).
    """
    sweep_contacts(con, serial)


@ti.kernel
def correction_sweep(vertex: ti.template(), edge: ti.template(), strand: ti.template(), con: ti.template(),
                     length: ti.template(), along_strands: ti.template(), serial: ti.template(),
                     serial_strands: ti.template()):
    """One sweep of the length-holding geometric correction: the 8 contact batches, then the edge lengths
    (``hold_lengths``).

    A Gauss-Seidel pass over contacts and inextensibility together, so a crossed pair pushed back drags
    its strands' neighbouring vertices along instead of stretching the edges at the contact.  ``serial``: the
    contact loops on the launching thread (``projection_sweep``), or ``SEQUENTIAL``: no batches, every contact
    in turn (``solve_contacts_sequential``, ``ContactConfig.correction_contact_order``), or ``SLABS``: the same in
    slab groups (``contact.slabs``); ``serial_strands``: the
    edge passes on the launching thread too.
    """
    sweep_contacts(con, serial)
    hold_lengths(vertex, edge, strand, con.vertex_z, length, along_strands, serial_strands, 1)


@ti.kernel
def correction_end(vertex: ti.template(), x: ti.template(), con: ti.template()):
    """End the geometric correction: x = z on the free vertices."""
    end_correction(vertex, x, con)


@ti.kernel
def projection_end(x: ti.template(), con: ti.template(), buf: ti.template()):
    """End a z-step: lambda_z += z - x and W_z for the global step."""
    update_contact_duals(x, con, buf)


@ti.kernel
def hold_lengths_sweep(vertex: ti.template(), edge: ti.template(), strand: ti.template(), con: ti.template(),
                       length: ti.template(), along_strands: ti.template(), serial: ti.template(),
                       passes: ti.template()):
    """The edge lengths ``passes`` more times (``hold_lengths``; one launch), after the last contact sweep of the
    correction; ``serial``: on the launching thread (a small model, ``ContactPipeline.correct``)."""
    hold_lengths(vertex, edge, strand, con.vertex_z, length, along_strands, serial, passes)
