"""SolverShape: the TressFX-style real-time solver of Han & Harada 2012, "Real-time Hair Simulation
with Efficient Hair Style Preservation", as a short sequence of kernel launches.

Per step, ``config.substeps`` times over ``dt / substeps`` (the paper's Algorithm 1 with two stages of
AMD's TressFX 4 and one of Mueller et al. 2012; kernels in :mod:`taichi_hair.solvers.shape.integration`,
:mod:`~taichi_hair.solvers.shape.constraints`, :mod:`~taichi_hair.solvers.shape.lengths` and
:mod:`~taichi_hair.solvers.shape.collisions`):

1. head transform W_T_H of each strand        -- ``interpolate_body_transforms``,
   ``compute_head_rotations`` (Sec. 3.1), at the end of the substep
2. forces (gravity, wind) and integration    -- ``begin_substep``, ``integrate`` (Sec. 3.2, Verlet)
2b. velocity shock propagation (TressFX)     -- ``compute_shock_coefficients`` (once per step),
   ``propagate_velocity_shock``
3. global shape constraints                  -- ``apply_global_shape_constraints`` (Sec. 3.3, Eq. 2)
4. local shape constraints, iterated         -- Sec. 3.4, Eq. 4, with the transforms of Sec. 4.2:
   Method 1 ``apply_local_shape_constraints_serial`` (Algorithm 3, serial per strand),
   Method 2 ``initialize_global_transforms``, then ``apply_local_shape_constraints_batch`` +
   ``update_global_transforms_jacobi`` (Algorithm 4, Jacobi, parallel per vertex),
   Method 3 ``apply_local_shape_constraints_batch(use_rest=True)`` (Algorithm 5, rest transforms)
5. edge length constraints, iterated         -- ``solve_edge_lengths_batch`` [MHHR07]
6. collision handling                        -- ``project_collisions`` (Sec. 3.5), against the colliders of
   :mod:`taichi_hair.contact.colliders` (planes, spheres, capsules, mesh SDFs), the ones SolverADMM uses
6b. exact lengths, root to tip               -- ``follow_the_leader`` (Mueller et al. 2012)
7. v = (x - x^t)/dt - s d_{i+1}/dt           -- ``end_substep``; after the last substep ``find_non_finite``

Why the last three additions (the paper's scheme alone stretches hair at real gravity): TressFX applies
9.82 scene units/s^2 to centimetre assets, about 1 % of real gravity, and its iteration counts (2-3
length iterations, Table 2) were set for that.  In SI units the predicted positions move g dt^2 per
step, and two Jacobi batches of length constraints cannot pull a 16-vertex chain back: the edges of
the batch projected first are left stretched several times over.  So:

* Substeps: K substeps of dt/K shrink the per-substep sag by K^2.  The bodies' transforms are
  interpolated over the step (rotations slerped, translations linear) from the previous step's
  control, so roots, global goals and colliders move a K-th of the way each substep.  A region's
  S_G and damping c are per step in the config and become ``1 - (1 - S)^(1/K)`` per substep, so a
  step shrinks the distance to the global goal, and the velocity, by the configured factor whatever K;
  iteration counts and S_L apply per substep (more substeps hold the local shape more firmly).
* Follow-the-leader (FTL): after the iterated constraints and the collisions each strand is walked from
  root to tip and every free vertex put at its rest length from its predecessor, along the current edge.
  This is where TressFX's length constraints and Han & Harada's scheme go at convergence when the
  root side is held, and it makes every edge exact (to rounding) in one pass.  A vertex the pass puts
  inside a collider is pushed out along the normal (no friction: that was applied in stage 6); only
  then is that edge off its length.
* FTL treats each vertex as infinitely heavier than the next one, and that adds energy: a horizontal
  strand released under gravity with no damping whips, its energy climbing above the start.  Mueller
  et al.'s velocity correction ("dynamic FTL") gives vertex i the move its follower's correction would
  have given it in a mass-weighted solve, v_i -= s d_{i+1}/dt.  We chose s = 1
  (``length_velocity_correction``): on a 16-vertex, 30 cm strand stepped at 1/96 s, s = 1 kept the
  energy below its start at 1, 2 and 4 substeps, while s = 0.9 (the factor a little below 1 that
  implementations of the paper use) still let it rise above the start at 2 and 4 substeps, and s = 0
  rose by several times the strand's potential drop (tests/test_solver_shape.py checks s = 1 and
  s = 0 on an 11-vertex strand).  The price, which we accept and state: the correction is a velocity, not a motion.
  A strand at rest under gravity reports a velocity, about g dt/K times the number of vertices beyond
  each vertex (each substep gravity's prediction is undone by FTL and its correction carried down the
  strand), while its positions do not move; and it sags a little further than with s = 0.  Setting
  s = 0 gives v = (x - x^t)/dt back.  A mass-symmetric variant (the correction relative to the
  predecessor's, d_{i+1} - d_i) removes that bias but gave the energy gain back; we did not keep it.
* Velocity shock propagation (VSP, TressFX 4's simulation shader): each substep the rigid motion of
  the root edge (the shortest arc between its directions at the start and end of the substep, and the
  root's translation) is blended with weight w into both the positions and the previous positions of
  the strand's free vertices.  Moving both carries the hair with the head without adding the head's
  velocity to it.  As in TressFX, w is ``shock_propagation`` unless the second root vertex's
  acceleration over the step exceeds ``shock_acceleration_threshold`` (TressFX measures it in scene
  units per frame^2; here m/s^2), then 1.  The default weight is 0 and the threshold 50 m/s^2 (about
  5 g): ordinary head motion is left to the dynamics, and a violent jerk or a teleport carries the
  strands rigidly instead of tearing them along.  With VSP acting, the State's velocity is the Verlet
  velocity relative to the carried positions.

Choices where the paper is silent (each is also stated where it is implemented):

* Kinematic vertices are the model's ``vertex_is_fixed`` ones (vertices 0 and 1 of a clamped
  strand, as in Sec. 3.2); they follow their body's transform at the end of each substep.
* Velocity form of Verlet: x_prev is x^t - v dt with the State's velocity, so the State stays
  usable by other solvers; the damping coefficient c in [0, 1] scales that term by (1 - c).
* Wind: acceleration ``air_drag (v_air - v)_perp``, the relative air velocity normal to the strand
  (``control.air_velocity`` is the wind).  It is explicit: ``air_drag dt / substeps`` must stay below 1.
* S_G ramp: full S_G up to ``global_range (1 - global_falloff)`` of the rest arc length from the
  root, then linear to zero at ``global_range`` (``falloff = 0`` is TressFX's cut-off).
* Eq. 4 with a kinematic P_{i-1}: P_i takes the whole S_L d (inverse-mass weighting); edge length
  constraints weight the two ends the same way, so masses only enter as fixed/free, as in the paper.
* Method 3 uses the rest rotations carried by the head, ``R_H R_{i-1}^0``, with the origin at the
  current P_{i-1} (the frame's translation is always the current vertex).
* Method 2 starts each step from ``R_H R_i^0``, the rest transforms carried by the head, so a
  step depends on the State alone.  We tried keeping the transforms from the previous step
  instead: curly strands then never settle (frames moved from step to step pick up a twist that
  space-parallel transport from the root would not have, the goal shapes turn about the strand,
  and 3 curly 20-vertex strands with 3 iterations and damping 0.2 still moved at 0.6 m/s after
  600 steps, against 2e-6 m/s from the head-carried start).
* Free strands (no body): no global constraint (there is no head to carry the goal); their root
  frame is the rest frame turned by the shortest arc onto the current root edge, and their "head"
  rotation (for Method 3 and Method 2's first transforms) the same arc at the start of the step.
* Frame 0's y axis is the model's ``strand_root_director`` (the paper's "arbitrary vector").
* Collisions (Sec. 3.5 only says a vertex inside a collider moves to its surface): a free vertex
  whose signed distance d to a collider is below its strand's hair radius ``RodMaterial.radius``
  (read at construction) moves by ``radius - d`` along the collider's distance gradient, so the
  hair's surface touches the body, as in SolverADMM's body contacts.  Colliders follow their body's
  end-of-substep transform (interpolated from ``control``), like the roots.  The collider's ``strands`` range (collision
  groups) is honoured.
* Friction, which the paper leaves out of this step: each collider's Coulomb coefficient mu is
  applied as position-based friction (PBD, Mueller et al. 2007; Macklin et al. 2014): the vertex's
  displacement over the substep relative to the collider (body frame, begin- and end-of-substep body
  transforms) loses its tangential part up to mu times the normal correction.  ``friction = 0``
  gives the paper's frictionless projection (the colliders' default is 0.3).  A vertex resting on
  a slope is pushed in by g cos(slope) h^2 per substep of h, so it holds while tan(slope) < mu and slides
  with acceleration g (sin - mu cos) otherwise, as in Coulomb's law (tested).  The first step after
  construction, :meth:`set_colliders` or :meth:`reset_collider_motion` sees no body motion.
  After the friction move the distance is evaluated again and any remaining penetration projected
  out along the normal (a concave surface, or the first-order step on a mesh SDF).
* Regions: each strand has a region id; a region has its own S_G, range, falloff, S_L, iteration
  counts and damping.  Methods 2 and 3 launch the largest iteration count and skip the strands
  whose region has fewer.

Behaviour worth knowing (measured in tests/test_solver_shape.py and benchmarks/bench_shape.py):

* Eq. 4 anchors a strand only through its root, so the local constraints relax like a
  Gauss-Seidel chain: reaching the rest shape takes O(m^2) iterations for m vertices (300
  iterations bring 8-vertex strands within 1e-5 m; 20-vertex strands are still mm away after
  1000).  With the paper's 3-4 iterations the global constraints hold the style near the root.
* Without the follow-the-leader pass (``follow_the_leader = False``, the paper's scheme) edge lengths
  are PBD constraints in two batches; the stretch under gravity falls with the iteration count and
  the substeps but is large at the paper's counts in SI units (figures in BENCHMARKS.md).  With it
  every edge is at its rest length after each substep, to single-precision rounding, except where a
  collider pushed the vertex the pass placed.
* Collision projection comes last for each vertex (stage 6, and again inside the follow-the-leader
  pass): after a step no free vertex is closer than a hair radius to an analytic collider (to a mesh:
  within the SDF's interpolation error, a fraction of a voxel), but edges between two outside
  vertices may still cut a thin collider (vertex-based, as in TressFX).

The step allocates nothing: all fields are created in ``__init__``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import taichi as ti

from ...solver_base import SolverBase
from . import collisions, integration, lengths
from . import constraints as sc
from ...model import Model, _np_float
from ...state import Control, State

METHODS = (1, 2, 3)
#: Profiled stages (``SolverShape(profile=True)``).
STAGES = ("integrate", "shock", "global", "local", "length", "collide", "leader", "end")
_FIELD_NAMES = ("vertex_position", "vertex_velocity")


def _check_unit_interval(owner: str, name: str, value) -> None:
    if not (isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
            and 0.0 <= value <= 1.0):
        raise ValueError(f"{owner}.{name} must be a number in [0, 1], got {value!r}")


def _check_count(owner: str, name: str, value) -> None:
    if not (isinstance(value, (int, np.integer)) and not isinstance(value, bool) and value >= 0):
        raise ValueError(f"{owner}.{name} must be an integer >= 0, got {value!r}")


@dataclass
class ShapeRegion:
    """Parameters of one region of strands (Sec. 5, Fig. 1: front, top, ponytail...).

    Attributes:
        global_stiffness: S_G of Eq. 2 at the root, in [0, 1]; 0 disables the global
            constraint, 1 freezes the affected vertices onto W_T_H P_i^0 [-].
        global_range: fraction of the strand's rest arc length, from the root, that the
            global constraint acts on, in [0, 1] (the paper's "global constraint range") [-].
        global_falloff: fraction of ``global_range`` over which S_G decreases linearly to
            zero at its end, in [0, 1]; 0 is a hard cut-off, 1 a ramp from the root [-].
        local_stiffness: S_L of Eq. 4, in [0, 1] [-].
        local_iterations: local shape constraint iterations per step (Algorithm 1 l.7) [-].
        length_iterations: edge length constraint iterations per step (Algorithm 1 l.9) [-].
        damping: Verlet damping coefficient c in [0, 1]: the velocity term of the
            integration is scaled by (1 - c) each step (Sec. 3.2) [-].
    """

    global_stiffness: float = 0.1
    global_range: float = 0.3
    global_falloff: float = 1.0
    local_stiffness: float = 0.8
    local_iterations: int = 3
    length_iterations: int = 2
    damping: float = 0.05

    def __post_init__(self):
        for name in ("global_stiffness", "global_range", "global_falloff", "local_stiffness", "damping"):
            _check_unit_interval("ShapeRegion", name, getattr(self, name))
        for name in ("local_iterations", "length_iterations"):
            _check_count("ShapeRegion", name, getattr(self, name))


@dataclass
class SolverShapeConfig:
    """Settings of :class:`SolverShape` (Han & Harada 2012).

    Attributes:
        method: how local and global transforms are updated for the local shape constraints
            (Sec. 4.2): 1 serial per strand (exact), 2 Jacobi-parallel per vertex, 3 rest-state
            transforms [-].
        regions: one :class:`ShapeRegion` per region; strands pick theirs through the
            ``strand_region`` argument of :class:`SolverShape` [-].
        air_drag: rate at which a vertex's velocity normal to the strand relaxes towards the
            wind ``control.air_velocity``; ``air_drag * dt / substeps`` must stay below 1 [1/s].
        substeps: substeps per :meth:`SolverShape.step`, each of ``dt / substeps`` with the body
            transforms interpolated over the step; a region's S_G and damping are converted so that
            a whole step keeps their effect (see the module docstring), its iteration counts and S_L
            apply per substep [-].
        follow_the_leader: after the iterated constraints and the collisions, walk each strand from
            root to tip and put every free vertex at its rest length from its predecessor (exact
            lengths; False: the paper's iterated constraints alone, which stretch under gravity) [-].
        length_velocity_correction: s in [0, 1] of the follow-the-leader velocity correction of
            Mueller et al. 2012, ``v_i -= s d_{i+1} / dt`` with d the pass's vertex moves; 0 keeps
            ``v = (x - x^t) / dt`` [-].
        shock_propagation: TressFX's velocity shock propagation weight w in [0, 1]: each substep the
            root edge's rigid motion is blended with weight w into the positions and previous
            positions of the strand's free vertices; 0 disables it below the threshold [-].
        shock_acceleration_threshold: root acceleration above which a strand's shock propagation
            weight is 1 for the step (TressFX's "VSP acceleration threshold", in SI units); inf
            never [m/s^2].
        check_finite: check every position and velocity after each step and raise
            :class:`SimulationDivergedError` on NaN/inf [-].
    """

    method: int = 2
    regions: tuple = field(default_factory=lambda: (ShapeRegion(),))
    air_drag: float = 1.0
    substeps: int = 2
    follow_the_leader: bool = True
    length_velocity_correction: float = 1.0
    shock_propagation: float = 0.0
    shock_acceleration_threshold: float = 50.0
    check_finite: bool = True

    def __post_init__(self):
        if not (isinstance(self.method, (int, np.integer)) and not isinstance(self.method, bool)
                and self.method in METHODS):
            raise ValueError(f"SolverShapeConfig.method must be one of {METHODS}, got {self.method!r}")
        if isinstance(self.regions, ShapeRegion):
            self.regions = (self.regions,)
        self.regions = tuple(self.regions)
        if not self.regions:
            raise ValueError("SolverShapeConfig.regions must hold at least one ShapeRegion")
        for k, r in enumerate(self.regions):
            if not isinstance(r, ShapeRegion):
                raise ValueError(f"SolverShapeConfig.regions[{k}] must be a ShapeRegion, got {type(r).__name__}")
            r.__post_init__()  # re-validate: the dataclass may have been mutated
        if not (isinstance(self.air_drag, (int, float)) and math.isfinite(self.air_drag) and self.air_drag >= 0):
            raise ValueError(f"SolverShapeConfig.air_drag must be a finite number >= 0, got {self.air_drag!r}")
        if not (isinstance(self.substeps, (int, np.integer)) and not isinstance(self.substeps, bool)
                and self.substeps >= 1):
            raise ValueError(f"SolverShapeConfig.substeps must be an integer >= 1, got {self.substeps!r}")
        for name in ("follow_the_leader", "check_finite"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"SolverShapeConfig.{name} must be a bool, got {getattr(self, name)!r}")
        for name in ("length_velocity_correction", "shock_propagation"):
            _check_unit_interval("SolverShapeConfig", name, getattr(self, name))
        t = self.shock_acceleration_threshold
        if not (isinstance(t, (int, float)) and not isinstance(t, bool) and not math.isnan(t) and t >= 0):
            raise ValueError(f"SolverShapeConfig.shock_acceleration_threshold must be a number >= 0 (inf: never), "
                             f"got {t!r}")


class _BodyTransforms:
    """Body transforms at the end of a substep, laid out as :class:`Control` holds them (so a
    ``ColliderSet`` can take them): ``body_rotation`` 3x3, ``body_translation`` [m], shape (body_count,)."""

    def __init__(self, body_count: int):
        self.body_count = body_count
        self.body_rotation = ti.Matrix.field(3, 3, float, body_count)
        self.body_translation = ti.Vector.field(3, float, body_count)


class SolverShape(SolverBase):
    """Position-based hair solver with global and local shape constraints (Han & Harada 2012).

    Args:
        model: the :class:`Model` to simulate (the same one SolverADMM takes).
        config: :class:`SolverShapeConfig`.
        strand_region: region id of each strand, shape (strand_count,), values in
            ``[0, len(config.regions))``; default all 0.
        profile: if True, synchronise after each stage and accumulate wall times in
            ``stage_seconds`` (slower; for benchmarks).
        colliders: bodies the hair collides with: :class:`~taichi_hair.contact.colliders.PlaneCollider`,
            ``SphereCollider``, ``CapsuleCollider``, ``MeshCollider``, or a built
            :class:`~taichi_hair.contact.colliders.ColliderSet` (as SolverADMM takes them); None: none.

    Regions, strand regions and colliders may be edited between steps (an interactive tool's
    sliders, Sec. 6 Fig. 4): change ``config.regions`` and call :meth:`upload_regions`, call
    :meth:`set_strand_region`, or :meth:`set_colliders`.

    Fields (all allocated here, shape (vertex_count,) unless stated):
        vertex_rest_rotation: ^wR_i^0, rest global rotation of frame i, quaternion (x, y, z, w) [-].
        vertex_rest_local_position: ^{i-1}P_i^0, vertex i in rest frame i-1 (0 at the root) [m].
        vertex_rotation, vertex_rotation_temp: ^wR_i and ^wR_temp_i of Method 2, swapped after each
            iteration (the latest is :attr:`global_rotation`), quaternions [-].
        vertex_arc_fraction: rest arc length from the root over the strand's length [-].
        vertex_position_begin, vertex_velocity_begin: x^t [m] and v^t [m/s] of the step.
        vertex_position_substep: x^t of the substep, Verlet's previous position, moved with the
            strand by the shock propagation [m].
        vertex_length_correction: d_i, the follow-the-leader pass's move of vertex i in the last
            substep (0 on kinematic vertices) [m].
        strand_shock_coefficient: shock propagation weight w of the step, shape (strand_count,) [-].
        body_rotation_begin, body_translation_begin: the bodies' transforms at the beginning of the
            step (the previous step's control), shape (body_count,) [-], [m].
        substep_bodies: the bodies' transforms interpolated to the end of the current substep
            (``body_rotation``, ``body_translation``, as a :class:`Control` holds them).
        strand_region: region id, shape (strand_count,) [-].
        strand_head_rotation: ^wR_H of the strand's body, quaternion, shape (strand_count,) [-].
        region_*: the :class:`ShapeRegion` values, shape (region_count,).
        vertex_collision_radius: hair radius of the vertex's strand (``RodMaterial.radius``), the
            distance kept from colliders [m].
        colliders: the :class:`~taichi_hair.contact.colliders.ColliderSet` (its own fields), or None.
    """

    FIELD_NAMES = _FIELD_NAMES
    STAGES = STAGES

    def __init__(self, model: Model, config: SolverShapeConfig | None = None, strand_region=None,
                 profile: bool = False, colliders=None):
        self._init_base(model, profile)
        self.config = config or SolverShapeConfig()
        cfg = self.config
        cfg.__post_init__()
        n, ns = model.vertex_count, model.strand_count
        self.region_count = len(cfg.regions)
        regions = self._check_strand_region(strand_region)
        quat = ti.types.vector(4, float)
        # Static rest data (Algorithm 2).
        self.vertex_rest_rotation = ti.field(quat, n)
        self.vertex_rest_local_position = ti.field(ti.math.vec3, n)
        self.vertex_arc_fraction = ti.field(float, n)
        # Per-step data.
        self.vertex_rotation = ti.field(quat, n)
        self.vertex_rotation_temp = ti.field(quat, n)
        self.vertex_position_begin = ti.field(ti.math.vec3, n)
        self.vertex_velocity_begin = ti.field(ti.math.vec3, n)
        self.vertex_position_substep = ti.field(ti.math.vec3, n)
        self.vertex_length_correction = ti.field(ti.math.vec3, n)
        self.strand_shock_coefficient = ti.field(float, ns)
        nb = max(1, model.body_count)
        self.body_rotation_begin = ti.Matrix.field(3, 3, float, nb)
        self.body_translation_begin = ti.Vector.field(3, float, nb)
        self.substep_bodies = _BodyTransforms(nb)
        self._has_body_begin = False
        self.strand_region = ti.field(ti.i32, ns)
        self.strand_head_rotation = ti.field(quat, ns)
        # Regions.
        nr = self.region_count
        self.region_global_stiffness = ti.field(float, nr)
        self.region_global_range = ti.field(float, nr)
        self.region_global_falloff = ti.field(float, nr)
        self.region_local_stiffness = ti.field(float, nr)
        self.region_local_iterations = ti.field(ti.i32, nr)
        self.region_length_iterations = ti.field(ti.i32, nr)
        self.region_damping = ti.field(float, nr)
        # Colliders (Sec. 3.5).
        self.vertex_collision_radius = ti.field(float, n)
        self.colliders = None
        self._bad = ti.field(ti.i32, ())

        self.strand_region.from_numpy(regions)
        self.set_colliders(colliders)
        self._set_coefficients()
        self.upload_regions()
        self.vertex_rotation.copy_from(self.vertex_rest_rotation)
        #: Method 2's latest global transforms ^wR_i (one of the two buffers) [-].
        self.global_rotation = self.vertex_rotation

    def _set_coefficients(self) -> None:
        """What the solver derives from the Model: collision radii, rest arc fractions, rest transforms."""
        model, h, n, f = self.model, self.model.host, self.model.vertex_count, _np_float()
        radius = np.array([mat.radius for mat in model.materials], np.float64)
        self.vertex_collision_radius.from_numpy(radius[h["vertex_strand"]].astype(f))
        # Rest arc-length fraction of each vertex, for the S_G ramp.
        starts, counts = h["strand_vertex_start"], h["strand_vertex_count"]
        le = h["edge_rest_length"]
        arc = np.zeros(n)
        for j in range(1, int(counts.max())):  # vectorised over strands, one local index at a time
            idx = starts[counts > j] + j
            arc[idx] = arc[idx - 1] + le[idx - 1]
        total = arc[starts + counts - 1]
        self.vertex_arc_fraction.from_numpy((arc / np.repeat(total, counts)).astype(f))
        sc.initialize_rest_transforms(model, self)

    # ------------------------------------------------------------------ set-up
    def upload_regions(self) -> None:
        """Copy ``config.regions`` to the region fields (call after editing a region between steps)."""
        regs = self.config.regions
        if len(regs) != self.region_count:
            raise ValueError(f"SolverShapeConfig.regions must keep its {self.region_count} regions "
                             f"(strands refer to them), got {len(regs)}")
        for r in regs:
            r.__post_init__()
        f = _np_float()
        for name in ("global_range", "global_falloff", "local_stiffness"):
            getattr(self, "region_" + name).from_numpy(np.array([getattr(r, name) for r in regs], dtype=f))
        # Per substep: 1 - (1 - c)^(1/K), so K substeps shrink the velocity (and the distance to the
        # global goal) by the configured factor per step, whatever K.
        k = self.config.substeps
        for name in ("global_stiffness", "damping"):
            per_step = np.array([getattr(r, name) for r in regs], dtype=np.float64)
            getattr(self, "region_" + name).from_numpy((1.0 - (1.0 - per_step) ** (1.0 / k)).astype(f))
        self._uploaded_substeps = k
        for name in ("local_iterations", "length_iterations"):
            getattr(self, "region_" + name).from_numpy(np.array([getattr(r, name) for r in regs], dtype=np.int32))
        self._max_local_iterations = max(r.local_iterations for r in regs)
        self._max_length_iterations = max(r.length_iterations for r in regs)
        self._any_global = any(r.global_stiffness > 0 and r.global_range > 0 for r in regs)

    def _check_strand_region(self, strand_region) -> np.ndarray:
        ns = self.model.strand_count
        if strand_region is None:
            return np.zeros(ns, np.int32)
        regions = np.asarray(strand_region).reshape(-1)
        if regions.shape != (ns,) or not np.issubdtype(regions.dtype, np.integer):
            raise ValueError(f"SolverShape.strand_region must be {ns} integers (one per strand), "
                             f"got shape {regions.shape} of {regions.dtype}")
        bad = np.where((regions < 0) | (regions >= self.region_count))[0]
        if bad.size:
            raise ValueError(f"SolverShape.strand_region[{int(bad[0])}] = {int(regions[bad[0]])} is not a "
                             f"region index in [0, {self.region_count})")
        return regions.astype(np.int32)

    def set_strand_region(self, strand_region) -> None:
        """Assign region ids, shape (strand_count,), values in [0, len(config.regions)) (None: all 0)."""
        self.strand_region.from_numpy(self._check_strand_region(strand_region))

    def set_colliders(self, colliders) -> None:
        """Replace the colliders (a list of :mod:`taichi_hair.contact.colliders` objects, a ``ColliderSet``, or
        None/empty for none).  A list is built into a new ``ColliderSet`` here (this allocates: call it
        between steps, not inside one).  As for any new ``ColliderSet``, the first step after this one
        sees no body motion (its begin-of-step transforms are its end-of-step ones), which only matters
        to friction."""
        self.colliders = self._collider_set(colliders)

    def reset_collider_motion(self) -> None:
        """Forget the bodies' last transforms: the next step sees no body motion (as the first step
        does).  Substeps interpolate the bodies from their last transforms and friction uses each
        collider's motion over a substep; call this after putting the State or the Control back in time
        (a reset, a restart), so a jump of the bodies is not read as motion."""
        self._has_body_begin = False
        if self.colliders is not None:
            self.colliders.has_begin = False

    # ------------------------------------------------------------------ stepping
    def step(self, state: State, control: Control, dt: float) -> None:
        """Advance ``state`` in place by one time step (Algorithm 1, ``config.substeps`` times).

        Args:
            state: positions and velocities at the beginning of the step (twists are not used).
            control: body transforms at the *end* of the step (W_T_H of each strand's root body),
                gravity, and air velocity (the wind).
            dt: time step [s].

        Raises:
            ValueError: for a bad ``dt`` or ``air_drag * dt / substeps >= 1``.
            SimulationDivergedError: if a position or velocity becomes non-finite; ``state`` is then
                restored to the beginning of the step.
        """
        self._check_dt(dt)
        cfg, m = self.config, self.model
        cfg.__post_init__()
        k_sub = cfg.substeps
        h = dt / k_sub
        if cfg.air_drag * h >= 1.0:
            raise ValueError(f"SolverShapeConfig.air_drag * dt / substeps must be < 1 for the explicit wind "
                             f"term, got {cfg.air_drag} * {dt} / {k_sub}")
        if self._uploaded_substeps != k_sub:
            self.upload_regions()
        x, v = state.vertex_position, state.vertex_velocity
        rot, tr = control.body_rotation, control.body_translation
        if not self._has_body_begin:  # first step (or after reset_collider_motion): no body motion before
            self.body_rotation_begin.copy_from(rot)
            self.body_translation_begin.copy_from(tr)
            self._has_body_begin = True
        t0 = self._tick()
        integration.begin_step(x, v, self)
        t0 = self._tock("integrate", t0)
        shock = cfg.shock_propagation > 0.0 or math.isfinite(cfg.shock_acceleration_threshold)
        if shock:
            integration.compute_shock_coefficients(m, self, rot, tr, cfg.shock_propagation,
                                                   min(cfg.shock_acceleration_threshold, 1e30), dt)
        t0 = self._tock("shock", t0)
        for k in range(1, k_sub + 1):
            self._substep(state, control, k / k_sub, h, shock)
        self.step_count += 1
        t0 = self._tick()
        if cfg.check_finite:
            self.check_finite(state)  # raises with the state and the bodies' begin transforms kept
        # The next step's substeps interpolate from this step's end.
        self.body_rotation_begin.copy_from(rot)
        self.body_translation_begin.copy_from(tr)
        self._tock("end", t0)

    def _substep(self, state: State, control: Control, u: float, h: float, shock: bool) -> None:
        """One pass of Algorithm 1 over ``h``, ending at the fraction ``u`` of the step."""
        cfg, m = self.config, self.model
        x, v = state.vertex_position, state.vertex_velocity
        bodies = self.substep_bodies
        rot, tr = bodies.body_rotation, bodies.body_translation
        t0 = self._tick()
        # 1-2. Head transforms at the end of the substep, forces and Verlet integration (Sec. 3.1, 3.2).
        integration.interpolate_body_transforms(self.body_rotation_begin, self.body_translation_begin,
                                                control.body_rotation, control.body_translation, u, rot, tr)
        sc.compute_head_rotations(m, rot, x, self)
        integration.begin_substep(x, self)
        integration.integrate(m, self, rot, tr, ti.math.vec3(*control.gravity), ti.math.vec3(*control.air_velocity),
                              cfg.air_drag, h, v, x)
        t0 = self._tock("integrate", t0)
        # 2b. TressFX's velocity shock propagation: carry the strands with their root's motion.
        if shock:
            integration.propagate_velocity_shock(m, self, x)
        t0 = self._tock("shock", t0)
        # 3. Global shape constraints (Sec. 3.3, Eq. 2).
        if self._any_global:
            sc.apply_global_shape_constraints(m, self, rot, tr, x)
        t0 = self._tock("global", t0)
        # 4. Local shape constraints (Sec. 3.4, Eq. 4) with the transforms of Sec. 4.2.
        self._local_shape_constraints(x)
        t0 = self._tock("local", t0)
        # 5. Edge length constraints, in two batches of disjoint edges (Sec. 5).
        for it in range(self._max_length_iterations):
            lengths.solve_edge_lengths_batch(m, self, 0, it, x)
            lengths.solve_edge_lengths_batch(m, self, 1, it, x)
        t0 = self._tock("length", t0)
        # 6. Collision handling (Sec. 3.5), colliders at the end-of-substep body transforms.
        if self.colliders is not None:
            self.colliders.begin_step(bodies)
            collisions.project_collisions(m, self, self.colliders, x)
        t0 = self._tock("collide", t0)
        # 6b. Exact lengths: follow-the-leader from root to tip, colliders kept.
        if cfg.follow_the_leader:
            cs = self.colliders if self.colliders is not None else self
            lengths.follow_the_leader(self.colliders is not None, m, self, cs, x)
        t0 = self._tock("leader", t0)
        # 7. Velocities for the next Verlet substep (with the follow-the-leader correction).
        s_corr = cfg.length_velocity_correction if cfg.follow_the_leader else 0.0
        integration.end_substep(m, self, h, s_corr, x, v)
        self._tock("end", t0)

    def _local_shape_constraints(self, x) -> None:
        m, method = self.model, self.config.method
        if method == 1:  # Algorithm 3: one launch, strands in parallel, vertices and iterations serial.
            sc.apply_local_shape_constraints_serial(m, self, x)
        elif method == 2:  # Algorithm 4; ^wT_temp <- ^wT (l.3-5) by swapping the two buffers.
            cur, temp = self.vertex_rotation, self.vertex_rotation_temp
            sc.initialize_global_transforms(m, self, x, cur)
            for it in range(self._max_local_iterations):
                cur, temp = temp, cur
                sc.apply_local_shape_constraints_batch(False, m, self, temp, 0, it, x)
                sc.apply_local_shape_constraints_batch(False, m, self, temp, 1, it, x)
                sc.update_global_transforms_jacobi(m, self, temp, it, x, cur)
            self.global_rotation = cur
        else:  # Algorithm 5.
            for it in range(self._max_local_iterations):
                sc.apply_local_shape_constraints_batch(True, m, self, self.vertex_rest_rotation, 0, it, x)
                sc.apply_local_shape_constraints_batch(True, m, self, self.vertex_rest_rotation, 1, it, x)

    def _non_finite_code(self, state: State) -> int:
        integration.find_non_finite(self.model, state.vertex_position, state.vertex_velocity, self._bad)
        return int(self._bad[None])

    def _restore_begin(self, state: State) -> None:
        integration.restore_begin(self, state.vertex_position, state.vertex_velocity)
