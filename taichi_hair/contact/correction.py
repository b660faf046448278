"""The geometric contact correction at the end of a step (Daviet 2023, Algorithm 1, last line), for a
:class:`~taichi_hair.contact.pipeline.ContactPipeline` (``ContactPipeline.correct`` calls :func:`correct`): x itself
is projected onto the contacts, with the edge lengths held, re-linearised every few sweeps, until no contact is
deeper than the tolerance or a cap of sweeps is reached.
"""

import numpy as np
import taichi as ti

from ..config import CorrectionEdgeOrder, CorrectionLengths, MassSplitting
from ..solver_base import on_gpu

from .narrow import SPLIT_NONE, relinearize_contacts
from .projection import (contact_statistics, correction_end, correction_sweep, hold_lengths_sweep, projection_begin,
                         projection_sweep, store_edge_lengths)

#: Edge-length passes that end the length-holding correction (:func:`correct`), before each
#: depth check.  8, not 4: measured (24 frames of assets/scenes/head_turn.toml) strain p99 / max 0.042 / 0.29 %
#: with 4 and 0.026 / 0.19 % with 8; the hairball (300 strands, 12 frames) 0.18 / 0.79 % and 0.13 / 0.66 %,
#: its hair-pair penetration p99 (worst frame) 36 and 32 um.  Not 16, although the contacts solved one by one
#: (``correction_contact_order``) meet the depth tolerance sooner and left one impact edge of the 300-strand
#: hairball 0.19 % long (0.05 % with 16): with 16 the stick-slip validation's onset error went from within 5 % to
#: 81 % (tests/test_stick_slip.py; 2026-12-05; as I read it, the passes slide its frictional tip).
_FINAL_EDGE_PASSES = 8
#: Plain sweeps after each (re)start of the correction before the Chebyshev acceleration begins (Wang 2015's S).
_CHEBYSHEV_DELAY = 3


def correct(pl, x, x0, sweeps: int) -> None:
    """Geometric contact correction at the end of the step (Alg. 1, last line): project x itself.

    Contacts are re-linearised at x first unless ``ContactConfig.relinearize_correction`` is off
    (x0: x^t), then again at the corrected positions every ``correction_relinearize_every`` sweeps
    (each time the correction restarts from them with fresh corrections), with the correction's own
    Delassus diagonal (``correction_mass_splitting``) and, unless ``correction_hair_friction``,
    frictionless hair-hair contacts.  Unless ``ContactConfig.correction_lengths`` is ``"free"`` (the
    paper's correction, which moves the contact vertices alone) each sweep also projects every edge back
    to its rest length (``"rest"``, default) or to its length before the correction (``"before"``)
    (``projection.correction_sweep``), and edge passes end it.  Sweeps are Chebyshev-accelerated
    (``correction_chebyshev_rho``).  After ``sweeps`` sweeps the correction goes on, 5 at a time, while
    a contact is deeper than ``correction_tolerance``, up to ``correction_max_iterations`` in all; the
    depth is checked after the final edge passes, on what the correction would return.  With
    ``late_body_contacts`` each restart first gives a body contact to every vertex the correction brought
    within reach of a body without one, and where the correction would stop and such vertices remain, it
    adds their contacts and sweeps ``correction_relinearize_every`` (or 10) more times, once, past the cap
    if need be.  Measured (the 16,000-strand hairball resumed after frame 12, a substep at the 80-sweep
    cap, scratch probe): 4 vertices 0.3-0.9 mm inside the ball after the correction, none with a body
    contact, each 0.3-1.3 mm outside before it and moved 1.4-2.3 mm by the pile's pushes.

    Why (issue 12, ``benchmarks/probes/penetration.py``, hairball 300 strands, frame 10): with one
    linearisation, batch mass splitting and friction the correction stalled at tip clumps of 17-20
    contacts per vertex (p99 penetration 74 um after its 40 sweeps, 54 um after 320); re-linearising
    every 10 sweeps, no mass splitting and frictionless hair pairs gave 54 / 29 um after 40 / 80
    sweeps, and with the acceleration 20 / 3 um (from another run's frame 10: 88 / 55 um without it).
    """
    m = pl.model
    cfg = pl.config
    hold = cfg.correction_lengths != CorrectionLengths.FREE
    along = (cfg.correction_edge_order == CorrectionEdgeOrder.STRANDS
             or (cfg.correction_edge_order == CorrectionEdgeOrder.AUTO and not on_gpu()))
    split = {MassSplitting.BATCH: True, MassSplitting.VERTEX: False, MassSplitting.NONE: SPLIT_NONE}[
        cfg.correction_mass_splitting]
    frictionless = not cfg.correction_hair_friction
    every = cfg.correction_relinearize_every if cfg.relinearize_correction else 0
    if cfg.relinearize_correction:
        # (Without it the correction keeps the detection's D_hat and friction coefficients.)
        relinearize_contacts(x, x0, pl.vertex_radius, pl.colliders, pl.con, split, frictionless,
                             pl.uses_batches(pl._dynamic))
    if hold:
        store_edge_lengths(m.edge, x, pl.edge_held_length, cfg.correction_lengths == CorrectionLengths.REST)
    projection_begin(x, pl.con, True)
    serial, small = pl._correction_order(), pl._serial_strands
    tol = cfg.correction_tolerance if cfg.correction_tolerance > 0 else 0.25 * pl.max_radius
    cap = max(sweeps, cfg.correction_max_iterations)
    rho = cfg.correction_chebyshev_rho
    if rho > 0 and pl._cheb is None:
        pl._cheb = (ti.Vector.field(3, float, m.vertex_count), ti.Vector.field(3, float, m.vertex_count))
    late = cfg.late_body_contacts and pl.colliders.count > 0
    extended = False  # the one extension for body contacts found at the end (below)
    done = 0
    since = 0  # sweeps since the last (re)start
    omega = 1.0
    target = sweeps
    while target > 0:
        if hold:
            correction_sweep(m.vertex, m.edge, m.strand, pl.con, pl.edge_held_length, along, serial,
                             small)
        else:
            projection_sweep(pl.con, serial)
        done += 1
        since += 1
        if rho > 0:
            if since < _CHEBYSHEV_DELAY:
                chebyshev_step(m.vertex, pl.con, pl._cheb[0], pl._cheb[1], 1.0, 1, small)
            else:
                omega = 2.0 / (2.0 - rho * rho) if since == _CHEBYSHEV_DELAY else 4.0 / (4.0 - rho * rho * omega)
                chebyshev_step(m.vertex, pl.con, pl._cheb[0], pl._cheb[1], omega, 0, small)
        if done == target:
            if hold:
                # Edge passes alone: each Gauss-Seidel sweep leaves the colour projected first off by a
                # fraction of the last contact push (a 0.4 mm push measured 0.18 % after one pass).  They
                # run before the depth check, so the check sees what the correction would return (they
                # re-open contacts: p99 12 -> 36 um, measured on the hairball, when they ran after it).
                hold_lengths_sweep(m.vertex, m.edge, m.strand, pl.con, pl.edge_held_length, along, small,
                                   _FINAL_EDGE_PASSES)
            stop = done >= cap
            if not stop:
                # Past the fixed sweeps, go on in groups of 5 while a contact is deeper than the tolerance.
                contact_statistics(pl.con.vertex_z, pl.vertex_radius, pl.colliders, pl.con,
                                   pl.stats_out, False)
                o = pl.stats_out.to_numpy()
                stop = max(o[3], o[4]) <= tol
            if stop and late and not extended:
                # The correction's own pushes can carry a vertex with no body contact into a body (the
                # hair of a dense pile pressing it down): give those vertices their contacts and sweep
                # ``every`` (10) more times, once, past the cap if need be.
                correction_end(m.vertex, x, pl.con)
                extended = True
                if pl.detect_late_body(x) > 0:
                    target = cap = done + max(every, 10)
                    _restart(pl, x, x0, split, frictionless)
                    since = 0
                    continue
            if stop:
                break
            target = min(target + 5, cap)
        if every > 0 and done % every == 0:
            # Re-linearise at the corrected positions and restart from them (fresh corrections r~ = 0):
            # the closest points and normals of deep pairs move by more than their penetration.  Vertices
            # the correction pushed within reach of a body without a contact get one first.
            correction_end(m.vertex, x, pl.con)
            if late:
                pl.detect_late_body(x)
            _restart(pl, x, x0, split, frictionless)
            since = 0
    pl.correction_sweeps_last = done
    correction_end(m.vertex, x, pl.con)


def _restart(pl, x, x0, split, frictionless) -> None:
    """Re-linearise every contact at x and restart the correction from it (z = x, r~ = 0)."""
    relinearize_contacts(x, x0, pl.vertex_radius, pl.colliders, pl.con, split, frictionless,
                         pl.uses_batches(pl._dynamic))
    projection_begin(x, pl.con, True)


@ti.kernel
def chebyshev_step(vertex: ti.template(), con: ti.template(), prev: ti.template(), cur: ti.template(), omega: float,
                   first: ti.i32, serial: ti.template()):
    """Chebyshev semi-iterative acceleration of the correction's sweeps (Wang 2015, for position-based
    projections): z_{k+1} = omega (z~_{k+1} - z_{k-1}) + z_{k-1}, with z~ the sweep's result; ``prev`` and
    ``cur`` hold z_{k-1} and z_k and move on by one.  ``first`` (1 or 0): only record z (omega unused); a launch
    argument, not a compile-time one, so that both uses share one kernel instance; ``serial``: on the launching
    thread."""
    ti.loop_config(serialize=serial)
    for i in range(con.vertex_z.shape[0]):
        zt = con.vertex_z[i]
        if first:
            prev[i] = zt
            cur[i] = zt
        elif vertex.vertex_is_fixed[i] == 0:
            zn = omega * (zt - prev[i]) + prev[i]
            prev[i] = cur[i]
            cur[i] = zn
            con.vertex_z[i] = zn


#: The end-of-step correction's "rest" lengths take the rest length for the length: warn when a material
#: stretches more than this under its own weight (the root strain rho g L / E_s of a hanging strand) [-].
SOFT_STRETCH_WARNING = 1.0e-3


def warn_soft_rest_lengths(model, config) -> None:
    """A warning naming the softest strand when ``correction_lengths="rest"`` would erase a real stretch."""
    if config.correction_lengths != CorrectionLengths.REST:
        return
    h = model.host
    le = np.asarray(h["edge_rest_length"], np.float64)
    real = le > 0
    strand = h["vertex_strand"]
    ns = model.strand_count
    area = np.asarray(h["strand_area"], np.float64)[strand]
    e_s = np.zeros_like(le)
    e_s[real] = np.asarray(h["edge_stretch_stiffness"], np.float64)[real] / (area[real] * le[real])
    length = np.bincount(strand, weights=le, minlength=ns)
    e_min = np.full(ns, np.inf)
    np.minimum.at(e_min, strand[real], e_s[real])
    strain = np.asarray(h["strand_density"], np.float64) * 9.81 * length / e_min
    s = int(np.argmax(strain))
    if strain[s] > SOFT_STRETCH_WARNING:
        import warnings

        warnings.warn(f"strand {s} stretches by {100 * strain[s]:.2g} % under its own weight (rho g L / E_s), but "
                      "ContactConfig.correction_lengths='rest' holds every edge at its rest length after contacts: "
                      "use correction_lengths='before' to keep a soft material's stretch", stacklevel=3)
