"""Discrete Elastic Rods strain measures as ``ti.func`` s (Daviet 2023, Sec. 4.1).

Conventions (shared by both measures):

* An edge's material frame is (d1, d2, d3) with d3 = t the unit tangent and
  d2 = t x d1.  Each interior vertex i owns the *edge pair* (e_{i-1}, e_i);
  its bending strain kappa_i in R^3 is a rotation-vector-like quantity whose
  component a is measured along director d_a: kappa_1, kappa_2 are the two
  bending curvatures (resisted by K_11, K_22) and kappa_3 is the twist
  (resisted by K_33).
* Variations of an edge vector move that edge's material frame by parallel
  transport (the minimal rotation taking the old tangent to the new one), at
  fixed twist angle theta.  This is the usual DER convention and the one used
  by the local step, so the Jacobians below are exact derivatives of the
  strains under it.

Korner et al. 2021 (default): with R = F_{i-1}^T F_i the rotation between
adjacent material frames and q = (w, v) its unit quaternion (w >= 0),
kappa = 2 v, whose norm is 2 sin(phi/2).

Bergou et al. 2008: with the curvature binormal kb = 2 t0 x t1 / (1 + t0.t1)
(norm 2 tan(phi/2)), kappa_a = kb . (d_a^{i-1} + d_a^i)/2 for a = 1, 2 and
kappa_3 = theta_i - theta_{i-1} + reference twist.

Stretching (per edge, energy E_s A e_rest eps^2 / 2):
* hyperelastic (Korner): eps = (|e|^2 - e_rest^2) / (2 e_rest^2).  The paper
  writes the measure |e|^2/e_rest - e_rest; we divide it by 2 e_rest so that
  the strain is dimensionless and its small-strain stiffness is the Young
  modulus (E_s A / e_rest), as for the linear measure.
* linear (Bergou): eps = |e| / e_rest - 1.
"""

import taichi as ti

vec3 = ti.math.vec3
vec6 = ti.types.vector(6, float)
mat3 = ti.math.mat3
mat36 = ti.types.matrix(3, 6, float)

KORNER = 0
BERGOU = 1


# --------------------------------------------------------------------------- frames
@ti.func
def parallel_transport(u: vec3, t0: vec3, t1: vec3) -> vec3:
    """Rotate u by the minimal rotation taking unit t0 to unit t1.

    Rodrigues' formula with the unnormalised axis b = t0 x t1:
    R u = c u + b x u + (b.u) b / (1 + c), c = t0.t1 (valid for c > -1).  A tangent that reversed
    (c <= -1 + 1e-6: an edge flipped in one step, e.g. by a body projection) has no minimal rotation; it
    is then the half turn about the axis a = u's part across t0 (R u = 2 (a.u) a - u = u for a director
    u across t0), instead of the formula's 0 / 0 = NaN.
    """
    b = t0.cross(t1)
    c = t0.dot(t1)
    out = u
    if c > -1.0 + 1e-6:
        out = c * u + b.cross(u) + (b.dot(u) / (1.0 + c)) * b
    else:
        a = u - u.dot(t0) * t0
        if a.norm() < 1e-12:  # u along t0: any axis across t0
            a = t0.cross(vec3(1.0, 0.0, 0.0)) if ti.abs(t0[0]) < 0.9 else t0.cross(vec3(0.0, 1.0, 0.0))
        a = a.normalized()
        out = 2.0 * a.dot(u) * a - u
    return out


@ti.func
def signed_angle(u: vec3, v: vec3, axis: vec3) -> float:
    """Angle from u to v, counter-clockwise about the unit axis [rad]."""
    return ti.atan2(u.cross(v).dot(axis), u.dot(v))


@ti.func
def material_frame(ref_d1: vec3, t: vec3, theta: float):
    """Material directors (m1, m2) from the reference director and twist angle."""
    ref_d2 = t.cross(ref_d1)
    c = ti.cos(theta)
    s = ti.sin(theta)
    return c * ref_d1 + s * ref_d2, -s * ref_d1 + c * ref_d2


@ti.func
def transported_material_frame(m1: vec3, t_old: vec3, t_new: vec3, dtheta: float):
    """Material frame after the tangent moves t_old -> t_new and the twist by dtheta."""
    m1_t = parallel_transport(m1, t_old, t_new)
    m1_t = (m1_t - m1_t.dot(t_new) * t_new).normalized()
    return material_frame(m1_t, t_new, dtheta)


# --------------------------------------------------------------------------- Korner
@ti.func
def korner_quaternion(m1a: vec3, m2a: vec3, ta: vec3, m1b: vec3, m2b: vec3, tb: vec3):
    """Unit quaternion (w, v) of R = F_a^T F_b, components in the frame basis, w >= 0."""
    # R_kl = d_k^a . d_l^b
    r11 = m1a.dot(m1b)
    r22 = m2a.dot(m2b)
    r33 = ta.dot(tb)
    w = 0.5 * ti.sqrt(ti.max(1.0 + r11 + r22 + r33, 1e-12))
    v = vec3(ta.dot(m2b) - m2a.dot(tb), m1a.dot(tb) - ta.dot(m1b), m2a.dot(m1b) - m1a.dot(m2b)) / (4.0 * w)
    return w, v


@ti.func
def korner_kappa(m1a: vec3, m2a: vec3, ta: vec3, m1b: vec3, m2b: vec3, tb: vec3) -> vec3:
    """Korner et al. 2021 bending/twist strain of an edge pair: 2 x quaternion vector part."""
    w, v = korner_quaternion(m1a, m2a, ta, m1b, m2b, tb)
    return 2.0 * v


@ti.func
def korner_edge_jacobian(
    m1a: vec3, m2a: vec3, ta: vec3, len_a: float, m1b: vec3, m2b: vec3, tb: vec3, len_b: float
) -> mat36:
    """d kappa / d (e_a, e_b), a 3x6 matrix (Korner measure).

    A variation de of an edge rotates its frame by omega = t x de / |e|, i.e. by
    the body-frame rotation vector A de with A = [-d2^T; d1^T; 0] / |e|.  With
    R' = exp(-[a]x) R exp([b]x) one gets
    d kappa = (w I + [v]x) b - (w I - [v]x) a.
    """
    w, v = korner_quaternion(m1a, m2a, ta, m1b, m2b, tb)
    vx = ti.Matrix([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    eye = ti.Matrix.identity(float, 3)
    Aa = ti.Matrix.rows([-m2a, m1a, vec3(0.0)]) / len_a
    Ab = ti.Matrix.rows([-m2b, m1b, vec3(0.0)]) / len_b
    Ja = -(w * eye - vx) @ Aa
    Jb = (w * eye + vx) @ Ab
    J = mat36(0.0)
    for r, c in ti.static(ti.ndrange(3, 3)):
        J[r, c] = Ja[r, c]
        J[r, c + 3] = Jb[r, c]
    return J


@ti.func
def korner_twist_derivatives(kappa: vec3):
    """Derivatives of the Korner strain with respect to the twists (theta_a, theta_b).

    Twisting frame b by d theta right-multiplies R by a rotation about the body
    z axis, twisting frame a left-multiplies it by the inverse one.  With
    kappa = 2 v, w = sqrt(1 - |v|^2):
    dk/dtheta_b = (v_y, -v_x, w), dk/dtheta_a = (v_y, -v_x, -w),
    d2k/dtheta_a^2 = d2k/dtheta_b^2 = -kappa/4,
    d2k/dtheta_a dtheta_b = -(kappa_x, kappa_y, -kappa_z)/4.
    Returns (dk_da, dk_db, d2k_aa, d2k_bb, d2k_ab).
    """
    v = 0.5 * kappa
    w = ti.sqrt(ti.max(1.0 - v.dot(v), 0.0))
    dk_db = vec3(v[1], -v[0], w)
    dk_da = vec3(v[1], -v[0], -w)
    d2_aa = -0.25 * kappa
    d2_ab = -0.25 * vec3(kappa[0], kappa[1], -kappa[2])
    return dk_da, dk_db, d2_aa, d2_aa, d2_ab


# --------------------------------------------------------------------------- Bergou
@ti.func
def curvature_binormal(ta: vec3, tb: vec3) -> vec3:
    """kb = 2 t_a x t_b / (1 + t_a . t_b); |kb| = 2 tan(phi/2)."""
    return 2.0 * ta.cross(tb) / (1.0 + ta.dot(tb))


@ti.func
def bergou_kappa(m1a: vec3, m2a: vec3, ta: vec3, m1b: vec3, m2b: vec3, tb: vec3, twist: float) -> vec3:
    """Bergou et al. 2008 strain: kb projected on the averaged directors, plus the twist."""
    kb = curvature_binormal(ta, tb)
    return vec3(0.5 * kb.dot(m1a + m1b), 0.5 * kb.dot(m2a + m2b), twist)


@ti.func
def bergou_edge_jacobian(
    m1a: vec3, m2a: vec3, ta: vec3, len_a: float, m1b: vec3, m2b: vec3, tb: vec3, len_b: float
) -> mat36:
    """d kappa / d (e_a, e_b) for the Bergou measure (3x6).

    With chi = 1 + ta.tb, t~ = (ta + tb)/chi and d~_a = (d_a^a + d_a^b)/chi:
    d kappa_a / d e_a = (-kappa_a t~ + t_b x d~_a) / |e_a|,
    d kappa_a / d e_b = (-kappa_a t~ - t_a x d~_a) / |e_b|   (a = 1, 2),
    and the reference-twist holonomy d kappa_3 / d e = kb / (2 |e|).
    """
    kb = curvature_binormal(ta, tb)
    chi = 1.0 + ta.dot(tb)
    tt = (ta + tb) / chi
    d1t = (m1a + m1b) / chi
    d2t = (m2a + m2b) / chi
    k1 = 0.5 * kb.dot(m1a + m1b)
    k2 = 0.5 * kb.dot(m2a + m2b)
    g1a = (-k1 * tt + tb.cross(d1t)) / len_a
    g1b = (-k1 * tt - ta.cross(d1t)) / len_b
    g2a = (-k2 * tt + tb.cross(d2t)) / len_a
    g2b = (-k2 * tt - ta.cross(d2t)) / len_b
    g3a = 0.5 * kb / len_a
    g3b = 0.5 * kb / len_b
    J = mat36(0.0)
    for c in ti.static(range(3)):
        J[0, c] = g1a[c]
        J[0, c + 3] = g1b[c]
        J[1, c] = g2a[c]
        J[1, c + 3] = g2b[c]
        J[2, c] = g3a[c]
        J[2, c + 3] = g3b[c]
    return J


@ti.func
def bergou_twist_derivatives(m1a: vec3, m2a: vec3, ta: vec3, m1b: vec3, m2b: vec3, tb: vec3):
    """Twist derivatives of the Bergou strain: (dk_da, dk_db, d2k_aa, d2k_bb, d2k_ab).

    dm1/dtheta = m2 and dm2/dtheta = -m1, so dkappa_1/dtheta_j = kb.m2_j / 2,
    dkappa_2/dtheta_j = -kb.m1_j / 2, dkappa_3/dtheta_b = 1 = -dkappa_3/dtheta_a.
    """
    kb = curvature_binormal(ta, tb)
    dk_da = vec3(0.5 * kb.dot(m2a), -0.5 * kb.dot(m1a), -1.0)
    dk_db = vec3(0.5 * kb.dot(m2b), -0.5 * kb.dot(m1b), 1.0)
    d2_aa = vec3(-0.5 * kb.dot(m1a), -0.5 * kb.dot(m2a), 0.0)
    d2_bb = vec3(-0.5 * kb.dot(m1b), -0.5 * kb.dot(m2b), 0.0)
    return dk_da, dk_db, d2_aa, d2_bb, vec3(0.0)


# --------------------------------------------------------------------------- dispatch
@ti.func
def pair_kappa(
    measure: ti.template(), m1a: vec3, m2a: vec3, ta: vec3, m1b: vec3, m2b: vec3, tb: vec3, twist: float
) -> vec3:
    """Strain of an edge pair with the measure chosen at compile time.

    ``twist`` (theta_b - theta_a + reference twist) is used by Bergou only.
    """
    k = vec3(0.0)
    if ti.static(measure == KORNER):
        k = korner_kappa(m1a, m2a, ta, m1b, m2b, tb)
    else:
        k = bergou_kappa(m1a, m2a, ta, m1b, m2b, tb, twist)
    return k


@ti.func
def pair_edge_jacobian(
    measure: ti.template(), m1a: vec3, m2a: vec3, ta: vec3, len_a: float, m1b: vec3, m2b: vec3, tb: vec3,
    len_b: float,
) -> mat36:
    J = mat36(0.0)
    if ti.static(measure == KORNER):
        J = korner_edge_jacobian(m1a, m2a, ta, len_a, m1b, m2b, tb, len_b)
    else:
        J = bergou_edge_jacobian(m1a, m2a, ta, len_a, m1b, m2b, tb, len_b)
    return J


@ti.func
def pair_twist_derivatives(
    measure: ti.template(), kappa: vec3, m1a: vec3, m2a: vec3, ta: vec3, m1b: vec3, m2b: vec3, tb: vec3
):
    dk_da, dk_db, d2_aa, d2_bb, d2_ab = vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0), vec3(0.0)
    if ti.static(measure == KORNER):
        dk_da, dk_db, d2_aa, d2_bb, d2_ab = korner_twist_derivatives(kappa)
    else:
        dk_da, dk_db, d2_aa, d2_bb, d2_ab = bergou_twist_derivatives(m1a, m2a, ta, m1b, m2b, tb)
    return dk_da, dk_db, d2_aa, d2_bb, d2_ab


@ti.func
def stretch_strain(measure: ti.template(), e: vec3, rest_length: float):
    """Stretch strain of an edge and its gradient d eps / d e: (eps, grad)."""
    eps = 0.0
    grad = vec3(0.0)
    if ti.static(measure == KORNER):
        inv = 1.0 / (rest_length * rest_length)
        eps = 0.5 * (e.dot(e) * inv - 1.0)
        grad = e * inv
    else:
        n = e.norm()
        eps = n / rest_length - 1.0
        grad = e / (n * rest_length)
    return eps, grad


@ti.func
def bend_energy(kappa: vec3, rest_kappa: vec3, stiffness: vec3) -> float:
    """E_b,i = 1/2 (kappa - rest)^T diag(stiffness) (kappa - rest), stiffness = E_b K / v [J]."""
    d = kappa - rest_kappa
    return 0.5 * (stiffness * d).dot(d)


@ti.func
def stretch_energy(eps: float, stiffness: float) -> float:
    """E_s,j = 1/2 stiffness eps^2 with stiffness = E_s A e_rest [J]."""
    return 0.5 * stiffness * eps * eps


# --------------------------------------------------------------------------- the local step's rank-5 solve
vec5 = ti.types.vector(5, float)
mat5 = ti.types.matrix(5, 5, float)


@ti.func
def proximal_step5(J: mat36, ga: vec3, gb: vec3, w_inv_e: vec5, lam: vec6, f: vec5) -> vec6:
    """delta solving (w I + V E V^T) delta = -w lam - V E f, the Gauss-Newton step of the local problem
    (Eq. 4) of one edge pair, with V = [J^T | (g_a, 0) | (0, g_b)] (6x5: the bending Jacobian's rows and the
    two edges' stretch gradients) and E = diag(e) their stiffnesses; ``w_inv_e`` = w / e.

    By the Woodbury identity, (w I + V E V^T)^-1 = (I - V P^-1 V^T) / w with P = w E^-1 + V^T V, and the
    E f terms cancel: delta = -lam + V P^-1 (V^T lam - f).  P is 5x5, symmetric positive definite, with
    P[3, 4] = g_a . 0 + 0 . g_b = 0; it is solved by LDL^T without pivoting.  No stiffness is multiplied
    into a sum with w: a stiff stretch (e / w ~ 4e7, past single precision's 1.7e7) only makes its
    w / e entry small, and the step tends to the constrained one (V^T delta = -f on those rows).  A zero
    stiffness needs a large w / e (1e30), which leaves that row's multiplier ~0."""
    P = mat5(0.0)
    t = vec5(0.0)
    for r in ti.static(range(3)):
        for s in ti.static(range(r, 3)):
            v = 0.0
            for c in ti.static(range(6)):
                v += J[r, c] * J[s, c]
            P[r, s] = v
            P[s, r] = v
        pa = J[r, 0] * ga[0] + J[r, 1] * ga[1] + J[r, 2] * ga[2]
        pb = J[r, 3] * gb[0] + J[r, 4] * gb[1] + J[r, 5] * gb[2]
        P[r, 3] = pa
        P[3, r] = pa
        P[r, 4] = pb
        P[4, r] = pb
        v = -f[r]
        for c in ti.static(range(6)):
            v += J[r, c] * lam[c]
        t[r] = v
    P[3, 3] = ga.dot(ga)
    P[4, 4] = gb.dot(gb)
    t[3] = ga[0] * lam[0] + ga[1] * lam[1] + ga[2] * lam[2] - f[3]
    t[4] = gb[0] * lam[3] + gb[1] * lam[4] + gb[2] * lam[5] - f[4]
    for r in ti.static(range(5)):
        P[r, r] += w_inv_e[r]
    # LDL^T of P and the solve P q = t.
    L = mat5(0.0)
    D = vec5(0.0)
    for j in ti.static(range(5)):
        s = P[j, j]
        for k in ti.static(range(j)):
            s -= L[j, k] * L[j, k] * D[k]
        D[j] = s
        for i in ti.static(range(j + 1, 5)):
            u = P[i, j]
            for k in ti.static(range(j)):
                u -= L[i, k] * L[j, k] * D[k]
            L[i, j] = u / s
    y = vec5(0.0)
    for i in ti.static(range(5)):
        s = t[i]
        for k in ti.static(range(i)):
            s -= L[i, k] * y[k]
        y[i] = s
    q = vec5(0.0)
    for i in ti.static(range(4, -1, -1)):
        s = y[i] / D[i]
        for k in ti.static(range(i + 1, 5)):
            s -= L[k, i] * q[k]
        q[i] = s
    delta = -lam
    for c in ti.static(range(6)):
        delta[c] += J[0, c] * q[0] + J[1, c] * q[1] + J[2, c] * q[2]
    for c in ti.static(range(3)):
        delta[c] += ga[c] * q[3]
        delta[c + 3] += gb[c] * q[4]
    return delta
