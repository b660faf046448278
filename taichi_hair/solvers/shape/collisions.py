"""Collision kernels of :class:`taichi_hair.solvers.shape.solver.SolverShape` (Han & Harada 2012, Sec. 3.5).

Vertices are projected out of the colliders of :mod:`taichi_hair.contact.colliders` (plane, sphere,
capsule, mesh SDF), with an optional position-based Coulomb friction:

* :func:`project_out_of_collider` -- the collision stage's projection, friction included;
* :func:`project_out_of_collider_normal` -- the same without friction, for the follow-the-leader pass;
* :func:`place_at_length_outside_collider` -- a follow-the-leader placement moved out of a collider
  while keeping its edge length (used by :func:`taichi_hair.solvers.shape.lengths.follow_the_leader`);
* :func:`project_collisions` -- the stage's kernel, every free vertex against the colliders acting on
  its strand.

Kernel arguments as in :mod:`taichi_hair.solvers.shape.constraints`.
"""


import taichi as ti

from ...contact.colliders import acts_on, body_transform, collider_distance
from .constraints import safe_normalized

vec3 = ti.math.vec3


# =========================================================================== collider projection (Sec. 3.5)
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


# =========================================================================== per-step stage
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
