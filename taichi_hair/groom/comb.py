"""The comb of a grooming session (Daviet 2023, Sec. 4.5 and 5.3).

A comb is one capsule "tooth" (a sphere brush when its length is 0), a frictional body collider of
the ADMM contact pipeline on its own body (``COMB_BODY``), present in the guides' solver from its
build on and idle between strokes.  A stroke:

1. :func:`stroke_positions`: the comb's positions along the path, in equal steps of at most
   ``step`` [m];
2. :func:`sweep`: one quasistatic solver step per move, with the comb's end-of-step transform in
   Control; returns which guides had a comb contact;
3. :func:`combed_strands`: those guides and the skinned strands bound to them, whose current pose
   the session then takes as rest pose (:func:`taichi_hair.groom.edits.rest_from_current`).

The stroke moves the comb's position along the polyline ``path`` (world coordinates [m])
in equal steps of at most ``step`` [m] (default ``radius / 2``), one quasistatic solver
step (``config.iterations`` ADMM iterations) per step, with the comb's end-of-step
transform in Control.  Contacts are detected at the beginning of a step and carry the
comb's surface point to its end-of-step position (Sec. 4.5), so hair ahead of the comb is
pushed (a vertex the comb overtakes stays in its front half as long as a step is shorter
than the radius, and is pushed forward, not backward; a step longer than the diameter
would jump over strands) and hair in touch is dragged along by friction, at most mu times
the normal force.  The hair is never moved directly.

The functions get the simulation objects (:class:`~taichi_hair.groom.simulation.GuideSimulation`)
as arguments; none of them holds or calls the session.
"""

from __future__ import annotations

import math
import time

import numpy as np

from .config import COMB_BODY, COMB_MAX_STEPS, _direction, _path, _positive
from .edits import _arc, _sample


def stroke_positions(path: np.ndarray, step: float) -> np.ndarray:
    """Positions of the comb along the polyline ``path`` (m, 3) [m] (repeated points skipped), in
    n equal steps of at most ``step`` [m]: (n + 1, 3), the last one ``path[-1]`` exactly.

    Raises:
        ValueError: a path that does not move, or one needing more than ``COMB_MAX_STEPS`` steps.
    """
    pts, h = path, step
    moving = np.r_[True, np.any(np.diff(pts, axis=0) != 0.0, axis=1)]
    knots = _arc(pts[moving])
    total = float(knots[-1])
    if total == 0.0:
        raise ValueError("'path' must move: its points are all equal")
    n = max(1, int(math.ceil(total / h * (1.0 - 1e-12))))
    if n > COMB_MAX_STEPS:
        raise ValueError(f"the path ({total:.4g} m) needs {n} steps of {h:.4g} m, more than {COMB_MAX_STEPS}; "
                         "pass a larger 'step'")
    positions = _sample(knots, pts[moving], np.linspace(0.0, total, n + 1))
    positions[-1] = pts[-1]
    return positions


def sweep(sim, positions: np.ndarray, radius: float, axis: np.ndarray, length: float, friction: float,
          frame_seconds: list) -> np.ndarray:
    """Move the comb collider of ``sim`` (a GuideSimulation) through ``positions`` (n + 1, 3) [m],
    one solver step per move; returns which guides (Model strands) had a comb contact, bool
    (guide_count,).  The comb is a capsule of ``radius`` [m] along the unit ``axis``, ``length`` [m]
    long, with Coulomb coefficient ``friction`` [-]; it is idle again afterwards.  The wall time of
    every step [s] is appended to ``frame_seconds``."""
    import taichi as ti

    solver, control = sim.solver, sim.control
    cs = solver.contacts.colliders
    k = sim.comb_collider
    half = 0.5 * length * axis
    cs.collider_a[k] = (-half).tolist()
    cs.collider_b[k] = half.tolist()
    cs.collider_radius[k] = radius
    cs.collider_friction[k] = friction
    # The first move starts at positions[0]: the begin-of-step transform of the comb body is the end
    # transform the ColliderSet keeps from the previous step (body 0, the head, never moves).
    control.body_translation[COMB_BODY] = positions[0].tolist()
    if not cs.has_begin:
        cs.body_rotation_end.copy_from(control.body_rotation)
        cs.body_translation_end.copy_from(control.body_translation)
        cs.has_begin = True
    cs.body_translation_end[COMB_BODY] = positions[0].tolist()
    cs.collider_strands[k] = [0, 2**31 - 1]
    touched = np.zeros(sim.model.strand_count, dtype=bool)
    vertex_strand = sim.model.host["vertex_strand"]
    try:
        for q in positions[1:]:
            t0 = time.perf_counter()
            control.body_translation[COMB_BODY] = q.tolist()
            solver.step(sim.state, control, 1.0)
            sim.note_step()
            con = solver.contacts
            nc = con.contact_count
            if nc:
                mine = con.con.contact_collider.to_numpy()[:nc] == k
                touched[vertex_strand[con.con.contact_vertex.to_numpy()[:nc, 0][mine]]] = True
            if touched.any():  # (guides held by shape springs: held where the comb left them, not pulled back)
                sim.shape_springs_follow(touched)
            ti.sync()
            frame_seconds.append(time.perf_counter() - t0)
    finally:
        cs.collider_strands[k] = [0, 0]  # idle: acts on no strand
    return touched


def combed_strands(touched: np.ndarray, guides: np.ndarray, skin, strand_count: int) -> np.ndarray:
    """Strands combed by a stroke, bool (strand_count,): the guides ``touched`` (bool per guide) and
    the skinned strands bound to one of them with a positive weight (``skin`` the SkinningLBS, or
    None when every strand is a guide)."""
    combed = np.zeros(strand_count, dtype=bool)
    combed[guides[touched]] = True
    if skin is not None:
        bound = skin.host["render_strand_guides"]
        weight = skin.host["render_strand_weights"]
        combed |= np.any(touched[bound] & (weight > 0.0), axis=1)
    return combed


def check_stroke(path, radius, axis, length, friction, step):
    """The checked arguments of a stroke (errors name the argument): ``(path (m, 3), radius, axis
    (3,), length, friction, step)`` in float64, ``step`` defaulting to ``radius / 2`` [m]."""
    pts = _path("path", path)
    r = _positive("radius", radius)
    ax, _ = _direction("axis", axis)
    length_ = _positive("length", length, allow_zero=True)
    mu = _positive("friction", friction, allow_zero=True)
    h = 0.5 * r if step is None else _positive("step", step)
    return pts, r, ax, length_, mu, h
