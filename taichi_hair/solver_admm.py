"""SolverADMM: Algorithm 1 of Daviet 2023 as a short sequence of kernel launches.

Per step (Sec. 4.2):

1. collision detection                       -- ``ContactPipeline.detect`` (contact/grid.py, contact/pipeline.py; Sec. 4.5)
2. advect the initial guess x <- x_pred      -- ``admm.begin_step`` (x^t + dt v^t; BDF2 below)
3. update DER frames                         -- ``frames.update_reference_frames``
4. for each ADMM iteration:
   a. local elasticity solve -> y           -- ``elasticity.solve_local_elasticity`` (Sec. 4.4)
   b. feasible projection -> z              -- ``ContactPipeline.project`` (contact/projection.py; Sec. 4.5, Eq. 5-6)
   c. lambda_y <- lambda_y + y - Bx         -- fused into the local step (y - Bx is its increment);
      lambda_z <- lambda_z + z - x          -- ``projection.update_contact_duals``
   d. tridiagonal solve M dx = f            -- ``admm.assemble_position_system`` + ``tridiag`` (Sec. 4.3, Eq. 3)
   e. x <- x + dx, update frames
   f. twist Newton step d2E/dth2 dth = -dE/dth -- ``admm.compute_pair_twist_terms`` + ``assemble_twist_system``
   g. theta <- theta + dth, update frames
      (f-g replaced by the exact twist-free frames ``frames.update_twist_free_frames`` when
      every rod is naturally straight and round: ``frames.twist_choice``)
5. optional geometric contact correction     -- ``ContactPipeline.correct`` (projection on x itself)
6. v = (x - x^t)/dt, omega = (theta - theta^t)/dt; check every value is finite.

Time integration (``SolverADMMConfig.integrator``): the paper's backward Euler, or BDF2, v_{n+1} = (3 x_{n+1} - 4
x_n + x_{n-1}) / (2 dt). BDF2 is the same incremental problem with another inertia term: writing v_{n+1} = (x -
x_hat) / h with h = 2 dt / 3 and x_hat = (4 x_n - x_{n-1}) / 3, the momentum balance M (v_{n+1} - v_hat) / h =
F(x), v_hat = (4 v_n - v_{n-1}) / 3, is M (x - x_pred) / h^2 = F(x) with x_pred = x_hat + h v_hat -- backward
Euler's form with (dt, x^t, v^t) replaced by (h, x_hat, v_hat) (likewise theta, omega with the rotational inertia).
So ``begin_step`` writes x_hat, v_hat into origin buffers, the assembly reads them with h in place of dt, and
``end_step`` sets v = (x - x_hat) / h. The dissipative terms use the same BDF2 rate:
  * air drag xi (v - v_air) with v = (x - x_hat) / h (the drag is a force at t_{n+1},
    evaluated with the step's own velocity, as backward Euler does with (x - x^t) / dt);
  * strain-rate damping tau K kappa_dot (Sec. 4.4), with kappa_dot = (kappa - kappa_hat) / h,
    kappa_hat = (4 kappa_n - kappa_{n-1}) / 3 (``admm.bdf2_strain_origin``): the local step's c (kappa - kappa_begin)
    with c = tau * damping_scale, damping_scale = 1 / h (1 / dt for backward Euler). Damping stays second-order
    consistent, so a damped rod converges at second order too.
x_{n-1}, v_{n-1}, theta_{n-1}, omega_{n-1} are the begin buffers of the last step (read by ``begin_step`` before it
overwrites them); kappa_{n-1}, eps_{n-1} sit in ``pair_kappa_previous``/``edge_strain_previous``.  A step without
that history -- the first one, one after ``reset_history``/``reset_duals`` or ``restore`` of a checkpoint without
it, after a failed step, or with another dt -- is a backward Euler step (it then makes the history).  The contact
weights W_z and the detection margins keep the physical dt (they set ADMM's convergence and the reach of a step,
not the discretisation).

With contacts the strand schedule runs one iteration per launch, the z-step
between launches (it couples strands); y and z both depend on x only, so
projecting before the local step of the same iteration is the same algorithm.

Step 4's schedules (``SolverADMMConfig.schedule``): "stage" launches the kernels above once per iteration,
each parallel over all vertices (GPU); "strand" runs the loop in one kernel, parallel over strands, all
iterations of a strand serially (CPU; ``schedule_strand``; bit-identical to "stage" on CPU); "lanes" runs
the strand schedule's arithmetic on lanes of eight strands (CPU SIMD; ``lanes``; equal to rounding).
The step allocates nothing: all buffers are created in ``__init__``.
"""

from __future__ import annotations

import numpy as np
import taichi as ti

from .solver_base import SolverBase, on_gpu
from . import admm
from .anderson import ANDERSON_MIN_ITERATIONS, AndersonBuffers, anderson_auto_window, anderson_begin, anderson_mix
from .config import DualFrame, Integrator, Mode, Schedule, SolverADMMConfig, StrainMeasure, Tridiagonal, Twist
from .elasticity import FRAME_NONE, FRAME_PAIR, FRAME_ROOT, prime_duals, solve_local_elasticity
from .fields import SolverBuffers, download, upload
from .frames import update_material_frames, update_reference_frames, update_twist_free_frames
from .model import Model, _np_float
from .lanes import (CONTACT_ITERATION, ITERATIONS, LaneLayout, admm_iterations_lanes, auto_schedule, lanes_frames, lanes_gather,
                    lanes_scatter)
from .schedule_strand import admm_iterations_strand
from .state import Control, State
from .strains import BERGOU, KORNER
from .tridiag import TridiagonalSolver

#: In the quasistatic mode the ADMM weight of a prestressed pair (a sag-free rest pose) is at least this times
#: the pair's prestress ratio |mu| / S times its w0 = 1 weight (``SolverADMM._set_coefficients``) [-].
PRESTRESS_WEIGHT = 400.0

#: Profiled stages.  The stage schedule fills local/global/frames/twist; the strand
#: schedule records its fused ADMM loop under "iterations" (and the frame update
#: before the loop under "frames").
STAGES = ("detection", "continuous", "begin", "local", "projection", "global", "frames", "twist", "anderson",
          "iterations", "correction", "end")
_FIELD_NAMES = ("vertex_position", "vertex_velocity", "edge_twist", "edge_angular_velocity")  # finite-check order


class SolverADMM(SolverBase):
    """ADMM local-global integrator for Discrete Elastic Rods (Daviet 2023).

    Args:
        model: the :class:`Model` to simulate.
        config: :class:`SolverADMMConfig`.
        profile: if True, synchronise after each stage and accumulate wall
            times in ``stage_seconds`` (slower; for benchmarks).
    """

    FIELD_NAMES = _FIELD_NAMES
    STAGES = STAGES

    def __init__(self, model: Model, config: SolverADMMConfig | None = None, profile: bool = False,
                 colliders=None):
        self._init_base(model, profile)
        self.config = config or SolverADMMConfig()
        cfg = self.config
        h = model.host
        if cfg.mode == Mode.QUASISTATIC:
            free = np.where(h["strand_body"] < 0)[0]
            if free.size:
                raise ValueError(f"strand {int(free[0])}: field 'root' is 'free', but the quasistatic mode needs every "
                                 "strand clamped (a free strand has no equilibrium under gravity)")
        self.dynamic = cfg.mode == Mode.DYNAMIC
        self.measure = KORNER if cfg.strain_measure == StrainMeasure.KORNER else BERGOU
        self.with_ref_twist = self.measure == BERGOU
        self.use_q = {DualFrame.NONE: FRAME_NONE, DualFrame.ROOT: FRAME_ROOT, DualFrame.PAIR: FRAME_PAIR}[cfg.dual_frame]
        self.buf = SolverBuffers(model.vertex_count)
        self._bad = ti.field(ti.i32, ())
        self._diag_kappa = ti.Vector.field(3, float, model.vertex_count)
        self._diag_strain = ti.field(float, model.vertex_count)
        #: The rest State, refilled in place by ``_set_coefficients`` (rest strains).
        self._rest_state = model.state()
        #: What the solver chose to model and why, by topic ("twist"; "contacts" with contacts), for reports.
        self.model_choices = {}
        self._set_coefficients()
        gpu = on_gpu()
        schedule = cfg.schedule
        if schedule == Schedule.AUTO:  # ("lanes" on a CPU only for large Models: lanes.AUTO_LANES_VERTICES)
            schedule = auto_schedule(gpu, cfg.tridiagonal == Tridiagonal.PCR, self.measure == KORNER, model.vertex_count)
        elif schedule != Schedule.STAGE and cfg.tridiagonal == Tridiagonal.PCR:
            raise ValueError(f"SolverADMMConfig.tridiagonal='pcr' cannot be used with SolverADMMConfig.schedule="
                             f"'{schedule}' (it solves each strand with Thomas)")
        if schedule == Schedule.LANES and (gpu or self.measure != KORNER):
            raise ValueError("SolverADMMConfig.schedule='lanes' needs Taichi's CPU arch and strain_measure='korner'")
        #: Resolved schedule: "stage", "strand" or "lanes" (``lanes.LaneLayout`` in ``self._lanes``).
        self.schedule = schedule
        self._lanes = LaneLayout(h["strand_vertex_start"], h["strand_vertex_count"]) if schedule == Schedule.LANES else None
        method = ("pcr" if gpu else "thomas") if cfg.tridiagonal == "auto" else cfg.tridiagonal
        self.tridiagonal_method = method = "thomas" if schedule != Schedule.STAGE else method
        self.tridiag = TridiagonalSolver(model.strand_vertex_start, model.strand_vertex_count, model.vertex_strand,
                                         h["strand_vertex_count"], method)
        #: Contacts (Sec. 4.5): hair-hair when config.contacts is set, bodies when colliders are given.
        self.contacts = None
        if cfg.contacts is not None or colliders:
            from .config import ContactConfig
            from .contact.pipeline import ContactPipeline

            ccfg = cfg.contacts if cfg.contacts is not None else ContactConfig(hair_hair=False)
            self.contacts = ContactPipeline(model, ccfg, self._collider_set(colliders))
        #: Anderson acceleration of the iterations (anderson.py); not with contacts, whose projection
        #: couples strands inside an iteration (measured only without them).  anderson_window None (auto):
        #: ANDERSON_DEFAULT_WINDOW where it was measured to converge to the plain iteration's answer
        #: (anderson.py, "Where it runs by default"), the plain iteration elsewhere.
        requested, why_not = anderson_auto_window(cfg.anderson_window, self.dynamic, self.twist_free,
                                                  cfg.integrator == Integrator.BDF2)
        window = requested if self.contacts is None else 0
        self.anderson = AndersonBuffers(model.vertex_count if window else 1,
                                        model.strand_count if window else 1, window)
        self.model_choices["acceleration"] = (
            f"Anderson acceleration, window {window}, with >= {ANDERSON_MIN_ITERATIONS} iterations per step"
            + ("" if cfg.iterations >= ANDERSON_MIN_ITERATIONS else f" (now {cfg.iterations}: plain)")
            if window else
            f"no acceleration: {why_not}" if requested == 0 else
            "no acceleration: not used with contacts")
        #: Statistics of the last step's contacts (see ``ContactPipeline.statistics``).
        self.contact_stats = {}
        self.iteration_count = 0
        #: dt [s] of the last completed dynamic step when the BDF2 history (the begin buffers and
        #: ``pair_kappa_previous``) is that step's; None when the next step has no history.
        self._history_dt = None

    # ------------------------------------------------------------------ set-up
    def _set_coefficients(self) -> None:
        """Discretisation-dependent coefficients (bending Voronoi lengths, W_y, halved stretch, rest strains)."""
        m, cfg, h = self.model, self.config, self.model.host
        local = h["vertex_local_index"]
        count_of_vertex = h["strand_vertex_count"][h["vertex_strand"]]
        active = h["pair_is_active"].astype(bool)
        vstar = m.pair_voronoi_length(cfg.voronoi_rescaling)
        bend = np.where(active[:, None], h["pair_bending_modulus"] / vstar[:, None], 0.0)
        weight = np.where(active, cfg.w0 * h["pair_bending_rigidity"] / vstar**3, 0.0)
        # Edge j belongs to pairs j and j+1 when 1 <= local j <= m-3: halve its stretch there.
        shared = (local >= 1) & (local <= count_of_vertex - 3)
        ks = h["edge_stretch_stiffness"] * np.where(shared, 0.5, 1.0)
        f = _np_float()
        m.reset_state(self._rest_state)
        rest = self._rest_state
        admm.compute_strains(self.measure, m.edge, m.pair, rest.vertex_position, rest.edge_twist, rest,
                             self.buf.pair_rest_kappa, self.buf.edge_strain_begin)
        # A sag-free rest pose (solvers/rest_pose.py) stores rest moments mu: kappa_bar = kappa(x*) - mu / S.
        moment = h.get("pair_rest_moment")
        if moment is not None and h.get("rest_pose_measure") != cfg.strain_measure:
            raise ValueError(f"the groom's sag-free rest pose was solved for the strain measure "
                             f"'{h.get('rest_pose_measure')}', the solver uses '{cfg.strain_measure}': solve it again "
                             "(solvers.rest_pose.solve_rest_pose) with this solver's config")
        # Model no more than the scene needs (frames.twist_choice): the twist unknowns of straight round rods.
        if cfg.twist == Twist.SOLVE:
            self.twist_free, why = False, "twist solved (SolverADMMConfig.twist='solve')"
        elif moment is not None and np.any(moment != 0.0):
            # A curved rest shape couples twist and bending: dropping the twist would not be exact.
            self.twist_free, why = False, "twist solved: the groom has a sag-free rest pose (curved rest shape)"
        else:
            from .frames import twist_choice

            self.twist_free, why = twist_choice(h, self.buf.pair_rest_kappa.to_numpy())
        self.model_choices["twist"] = why
        if self.twist_free:
            bend = bend.copy()
            bend[:, 2] = 0.0  # the energy minimised over theta has no twist term
        if moment is not None:
            rk = self.buf.pair_rest_kappa.to_numpy().astype(np.float64)
            mu = np.asarray(moment, np.float64)
            safe = np.where(bend > 0.0, bend, 1.0)
            self.buf.pair_rest_kappa.from_numpy(np.where(bend > 0.0, rk - mu / safe, rk).astype(f))
            # Prestress: the local step's Gauss-Newton Hessian J^T K J leaves out mu . d2kappa/de2, of relative
            # size rho = |mu| / S = |kappa(x*) - kappa_bar| (zero for an authored rest pose at rest).  With
            # W_y at w0 = 1 the iteration then diverged from the sag-free equilibrium of the hang scene's curly
            # strands (20 strands, quasistatic, 200 steps: 17 cm; at w0 = 5: 0.2 mm; at 25: 1 um; rho up to
            # ~0.9): the weight of a prestressed pair is raised to PRESTRESS_WEIGHT * rho times its w0 = 1
            # weight.  Measured over 600 steps (largest drift from x*): 25 -> 24 um at 200 steps, 100 -> 22 um
            # (still growing), 400 -> 2.8 um (w0 = 25 everywhere: 2.1 um).
            # Quasistatic mode only (2026-12-05): in the dynamic mode the inertia m/dt^2 in the global step keeps
            # the iteration at the equilibrium without it (wavy groom on the head, still, 2 s: p90 0.004 mm), and
            # the raised weight cost the convergence of every step: in the head turn 10 iterations left 23 % of a
            # substep's displacement without contacts (0.5 % without the raise) and 30 % with them (12 %)
            # (benchmarks/probes/head_turn_convergence.py; BENCHMARKS.md, issue 14).
            if not self.dynamic:
                rho = np.where(active, np.linalg.norm(mu[:, :2] / safe[:, :2], axis=1), 0.0)
                weight = np.maximum(weight, PRESTRESS_WEIGHT * rho * weight / cfg.w0)
        # Weights past the solver's float type (an absurd w0, issue 17): one line naming the field, not numpy's
        # "overflow encountered in cast" and a divergence at step 1.
        top = float(np.finfo(f).max) / 1e6  # headroom: W_y is summed and multiplied in the global step
        if np.any(weight > top):
            k = int(np.argmax(weight))
            raise ValueError(f"SolverADMMConfig.w0 = {cfg.w0:g} makes the elasticity weight W_y of pair {k} "
                             f"{weight[k]:.3g}, beyond what {np.dtype(f).name} holds with headroom ({top:.3g}); "
                             f"use w0 of order 1 (the default 1, the paper's 25)")
        upload([(self.buf.pair_bend_stiffness, bend.astype(f)), (self.buf.pair_admm_weight, weight.astype(f)),
                (self.buf.edge_pair_stretch_stiffness, ks.astype(f))])
        self.host_pair_voronoi_bend = vstar

    def _anderson_on(self) -> bool:
        """Whether this step mixes (anderson.py): a history is allocated (window > 0, no contacts) and the
        step has at least ANDERSON_MIN_ITERATIONS iterations (``config.iterations`` may change between steps)."""
        return self.anderson.window > 0 and self.config.iterations >= ANDERSON_MIN_ITERATIONS

    def _active_lanes(self):
        """The lane layout where this step runs the lanes, else None (a step that mixes runs the strand kernel)."""
        return self._lanes if self._lanes is not None and not self._anderson_on() else None

    def _continuous_iterations(self) -> set:
        """ADMM iterations (0-based) that begin with continuous-time detection: ``continuous_detections``
        of them at regular intervals, the first on the advected guess (iteration 0)."""
        con = self.contacts
        k = con.config.continuous_detections if con is not None else 0
        n = self.config.iterations
        return {(j * n) // k for j in range(k)} if k > 0 else set()

    def refresh_model(self) -> None:
        """Recompute everything derived from the Model after :meth:`Model.update` (no new fields)."""
        super().refresh_model()
        if self.contacts is not None:
            self.contacts.set_coefficients()

    # ------------------------------------------------------------------ stepping
    def step(self, state: State, control: Control, dt: float) -> None:
        """Advance ``state`` in place by one time step (Algorithm 1).

        Args:
            state: positions, velocities, twists and frames at the beginning of the step.
            control: body transforms at the *end* of the step, gravity and air velocity.
            dt: time step [s]; in the quasistatic mode it scales nothing and may be any positive number.

        Raises:
            SimulationDivergedError: if any value becomes non-finite; ``state`` is then restored to the step's beginning.
        """
        self._check_dt(dt)
        m, b, cfg, dyn = self.model, self.buf, self.config, self.dynamic
        bdf2_run = dyn and cfg.integrator == Integrator.BDF2
        # BDF2 needs the last step's state at the same dt; otherwise a backward Euler step.
        bdf2 = bdf2_run and self._history_dt == dt
        self._history_dt = None  # until this step has completed
        h = 2.0 * dt / 3.0 if bdf2 else dt  # inertia step: M (x - x_pred) / h^2 (module docstring)
        damping_scale = 1.0 / h if dyn else 0.0
        # W_y >= inertia_floor m / h^2 (dynamic mode): the same scalar for the local and the global step.
        weight_floor = cfg.inertia_floor / (h * h) if dyn else 0.0
        self._weight_floor = weight_floor
        g, v_air = ti.math.vec3(*control.gravity), ti.math.vec3(*control.air_velocity)
        t0, con = self._tick(), self.contacts
        if con is not None:
            # Proximity detection on x^t (Alg. 1 l.1); clear last step's collision weights first.
            con.clear(b)
            con.colliders.begin_step(control)
            con.detect(state, dt, control.gravity, dyn)
            t0 = self._tock("detection", t0)
        # Begin-of-step strains for strain-rate damping (Sec. 4.4), then advect (Alg. 1 l.2).
        admm.compute_strains(self.measure, m.edge, m.pair, state.vertex_position, state.edge_twist, state,
                             b.pair_kappa_begin, b.edge_strain_begin)
        if bdf2_run:
            admm.bdf2_strain_origin(bdf2, b)
        admm.begin_step(dyn, bdf2, m.vertex, m.edge, control.body_rotation, control.body_translation, m.strand, state, state,
                        b, h)
        if not cfg.warm_start_duals:
            admm.reset_duals(b)
        t0 = self._tock("begin", t0)
        if self._active_lanes() is None:  # (the lanes move their own: lanes_frames after the gather)
            self._update_frames(state, control)
        t0 = self._tock("frames", t0)

        if self.schedule == Schedule.STAGE:
            t0 = self._iterations_stage(state, control, h, g, v_air, damping_scale, t0)
        else:
            t0 = self._iterations_fused(state, control, h, g, v_air, damping_scale, weight_floor, t0)

        if con is not None:
            con.count_status(state.vertex_position)
        if con is not None and con.config.correction_iterations > 0:
            if con.config.continuous_detections > 0:
                # "Repeat continuous-collision detection and feasible projection on x" (Alg. 1, end).
                con.detect_continuous(b.vertex_position_begin, state.vertex_position)
                t0 = self._tock("continuous", t0)
            if con.config.late_body_contacts:
                con.detect_late_body(state.vertex_position)  # vertices the pile pushed into a body this step
            con.correct(state.vertex_position, b.vertex_position_begin, con.config.correction_iterations)
            self._update_frames(state, control)
            t0 = self._tock("correction", t0)
        if self.twist_free:
            # theta of the twist-free frames, once per step (the iterations only need the frames).
            update_twist_free_frames(m.strand, m.edge, state.edge_twist, state, 1)
        admm.end_step(dyn, state, state, b, h)
        self.step_count += 1
        if cfg.check_finite:
            self.check_finite(state)
        if bdf2_run:
            self._history_dt = dt
        if con is not None:
            self.contact_stats = con.statistics(state.vertex_position)
        self._tock("end", t0)

    def vertex_contact_state(self) -> np.ndarray:
        """Per vertex after the last step: 0 free, 1 sticking, 2 sliding, int8 (vertex_count,); all 0 without contacts."""
        n = self.model.vertex_count
        return np.zeros(n, np.int8) if self.contacts is None else self.contacts.vertex_states(n)

    def _iterations_fused(self, state: State, control: Control, h: float, g, v_air, damping_scale: float,
                          weight_floor: float, t0: float) -> float:
        """Step 4 of Algorithm 1, "strand" or "lanes" schedule: without contacts every iteration in one launch
        (``schedule_strand``, or ``lanes`` when no Anderson mixing), with contacts one launch per iteration and the
        z-step between them (it couples strands; the lanes are gathered once per step, and only x goes back between)."""
        m, b, cfg, con, x, theta = self.model, self.buf, self.config, self.contacts, state.vertex_position, state.edge_twist
        lanes = self._active_lanes()

        def launch(iterations: int, mode: int) -> None:
            if lanes is not None:
                admm_iterations_lanes(self.use_q, self.dynamic, self.twist_free, lanes, m, control.body_rotation, x, theta,
                                      state, b, g, v_air, cfg.air_viscosity, h, damping_scale, iterations, weight_floor, mode)
            else:
                admm_iterations_strand(self.measure, self.use_q, self.with_ref_twist, self.dynamic, self.twist_free, m,
                                       control.body_rotation, x, theta, state, b, g, v_air, cfg.air_viscosity, h,
                                       damping_scale, iterations, weight_floor, self.anderson, self.anderson.window,
                                       int(self._anderson_on()))  # (window 0 with contacts: no Anderson there)

        if lanes is not None:
            lanes_gather(lanes, m, control.body_rotation, x, theta, state, b, damping_scale, weight_floor)
            lanes_frames(self.twist_free, lanes)
        if con is None:
            launch(cfg.iterations, ITERATIONS)  # (a-g) for every iteration in one kernel
            self.iteration_count += cfg.iterations
        else:
            ccd_at = self._continuous_iterations()
            for it in range(cfg.iterations):
                if it in ccd_at:
                    # Optional continuous-time detection from x^t to the current iterate (Alg. 1 l.5).
                    con.detect_continuous(b.vertex_position_begin, x)
                    t0 = self._tock("continuous", t0)
                # (b, c) z-step and lambda_z update, then (a, c-g) one iteration strand by strand.
                con.project(x, b, con.config.projection_iterations)
                t0 = self._tock("projection", t0)
                launch(1, CONTACT_ITERATION)
                t0 = self._tock("iterations", t0)
                self.iteration_count += 1
        if lanes is not None:
            lanes_scatter(lanes, x, theta, state, b)
        return self._tock("iterations", t0)

    def _iterations_stage(self, state: State, control: Control, dt: float, g, v_air, damping_scale: float,
                          t0: float) -> float:
        """Step 4 of Algorithm 1, "stage" schedule: a few kernels per iteration, each over all vertices.

        ``dt`` is the integrator's inertia step h (dt, or 2 dt / 3 for a BDF2 step)."""
        m, b, cfg, dyn, con, aa, aa_on = (self.model, self.buf, self.config, self.dynamic, self.contacts, self.anderson,
                                          self._anderson_on())
        ccd_at = self._continuous_iterations()
        if aa_on:
            anderson_begin(m.strand, m.edge, state.vertex_position, state.edge_twist, b, aa)
        for it in range(cfg.iterations):
            if it in ccd_at:
                # Optional continuous-time detection from x^t to the current iterate (Alg. 1 l.5).
                con.detect_continuous(b.vertex_position_begin, state.vertex_position)
                t0 = self._tock("continuous", t0)
            # (a) Local elasticity solve over y (Sec. 4.4).
            solve_local_elasticity(self.measure, self.use_q, m.vertex, m.edge, m.pair, m.strand, control.body_rotation,
                                   state.vertex_position, state.edge_twist, state, b, damping_scale, self._weight_floor)
            t0 = self._tock("local", t0)
            # (b) Feasible projection over z (Sec. 4.5) and lambda_z += z - x.
            if self.contacts is not None:
                self.contacts.project(state.vertex_position, b, self.contacts.config.projection_iterations)
                t0 = self._tock("projection", t0)
            # (c) The dual update lambda_y += y - Bx is fused into the local step.
            # (d, e) Global tridiagonal solve over x (Sec. 4.3), then frames.
            admm.assemble_position_system(dyn, m.vertex, m.edge, m.pair, state.vertex_position, b, g, v_air,
                                          cfg.air_viscosity, dt, self._weight_floor)
            self.tridiag.solve(b.tri_lower, b.tri_diag, b.tri_upper, b.tri_rhs3)
            admm.apply_position_update(m.vertex, state.vertex_position, b)
            t0 = self._tock("global", t0)
            update_reference_frames(self.with_ref_twist, m.vertex, m.edge, m.pair, m.strand, control.body_rotation,
                                    state.vertex_position, state.edge_twist, state)
            t0 = self._tock("frames", t0)
            if self.twist_free:
                # (f, g) replaced by the twist of a naturally straight round rod: none (frames.twist_choice).
                update_twist_free_frames(m.strand, m.edge, state.edge_twist, state, 0)
            else:
                # (f, g) Twist Newton step, then material frames.
                admm.compute_pair_twist_terms(self.measure, m.vertex, m.pair, m.strand, state.edge_twist, state, b, damping_scale)
                admm.assemble_twist_system(dyn, m.edge, m.pair, state.edge_twist, b, dt)
                self.tridiag.solve(b.tri_lower, b.tri_diag, b.tri_upper, b.tri_rhs1)
                t0 = self._tock("twist", t0)
                update_material_frames(m.edge, state.edge_twist, state, b.tri_rhs1)  # theta += dtheta, then frames
            t0 = self._tock("frames", t0)
            if aa_on:
                # Anderson mixing of u = (x, lambda_y, theta), strand by strand, then the frames of the mix (anderson.py).
                anderson_mix(m.strand, m.vertex, m.edge, state.vertex_position, state.edge_twist, b, aa, aa.window,
                             int(it == cfg.iterations - 1))
                self._update_frames(state, control)
                t0 = self._tock("anderson", t0)
            self.iteration_count += 1
        return t0

    def _update_frames(self, state: State, control: Control) -> None:
        """Reference (and material) frames after x changed outside the iterations; the twist-free frames too when the
        twist unknowns are dropped."""
        m = self.model
        update_reference_frames(self.with_ref_twist, m.vertex, m.edge, m.pair, m.strand, control.body_rotation,
                                state.vertex_position, state.edge_twist, state)
        if self.twist_free:
            update_twist_free_frames(m.strand, m.edge, state.edge_twist, state, 0)

    def model_report(self) -> dict:
        """What the solver modelled and skipped so far, in words, by topic (README, "Model no more than a scene needs")."""
        rep = dict(self.model_choices, schedule=f"{self.schedule}" + (" (the strand kernel where Anderson mixing runs)"
                                                                          if self._lanes is not None else ""))
        rep["mode"] = ("quasistatic: inertia and damping dropped" if not self.dynamic
                       else "dynamic (BDF2, backward Euler on steps without history)"
                       if self.config.integrator == Integrator.BDF2 else "dynamic (backward Euler)")
        con = self.contacts
        if con is None:
            return {**rep, "contacts": "no contacts"}
        cfg = con.config
        if cfg.hair_hair:
            rep["hair_hair_search"] = (
                f"skipped in {con.hair_search_skip_count} of {con.detections} steps (no two strands within reach)"
                if cfg.skip_when_apart else f"run in every step ({con.detections}; skip_when_apart off)")
            rep["hair_hair_search"] += (f"; {con.pair_extra_rounds} rounds past the first (pair buffer of "
                                        f"{con.pairs.capacity} full; ContactConfig.pairs_per_edge)")
        else:
            rep["hair_hair_search"] = "off (ContactConfig.hair_hair = False)"
        if cfg.continuous_detections > 0:
            rep["continuous_detection"] = (
                f"{cfg.continuous_detections + 1} passes per step; skipped in {con.ccd_skip_total} of "
                f"{con.ccd_pass_total} (largest displacement within the margin)" if cfg.skip_slow_continuous
                else f"{cfg.continuous_detections + 1} passes per step, none skipped (skip_slow_continuous off)")
        else:
            rep["continuous_detection"] = "off (proximity detection only)"
        return rep

    def _non_finite_code(self, state: State) -> int:
        admm.find_non_finite(self.model.vertex, state, state, self._bad)
        return int(self._bad[None])

    def _restore_begin(self, state: State) -> None:
        admm.restore_begin(state, state, self.buf)
        update_reference_frames(True, self.model.vertex, self.model.edge, self.model.pair, self.model.strand,
                                self.model._rest_rotation,
                                state.vertex_position, state.edge_twist, state)

    def reset_duals(self) -> None:
        """Forget what the solver carries from step to step for the state it stepped: the warm-started elasticity
        multipliers and the BDF2 history (:meth:`reset_history`); call it after a teleport or a load."""
        admm.reset_duals(self.buf)
        self.reset_history()

    def prime_duals(self, state: State, control: Control, dt: float | None = None) -> None:
        """Start the warm-started elasticity duals at the ADMM fixed point of ``state`` (its exact bending
        forces, :func:`elasticity.prime_duals`) instead of zero, and forget the BDF2 history.  For a run that
        starts at an equilibrium (a sag-free rest pose, :mod:`taichi_hair.solvers.rest_pose`): with zero duals
        the first steps sag while the duals build up (10 iterations per step) and set the groom swinging.
        ``dt`` [s]: the coming steps' time step (the dynamic mode's weight floor depends on it)."""
        cfg = self.config
        floor = cfg.inertia_floor / (dt * dt) if self.dynamic and dt else 0.0
        self._update_frames(state, control)
        m = self.model
        prime_duals(self.measure, self.use_q, m.vertex, m.edge, m.pair, m.strand, control.body_rotation,
                    state.vertex_position, state.edge_twist, state, self.buf, floor)
        self.reset_history()

    def reset_history(self) -> None:
        """Forget the BDF2 history: the next step is a backward Euler step (then BDF2 again)."""
        self._history_dt = None

    def set_attachments(self, vertices, targets, weights) -> None:
        """Zero-length springs k_i (target_i - x_i) on ``vertices`` only, from the next step on (targets [m], (k, 3);
        k_i [N/m], (k,) or one), in the position system (``admm.assemble_position_at``; the grooming drag and shape springs)."""
        v, t, k = np.asarray(vertices, np.int64), np.asarray(targets, np.float64), np.asarray(weights, np.float64)
        n = self.model.vertex_count
        if (v.ndim != 1 or np.any((v < 0) | (v >= n)) or t.shape != (v.size, 3) or k.shape not in ((), v.shape)
                or not (np.all(np.isfinite(t)) and np.all(np.isfinite(k)) and np.all(k >= 0))):
            raise ValueError(f"set_attachments: vertices in [0, {n}), one finite target each and weights >= 0 expected")
        weight, target = np.zeros(n, _np_float()), np.zeros((n, 3), _np_float())
        weight[v], target[v] = k, t
        upload([(self.buf.vertex_attach_weight, weight), (self.buf.vertex_attach_target, target)])

    def checkpoint(self) -> dict:
        """What the solver carries from one step to the next, as NumPy arrays.

        Together with ``State.to_numpy()`` this is everything a later step
        depends on: the warm-started elasticity duals lambda_y and the forces
        they give, the step/iteration counters, and the BDF2 history (x_{n-1},
        v_{n-1}, theta_{n-1}, omega_{n-1}, kappa_{n-1}, eps_{n-1} and the dt it was
        made at; NaN when there is none).  Contacts are detected afresh each
        step, so they hold nothing across steps.
        """
        b = self.buf
        keys = SolverBuffers.names(b.warm_start)
        snap = dict(zip(keys, download([getattr(b, key) for key in keys])))  # (one kernel: fields.download)
        snap.update({"step_count": np.int64(self.step_count), "iteration_count": np.int64(self.iteration_count),
                     "history_dt": np.float64(np.nan if self._history_dt is None else self._history_dt)})
        if self._history_dt is not None:
            keys = SolverBuffers.names(b.history)
            snap.update(zip(["history_" + key for key in keys], download([getattr(b, key) for key in keys])))
        if self.contacts is not None:
            cs = self.contacts.colliders
            # The previous step's end transforms become the next step's begin transforms (collider velocity).
            snap["collider_has_begin"] = np.int64(cs.has_begin)
            snap["collider_rotation_end"] = cs.body_rotation_end.to_numpy()
            snap["collider_translation_end"] = cs.body_translation_end.to_numpy()
        return snap

    def restore(self, snapshot: dict) -> None:
        """Load what :meth:`checkpoint` returned (same Model layout).  Every member is checked for presence
        and shape before the first ``from_numpy``, so a bad snapshot raises ValueError naming the member and
        changes nothing."""
        from .fields import field_numpy_shape

        def need(key, field):
            if key not in snapshot:
                raise ValueError(f"SolverADMM.restore: the snapshot lacks {key!r}")
            a = np.asarray(snapshot[key])
            want = field_numpy_shape(field) if field is not None else ()
            if a.shape != want:
                raise ValueError(f"SolverADMM.restore: {key} has the shape {a.shape}, expected {want}")
            return a

        loads = [(getattr(self.buf, key), need(key, getattr(self.buf, key)))
                 for key in SolverBuffers.names(self.buf.warm_start)]
        counts = [int(need(key, None)) for key in ("step_count", "iteration_count")]
        # The BDF2 history; a checkpoint without one (older files, backward Euler) restarts it.
        hdt = float(snapshot.get("history_dt", np.nan))
        if np.isfinite(hdt):
            loads += [(getattr(self.buf, key), need("history_" + key, getattr(self.buf, key)))
                      for key in SolverBuffers.names(self.buf.history)]
        colliders = None
        if self.contacts is not None and "collider_has_begin" in snapshot:
            cs = self.contacts.colliders
            colliders = (bool(need("collider_has_begin", None)),
                         need("collider_rotation_end", cs.body_rotation_end),
                         need("collider_translation_end", cs.body_translation_end))
        upload(loads)  # (each array cast to its field's type, as from_numpy does)
        self.step_count, self.iteration_count = counts
        self._history_dt = hdt if np.isfinite(hdt) else None
        if colliders is not None:
            cs = self.contacts.colliders
            cs.has_begin = colliders[0]
            cs.body_rotation_end.from_numpy(colliders[1])
            cs.body_translation_end.from_numpy(colliders[2])

    # ------------------------------------------------------------------ diagnostics
    def energy(self, state: State, control: Control) -> dict:
        """Elastic and gravitational energies of ``state`` [J] (host-side, float64; attachments left out): bending
        in the solver's discretisation (bending Voronoi lengths), stretching with the full per-edge stiffness.
        Returns a dict with keys ``bend``, ``stretch``, ``gravity``, ``total``."""
        m, b = self.model, self.buf
        kappa, eps = self._diag_kappa, self._diag_strain
        admm.compute_strains(self.measure, m.edge, m.pair, state.vertex_position, state.edge_twist, state, kappa, eps)
        k = kappa.to_numpy().astype(np.float64)
        rk = b.pair_rest_kappa.to_numpy().astype(np.float64)
        kb = b.pair_bend_stiffness.to_numpy().astype(np.float64)
        e = eps.to_numpy().astype(np.float64)
        h = m.host
        bend = 0.5 * float(np.sum(kb * (k - rk) ** 2))
        stretch = 0.5 * float(np.sum(h["edge_stretch_stiffness"] * e**2))
        x = state.vertex_position.to_numpy().astype(np.float64)
        grav = -float(np.sum(h["vertex_mass"][:, None] * x * np.asarray(control.gravity)[None, :]))
        return {"bend": bend, "stretch": stretch, "gravity": grav, "total": bend + stretch + grav}
