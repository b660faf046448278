"""The contacts of a quasistatic step kept for the next one (``ContactConfig.redetect_share``; a choice of this project).

A detection (``ContactPipeline.detect``) finds every pair within r_a + r_b + margin, keeps each edge's closest ones,
writes the contacts, sorts them by slab group, builds the vertices' lists and weights and carries the last step's
impulses over pair by pair: 65-80 ms of a 270-350 ms still step of the grooming benchmark (2026-12-07, kernel
profiler).  Between two quasistatic steps of a groom at rest the hair moves by micrometres, and the contact set
hardly changes (150-2,000 of 153k contacts each step).  So while no vertex has moved more than ``redetect_share``
x margin since the last detection, the step keeps that detection's contacts, in the same order, with the same
lists and W_z, and only measures them again at x (:func:`refresh_contacts`: closest points, normals and weights, as
``narrow.write_contacts`` writes them) and carries each contact's impulse to itself (:func:`refresh_impulses`).

What that keeps: a segment distance changes by at most the larger displacement of each segment's ends, so every
pair now within r_a + r_b + (1 - 2 ``redetect_share``) margin was within reach at the detection (a contact, unless
its edges had more than ``max_contacts_per_edge`` closer ones).  The default, a quarter, keeps every pair within
half the margin, as a detection with half the margin would: a 40 um margin instead of 100 um measured the same
penetrations, strain and drift on the grooming benchmark (2026-12-07).  Bodies, kinematic vertices, the time step
and gravity must be as at the detection (else the step detects): ``ContactPipeline._reuse_key``.
"""

import taichi as ti

from ..fields import download
from .narrow import (_body_reach, _delassus, measure_body_contact, measure_hair_contact, store_entry_coefficients,
                     store_push)
from .warm import duals_of_impulses

vec3 = ti.math.vec3


@ti.kernel
def max_displacement(x: ti.template(), x_ref: ti.template()) -> float:
    """max_i |x_i - x_ref,i| [m]."""
    m = 0.0
    for i in x:
        ti.atomic_max(m, (x[i] - x_ref[i]).norm())
    return m


@ti.kernel
def refresh_contacts(x: ti.template(), radius: ti.template(), cs: ti.template(), con: ti.template(),
                     hair_friction: float):
    """Every contact measured again at x, as the detection writes it (``narrow.write_contacts``): a hair pair (edges
    a, b) its closest points, normal, weights and u_kin = -thickness n; a body contact (vertex a, collider k) the
    body point and normal at the end-of-step transform.  Thicknesses, vertices and colliders are kept."""
    nc = ti.min(con.contact_count[None], con.capacity)
    for c in range(nc):
        a = con.contact_vertex[c][0]
        k = con.contact_collider[c]
        if k < 0:
            measure_hair_contact(x, con, c, a, con.contact_vertex[c][2], hair_friction)
        else:
            q, d, nq = _body_reach(cs, k, x[a])
            measure_body_contact(radius, cs, con, c, a, k, q, d, nq)


@ti.kernel
def refresh_impulses(con: ti.template(), warm: ti.template(), split_by_batch: ti.template(), coefficients: ti.template()):
    """D_hat and the pushes of the measured contacts (the lists and W_z are the detection's), fresh corrections, each
    hair pair's impulse of the last step, r~ = r D_hat (``contact.warm``: the same contact, so the same index; body
    contacts start from zero, as there), and the collision duals lambda_z = W_z^-1 H^T D_hat^-1 r~."""
    nc = ti.min(con.contact_count[None], con.capacity)
    for c in range(nc):
        dh = _delassus(con, c, split_by_batch)
        con.contact_delassus[c] = dh
        r = vec3(0.0)
        if con.contact_collider[c] < 0:
            r = warm.warm_impulse[c] * dh
        con.contact_accumulated[c] = r
        con.contact_delta[c] = vec3(0.0)
        con.contact_status[c] = 0
        store_push(con, c)
    duals_of_impulses(con)
    if ti.static(coefficients):
        store_entry_coefficients(con)


def reuse_key(pl, dt: float, gravity, dynamic: bool):
    """What a kept detection must share with the step of pipeline ``pl``, or None where none is kept: the quasistatic
    mode, ``redetect_share`` > 0, no hair-hair search in rounds; the time step, gravity, the contact options the
    detection's contacts and weights depend on, the kinematic vertices, and still bodies and colliders (their
    transforms and the strands they act on)."""
    import numpy as np

    cfg, cs = pl.config, pl.colliders
    if dynamic or cfg.redetect_share <= 0.0 or pl.pair_rounds_last > 1:
        return None
    # One launch per element type (fields.download), not six to_numpy kernel instances in the first step.
    rb, re, tb, te, strands, fixed = download((cs.body_rotation_begin, cs.body_rotation_end, cs.body_translation_begin,
                                               cs.body_translation_end, cs.collider_strands, pl.model.vertex.vertex_is_fixed))
    if not (np.array_equal(rb, re) and np.array_equal(tb, te)):
        return None
    return (float(dt), tuple(float(c) for c in gravity), cfg.margin, cfg.mass_splitting, cfg.weight_time, cfg.hair_hair,
            cfg.keep_rest_overlaps, cfg.max_contacts_per_edge, rb.tobytes(), tb.tobytes(), strands.tobytes(), fixed.tobytes())


def kept_contacts(pl, x, key) -> bool:
    """Keep the last detection's contacts for this step of pipeline ``pl`` where ``key`` (:func:`reuse_key`) matches
    the detection's, its impulses were kept (``contact.warm``) and no vertex has moved more than ``redetect_share`` x
    margin since: measure them at x, carry each impulse to itself.  Returns whether it did."""
    from ..config import MassSplitting

    cfg = pl.config
    if key is None or key != pl._detection_key or not pl._warm_valid or pl._warm is None:
        return False
    if max_displacement(x, pl._detected_at) > cfg.redetect_share * cfg.margin:
        return False
    refresh_contacts(x, pl.vertex_radius, pl.colliders, pl.con, cfg.friction)
    refresh_impulses(pl.con, pl._warm, cfg.mass_splitting == MassSplitting.BATCH, pl.uses_batches(False))
    pl.late_body_contacts = pl.continuous_contacts = pl.capped_queries = pl.ccd_skipped = 0
    pl.contacts_reused = True
    pl.reuse_count += 1
    return True


def prepare_reuse(pl, x) -> None:
    """Run the kept contacts' kernels once, at the first detection whose contacts a step may keep, so that they compile
    with the first frame and not in a later one (a still groom's third frame took 0.9-1.2 s instead of 0.3 s, measured
    on the grooming benchmark).  At the detection's own positions they measure the contacts as it did (to rounding)
    and, the impulses kept being none yet (a new ``contact.warm`` buffer, zero), leave r~ and lambda_z at zero as the
    detection does.  Nothing is run where impulses are already kept (they belong to other contacts)."""
    from ..config import MassSplitting
    from ..fields import WarmFields

    pl._reuse_ready = True
    if pl._warm is not None:
        return
    pl._warm = WarmFields(pl.con.capacity, pl.model.vertex_count)
    max_displacement(x, pl._detected_at)
    refresh_contacts(x, pl.vertex_radius, pl.colliders, pl.con, pl.config.friction)
    refresh_impulses(pl.con, pl._warm, pl.config.mass_splitting == MassSplitting.BATCH, pl.uses_batches(False))
