"""Kernels of :class:`taichi_hair.solvers.shape.solver.SolverShape` (Han & Harada 2012, "Real-time Hair
Simulation with Efficient Hair Style Preservation").

One stage per kernel, in the order of the paper's Algorithm 1; the math lives in
``ti.func``s that a test can call alone (wrap one in a tiny kernel):

* rotations are unit quaternions stored as ``vec4`` (x, y, z, w), as in TressFX; their algebra is
  :mod:`taichi_hair.rotation` (``quat_mul``, ``quat_rotate``, ``quat_between``, ``quat_slerp``, ...);
* :func:`global_stiffness_at` -- the root-to-tip ramp of S_G (Sec. 3.3);
* :func:`local_shape_correction` -- the two-vertex update of Eq. 4;
* :func:`edge_length_correction` -- the PBD distance constraint [MHHR07];
* :func:`project_out_of_collider` -- Sec. 3.5, against any collider of
  :mod:`taichi_hair.contact.colliders` (plane, sphere, capsule, mesh SDF), with an
  optional position-based Coulomb friction.

Kernel arguments follow the package convention: ``model`` (static groom data),
``solver`` (the :class:`SolverShape`, holding its own fields), control inputs,
the state fields, scalars.  A strand's region ``r = solver.strand_region[s]``
selects its row in the ``solver.region_*`` fields.

Notation (Sec. 3.1): frame i has its origin at P_i and rotation ``R_i`` whose x
axis is ``normalize(P_i - P_{i-1})`` (``P_1 - P_0`` for i = 0); the local rest
position of vertex i is ``^{i-1}P_i^0 = R_{i-1}^{0 T} (P_i^0 - P_{i-1}^0)``.
"""


import taichi as ti

from ...contact.colliders import acts_on, body_transform, collider_distance
from ...rotation import (quat_between, quat_from_matrix, quat_identity, quat_mul, quat_rotate, quat_rotate_inverse,
                         quat_slerp, quat_to_matrix)

vec3 = ti.math.vec3
vec4 = ti.math.vec4


# =========================================================================== frames
@ti.func
def safe_normalized(v: vec3, fallback: vec3) -> vec3:
    """v / |v|, or ``fallback`` when v is (nearly) zero: collapsed vertices must not make NaN frames."""
    n = v.norm()
    out = fallback
    if n > 1e-12:
        out = v / n
    return out


@ti.func
def advance_frame(q_prev: vec4, x_prev: vec3, x_next: vec3) -> vec4:
    """Global rotation of frame i from frame i-1 (Eq. 1, Algorithm 2 l.7-9, Algorithm 3 l.10-12).

    ``^{i-1}x_i = R_{i-1}^T normalize(P_i - P_{i-1})``; the local transform ``^{i-1}R_i`` is the
    rotation from (1, 0, 0) to ``^{i-1}x_i``, and ``^wR_i = ^wR_{i-1} ^{i-1}R_i``.
    """
    e_x = vec3(1.0, 0.0, 0.0)
    local_x = safe_normalized(quat_rotate_inverse(q_prev, x_next - x_prev), e_x)
    return quat_mul(q_prev, quat_between(vec3(1.0, 0.0, 0.0), local_x)).normalized()


# =========================================================================== constraint math
@ti.func
def global_stiffness_at(stiffness: float, effective_range: float, falloff: float, u: float) -> float:
    """S_G at rest arc-length fraction u in [0, 1] from the root (Sec. 3.3).

    Full ``stiffness`` up to ``effective_range * (1 - falloff)``, then a linear ramp to zero at
    ``effective_range``; zero beyond.  ``falloff = 0`` is TressFX's step cut-off, ``falloff = 1``
    a linear decrease over the whole range; ``effective_range = 0`` disables the constraint.
    """
    ramp = 1.0
    width = falloff * effective_range
    if effective_range <= 0.0:
        ramp = 0.0
    elif width > 0.0:
        ramp = ti.math.clamp((effective_range - u) / width, 0.0, 1.0)
    elif u > effective_range:
        ramp = 0.0
    return stiffness * ramp


@ti.func
def local_shape_correction(x_prev: vec3, x_i: vec3, goal_i: vec3, stiffness: float, w_prev: float, w_i: float):
    """Eq. 4: move P_{i-1} and P_i so that the edge moves S_L of the way to its goal.

    ``d = goal_i - x_i`` (``goal_i = P_{i-1} + R_{i-1} ^{i-1}P_i^0``, Eq. 4's ``^{i-1}d_i`` in world
    axes).  With both vertices free each takes half of ``S_L d`` (P_{i-1} backwards, P_i forwards;
    the paper's "=" for P_{i-1} is read as "-=").  A kinematic P_{i-1} (w = 0) gives P_i the whole
    correction, as PBD's inverse-mass weighting does.  Returns (new P_{i-1}, new P_i).
    """
    d = stiffness * (goal_i - x_i)
    w = w_prev + w_i
    a = 0.0
    b = 0.0
    if w > 0.0:
        a = w_prev / w
        b = w_i / w
    return x_prev - a * d, x_i + b * d


@ti.func
def edge_length_correction(x_a: vec3, x_b: vec3, rest_length: float, w_a: float, w_b: float):
    """Position-based distance constraint |x_b - x_a| = rest_length [MHHR07].  Returns new (x_a, x_b)."""
    e = x_b - x_a
    length = e.norm()
    w = w_a + w_b
    new_a = x_a
    new_b = x_b
    if w > 0.0 and length > 1e-12:
        c = (length - rest_length) / (length * w)
        new_a = x_a + (w_a * c) * e
        new_b = x_b - (w_b * c) * e
    return new_a, new_b


@ti.func
def project_out_of_collider(cs: ti.template(), c: ti.i32, p: vec3, p_begin: vec3, radius: float) -> vec3:
    """Sec. 3.5 against collider ``c`` of the :class:`~taichi_hair.contact.colliders.ColliderSet` ``cs``.

    ``p`` is the vertex after the constraints, ``p_begin`` the same vertex at the beginning of the step
    (x^t), ``radius`` the hair radius [m].  If the signed distance d of ``p`` to the collider (at the
    end-of-step body transform) is below ``radius``, ``p`` moves by ``radius - d`` along the collider's
    outward normal (the distance gradient), so the hair's surface touches the collider's, as in
    SolverADMM's body contacts.  With a friction coefficient mu > 0, the displacement of the vertex
    over the step relative to the collider (both in the body frame: ``p`` at the end transform,
    ``p_begin`` at the begin transform) loses its tangential part up to mu times the normal correction
    (position-based Coulomb friction, Mueller et al. 2007 / Macklin et al. 2014: sticking when the
    tangential displacement is within mu * depth, sliding with that much taken off otherwise).  The
    distance is evaluated once more after that and a remaining penetration is projected out along the
    normal (no friction): friction's tangential move can re-enter a concave surface, and on a mesh
    SDF one step along the trilinear gradient is only first-order.  Points outside a mesh's SDF grid
    are far from it (``colliders.FAR``) and never move.
    """
    return _project_out(cs, c, p, p_begin, radius, cs.collider_friction[c])


@ti.func
def _project_out(cs: ti.template(), c: ti.i32, p: vec3, p_begin: vec3, radius: float, mu: float) -> vec3:
    """The body of :func:`project_out_of_collider` with the friction coefficient ``mu`` given (0: none)."""
    R, T = body_transform(cs.body_rotation_end, cs.body_translation_end, cs.collider_body[c])
    q = R.transpose() @ (p - T)
    d, n = collider_distance(cs, c, q)
    out = p
    if d < radius:
        depth = radius - d
        q = q + depth * n
        if mu > 0.0:
            Rb, Tb = body_transform(cs.body_rotation_begin, cs.body_translation_begin, cs.collider_body[c])
            dq = q - Rb.transpose() @ (p_begin - Tb)
            tangential = dq - dq.dot(n) * n
            tn = tangential.norm()
            if tn > 1e-12:
                q = q - ti.min(1.0, mu * depth / tn) * tangential
        d2, n2 = collider_distance(cs, c, q)
        if d2 < radius:
            q = q + (radius - d2) * n2
        out = R @ q + T
    return out


@ti.func
def project_out_of_collider_normal(cs: ti.template(), c: ti.i32, p: vec3, radius: float) -> vec3:
    """:func:`project_out_of_collider` without friction: ``p`` moves along the collider's normal until it
    is ``radius`` away (two passes, as there).  The follow-the-leader pass uses it: friction was already
    applied once in the step's collision stage and must not act twice."""
    return _project_out(cs, c, p, p, radius, 0.0)


@ti.func
def place_at_length_outside_collider(cs: ti.template(), c: ti.i32, leader: vec3, p: vec3, rest_length: float,
                                     radius: float) -> vec3:
    """The follow-the-leader placement ``p`` (at ``rest_length`` from ``leader``) moved out of collider
    ``c`` while keeping that length, as far as a tangent plane allows.

    If ``p`` is closer than ``radius`` to the collider it is pushed out along the normal n to q (as
    :func:`project_out_of_collider_normal`), then slid in the tangent plane at q to the point at
    ``rest_length`` from the leader that is nearest to q: with the leader at height a above the plane
    and lateral offset b from q, ``q + b - sqrt(l^2 - a^2) b / |b|``.  Pushing back towards the leader
    along the edge instead would leave an edge that points into the collider short (a strand draped
    straight down onto a sphere), and no amount of pushing along the normal fixes it.  If the leader
    is more than ``rest_length`` above the plane, the vertex goes back onto the line from the leader
    to q, at the rest length (then outside the plane).  A convex collider lies below its tangent plane,
    so the slid point is outside up to the surface's curvature; the caller pushes once more.
    """
    R, T = body_transform(cs.body_rotation_end, cs.body_translation_end, cs.collider_body[c])
    q = R.transpose() @ (p - T)
    o = R.transpose() @ (leader - T)
    out = p
    d, n = collider_distance(cs, c, q)
    if d < radius:
        q = q + (radius - d) * n
        w = o - q
        a = w.dot(n)
        b = w - a * n
        r2 = rest_length * rest_length - a * a
        if r2 > 0.0:
            bn = b.norm()
            lateral = vec3(0.0)
            if bn > 1e-9 * rest_length:
                lateral = b / bn
            else:  # the edge points straight into the collider: any tangent direction will do
                lateral = safe_normalized(n.cross(vec3(0.0, 0.0, 1.0)), safe_normalized(n.cross(vec3(1.0, 0.0, 0.0)),
                                                                                        vec3(0.0, 1.0, 0.0)))
            q = q + b - ti.sqrt(r2) * lateral
        else:
            q = o + rest_length * safe_normalized(q - o, n)
        out = R @ q + T
    return out


@ti.func
def inverse_mass(model: ti.template(), i: ti.i32) -> float:
    """1 for a simulated vertex, 0 for a kinematic one (Sec. 3.2: only the fixed/free flag is used)."""
    return 1.0 - ti.cast(model.vertex_is_fixed[i], float)


@ti.func
def root_rotation(model: ti.template(), solver: ti.template(), x: ti.template(), s: ti.i32, k: ti.i32) -> vec4:
    """Global rotation ^wR_k of frame k in {0, 1} of strand s ("update wT_0 and wT_1", Alg. 3 l.6).

    Clamped strand: the head rotation times the rest rotation, ``^wR_H ^wR_k^0``.  Free strand (no
    head): the rest frame turned by the shortest arc from the rest root tangent to the current one.
    """
    a = model.strand_vertex_start[s]
    q = quat_identity()
    if model.strand_body[s] >= 0:
        q = quat_mul(solver.strand_head_rotation[s], solver.vertex_rest_rotation[a + k])
    else:
        q0 = solver.vertex_rest_rotation[a]
        rest_x = quat_rotate(q0, vec3(1.0, 0.0, 0.0))
        cur_x = safe_normalized(x[a + 1] - x[a], rest_x)
        q = quat_mul(quat_between(rest_x, cur_x), q0).normalized()
    return q


# =========================================================================== set-up (Algorithm 2)
@ti.kernel
def initialize_rest_transforms(model: ti.template(), solver: ti.template()):
    """Algorithm 2: rest global rotations ^wR_i^0 and local rest positions ^{i-1}P_i^0, serial per strand.

    Frame 0: x_0 along P_1 - P_0, y_0 the model's root director (``strand_root_director``,
    re-orthogonalised; the paper's "arbitrary vector"), z_0 = x_0 x y_0.
    """
    for s in model.strand_vertex_start:
        a = model.strand_vertex_start[s]
        m = model.strand_vertex_count[s]
        p0 = model.vertex_rest_position[a]
        x0 = (model.vertex_rest_position[a + 1] - p0).normalized()
        y0 = model.strand_root_director[s]
        y0 = y0 - y0.dot(x0) * x0
        if y0.norm_sqr() < 1e-12:
            y0 = x0.cross(vec3(0.0, 0.0, 1.0))
            if y0.norm_sqr() < 1e-12:
                y0 = x0.cross(vec3(1.0, 0.0, 0.0))
        y0 = y0.normalized()
        z0 = x0.cross(y0)
        q = quat_from_matrix(ti.Matrix.cols([x0, y0, z0]))
        solver.vertex_rest_rotation[a] = q
        solver.vertex_rest_local_position[a] = vec3(0.0)
        for k in range(1, m):
            i = a + k
            prev = model.vertex_rest_position[i - 1]
            cur = model.vertex_rest_position[i]
            solver.vertex_rest_local_position[i] = quat_rotate_inverse(q, cur - prev)
            q = advance_frame(q, prev, cur)
            solver.vertex_rest_rotation[i] = q


# =========================================================================== per-step stages
@ti.kernel
def compute_head_rotations(model: ti.template(), body_rotation: ti.template(), x: ti.template(),
                           solver: ti.template()):
    """^wR_H of each strand as a quaternion: the rotation of its root body.

    A free strand has no body; its "head" is the shortest arc taking its rest root edge onto its
    begin-of-step root edge, so Method 3's goals and Method 2's first transforms turn with it.
    """
    for s in model.strand_body:
        b = model.strand_body[s]
        q = quat_identity()
        if b >= 0:
            q = quat_from_matrix(body_rotation[b])
        else:
            a = model.strand_vertex_start[s]
            rest_x = quat_rotate(solver.vertex_rest_rotation[a], vec3(1.0, 0.0, 0.0))
            q = quat_between(rest_x, safe_normalized(x[a + 1] - x[a], rest_x))
        solver.strand_head_rotation[s] = q


@ti.kernel
def begin_step(x: ti.template(), v: ti.template(), solver: ti.template()):
    """Keep x^t and v^t of the whole step (to restore a diverged step, and for the shock test)."""
    for i in x:
        solver.vertex_position_begin[i] = x[i]
        solver.vertex_velocity_begin[i] = v[i]


@ti.kernel
def begin_substep(x: ti.template(), solver: ti.template()):
    """Keep the substep's x^t (the Verlet x_prev of Sec. 3.2, moved by the shock propagation)."""
    for i in x:
        solver.vertex_position_substep[i] = x[i]


@ti.kernel
def interpolate_body_transforms(rotation_begin: ti.template(), translation_begin: ti.template(),
                                rotation_end: ti.template(), translation_end: ti.template(), u: float,
                                out_rotation: ti.template(), out_translation: ti.template()):
    """Body transforms at the fraction u in [0, 1] of the step: rotations slerped, translations linear, so
    that a body turning at a constant rate takes equal turns per substep and clamped roots stay on it."""
    for b in rotation_end:
        if u >= 1.0:  # the end of the step: the control's transforms bit for bit
            out_rotation[b] = rotation_end[b]
            out_translation[b] = translation_end[b]
        else:
            qa = quat_from_matrix(rotation_begin[b])
            qb = quat_from_matrix(rotation_end[b])
            out_rotation[b] = quat_to_matrix(quat_slerp(qa, qb, u))
            out_translation[b] = (1.0 - u) * translation_begin[b] + u * translation_end[b]


@ti.kernel
def integrate(
    model: ti.template(),
    solver: ti.template(),
    body_rotation: ti.template(),
    body_translation: ti.template(),
    gravity: vec3,
    air_velocity: vec3,
    air_drag: float,
    dt: float,
    v: ti.template(),
    x: ti.template(),
):
    """Sec. 3.2: Verlet with damping, x <- x^t + (1 - c) v dt + a dt^2, for free vertices; kinematic
    vertices go to their body's transform at the end of the (sub)step, W_T_H x_body.

    ``x^t`` is ``solver.vertex_position_substep``, ``v`` the state velocity (that of the previous
    substep), so ``v dt`` is Verlet's x - x_prev; c is the region's damping coefficient per substep.
    a = gravity + wind, the wind term being ``air_drag (v_air - v)_perp``: the relative air velocity's
    component normal to the strand (tangent = central difference of the begin-of-substep positions),
    where a thin fibre's drag acts.
    """
    for i in x:
        if model.vertex_is_fixed[i] != 0:
            b = model.strand_body[model.vertex_strand[i]]
            x[i] = body_rotation[b] @ model.vertex_body_position[i] + body_translation[b]
        else:
            s = model.vertex_strand[i]
            r = solver.strand_region[s]
            a = model.strand_vertex_start[s]
            last = a + model.strand_vertex_count[s] - 1
            lo = ti.max(i - 1, a)
            hi = ti.min(i + 1, last)
            t = safe_normalized(solver.vertex_position_substep[hi] - solver.vertex_position_substep[lo], vec3(0.0))
            vi = v[i]
            rel = air_velocity - vi
            accel = gravity + air_drag * (rel - rel.dot(t) * t)
            c = solver.region_damping[r]
            x[i] = solver.vertex_position_substep[i] + (1.0 - c) * dt * vi + (dt * dt) * accel


@ti.kernel
def compute_shock_coefficients(model: ti.template(), solver: ti.template(), body_rotation: ti.template(),
                               body_translation: ti.template(), coefficient: float, acceleration_threshold: float,
                               dt: float):
    """TressFX's velocity shock propagation, strand level: the blend weight of the root's rigid motion.

    ``coefficient`` for every strand with two kinematic root vertices, raised to 1 where the second root
    vertex's acceleration over the step, ``|x_1^{t+1} - 2 x_1^t + x_1^{t-1}| / dt^2`` with
    ``x_1^{t-1} = x_1^t - v_1^t dt``, exceeds ``acceleration_threshold`` [m/s^2] (TressFX measures the
    same second difference in scene units per frame^2).  0 for other strands (no root motion to carry).
    """
    for s in model.strand_body:
        a = model.strand_vertex_start[s]
        w = 0.0
        if model.vertex_is_fixed[a] != 0 and model.vertex_is_fixed[a + 1] != 0:
            b = model.strand_body[s]
            x_end = body_rotation[b] @ model.vertex_body_position[a + 1] + body_translation[b]
            x_now = solver.vertex_position_begin[a + 1]
            x_before = x_now - dt * solver.vertex_velocity_begin[a + 1]
            w = coefficient
            if (x_end - 2.0 * x_now + x_before).norm() > acceleration_threshold * dt * dt:
                w = 1.0
        solver.strand_shock_coefficient[s] = w


@ti.kernel
def propagate_velocity_shock(model: ti.template(), solver: ti.template(), x: ti.template()):
    """TressFX's velocity shock propagation, vertex level: the rigid motion (R, T) taking the root edge
    from the beginning of the substep to its end (R the shortest arc between the two root-edge
    directions, T placing the root) is blended with weight w into both x and x^t of every free vertex:
    ``y <- (1 - w) y + w (R y + T)``.  Moving both carries the strand with the head without adding the
    head's velocity to it (the Verlet velocity x - x^t only turns by R), which is what keeps a sudden head
    motion from stretching or whipping the hair."""
    for i in x:
        s = model.vertex_strand[i]
        w = solver.strand_shock_coefficient[s]
        if w > 0.0 and model.vertex_is_fixed[i] == 0:
            a = model.strand_vertex_start[s]
            u = safe_normalized(solver.vertex_position_substep[a + 1] - solver.vertex_position_substep[a],
                                vec3(1.0, 0.0, 0.0))
            e = safe_normalized(x[a + 1] - x[a], u)
            q = quat_between(u, e)
            T = x[a] - quat_rotate(q, solver.vertex_position_substep[a])
            x[i] = (1.0 - w) * x[i] + w * (quat_rotate(q, x[i]) + T)
            p = solver.vertex_position_substep[i]
            solver.vertex_position_substep[i] = (1.0 - w) * p + w * (quat_rotate(q, p) + T)


@ti.kernel
def apply_global_shape_constraints(
    model: ti.template(),
    solver: ti.template(),
    body_rotation: ti.template(),
    body_translation: ti.template(),
    x: ti.template(),
):
    """Eq. 2: P_i += S_G (W_T_H P_i^0 - P_i), S_G ramped from the root (Sec. 3.3).

    Free strands have no head transform and get no global constraint.
    """
    for i in x:
        s = model.vertex_strand[i]
        b = model.strand_body[s]
        if model.vertex_is_fixed[i] == 0 and b >= 0:
            r = solver.strand_region[s]
            sg = global_stiffness_at(solver.region_global_stiffness[r], solver.region_global_range[r],
                                     solver.region_global_falloff[r], solver.vertex_arc_fraction[i])
            if sg > 0.0:
                goal = body_rotation[b] @ model.vertex_rest_position[i] + body_translation[b]
                x[i] += sg * (goal - x[i])


@ti.kernel
def apply_local_shape_constraints_serial(model: ti.template(), solver: ti.template(), x: ti.template()):
    """Method 1 (Algorithm 3): per strand, sweep root to tip; each vertex's frame is advanced right after
    its constraint, so every transform is exact.  All of the region's iterations run in this launch."""
    for s in model.strand_vertex_start:
        a = model.strand_vertex_start[s]
        m = model.strand_vertex_count[s]
        r = solver.strand_region[s]
        sl = solver.region_local_stiffness[r]
        for _ in range(solver.region_local_iterations[r]):
            q = root_rotation(model, solver, x, s, 1)  # ^wR_1 (= ^wR_0 up to rounding)
            for k in range(2, m):
                i = a + k
                goal = x[i - 1] + quat_rotate(q, solver.vertex_rest_local_position[i])
                p_prev, p_i = local_shape_correction(x[i - 1], x[i], goal, sl, inverse_mass(model, i - 1),
                                                     inverse_mass(model, i))
                x[i - 1] = p_prev
                x[i] = p_i
                q = advance_frame(q, p_prev, p_i)


@ti.kernel
def initialize_global_transforms(model: ti.template(), solver: ti.template(), x: ti.template(),
                                 rotation: ti.template()):
    """Method 2 start of step: ^wR_i <- ^wR_H ^wR_i^0, the rest transforms carried by the head (root
    frames as in :func:`root_rotation`)."""
    for i in x:
        s = model.vertex_strand[i]
        k = model.vertex_local_index[i]
        if k <= 1:
            rotation[i] = root_rotation(model, solver, x, s, k)
        else:
            rotation[i] = quat_mul(solver.strand_head_rotation[s], solver.vertex_rest_rotation[i])


@ti.kernel
def apply_local_shape_constraints_batch(
    use_rest: ti.template(),
    model: ti.template(),
    solver: ti.template(),
    rotation: ti.template(),
    parity: ti.i32,
    iteration: ti.i32,
    x: ti.template(),
):
    """Eq. 4 for the vertices i >= 2 whose local index has the given parity, all strands in parallel.

    Method 2 (Alg. 4 l.12-13) reads frame i-1 from ``rotation``, the transforms ^wT_temp of the
    previous iteration; Method 3 (Alg. 5, ``use_rest``) uses the rest transform carried by the head,
    ^wR_H ^wR_{i-1}^0, and ignores ``rotation``.  Either way the frame's origin is the current
    P_{i-1}.  Vertex i writes P_{i-1} and P_i, so the even batch then the odd batch never write the
    same vertex twice (Sec. 5's batching).  A strand whose region has fewer iterations than
    ``iteration + 1`` is skipped.
    """
    for i in x:
        k = model.vertex_local_index[i]
        if k >= 2 and k % 2 == parity:
            s = model.vertex_strand[i]
            r = solver.strand_region[s]
            if iteration < solver.region_local_iterations[r]:
                q = quat_identity()
                if ti.static(use_rest):
                    q = quat_mul(solver.strand_head_rotation[s], solver.vertex_rest_rotation[i - 1])
                else:
                    q = rotation[i - 1]
                goal = x[i - 1] + quat_rotate(q, solver.vertex_rest_local_position[i])
                p_prev, p_i = local_shape_correction(x[i - 1], x[i], goal, solver.region_local_stiffness[r],
                                                     inverse_mass(model, i - 1), inverse_mass(model, i))
                x[i - 1] = p_prev
                x[i] = p_i


@ti.kernel
def update_global_transforms_jacobi(model: ti.template(), solver: ti.template(), rotation_in: ti.template(),
                                    iteration: ti.i32, x: ti.template(), rotation_out: ti.template()):
    """Algorithm 4 l.9-16: ^wR_i <- ^wR_temp_{i-1} ^{i-1}R_i, every vertex in parallel (Jacobi).

    Reading ``rotation_in`` (^wT_temp) and writing ``rotation_out`` (^wT) is Algorithm 4's copy
    ^wT_temp <- ^wT done by swapping two buffers between iterations instead of copying.
    """
    for i in x:
        s = model.vertex_strand[i]
        k = model.vertex_local_index[i]
        if k <= 1:
            rotation_out[i] = root_rotation(model, solver, x, s, k)
        elif iteration < solver.region_local_iterations[solver.strand_region[s]]:
            rotation_out[i] = advance_frame(rotation_in[i - 1], x[i - 1], x[i])
        else:
            rotation_out[i] = rotation_in[i]


@ti.kernel
def solve_edge_lengths_batch(model: ti.template(), solver: ti.template(), parity: ti.i32, iteration: ti.i32,
                             x: ti.template()):
    """Algorithm 1 l.9: distance constraints on edges (k, k+1) with k of the given parity (disjoint writes)."""
    for i in x:
        k = model.vertex_local_index[i]
        s = model.vertex_strand[i]
        if k < model.strand_vertex_count[s] - 1 and k % 2 == parity:
            if iteration < solver.region_length_iterations[solver.strand_region[s]]:
                xa, xb = edge_length_correction(x[i], x[i + 1], model.edge_rest_length[i], inverse_mass(model, i),
                                                inverse_mass(model, i + 1))
                x[i] = xa
                x[i + 1] = xb


@ti.kernel
def project_collisions(model: ti.template(), solver: ti.template(), cs: ti.template(), x: ti.template()):
    """Sec. 3.5: project every free vertex out of the colliders that act on its strand.

    Colliders are visited in order, once each (Gauss-Seidel over colliders): a vertex caught
    between two colliders ends outside the last one.  ``cs`` holds the body transforms of the
    (sub)step (:meth:`ColliderSet.begin_step`); colliders follow the end-of-substep transform, and
    friction sees the vertex's motion over the substep.
    """
    for i in x:
        if model.vertex_is_fixed[i] == 0:
            s = model.vertex_strand[i]
            p = x[i]
            for c in range(cs.count_field[None]):
                if acts_on(cs, c, s):
                    p = project_out_of_collider(cs, c, p, solver.vertex_position_substep[i],
                                                solver.vertex_collision_radius[i])
            x[i] = p


@ti.kernel
def follow_the_leader(use_colliders: ti.template(), model: ti.template(), solver: ti.template(),
                      cs: ti.template(), x: ti.template()):
    """Exact edge lengths: walk each strand from root to tip and put every free vertex at its rest length
    from its predecessor, along the current edge direction (follow-the-leader, FTL, as in Mueller et al.
    2012; what the iterated length constraints converge to when the root side is held).

    With ``use_colliders`` the placed vertex is then pushed out of the colliders along their normals
    and slid in the collider's tangent plane back to the rest length from its predecessor
    (:func:`place_at_length_outside_collider`), then pushed out once more along the normals
    (:func:`project_out_of_collider_normal`): the pass does not undo the collision stage, and an edge
    is off its rest length only by what that last push leaves (the slide's chord dips into a curved
    surface by a second-order amount).  The walk goes on from the placed vertex.  The move of
    each vertex, ``d_i = x_i^new - x_i^old``, is kept in ``solver.vertex_length_correction`` for the
    velocity correction of :func:`end_substep` (0 on kinematic vertices).  A zero-length edge keeps the
    direction of the edge before it (the rest direction carried by the head at the root).
    """
    for s in model.strand_vertex_start:
        a = model.strand_vertex_start[s]
        m = model.strand_vertex_count[s]
        solver.vertex_length_correction[a] = vec3(0.0)
        fallback = quat_rotate(solver.strand_head_rotation[s],
                               safe_normalized(model.vertex_rest_position[a + 1] - model.vertex_rest_position[a],
                                               vec3(1.0, 0.0, 0.0)))
        for k in range(1, m):
            i = a + k
            e = x[i] - x[i - 1]
            direction = safe_normalized(e, fallback)
            fallback = direction
            if model.vertex_is_fixed[i] == 0:
                rest = model.edge_rest_length[i - 1]
                p = x[i - 1] + rest * direction
                if ti.static(use_colliders):
                    for c in range(cs.count_field[None]):
                        if acts_on(cs, c, s):
                            p = place_at_length_outside_collider(cs, c, x[i - 1], p, rest,
                                                                 solver.vertex_collision_radius[i])
                    for c in range(cs.count_field[None]):  # the last word is the colliders'
                        if acts_on(cs, c, s):
                            p = project_out_of_collider_normal(cs, c, p, solver.vertex_collision_radius[i])
                solver.vertex_length_correction[i] = p - x[i]
                x[i] = p
            else:
                solver.vertex_length_correction[i] = vec3(0.0)


@ti.kernel
def end_substep(model: ti.template(), solver: ti.template(), dt: float, length_velocity_correction: float,
                x: ti.template(), v: ti.template()):
    """v = (x - x^t) / dt - s d_{i+1} / dt: the Verlet velocity of the next substep, kept in the State.

    The second term is the velocity correction of Mueller et al. 2012 ("dynamic FTL") with
    s = ``length_velocity_correction``: follow-the-leader moves vertex i+1 by d_{i+1} and leaves
    vertex i where it was, as if i were infinitely heavy; a mass-weighted constraint would have moved
    i by -d_{i+1} as well.  Adding that missing move to i's velocity (not its position) gives back the
    momentum the one-sided projection takes.  s = 0 gives v = (x - x^t) / dt.  Tips (no i+1) and
    kinematic vertices get no correction.
    """
    for i in x:
        vi = (x[i] - solver.vertex_position_substep[i]) / dt
        if length_velocity_correction > 0.0 and model.vertex_is_fixed[i] == 0:
            s = model.vertex_strand[i]
            if model.vertex_local_index[i] < model.strand_vertex_count[s] - 1:
                vi -= (length_velocity_correction / dt) * solver.vertex_length_correction[i + 1]
        v[i] = vi


@ti.kernel
def restore_begin(solver: ti.template(), x: ti.template(), v: ti.template()):
    """Undo a diverged step."""
    for i in x:
        x[i] = solver.vertex_position_begin[i]
        v[i] = solver.vertex_velocity_begin[i]


@ti.kernel
def find_non_finite(model: ti.template(), x: ti.template(), v: ti.template(), out: ti.template()):
    """out[None] <- min over bad vertices of (strand * 2 + field code), -1 if all finite.

    Field codes: 0 vertex_position, 1 vertex_velocity.
    """
    out[None] = 2147483647
    for i in x:
        code = -1
        # NaN fails every comparison, so "not (|.| <= big)" flags NaN, inf and runaway values.
        if not (ti.abs(x[i]).sum() <= 1e30):
            code = 0
        elif not (ti.abs(v[i]).sum() <= 1e30):
            code = 1
        if code >= 0:
            ti.atomic_min(out[None], model.vertex_strand[i] * 2 + code)
    if out[None] == 2147483647:
        out[None] = -1
