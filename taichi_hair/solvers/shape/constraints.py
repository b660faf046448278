"""Shape-constraint kernels of :class:`taichi_hair.solvers.shape.solver.SolverShape` (Han & Harada 2012,
"Real-time Hair Simulation with Efficient Hair Style Preservation"): the frames of Sec. 3.1, the rest
transforms of Algorithm 2, the global shape constraints (Sec. 3.3, Eq. 2) and the local shape
constraints (Sec. 3.4, Eq. 4) with the transforms of Methods 1-3 (Sec. 4.2).

The solver's other kernels live beside this module, one module per job: :mod:`.integration` (begin
and end of the step and substep, body-transform interpolation, Verlet, velocity shock propagation,
the divergence check), :mod:`.lengths` (edge-length constraints, follow-the-leader) and
:mod:`.collisions` (Sec. 3.5).

One stage per kernel (the stages, in the order of the paper's Algorithm 1, are listed in
:mod:`taichi_hair.solvers.shape.solver`); the math lives in ``ti.func``s that a test can call alone
(wrap one in a tiny kernel):

* rotations are unit quaternions stored as ``vec4`` (x, y, z, w), as in TressFX; their algebra is
  :mod:`taichi_hair.rotation` (``quat_mul``, ``quat_rotate``, ``quat_between``, ``quat_slerp``, ...);
* :func:`global_stiffness_at` -- the root-to-tip ramp of S_G (Sec. 3.3);
* :func:`local_shape_correction` -- the two-vertex update of Eq. 4;
* :func:`taichi_hair.solvers.shape.lengths.edge_length_correction` -- the PBD distance constraint [MHHR07];
* :func:`taichi_hair.solvers.shape.collisions.project_out_of_collider` -- Sec. 3.5, against any collider of
  :mod:`taichi_hair.contact.colliders` (plane, sphere, capsule, mesh SDF), with an
  optional position-based Coulomb friction.

Kernel arguments follow the package convention (in all four modules): ``model`` (static groom data),
``solver`` (the :class:`SolverShape`, holding its own fields), control inputs,
the state fields, scalars.  A strand's region ``r = solver.strand_region[s]``
selects its row in the ``solver.region_*`` fields.

Notation (Sec. 3.1): frame i has its origin at P_i and rotation ``R_i`` whose x
axis is ``normalize(P_i - P_{i-1})`` (``P_1 - P_0`` for i = 0); the local rest
position of vertex i is ``^{i-1}P_i^0 = R_{i-1}^{0 T} (P_i^0 - P_{i-1}^0)``.
"""


import taichi as ti

from ...rotation import quat_between, quat_from_matrix, quat_identity, quat_mul, quat_rotate, quat_rotate_inverse

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
