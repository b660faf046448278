"""Edge-length kernels of :class:`taichi_hair.solvers.shape.solver.SolverShape`.

* :func:`edge_length_correction` -- the position-based distance constraint [MHHR07] on one edge;
* :func:`solve_edge_lengths_batch` -- Algorithm 1 l.9, the iterated length constraints in two batches of
  disjoint edges;
* :func:`follow_the_leader` -- exact edge lengths, root to tip (Mueller et al. 2012), colliders kept
  (with :mod:`taichi_hair.solvers.shape.collisions`); its velocity correction is applied by
  :func:`taichi_hair.solvers.shape.integration.end_substep`.

Kernel arguments as in :mod:`taichi_hair.solvers.shape.constraints`.
"""


import taichi as ti

from ...contact.colliders import acts_on
from ...rotation import quat_rotate
from .collisions import place_at_length_outside_collider, project_out_of_collider_normal
from .constraints import inverse_mass, safe_normalized

vec3 = ti.math.vec3


# =========================================================================== constraint math
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


# =========================================================================== per-step stages
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
        leader = x[a]  # x_{i-1} as placed, carried in a register (the same operations, one load less)
        for k in range(1, m):
            i = a + k
            xi = x[i]
            e = xi - leader
            direction = safe_normalized(e, fallback)
            fallback = direction
            if model.vertex_is_fixed[i] == 0:
                rest = model.edge_rest_length[i - 1]
                p = leader + rest * direction
                if ti.static(use_colliders):
                    for c in range(cs.count_field[None]):
                        if acts_on(cs, c, s):
                            p = place_at_length_outside_collider(cs, c, leader, p, rest,
                                                                 solver.vertex_collision_radius[i])
                    for c in range(cs.count_field[None]):  # the last word is the colliders'
                        if acts_on(cs, c, s):
                            p = project_out_of_collider_normal(cs, c, p, solver.vertex_collision_radius[i])
                solver.vertex_length_correction[i] = p - xi
                x[i] = p
                leader = p
            else:
                solver.vertex_length_correction[i] = vec3(0.0)
                leader = xi
