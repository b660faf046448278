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
* body: each free vertex within r + margin of a collider (at the
  begin-of-step body transform) gets a contact with h = 1 against the body
  surface point s, carried rigidly to the end-of-step transform:
  u = x - s_end - r n_end.

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

from .colliders import acts_on, body_transform, collider_distance
from .grid import contact_normal, row_holds, segment_closest_points
from .projection import BATCHES

vec3 = ti.math.vec3
ivec4 = ti.types.vector(4, ti.i32)
vec4 = ti.types.vector(4, float)


@ti.func
def _in_list(grid: ti.template(), a: ti.i32, b: ti.i32) -> bool:
    return row_holds(grid.edge_candidate, grid.edge_candidate_count, a, b)


@ti.func
def _emits(grid: ti.template(), a: ti.i32, k: ti.i32) -> bool:
    b = grid.edge_candidate[a, k]
    return a < b or not _in_list(grid, b, a)


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
                    R, T = body_transform(cs.body_rotation_begin, cs.body_translation_begin, cs.collider_body[k])
                    d, n = collider_distance(cs, k, R.transpose() @ (x[a] - T))
                    if d < radius[a] + margin + sweep * v[a].norm() + fall:
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
                   hair_friction: float, margin: float, sweep: float, fall: float):
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
                    s, t, dist = segment_closest_points(x[a], x[a + 1], x[b], x[b + 1])
                    pa = x[a] + s * (x[a + 1] - x[a])
                    pb = x[b] + t * (x[b + 1] - x[b])
                    nrm = contact_normal(pa - pb, x[a + 1] - x[a], x[b + 1] - x[b])
                    r = radius[a] + radius[b]
                    con.contact_vertex[c] = ivec4(a, a + 1, b, b + 1)
                    con.contact_weight[c] = vec4(1.0 - s, s, -(1.0 - t), -t)
                    con.contact_normal[c] = nrm
                    con.contact_kinematic[c] = -r * nrm
                    con.contact_friction[c] = hair_friction
                    con.contact_collider[c] = -1
                c += 1
        if vertex.vertex_is_fixed[a] == 0:
            cb = n_hair + grid.vertex_body_emit_count[a]
            for k in range(cs.count_field[None]):
                body = cs.collider_body[k]
                R, T = body_transform(cs.body_rotation_begin, cs.body_translation_begin, body)
                q = R.transpose() @ (x[a] - T)
                d, nq = collider_distance(cs, k, q)
                if d < radius[a] + margin + sweep * v[a].norm() + fall and acts_on(cs, k, vertex.vertex_strand[a]):
                    if cb < cap:
                        Re, Te = body_transform(cs.body_rotation_end, cs.body_translation_end, body)
                        s_end = Re @ (q - d * nq) + Te
                        n_end = Re @ nq
                        con.contact_vertex[cb] = ivec4(a, -1, -1, -1)
                        con.contact_weight[cb] = vec4(1.0, 0.0, 0.0, 0.0)
                        con.contact_normal[cb] = n_end
                        con.contact_kinematic[cb] = -s_end - radius[a] * n_end
                        con.contact_friction[cb] = cs.collider_friction[k]
                        con.contact_collider[cb] = k
                    cb += 1


#: ``_delassus``'s third choice (after True: by batch, False: by vertex): no mass splitting (n_i = 1).
SPLIT_NONE = 2


@ti.func
def _delassus(con: ti.template(), c: ti.i32, split_by_batch: ti.template()) -> float:
    """Mass-split Delassus diagonal D_hat_c = sum_i n_i h_ci^2 / W_z,i of contact c (Sec. 4.5).

    ``split_by_batch``: True (n_i = c's batch's contacts on i), False (n_i = all of i's contacts), or
    ``SPLIT_NONE`` (n_i = 1: the plain Delassus diagonal D of Eq. 6, no splitting; the correction's option
    ``ContactConfig.correction_mass_splitting = "none"``).

    Clamped vertices enter with the W_z a free vertex would have, although they do not move.  With the
    paper's 1/W_z = 0 for them, a contact whose point lies near a clamped vertex (weight h ~ 1 there and
    h ~ 0.01 on the free one) gets a tiny D_hat, and the z-step moves the free vertex by Delta u / h, a
    lever amplified a hundredfold: measured, 8,600 clamped strands generated on a head (roots 2.5 mm apart,
    103k contacts at rest) moved by 56 mm then 1 m in two quasistatic iterations and diverged.  Counting
    the clamped vertex only under-relaxes such contacts (what cannot move is not asked to).
    """
    dh = 0.0
    for k in ti.static(range(4)):
        v = con.contact_vertex[c][k]
        if v >= 0:
            h = con.contact_weight[c][k]
            # Virtual copies of vertex v: all its contacts (the paper's n_i), or only those of c's
            # batch, the ones updated at the same time as c (see ContactConfig.mass_splitting).
            copies = con.vertex_contact_count[v]
            if ti.static(split_by_batch == SPLIT_NONE):
                copies = 1
            elif ti.static(split_by_batch):
                copies = 0
                for e in range(con.vertex_contact_start[v], con.vertex_contact_start[v + 1]):
                    if con.vertex_contact_list[e] % BATCHES == c % BATCHES:
                        copies += 1
            dh += copies * h * h * con.vertex_delassus_inv_weight[v]
    return dh


@ti.kernel
def relinearize_contacts(x: ti.template(), x0: ti.template(), radius: ti.template(), cs: ti.template(),
                         con: ti.template(), split_by_batch: ti.template(), frictionless_hair: ti.template()):
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
            con.contact_kinematic[c] = -(radius[a] + radius[b]) * nrm - (d0 - d0.dot(nrm) * nrm)
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


@ti.func
def _batch_order_after(c: ti.i32, d: ti.i32) -> bool:
    """Does contact c come after d in a vertex's list (ordered by batch c % BATCHES, then index)?"""
    return c % BATCHES > d % BATCHES or (c % BATCHES == d % BATCHES and c > d)


@ti.kernel
def build_adjacency(vertex: ti.template(), con: ti.template(), vertex_weight_base: ti.template(),
                    vertex_typical_length: ti.template(), vertex_dt_bend: ti.template(), dt: float,
                    gravity_norm: float, dynamic: ti.template(), first_new: ti.i32, split_by_batch: ti.template()):
    """CSR vertex -> contacts (sorted), W_z (Sec. 4.5 "Collision constraint weights"), D_hat.

    Contacts from ``first_new`` on start from zero; with ``first_new`` = 0 (the proximity detection at the
    beginning of a step) the collision duals lambda_z are zeroed too.  Contacts appended later in the step
    (continuous-time detection) keep the earlier contacts' progress: their accumulated corrections
    r~ = D_hat r are rescaled to the new D_hat (more contacts on a vertex split its mass further), so the
    impulses r they stand for are unchanged, and lambda_z is kept.
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
    for c in range(nc):
        for k in ti.static(range(4)):
            v = con.contact_vertex[c][k]
            if v >= 0:
                slot = ti.atomic_add(con.vertex_contact_count[v], 1)
                con.vertex_contact_list[con.vertex_contact_start[v] + slot] = c
    # Sort each vertex's list by batch, then contact index (insertion sort; the atomics above fill in any
    # order), and record where each batch begins: a batch's corrections then read only its own entries.
    for i in con.vertex_contact_count:
        beg = con.vertex_contact_start[i]
        end = con.vertex_contact_start[i + 1]
        for j in range(beg + 1, end):
            key = con.vertex_contact_list[j]
            k = j - 1
            while k >= beg and _batch_order_after(con.vertex_contact_list[k], key):
                con.vertex_contact_list[k + 1] = con.vertex_contact_list[k]
                k -= 1
            con.vertex_contact_list[k + 1] = key
        e = beg
        for b in ti.static(range(BATCHES)):
            while e < end and con.vertex_contact_list[e] % BATCHES < b:
                e += 1
            con.vertex_batch_start[i, b] = e
        # W_z,i = m_i / dt~^2 with dt~ = min(dt, sqrt(L~/|g|), 2 L~^2/R sqrt(rho/E_b)) (Sec. 4.5).
        # Kinematic (clamped) vertices do not move (1/W_z = 0) but still count in D_hat with the weight a
        # free vertex would have: see ``_delassus``.
        inv_w = 0.0
        if con.vertex_contact_count[i] > 0:
            dtt = vertex_dt_bend[i]
            if gravity_norm > 0.0:
                dtt = ti.min(dtt, ti.sqrt(vertex_typical_length[i] / gravity_norm))
            if ti.static(dynamic):
                dtt = ti.min(dtt, dt)
            inv_w = dtt * dtt / vertex_weight_base[i]
        con.vertex_delassus_inv_weight[i] = inv_w
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


#: Edge-length passes that end the length-holding correction (``ContactPipeline.correct``), before each
#: depth check.  8, not 4: measured (24 frames of assets/scenes/head_turn.toml) strain p99 / max 0.042 / 0.29 %
#: with 4 and 0.026 / 0.19 % with 8; the hairball (300 strands, 12 frames) 0.18 / 0.79 % and 0.13 / 0.66 %,
#: its hair-pair penetration p99 (worst frame) 36 and 32 um.
_FINAL_EDGE_PASSES = 8
#: Plain sweeps after each (re)start of the correction before the Chebyshev acceleration begins (Wang 2015's S).
_CHEBYSHEV_DELAY = 3


# --------------------------------------------------------------------------- host orchestration
class ContactPipeline:
    """Detection, projection and correction for one Model (all fields allocated here, once).

    Used by :class:`~taichi_hair.solver_admm.SolverADMM`; the buffers grow (with
    a warning that gives the count) only when a detection overflows them.

    Args:
        model: the Model.
        config: :class:`~taichi_hair.config.ContactConfig`.
        colliders: a :class:`~taichi_hair.contact.colliders.ColliderSet` or ``None``.
    """

    def __init__(self, model, config, colliders=None):
        from .colliders import ColliderSet
        from ..fields import BoxGridFields, CCDFields, ContactFields, GridFields, StrandBoxFields

        self.model = model
        self.config = config
        self.colliders = colliders if colliders is not None else ColliderSet([], model.body_count)
        n = model.vertex_count
        #: Contact radius of each vertex/edge (its strand's radius) [m], shape (vertex_count,).
        self.vertex_radius = ti.field(float, n)
        #: m_i, for W_z = m_i / dt~^2 [kg], shape (vertex_count,).
        self.vertex_weight_base = ti.field(float, n)
        #: Typical edge length L~ of the vertex's strand [m], shape (vertex_count,).
        self.vertex_typical_length = ti.field(float, n)
        #: Bending time 2 L~^2/R sqrt(rho/E_b) of the vertex's strand (Sec. 4.5) [s], shape (vertex_count,).
        self.vertex_dt_bend = ti.field(float, n)
        self.set_coefficients()
        table = 1
        while table < 2 * n:
            table *= 2
        self.grid = GridFields(n, config.max_contacts_per_edge)
        #: Multi-insert hash of edge boxes, shared by proximity and continuous detection.
        self.boxes = BoxGridFields(n, table, max(12 * n, 1 << 14))
        capacity = max(16, int(config.capacity_per_vertex * n))
        self.con = ContactFields(capacity, n)
        self.stats_out = ti.field(float, 6)
        #: Edge lengths the geometric correction holds (rest, or before the correction) [m], shape (vertex_count,).
        self.edge_held_length = ti.field(float, n)
        #: Sweeps of the geometric correction in the last step (reported in ``statistics``).
        self.correction_sweeps_last = 0
        #: z_{k-1}, z_k of the correction's Chebyshev acceleration (allocated on first use).
        self._cheb = None
        #: Continuous-time detection buffers (allocated here when ``continuous_detections`` > 0, so a step
        #: allocates nothing; a direct call of ``detect_continuous`` without them allocates them then).
        self.ccd = CCDFields(n) if config.continuous_detections > 0 else None
        self.strand_boxes = StrandBoxFields(model.strand_count)
        #: Whether the last step skipped the hair-hair search (no strands within reach), and how many did.
        self.hair_search_skipped = False
        self.hair_search_skip_count = 0
        self.ccd_skipped = 0
        #: Continuous passes run or skipped, and skipped, since the pipeline was made.
        self.ccd_pass_total = 0
        self.ccd_skip_total = 0
        self.continuous_contacts = 0
        self.capped_queries = 0
        self.grow_events = 0
        self.detections = 0

    def set_coefficients(self) -> None:
        """(Re)compute the per-vertex contact coefficients from the Model (after an in-place Model update)."""
        import numpy as np

        from ..model import _np_float

        model = self.model
        h = model.host
        f = _np_float()
        strand = h["vertex_strand"]
        radius = np.array([model.materials[s].radius for s in range(model.strand_count)])[strand]
        density = np.array([model.materials[s].density for s in range(model.strand_count)])[strand]
        e_bend = np.array([model.materials[s].youngs_modulus_bend for s in range(model.strand_count)])[strand]
        # Typical edge length L~ per strand (mean rest edge) for dt~ (Sec. 4.5).
        le = h["edge_rest_length"]
        counts = np.bincount(strand, weights=(le > 0).astype(float), minlength=model.strand_count)
        sums = np.bincount(strand, weights=le, minlength=model.strand_count)
        typical = (sums / np.maximum(counts, 1))[strand]
        self.vertex_radius.from_numpy(radius.astype(f))
        self.vertex_weight_base.from_numpy(np.maximum(h["vertex_mass"], 1e-30).astype(f))
        self.vertex_typical_length.from_numpy(typical.astype(f))
        self.vertex_dt_bend.from_numpy((2.0 * typical**2 / radius * np.sqrt(density / e_bend)).astype(f))
        self.max_radius = float(radius.max())

    @property
    def contact_count(self) -> int:
        return min(int(self.con.contact_count[None]), self.con.capacity)

    def detect(self, state, dt: float, gravity, dynamic: bool) -> int:
        """Proximity detection at the beginning of a step (Algorithm 1, line 1); returns the contact count."""
        import warnings

        import numpy as np

        from ..fields import ContactFields
        from .grid import compute_edge_bounds, find_candidates, proximity_boxes

        m, cfg, g = self.model, self.config, self.grid
        x, v = state.vertex_position, state.vertex_velocity
        compute_edge_bounds(m.edge, x, v, g)
        max_edge = float(g.max_edge_length[None])
        speed = float(g.max_speed[None])
        # Reach of the step (dynamic mode): two edges may approach by their relative displacement,
        # bounded by velocity_margin dt (|v_a - v_b| + spreads) (grid.find_candidates); a vertex may
        # approach a body by velocity_margin (|v| dt + |g| dt^2).  Proximity detection runs once per step.
        gn = float(np.linalg.norm(np.asarray(gravity, float)))
        sweep = cfg.velocity_margin * dt if dynamic else 0.0
        fall = cfg.velocity_margin * gn * dt * dt if dynamic else 0.0
        margin = cfg.margin
        # The velocity part of the reach is capped at one longest edge, so the cells (and the cost of the
        # query) stay about two edges wide; faster relative motion can tunnel within a step in the
        # proximity-only mode, as in the paper's (continuous_detections > 0 catches it).
        # Body contacts keep the full margin (it does not change the grid); hair-hair pairs get it capped.
        body_sweep, body_fall = sweep, fall
        if cfg.continuous_detections > 0:
            # Continuous-time detection catches the pairs that close during the step: hair-hair
            # proximity needs no velocity reach (bodies keep it: they have no continuous test).
            sweep, fall = 0.0, 0.0
        motion = sweep * 2.0 * speed + fall
        if motion > max_edge > 0.0:
            sweep *= max_edge / motion
            fall *= max_edge / motion
            motion = max_edge
        self.hair_search_skipped = False
        if cfg.hair_hair:
            proximity_boxes(m.edge, x, self.vertex_radius, g, self.boxes, margin, sweep, fall)
            if cfg.skip_when_apart and self._strands_apart(x, margin, sweep, fall):
                # No two strands within reach and none can touch itself: nothing to search (grid.strands_apart).
                g.edge_candidate_count.fill(0)
                self.hair_search_skipped = True
                self.hair_search_skip_count += 1
            else:
                h = self._fill_box_grid(max(max_edge, 1e-9))
                find_candidates(m.vertex, m.edge, x, self.vertex_radius, g, self.boxes, h, margin, sweep, fall)
        else:
            g.edge_candidate_count.fill(0)
        sweep, fall = body_sweep, body_fall
        while True:
            count_contacts(m.vertex, x, v, self.vertex_radius, g, self.colliders, margin, sweep, fall)
            write_contacts(m.vertex, m.strand, x, v, self.vertex_radius, g, self.colliders, self.con, cfg.friction, margin,
                           sweep, fall)
            total = int(self.con.contact_count[None])
            if total <= self.con.capacity:
                break
            new_cap = max(2 * self.con.capacity, int(1.25 * total))
            warnings.warn(f"contact buffer overflow: {total} contacts for a capacity of {self.con.capacity}; "
                          f"growing it to {new_cap} and detecting again (no contact dropped)", stacklevel=3)
            self.con = ContactFields(new_cap, m.vertex_count)
            self.grow_events += 1
        build_adjacency(m.vertex, self.con, self.vertex_weight_base, self.vertex_typical_length, self.vertex_dt_bend,
                        dt, gn, dynamic, 0, cfg.mass_splitting == "batch")
        self.detections += 1
        # Per-step statistics of the continuous passes of this step.
        self.continuous_contacts = 0
        self.capped_queries = 0
        self.ccd_skipped = 0
        self._dt, self._gn, self._dynamic = dt, gn, dynamic
        return total

    def detect_continuous(self, x0, x) -> int:
        """Continuous-time detection from x0 (begin of step) to x (current iterate); appends the new
        impacts as contacts (module :mod:`taichi_hair.contact.ccd`) and returns how many it added."""
        from .ccd import count_impact_contacts, find_impacts, swept_boxes, write_impact_contacts
        from ..fields import CCDFields

        m, cfg = self.model, self.config
        if not cfg.hair_hair:
            return 0
        if self.ccd is None:
            self.ccd = CCDFields(m.vertex_count)
        ccd = self.ccd
        swept_boxes(m.edge, x0, x, self.vertex_radius, self.boxes, ccd)
        # Two edges outside each other's proximity reach approach by at most twice the largest
        # displacement: when that is within the proximity margin no impact is possible (skip the pass).
        self.ccd_pass_total += 1
        if cfg.skip_slow_continuous and 2.0 * float(ccd.max_displacement[None]) <= cfg.margin:
            self.ccd_skipped += 1
            self.ccd_skip_total += 1
            return 0
        # Cells of the longest edge (the paper's size), widened for very fast motion so no swept box spans
        # more than ~5 cells per axis.
        h = self._fill_box_grid(max(float(ccd.max_edge_length[None]), 0.25 * float(ccd.max_box_side[None]), 1e-9))
        find_impacts(m.vertex, m.edge, x0, x, self.vertex_radius, self.boxes, ccd, self.con, h)
        self.capped_queries += int(ccd.capped_queries[None])
        count_impact_contacts(ccd, self.con)
        first = min(int(self.con.contact_count[None]), self.con.capacity)
        while True:
            write_impact_contacts(x0, x, self.vertex_radius, ccd, self.con, first, cfg.friction)
            total = int(self.con.contact_count[None])
            if total <= self.con.capacity:
                break
            self._grow_contacts(total, keep=first)
        added = total - first
        if added > 0:
            build_adjacency(m.vertex, self.con, self.vertex_weight_base, self.vertex_typical_length, self.vertex_dt_bend,
                            self._dt, self._gn, self._dynamic, first, cfg.mass_splitting == "batch")
        self.continuous_contacts += added
        return added

    def _strands_apart(self, x, margin: float, sweep: float, fall: float) -> bool:
        """Strand-level broad phase on the edge boxes just computed (``grid.strands_apart``)."""
        from .grid import strands_apart
        from .grid import strand_boxes

        sb = self.strand_boxes
        strand_boxes(self.model.strand, self.model.edge, x, self.vertex_radius, self.grid, self.boxes, sb, margin, sweep, fall)
        return strands_apart(sb.strand_box_lo.to_numpy(), sb.strand_box_hi.to_numpy(),
                             sb.strand_self_clear.to_numpy())

    def _fill_box_grid(self, h: float) -> float:
        """Enter every edge box (already in ``self.boxes``) in the cells of size h [m] it overlaps; grow the
        entry buffer (reported) when it is too small.  Returns h as the kernels see it."""
        import warnings

        from ..fields import BoxGridFields
        from .grid import count_cells, fill_entries

        m, bx = self.model, self.boxes
        count_cells(m.edge, bx, h)
        entries = int(bx.edge_entry_start[m.vertex_count])
        if entries > bx.entry_capacity:
            new_cap = max(2 * bx.entry_capacity, int(1.25 * entries))
            warnings.warn(f"collision grid: {entries} cell entries for a capacity of {bx.entry_capacity}; "
                          f"growing it to {new_cap}", stacklevel=4)
            new = BoxGridFields(m.vertex_count, bx.table_size, new_cap)
            new.edge_box_lo.copy_from(bx.edge_box_lo)
            new.edge_box_hi.copy_from(bx.edge_box_hi)
            self.boxes = bx = new
            count_cells(m.edge, bx, h)
            self.grow_events += 1
        fill_entries(bx)
        return h

    def _grow_contacts(self, needed: int, keep: int) -> None:
        """Grow the contact buffers mid-step, keeping the first ``keep`` contacts and the duals."""
        import warnings

        from ..fields import ContactFields

        old = self.con
        new_cap = max(2 * old.capacity, int(1.25 * needed))
        warnings.warn(f"contact buffer overflow: {needed} contacts for a capacity of {old.capacity}; "
                      f"growing it to {new_cap} (no contact dropped)", stacklevel=4)
        new = ContactFields(new_cap, self.model.vertex_count)
        for name in ("contact_vertex", "contact_weight", "contact_normal", "contact_kinematic", "contact_friction",
                     "contact_delassus", "contact_accumulated", "contact_delta", "contact_collider",
                     "contact_status"):
            a = getattr(new, name).to_numpy()
            a[:keep] = getattr(old, name).to_numpy()[:keep]
            getattr(new, name).from_numpy(a)
        new.vertex_contact_dual.copy_from(old.vertex_contact_dual)
        new.contact_count[None] = keep
        self.con = new
        self.grow_events += 1

    def project(self, x, buf, sweeps: int) -> None:
        """The z-step and lambda_z update of one ADMM iteration (Sec. 4.5), then W_z for the global step."""
        from .projection import projection_begin, projection_end, projection_sweep

        projection_begin(x, self.con, False)
        for _ in range(sweeps):
            projection_sweep(self.con)
        projection_end(x, self.con, buf)

    def correct(self, x, x0, sweeps: int) -> None:
        """Geometric contact correction at the end of the step (Alg. 1, last line): project x itself.

        Contacts are re-linearised at x first unless ``ContactConfig.relinearize_correction`` is off
        (x0: x^t), then again at the corrected positions every ``correction_relinearize_every`` sweeps
        (each time the correction restarts from them with fresh corrections), with the correction's own
        Delassus diagonal (``correction_mass_splitting``) and, unless ``correction_hair_friction``,
        frictionless hair-hair contacts.  Unless ``ContactConfig.correction_lengths`` is ``"free"`` (the
        paper's correction, which moves the contact vertices alone) each sweep also projects every edge back
        to its rest length (``"rest"``, default) or to its length before the correction (``"before"``)
        (``projection.correction_sweep``), and edge passes end it.  Sweeps are Chebyshev-accelerated
        (``correction_chebyshev_rho``).  After ``sweeps`` sweeps the correction goes on, 5 at a time, while
        a contact is deeper than ``correction_tolerance``, up to ``correction_max_iterations`` in all; the
        depth is checked after the final edge passes, on what the correction would return.

        Why (issue 12, ``benchmarks/probes/penetration.py``, hairball 300 strands, frame 10): with one
        linearisation, batch mass splitting and friction the correction stalled at tip clumps of 17-20
        contacts per vertex (p99 penetration 74 um after its 40 sweeps, 54 um after 320); re-linearising
        every 10 sweeps, no mass splitting and frictionless hair pairs gave 54 / 29 um after 40 / 80
        sweeps, and with the acceleration 20 / 3 um (from another run's frame 10: 88 / 55 um without it).
        """
        from .projection import (chebyshev_step, contact_statistics, correction_end, correction_sweep,
                                 hold_lengths_sweep, projection_begin, projection_sweep, store_edge_lengths)

        m = self.model
        cfg = self.config
        hold = cfg.correction_lengths != "free"
        split = {"batch": True, "vertex": False, "none": SPLIT_NONE}[cfg.correction_mass_splitting]
        frictionless = not cfg.correction_hair_friction
        every = cfg.correction_relinearize_every if cfg.relinearize_correction else 0
        if cfg.relinearize_correction:
            # (Without it the correction keeps the detection's D_hat and friction coefficients.)
            relinearize_contacts(x, x0, self.vertex_radius, self.colliders, self.con, split, frictionless)
        if hold:
            store_edge_lengths(m.edge, x, self.edge_held_length, cfg.correction_lengths == "rest")
        projection_begin(x, self.con, True)
        tol = cfg.correction_tolerance if cfg.correction_tolerance > 0 else self.max_radius
        cap = max(sweeps, cfg.correction_max_iterations)
        rho = cfg.correction_chebyshev_rho
        if rho > 0 and self._cheb is None:
            self._cheb = (ti.Vector.field(3, float, m.vertex_count), ti.Vector.field(3, float, m.vertex_count))
        done = 0
        since = 0  # sweeps since the last (re)start
        omega = 1.0
        target = sweeps
        while target > 0:
            if hold:
                correction_sweep(m.vertex, m.edge, self.con, self.edge_held_length)
            else:
                projection_sweep(self.con)
            done += 1
            since += 1
            if rho > 0:
                if since < _CHEBYSHEV_DELAY:
                    chebyshev_step(m.vertex, self.con, self._cheb[0], self._cheb[1], 1.0, True)
                else:
                    omega = 2.0 / (2.0 - rho * rho) if since == _CHEBYSHEV_DELAY else 4.0 / (4.0 - rho * rho * omega)
                    chebyshev_step(m.vertex, self.con, self._cheb[0], self._cheb[1], omega, False)
            if done == target:
                if hold:
                    # Edge passes alone: each Gauss-Seidel sweep leaves the colour projected first off by a
                    # fraction of the last contact push (a 0.4 mm push measured 0.18 % after one pass).  They
                    # run before the depth check, so the check sees what the correction would return (they
                    # re-open contacts: p99 12 -> 36 um, measured on the hairball, when they ran after it).
                    for _ in range(_FINAL_EDGE_PASSES):
                        hold_lengths_sweep(m.vertex, m.edge, self.con, self.edge_held_length)
                if done >= cap:
                    break
                # Past the fixed sweeps, go on in groups of 5 while a contact is deeper than the tolerance.
                contact_statistics(self.con.vertex_z, self.vertex_radius, self.colliders, self.con,
                                   self.stats_out, False)
                o = self.stats_out.to_numpy()
                if max(o[3], o[4]) <= tol:
                    break
                target = min(target + 5, cap)
            if every > 0 and done % every == 0:
                # Re-linearise at the corrected positions and restart from them (fresh corrections r~ = 0):
                # the closest points and normals of deep pairs move by more than their penetration.
                correction_end(m.vertex, x, self.con)
                relinearize_contacts(x, x0, self.vertex_radius, self.colliders, self.con, split, frictionless)
                projection_begin(x, self.con, True)
                since = 0
        self.correction_sweeps_last = done
        correction_end(m.vertex, x, self.con)

    def clear(self, buf) -> None:
        from .projection import clear_contact_terms

        clear_contact_terms(self.con, buf)

    def count_status(self, x) -> None:
        """Record the sticking/sliding/separating counts of the last ADMM projection (before correction)."""
        from .projection import contact_statistics

        contact_statistics(x, self.vertex_radius, self.colliders, self.con, self.stats_out, True)

    def statistics(self, x) -> dict:
        """Contact count, sticking/sliding/separating counts (last ADMM projection), penetrations [m].

        ``max_penetration_m`` is the deepest of all; ``hair_penetration_max_m`` / ``_p99_m`` and
        ``crossed_pairs`` are over the hair-hair contacts of the step (pairs within reach at its beginning),
        a crossed pair counting as more than r_a + r_b deep (``projection.contact_statistics``);
        ``body_penetration_max_m`` is against the solver's collider distance (a mesh's voxel SDF).
        """
        import numpy as np

        from .projection import contact_statistics

        con = self.con
        contact_statistics(x, self.vertex_radius, self.colliders, con, self.stats_out, False)
        o = self.stats_out.to_numpy()
        nc = self.contact_count
        p99 = 0.0
        if self.config.hair_hair and nc > 0:
            pen = con.contact_penetration.to_numpy()[:nc]
            hair = con.contact_collider.to_numpy()[:nc] < 0
            if hair.any():
                p99 = float(np.percentile(pen[hair], 99))
        return {"contacts": nc, "sticking": int(o[0]), "sliding": int(o[1]),
                "separating": int(o[2]), "max_penetration_m": max(float(o[3]), float(o[4]), 0.0),
                "body_penetration_max_m": max(float(o[3]), 0.0), "hair_penetration_max_m": max(float(o[4]), 0.0),
                "hair_penetration_p99_m": p99, "crossed_pairs": int(o[5]),
                "correction_sweeps": self.correction_sweeps_last,
                "continuous_contacts": self.continuous_contacts, "accd_capped": self.capped_queries,
                "continuous_passes_skipped": self.ccd_skipped, "hair_search_skipped": self.hair_search_skipped}
