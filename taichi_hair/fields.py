"""Structure-of-arrays field groups (one Taichi field per quantity).

Layout: all strands live in one flat vertex array; strand ``s`` owns vertices
``strand_vertex_start[s] ... strand_vertex_start[s] + strand_vertex_count[s] - 1``.
Edges and edge pairs reuse the vertex index:

* edge ``i`` joins vertices ``i`` and ``i + 1``; the slot of a strand's last
  vertex is a *ghost edge* whose twist is kinematically fixed (Sec. 4.1 extends
  the twists to m per strand the same way);
* the edge pair ``(e_{i-1}, e_i)`` belongs to vertex ``i`` and exists for
  interior vertices only (0 < local index < m - 1).

So every per-vertex, per-edge and per-pair field has shape ``(vertex_count,)``
and a strand is a contiguous range in all of them.  Groups are split by how
often they change: ``*Info`` groups belong to the Model and are written once at
``finalize()``; ``*StateFields`` change every step; solver scratch lives with
the solver.  Every field is allocated once, never inside ``step()``.
"""

import taichi as ti

vec3 = ti.math.vec3
vec6 = ti.types.vector(6, float)


class VertexInfo:
    """Static per-vertex data.  All fields have shape (vertex_count,)."""

    def __init__(self, n: int):
        #: Lumped mass m_i = rho A v_i [kg].
        self.vertex_mass = ti.field(float, n)
        #: Voronoi length v_i = (e_{i-1} + e_i)/2 at rest (true value, used for mass and drag) [m].
        self.vertex_voronoi_length = ti.field(float, n)
        #: Index of the strand owning the vertex [-].
        self.vertex_strand = ti.field(ti.i32, n)
        #: Index of the vertex inside its strand, 0 at the root [-].
        self.vertex_local_index = ti.field(ti.i32, n)
        #: 1 if the vertex is kinematic (clamped root vertex), else 0 [-].
        self.vertex_is_fixed = ti.field(ti.i32, n)
        #: Position of a kinematic vertex in its body's frame [m] (zero for free vertices).
        self.vertex_body_position = ti.field(vec3, n)
        #: Rest (input) position [m].
        self.vertex_rest_position = ti.field(vec3, n)


class EdgeInfo:
    """Static per-edge data.  Shape (vertex_count,); a strand's last slot is the ghost edge."""

    def __init__(self, n: int):
        #: Rest length e_j [m] (0 on ghost edges).
        self.edge_rest_length = ti.field(float, n)
        #: Full stretch stiffness E_s A e_j (energy 1/2 k eps^2) [N m].
        self.edge_stretch_stiffness = ti.field(float, n)
        #: Rotational inertia rho I e_j about the tangent [kg m].  (I = A R^2 (1+l^2)/2.)
        self.edge_rotational_inertia = ti.field(float, n)
        #: 1 if the twist of the edge is kinematic (clamped root edge or ghost edge) [-].
        self.edge_is_fixed = ti.field(ti.i32, n)
        #: Rest reference director d1 (space-parallel transported along the input shape) [-].
        self.edge_rest_director = ti.field(vec3, n)
        #: Rest twist angle of the material frame about the rest reference frame [rad].
        self.edge_rest_twist = ti.field(float, n)


class PairInfo:
    """Static per-edge-pair (interior vertex) data.  Shape (vertex_count,), zero on strand ends."""

    def __init__(self, n: int):
        #: 1 if vertex i is interior (the pair (e_{i-1}, e_i) exists), else 0 [-].
        self.pair_is_active = ti.field(ti.i32, n)
        #: Diagonal of E_b K (Sec. 4.1): bending about d1, d2 and twisting rigidities [N m^2].
        self.pair_bending_modulus = ti.field(vec3, n)
        #: E_b A R^2 / 4, the scale of the ADMM weights W_y (Sec. 4.4) [N m^2].
        self.pair_bending_rigidity = ti.field(float, n)


class StrandInfo:
    """Static per-strand data.  All fields have shape (strand_count,)."""

    def __init__(self, n: int):
        #: Index of the strand's first (root) vertex [-].
        self.strand_vertex_start = ti.field(ti.i32, n)
        #: Number of vertices m of the strand [-].
        self.strand_vertex_count = ti.field(ti.i32, n)
        #: Body the root is clamped to (index into Control.body_*), -1 if free [-].
        self.strand_body = ti.field(ti.i32, n)
        #: Reference director d1 of the root edge in the body frame [-] (unit).
        self.strand_root_director = ti.field(vec3, n)
        #: Strain-rate damping relaxation time tau [s].
        self.strand_damping_time = ti.field(float, n)


class VertexStateFields:
    """Per-vertex state.  Shape (vertex_count,)."""

    def __init__(self, n: int):
        #: Centerline position x_i [m].
        self.vertex_position = ti.field(vec3, n)
        #: Velocity v_i [m/s].
        self.vertex_velocity = ti.field(vec3, n)


class EdgeStateFields:
    """Per-edge state, frames included.  Shape (vertex_count,); ghost slots stay zero."""

    def __init__(self, n: int):
        #: Twist angle theta_j of the material frame about the reference frame [rad].
        self.edge_twist = ti.field(float, n)
        #: Angular velocity omega_j of the twist [rad/s].
        self.edge_angular_velocity = ti.field(float, n)
        #: Unit tangent t_j of the current edge [-].
        self.edge_tangent = ti.field(vec3, n)
        #: Reference director d1_j, time-parallel transported [-]; d2 = t x d1.
        self.edge_reference_director = ti.field(vec3, n)
        #: Material directors (m1_j, m2_j), the reference frame rotated by theta_j [-].
        self.edge_material_d1 = ti.field(vec3, n)
        self.edge_material_d2 = ti.field(vec3, n)
        #: Reference twist of the pair ending at edge j: signed angle from the space-parallel
        #: transport of d1_{j-1} to d1_j about t_j, kept continuous in time [rad].
        #: Stored at the pair's vertex index j.
        self.edge_reference_twist = ti.field(float, n)


class SolverCoefficients:
    """What SolverADMM derives from the Model (``_set_coefficients``; again after ``refresh_model``).
    Shape (vertex_count,)."""

    def __init__(self, n: int):
        #: Rest strain kappa_bar of each pair for the chosen strain measure [-].
        self.pair_rest_kappa = ti.field(vec3, n)
        #: Diagonal of E_b K / v_i*, v_i* the bending Voronoi length (rescaled at the
        #: strand ends when enabled, Sec. 5.1) [J].
        self.pair_bend_stiffness = ti.field(vec3, n)
        #: ADMM weight W_y,i = w0 E_b A R^2 / (4 v_i*^3) (Sec. 4.4) [N/m].
        self.pair_admm_weight = ti.field(float, n)
        #: Stretch stiffness E_s A e_j seen by one pair, halved when the edge belongs
        #: to two pairs (Sec. 4.4) [N m].
        self.edge_pair_stretch_stiffness = ti.field(float, n)
        #: Zero-length spring of each vertex to a target, set by the caller (``SolverADMM.set_attachments``; the
        #: grooming drag), not by the Model: weight k_i [N/m] (0: none) and target [m]; the position system gets
        #: k_i on its diagonal and k_i (target - x_i) on its right-hand side.
        self.vertex_attach_weight = ti.field(float, n)
        self.vertex_attach_target = ti.field(vec3, n)


class SolverWarmStart:
    """The elasticity duals warm-started from step to step (checkpointed as a group; ``reset_duals``
    clears them).  Shape (vertex_count,)."""

    def __init__(self, n: int):
        #: Scaled dual lambda_y [m], in the root-attachment frame Q^t when enabled.
        self.pair_dual = ti.field(vec6, n)
        #: Force of pair i on the global step, W_y (lambda + y - Bx)_i, world frame [N].
        self.pair_force = ti.field(vec6, n)


class StepHistory:
    """Begin-of-step copies of the State, restored when a step diverges; between two steps they hold
    the last step's, x_{n-1}, v_{n-1}, theta_{n-1}, omega_{n-1}, kappa_{n-1}, eps_{n-1}: the BDF2 history
    (checkpointed as a group with BDF2).  Shape (vertex_count,)."""

    def __init__(self, n: int):
        #: Begin-of-step positions x^t [m] and velocities v^t [m/s].
        self.vertex_position_begin = ti.field(vec3, n)
        self.vertex_velocity_begin = ti.field(vec3, n)
        #: Begin-of-step twists theta^t [rad] and angular velocities omega^t [rad/s].
        self.edge_twist_begin = ti.field(float, n)
        self.edge_angular_velocity_begin = ti.field(float, n)
        #: BDF2 only: the begin-of-step strains of the last step, kappa_{n-1} [-] and eps_{n-1} [-].
        self.pair_kappa_previous = ti.field(vec3, n)
        self.edge_strain_previous = ti.field(float, n)


class StepScratch:
    """Written and read within one step (nothing here survives it).  Shape (vertex_count,)."""

    def __init__(self, n: int):
        #: Origin of the step's velocity, v_{n+1} = (x - x_hat) / h [m], and the velocity of the inertial
        #: predictor x_pred = x_hat + h v_hat [m/s]: x_hat = x^t, v_hat = v^t for backward Euler,
        #: (4 x_n - x_{n-1}) / 3 and (4 v_n - v_{n-1}) / 3 for BDF2 (``admm.begin_step``).
        self.vertex_position_origin = ti.field(vec3, n)
        self.vertex_velocity_origin = ti.field(vec3, n)
        #: The same for the twists: theta_hat [rad] and omega_hat [rad/s].
        self.edge_twist_origin = ti.field(float, n)
        self.edge_angular_velocity_origin = ti.field(float, n)
        #: Origin of the strain rates of strain-rate damping, kappa_dot = (kappa - kappa_hat) / h:
        #: kappa_hat [-] and eps_hat [-] (kappa^t, eps^t for backward Euler; (4 kappa_n - kappa_{n-1}) / 3
        #: for BDF2, ``admm.bdf2_strain_origin``).
        self.pair_kappa_begin = ti.field(vec3, n)
        self.edge_strain_begin = ti.field(float, n)
        #: Per-pair twist Hessian (d2/dtheta_a^2, d2/dtheta_b^2, d2/dtheta_a dtheta_b) [J]
        #: and gradient (d/dtheta_a, d/dtheta_b) [J], assembled into the twist system.
        self.pair_twist_hessian = ti.field(vec3, n)
        self.pair_twist_gradient = ti.field(ti.math.vec2, n)
        #: Tridiagonal systems: lower/diag/upper [N/m or J], right-hand sides.
        self.tri_lower = ti.field(float, n)
        self.tri_diag = ti.field(float, n)
        self.tri_upper = ti.field(float, n)
        #: Right-hand side then solution of the position system (3 axes) [N -> m].
        self.tri_rhs3 = ti.field(vec3, n)
        #: Right-hand side then solution of the twist system [J -> rad].
        self.tri_rhs1 = ti.field(float, n)
        #: Collision weight W_z,i of the current iteration, 0 without contact (Sec. 4.5) [N/m].
        self.vertex_contact_weight = ti.field(float, n)
        #: lambda_z + z, the collision target of the global step: f += W_z (lambda_z + z - x) [m].
        self.vertex_contact_target = ti.field(vec3, n)


class SolverBuffers:
    """SolverADMM's buffers, by lifetime: ``coefficients`` (from the Model), ``warm_start`` (duals carried
    between steps), ``history`` (begin-of-step copies, the BDF2 history) and ``scratch`` (within a step).

    Kernels take the whole object once (``b: ti.template()``, one kernel instance) and read each field
    by name (``b.pair_dual``): every group's fields are also attributes of this object, the same field
    objects.
    """

    GROUPS = ("coefficients", "warm_start", "history", "scratch")

    def __init__(self, n: int):
        self.coefficients = SolverCoefficients(n)
        self.warm_start = SolverWarmStart(n)
        self.history = StepHistory(n)
        self.scratch = StepScratch(n)
        for group in self.GROUPS:
            for name, field in vars(getattr(self, group)).items():
                setattr(self, name, field)

    @staticmethod
    def names(group) -> tuple:
        """The field names of one group, in their declaration order."""
        return tuple(vars(group))


# --------------------------------------------------------------------------- contacts (Sec. 4.5)
#: Contact batches of the hybrid Gauss-Seidel/Jacobi projection: contact c is in batch c % CONTACT_BATCHES
#: (Daviet 2023 Sec. 4.5: 8; :mod:`taichi_hair.contact.projection`).
CONTACT_BATCHES = 8
#: Slabs of strands of the slab-parallel Gauss-Seidel sweep (``contact.slabs``): the contact groups are the slabs'
#: own contacts, those between neighbouring slabs, and the rest, 2 * CONTACT_SLABS groups [-].
CONTACT_SLABS = 8
ivec4 = ti.types.vector(4, ti.i32)
vec4 = ti.types.vector(4, float)
vec9 = ti.types.vector(9, float)


class ContactFields:
    """Contact buffers, sized up front (``capacity`` contacts); overflow is detected and grows them.

    A contact c couples up to four vertices I_c (two per edge for hair-hair,
    one for a body contact) with weights h_{c,i}: the relative position is
    u = sum_i h_{c,i} x_i + u_kin (Sec. 4.5), normal component >= 0 when apart.
    """

    def __init__(self, capacity: int, vertex_count: int):
        self.capacity = capacity
        c, n = capacity, vertex_count
        #: Number of contacts detected at the last detection; may exceed capacity (overflow) [-], shape ().
        self.contact_count = ti.field(ti.i32, ())
        #: Scratch of ``projection.contact_statistics``: its counts (sticking, sliding, separating, -, thinner than
        #: r_a + r_b) summed in a 0-D field, which Taichi reduces per thread (out[k] += 1 on a shared 1-D field was a
        #: contended atomic per contact: 2.3-6.5 against 0.2-0.8 ms over 153k contacts, three runs of a scratch probe).
        #: Slot 3 is unused: crossed pairs, rare, keep their atomic in ``projection._penetrations`` [-], shape ().
        self.contact_tally = ti.Vector.field(5, float, ())
        #: Vertices I_c of each contact, -1 where unused [-], shape (capacity,).
        self.contact_vertex = ti.field(ivec4, c)
        #: Weights h_{c,i} (negative on the second edge of a hair-hair contact) [-], shape (capacity,).
        self.contact_weight = ti.field(vec4, c)
        #: Unit contact normal n_c, pointing from the second side to the first [-], shape (capacity,).
        self.contact_normal = ti.field(vec3, c)
        #: Kinematic term u_kin, so that u = H x + u_kin [m], shape (capacity,).
        self.contact_kinematic = ti.field(vec3, c)
        #: Coulomb friction coefficient mu_c [-], shape (capacity,).
        self.contact_friction = ti.field(float, c)
        #: Contact thickness: the gap is measured past it.  r_a + r_b for a hair pair (less for a pair already
        #: closer at rest, ``ContactConfig.keep_rest_overlaps``), r for a body contact [m], shape (capacity,).
        self.contact_thickness = ti.field(float, c)
        #: Mass-split Delassus diagonal D_hat_c = sum_i n_i h_{c,i}^2 / W_z,i [m/N], shape (capacity,).
        self.contact_delassus = ti.field(float, c)
        #: W_z,i^-1 h_{c,i} / D_hat_c for each of the contact's vertices: how far its correction moves each in the
        #: sweeps one by one, 0 where D_hat_c = 0, the vertex is kinematic or unused (``narrow.store_push``)
        #: [-], shape (capacity,).
        self.contact_push = ti.field(vec4, c)
        #: Accumulated correction r_tilde_c = D_hat_c r_c (Sec. 4.5, footnote 3) [m], shape (capacity,).
        self.contact_accumulated = ti.field(vec3, c)
        #: Correction Delta u_c of the current batch [m], shape (capacity,).
        self.contact_delta = ti.field(vec3, c)
        #: Collider index for a body contact, -1 for hair-hair [-], shape (capacity,).
        self.contact_collider = ti.field(ti.i32, c)
        #: Last local solve: 0 separating, 1 sticking, 2 sliding [-], shape (capacity,).
        self.contact_status = ti.field(ti.i32, c)
        #: ``contact_status`` of the step's last ADMM projection, kept before the end-of-step correction
        #: overwrites it (what the sticking/sliding counts and ``vertex_states`` report) [-], shape (capacity,).
        self.contact_status_admm = ti.field(ti.i32, c)
        #: Penetration at the last statistics: -(signed gap) where the contact's sides overlap, else 0 [m];
        #: a hair pair that crossed has its gap measured along the normal kept on the begin-of-step side,
        #: so a crossing counts as more than r_a + r_b deep, shape (capacity,).
        self.contact_penetration = ti.field(float, c)
        #: Number of contacts n_i touching vertex i [-], shape (vertex_count,).
        self.vertex_contact_count = ti.field(ti.i32, n)
        #: CSR of the contacts of each vertex, sorted by batch (c % CONTACT_BATCHES),
        #: then by contact index: start [-], shape (vertex_count + 1,).
        self.vertex_contact_start = ti.field(ti.i32, n + 1)
        #: CSR entries (contact indices) [-], shape (4 * capacity,).
        self.vertex_contact_list = ti.field(ti.i32, 4 * c)
        #: h_ci / D_hat_c of each CSR entry, 0 where D_hat_c = 0 (``narrow.store_entry_coefficients``): the
        #: factor of the contact's correction in its vertex's update [N/m], shape (4 * capacity,).
        self.vertex_contact_coefficient = ti.field(float, 4 * c)
        #: Where batch b begins in vertex i's CSR list (it ends where batch b + 1 begins, the last batch at
        #: ``vertex_contact_start[i + 1]``) [-], shape (vertex_count, BATCHES).
        self.vertex_batch_start = ti.field(ti.i32, (n, CONTACT_BATCHES))
        #: Where each slab group of the contacts begins (``contact.slabs.group_contacts`` sorts the detection's
        #: contacts by group; contacts appended later in the step join the last group) [-], shape
        #: (2 * CONTACT_SLABS + 1,); the sort's scratch: each contact's group (then a copy of ``contact_collider``),
        #: the index each sorted contact came from [-], shape (capacity,), and copies of ``contact_vertex`` and
        #: ``contact_weight``, shape (capacity,).
        self.contact_group_start = ti.field(ti.i32, 2 * CONTACT_SLABS + 1)
        self.contact_group = ti.field(ti.i32, c)
        self.contact_order = ti.field(ti.i32, c)
        self.contact_vertex_scratch = ti.field(ivec4, c)
        self.contact_weight_scratch = ti.field(vec4, c)
        #: Compact list of the vertices with at least one contact [-], shape (vertex_count,), and its length, shape ().
        self.active_vertex = ti.field(ti.i32, n)
        self.active_vertex_count = ti.field(ti.i32, ())
        #: 1 / W_z,i (0 for kinematic vertices or vertices without contact) [m/N], shape (vertex_count,).
        self.vertex_contact_inv_weight = ti.field(float, n)
        #: Auxiliary positions z of the feasible projection [m], shape (vertex_count,).
        self.vertex_z = ti.field(vec3, n)
        #: Scaled collision dual lambda_z [m], shape (vertex_count,).
        self.vertex_contact_dual = ti.field(vec3, n)


class BoxGridFields:
    """A multi-insert spatial hash of edge boxes (Sec. 4.5 "Collision detection").

    Every real edge is entered in each cell (of size h, cubic) that its box overlaps;
    the (edge, cell) entries are counting-sorted by hash bucket, so an edge finds every
    other edge whose box shares a cell by visiting its own cells only.  Proximity
    detection uses boxes of the edge grown by its reach; continuous detection boxes of
    the edge's swept positions.  ``entry_capacity`` entries are allocated up front and
    grown (reported) when a detection needs more.  Per-edge fields have shape
    (vertex_count,) (indexed by edge).
    """

    def __init__(self, vertex_count: int, table_size: int, entry_capacity: int):
        n, t, cap = vertex_count, table_size, entry_capacity
        self.table_size = t
        self.entry_capacity = cap
        #: Box of each edge: lower and upper corners [m].
        self.edge_box_lo = ti.field(vec3, n)
        self.edge_box_hi = ti.field(vec3, n)
        #: Cell range of each edge's box, inclusive [-]; ghost edges get an empty range.
        self.edge_cell_lo = ti.Vector.field(3, ti.i32, n)
        self.edge_cell_hi = ti.Vector.field(3, ti.i32, n)
        #: Cells per edge, then their exclusive prefix sum; entry n holds the total [-], shape (vertex_count + 1,).
        self.edge_entry_start = ti.field(ti.i32, n + 1)
        #: Entries per bucket, start of each bucket, fill cursor [-], shapes (t,), (t + 1,), (t,).
        self.bucket_count = ti.field(ti.i32, t)
        self.bucket_start = ti.field(ti.i32, t + 1)
        self.bucket_cursor = ti.field(ti.i32, t)
        #: (edge, cell) entries sorted by bucket: the edge [-] and a copy of its box [m] (so that the
        #: query reads the candidates' boxes sequentially), shape (entry_capacity,).
        self.entry_edge = ti.field(ti.i32, cap)
        self.entry_box_lo = ti.field(vec3, cap)
        self.entry_box_hi = ti.field(vec3, cap)


class StrandBoxFields:
    """Strand-level broad phase (``grid.strands_apart``): per-strand boxes, shape (strand_count,)."""

    def __init__(self, strand_count: int, velocity_moments: bool = False):
        s = max(1, strand_count)
        #: Union of the strand's edge detection boxes: lower and upper corners [m] (+/-1e30 if no real edge).
        self.strand_box_lo = ti.field(vec3, s)
        self.strand_box_hi = ti.field(vec3, s)
        #: 1 where no two non-adjacent edges of the strand can be within reach of each other [-].
        self.strand_self_clear = ti.field(ti.i32, s)
        #: Per-strand sums for the hair's rigid velocity fit (``grid.strand_velocity_moments``): n [-], first
        #: vertex [m], sum r [m], sum v [m/s], sum r x v [m^2/s], sum r r^T [m^2], shape (strand_count, 22);
        #: None unless asked for (``ContactConfig.rigid_reach``).
        self.strand_velocity_moments = ti.field(float, (s, 22)) if velocity_moments else None


class GridFields:
    """Proximity broad and narrow phase: per-edge 18-DOPs, velocities and closest candidates.

    Every field of shape (vertex_count,) is indexed by edge.
    """

    def __init__(self, vertex_count: int, candidates_per_edge: int):
        n, k = vertex_count, candidates_per_edge
        self.candidates_per_edge = k
        #: 18-DOP of each edge in 12 floats: centre [m] and half-extents along the 9 DOP axes
        #: (x, y, z, x+-y, x+-z, y+-z, unnormalised) [m].
        self.edge_dop_center = ti.field(vec3, n)
        self.edge_dop_extent = ti.field(vec9, n)
        #: Mean velocity of each edge's two vertices [m/s] and half their difference (spread) [m/s].
        self.edge_velocity = ti.field(vec3, n)
        self.edge_velocity_spread = ti.field(float, n)
        #: The closest colliding edges of each edge, sorted by distance: other edge [-] and distance [m],
        #: shape (vertex_count, candidates_per_edge); and their number, shape (vertex_count,).
        self.edge_candidate = ti.field(ti.i32, (n, k))
        self.edge_candidate_distance = ti.field(float, (n, k))
        self.edge_candidate_count = ti.field(ti.i32, n)
        #: Contacts emitted by each edge, then their exclusive prefix sum [-], shape (vertex_count + 1,).
        self.edge_emit_count = ti.field(ti.i32, n + 1)
        #: Body contacts emitted by each vertex, then their prefix sum [-], shape (vertex_count + 1,).
        self.vertex_body_emit_count = ti.field(ti.i32, n + 1)
        #: Scalars: largest edge length [m], largest edge speed |v_e| + spread [m/s].
        self.max_edge_length = ti.field(float, ())
        self.max_speed = ti.field(float, ())


class PairFields:
    """Hair-hair pairs within reach, each found once (``contact.pairs.find_candidates``), and per edge the pairs it
    is the higher edge of (CSR), which it adds to its closest (``GridFields.edge_candidate``).

    ``capacity`` pairs, allocated once (``ContactConfig.pairs_per_edge`` per vertex): where a step finds more,
    the search runs in rounds, each edge resuming where the full buffer stopped it (``edge_pair_resume``); the
    1,000-strand hairball's pile has ~36 pairs per edge.
    """

    def __init__(self, vertex_count: int, capacity: int, skin: bool = False):
        n = vertex_count
        self.capacity = capacity
        #: With a skin (``ContactConfig.pair_skin``, ``contact.pairs.find_candidates_skin``): whether the stored pairs
        #: hold every pair within reach + skin of the edges' anchors (host), per edge whether it searches this
        #: step [-] and where its two vertices were at its last search [m], shape (vertex_count,) each; the pairs
        #: of each edge, both sides, for ``edge_pair_start`` [-], shape (2 capacity,).
        self.skin_valid = False
        if skin:
            self.edge_moved = ti.field(ti.i32, n)
            self.edge_anchor_start = ti.Vector.field(3, float, n)
            self.edge_anchor_end = ti.Vector.field(3, float, n)
            self.edge_pair_both_list = ti.field(ti.i32, 2 * capacity)
            #: Where the vertices were when ``contact.pairs.lists_from_pairs`` last ran [m], shape (vertex_count,), and
            #: the largest displacement since [m], shape (): each stored pair's ``pair_distance`` is its distance there
            #: or a lower bound of it (a pair found since: of its distance now).
            self.vertex_listed_position = ti.Vector.field(3, float, n)
            self.vertex_max_move = ti.field(float, ())
            #: Whether each stored pair is within reach (r_a + r_b + margin) at the last ``lists_from_pairs`` [-],
            #: shape (capacity,).
            self.pair_within = ti.field(ti.i8, capacity)
        #: The two edges of each pair, lower first [-], shape (capacity, 2); their distance [m], shape (capacity,).
        self.pair_edge = ti.Vector.field(2, ti.i32, capacity)
        self.pair_distance = ti.field(float, capacity)
        #: Pairs the last round appended (may exceed the capacity: those past it wait for the next round) [-].
        self.pair_count = ti.field(ti.i32, ())
        #: Per edge: -1 when all its pairs are stored, else the index (in its search order) of the first pair the
        #: next round stores [-], shape (vertex_count,); the edges still pending after the last round [-].
        self.edge_pair_resume = ti.field(ti.i32, n)
        self.pending_count = ti.field(ti.i32, ())
        #: Per edge: the start in ``edge_pair_list`` of the pairs it is the higher edge of, then the total [-],
        #: shape (vertex_count + 1,); a fill cursor, shape (vertex_count,); pair indices by higher edge, shape
        #: (capacity,).
        self.edge_pair_start = ti.field(ti.i32, n + 1)
        self.edge_pair_fill = ti.field(ti.i32, n)
        self.edge_pair_list = ti.field(ti.i32, capacity)


class WarmFields:
    """The contacts of the last quasistatic step and their impulses, for the next detection's warm start
    (``contact.warm``): contact c's key (its first vertex a, and its second edge's first vertex b for a hair pair,
    -1 for a body contact) [-], impulse r_c = r~_c / D_hat_c [m^2/N], shape (capacity,); the CSR of those
    contacts by a [-], shapes (vertex_count + 1,), (capacity,); how many [-], shape ()."""

    def __init__(self, capacity: int, vertex_count: int):
        self.capacity = capacity
        self.warm_key_a = ti.field(ti.i32, capacity)
        self.warm_key_b = ti.field(ti.i32, capacity)
        self.warm_impulse = ti.field(vec3, capacity)
        self.warm_start = ti.field(ti.i32, vertex_count + 1)
        self.warm_order = ti.field(ti.i32, capacity)
        self.warm_count = ti.field(ti.i32, ())


class CCDFields:
    """Continuous-time detection (Sec. 4.5, ACCD): per-edge earliest impacts.

    Per-edge fields have shape (vertex_count,) (indexed by edge).
    """

    def __init__(self, vertex_count: int, impacts_per_edge: int = 2):
        n, k = vertex_count, impacts_per_edge
        self.impacts_per_edge = k
        #: The earliest impacts of each edge, sorted by (time, other edge): other edge [-] and time of
        #: impact in [0, 1] of the step's motion [-], shape (vertex_count, impacts_per_edge); their number.
        self.edge_impact = ti.field(ti.i32, (n, k))
        self.edge_impact_time = ti.field(float, (n, k))
        self.edge_impact_count = ti.field(ti.i32, n)
        #: Contacts emitted by each edge, then their exclusive prefix sum [-], shape (vertex_count + 1,).
        self.edge_emit_count = ti.field(ti.i32, n + 1)
        #: Largest vertex displacement |x - x^t| [m], largest swept-box side [m], longest current edge [m],
        #: and ACCD loops that hit the iteration cap [-].
        self.max_displacement = ti.field(float, ())
        self.max_box_side = ti.field(float, ())
        self.max_edge_length = ti.field(float, ())
        self.capped_queries = ti.field(ti.i32, ())


# --------------------------------------------------------------------------- host transfers, one kernel per group
# Taichi's ``field.from_numpy`` / ``to_numpy`` / ``copy_from`` / ``fill`` compile one kernel instance per field, and a
# new Model's fields are new instances: each costs Taichi's frontend and a load from the kernel cache (30-60 ms
# warm, more cold; measured 2026-12-07, a 4-strand Model with its State and solver took 50 instances, 38 of them
# such copies).  These do the same for a whole group of fields in one kernel (issue 15, item 5).


def field_numpy_shape(field) -> tuple:
    """The shape ``field.to_numpy()`` has: the field's shape, then (n,) for a vector or (n, m) for a matrix
    field."""
    n, m = getattr(field, "n", None), getattr(field, "m", None)
    tail = () if n is None else (n,) if m == 1 else (n, m)
    return tuple(field.shape) + tail


def upload(pairs) -> None:
    """``field.from_numpy(array)`` for every ``(field, array)`` of ``pairs``: fields of one dimension, scalar, vector or
    matrix elements; each array is cast to its field's type on the host (NumPy's rounding, as ``from_numpy``'s
    kernel does) and its shape checked before anything is written.  One kernel launch per element type."""
    import numpy as np

    groups: dict = {}
    for field, value in pairs:
        shape = _transfer_shape(field)
        a = np.ascontiguousarray(value, dtype=ti.lang.util.to_numpy_type(field.dtype))
        if a.shape != shape:
            raise ValueError(f"upload: an array of shape {a.shape} for a field of shape {shape}")
        groups.setdefault(a.dtype, []).append((field, a))
    for items in groups.values():
        offsets = np.cumsum([0] + [a.size for _, a in items[:-1]])
        _transfer_kernel(tuple(f for f, _ in items), _layout([f for f, _ in items], offsets),
                         np.concatenate([a.ravel() for _, a in items]), False)


def download(fields) -> list:
    """``[field.to_numpy() for field in fields]`` (fields of one dimension) in one kernel launch per element type."""
    import numpy as np

    groups: dict = {}
    for j, field in enumerate(fields):
        groups.setdefault(ti.lang.util.to_numpy_type(field.dtype), []).append(j)
    out = [None] * len(fields)
    for dtype, idx in groups.items():
        shapes = [_transfer_shape(fields[j]) for j in idx]
        offsets = np.cumsum([0] + [int(np.prod(s)) for s in shapes])
        data = np.empty(int(offsets[-1]), dtype)
        _transfer_kernel(tuple(fields[j] for j in idx), _layout([fields[j] for j in idx], offsets), data, True)
        for k, j in enumerate(idx):
            out[j] = data[offsets[k]:offsets[k + 1]].reshape(shapes[k])
    return out


def _transfer_shape(field) -> tuple:
    if len(field.shape) != 1:
        raise ValueError(f"upload / download: fields of one dimension only, not of shape {tuple(field.shape)}")
    return field_numpy_shape(field)


def _layout(fields, offsets) -> tuple:
    """Per field, its offset in the packed array and its element shape (compile-time arguments of the kernel)."""
    return tuple((int(o),) + field_numpy_shape(f)[1:] for f, o in zip(fields, offsets))


@ti.kernel
def _transfer_kernel(fields: ti.template(), layout: ti.template(), data: ti.types.ndarray(), to_host: ti.template()):
    """fields -> data (``to_host``) or data -> fields; field k's element i at ``layout[k][0]`` + its row-major index."""
    for k in ti.static(range(len(fields))):
        for i in range(fields[k].shape[0]):
            if ti.static(len(layout[k]) == 1):
                if ti.static(to_host):
                    data[layout[k][0] + i] = fields[k][i]
                else:
                    fields[k][i] = data[layout[k][0] + i]
            elif ti.static(len(layout[k]) == 2):
                for c in ti.static(range(layout[k][1])):
                    if ti.static(to_host):
                        data[layout[k][0] + i * layout[k][1] + c] = fields[k][i][c]
                    else:
                        fields[k][i][c] = data[layout[k][0] + i * layout[k][1] + c]
            else:
                for r, c in ti.static(ti.ndrange(layout[k][1], layout[k][2])):
                    j = layout[k][0] + (i * layout[k][1] + r) * layout[k][2] + c
                    if ti.static(to_host):
                        data[j] = fields[k][i][r, c]
                    else:
                        fields[k][i][r, c] = data[j]
