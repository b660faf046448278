"""DER reference and material frames (Bergou et al. 2010, time-parallel transport).

Each time x or theta changes (Algorithm 1), frames are brought up to date:
``update_reference_frames`` transports every edge's reference director from
its old tangent to its new one (time-parallel transport), re-derives the
material frame from the twist, and updates the reference twist of each edge
pair continuously in time; ``update_material_frames`` only re-derives the
material directors after a twist update; ``update_twist_free_frames`` replaces
the twist unknowns by their exact value for naturally straight rods of round
section (:func:`twist_choice`, at the end of this module).  The root edge of a clamped strand
takes its reference director from the body it is attached to, so an animated
root rotates the whole frame, not just the tangent.
"""

import math

import numpy as np
import taichi as ti

from .strains import material_frame, parallel_transport, signed_angle

vec3 = ti.math.vec3


@ti.func
def wrap_angle(a: float) -> float:
    """Map an angle to (-pi, pi]."""
    two_pi = 2.0 * math.pi
    return a - two_pi * ti.round(a / two_pi)


@ti.func
def reference_frame_at(
    i: ti.i32,
    vertex: ti.template(),
    edge: ti.template(),
    strand: ti.template(),
    body_rotation: ti.template(),
    x: ti.template(),
    theta: ti.template(),
    es: ti.template(),
):
    """Edge i: tangent from x[i], x[i+1], time-parallel transported reference director
    (the body's for a clamped root edge), material directors.  Nothing on ghost edges."""
    if edge.edge_rest_length[i] > 0.0:
        t_new = (x[i + 1] - x[i]).normalized()
        d1 = parallel_transport(es.edge_reference_director[i], es.edge_tangent[i], t_new)
        s = vertex.vertex_strand[i]
        b = strand.strand_body[s]
        if vertex.vertex_local_index[i] == 0 and b >= 0:
            d1 = body_rotation[b] @ strand.strand_root_director[s]
        d1 = (d1 - d1.dot(t_new) * t_new).normalized()
        es.edge_tangent[i] = t_new
        es.edge_reference_director[i] = d1
        m1, m2 = material_frame(d1, t_new, theta[i])
        es.edge_material_d1[i] = m1
        es.edge_material_d2[i] = m2


@ti.func
def reference_twist_at(i: ti.i32, pair: ti.template(), es: ti.template()):
    """Reference twist of pair i, continuous in time.  Needs the tangents and reference
    directors of edges i-1 and i up to date (:func:`reference_frame_at` on both first)."""
    if pair.pair_is_active[i] != 0:
        t_prev = es.edge_tangent[i - 1]
        t_cur = es.edge_tangent[i]
        d1_transported = parallel_transport(es.edge_reference_director[i - 1], t_prev, t_cur)
        angle = signed_angle(d1_transported, es.edge_reference_director[i], t_cur)
        old = es.edge_reference_twist[i]
        es.edge_reference_twist[i] = old + wrap_angle(angle - old)


@ti.func
def material_frame_at(i: ti.i32, edge: ti.template(), theta: ti.template(), es: ti.template(),
                      dtheta: ti.template()):
    """Edge i: theta <- theta + dtheta if free, then the material directors."""
    if edge.edge_is_fixed[i] == 0:
        theta[i] += dtheta[i]
    if edge.edge_rest_length[i] > 0.0:
        m1, m2 = material_frame(es.edge_reference_director[i], es.edge_tangent[i], theta[i])
        es.edge_material_d1[i] = m1
        es.edge_material_d2[i] = m2


@ti.kernel
def update_reference_frames(
    with_reference_twist: ti.template(),
    vertex: ti.template(),
    edge: ti.template(),
    pair: ti.template(),
    strand: ti.template(),
    body_rotation: ti.template(),
    x: ti.template(),
    theta: ti.template(),
    es: ti.template(),
):
    """Tangents, reference directors, material directors and reference twists from x and theta.

    ``with_reference_twist`` (compile-time) skips the reference twist, which only
    the Bergou strain needs (Korner's strain reads the material frames directly).
    The reference twists need every tangent updated first: two loops.
    """
    for i in x:
        reference_frame_at(i, vertex, edge, strand, body_rotation, x, theta, es)
    if ti.static(with_reference_twist):
        for i in x:
            reference_twist_at(i, pair, es)


@ti.kernel
def update_material_frames(edge: ti.template(), theta: ti.template(), es: ti.template(), dtheta: ti.template()):
    """theta <- theta + dtheta on free edges, then the material directors (tangents and
    reference frames are unchanged by a twist update)."""
    for i in theta:
        material_frame_at(i, edge, theta, es, dtheta)


@ti.func
def twist_free_strand(start: ti.i32, count: ti.i32, edge: ti.template(), theta: ti.template(), es: ti.template(),
                      with_theta: ti.template()):
    """Material frames of one strand with no twist: each free edge's frame is the previous edge's
    parallel-transported along the centerline (the space-parallel, "Bishop", frame); with
    ``with_theta`` (compile-time) also theta, the angle of that frame from the edge's reference
    director, kept continuous in time (once per step is enough: nothing reads theta inside the
    iterations when the twist is dropped).

    This is the exact minimiser of the twisting energy over theta when the rest twist and curvature are
    zero, the section is round and nothing holds the tip's twist: every pair's twist is then zero, the
    bending energy does not depend on the frame, and the twist unknowns carry no information
    (:func:`twist_choice` decides when that holds).  Needs the tangents up to date
    (and the reference directors for theta); edges are visited root to tip, serially per strand.
    """
    for k in range(1, count - 1):
        i = start + k
        if edge.edge_is_fixed[i] == 0 and edge.edge_rest_length[i] > 0.0:
            t_cur = es.edge_tangent[i]
            m1 = parallel_transport(es.edge_material_d1[i - 1], es.edge_tangent[i - 1], t_cur)
            m1 = (m1 - m1.dot(t_cur) * t_cur).normalized()
            if ti.static(with_theta):
                angle = signed_angle(es.edge_reference_director[i], m1, t_cur)
                old = theta[i]
                theta[i] = old + wrap_angle(angle - old)
            es.edge_material_d1[i] = m1
            es.edge_material_d2[i] = t_cur.cross(m1)  # = -sin d1 + cos d2 of material_frame


@ti.kernel
def update_twist_free_frames(strand: ti.template(), edge: ti.template(), theta: ti.template(), es: ti.template(),
                             with_theta: ti.i32):
    """:func:`twist_free_strand` for every strand (strands in parallel).  ``with_theta`` (1 or 0) is a launch
    argument here, so that the solver's two uses share one kernel instance (one fewer per Model to compile)."""
    for s in strand.strand_vertex_start:
        if with_theta:
            twist_free_strand(strand.strand_vertex_start[s], strand.strand_vertex_count[s], edge, theta, es, True)
        else:
            twist_free_strand(strand.strand_vertex_start[s], strand.strand_vertex_count[s], edge, theta, es, False)


# --------------------------------------------------------------------------- when the twist can be dropped
# Model no more than a scene needs (issue 4 item 6):
# * **Twist unknowns dropped** (``SolverADMMConfig.twist = "auto"``, default): when every strand is
# naturally straight (rest curvature and twist below :data:`STRAIGHT_TOLERANCE` rad per edge pair),
# of round section (equal bending stiffnesses) and nothing but its root holds its twist (no fixed
# edge past the root edge), the twisting energy is minimised exactly by frames with no twist (each
# edge's material frame the previous one's, parallel-transported along the centerline), whatever
# the centerline, and the bending energy of a round, straight-at-rest rod does not depend on the
# frame.  The twist Newton step (a tridiagonal solve per strand and iteration) is then replaced by
# that frame (:func:`taichi_hair.frames.twist_free_strand`), and the twist stiffness drops out of the
# local step (the energy minimised over theta has none).  Same equilibria; dynamic trajectories
# differ by the rotational inertia of the twist and by the ADMM iterate path, within the tolerance
# of the tests.  ``twist = "solve"`` keeps the paper's unknowns.

#: Largest rest curvature or twist component [rad per edge pair] of a "naturally straight" strand.
STRAIGHT_TOLERANCE = 1.0e-5
#: Largest relative difference of the two bending stiffnesses of a "round" section.
ROUND_TOLERANCE = 1.0e-6


def twist_choice(host: dict, rest_kappa: np.ndarray) -> tuple[bool, str]:
    """Whether the twist unknowns can be dropped, and why (or why not), naming a strand.

    Args:
        host: ``Model.host``.
        rest_kappa: rest strain of every pair (the solver's ``pair_rest_kappa``), shape (vertex_count, 3)
            [rad]: bending components 0 and 1, twist 2.
    """
    active = host["pair_is_active"].astype(bool)
    strand = host["vertex_strand"]
    k = np.abs(np.asarray(rest_kappa, np.float64))
    curved = active & (k.max(axis=1) > STRAIGHT_TOLERANCE)
    if curved.any():
        i = int(np.argmax(curved))
        return False, (f"twist solved: strand {int(strand[i])} is not naturally straight (rest curvature/twist "
                       f"{k[i].max():.3g} rad at vertex {i} > {STRAIGHT_TOLERANCE:g})")
    kb = np.asarray(host["pair_bending_modulus"], np.float64)
    big = np.maximum(np.abs(kb[:, 0]), np.abs(kb[:, 1]))
    flat = active & (np.abs(kb[:, 0] - kb[:, 1]) > ROUND_TOLERANCE * np.maximum(big, 1e-300))
    if flat.any():
        i = int(np.argmax(flat))
        return False, f"twist solved: strand {int(strand[i])} has an elliptic section (bending stiffnesses differ)"
    local = host["vertex_local_index"]
    count = host["strand_vertex_count"][strand]
    ghost = local == count - 1
    held = (host["edge_is_fixed"] != 0) & (local >= 1) & ~ghost
    if held.any():
        i = int(np.argmax(held))
        return False, (f"twist solved: strand {int(strand[i])} has a fixed edge past its root (edge {i}) that "
                       "holds its twist")
    return True, ("twist unknowns dropped: every strand is naturally straight, of round section and free to "
                  "untwist (exact; SolverADMMConfig.twist='solve' keeps them)")
