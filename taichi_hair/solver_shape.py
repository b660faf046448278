"""SolverShape: the TressFX-style real-time solver of Han & Harada 2012, "Real-time Hair Simulation
with Efficient Hair Style Preservation", as a short sequence of kernel launches.

Per step (the paper's Algorithm 1; kernels in :mod:`taichi_hair.shape_constraints`):

1. head transform W_T_H of each strand        -- ``compute_head_rotations`` (Sec. 3.1)
2. forces (gravity, wind) and integration    -- ``begin_step``, ``integrate`` (Sec. 3.2, Verlet)
3. global shape constraints                  -- ``apply_global_shape_constraints`` (Sec. 3.3, Eq. 2)
4. local shape constraints, iterated         -- Sec. 3.4, Eq. 4, with the transforms of Sec. 4.2:
   Method 1 ``apply_local_shape_constraints_serial`` (Algorithm 3, serial per strand),
   Method 2 ``initialize_global_transforms``, then ``apply_local_shape_constraints_batch`` +
   ``update_global_transforms_jacobi`` (Algorithm 4, Jacobi, parallel per vertex),
   Method 3 ``apply_local_shape_constraints_batch(use_rest=True)`` (Algorithm 5, rest transforms)
5. edge length constraints, iterated         -- ``solve_edge_lengths_batch`` [MHHR07]
6. collision handling                        -- ``project_collisions`` (Sec. 3.5), against the colliders of
   :mod:`taichi_hair.colliders` (planes, spheres, capsules, mesh SDFs), the ones SolverADMM uses
7. v = (x - x^t)/dt, finiteness check        -- ``end_step``, ``find_non_finite``

Choices where the paper is silent (each is also stated where it is implemented):

* Kinematic vertices are the model's ``vertex_is_fixed`` ones (vertices 0 and 1 of a clamped
  strand, as in Sec. 3.2); they follow their body's transform at the end of the step.
* Velocity form of Verlet: x_prev is x^t - v dt with the State's velocity, so the State stays
  usable by other solvers; the damping coefficient c in [0, 1] scales that term by (1 - c).
* Wind: acceleration ``air_drag (v_air - v)_perp``, the relative air velocity normal to the strand
  (``control.air_velocity`` is the wind).  It is explicit: ``air_drag dt`` must stay below 1.
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
  end-of-step transform (``control``), like the roots.  The collider's ``strands`` range (collision
  groups) is honoured.
* Friction, which the paper leaves out of this step: each collider's Coulomb coefficient mu is
  applied as position-based friction (PBD, Mueller et al. 2007; Macklin et al. 2014): the vertex's
  displacement over the step relative to the collider (body frame, begin- and end-of-step body
  transforms) loses its tangential part up to mu times the normal correction.  ``friction = 0``
  gives the paper's frictionless projection (the colliders' default is 0.3).  A vertex resting on
  a slope is pushed in by g cos(slope) dt^2 per step, so it holds while tan(slope) < mu and slides
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
* Edge lengths are PBD constraints in two batches; the stretch under gravity falls with the
  iteration count but is large at the paper's counts: 11-vertex, 20 cm horizontal strands
  hanging at dt = 1/60 s with S_L = S_G = 0 reach a largest edge stretch of 105 % with 2
  iterations, 17 % with 10, 0.3 % with 100 (single precision, CPU).  Long strands suffer most:
  on the ``hang`` scene with 64-vertex, 32 cm strands (Table 2's model 3 settings, 3 length and 4 local
  iterations, S_G = 0.2 over 30 %) the mean edge stretch after 1 s was 243 % at dt = 1/60 s, 39 %
  with 30 length iterations, and 6.8 % with 4 substeps of 1/240 s (g dt^2 is then 16 times
  smaller).  Substepping, or more length iterations, is the remedy within the paper's scheme.
* Collision projection is the last stage (as in Algorithm 1): after it no free vertex is closer
  than a hair radius to an analytic collider (to a mesh: within the SDF's interpolation error, a
  fraction of a voxel), but edge lengths may be violated by the projection, and edges between two
  outside vertices may still cut a thin collider (vertex-based, as in TressFX).

The step allocates nothing: all fields are created in ``__init__``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import taichi as ti

from .profiling import StageTimer
from . import shape_constraints as sc
from .errors import SimulationDivergedError
from .model import Model, _np_float
from .state import Control, State

METHODS = (1, 2, 3)
#: Profiled stages (``SolverShape(profile=True)``).
STAGES = ("integrate", "global", "local", "length", "collide", "end")
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
            wind ``control.air_velocity``; ``air_drag * dt`` must stay below 1 [1/s].
        check_finite: check every position and velocity after each step and raise
            :class:`SimulationDivergedError` on NaN/inf [-].
    """

    method: int = 2
    regions: tuple = field(default_factory=lambda: (ShapeRegion(),))
    air_drag: float = 1.0
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
        if not isinstance(self.check_finite, bool):
            raise ValueError(f"SolverShapeConfig.check_finite must be a bool, got {self.check_finite!r}")


class SolverShape(StageTimer):
    """Position-based hair solver with global and local shape constraints (Han & Harada 2012).

    Args:
        model: the :class:`Model` to simulate (the same one SolverADMM takes).
        config: :class:`SolverShapeConfig`.
        strand_region: region id of each strand, shape (strand_count,), values in
            ``[0, len(config.regions))``; default all 0.
        profile: if True, synchronise after each stage and accumulate wall times in
            ``stage_seconds`` (slower; for benchmarks).
        colliders: bodies the hair collides with: :class:`~taichi_hair.colliders.PlaneCollider`,
            ``SphereCollider``, ``CapsuleCollider``, ``MeshCollider``, or a built
            :class:`~taichi_hair.colliders.ColliderSet` (as SolverADMM takes them); None: none.

    Regions, strand regions and colliders may be edited between steps (an interactive tool's
    sliders, Sec. 6 Fig. 4): change ``config.regions`` and call :meth:`upload_regions`, call
    :meth:`set_strand_region`, or :meth:`set_colliders`.

    Fields (all allocated here, shape (vertex_count,) unless stated):
        vertex_rest_rotation: ^wR_i^0, rest global rotation of frame i, quaternion (x, y, z, w) [-].
        vertex_rest_local_position: ^{i-1}P_i^0, vertex i in rest frame i-1 (0 at the root) [m].
        vertex_rotation, vertex_rotation_temp: ^wR_i and ^wR_temp_i of Method 2, swapped after each
            iteration (the latest is :attr:`global_rotation`), quaternions [-].
        vertex_arc_fraction: rest arc length from the root over the strand's length [-].
        vertex_position_begin, vertex_velocity_begin: x^t [m] and v^t [m/s].
        strand_region: region id, shape (strand_count,) [-].
        strand_head_rotation: ^wR_H of the strand's body, quaternion, shape (strand_count,) [-].
        region_*: the :class:`ShapeRegion` values, shape (region_count,).
        vertex_collision_radius: hair radius of the vertex's strand (``RodMaterial.radius``), the
            distance kept from colliders [m].
        colliders: the :class:`~taichi_hair.colliders.ColliderSet` (its own fields), or None.
    """

    def __init__(self, model: Model, config: SolverShapeConfig | None = None, strand_region=None,
                 profile: bool = False, colliders=None):
        self.model = model
        self.config = config or SolverShapeConfig()
        cfg = self.config
        cfg.__post_init__()
        h = model.host
        n, ns = model.vertex_count, model.strand_count
        self.region_count = len(cfg.regions)
        regions = self._check_strand_region(strand_region)
        f = _np_float()
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
        radius = np.array([mat.radius for mat in model.materials], np.float64)
        self.vertex_collision_radius.from_numpy(radius[h["vertex_strand"]].astype(f))
        self.set_colliders(colliders)
        # Rest arc-length fraction of each vertex, for the S_G ramp.
        starts, counts = h["strand_vertex_start"], h["strand_vertex_count"]
        le = h["edge_rest_length"]
        arc = np.zeros(n)
        for j in range(1, int(counts.max())):  # vectorised over strands, one local index at a time
            idx = starts[counts > j] + j
            arc[idx] = arc[idx - 1] + le[idx - 1]
        total = arc[starts + counts - 1]
        self.vertex_arc_fraction.from_numpy((arc / np.repeat(total, counts)).astype(f))
        self.upload_regions()
        sc.initialize_rest_transforms(model, self)
        self.vertex_rotation.copy_from(self.vertex_rest_rotation)
        #: Method 2's latest global transforms ^wR_i (one of the two buffers) [-].
        self.global_rotation = self.vertex_rotation
        self.profile = profile
        self.stage_seconds = {k: 0.0 for k in STAGES}
        self.step_count = 0

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
        for name in ("global_stiffness", "global_range", "global_falloff", "local_stiffness", "damping"):
            getattr(self, "region_" + name).from_numpy(np.array([getattr(r, name) for r in regs], dtype=f))
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
        """Replace the colliders (a list of :mod:`taichi_hair.colliders` objects, a ``ColliderSet``, or
        None/empty for none).  A list is built into a new ``ColliderSet`` here (this allocates: call it
        between steps, not inside one).  As for any new ``ColliderSet``, the first step after this one
        sees no body motion (its begin-of-step transforms are its end-of-step ones), which only matters
        to friction."""
        from .colliders import ColliderSet

        if colliders is None or (not isinstance(colliders, ColliderSet) and len(colliders) == 0):
            self.colliders = None
            return
        if not isinstance(colliders, ColliderSet):
            colliders = ColliderSet(colliders, self.model.body_count)
        elif colliders.body_count != self.model.body_count:
            raise ValueError(f"SolverShape: the ColliderSet has {colliders.body_count} bodies, the model "
                             f"{self.model.body_count}")
        self.colliders = colliders

    def reset_collider_motion(self) -> None:
        """Forget the bodies' last transforms: the next step sees no body motion (as the first step
        does).  Friction uses each collider's motion over a step; call this after putting the State
        or the Control back in time (a reset, a restart), so a jump of the bodies is not read as motion."""
        if self.colliders is not None:
            self.colliders.has_begin = False

    # ------------------------------------------------------------------ stepping
    def step(self, state: State, control: Control, dt: float) -> None:
        """Advance ``state`` in place by one time step (Algorithm 1).

        Args:
            state: positions and velocities at the beginning of the step (twists are not used).
            control: body transforms at the *end* of the step (W_T_H of each strand's root body),
                gravity, and air velocity (the wind).
            dt: time step [s].

        Raises:
            ValueError: for a bad ``dt`` or ``air_drag * dt >= 1``.
            SimulationDivergedError: if a position or velocity becomes non-finite; ``state`` is then
                restored to the beginning of the step.
        """
        if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
            raise ValueError(f"SolverShape.step: dt must be a finite positive number, got {dt!r}")
        cfg, m = self.config, self.model
        if cfg.air_drag * dt >= 1.0:
            raise ValueError(f"SolverShapeConfig.air_drag * dt must be < 1 for the explicit wind term, got "
                             f"{cfg.air_drag} * {dt}")
        x, v = state.vertex_position, state.vertex_velocity
        rot, tr = control.body_rotation, control.body_translation
        t0 = self._tick()

        # 1-2. Head transforms, forces and Verlet integration (Sec. 3.1, 3.2).
        sc.compute_head_rotations(m, rot, x, self)
        sc.begin_step(x, v, self)
        sc.integrate(m, self, rot, tr, ti.math.vec3(*control.gravity), ti.math.vec3(*control.air_velocity),
                     cfg.air_drag, dt, x)
        t0 = self._tock("integrate", t0)
        # 3. Global shape constraints (Sec. 3.3, Eq. 2).
        if self._any_global:
            sc.apply_global_shape_constraints(m, self, rot, tr, x)
        t0 = self._tock("global", t0)
        # 4. Local shape constraints (Sec. 3.4, Eq. 4) with the transforms of Sec. 4.2.
        self._local_shape_constraints(x)
        t0 = self._tock("local", t0)
        # 5. Edge length constraints, in two batches of disjoint edges (Sec. 5).
        for it in range(self._max_length_iterations):
            sc.solve_edge_lengths_batch(m, self, 0, it, x)
            sc.solve_edge_lengths_batch(m, self, 1, it, x)
        t0 = self._tock("length", t0)
        # 6. Collision handling (Sec. 3.5), colliders at the end-of-step body transforms.
        if self.colliders is not None:
            self.colliders.begin_step(control)
            sc.project_collisions(m, self, self.colliders, x)
        t0 = self._tock("collide", t0)
        # 7. Velocities for the next Verlet step; finiteness.
        sc.end_step(self, dt, x, v)
        self.step_count += 1
        if cfg.check_finite:
            self.check_finite(state)
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

    def check_finite(self, state: State) -> None:
        """Raise SimulationDivergedError (after restoring the begin-of-step state) on NaN/inf."""
        sc.find_non_finite(self.model, state.vertex_position, state.vertex_velocity, self._bad)
        code = int(self._bad[None])
        if code >= 0:
            sc.restore_begin(self, state.vertex_position, state.vertex_velocity)
            raise SimulationDivergedError(code // 2, _FIELD_NAMES[code % 2], self.step_count)
