"""ADMM local step: the elasticity proximal operator per edge pair (Sec. 4.4, Eq. 4).

For each interior vertex i we approximately solve

    min_y  E_b,i(y) + E_s,i(y) + D_i(y) + w_i/2 |(Bx)_i - lambda_i - y|^2,   y in R^6

with a single Gauss-Newton step from y0 = (Bx)_i (where the frames are known),
combined bending and stretching (each edge's stretch stiffness halved when it
is shared by two pairs), and the strain-rate damping terms D_s, D_b of
Brown et al. 2018 in the dynamic mode.  The 6x6 system w I + (rank 5) is
solved through a 5x5 one by the Woodbury identity (``strains.proximal_step5``),
LDL^T without pivoting in the working precision.

With the root-attachment rotation Q (Sec. 4.4 "Local frame") the dual lambda
is stored in the strand's body frame; it is rotated to world coordinates here.
"""

import taichi as ti

from .admm import pair_weight
from .strains import (
    pair_edge_jacobian,
    pair_kappa,
    proximal_step5,
    stretch_strain,
    vec5,
    vec6,
)

vec3 = ti.math.vec3


@ti.func
def dual_to_world(lam: vec6, R: ti.math.mat3) -> vec6:
    a = R @ vec3(lam[0], lam[1], lam[2])
    b = R @ vec3(lam[3], lam[4], lam[5])
    return vec6(a[0], a[1], a[2], b[0], b[1], b[2])


FRAME_NONE = 0
FRAME_ROOT = 1
FRAME_PAIR = 2


@ti.func
def dual_frame(frame: ti.template(), strand: ti.template(), body_rotation: ti.template(), es: ti.template(),
               s: int, i: int):
    """Rotation Q in which the dual lambda_y of pair i is stored (Sec. 4.4 "Local frame").

    FRAME_ROOT: the root attachment rotation of strand s (the paper's choice);
    FRAME_PAIR: the current material frame (m1, m2, t) of edge i, the per-vertex
    frame the paper reports trying; FRAME_NONE: identity (world coordinates).
    """
    R = ti.Matrix.identity(float, 3)
    if ti.static(frame == FRAME_ROOT):
        b = strand.strand_body[s]
        if b >= 0:
            R = body_rotation[b]
    elif ti.static(frame == FRAME_PAIR):
        R = ti.Matrix.cols([es.edge_material_d1[i], es.edge_material_d2[i], es.edge_tangent[i]])
    return R


@ti.func
def pair_strain_at(i: ti.i32, measure: ti.template(), x: ti.template(), theta: ti.template(), es: ti.template()):
    """Edge vectors (e_{i-1}, e_i), strain kappa_i and its edge Jacobian d kappa / d (e_{i-1}, e_i) of the
    active pair i at the current positions and frames (the local step's and ``prime_duals``' one evaluation)."""
    a = i - 1
    ea = x[i] - x[a]
    eb = x[i + 1] - x[i]
    m1a, m2a, ta = es.edge_material_d1[a], es.edge_material_d2[a], es.edge_tangent[a]
    m1b, m2b, tb = es.edge_material_d1[i], es.edge_material_d2[i], es.edge_tangent[i]
    twist = theta[i] - theta[a] + es.edge_reference_twist[i]
    kappa = pair_kappa(measure, m1a, m2a, ta, m1b, m2b, tb, twist)
    J = pair_edge_jacobian(measure, m1a, m2a, ta, ea.norm(), m1b, m2b, tb, eb.norm())
    return ea, eb, kappa, J


@ti.func
def local_elasticity_at(
    i: ti.i32,
    measure: ti.template(),
    use_q: ti.template(),
    vertex: ti.template(),
    edge: ti.template(),
    pair: ti.template(),
    strand: ti.template(),
    body_rotation: ti.template(),
    x: ti.template(),
    theta: ti.template(),
    es: ti.template(),
    buf: ti.template(),
    damping_scale: float,
    weight_floor: float,
):
    """Local step of pair i (nothing on inactive pairs): see :func:`solve_local_elasticity`.

    Reads x[i-1..i+1], the frames of edges i-1 and i, theta and the reference
    twist of pair i; writes ``buf.pair_dual[i]`` and ``buf.pair_force[i]``.
    """
    if pair.pair_is_active[i] != 0:
        a = i - 1
        ea, eb, kappa, J = pair_strain_at(i, measure, x, theta, es)
        s = vertex.vertex_strand[i]
        c = strand.strand_damping_time[s] * damping_scale
        one_c = 1.0 + c
        k = buf.pair_bend_stiffness[i]
        # Stretch strains and gradients of both edges; stiffness halved on shared edges.
        eps_a, ga = stretch_strain(measure, ea, edge.edge_rest_length[a])
        eps_b, gb = stretch_strain(measure, eb, edge.edge_rest_length[i])
        ksa = buf.edge_pair_stretch_stiffness[a]
        ksb = buf.edge_pair_stretch_stiffness[i]
        # Proximal term w/2 |y - (Bx - lambda)|^2, linearised at y0 = Bx.
        w = pair_weight(vertex, buf, i, weight_floor)
        Q = dual_frame(use_q, strand, body_rotation, es, s, i)
        lam = dual_to_world(buf.pair_dual[i], Q)
        # Gauss-Newton step: bending (J^T K J) and the two stretches (g g^T k_s), each with its strain-rate
        # damping ((1 + c) times the stiffness, the strain offset by c (strain - strain at the step's
        # beginning)), plus w I: (w I + V E V^T) delta = -w lam - V E f with V = [J^T | g_a | g_b],
        # E = (1 + c) diag(k, k_sa, k_sb) and f the offsets divided by 1 + c (``proximal_step5``).
        f = vec5(0.0)
        wie = vec5(0.0)
        for r in ti.static(range(3)):
            f[r] = ((kappa[r] - buf.pair_rest_kappa[i][r]) + c * (kappa[r] - buf.pair_kappa_begin[i][r])) / one_c
            wie[r] = ti.min(w / (one_c * k[r]), 1e30)  # a zero stiffness: 1e30, q_r ~ 0
        f[3] = (eps_a + c * (eps_a - buf.edge_strain_begin[a])) / one_c
        f[4] = (eps_b + c * (eps_b - buf.edge_strain_begin[i])) / one_c
        wie[3] = ti.min(w / (one_c * ksa), 1e30)
        wie[4] = ti.min(w / (one_c * ksb), 1e30)
        delta = proximal_step5(J, ga, gb, wie, lam, f)
        # y = Bx + delta.  Fused dual update (Algorithm 1): lambda <- lambda + y - Bx = lambda + delta,
        # stored back in the frame Q; and the force the global step needs,
        # W_y (lambda + y - Bx) = W_y (lambda_old + 2 delta), in world coordinates.
        lam_new = lam + delta
        buf.pair_dual[i] = dual_to_world(lam_new, Q.transpose())
        buf.pair_force[i] = w * (lam_new + delta)


@ti.kernel
def solve_local_elasticity(
    measure: ti.template(),
    use_q: ti.template(),
    vertex: ti.template(),
    edge: ti.template(),
    pair: ti.template(),
    strand: ti.template(),
    body_rotation: ti.template(),
    x: ti.template(),
    theta: ti.template(),
    es: ti.template(),
    buf: ti.template(),
    damping_scale: float,
    weight_floor: float,
):
    """y_i <- one Gauss-Newton step of Eq. (4) for every edge pair, then the dual update.

    Since the step starts from y0 = (Bx)_i, y - Bx is the Gauss-Newton
    increment itself, so the dual update lambda <- lambda + y - Bx of
    Algorithm 1 is done here too, and the pair's force on the global step,
    W_y (lambda + y - Bx), is stored in ``buf.pair_force``.

    ``damping_scale`` is 1/dt in the dynamic mode and 0 in the quasistatic one;
    tau * damping_scale is the strain-rate damping weight of Sec. 4.4.
    """
    for i in x:
        local_elasticity_at(i, measure, use_q, vertex, edge, pair, strand, body_rotation, x, theta, es, buf,
                            damping_scale, weight_floor)


@ti.kernel
def prime_duals(
    measure: ti.template(),
    use_q: ti.template(),
    vertex: ti.template(),
    edge: ti.template(),
    pair: ti.template(),
    strand: ti.template(),
    body_rotation: ti.template(),
    x: ti.template(),
    theta: ti.template(),
    es: ti.template(),
    buf: ti.template(),
    weight_floor: float,
):
    """Duals at the ADMM fixed point of the current configuration, for the bending: with y = Bx, the local
    step's optimality grad E_i(Bx) + W_y lambda_i = 0 gives lambda_i = -grad E_i / W_y, and the pair's force
    on the global step W_y lambda_i = -grad E_i, with grad E_i = J^T K (kappa - kappa_bar) (damping is zero at
    rest).  A state that is an equilibrium (a sag-free rest pose) then stays one from the first iteration
    instead of sagging while the duals build up.  The stretch is left out: the local step resolves it as a
    near constraint within each iteration (the Woodbury form), and its dual would be k_s / W_y ~ 1e7 times the
    bending scale, which single precision cannot cancel (measured: a stretched upright strand diverged at
    step 1 with it; without it the sag-free test strand moves 0.34 um in 2 s, against 117 um unprimed)."""
    for i in x:
        if pair.pair_is_active[i] != 0:
            _, _, kappa, J = pair_strain_at(i, measure, x, theta, es)
            g = J.transpose() @ (buf.pair_bend_stiffness[i] * (kappa - buf.pair_rest_kappa[i]))
            w = pair_weight(vertex, buf, i, weight_floor)
            s = vertex.vertex_strand[i]
            Q = dual_frame(use_q, strand, body_rotation, es, s, i)
            buf.pair_dual[i] = dual_to_world(-g / w, Q.transpose())
            buf.pair_force[i] = -g
