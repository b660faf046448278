"""ADMM stage kernels of Algorithm 1 (Daviet 2023); the contact stages live in contact/pipeline.py and contact/projection.py.

Each kernel is one stage; ``solver_admm.SolverADMM.step`` sequences them
(the "stage" schedule).  The per-index body of each stage is a ``ti.func``
(``*_at``) so that ``schedule_strand`` can run the same arithmetic strand by
strand inside one kernel (the "strand" schedule).

Bit-identity of the two schedules: under Taichi's fast math, LLVM fuses a
multiply and an add into one FMA only where the product has a single use, so
the rounding of an expression can depend on what the compiler managed to
share with the surrounding code.  The ``*_at`` functions therefore take the
index and the scalars as *typed* arguments (local copies, the same in both
kernels) rather than passing the enclosing kernel's arguments through: with
pass-through arguments the two schedules differed in the last bits (Korner
twist terms).  ``tests/test_schedules.py`` guards the identity.

Arguments read as dataflow: model groups, state, scalars, outputs.

Units: the incremental problem is written in energy units [J], so the
position system has entries in N/m (mass/dt^2, W_y) and right-hand sides in N;
the twist system has entries in J (per rad^2) and right-hand sides in J.
"""

import taichi as ti

from .strains import pair_kappa, pair_twist_derivatives, stretch_strain, vec6

vec3 = ti.math.vec3


# --------------------------------------------------------------------------- begin / end of step
@ti.kernel
def begin_step(
    dynamic: ti.template(),
    bdf2: ti.template(),
    vertex: ti.template(),
    edge: ti.template(),
    body_rotation: ti.template(),
    body_translation: ti.template(),
    strand: ti.template(),
    vs: ti.template(),
    es: ti.template(),
    buf: ti.template(),
    h: float,
):
    """Store x^t, v^t, theta^t, omega^t and the step's origins; advect the initial guess (Algorithm 1,
    line 2) to the inertial predictor x_pred = x_hat + h v_hat; move roots.

    Backward Euler (``bdf2`` False, h = dt): x_hat = x_n, v_hat = v_n.  BDF2 (h = 2 dt / 3):
    x_hat = (4 x_n - x_{n-1}) / 3 and v_hat = (4 v_n - v_{n-1}) / 3, with x_{n-1}, v_{n-1} read from
    the begin buffers before they are overwritten (they hold the last step's begin state).
    Kinematic vertices go straight to the body transform of the end of the
    step: x = R_b x_body + T_b.
    """
    for i in vs.vertex_position:
        x = vs.vertex_position[i]
        v = vs.vertex_velocity[i]
        th = es.edge_twist[i]
        om = es.edge_angular_velocity[i]
        x_hat, v_hat, th_hat, om_hat = x, v, th, om
        if ti.static(bdf2):
            x_hat = (4.0 * x - buf.vertex_position_begin[i]) / 3.0
            v_hat = (4.0 * v - buf.vertex_velocity_begin[i]) / 3.0
            th_hat = (4.0 * th - buf.edge_twist_begin[i]) / 3.0
            om_hat = (4.0 * om - buf.edge_angular_velocity_begin[i]) / 3.0
        buf.vertex_position_begin[i] = x
        buf.vertex_velocity_begin[i] = v
        buf.vertex_position_origin[i] = x_hat
        buf.vertex_velocity_origin[i] = v_hat
        if vertex.vertex_is_fixed[i] != 0:
            b = strand.strand_body[vertex.vertex_strand[i]]
            vs.vertex_position[i] = body_rotation[b] @ vertex.vertex_body_position[i] + body_translation[b]
        elif ti.static(dynamic):
            vs.vertex_position[i] = x_hat + h * v_hat
        buf.edge_twist_begin[i] = th
        buf.edge_angular_velocity_begin[i] = om
        buf.edge_twist_origin[i] = th_hat
        buf.edge_angular_velocity_origin[i] = om_hat
        if ti.static(dynamic):
            if edge.edge_is_fixed[i] == 0:
                es.edge_twist[i] = th_hat + h * om_hat


@ti.kernel
def bdf2_strain_origin(bdf2: ti.template(), buf: ti.template()):
    """Strain-rate origins of a BDF2 run: kappa_hat = (4 kappa_n - kappa_{n-1}) / 3 (and eps_hat) in
    place of kappa_n in ``pair_kappa_begin``, so that the local step's damping
    c (kappa - kappa_hat) with c = tau / h is tau kappa_dot of BDF2; kappa_n kept for the next step.
    A backward Euler step of a BDF2 run (``bdf2`` False: no history) only keeps kappa_n."""
    for i in buf.pair_kappa_begin:
        k = buf.pair_kappa_begin[i]
        e = buf.edge_strain_begin[i]
        if ti.static(bdf2):
            buf.pair_kappa_begin[i] = (4.0 * k - buf.pair_kappa_previous[i]) / 3.0
            buf.edge_strain_begin[i] = (4.0 * e - buf.edge_strain_previous[i]) / 3.0
        buf.pair_kappa_previous[i] = k
        buf.edge_strain_previous[i] = e


@ti.kernel
def end_step(dynamic: ti.template(), vs: ti.template(), es: ti.template(), buf: ti.template(), h: float):
    """Velocities of the step, v = (x - x_hat)/h, omega = (theta - theta_hat)/h (zero if quasistatic):
    (x - x^t)/dt for backward Euler, (3 x - 4 x_n + x_{n-1}) / (2 dt) for BDF2."""
    for i in vs.vertex_position:
        if ti.static(dynamic):
            vs.vertex_velocity[i] = (vs.vertex_position[i] - buf.vertex_position_origin[i]) / h
            es.edge_angular_velocity[i] = (es.edge_twist[i] - buf.edge_twist_origin[i]) / h
        else:
            vs.vertex_velocity[i] = vec3(0.0)
            es.edge_angular_velocity[i] = 0.0


@ti.kernel
def restore_begin(vs: ti.template(), es: ti.template(), buf: ti.template()):
    """Undo a failed step: copy the begin-of-step state back."""
    for i in vs.vertex_position:
        vs.vertex_position[i] = buf.vertex_position_begin[i]
        vs.vertex_velocity[i] = buf.vertex_velocity_begin[i]
        es.edge_twist[i] = buf.edge_twist_begin[i]
        es.edge_angular_velocity[i] = buf.edge_angular_velocity_begin[i]


# --------------------------------------------------------------------------- strains
@ti.kernel
def compute_strains(
    measure: ti.template(),
    edge: ti.template(),
    pair: ti.template(),
    x: ti.template(),
    theta: ti.template(),
    es: ti.template(),
    out_kappa: ti.template(),
    out_strain: ti.template(),
):
    """kappa_i for every pair and eps_j for every edge at the current configuration."""
    for i in x:
        if pair.pair_is_active[i] != 0:
            a = i - 1
            twist = theta[i] - theta[a] + es.edge_reference_twist[i]
            out_kappa[i] = pair_kappa(
                measure,
                es.edge_material_d1[a], es.edge_material_d2[a], es.edge_tangent[a],
                es.edge_material_d1[i], es.edge_material_d2[i], es.edge_tangent[i],
                twist,
            )
        else:
            out_kappa[i] = vec3(0.0)
        eps = 0.0
        if edge.edge_rest_length[i] > 0.0:
            eps, grad = stretch_strain(measure, x[i + 1] - x[i], edge.edge_rest_length[i])
        out_strain[i] = eps


# --------------------------------------------------------------------------- duals
@ti.kernel
def reset_duals(buf: ti.template()):
    for i in buf.pair_dual:
        buf.pair_dual[i] = vec6(0.0)
        buf.pair_force[i] = vec6(0.0)


# --------------------------------------------------------------------------- weights
@ti.func
def pair_weight(vertex: ti.template(), buf: ti.template(), i: ti.i32, weight_floor: float) -> float:
    """W_y of pair i: the w0 weight, at least ``weight_floor`` m_i (``SolverADMMConfig.inertia_floor`` / h^2
    in the dynamic mode, 0 in the quasistatic one) [N/m].  The local and the global step call this one
    function with the same scalar, so both see the same W_y."""
    return ti.max(buf.pair_admm_weight[i], weight_floor * vertex.vertex_mass[i])


# --------------------------------------------------------------------------- global step (Sec. 4.3)
@ti.func
def assemble_position_at(
    i: ti.i32,
    dynamic: ti.template(),
    vertex: ti.template(),
    edge: ti.template(),
    pair: ti.template(),
    x: ti.template(),
    buf: ti.template(),
    gravity: vec3,
    air_velocity: vec3,
    air_viscosity: float,
    dt: float,
    weight_floor: float,
):
    """Row i of the position system (see :func:`assemble_position_system`).

    Reads ``buf.pair_force`` of pairs i-1, i and i+1: the local step must be done
    on the whole strand first.
    """
    if vertex.vertex_is_fixed[i] != 0:
        buf.tri_lower[i] = 0.0
        buf.tri_diag[i] = 1.0
        buf.tri_upper[i] = 0.0
        buf.tri_rhs3[i] = vec3(0.0)
    else:
        m = vertex.vertex_mass[i]
        diag = 0.0
        f = m * gravity
        if ti.static(dynamic):
            inv_dt = 1.0 / dt
            diag += m * inv_dt * inv_dt
            x_pred = buf.vertex_position_origin[i] + dt * buf.vertex_velocity_origin[i]
            f -= m * inv_dt * inv_dt * (x[i] - x_pred)
            xi = air_viscosity * vertex.vertex_voronoi_length[i]
            diag += xi * inv_dt
            f -= xi * ((x[i] - buf.vertex_position_origin[i]) * inv_dt - air_velocity)
        # Edge (i-1, i): weight from pairs i-1 and i.
        lower = 0.0
        if vertex.vertex_local_index[i] > 0:
            we = (pair_weight(vertex, buf, i - 1, weight_floor) * pair.pair_is_active[i - 1]
                  + pair_weight(vertex, buf, i, weight_floor) * pair.pair_is_active[i])
            diag += we
            if vertex.vertex_is_fixed[i - 1] == 0:
                lower = -we
        upper = 0.0
        if edge.edge_rest_length[i] > 0.0:
            we = (pair_weight(vertex, buf, i, weight_floor) * pair.pair_is_active[i]
                  + pair_weight(vertex, buf, i + 1, weight_floor) * pair.pair_is_active[i + 1])
            diag += we
            if vertex.vertex_is_fixed[i + 1] == 0:
                upper = -we
        # B^T r with r_p = W_y (lambda + y - Bx)_p = (ra_p, rb_p) from the local step:
        # vertex i gets ra_i - rb_i from its own pair, rb_{i-1} and -ra_{i+1}
        # (pair_force is zero on inactive pairs).
        # Distinct names on purpose: Taichi 1.7 miscompiled a local vector reassigned
        # inside branches here (the first "+=" was lost).
        r_own = buf.pair_force[i]
        f += vec3(r_own[0] - r_own[3], r_own[1] - r_own[4], r_own[2] - r_own[5])
        if vertex.vertex_local_index[i] > 0:
            r_prev = buf.pair_force[i - 1]
            f += vec3(r_prev[3], r_prev[4], r_prev[5])
        if edge.edge_rest_length[i] > 0.0:
            r_next = buf.pair_force[i + 1]
            f -= vec3(r_next[0], r_next[1], r_next[2])
        # Collision constraint (Sec. 4.5): W_z on the diagonal, W_z (lambda_z + z - x) in f; zero without contact.
        w_z = buf.vertex_contact_weight[i]
        diag += w_z
        f += w_z * (buf.vertex_contact_target[i] - x[i])
        # Attachment (``SolverADMM.set_attachments``): k (target - x), zero without one (exactly: adding 0 changes no
        # bit, so a solver without attachments steps as before).
        w_a = buf.vertex_attach_weight[i]
        diag += w_a
        f += w_a * (buf.vertex_attach_target[i] - x[i])
        buf.tri_lower[i] = lower
        buf.tri_diag[i] = diag
        buf.tri_upper[i] = upper
        buf.tri_rhs3[i] = f


@ti.kernel
def assemble_position_system(
    dynamic: ti.template(),
    vertex: ti.template(),
    edge: ti.template(),
    pair: ti.template(),
    x: ti.template(),
    buf: ti.template(),
    gravity: vec3,
    air_velocity: vec3,
    air_viscosity: float,
    dt: float,
    weight_floor: float,
):
    """Assemble M_hat dx = f_hat of Eq. (3); the same tridiagonal matrix serves the three axes.

    M = d2E_e/dx2 + W_z + B^T W_y B, f = -dE_e/dx + W_z (lambda_z + z - x) + B^T W_y (lambda_y + y - Bx), plus the
    attachments' k and k (target - x) (``SolverADMM.set_attachments``; not in the paper).
    B^T W_y B is an edge Laplacian whose edge weight is the sum of the weights
    of the (one or two) pairs containing the edge.  Kinematic vertices get an
    identity row and no coupling (the projections Pi_A of Eq. 3).

    Dynamic mode: ``dt`` is the integrator's inertia step h (dt for backward Euler, 2 dt / 3 for
    BDF2), giving the inertia M (x - x_pred) / h^2 and the air drag xi ((x - x_hat) / h - v_air)
    with x_pred, x_hat from :func:`begin_step` (``buf.vertex_*_origin``).
    """
    for i in x:
        assemble_position_at(i, dynamic, vertex, edge, pair, x, buf, gravity, air_velocity, air_viscosity, dt,
                             weight_floor)


@ti.func
def apply_position_update_at(i: ti.i32, vertex: ti.template(), x: ti.template(), buf: ti.template()):
    """x[i] <- x[i] + dx[i] if vertex i is free."""
    if vertex.vertex_is_fixed[i] == 0:
        x[i] += buf.tri_rhs3[i]


@ti.kernel
def apply_position_update(vertex: ti.template(), x: ti.template(), buf: ti.template()):
    """x <- x + dx for free vertices (the solution sits in tri_rhs3)."""
    for i in x:
        apply_position_update_at(i, vertex, x, buf)


# --------------------------------------------------------------------------- twist step
@ti.func
def pair_twist_terms_at(
    i: ti.i32,
    measure: ti.template(),
    vertex: ti.template(),
    pair: ti.template(),
    strand: ti.template(),
    theta: ti.template(),
    es: ti.template(),
    buf: ti.template(),
    damping_scale: float,
):
    """Twist gradient and Hessian of pair i (see :func:`compute_pair_twist_terms`)."""
    if pair.pair_is_active[i] != 0:
        a = i - 1
        m1a, m2a, ta = es.edge_material_d1[a], es.edge_material_d2[a], es.edge_tangent[a]
        m1b, m2b, tb = es.edge_material_d1[i], es.edge_material_d2[i], es.edge_tangent[i]
        twist = theta[i] - theta[a] + es.edge_reference_twist[i]
        kappa = pair_kappa(measure, m1a, m2a, ta, m1b, m2b, tb, twist)
        dk_a, dk_b, d2_aa, d2_bb, d2_ab = pair_twist_derivatives(measure, kappa, m1a, m2a, ta, m1b, m2b, tb)
        c = strand.strand_damping_time[vertex.vertex_strand[i]] * damping_scale
        k = buf.pair_bend_stiffness[i]
        gk = k * ((kappa - buf.pair_rest_kappa[i]) + c * (kappa - buf.pair_kappa_begin[i]))
        h_aa = (1.0 + c) * (k * dk_a).dot(dk_a)
        h_bb = (1.0 + c) * (k * dk_b).dot(dk_b)
        h_ab = (1.0 + c) * (k * dk_a).dot(dk_b)
        e_aa = h_aa + gk.dot(d2_aa)
        e_bb = h_bb + gk.dot(d2_bb)
        e_ab = h_ab + gk.dot(d2_ab)
        exact_psd = e_aa >= 0.0 and e_bb >= 0.0 and e_aa * e_bb - e_ab * e_ab >= 0.0
        buf.pair_twist_hessian[i] = ti.select(exact_psd, vec3(e_aa, e_bb, e_ab), vec3(h_aa, h_bb, h_ab))
        buf.pair_twist_gradient[i] = ti.math.vec2(gk.dot(dk_a), gk.dot(dk_b))


@ti.kernel
def compute_pair_twist_terms(
    measure: ti.template(),
    vertex: ti.template(),
    pair: ti.template(),
    strand: ti.template(),
    theta: ti.template(),
    es: ti.template(),
    buf: ti.template(),
    damping_scale: float,
):
    """Per pair: gradient and Hessian of E_b,i (+ damping) with respect to (theta_{i-1}, theta_i).

    The exact Hessian J^T K J + (K (kappa - rest)) . d2 kappa is used when it is
    positive semi-definite, its Gauss-Newton part otherwise, so the assembled
    system stays SPD far from rest.
    """
    for i in theta:
        pair_twist_terms_at(i, measure, vertex, pair, strand, theta, es, buf, damping_scale)


@ti.func
def assemble_twist_at(
    j: ti.i32,
    dynamic: ti.template(),
    edge: ti.template(),
    pair: ti.template(),
    theta: ti.template(),
    buf: ti.template(),
    dt: float,
):
    """Row j of the twist system (see :func:`assemble_twist_system`).

    Reads the twist terms of pairs j and j+1.
    """
    if edge.edge_is_fixed[j] != 0:
        buf.tri_lower[j] = 0.0
        buf.tri_diag[j] = 1.0
        buf.tri_upper[j] = 0.0
        buf.tri_rhs1[j] = 0.0
    else:
        diag = 0.0
        g = 0.0
        lower = 0.0
        upper = 0.0
        # Distinct names for the two pairs' Hessians (see the Taichi 1.7 note above).
        if pair.pair_is_active[j] != 0:
            h_own = buf.pair_twist_hessian[j]
            diag += h_own[1]
            g += buf.pair_twist_gradient[j][1]
            if edge.edge_is_fixed[j - 1] == 0:
                lower = h_own[2]
        if pair.pair_is_active[j + 1] != 0:
            h_next = buf.pair_twist_hessian[j + 1]
            diag += h_next[0]
            g += buf.pair_twist_gradient[j + 1][0]
            if edge.edge_is_fixed[j + 1] == 0:
                upper = h_next[2]
        if ti.static(dynamic):
            inertia = edge.edge_rotational_inertia[j] / (dt * dt)
            diag += inertia
            pred = buf.edge_twist_origin[j] + dt * buf.edge_angular_velocity_origin[j]
            g += inertia * (theta[j] - pred)
        buf.tri_lower[j] = lower
        buf.tri_diag[j] = diag
        buf.tri_upper[j] = upper
        buf.tri_rhs1[j] = -g


@ti.kernel
def assemble_twist_system(
    dynamic: ti.template(),
    edge: ti.template(),
    pair: ti.template(),
    theta: ti.template(),
    buf: ti.template(),
    dt: float,
):
    """Newton system d2E/dtheta2 dtheta = -dE/dtheta (+ rotational inertia), tridiagonal over edges.

    Edge j is the second edge of pair j and the first edge of pair j+1.
    Kinematic twists (clamped root edge, ghost edge) get identity rows.
    Dynamic mode: ``dt`` is the inertia step h, as in :func:`assemble_position_system`.
    """
    for j in theta:
        assemble_twist_at(j, dynamic, edge, pair, theta, buf, dt)


# --------------------------------------------------------------------------- checks
@ti.kernel
def find_non_finite(vertex: ti.template(), vs: ti.template(), es: ti.template(), out: ti.template()):
    """out[None] <- min over bad vertices of (strand * 4 + field code), or -1 if all finite.

    Field codes: 0 vertex_position, 1 vertex_velocity, 2 edge_twist, 3 edge_angular_velocity.
    """
    out[None] = 2147483647
    for i in vs.vertex_position:
        code = -1
        # NaN fails every comparison, so "not (|.| <= big)" flags NaN, inf and runaway values.
        if not (ti.abs(vs.vertex_position[i]).sum() <= 1e30):
            code = 0
        elif not (ti.abs(vs.vertex_velocity[i]).sum() <= 1e30):
            code = 1
        elif not (ti.abs(es.edge_twist[i]) <= 1e30):
            code = 2
        elif not (ti.abs(es.edge_angular_velocity[i]) <= 1e30):
            code = 3
        if code >= 0:
            ti.atomic_min(out[None], vertex.vertex_strand[i] * 4 + code)
    if out[None] == 2147483647:
        out[None] = -1
