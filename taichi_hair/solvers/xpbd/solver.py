"""SolverXPBD: a purely local XPBD baseline for elastic rods (Cosserat rods of Kugelstadt and Schoemer 2016).

This is the kind of local solver Daviet 2023 (Sec. 4.2) argues against: every
constraint is projected on its own, so stiffness propagates along a strand by
one edge per color sweep and long stiff chains need many substeps.  It is
meant as a fair baseline on the same :class:`Model`, :class:`State` and
:class:`Control` as :class:`SolverADMM`, with the same elastic energy.

Choice of model: Cosserat rods with one quaternion per edge (stretch-shear and
bend-twist constraints, Kugelstadt and Schoemer 2016) rather than DER-style
position constraints.  The bend-twist constraint 2 Im(conj(q_a) q_b) is the
Korner strain the ADMM solver uses by default, so its compliance is exactly
v*/(E K_aa) of the ADMM energy (Sec. 4.1, with the same bending Voronoi
lengths v*); the stretch-shear compliance is 1/(E_s A l) per component.
The two transverse (shear) components have no DER counterpart (DER frames
sit on the tangents); they get the stretch stiffness E_s A l rather than a
shear modulus, the stiffest choice and so the closest to DER.

Per step ``step(state, control, dt)`` (Macklin et al. 2019, "small steps"):

1. rebuild the edge quaternions and angular velocities from the State's
   material frames and velocities; save the state     -- ``xpbd_constraints.begin_step``
2. for each of ``substeps`` substeps of dt_s = dt / substeps (one launch each,
   ``xpbd_constraints.substep``, up to 2 iterations; else one per sweep):
   a. record C at the substep start (damping), reset the Lagrange multipliers;
      kinematic roots interpolated toward R_b x_body + T_b (the root frame
      toward R_b times its rest frame); v += dt_s g (+ exact linear drag),
      x += dt_s v; each free frame follows its edge (minimal rotation from
      d3(q) to the predicted tangent) and turns by its twist rate
   b. ``iterations`` times: bend-twist (even, odd pairs), then stretch-shear
      (even, odd edges); Gauss-Seidel across colors, parallel inside each
   c. v = (x - x_prev)/dt_s, omega from q conj(q_prev), times exp(-damping dt_s)
3. DER frames from the new positions (time-parallel transport), twists from
   the quaternions                                    -- ``frames.update_reference_frames`` + ``write_twists``
4. check every value is finite, else restore and raise SimulationDivergedError.

State written back: positions; velocities of the last substep,
(x - x_prev)/dt_s (the XPBD velocity; it differs from (x - x^t)/dt, the
mean over the step, by the acceleration within the step); twists, twist rates
and every DER frame.  The shear of the quaternions (their d3 off the tangent)
is not stored in the State: each step starts from frames on the tangents.
This makes a State snapshot the whole state (no hidden solver state between
steps) at the cost of projecting out a small shear once per step.

Departures from Kugelstadt and Schoemer 2016, each measured on hair:

* Stretch along d3 is solved with the positions' weights alone (K&S's
  quaternion term 4 w_q I also counts the d3 direction, which a unit
  quaternion cannot change): with their denominator a 2 cm cantilever at one
  substep per 1/96 s step reached 65x edge stretch, 28x with the split (both
  measured with K&S's frame momentum, below; the stretch is poor either way).
* Frames carry no transverse angular momentum of their own: they follow their
  edges in the prediction (twist rate kept).  With K&S's q += dt/2 omega q and
  one iteration, a cantilever with 10 substeps and damping 50/s blew up
  (edges 5x their length, twist 9 rad); with the follower it settles.
* Bend-twist is swept before stretch-shear, so that the frame corrections
  reach the positions in the same iteration (the other order, with the
  follower prediction, made bending ineffective at one iteration).

Frame inertia: the angular mass of an edge's frame (its weight in the
solve) is the tumbling inertia of the edge as a rigid segment,
rho A l^3 / 12 (``frame_inertia="segment"``, default), or the physical
cross-section inertia rho I l (``"section"``, R^2/l^2 ~ 1e-3 times lighter
for hair), times ``frame_inertia_scale``.  The equilibrium does not depend on
it; the convergence does.  With light frames the bend-twist constraints
(alpha~ << 4 w_q) snap the frames each sweep and the positions follow through
stretch-shear: bending then acts on the positions like an explicit force,
so undamped runs need dt_s below the explicit limit of the bending modes.
Measured (2 cm hair cantilever, 16 edges, damping 0): 10 substeps per 1/96 s
step go wild (160 % stretch, frames flip by 2 pi), 100 stay bounded over
60 steps.  This, and the N-dependent convergence (tests/test_solver_xpbd.py:
the 8-edge cantilever sags 38x / 4.6x / 1.5x / 1.1x the converged answer with
30 / 100 / 300 / 1000 substeps; 16 edges 8.4x / 1.7x with 300 / 1000), is
the weakness of purely local solvers that Daviet 2023, Sec. 4.2, describes.
Heavier frames trade dynamics (extra rotational inertia) for stability;
measured, same cantilever, 60 undamped steps, largest edge stretch with
10 / 30 substeps: ``frame_inertia_scale`` 0.01: 296x / 37x; 1: 2.8x (frames
flip by 2 pi) / 0.19; 100: 0.45 / 0.020.

Schedules (``SolverXPBDConfig.schedule``): "stage" launches one kernel per
substep, each color a loop over all vertices (GPU); "strand" runs all the
substeps of a step in one kernel, parallel over strands (CPU default).  Same
per-element functions in the same order per strand.

Nothing is allocated in ``step()``; no atomics, so CPU reruns are bitwise identical.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum

import numpy as np
import taichi as ti

from . import constraints as xc
from ...admm import find_non_finite
from ...config import Schedule, as_choice
from ...solver_base import SolverBase, on_gpu
from ...frames import update_reference_frames
from ...model import Model, _np_float
from ...rotation import quat_conjugate_np, quat_from_matrix_np, quat_mul_np
from ...state import Control, State

vec3 = ti.math.vec3
vec4 = ti.math.vec4
class FrameInertia(StrEnum):
    SEGMENT = "segment"
    SECTION = "section"


FRAME_INERTIAS = tuple(m.value for m in FrameInertia)
#: Up to this many iterations a substep is one kernel launch with the sweeps unrolled (compile time grows
#: with the count); beyond, one launch per sweep.
_FUSED_ITERATIONS = 2
SCHEDULES = tuple(m.value for m in Schedule)
_FIELD_NAMES = ("vertex_position", "vertex_velocity", "edge_twist", "edge_angular_velocity")


@dataclass
class SolverXPBDConfig:
    """Settings of :class:`SolverXPBD`.

    ``substeps``, ``iterations``, ``damping`` and ``air_viscosity`` are read at every step and may be
    changed between steps; the other fields are used when the solver is built.

    Attributes:
        substeps: substeps per call to ``step``; dt_s = dt / substeps [-].
            Small-step XPBD (Macklin et al. 2019) uses many substeps and one
            iteration each.
        iterations: constraint sweeps (all four colors) per substep [-].
        damping: velocity damping rate c: v and omega are multiplied by
            exp(-c dt_s) each substep [1/s]; 0 disables it.
        air_viscosity: linear drag coefficient xi, force per unit length
            xi (v_air - v), integrated exactly per substep [Pa s].
        strain_rate_damping: apply each strand's ``RodMaterial.damping_time`` tau
            as XPBD constraint damping gamma = tau / dt_s (Macklin et al. 2016,
            Eq. 26; the counterpart of the ADMM solver's strain-rate damping).
            Off by default: Eq. 26 divides each correction by (1 + gamma), which
            with one unconverged iteration weakens every constraint; measured
            (helix, 20 substeps of 1/96 s, tau = 1e-2 s, gamma ~ 19) the damped
            strand fell apart (late mean speed 2.6 m/s against 0.18 undamped).
            Use ``damping`` instead.
        voronoi_rescaling: bending Voronoi lengths v_1* = e_0 + e_1/2 at the second
            and penultimate vertices, as ``SolverADMMConfig.voronoi_rescaling``
            (Daviet 2023, Sec. 5.1); keeps the same energy as the ADMM solver.
        frame_inertia: angular mass of the edge frames, ``"segment"``
            (rho A l^3/12) or ``"section"`` (rho I l); see the module docstring.
        frame_inertia_scale: factor on that angular mass [-] (> 0); the equilibrium does
            not depend on it, the convergence of the local solve does (see the module docstring).
        schedule: ``"stage"``: one launch per substep, each color a loop over all
            vertices (GPUs); ``"strand"``: all substeps of a step in one launch,
            parallel over strands, each strand's colors as serial passes (CPUs);
            ``"auto"``: ``"strand"`` on CPU, ``"stage"`` on GPU archs.  Same
            arithmetic per element (equal to rounding, see the tests).
        check_finite: after each step, check every state value for NaN/inf and
            raise :class:`SimulationDivergedError` naming the strand.
    """

    substeps: int = 20
    iterations: int = 1
    damping: float = 0.0
    air_viscosity: float = 0.0
    strain_rate_damping: bool = False
    voronoi_rescaling: bool = True
    frame_inertia: FrameInertia = FrameInertia.SEGMENT
    frame_inertia_scale: float = 1.0
    schedule: Schedule = Schedule.AUTO
    check_finite: bool = True

    def __post_init__(self):
        for name in ("substeps", "iterations"):
            v = getattr(self, name)
            if not (isinstance(v, int) and not isinstance(v, bool) and v >= 1):
                raise ValueError(f"SolverXPBDConfig.{name} must be an integer >= 1, got {v!r}")
        for name in ("damping", "air_viscosity"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v >= 0):
                raise ValueError(f"SolverXPBDConfig.{name} must be a finite number >= 0, got {v!r}")
        for name in ("strain_rate_damping", "voronoi_rescaling", "check_finite"):
            v = getattr(self, name)
            if not isinstance(v, bool):
                raise ValueError(f"SolverXPBDConfig.{name} must be a bool, got {v!r}")
        _check_positive("frame_inertia_scale", self.frame_inertia_scale)
        self.schedule = as_choice(Schedule, "SolverXPBDConfig", "schedule", self.schedule)
        self.frame_inertia = as_choice(FrameInertia, "SolverXPBDConfig", "frame_inertia", self.frame_inertia)


def _check_positive(name: str, value) -> None:
    if not (isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value > 0):
        raise ValueError(f"SolverXPBDConfig.{name} must be a finite positive number, got {value!r}")


class XPBDBuffers:
    """Coefficients and scratch of SolverXPBD.  Shape (vertex_count,); edge fields are zero on ghost slots,
    pair fields on strand ends."""

    def __init__(self, n: int):
        #: 1/m_i, 0 for kinematic vertices [1/kg].
        self.vertex_inverse_mass = ti.field(float, n)
        #: Inverse angular mass 1/(4 J_j) of the edge quaternion, 0 for a clamped root edge [1/(kg m^2)].
        self.edge_inverse_inertia = ti.field(float, n)
        #: Stretch-shear compliance 1/(E_s A l_j) [1/J].
        self.edge_compliance = ti.field(float, n)
        #: Bend-twist compliance v_i*/(E K_aa), a = 1, 2, 3 [1/J].
        self.pair_compliance = ti.field(vec3, n)
        #: Strain-rate damping times tau of the edge's and pair's strand (0 when disabled) [s].
        self.edge_damping_time = ti.field(float, n)
        self.pair_damping_time = ti.field(float, n)
        #: Rest quaternion of each edge's material frame [-] and rest Darboux strain of each pair [-].
        self.edge_rest_quaternion = ti.field(vec4, n)
        self.pair_rest_darboux = ti.field(vec3, n)
        #: Current, previous-substep, begin-of-step and end-of-step-target quaternions [-].
        self.edge_quaternion = ti.field(vec4, n)
        self.edge_quaternion_previous = ti.field(vec4, n)
        self.edge_quaternion_begin = ti.field(vec4, n)
        self.edge_quaternion_target = ti.field(vec4, n)
        #: Angular velocity of each edge frame, world frame [rad/s].
        self.edge_omega = ti.field(vec3, n)
        #: Lagrange multipliers of the current substep [-] (XPBD, reset each substep).
        self.edge_lambda = ti.field(vec3, n)
        self.pair_lambda = ti.field(vec3, n)
        #: Constraint values at the start of the substep (damping) [-].
        self.edge_constraint_start = ti.field(vec3, n)
        self.pair_constraint_start = ti.field(vec3, n)
        #: Previous-substep positions [m]; end-of-step targets of kinematic vertices [m].
        self.vertex_position_previous = ti.field(vec3, n)
        self.vertex_target = ti.field(vec3, n)
        #: Begin-of-step copies of the State (restored on divergence).
        self.vertex_position_begin = ti.field(vec3, n)
        self.vertex_velocity_begin = ti.field(vec3, n)
        self.edge_twist_begin = ti.field(float, n)
        self.edge_angular_velocity_begin = ti.field(float, n)
        self.edge_tangent_begin = ti.field(vec3, n)
        self.edge_reference_director_begin = ti.field(vec3, n)
        self.edge_reference_twist_begin = ti.field(float, n)


class SolverXPBD(SolverBase):
    """XPBD Cosserat-rod integrator (module docstring), same interface as :class:`SolverADMM`.

    Args:
        model: the :class:`Model` to simulate.
        config: :class:`SolverXPBDConfig`.
        profile: if True, synchronise after each step and accumulate its wall time in
            ``stage_seconds["substeps"]``.
        colliders: must be None or empty: SolverXPBD has no collision handling (a baseline solver).
    """

    FIELD_NAMES = _FIELD_NAMES
    STAGES = ("substeps",)

    def __init__(self, model: Model, config: SolverXPBDConfig | None = None, profile: bool = False,
                 colliders=None):
        self._init_base(model, profile)
        if colliders is not None and len(colliders) > 0:
            raise ValueError("SolverXPBD has no collision handling: colliders must be None (use SolverADMM or "
                             "SolverShape for bodies)")
        self.config = config or SolverXPBDConfig()
        if not isinstance(self.config, SolverXPBDConfig):
            raise ValueError(f"SolverXPBD: config must be a SolverXPBDConfig, got {type(self.config).__name__}")
        schedule = self.config.schedule
        if schedule == Schedule.AUTO:
            schedule = Schedule.STAGE if on_gpu() else Schedule.STRAND
        #: Resolved schedule: "stage" (one launch per substep, parallel over vertices) or "strand".
        self.schedule = schedule
        self.buf = XPBDBuffers(model.vertex_count)
        self._bad = ti.field(ti.i32, ())
        self._set_coefficients()
        #: Vertex-iterations done so far (vertex_count x substeps x iterations per step) [-].
        self.vertex_iteration_count = 0

    def _set_coefficients(self) -> None:
        """Inverse masses, compliances and rest strains (host side, float64)."""
        m, cfg, h = self.model, self.config, self.model.host
        n = m.vertex_count
        le = h["edge_rest_length"]
        local = h["vertex_local_index"]
        strand = h["vertex_strand"]
        clamped = h["strand_body"][strand] >= 0
        edge_ok = le > 0
        active = h["pair_is_active"].astype(bool)
        f = _np_float()
        b = self.buf
        b.vertex_inverse_mass.from_numpy(np.where(h["vertex_is_fixed"] != 0, 0.0, 1.0 / h["vertex_mass"]).astype(f))
        if cfg.frame_inertia == FrameInertia.SEGMENT:
            inertia = h["strand_density"][strand] * h["strand_area"][strand] * le**3 / 12.0
        else:
            inertia = h["edge_rotational_inertia"]
        inertia = cfg.frame_inertia_scale * inertia
        kinematic_edge = ~edge_ok | (clamped & (local == 0))
        b.edge_inverse_inertia.from_numpy(
            np.where(kinematic_edge, 0.0, 1.0 / (4.0 * np.where(edge_ok, inertia, 1.0))).astype(f))
        b.edge_compliance.from_numpy(
            np.where(edge_ok, 1.0 / np.where(edge_ok, h["edge_stretch_stiffness"], 1.0), 0.0).astype(f))
        vstar = m.pair_voronoi_length(cfg.voronoi_rescaling)
        modulus = np.where(active[:, None], h["pair_bending_modulus"], 1.0)
        b.pair_compliance.from_numpy(np.where(active[:, None], vstar[:, None] / modulus, 0.0).astype(f))
        tau = h["strand_damping_time"][strand] if cfg.strain_rate_damping else np.zeros(n)
        b.edge_damping_time.from_numpy(np.where(edge_ok, tau, 0.0).astype(f))
        b.pair_damping_time.from_numpy(np.where(active, tau, 0.0).astype(f))
        # Rest quaternions from the rest material frames (the builder's input shape and twists).
        rest = m.state()
        d1 = rest.edge_material_d1.to_numpy().astype(np.float64)
        d2 = rest.edge_material_d2.to_numpy().astype(np.float64)
        t = rest.edge_tangent.to_numpy().astype(np.float64)
        q = np.zeros((n, 4))  # (x, y, z, w), taichi_hair.rotation's order
        q[edge_ok] = quat_from_matrix_np(np.stack([d1[edge_ok], d2[edge_ok], t[edge_ok]], axis=2))
        darboux = np.zeros((n, 3))
        ia = np.where(active)[0]
        r = quat_mul_np(quat_conjugate_np(q[ia - 1]), q[ia])
        s = np.where(r[:, 3] < 0, -1.0, 1.0)
        darboux[ia] = 2.0 * s[:, None] * r[:, :3]
        b.edge_rest_quaternion.from_numpy(q.astype(f))
        b.pair_rest_darboux.from_numpy(darboux.astype(f))
        self.host_pair_voronoi_bend = vstar

    # ------------------------------------------------------------------ stepping
    def step(self, state: State, control: Control, dt: float) -> None:
        """Advance ``state`` in place by one time step of ``config.substeps`` XPBD substeps.

        Args:
            state: positions, velocities, twists and frames at the beginning of the step.
            control: body transforms at the *end* of the step (roots are interpolated
                linearly across the substeps), gravity and air velocity.
            dt: time step [s].

        Raises:
            ValueError: for a non-finite or non-positive dt.
            SimulationDivergedError: if any value becomes non-finite; ``state`` is then
                restored to the beginning of the step.
        """
        self._check_dt(dt)
        t0 = self._tick()
        m, b, cfg = self.model, self.buf, self.config
        n_sub = cfg.substeps
        dts = dt / n_sub
        g = vec3(*control.gravity)
        v_air = vec3(*control.air_velocity)
        damping = 1.0 / dts  # gamma = tau / dt_s, tau stored per constraint
        decay = math.exp(-cfg.damping * dts)
        xc.begin_step(m.vertex, m.edge, m.strand, control.body_rotation, control.body_translation, state, state, b)
        if self.schedule == Schedule.STRAND:
            xc.substeps_strand(m.vertex, m.edge, m.pair, m.strand, state, b, g, v_air, cfg.air_viscosity, dts, dts * dts, n_sub,
                               cfg.iterations, damping, decay)
        for k in range(n_sub if self.schedule == Schedule.STAGE else 0):
            fraction = (k + 1) / n_sub
            if cfg.iterations <= _FUSED_ITERATIONS:
                # (a-c) in one launch, the sweeps unrolled.
                xc.substep(cfg.iterations, m.vertex, m.edge, m.pair, state, b, g, v_air, cfg.air_viscosity, dts,
                           fraction, damping,
                           decay)
            else:
                xc.predict(m.vertex, m.edge, m.pair, state, b, g, v_air, cfg.air_viscosity, dts, fraction)
                for _ in range(cfg.iterations):
                    xc.solve_constraints(m.vertex, m.edge, m.pair, state.vertex_position, b, dts * dts, damping)
                xc.update_velocities(m.edge, state, b, dts, decay)
        update_reference_frames(True, m.vertex, m.edge, m.pair, m.strand, control.body_rotation,
                                state.vertex_position, state.edge_twist,
                                state)
        xc.write_twists(m.edge, state, b)
        self.step_count += 1
        self.vertex_iteration_count += m.vertex_count * n_sub * cfg.iterations
        self._tock("substeps", t0)
        if cfg.check_finite:
            self.check_finite(state)

    def _non_finite_code(self, state: State) -> int:
        find_non_finite(self.model.vertex, state, state, self._bad)
        return int(self._bad[None])

    def _restore_begin(self, state: State) -> None:
        xc.restore_begin(state, state, self.buf)

    # ------------------------------------------------------------------ diagnostics
    def edge_stretch(self, state: State) -> np.ndarray:
        """Stretch strain |e_j|/l_j - 1 of every edge (host, float64), shape (vertex_count,), 0 on ghosts [-]."""
        h = self.model.host
        x = state.vertex_position.to_numpy().astype(np.float64)
        le = h["edge_rest_length"]
        e = np.zeros_like(x)
        e[:-1] = x[1:] - x[:-1]
        ok = le > 0
        out = np.zeros(le.shape[0])
        out[ok] = np.linalg.norm(e[ok], axis=1) / le[ok] - 1.0
        return out

