"""XPBD Cosserat-rod kernels (Kugelstadt and Schoemer 2016, with XPBD compliance, Macklin et al. 2016/2019).

Unknowns: vertex positions x_i and one unit quaternion q_j per edge (the
material frame (d1, d2, d3) = R(q_j)(e1, e2, e3)).  Quaternions are ``vec4``
stored as (x, y, z, w), the order of :mod:`taichi_hair.rotation` (which holds their algebra).

Constraints (both dimensionless, vector valued, one Lagrange multiplier
vector each, reset at every substep):

* stretch-shear of edge j (Kugelstadt and Schoemer 2016, Eq. 31):
  C_s = (x_{j+1} - x_j) / l_j - d3(q_j).  With d3 along the edge,
  |C_s| = |e|/l - 1 is the stretch strain of the ADMM solver; the two
  transverse components are shear (absent from DER, here as stiff as stretch).
  Gradients: dC/dx_j = -I/l, dC/dx_{j+1} = I/l, and for unit q,
  grad_q C^T v = 2 v q e3 (quaternion products, v pure), so that
  grad_q C W_q grad_q C^T = 4 w_q I exactly (K&S Eq. 37).
* bend-twist of the pair (e_{i-1}, e_i) at interior vertex i (K&S Eq. 32):
  C_b = 2 s Im(conj(q_{i-1}) q_i) - kappa_rest, s = sign(Re(conj(q_{i-1}) q_i))
  (the sign picks the closer of q and -q, K&S Sec. 4.2).  2 Im(conj(q_a) q_b)
  is *exactly* the Korner et al. 2021 strain the ADMM solver uses by
  default (strains.korner_kappa), components in the frame of edge i-1.
  grad_{q_a} C^T v = -2 s q_b v, grad_{q_b} C^T v = 2 s q_a v, so
  grad C W grad C^T = 4 (w_a + w_b) I.

XPBD update of a constraint with compliance alpha (diagonal), alpha~ =
alpha / dt_sub^2 and damping gamma = tau / dt_sub (Macklin et al. 2016,
Eq. 26, with Rayleigh damping beta = tau k, so that alpha~ beta~ / dt = tau / dt):

    dlambda = -(C + alpha~ lambda + gamma (C - C_start)) / ((1 + gamma) grad C W grad C^T + alpha~)

C - C_start approximates grad C (x - x_prev) (C_start: the constraint at the
beginning of the substep).  Compliances are 1 / (E_s A l) per stretch-shear
component and v* / (E K_aa) per bend-twist component, the stiffnesses of
the ADMM solver's energy (Sec. 4.1), so both solvers minimise the same
elastic energy.

Parallelism: stretch-shear constraints of edges with the same local-index
parity share no unknown, nor do bend-twist constraints of pairs with the same
parity (they share only the quaternion of the middle edge of *adjacent* pairs).
So each parity class is solved in parallel with no write conflicts (true
Gauss-Seidel within the class too), and the four classes run one after the
other (Gauss-Seidel across colors).  No atomics: reruns are bitwise identical.
"""

import taichi as ti

from ...frames import wrap_angle
from ...rotation import quat_conjugate, quat_d3, quat_from_frame, quat_from_matrix, quat_mul, quat_pure, quat_rotate
from ...strains import material_frame, signed_angle

vec3 = ti.math.vec3
vec4 = ti.math.vec4


@ti.func
def darboux_strain(qa: vec4, qb: vec4):
    """(2 s Im(conj(qa) qb), s): the Korner bending/twist strain of a pair and the sign s."""
    r = quat_mul(quat_conjugate(qa), qb)
    s = 1.0
    if r[3] < 0.0:
        s = -1.0
    return 2.0 * s * vec3(r[0], r[1], r[2]), s


@ti.func
def stretch_shear_strain(xa: vec3, xb: vec3, q: vec4, rest_length: float) -> vec3:
    """C_s = (xb - xa)/l - d3(q) [-]."""
    return (xb - xa) / rest_length - quat_d3(q)


# --------------------------------------------------------------------------- step set-up
@ti.kernel
def begin_step(
    vertex: ti.template(),
    edge: ti.template(),
    strand: ti.template(),
    body_rotation: ti.template(),
    body_translation: ti.template(),
    vs: ti.template(),
    es: ti.template(),
    buf: ti.template(),
):
    """Save the state (for restore on divergence), targets of kinematic vertices and of the clamped
    root frame, and per-edge quaternions and angular velocities rebuilt from the State's frames.

    The State is the only persistent state: q_j is the material frame (m1, m2, t) of the step's
    start and omega_j = t x (v_{j+1} - v_j)/|e_j| + (d theta_j/dt) t, the DER angular velocity
    (the time-parallel reference frame does not spin about t).
    """
    for i in vs.vertex_position:
        x = vs.vertex_position[i]
        buf.vertex_position_begin[i] = x
        buf.vertex_velocity_begin[i] = vs.vertex_velocity[i]
        buf.edge_twist_begin[i] = es.edge_twist[i]
        buf.edge_angular_velocity_begin[i] = es.edge_angular_velocity[i]
        buf.edge_tangent_begin[i] = es.edge_tangent[i]
        buf.edge_reference_director_begin[i] = es.edge_reference_director[i]
        buf.edge_reference_twist_begin[i] = es.edge_reference_twist[i]
        s = vertex.vertex_strand[i]
        b = strand.strand_body[s]
        buf.vertex_target[i] = x
        if vertex.vertex_is_fixed[i] != 0:
            buf.vertex_target[i] = body_rotation[b] @ vertex.vertex_body_position[i] + body_translation[b]
        if edge.edge_rest_length[i] > 0.0:
            t = es.edge_tangent[i]
            q = quat_from_frame(es.edge_material_d1[i], es.edge_material_d2[i], t)
            buf.edge_quaternion[i] = q
            buf.edge_quaternion_begin[i] = q
            e = vs.vertex_position[i + 1] - x
            omega = t.cross(vs.vertex_velocity[i + 1] - vs.vertex_velocity[i]) / e.norm() \
                + es.edge_angular_velocity[i] * t
            buf.edge_omega[i] = omega
            target = q
            if vertex.vertex_local_index[i] == 0 and b >= 0:
                target = quat_mul(quat_from_matrix(body_rotation[b]), buf.edge_rest_quaternion[i])
                if target.dot(q) < 0.0:
                    target = -target
            buf.edge_quaternion_target[i] = target


@ti.func
def record_constraints_at(i: ti.i32, edge: ti.template(), pair: ti.template(), x: ti.template(), buf: ti.template()):
    """Constraint values at the start of the substep (for gamma (C - C_start)); multipliers reset."""
    l = edge.edge_rest_length[i]
    if l > 0.0:
        buf.edge_constraint_start[i] = stretch_shear_strain(x[i], x[i + 1], buf.edge_quaternion[i], l)
    if pair.pair_is_active[i] != 0:
        k, _ = darboux_strain(buf.edge_quaternion[i - 1], buf.edge_quaternion[i])
        buf.pair_constraint_start[i] = k - buf.pair_rest_darboux[i]
    buf.edge_lambda[i] = vec3(0.0)
    buf.pair_lambda[i] = vec3(0.0)


@ti.func
def predict_vertex_at(i: ti.i32, vertex: ti.template(), vs: ti.template(), buf: ti.template(), gravity: vec3,
                      air_velocity: vec3, air_viscosity: float, dt: float, fraction: float):
    """Kinematic vertex: interpolated toward its end-of-step target; free vertex: v += dt g (and exact
    linear drag), x += dt v."""
    x = vs.vertex_position[i]
    buf.vertex_position_previous[i] = x
    if vertex.vertex_is_fixed[i] != 0:
        vs.vertex_position[i] = buf.vertex_position_begin[i] \
            + fraction * (buf.vertex_target[i] - buf.vertex_position_begin[i])
    else:
        v = vs.vertex_velocity[i] + dt * gravity
        if air_viscosity > 0.0:
            # Exact solution of m dv/dt = xi v_vor (v_air - v) over dt (unconditionally stable).
            rate = air_viscosity * vertex.vertex_voronoi_length[i] / vertex.vertex_mass[i]
            v = air_velocity + (v - air_velocity) * ti.exp(-rate * dt)
        vs.vertex_velocity[i] = v
        vs.vertex_position[i] = x + dt * v


@ti.func
def predict_frame_at(i: ti.i32, edge: ti.template(), x: ti.template(), buf: ti.template(), dt: float,
                     fraction: float):
    """Kinematic root frame: normalised interpolation toward its target.  Free frame: follows its
    edge (the minimal rotation taking d3(q) to the predicted tangent), then turns by the twist rate
    about the tangent.  Frames carry no transverse angular momentum of their own: with it
    (q += dt/2 omega q, Kugelstadt and Schoemer 2016) one iteration per substep was unstable on hair."""
    if edge.edge_rest_length[i] > 0.0:
        q = buf.edge_quaternion[i]
        buf.edge_quaternion_previous[i] = q
        if buf.edge_inverse_inertia[i] == 0.0:
            q0 = buf.edge_quaternion_begin[i]
            q = (q0 + fraction * (buf.edge_quaternion_target[i] - q0)).normalized()
        else:
            a = quat_d3(q)
            t = (x[i + 1] - x[i]).normalized()
            transport = vec4(*a.cross(t), 1.0 + a.dot(t))
            if transport[3] > 1e-6:
                q = quat_mul(transport.normalized(), q)
            half = 0.5 * dt * buf.edge_omega[i].dot(t)
            q = quat_mul(vec4(*(ti.sin(half) * t), ti.cos(half)), q).normalized()
        buf.edge_quaternion[i] = q


@ti.func
def solve_stretch_shear_at(i: ti.i32, edge: ti.template(), x: ti.template(), buf: ti.template(), dt2: float,
                           damping: float):
    """XPBD projection of the stretch-shear constraint of edge i (see the module docstring)."""
    l = edge.edge_rest_length[i]
    wa = buf.vertex_inverse_mass[i]
    wb = buf.vertex_inverse_mass[i + 1]
    wq = buf.edge_inverse_inertia[i]
    q = buf.edge_quaternion[i]
    c = stretch_shear_strain(x[i], x[i + 1], q, l)
    alpha = buf.edge_compliance[i] / dt2
    gamma = damping * buf.edge_damping_time[i]
    lam = buf.edge_lambda[i]
    # The constraint-space matrix is (wa + wb)/l^2 I + 4 wq (I - d3 d3^T) + alpha~ I: the frame cannot
    # take up the stretch component along d3 (a rotation does not change |d3|; K&S's 4 wq I counts it),
    # so the components along and across d3 get their own denominators.
    d3 = quat_d3(q)
    rhs = -(c + alpha * lam + gamma * (c - buf.edge_constraint_start[i]))
    along = rhs.dot(d3) * d3
    wx = (wa + wb) / (l * l)
    dlam = along / ((1.0 + gamma) * wx + alpha) + (rhs - along) / ((1.0 + gamma) * (wx + 4.0 * wq) + alpha)
    buf.edge_lambda[i] = lam + dlam
    x[i] -= (wa / l) * dlam
    x[i + 1] += (wb / l) * dlam
    if wq > 0.0:
        e3 = quat_pure(vec3(0.0, 0.0, 1.0))
        q += (2.0 * wq) * quat_mul(quat_pure(dlam), quat_mul(q, e3))
        buf.edge_quaternion[i] = q.normalized()


@ti.func
def solve_bend_twist_at(i: ti.i32, buf: ti.template(), dt2: float, damping: float):
    """XPBD projection of the bend-twist constraint of the pair at vertex i (edges i-1, i)."""
    qa = buf.edge_quaternion[i - 1]
    qb = buf.edge_quaternion[i]
    wa = buf.edge_inverse_inertia[i - 1]
    wb = buf.edge_inverse_inertia[i]
    k, s = darboux_strain(qa, qb)
    c = k - buf.pair_rest_darboux[i]
    alpha = buf.pair_compliance[i] / dt2
    gamma = damping * buf.pair_damping_time[i]
    lam = buf.pair_lambda[i]
    w = (1.0 + gamma) * 4.0 * (wa + wb)
    dlam = vec3(0.0)
    for a in ti.static(range(3)):
        dlam[a] = -(c[a] + alpha[a] * lam[a] + gamma * (c[a] - buf.pair_constraint_start[i][a])) / (w + alpha[a])
    buf.pair_lambda[i] = lam + dlam
    p = quat_pure(dlam)
    if wa > 0.0:
        buf.edge_quaternion[i - 1] = (qa - (2.0 * s * wa) * quat_mul(qb, p)).normalized()
    if wb > 0.0:
        buf.edge_quaternion[i] = (qb + (2.0 * s * wb) * quat_mul(qa, p)).normalized()


@ti.func
def update_velocity_at(i: ti.i32, edge: ti.template(), vs: ti.template(), buf: ti.template(), dt: float,
                       decay: float):
    """v = (x - x_prev)/dt and omega = 2 Im(q conj(q_prev))/dt (closer sign), times the decay factor."""
    vs.vertex_velocity[i] = decay * (vs.vertex_position[i] - buf.vertex_position_previous[i]) / dt
    if edge.edge_rest_length[i] > 0.0:
        r = quat_mul(buf.edge_quaternion[i], quat_conjugate(buf.edge_quaternion_previous[i]))
        if r[3] < 0.0:
            r = -r
        buf.edge_omega[i] = decay * 2.0 * vec3(r[0], r[1], r[2]) / dt


@ti.func
def sweep_colors(vertex: ti.template(), edge: ti.template(), pair: ti.template(), x: ti.template(),
                 buf: ti.template(), dt2: float, damping: float):
    """One XPBD iteration: four colors in sequence, each a parallel loop without write conflicts.

    Bend-twist first, so that its frame corrections reach the positions through stretch-shear in the
    same iteration (the other order loses them with one iteration per substep: the next prediction
    puts the frames back on their edges).  Each top-level loop is a separate offloaded task: Taichi
    runs them in order with a barrier in between.
    """
    for i in x:  # bend-twist, pairs at even vertices
        if pair.pair_is_active[i] != 0 and vertex.vertex_local_index[i] % 2 == 0:
            solve_bend_twist_at(i, buf, dt2, damping)
    for i in x:  # bend-twist, pairs at odd vertices
        if pair.pair_is_active[i] != 0 and vertex.vertex_local_index[i] % 2 == 1:
            solve_bend_twist_at(i, buf, dt2, damping)
    for i in x:  # stretch-shear, even local edges
        if edge.edge_rest_length[i] > 0.0 and vertex.vertex_local_index[i] % 2 == 0:
            solve_stretch_shear_at(i, edge, x, buf, dt2, damping)
    for i in x:  # stretch-shear, odd local edges
        if edge.edge_rest_length[i] > 0.0 and vertex.vertex_local_index[i] % 2 == 1:
            solve_stretch_shear_at(i, edge, x, buf, dt2, damping)


@ti.kernel
def substep(
    iterations: ti.template(),
    vertex: ti.template(),
    edge: ti.template(),
    pair: ti.template(),
    vs: ti.template(),
    buf: ti.template(),
    gravity: vec3,
    air_velocity: vec3,
    air_viscosity: float,
    dt: float,
    fraction: float,
    damping: float,
    decay: float,
):
    """A whole substep in one launch: predict, ``iterations`` sweeps (unrolled), velocities.

    ``fraction`` is how far kinematic roots have moved toward their end-of-step targets; ``damping``
    is 1/dt (gamma = tau/dt); ``decay`` the velocity factor exp(-c dt).
    """
    for i in vs.vertex_position:
        record_constraints_at(i, edge, pair, vs.vertex_position, buf)
    for i in vs.vertex_position:
        predict_vertex_at(i, vertex, vs, buf, gravity, air_velocity, air_viscosity, dt, fraction)
    for i in vs.vertex_position:
        predict_frame_at(i, edge, vs.vertex_position, buf, dt, fraction)
    for _ in ti.static(range(iterations)):
        sweep_colors(vertex, edge, pair, vs.vertex_position, buf, dt * dt, damping)
    for i in vs.vertex_position:
        update_velocity_at(i, edge, vs, buf, dt, decay)


@ti.kernel
def substeps_strand(
    vertex: ti.template(),
    edge: ti.template(),
    pair: ti.template(),
    strand: ti.template(),
    vs: ti.template(),
    buf: ti.template(),
    gravity: vec3,
    air_velocity: vec3,
    air_viscosity: float,
    dt: float,
    dt2: float,
    substeps: ti.i32,
    iterations: ti.i32,
    damping: float,
    decay: float,
):
    """All substeps of a step in one launch, parallel over strands ("strand" schedule, for CPUs).

    Each strand runs the same per-element functions in the same order as :func:`substep` (strands
    share no unknown, so a strand may run all its substeps before another starts); the colors become
    serial passes over the strand.
    """
    for s in strand.strand_vertex_start:
        a = strand.strand_vertex_start[s]
        c = strand.strand_vertex_count[s]
        for k in range(substeps):
            fraction = ti.cast(k + 1, float) / ti.cast(substeps, float)
            for i in range(a, a + c):
                record_constraints_at(i, edge, pair, vs.vertex_position, buf)
            for i in range(a, a + c):
                predict_vertex_at(i, vertex, vs, buf, gravity, air_velocity, air_viscosity, dt, fraction)
            for i in range(a, a + c):
                predict_frame_at(i, edge, vs.vertex_position, buf, dt, fraction)
            for _ in range(iterations):
                for j in range((c - 1) // 2):  # bend-twist, pairs at even vertices (local 2, 4, ...)
                    i = a + 2 + 2 * j
                    if pair.pair_is_active[i] != 0:
                        solve_bend_twist_at(i, buf, dt2, damping)
                for j in range(c // 2):  # bend-twist, pairs at odd vertices (local 1, 3, ...)
                    i = a + 1 + 2 * j
                    if pair.pair_is_active[i] != 0:
                        solve_bend_twist_at(i, buf, dt2, damping)
                for j in range((c + 1) // 2):  # stretch-shear, even local edges
                    i = a + 2 * j
                    if edge.edge_rest_length[i] > 0.0:
                        solve_stretch_shear_at(i, edge, vs.vertex_position, buf, dt2, damping)
                for j in range(c // 2):  # stretch-shear, odd local edges
                    i = a + 1 + 2 * j
                    if edge.edge_rest_length[i] > 0.0:
                        solve_stretch_shear_at(i, edge, vs.vertex_position, buf, dt2, damping)
            for i in range(a, a + c):
                update_velocity_at(i, edge, vs, buf, dt, decay)


@ti.kernel
def predict(
    vertex: ti.template(),
    edge: ti.template(),
    pair: ti.template(),
    vs: ti.template(),
    buf: ti.template(),
    gravity: vec3,
    air_velocity: vec3,
    air_viscosity: float,
    dt: float,
    fraction: float,
):
    """The prediction of :func:`substep` alone (for many iterations, launched one by one)."""
    for i in vs.vertex_position:
        record_constraints_at(i, edge, pair, vs.vertex_position, buf)
    for i in vs.vertex_position:
        predict_vertex_at(i, vertex, vs, buf, gravity, air_velocity, air_viscosity, dt, fraction)
    for i in vs.vertex_position:
        predict_frame_at(i, edge, vs.vertex_position, buf, dt, fraction)


@ti.kernel
def solve_constraints(vertex: ti.template(), edge: ti.template(), pair: ti.template(), x: ti.template(),
                      buf: ti.template(), dt2: float, damping: float):
    """One XPBD iteration (:func:`sweep_colors`)."""
    sweep_colors(vertex, edge, pair, x, buf, dt2, damping)


@ti.kernel
def update_velocities(edge: ti.template(), vs: ti.template(), buf: ti.template(), dt: float, decay: float):
    for i in vs.vertex_position:
        update_velocity_at(i, edge, vs, buf, dt, decay)


@ti.kernel
def write_twists(edge: ti.template(), es: ti.template(), buf: ti.template()):
    """DER twist from the quaternions, after ``update_reference_frames`` moved tangents and reference
    directors: theta = angle from the reference director to R(q) e1 about t (continuous in time), the
    twist rate omega . t; then the material frames.  Kinematic twists (root, ghost) are kept."""
    for i in es.edge_twist:
        if edge.edge_rest_length[i] > 0.0:
            t = es.edge_tangent[i]
            d1 = es.edge_reference_director[i]
            if edge.edge_is_fixed[i] == 0:
                old = es.edge_twist[i]
                phi = signed_angle(d1, quat_rotate(buf.edge_quaternion[i], vec3(1.0, 0.0, 0.0)), t)
                es.edge_twist[i] = old + wrap_angle(phi - old)
                es.edge_angular_velocity[i] = buf.edge_omega[i].dot(t)
            else:
                es.edge_angular_velocity[i] = 0.0
            m1, m2 = material_frame(d1, t, es.edge_twist[i])
            es.edge_material_d1[i] = m1
            es.edge_material_d2[i] = m2


@ti.kernel
def restore_begin(vs: ti.template(), es: ti.template(), buf: ti.template()):
    """Put back the state saved by ``begin_step`` (after a divergence)."""
    for i in vs.vertex_position:
        vs.vertex_position[i] = buf.vertex_position_begin[i]
        vs.vertex_velocity[i] = buf.vertex_velocity_begin[i]
        es.edge_twist[i] = buf.edge_twist_begin[i]
        es.edge_angular_velocity[i] = buf.edge_angular_velocity_begin[i]
        es.edge_tangent[i] = buf.edge_tangent_begin[i]
        es.edge_reference_director[i] = buf.edge_reference_director_begin[i]
        es.edge_reference_twist[i] = buf.edge_reference_twist_begin[i]
        t = es.edge_tangent[i]
        if t.norm_sqr() > 0.0:
            m1, m2 = material_frame(es.edge_reference_director[i], t, es.edge_twist[i])
            es.edge_material_d1[i] = m1
            es.edge_material_d2[i] = m2
