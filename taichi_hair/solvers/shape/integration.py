"""Time-stepping kernels of :class:`taichi_hair.solvers.shape.solver.SolverShape` (Han & Harada 2012,
Sec. 3.2, with TressFX's velocity shock propagation): everything of a step that is not a constraint.

* :func:`begin_step`, :func:`begin_substep` -- keep x^t and v^t of the step and x^t of the substep;
* :func:`interpolate_body_transforms` -- the bodies' transforms at a fraction of the step;
* :func:`integrate` -- Verlet with damping, gravity and wind (Sec. 3.2);
* :func:`compute_shock_coefficients`, :func:`propagate_velocity_shock` -- TressFX's velocity shock
  propagation;
* :func:`end_substep` -- the next substep's Verlet velocity, with the follow-the-leader velocity
  correction (the moves kept by :func:`taichi_hair.solvers.shape.lengths.follow_the_leader`);
* :func:`restore_begin`, :func:`find_non_finite` -- undo a diverged step, and detect one.

Kernel arguments as in :mod:`taichi_hair.solvers.shape.constraints`.
"""


import taichi as ti

from ...rotation import quat_between, quat_from_matrix, quat_rotate, quat_slerp, quat_to_matrix
from .constraints import safe_normalized

vec3 = ti.math.vec3


# =========================================================================== begin of step and substep
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


# =========================================================================== per-step stages
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


# =========================================================================== divergence
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
