"""The "lanes" schedule: the strand schedule's ADMM iterations on lanes of eight strands (CPU SIMD; issue 15, item 1).

Taichi's CPU backend compiles the strand schedule (:mod:`taichi_hair.schedule_strand`) to scalar code: one
strand per thread, its stages' dependency chains (square roots, divisions, sin and cos) leaving the cores'
vector units idle.  Written on ``ti.types.vector(8, f32)`` values, one strand per lane, the same arithmetic
runs on all eight lanes at once (``benchmarks/probes/simd_lanes.py``: 2.1-2.65x on one stage), but only when
the eight strands' values sit side by side in memory; gathered from the strands' own layout at every vertex the
gain is gone (the same probe's ``gather_8``).  So this schedule works on a second layout:

* the strands are grouped by eight of one vertex count (:class:`LaneLayout`; the last group of a count is
  padded with copies of its first strand, whose results are dropped);
* each step, :func:`lanes_gather` copies every group's constants and state into its lane rows (one row per local
  vertex index, each value a vector of the eight strands'), :func:`lanes_frames` moves the frames to the step's
  first iterate, :func:`admm_iterations_lanes` (one parallel loop over groups) runs the iterations on them, and
  :func:`lanes_scatter` copies the state back: the gathers are paid once per step, not per stage.  With contacts
  the iterations run one launch at a time, the z-step between them; each launch takes in only the z-step's
  weights and targets and gives back only x.
* what does not change over the iterations is computed before them: the positions' tridiagonal matrix, factored
  once per launch (:func:`_factor_positions`; the weights, masses and z-step weights are constant there), and the
  local step's divisions by the rest lengths and stiffnesses once per step (:func:`_local_constants`, in
  :func:`lanes_frames`).  sin and cos are a polynomial on lanes (``layout.sincos``: Taichi's own call the scalar
  libm once per lane).

The iteration is Algorithm 1's steps (a)-(g) as in the strand schedule, stage for stage, for the Korner
measure (the default) with the twist solved or the twist-free frames; each function below names the ``*_at``
function whose arithmetic it repeats on lanes.  Branches that differ between strands (a fixed vertex, a body
or none, a reversed tangent) become selects.  Not covered: the Bergou measure (``SolverADMM`` refuses it with this
schedule) and Anderson mixing (steps that mix run the strand kernel).

The results agree with the strand schedule to rounding, not to the bit: the compiler fuses and orders the
vector code's products otherwise (``tests/test_schedule_lanes.py`` states the tolerances).  Deterministic: the
same bits from run to run (each lane's arithmetic does not depend on the others').
"""

import taichi as ti

from ..elasticity import FRAME_PAIR, FRAME_ROOT
from .layout import (V8, cross, dot, gather_constants, gather_frames, gather_state, gather_targets, load3, material_frame, matvec,
                     matvec_t, normalized, parallel_transport, scale, scatter, scatter_positions, select3, sincos, store3, sub)

vec3 = ti.math.vec3

#: ``admm_iterations_lanes``'s launches: the iterations of a step without contacts, or one iteration of a step with
#: contacts (see the kernel).
ITERATIONS = 0
CONTACT_ITERATION = 1


# =========================================================================== the stages on lanes
@ti.func
def _identity3():
    return [[V8(1.0), V8(0.0), V8(0.0)], [V8(0.0), V8(1.0), V8(0.0)], [V8(0.0), V8(0.0), V8(1.0)]]


@ti.func
def _group_rotation(L: ti.template(), g):
    return [[L.group_rotation[g, a, b] for b in ti.static(range(3))] for a in ti.static(range(3))]


@ti.func
def _pair_frame(L: ti.template(), r):
    d1, d2, t = load3(L.lane_d1, r), load3(L.lane_d2, r), load3(L.lane_tangent, r)
    return [[d1[a], d2[a], t[a]] for a in ti.static(range(3))]


@ti.func
def _local_constants(L: ti.template(), g, r, k, m):
    """Row r's (local index k of m) constants of the local step over a step: its edge's 1 / l^2 and, for a pair,
    the diagonal w / ((1 + c) k) of w E^-1 (``strains.proximal_step5``; capped at 1e30 where a stiffness is 0)."""
    L.lane_inverse_rest_length2[r] = 1.0 / (L.lane_rest_length[r] * L.lane_rest_length[r])
    if 0 < k < m - 1:
        w = L.lane_pair_weight[r]
        one_c = 1.0 + L.group_damping[g]
        for c in ti.static(range(3)):
            L.lane_pair_compliance[r, c] = ti.min(w / (one_c * L.lane_bend_stiffness[r, c]), 1e30)
        L.lane_pair_compliance[r, 3] = ti.min(w / (one_c * L.lane_stretch_stiffness[r - 1]), 1e30)
        L.lane_pair_compliance[r, 4] = ti.min(w / (one_c * L.lane_stretch_stiffness[r]), 1e30)


@ti.func
def _local_elasticity(L: ti.template(), use_q: ti.template(), g, r):
    """``elasticity.local_elasticity_at`` of pair row r (Korner measure): one Gauss-Newton step of Eq. (4) by the
    5x5 Woodbury form (``strains.proximal_step5``), the fused dual update and the pair's force."""
    a = r - 1
    xa, xi, xb = load3(L.lane_position, a), load3(L.lane_position, r), load3(L.lane_position, r + 1)
    ea, eb = sub(xi, xa), sub(xb, xi)
    m1a, m2a, ta = load3(L.lane_d1, a), load3(L.lane_d2, a), load3(L.lane_tangent, a)
    m1b, m2b, tb = load3(L.lane_d1, r), load3(L.lane_d2, r), load3(L.lane_tangent, r)
    # Korner strain: the quaternion (w, v) of F_a^T F_b, kappa = 2 v (strains.korner_quaternion).
    w_q = 0.5 * ti.sqrt(ti.max(1.0 + dot(m1a, m1b) + dot(m2a, m2b) + dot(ta, tb), 1e-12))
    inv4w = 1.0 / (4.0 * w_q)
    v = [(dot(ta, m2b) - dot(m2a, tb)) * inv4w, (dot(m1a, tb) - dot(ta, m1b)) * inv4w,
         (dot(m2a, m1b) - dot(m1a, m2b)) * inv4w]
    kappa = [2.0 * v[0], 2.0 * v[1], 2.0 * v[2]]
    # Its edge Jacobian (strains.korner_edge_jacobian): Ja = -(w I - [v]x) Aa, Jb = (w I + [v]x) Ab, with
    # A = [-d2^T; d1^T; 0] / |e|.
    len_a = ti.sqrt(dot(ea, ea))
    len_b = ti.sqrt(dot(eb, eb))
    vx = [[V8(0.0), -v[2], v[1]], [v[2], V8(0.0), -v[0]], [-v[1], v[0], V8(0.0)]]
    Aa = [scale(-1.0 / len_a, m2a), scale(1.0 / len_a, m1a)]
    Ab = [scale(-1.0 / len_b, m2b), scale(1.0 / len_b, m1b)]
    J = [[V8(0.0) for _ in ti.static(range(6))] for _ in ti.static(range(3))]
    for row in ti.static(range(3)):
        for c in ti.static(range(3)):
            # (w I -+ vx)[row, 0:2] @ A[0:2, c] (A's third row is zero)
            e0 = ti.static(1.0 if row == 0 else 0.0)
            e1 = ti.static(1.0 if row == 1 else 0.0)
            ma0 = e0 * w_q - vx[row][0]
            ma1 = e1 * w_q - vx[row][1]
            mb0 = e0 * w_q + vx[row][0]
            mb1 = e1 * w_q + vx[row][1]
            J[row][c] = -(ma0 * Aa[0][c] + ma1 * Aa[1][c])
            J[row][c + 3] = mb0 * Ab[0][c] + mb1 * Ab[1][c]
    c_damp = L.group_damping[g]
    inv_one_c = 1.0 / (1.0 + c_damp)
    # Stretch strains (Korner: eps = (|e|^2 / l^2 - 1) / 2, grad e / l^2; strains.stretch_strain).
    inv_a = L.lane_inverse_rest_length2[a]
    inv_b = L.lane_inverse_rest_length2[r]
    eps_a = 0.5 * (dot(ea, ea) * inv_a - 1.0)
    eps_b = 0.5 * (dot(eb, eb) * inv_b - 1.0)
    ga = scale(inv_a, ea)
    gb = scale(inv_b, eb)
    w = L.lane_pair_weight[r]
    # The frame Q of the dual (elasticity.dual_frame): the root body's rotation, the pair's frame, or none.
    Q = _group_rotation(L, g) if ti.static(use_q == FRAME_ROOT) else (
        _pair_frame(L, r) if ti.static(use_q == FRAME_PAIR) else _identity3())
    lam_q = [L.lane_dual[r, c] for c in ti.static(range(6))]
    la3 = matvec(Q, [lam_q[0], lam_q[1], lam_q[2]])
    lb3 = matvec(Q, [lam_q[3], lam_q[4], lam_q[5]])
    lam = [la3[0], la3[1], la3[2], lb3[0], lb3[1], lb3[2]]
    f = [V8(0.0) for _ in ti.static(range(5))]
    for c in ti.static(range(3)):
        f[c] = ((kappa[c] - L.lane_rest_kappa[r, c]) + c_damp * (kappa[c] - L.lane_kappa_begin[r, c])) * inv_one_c
    f[3] = (eps_a + c_damp * (eps_a - L.lane_strain_begin[a])) * inv_one_c
    f[4] = (eps_b + c_damp * (eps_b - L.lane_strain_begin[r])) * inv_one_c
    # proximal_step5: P = w E^-1 + V^T V (5x5, P[3, 4] = 0), t = V^T lam - f; LDL^T; delta = -lam + V q.
    P = [[V8(0.0) for _ in ti.static(range(5))] for _ in ti.static(range(5))]
    t = [V8(0.0) for _ in ti.static(range(5))]
    for r1 in ti.static(range(3)):
        for s1 in ti.static(range(r1, 3)):
            acc = J[r1][0] * J[s1][0]
            for c in ti.static(range(1, 6)):
                acc += J[r1][c] * J[s1][c]
            P[r1][s1] = acc
            P[s1][r1] = acc
        pa = J[r1][0] * ga[0] + J[r1][1] * ga[1] + J[r1][2] * ga[2]
        pb = J[r1][3] * gb[0] + J[r1][4] * gb[1] + J[r1][5] * gb[2]
        P[r1][3] = pa
        P[3][r1] = pa
        P[r1][4] = pb
        P[4][r1] = pb
        acc = -f[r1]
        for c in ti.static(range(6)):
            acc += J[r1][c] * lam[c]
        t[r1] = acc
    P[3][3] = dot(ga, ga)
    P[4][4] = dot(gb, gb)
    t[3] = ga[0] * lam[0] + ga[1] * lam[1] + ga[2] * lam[2] - f[3]
    t[4] = gb[0] * lam[3] + gb[1] * lam[4] + gb[2] * lam[5] - f[4]
    for d in ti.static(range(5)):
        P[d][d] = P[d][d] + L.lane_pair_compliance[r, d]
    Lm = [[V8(0.0) for _ in ti.static(range(5))] for _ in ti.static(range(5))]
    D = [V8(0.0) for _ in ti.static(range(5))]
    D_inv = [V8(0.0) for _ in ti.static(range(5))]
    for j in ti.static(range(5)):
        s = P[j][j]
        for k in ti.static(range(j)):
            s = s - Lm[j][k] * Lm[j][k] * D[k]
        D[j] = s
        D_inv[j] = 1.0 / s
        for i2 in ti.static(range(j + 1, 5)):
            u = P[i2][j]
            for k in ti.static(range(j)):
                u = u - Lm[i2][k] * Lm[j][k] * D[k]
            Lm[i2][j] = u * D_inv[j]
    y = [V8(0.0) for _ in ti.static(range(5))]
    for i2 in ti.static(range(5)):
        s = t[i2]
        for k in ti.static(range(i2)):
            s = s - Lm[i2][k] * y[k]
        y[i2] = s
    q = [V8(0.0) for _ in ti.static(range(5))]
    for i2 in ti.static(range(4, -1, -1)):
        s = y[i2] * D_inv[i2]
        for k in ti.static(range(i2 + 1, 5)):
            s = s - Lm[k][i2] * q[k]
        q[i2] = s
    delta = [-lam[c] for c in ti.static(range(6))]
    for c in ti.static(range(6)):
        delta[c] = delta[c] + (J[0][c] * q[0] + J[1][c] * q[1] + J[2][c] * q[2])
    for c in ti.static(range(3)):
        delta[c] = delta[c] + ga[c] * q[3]
        delta[c + 3] = delta[c + 3] + gb[c] * q[4]
    lam_new = [lam[c] + delta[c] for c in ti.static(range(6))]
    back_a = matvec_t(Q, [lam_new[0], lam_new[1], lam_new[2]])
    back_b = matvec_t(Q, [lam_new[3], lam_new[4], lam_new[5]])
    active = L.lane_pair_active[r] != 0
    for c in ti.static(range(3)):
        L.lane_dual[r, c] = ti.select(active, back_a[c], L.lane_dual[r, c])
        L.lane_dual[r, c + 3] = ti.select(active, back_b[c], L.lane_dual[r, c + 3])
    for c in ti.static(range(6)):
        L.lane_force[r, c] = ti.select(active, w * (lam_new[c] + delta[c]), L.lane_force[r, c])


@ti.func
def _position_matrix(L: ti.template(), dynamic: ti.template(), r, k, m, air_viscosity: float, dt: float):
    """The matrix half of ``admm.assemble_position_at`` for row r (local index k of m), on lanes: the rows of
    M/dt^2 + (air) + B^T W B + W_z + W_attach, written to ``lane_position_lower`` / ``_inverse_pivot`` (the diagonal,
    until :func:`_factor_positions`) / ``_ratio`` (the upper entry, until then).  Constant over a launch's
    iterations: the weights, masses, fixed vertices and the z-step's weights do not change between them."""
    fixed = L.lane_vertex_fixed[r] != 0
    diag = V8(0.0)
    if ti.static(dynamic):
        inv_dt = 1.0 / dt
        diag += L.lane_mass[r] * inv_dt * inv_dt
        diag += air_viscosity * L.lane_voronoi[r] * inv_dt
    # The rows before and after (k > 0, k < m - 1), read at a valid row and masked where absent.
    has_prev = k > 0
    has_next = k < m - 1
    rp = ti.select(has_prev, r - 1, r)
    rn = ti.select(has_next, r + 1, r)
    w_own = L.lane_pair_weight[r] * ti.cast(L.lane_pair_active[r], ti.f32)
    we_prev = L.lane_pair_weight[rp] * ti.cast(L.lane_pair_active[rp], ti.f32) + w_own
    diag += ti.select(has_prev, we_prev, 0.0)
    lower = ti.select(has_prev & (L.lane_vertex_fixed[rp] == 0), -we_prev, 0.0)
    real_edge = has_next & (L.lane_rest_length[r] > 0.0)
    we_next = w_own + L.lane_pair_weight[rn] * ti.cast(L.lane_pair_active[rn], ti.f32)
    diag += ti.select(real_edge, we_next, 0.0)
    upper = ti.select(real_edge & (L.lane_vertex_fixed[rn] == 0), -we_next, 0.0)
    diag += L.lane_contact_weight[r]
    diag += L.lane_attach_weight[r]
    L.lane_position_lower[r] = ti.select(fixed, 0.0, lower)
    L.lane_position_inverse_pivot[r] = ti.select(fixed, 1.0, diag)
    L.lane_position_ratio[r] = ti.select(fixed, 0.0, upper)


@ti.func
def _factor_positions(L: ti.template(), r0, m):
    """The forward elimination of ``tridiag.thomas_strand`` on the matrix alone (once per launch): the pivots'
    inverses and the ratios c'_k = upper_k / pivot_k, in place of the diagonal and the upper entries."""
    inv = 1.0 / L.lane_position_inverse_pivot[r0]
    cp = L.lane_position_ratio[r0] * inv
    L.lane_position_inverse_pivot[r0] = inv
    L.lane_position_ratio[r0] = cp
    for k in range(1, m):
        r = r0 + k
        inv_k = 1.0 / (L.lane_position_inverse_pivot[r] - L.lane_position_lower[r] * cp)
        cp = L.lane_position_ratio[r] * inv_k
        L.lane_position_inverse_pivot[r] = inv_k
        L.lane_position_ratio[r] = cp


@ti.func
def _position_rhs(L: ti.template(), dynamic: ti.template(), r, k, m, gravity: vec3, air_velocity: vec3,
                  air_viscosity: float, dt: float):
    """The right-hand side of ``admm.assemble_position_at`` for row r (local index k of m), on lanes."""
    fixed = L.lane_vertex_fixed[r] != 0
    mass = L.lane_mass[r]
    x = load3(L.lane_position, r)
    f = [mass * gravity[c] for c in ti.static(range(3))]
    if ti.static(dynamic):
        inv_dt = 1.0 / dt
        xo = load3(L.lane_position_origin, r)
        vo = load3(L.lane_velocity_origin, r)
        xi = air_viscosity * L.lane_voronoi[r]
        for c in ti.static(range(3)):
            x_pred = xo[c] + dt * vo[c]
            f[c] = f[c] - mass * inv_dt * inv_dt * (x[c] - x_pred)
            f[c] = f[c] - xi * ((x[c] - xo[c]) * inv_dt - air_velocity[c])
    has_prev = k > 0
    has_next = k < m - 1
    rp = ti.select(has_prev, r - 1, r)
    rn = ti.select(has_next, r + 1, r)
    real_edge = has_next & (L.lane_rest_length[r] > 0.0)
    # B^T r: ra_i - rb_i of the own pair, rb_{i-1}, -ra_{i+1} (zero where absent: adding 0 changes no bit).
    for c in ti.static(range(3)):
        f[c] = f[c] + (L.lane_force[r, c] - L.lane_force[r, c + 3])
        f[c] = f[c] + ti.select(has_prev, L.lane_force[rp, c + 3], 0.0)
        f[c] = f[c] - ti.select(real_edge, L.lane_force[rn, c], 0.0)
    # Collision constraint (W_z (z + lambda_z - x)) and attachment (k (target - x)), zero without them.
    w_z = L.lane_contact_weight[r]
    for c in ti.static(range(3)):
        f[c] = f[c] + w_z * (L.lane_contact_target[r, c] - x[c])
    w_a = L.lane_attach_weight[r]
    for c in ti.static(range(3)):
        f[c] = f[c] + w_a * (L.lane_attach_target[r, c] - x[c])
    for c in ti.static(range(3)):
        L.lane_rhs[r, c] = ti.select(fixed, 0.0, f[c])


@ti.func
def _solve_positions(L: ti.template(), r0, m):
    """``tridiag.thomas_strand``'s substitutions with the factored matrix (:func:`_factor_positions`), the three
    columns of ``lane_rhs`` (the position increments)."""
    inv = L.lane_position_inverse_pivot[r0]
    d0 = L.lane_rhs[r0, 0] * inv
    d1 = L.lane_rhs[r0, 1] * inv
    d2 = L.lane_rhs[r0, 2] * inv
    L.lane_rhs[r0, 0] = d0
    L.lane_rhs[r0, 1] = d1
    L.lane_rhs[r0, 2] = d2
    for k in range(1, m):
        r = r0 + k
        low = L.lane_position_lower[r]
        inv_k = L.lane_position_inverse_pivot[r]
        d0 = (L.lane_rhs[r, 0] - low * d0) * inv_k
        d1 = (L.lane_rhs[r, 1] - low * d1) * inv_k
        d2 = (L.lane_rhs[r, 2] - low * d2) * inv_k
        L.lane_rhs[r, 0] = d0
        L.lane_rhs[r, 1] = d1
        L.lane_rhs[r, 2] = d2
    for kk in range(1, m):
        r = r0 + m - 1 - kk
        cp = L.lane_position_ratio[r]
        d0 = L.lane_rhs[r, 0] - cp * d0
        d1 = L.lane_rhs[r, 1] - cp * d1
        d2 = L.lane_rhs[r, 2] - cp * d2
        L.lane_rhs[r, 0] = d0
        L.lane_rhs[r, 1] = d1
        L.lane_rhs[r, 2] = d2


@ti.func
def _thomas(L: ti.template(), r0, m):
    """``tridiag.thomas_strand`` on lanes, one right-hand side (column 0 of ``lane_rhs``: the twist step, whose
    matrix changes every iteration)."""
    inv = 1.0 / L.lane_diag[r0]
    cp = L.lane_upper[r0] * inv
    L.lane_upper[r0] = cp
    d0 = L.lane_rhs[r0, 0] * inv
    L.lane_rhs[r0, 0] = d0
    for k in range(1, m):
        r = r0 + k
        low = L.lane_lower[r]
        inv_k = 1.0 / (L.lane_diag[r] - low * cp)
        cp = L.lane_upper[r] * inv_k
        L.lane_upper[r] = cp
        d0 = (L.lane_rhs[r, 0] - low * d0) * inv_k
        L.lane_rhs[r, 0] = d0
    for kk in range(1, m):
        r = r0 + m - 1 - kk
        d0 = L.lane_rhs[r, 0] - L.lane_upper[r] * d0
        L.lane_rhs[r, 0] = d0


@ti.func
def _reference_frame(L: ti.template(), g, r, k, new_twist: ti.template()):
    """``frames.reference_frame_at`` of edge row r (local index k), on lanes (real edges only).  ``new_twist``
    (compile-time): theta changed since its sin and cos were stored (the step's start: compute and store them), or not
    (the iterations' stage (e): the twist step of the iteration before stored them)."""
    x0, x1 = load3(L.lane_position, r), load3(L.lane_position, r + 1)
    t_new = normalized(sub(x1, x0))
    moved = parallel_transport(load3(L.lane_reference, r), load3(L.lane_tangent, r), t_new)
    # The root edge of a strand with a body takes the body's director.
    root = matvec(_group_rotation(L, g), [L.group_root_director[g, c] for c in ti.static(range(3))])
    d1_raw = select3((L.group_has_body[g] != 0) & (k == 0), root, moved)
    d1 = normalized(sub(d1_raw, scale(dot(d1_raw, t_new), t_new)))
    if ti.static(new_twist):
        sin_t, cos_t = sincos(L.lane_twist[r])
        L.lane_twist_sin[r] = sin_t
        L.lane_twist_cos[r] = cos_t
    m1, m2 = material_frame(d1, t_new, L.lane_twist_sin[r], L.lane_twist_cos[r])
    real = L.lane_rest_length[r] > 0.0
    store3(L.lane_tangent, r, select3(real, t_new, load3(L.lane_tangent, r)))
    store3(L.lane_reference, r, select3(real, d1, load3(L.lane_reference, r)))
    store3(L.lane_d1, r, select3(real, m1, load3(L.lane_d1, r)))
    store3(L.lane_d2, r, select3(real, m2, load3(L.lane_d2, r)))


@ti.func
def _pair_twist_terms(L: ti.template(), g, r):
    """``admm.pair_twist_terms_at`` of pair row r (Korner measure: ``strains.korner_twist_derivatives``)."""
    a = r - 1
    m1a, m2a, ta = load3(L.lane_d1, a), load3(L.lane_d2, a), load3(L.lane_tangent, a)
    m1b, m2b, tb = load3(L.lane_d1, r), load3(L.lane_d2, r), load3(L.lane_tangent, r)
    w_q = 0.5 * ti.sqrt(ti.max(1.0 + dot(m1a, m1b) + dot(m2a, m2b) + dot(ta, tb), 1e-12))
    inv4w = 1.0 / (4.0 * w_q)
    kappa = [2.0 * ((dot(ta, m2b) - dot(m2a, tb)) * inv4w), 2.0 * ((dot(m1a, tb) - dot(ta, m1b)) * inv4w),
             2.0 * ((dot(m2a, m1b) - dot(m1a, m2b)) * inv4w)]
    v = scale(0.5, kappa)
    wv = ti.sqrt(ti.max(1.0 - dot(v, v), 0.0))
    dk_db = [v[1], -v[0], wv]
    dk_da = [v[1], -v[0], -wv]
    d2_aa = scale(-0.25, kappa)
    d2_ab = [-0.25 * kappa[0], -0.25 * kappa[1], 0.25 * kappa[2]]
    c = L.group_damping[g]
    kk = load3(L.lane_bend_stiffness, r)
    gk = [kk[e] * ((kappa[e] - L.lane_rest_kappa[r, e]) + c * (kappa[e] - L.lane_kappa_begin[r, e]))
          for e in ti.static(range(3))]
    h_aa = (1.0 + c) * dot([kk[e] * dk_da[e] for e in ti.static(range(3))], dk_da)
    h_bb = (1.0 + c) * dot([kk[e] * dk_db[e] for e in ti.static(range(3))], dk_db)
    h_ab = (1.0 + c) * dot([kk[e] * dk_da[e] for e in ti.static(range(3))], dk_db)
    e_aa = h_aa + dot(gk, d2_aa)
    e_bb = h_bb + dot(gk, d2_aa)
    e_ab = h_ab + dot(gk, d2_ab)
    exact = (e_aa >= 0.0) & (e_bb >= 0.0) & (e_aa * e_bb - e_ab * e_ab >= 0.0)
    active = L.lane_pair_active[r] != 0
    L.lane_twist_hessian[r, 0] = ti.select(active, ti.select(exact, e_aa, h_aa), L.lane_twist_hessian[r, 0])
    L.lane_twist_hessian[r, 1] = ti.select(active, ti.select(exact, e_bb, h_bb), L.lane_twist_hessian[r, 1])
    L.lane_twist_hessian[r, 2] = ti.select(active, ti.select(exact, e_ab, h_ab), L.lane_twist_hessian[r, 2])
    L.lane_twist_gradient[r, 0] = ti.select(active, dot(gk, dk_da), L.lane_twist_gradient[r, 0])
    L.lane_twist_gradient[r, 1] = ti.select(active, dot(gk, dk_db), L.lane_twist_gradient[r, 1])


@ti.func
def _assemble_twist(L: ti.template(), dynamic: ti.template(), r, k, m, dt: float):
    """``admm.assemble_twist_at`` of edge row r (local index k of m), on lanes."""
    fixed = L.lane_edge_fixed[r] != 0
    diag = V8(0.0)
    g = V8(0.0)
    lower = V8(0.0)
    upper = V8(0.0)
    own = L.lane_pair_active[r] != 0
    diag += ti.select(own, L.lane_twist_hessian[r, 1], 0.0)
    g += ti.select(own, L.lane_twist_gradient[r, 1], 0.0)
    if k > 0:
        lower = ti.select(own & (L.lane_edge_fixed[r - 1] == 0), L.lane_twist_hessian[r, 2], 0.0)
    if k < m - 1:
        nxt = L.lane_pair_active[r + 1] != 0
        diag += ti.select(nxt, L.lane_twist_hessian[r + 1, 0], 0.0)
        g += ti.select(nxt, L.lane_twist_gradient[r + 1, 0], 0.0)
        upper = ti.select(nxt & (L.lane_edge_fixed[r + 1] == 0), L.lane_twist_hessian[r + 1, 2], 0.0)
    if ti.static(dynamic):
        inertia = L.lane_inertia[r] / (dt * dt)
        diag += inertia
        pred = L.lane_twist_origin[r] + dt * L.lane_omega_origin[r]
        g += inertia * (L.lane_twist[r] - pred)
    L.lane_lower[r] = ti.select(fixed, 0.0, lower)
    L.lane_diag[r] = ti.select(fixed, 1.0, diag)
    L.lane_upper[r] = ti.select(fixed, 0.0, upper)
    L.lane_rhs[r, 0] = ti.select(fixed, 0.0, -g)


@ti.func
def _twist_free(L: ti.template(), r0, m):
    """``frames.twist_free_strand`` (without theta) on lanes: each free real edge's frame is the previous edge's,
    parallel-transported along the centerline."""
    for k in range(1, m - 1):
        r = r0 + k
        free = (L.lane_edge_fixed[r] == 0) & (L.lane_rest_length[r] > 0.0)
        t_cur = load3(L.lane_tangent, r)
        moved = parallel_transport(load3(L.lane_d1, r - 1), load3(L.lane_tangent, r - 1), t_cur)
        m1 = normalized(sub(moved, scale(dot(moved, t_cur), t_cur)))
        store3(L.lane_d1, r, select3(free, m1, load3(L.lane_d1, r)))
        store3(L.lane_d2, r, select3(free, cross(t_cur, m1), load3(L.lane_d2, r)))


@ti.kernel
def admm_iterations_lanes(
    use_q: ti.template(),
    dynamic: ti.template(),
    twist_free: ti.template(),
    L: ti.template(),
    model: ti.template(),
    body_rotation: ti.template(),
    x: ti.template(),
    theta: ti.template(),
    es: ti.template(),
    buf: ti.template(),
    gravity: vec3,
    air_velocity: vec3,
    air_viscosity: float,
    dt: float,
    damping_scale: float,
    iterations: ti.i32,
    weight_floor: float,
    launch: ti.template(),
):
    """``iterations`` ADMM iterations (Algorithm 1, lines 4a-4g) for every group of eight strands, groups in parallel:
    the strand schedule's kernel (``schedule_strand.admm_iterations_strand``) on lanes, Korner measure, no Anderson
    mixing.  The frames must be up to date on entry, as there.

    Each step gathers the lanes first (:func:`lanes_gather`) and scatters them back after its last iteration
    (:func:`lanes_scatter`).  ``launch`` (compile-time): ``ITERATIONS`` runs the step's iterations on the lanes (a step
    without contacts: one launch); ``CONTACT_ITERATION`` gathers the z-step's weights and targets first and scatters
    x after (a step with contacts: the z-step runs between single iterations).  The gathers and scatters are kernels
    of their own, shared by every variant of this one: inside it, they tripled its compilation (57 s against 12 s for
    the iterations alone, 11 s for the gather kernel, on the 2-core VM) for no measured speed."""
    for g in L.group_vertex_count:
        if ti.static(launch == CONTACT_ITERATION):
            gather_targets(L, g, buf)
        r0 = L.group_row_start[g]
        m = L.group_vertex_count[g]
        # The global step's matrix, factored once for the launch (the local step's constants: lanes_frames).
        for k in range(m):
            _position_matrix(L, dynamic, r0 + k, k, m, air_viscosity, dt)
        _factor_positions(L, r0, m)
        for _it in range(iterations):
            # (a, c) Local step and fused dual update, every pair.
            for k in range(1, m - 1):
                _local_elasticity(L, use_q, g, r0 + k)
            # (d) Global step: the right-hand side, the factored matrix's substitutions, x += dx on free vertices.
            for k in range(m):
                _position_rhs(L, dynamic, r0 + k, k, m, gravity, air_velocity, air_viscosity, dt)
            _solve_positions(L, r0, m)
            for k in range(m):
                r = r0 + k
                free = L.lane_vertex_fixed[r] == 0
                for c in ti.static(range(3)):
                    L.lane_position[r, c] = ti.select(free, L.lane_position[r, c] + L.lane_rhs[r, c],
                                                      L.lane_position[r, c])
            # (e) Frames of the real edges.
            for k in range(m - 1):
                _reference_frame(L, g, r0 + k, k, False)
            if ti.static(twist_free):
                _twist_free(L, r0, m)
            else:
                # (f) Twist Newton step.
                for k in range(1, m - 1):
                    _pair_twist_terms(L, g, r0 + k)
                for k in range(m):
                    _assemble_twist(L, dynamic, r0 + k, k, m, dt)
                _thomas(L, r0, m)
                # (g) theta += dtheta on free edges, material frames of the real edges.
                for k in range(m):
                    r = r0 + k
                    L.lane_twist[r] = ti.select(L.lane_edge_fixed[r] == 0, L.lane_twist[r] + L.lane_rhs[r, 0],
                                                L.lane_twist[r])
                for k in range(m - 1):
                    r = r0 + k
                    sin_t, cos_t = sincos(L.lane_twist[r])
                    L.lane_twist_sin[r] = sin_t
                    L.lane_twist_cos[r] = cos_t
                    m1, m2 = material_frame(load3(L.lane_reference, r), load3(L.lane_tangent, r), sin_t, cos_t)
                    real = L.lane_rest_length[r] > 0.0
                    store3(L.lane_d1, r, select3(real, m1, load3(L.lane_d1, r)))
                    store3(L.lane_d2, r, select3(real, m2, load3(L.lane_d2, r)))
        if ti.static(launch == CONTACT_ITERATION):
            scatter_positions(L, g, x)


def lanes_gather(L, model, body_rotation, x, theta, es, buf, damping_scale: float, weight_floor: float) -> None:
    """Every group's constants and state into the lanes (the beginning of a step), in three kernels: as one, Taichi
    compiled them in 16-19 s, as three in 6.8 s (cold cache, a 64 x 14 groom, scratch probe 2026-12-07); its
    passes grow faster than the code."""
    _gather_constants(L, model, body_rotation, buf, damping_scale, weight_floor)
    _gather_state(L, x, theta, buf)
    _gather_frames(L, es, buf)


@ti.kernel
def _gather_constants(L: ti.template(), model: ti.template(), body_rotation: ti.template(), buf: ti.template(),
                      damping_scale: float, weight_floor: float):
    for g in L.group_vertex_count:
        gather_constants(L, g, model, body_rotation, buf, damping_scale, weight_floor)


@ti.kernel
def _gather_frames(L: ti.template(), es: ti.template(), buf: ti.template()):
    for g in L.group_vertex_count:
        gather_frames(L, g, es, buf)


@ti.kernel
def _gather_state(L: ti.template(), x: ti.template(), theta: ti.template(), buf: ti.template()):
    for g in L.group_vertex_count:
        gather_state(L, g, x, theta, buf)


@ti.kernel
def lanes_frames(twist_free: ti.template(), L: ti.template()):
    """The frames at the step's first iterate, on the gathered lanes (after :func:`lanes_gather`): the reference frames
    parallel-transported to the new tangents, then the material frames (or the twist-free frames), as the
    iterations' stage (e) does.  The step's frame update in the strands' layout (``SolverADMM._update_frames``, scalar
    sin and cos) is skipped where the lanes run.  Also the local step's constants of the step
    (:func:`_local_constants`), once per step: a step with contacts launches the iterations one at a time."""
    for g in L.group_vertex_count:
        r0 = L.group_row_start[g]
        m = L.group_vertex_count[g]
        for k in range(m):
            _local_constants(L, g, r0 + k, k, m)
        for k in range(m - 1):
            _reference_frame(L, g, r0 + k, k, True)
        if ti.static(twist_free):
            _twist_free(L, r0, m)


@ti.kernel
def lanes_scatter(L: ti.template(), x: ti.template(), theta: ti.template(), es: ti.template(), buf: ti.template()):
    """Every group's state back to the strands' layout (after the last iteration of a step with contacts)."""
    for g in L.group_vertex_count:
        scatter(L, g, x, theta, es, buf)
