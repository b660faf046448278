"""Lanes of eight strands (``taichi_hair.lanes``): the lane layout, its gathers and scatters, and vector arithmetic on
lanes.  See :mod:`taichi_hair.lanes.schedule` for why and for the iteration itself."""

import numpy as np
import taichi as ti

from ..fields import vec6

LANES = 8
V8 = ti.types.vector(LANES, ti.f32)
I8 = ti.types.vector(LANES, ti.i32)
vec3 = ti.math.vec3


# =========================================================================== lane arithmetic
# A lane vector (three components, each a V8) is a Python list of three V8 values; Taichi unrolls the lists at
# compile time, so every operation below is eight scalar operations side by side, which LLVM emits as vector code.
@ti.func
def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@ti.func
def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


@ti.func
def add(a, b):
    return [a[c] + b[c] for c in ti.static(range(3))]


@ti.func
def sub(a, b):
    return [a[c] - b[c] for c in ti.static(range(3))]


@ti.func
def scale(s, a):
    return [s * a[c] for c in ti.static(range(3))]


@ti.func
def normalized(a):
    inv = 1.0 / ti.sqrt(dot(a, a))
    return [a[c] * inv for c in ti.static(range(3))]


@ti.func
def select3(m, a, b):
    return [ti.select(m, a[c], b[c]) for c in ti.static(range(3))]


@ti.func
def load3(f: ti.template(), r):
    return [f[r, 0], f[r, 1], f[r, 2]]


@ti.func
def store3(f: ti.template(), r, a):
    for c in ti.static(range(3)):
        f[r, c] = a[c]


@ti.func
def matvec(R, a):
    """R (a 3x3 list of V8) times the lane vector a."""
    return [R[r][0] * a[0] + R[r][1] * a[1] + R[r][2] * a[2] for r in ti.static(range(3))]


@ti.func
def matvec_t(R, a):
    """R^T a."""
    return [R[0][r] * a[0] + R[1][r] * a[1] + R[2][r] * a[2] for r in ti.static(range(3))]


@ti.func
def parallel_transport(u, t0, t1):
    """``strains.parallel_transport`` on lanes: Rodrigues' formula, the half turn where a tangent reversed."""
    b = cross(t0, t1)
    c = dot(t0, t1)
    ok = c > -1.0 + 1e-6
    rot = add(add(scale(c, u), cross(b, u)), scale(dot(b, u) / ti.select(ok, 1.0 + c, 1.0), b))
    across = sub(u, scale(dot(u, t0), t0))
    small = ti.sqrt(dot(across, across)) < 1e-12
    alt_x = cross(t0, [V8(1.0), V8(0.0), V8(0.0)])
    alt_y = cross(t0, [V8(0.0), V8(1.0), V8(0.0)])
    alt = select3(ti.abs(t0[0]) < 0.9, alt_x, alt_y)
    axis = normalized(select3(small, alt, across))
    half = sub(scale(2.0 * dot(axis, u), axis), u)
    return select3(ok, rot, half)


@ti.func
def sincos(theta):
    """sin and cos of a V8 in vector code (the frames' twist angles).

    Taichi's CPU backend calls the scalar libm ``sinf`` / ``cosf`` once per lane: 5-6.5 ns per lane for both,
    about a quarter of the lanes' iteration (two material frames per edge).  This is Cephes' ``sinf`` / ``cosf``
    written on lanes: the quadrant q = round(theta / (pi/2)), the remainder r = theta - q pi/2 in float64 (Taichi's
    fast math folds Cody-Waite's three-part pi/2 into one float32 constant, which left 3e-7 absolute error near
    the zeros), and the minimax polynomials of degree 7 (sin) and 8 (cos) on |r| <= pi/4.  Measured against float64 over
    |theta| <= 10 (scratch probe, 2026-12-07): at most 1.5 ulp (libm 0.56 ulp), 1.0-1.1 ns per lane for both.  Accurate
    for |theta| < 2^20 (q exact in float32); the twist angles are a few radians."""
    q = ti.round(theta * 0.6366197723675814)
    r = ti.cast(ti.cast(theta, ti.f64) - ti.cast(q, ti.f64) * ti.f64(1.5707963267948966), ti.f32)
    r2 = r * r
    s = r + r * r2 * (-1.6666654611e-1 + r2 * (8.3321608736e-3 + r2 * -1.9515295891e-4))
    c = 1.0 - 0.5 * r2 + r2 * r2 * (4.166664568298827e-2 + r2 * (-1.388731625493765e-3 + r2 * 2.443315711809948e-5))
    quadrant = ti.cast(q, ti.i32) & 3  # two's complement: -1 -> 3
    sin_t = ti.select(quadrant == 0, s, ti.select(quadrant == 1, c, ti.select(quadrant == 2, -s, -c)))
    cos_t = ti.select(quadrant == 0, c, ti.select(quadrant == 1, -s, ti.select(quadrant == 2, -c, s)))
    return sin_t, cos_t


@ti.func
def material_frame(d1, t, s, c):
    """``strains.material_frame`` on lanes, given s = sin(theta) and c = cos(theta) (:func:`sincos`)."""
    d2 = cross(t, d1)
    return add(scale(c, d1), scale(s, d2)), add(scale(-s, d1), scale(c, d2))


# =========================================================================== the layout
@ti.data_oriented
class LaneLayout:
    """Strands grouped by eight of one vertex count, and the lane rows of :func:`admm_iterations_lanes`.

    Row ``group_row_start[g] + k`` holds local vertex (edge, pair) k of the eight strands of group g, one per lane.
    Fields are allocated once, here (``SolverADMM`` builds it at its construction when the schedule is "lanes").
    """

    def __init__(self, strand_vertex_start: np.ndarray, strand_vertex_count: np.ndarray):
        counts = np.asarray(strand_vertex_count, np.int64)
        starts = np.asarray(strand_vertex_start, np.int64)
        groups = []
        for m in np.unique(counts):
            members = np.flatnonzero(counts == m)  # in index order: neighbouring strands share a group
            for k in range(0, members.size, LANES):
                chunk = members[k:k + LANES]
                real = chunk.size
                chunk = np.concatenate([chunk, np.full(LANES - real, chunk[0])])  # padding: copies of the first
                groups.append((int(m), chunk, real))
        G = len(groups)
        row_start = np.zeros(G + 1, np.int64)
        for g, (m, _, _) in enumerate(groups):
            row_start[g + 1] = row_start[g] + m
        #: Number of groups and of lane rows.
        self.group_count = G
        self.row_count = int(row_start[-1])
        #: Padded lanes (copies whose results are not scattered) [-].
        self.padded_lanes = int(sum(LANES - real for _, _, real in groups))
        R = max(self.row_count, 1)
        G1 = max(G, 1)
        # --- per group
        #: First lane row of each group [-], shape (G + 1,).
        self.group_row_start = ti.field(ti.i32, G1 + 1)
        #: Vertex count of each group's strands [-], shape (G,).
        self.group_vertex_count = ti.field(ti.i32, G1)
        #: Strand of each lane [-], shape (G,) of I8.
        self.group_strand = ti.field(I8, G1)
        #: First vertex of each lane's strand [-], shape (G,) of I8.
        self.group_vertex_start = ti.field(I8, G1)
        #: 1 for the lanes whose results are scattered back, 0 for padding [-], shape (G,) of I8.
        self.group_lane_real = ti.field(I8, G1)
        #: Strand-damping coefficient c = tau * damping_scale of each lane [-], shape (G,) of V8.
        self.group_damping = ti.field(V8, G1)
        #: The lane's body rotation (identity without a body) [-], shape (G, 3, 3) of V8.
        self.group_rotation = ti.field(V8, (G1, 3, 3))
        #: 1 where the lane's strand has a body [-], shape (G,) of I8.
        self.group_has_body = ti.field(I8, G1)
        #: The strand's root director in its body frame [-], shape (G, 3) of V8.
        self.group_root_director = ti.field(V8, (G1, 3))
        # --- per lane row: constants of the launch
        self.lane_vertex_fixed = ti.field(I8, R)          #: vertex_is_fixed [-]
        self.lane_edge_fixed = ti.field(I8, R)            #: edge_is_fixed [-]
        self.lane_pair_active = ti.field(I8, R)           #: pair_is_active [-]
        self.lane_mass = ti.field(V8, R)                  #: vertex_mass [kg]
        self.lane_voronoi = ti.field(V8, R)               #: vertex_voronoi_length [m]
        self.lane_rest_length = ti.field(V8, R)           #: edge_rest_length [m]
        self.lane_inertia = ti.field(V8, R)               #: edge_rotational_inertia [kg m^2]
        self.lane_pair_weight = ti.field(V8, R)           #: W_y of the pair, with its floor [N/m]
        self.lane_bend_stiffness = ti.field(V8, (R, 3))   #: pair_bend_stiffness [J]
        self.lane_rest_kappa = ti.field(V8, (R, 3))       #: pair_rest_kappa [-]
        self.lane_kappa_begin = ti.field(V8, (R, 3))      #: pair_kappa_begin [-]
        self.lane_strain_begin = ti.field(V8, R)          #: edge_strain_begin [-]
        self.lane_stretch_stiffness = ti.field(V8, R)     #: edge_pair_stretch_stiffness [J]
        self.lane_position_origin = ti.field(V8, (R, 3))  #: vertex_position_origin [m]
        self.lane_velocity_origin = ti.field(V8, (R, 3))  #: vertex_velocity_origin [m/s]
        self.lane_twist_origin = ti.field(V8, R)          #: edge_twist_origin [rad]
        self.lane_omega_origin = ti.field(V8, R)          #: edge_angular_velocity_origin [rad/s]
        self.lane_contact_weight = ti.field(V8, R)        #: vertex_contact_weight W_z [N/m]
        self.lane_contact_target = ti.field(V8, (R, 3))   #: vertex_contact_target [m]
        self.lane_attach_weight = ti.field(V8, R)         #: vertex_attach_weight [N/m]
        self.lane_attach_target = ti.field(V8, (R, 3))    #: vertex_attach_target [m]
        # --- per lane row: state and working values
        self.lane_position = ti.field(V8, (R, 3))         #: x [m]
        self.lane_twist = ti.field(V8, R)                 #: theta [rad]
        #: sin and cos of theta, computed where theta changes (``lanes_frames``, the twist step) and read by the frames
        #: of the next iteration [-].
        self.lane_twist_sin = ti.field(V8, R)
        self.lane_twist_cos = ti.field(V8, R)
        self.lane_tangent = ti.field(V8, (R, 3))          #: edge_tangent [-]
        self.lane_reference = ti.field(V8, (R, 3))        #: edge_reference_director [-]
        self.lane_d1 = ti.field(V8, (R, 3))               #: edge_material_d1 [-]
        self.lane_d2 = ti.field(V8, (R, 3))               #: edge_material_d2 [-]
        self.lane_dual = ti.field(V8, (R, 6))             #: pair_dual lambda_y (in its frame Q) [-]
        self.lane_force = ti.field(V8, (R, 6))            #: pair_force W_y (lambda + y - Bx) [N]
        self.lane_lower = ti.field(V8, R)                 #: the twist step's tridiagonal rows [J]
        self.lane_diag = ti.field(V8, R)
        self.lane_upper = ti.field(V8, R)
        self.lane_rhs = ti.field(V8, (R, 3))              #: right-hand sides, then solutions
        #: The positions' tridiagonal matrix, factored once per launch (its entries do not change between the
        #: iterations of a step): the sub-diagonal [N/m], 1 / pivot [m/N] and upper / pivot [-] of each row.
        self.lane_position_lower = ti.field(V8, R)
        self.lane_position_inverse_pivot = ti.field(V8, R)
        self.lane_position_ratio = ti.field(V8, R)
        #: The local step's launch constants (no division left in its iterations): each pair's w / ((1 + c) k) for
        #: its three bending and two stretch terms [-], shape (R, 5), and each edge's 1 / l^2 [1/m^2].
        self.lane_pair_compliance = ti.field(V8, (R, 5))
        self.lane_inverse_rest_length2 = ti.field(V8, R)
        self.lane_twist_hessian = ti.field(V8, (R, 3))    #: pair_twist_hessian (aa, bb, ab) [J]
        self.lane_twist_gradient = ti.field(V8, (R, 2))   #: pair_twist_gradient [J]
        if G:
            self.group_row_start.from_numpy(row_start.astype(np.int32))
            self.group_vertex_count.from_numpy(np.array([m for m, _, _ in groups], np.int32))
            lanes = np.stack([c for _, c, _ in groups])
            self.group_strand.from_numpy(lanes.astype(np.int32))
            self.group_vertex_start.from_numpy(starts[lanes].astype(np.int32))
            real = np.zeros((G, LANES), np.int32)
            for g, (_, _, r) in enumerate(groups):
                real[g, :r] = 1
            self.group_lane_real.from_numpy(real)


# =========================================================================== gather / scatter
@ti.func
def v8(f: ti.template(), idx):
    return V8([f[idx[q]] for q in ti.static(range(LANES))])


@ti.func
def i8(f: ti.template(), idx):
    return I8([f[idx[q]] for q in ti.static(range(LANES))])


@ti.func
def v8c(f: ti.template(), idx, c: ti.template()):
    return V8([f[idx[q]][c] for q in ti.static(range(LANES))])


@ti.func
def gather_constants(L: ti.template(), g, model: ti.template(), body_rotation: ti.template(), buf: ti.template(),
                     damping_scale: float, weight_floor: float):
    """The Model's and the coefficients' values of group g (and its body rotation, damping and weight floor)."""
    strands = L.group_strand[g]
    base = L.group_vertex_start[g]
    L.group_damping[g] = V8([model.strand_damping_time[strands[q]] for q in ti.static(range(LANES))]) * damping_scale
    has = I8(0)
    for q in ti.static(range(LANES)):
        b = model.strand_body[strands[q]]
        R = ti.Matrix.identity(float, 3)
        if b >= 0:
            R = body_rotation[b]
            has[q] = 1
        for r, c in ti.static(ti.ndrange(3, 3)):
            L.group_rotation[g, r, c][q] = R[r, c]
        for c in ti.static(range(3)):
            L.group_root_director[g, c][q] = model.strand_root_director[strands[q]][c]
    L.group_has_body[g] = has
    r0 = L.group_row_start[g]
    for k in range(L.group_vertex_count[g]):
        r = r0 + k
        i = base + k
        L.lane_vertex_fixed[r] = i8(model.vertex_is_fixed, i)
        L.lane_edge_fixed[r] = i8(model.edge_is_fixed, i)
        L.lane_pair_active[r] = i8(model.pair_is_active, i)
        m = v8(model.vertex_mass, i)
        L.lane_mass[r] = m
        L.lane_voronoi[r] = v8(model.vertex_voronoi_length, i)
        L.lane_rest_length[r] = v8(model.edge_rest_length, i)
        L.lane_inertia[r] = v8(model.edge_rotational_inertia, i)
        # pair_weight's formula (admm.pair_weight), on the gathered values.
        L.lane_pair_weight[r] = ti.max(v8(buf.pair_admm_weight, i), weight_floor * m)
        L.lane_stretch_stiffness[r] = v8(buf.edge_pair_stretch_stiffness, i)
        for c in ti.static(range(3)):
            L.lane_bend_stiffness[r, c] = v8c(buf.pair_bend_stiffness, i, c)
            L.lane_rest_kappa[r, c] = v8c(buf.pair_rest_kappa, i, c)


@ti.func
def gather_state(L: ti.template(), g, x: ti.template(), theta: ti.template(), buf: ti.template()):
    """The state of group g at the step's start but its frames (:func:`gather_frames`): positions, twists, the
    step's origins and strains, the attachment springs, and the z-step's weights and targets."""
    base = L.group_vertex_start[g]
    r0 = L.group_row_start[g]
    for k in range(L.group_vertex_count[g]):
        r = r0 + k
        i = base + k
        L.lane_strain_begin[r] = v8(buf.edge_strain_begin, i)
        L.lane_twist_origin[r] = v8(buf.edge_twist_origin, i)
        L.lane_omega_origin[r] = v8(buf.edge_angular_velocity_origin, i)
        L.lane_twist[r] = v8(theta, i)
        for c in ti.static(range(3)):
            L.lane_kappa_begin[r, c] = v8c(buf.pair_kappa_begin, i, c)
            L.lane_position_origin[r, c] = v8c(buf.vertex_position_origin, i, c)
            L.lane_velocity_origin[r, c] = v8c(buf.vertex_velocity_origin, i, c)
            L.lane_position[r, c] = v8c(x, i, c)
        # The attachment springs (set between steps, SolverADMM.set_attachments).
        L.lane_attach_weight[r] = v8(buf.vertex_attach_weight, i)
        for c in ti.static(range(3)):
            L.lane_attach_target[r, c] = v8c(buf.vertex_attach_target, i, c)
    gather_targets(L, g, buf)


@ti.func
def gather_frames(L: ti.template(), g, es: ti.template(), buf: ti.template()):
    """The frames, duals and forces of group g at the step's start."""
    base = L.group_vertex_start[g]
    r0 = L.group_row_start[g]
    for k in range(L.group_vertex_count[g]):
        r = r0 + k
        i = base + k
        for c in ti.static(range(3)):
            L.lane_tangent[r, c] = v8c(es.edge_tangent, i, c)
            L.lane_reference[r, c] = v8c(es.edge_reference_director, i, c)
            L.lane_d1[r, c] = v8c(es.edge_material_d1, i, c)
            L.lane_d2[r, c] = v8c(es.edge_material_d2, i, c)
        for c in ti.static(range(6)):
            L.lane_dual[r, c] = v8c(buf.pair_dual, i, c)
            L.lane_force[r, c] = v8c(buf.pair_force, i, c)


@ti.func
def gather_targets(L: ti.template(), g, buf: ti.template()):
    """The collision weights and targets of group g (the z-step sets them between iterations)."""
    base = L.group_vertex_start[g]
    r0 = L.group_row_start[g]
    for k in range(L.group_vertex_count[g]):
        r = r0 + k
        i = base + k
        L.lane_contact_weight[r] = v8(buf.vertex_contact_weight, i)
        for c in ti.static(range(3)):
            L.lane_contact_target[r, c] = v8c(buf.vertex_contact_target, i, c)


@ti.func
def lane_vec3(f: ti.template(), r, q: ti.template()):
    """Lane q of the vector stored in row r of a (rows, 3) lane field, as a vec3."""
    return vec3(f[r, 0][q], f[r, 1][q], f[r, 2][q])


@ti.func
def scatter_positions(L: ti.template(), g, x: ti.template()):
    """x of group g's real lanes back to the strands' layout (for the z-step between iterations)."""
    real = L.group_lane_real[g]
    r0 = L.group_row_start[g]
    for k in range(L.group_vertex_count[g]):
        r = r0 + k
        for q in ti.static(range(LANES)):
            if real[q] != 0:
                x[L.group_vertex_start[g][q] + k] = lane_vec3(L.lane_position, r, q)


@ti.func
def scatter(L: ti.template(), g, x: ti.template(), theta: ti.template(), es: ti.template(),
            buf: ti.template()):
    real = L.group_lane_real[g]
    r0 = L.group_row_start[g]
    for k in range(L.group_vertex_count[g]):
        r = r0 + k
        for q in ti.static(range(LANES)):
            if real[q] != 0:
                i = L.group_vertex_start[g][q] + k
                x[i] = lane_vec3(L.lane_position, r, q)
                theta[i] = L.lane_twist[r][q]
                es.edge_tangent[i] = lane_vec3(L.lane_tangent, r, q)
                es.edge_reference_director[i] = lane_vec3(L.lane_reference, r, q)
                es.edge_material_d1[i] = lane_vec3(L.lane_d1, r, q)
                es.edge_material_d2[i] = lane_vec3(L.lane_d2, r, q)
                # Built from the lanes alone (a read-modify-write of the six components read 12 values for nothing).
                buf.pair_dual[i] = vec6([L.lane_dual[r, c][q] for c in ti.static(range(6))])
                buf.pair_force[i] = vec6([L.lane_force[r, c][q] for c in ti.static(range(6))])
