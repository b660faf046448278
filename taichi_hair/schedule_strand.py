"""The "strand" schedule: every ADMM iteration of a step in one kernel, one strand per thread.

The "stage" schedule (``SolverADMM.step`` with ``schedule="stage"``) launches
about nine kernels per ADMM iteration, each a parallel loop over *all*
vertices: local step, position assembly, tridiagonal solve, position update,
reference frames, pair twist terms, twist assembly, tridiagonal solve,
material frames.  That is the right shape for a GPU, where every vertex gets
its own thread.  On a CPU with a few cores it is not: every stage streams the
whole groom through memory, and the launch overhead dominates small scenes.

Strands are independent inside an ADMM iteration (contacts aside), so
:func:`admm_iterations_strand` runs one parallel loop over strands (the only
parallel loop of the kernel: Taichi parallelises the outermost loop), and,
for its strand, *all* iterations serially:

    for it in range(iterations):
        local step            (local_elasticity_at,     every pair)
        position assembly     (assemble_position_at,    every vertex)
        Thomas solve          (thomas_strand,           3 right-hand sides)
        x += dx               (apply_position_update_at)
        reference frames      (reference_frame_at,      every edge)
        reference twists      (reference_twist_at,      every pair; Bergou only)
        pair twist terms      (pair_twist_terms_at,     every pair)
        twist assembly        (assemble_twist_at,       every edge)
        Thomas solve          (thomas_strand,           1 right-hand side)
        theta += dtheta       (material_frame_at,       every edge)
        Anderson mixing       (anderson_mix_strand,     when anderson_window > 0; then the frames again)

or, when the twist unknowns are dropped (``twist_free``, ``frames.twist_choice``),
the last four replaced by the twist-free frames (``twist_free_strand``).

A strand's working set (a few kB for tens of vertices) stays in L1/L2 cache
across stages and iterations, and there is one launch per step instead of
~9 per iteration.

Each stage is a full serial loop over the strand before the next starts,
because of the same dependencies as between the staged kernels: the
assembly of vertex i reads the pair forces of i-1, i, i+1; the reference
twist of pair i needs the tangents and reference directors of edges i-1 and
i; the twist assembly of edge j reads the twist terms of pairs j and j+1; the
solves need the whole strand assembled.  The ``*_at`` functions are the
bodies of the stage kernels, so each element sees the same arithmetic in
the same order, and on CPU the two schedules give bit-identical states
(``tests/test_schedules.py``).  The tridiagonal solves are always Thomas.
"""

import taichi as ti

from .admm import (
    apply_position_update_at,
    assemble_position_at,
    assemble_twist_at,
    pair_twist_terms_at,
)
from .anderson import anderson_begin_strand, anderson_mix_strand
from .elasticity import local_elasticity_at
from .frames import material_frame_at, reference_frame_at, reference_twist_at, twist_free_strand
from .tridiag import thomas_strand

vec3 = ti.math.vec3


@ti.func
def strand_reference_frames(start, m, with_reference_twist: ti.template(), model: ti.template(),
                            body_rotation: ti.template(), x: ti.template(), theta: ti.template(), es: ti.template()):
    """Stage (e) for one strand: every edge's tangent and reference frame first, then (when the model has
    them) the reference twists, which read the frames of both edges of a pair."""
    for k in range(m):
        reference_frame_at(start + k, model.vertex, model.edge, model.strand, body_rotation, x, theta, es)
    if ti.static(with_reference_twist):
        for k in range(m):
            reference_twist_at(start + k, model.pair, es)


@ti.kernel
def admm_iterations_strand(
    measure: ti.template(),
    use_q: ti.template(),
    with_reference_twist: ti.template(),
    dynamic: ti.template(),
    twist_free: ti.template(),
    model: ti.template(),
    body_rotation: ti.template(),
    x: ti.template(),
    theta: ti.template(),
    es: ti.template(),
    buf: ti.template(),
    gravity: vec3,
    air_velocity: vec3,
    air_viscosity: float,
    dt: float,
    damping_scale: float,
    iterations: ti.i32,
    weight_floor: float,
    aa: ti.template(),
    window: ti.template(),
    anderson_on: ti.i32,
):
    """``iterations`` ADMM iterations (Algorithm 1, lines 4a-4g) for every strand, strands in parallel.

    Arguments as for the stage kernels: ``model`` serves as the vertex, edge,
    pair and strand groups; ``x``, ``theta``, ``es`` are the state;
    ``buf`` the solver buffers.  The frames must be up to date on entry
    (``update_reference_frames`` after ``begin_step``), as in the stage schedule.
    """
    for s in model.strand_vertex_start:
        start = model.strand_vertex_start[s]
        m = model.strand_vertex_count[s]
        if ti.static(window > 0):
            if anderson_on:
                anderson_begin_strand(s, start, m, model.edge, x, theta, buf, aa)
        for _it in range(iterations):
            # (a, c) Local elasticity solve and fused dual update, every pair of the strand.
            for k in range(m):
                i = start + k
                local_elasticity_at(i, measure, use_q, model.vertex, model.edge, model.pair, model.strand,
                                    body_rotation, x, theta,
                                    es, buf, damping_scale, weight_floor)
            # (d) Global step: assemble (reads pair forces i-1, i, i+1), solve, update.
            for k in range(m):
                i = start + k
                assemble_position_at(i, dynamic, model.vertex, model.edge, model.pair, x, buf, gravity, air_velocity,
                                     air_viscosity, dt, weight_floor)
            thomas_strand(start, m, buf.tri_lower, buf.tri_diag, buf.tri_upper, buf.tri_rhs3)
            for k in range(m):
                i = start + k
                apply_position_update_at(i, model.vertex, x, buf)
            # (e) Frames: every edge's tangent first, then the reference twists.
            strand_reference_frames(start, m, with_reference_twist, model, body_rotation, x, theta, es)
            if ti.static(twist_free):
                # (f, g) replaced: the exact twist of a naturally straight round rod (none).
                twist_free_strand(start, m, model.edge, theta, es, False)
            else:
                # (f) Twist Newton step.
                for k in range(m):
                    i = start + k
                    pair_twist_terms_at(i, measure, model.vertex, model.pair, model.strand, theta, es, buf, damping_scale)
                for k in range(m):
                    i = start + k
                    assemble_twist_at(i, dynamic, model.edge, model.pair, theta, buf, dt)
                thomas_strand(start, m, buf.tri_lower, buf.tri_diag, buf.tri_upper, buf.tri_rhs1)
                # (g) theta += dtheta, material frames.
                for k in range(m):
                    i = start + k
                    material_frame_at(i, model.edge, theta, es, buf.tri_rhs1)
            if ti.static(window > 0):
                # Anderson mixing of u = (x, lambda_y, theta), then the frames of the mix (anderson.py).
                if anderson_on:
                    if anderson_mix_strand(s, start, m, model.vertex, model.edge, x, theta, buf, aa, window,
                                           _it == iterations - 1):
                        strand_reference_frames(start, m, with_reference_twist, model, body_rotation, x, theta, es)
                        if ti.static(twist_free):
                            twist_free_strand(start, m, model.edge, theta, es, False)
