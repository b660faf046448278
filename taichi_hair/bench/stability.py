"""Stability atlas (issue 4, item 5): where each method is stable, stable but wrong, or unstable.

For each method (``admm``: :class:`SolverADMM` with the paper's constraint weight scale
w0 = 25 and plain iteration; ``admm_w1``: w0 = 1, plain; ``admm_aa``: w0 = 1 with
Anderson acceleration (the default on these straight rods); ``admm_bdf2``: w0 = 1, BDF2, plain
(:mod:`taichi_hair.bench.methods`); ``shape``: :class:`SolverShape` (TressFX),
``xpbd``: :class:`SolverXPBD`) we run a grid of

* time step dt per call to ``step`` (1/24 to 1/384 s by default);
* the method's iteration knob: ADMM iterations per step; SolverShape local-shape and
  edge-length iterations per step (both set to the knob); XPBD substeps per step (one
  constraint sweep each: small-step XPBD, Macklin et al. 2019, is how XPBD is meant to be run);
* rod cases, all strands of ONE Model so a knob setting is one run (hair material of Daviet
  2023 Fig. 2, clamped horizontally and released under gravity):

  ``short``: 5 cm, 20 edges (Gamma = 0.85);
  ``long``: 50 cm, 200 edges (Gamma = 850): the long chain that is hard for local methods;
  ``edge-variance``: 10 cm, 40 edges whose lengths vary by a factor of up to 16 (log-uniform
  in [0.25, 4] times the mean, seeded), the ADMM paper's first hard case (Sec. 6.1);
  ``stretch-stiff``: 10 cm, 40 edges, E_s = 1000 E_b: very different stretching and bending
  stiffnesses, the ADMM paper's second hard case (Sec. 6.1).

Every run simulates ``duration`` (1.5) seconds with the same physical damping for all methods (a
velocity relaxation rate ``drag_rate`` = 8 /s, so oscillation amplitudes decay as exp(-4 t):
ADMM air drag xi = rate rho A, SolverShape's Verlet
damping c = 1 - exp(-rate dt), XPBD's damping = rate), so a stable run ends near the
cantilever's equilibrium.  Each cell (method, case, dt, knob) is classified by
:func:`classify`:

* ``unstable``: a non-finite value, or energy growth: the strand's kinetic plus gravitational
  energy exceeded its initial value by more than ``energy_tolerance`` m g L at any sampled
  step.  (A damped passive rod released from rest can only lose energy, and its elastic energy
  is >= 0, so kinetic + gravity <= initial holds whatever the elastic model; checking it needs
  no elastic energy, which the three methods define differently.)
* ``wrong`` (stable but wrong): largest edge stretch above 1 % at the end, or the tip's drop
  H off by more than 10 % from the heavy elastica at the rod's Gamma
  (:func:`taichi_hair.validation.elastica.solve_heavy_elastica`; the continuum reference, so
  the discretisation error of the model itself, ~1-2 % at these resolutions, is included),
  or, for rods that have not settled, a tip speed above ``settle_speed`` at the end.  A rod
  that stretches a lot under gravity lowers its potential energy, so a method that lets rods
  fall apart (SolverShape with few length iterations: stretches of 20x were measured) is
  "wrong" here, not "unstable": energy growth catches blow-ups, the stretch criterion the rest.
* ``ok``: stable and accurate.

Why two ADMM rows: w0 matters as much as the iteration count.  Measured (this Model, dt = 1/96 s,
50 iterations, drag 8 /s; script and output in
benchmarks/results/stability/admm_w0_settling.txt): with w0 = 25 the tip drops were still
off by 3-37 % after 1 to 6 s of simulated time, the rods oscillating at 0.003-0.19 m/s despite
the drag (each step's ADMM solve stops short of its minimum and the leftover keeps them
moving); with w0 = 1 the three hair-like rods settled within 2 s to 0.1-1.2 % of the elastica,
but the E_s = 1000 E_b rod went non-finite (the Sec. 6.1 limitation: a weight set from the
bending stiffness is far too soft for a very stiff stretch).  Neither the dual warm start (off: -20 %, -15 %
sag errors after 3 s) nor the dual frame ("pair": same as "root") is the cause; w0 = 5 settles
to ~1 % in the same 3 s (second study in the same file).

Default atlas, measured (``taichi-hair bench stability --out benchmarks/results/stability``,
2026-12-02 13:40 UTC, commit 0e514de, 2-core VM at load ~1, f32 CPU,
158 s; cells ok / wrong / unstable out of 36 per method):
``admm`` (w0 = 25, plain) 5 / 31 / 0 (never unstable, accurate only at dt = 1/384 s with 10-50
iterations); ``admm_aa`` (w0 = 1, Anderson window 5, the default on these rods) 23 / 11 / 2 (ok for every rod with
10 and 50 iterations from dt = 1/96 s on and with 50 at 1/24 s; wrong with 2 iterations everywhere but
1/384 s and with 10 at 1/24 s on three rods; unstable only with 2 iterations at 1/384 s on the long and
edge-variance rods, where Anderson does not mix and the cells are the plain iteration's);
``admm_w1`` (w0 = 1, plain) 18 / 16 / 2 (at 10 iterations and
1/96 s the long rod does not settle and the edge-variance rod sags 12.7 % wrong; before the Woodbury
local step it was 12 / 13 / 11, every stiff-stretch cell non-finite); ``admm_bdf2`` (w0 = 1, plain,
BDF2) 14 / 14 / 8 (BDF2's extrapolated predictor amplifies an unconverged ADMM step: 2 iterations are
unstable at 1/96 and 1/384 s, and 10 iterations at 1/96 s on the edge-variance rod; with 50
iterations every cell from 1/96 s on is ok); ``shape`` 3 / 24 / 9 (no bending
stiffness, so the sag is not the elastica's; the follow-the-leader pass with Mueller's velocity
correction gains energy on the long and edge-variance rods at dt = 1/384 s and at 2 iterations at
1/24 s, up to 5.4 m g L); ``xpbd`` 1 / 31 / 4.
So: ADMM with w0 = 1 and Anderson acceleration is the most often right; the paper's w0 = 25 is the
only never unstable one; BDF2 needs converged steps; the local methods fail first on the long chain
and the uneven edges.

"Lost rest shape" is not a separate criterion here: the rods are straight, so a lost rest shape
shows as a sag error.  SolverShape has no bending stiffness (its shape constraints are
stiffness-free goals), so its sag does not follow the elastica: at any knob it is "wrong" by
this measure unless its goals happen to match; that is the method, not a bug.
"""

from __future__ import annotations

import csv
import json
import math
import os
import time
from dataclasses import dataclass

import numpy as np

from ..validation.elasticity_params import GRAVITY, HAIR
from .methods import admm_config, is_admm

LABELS = ("unstable", "wrong", "ok")
METHODS = ("admm", "admm_w1", "admm_aa", "admm_bdf2", "shape", "xpbd")
KNOB_NAMES = {"admm": "iterations", "admm_w1": "iterations", "admm_aa": "iterations", "admm_bdf2": "iterations",
              "shape": "iterations",
              "xpbd": "substeps"}


@dataclass
class StabilityThresholds:
    """Thresholds of :func:`classify`.

    Attributes:
        energy_tolerance: allowed growth of kinetic + gravitational energy above its initial
            value, in units of the strand's m g L [-].
        stretch: largest edge strain |l / l_rest - 1| accepted at the end [-].
        sag: relative error of the tip drop H against the reference accepted at the end [-].
        settle_speed: largest tip speed accepted at the end [m/s].
    """

    energy_tolerance: float = 0.05
    stretch: float = 0.01
    sag: float = 0.10
    settle_speed: float = 0.05

    def __post_init__(self):
        for name in ("energy_tolerance", "stretch", "sag", "settle_speed"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"StabilityThresholds.{name} must be a finite positive number, got {v!r}")


def classify(finite: bool, energy_gain: float, stretch: float, sag_error: float, tip_speed: float,
             thresholds: StabilityThresholds | None = None) -> tuple[str, str]:
    """Label one strand's run: ``("unstable" | "wrong" | "ok", reason)``.

    Args:
        finite: every position and velocity stayed finite.
        energy_gain: largest (E_kin + E_grav - E_initial) / (m g L) over the sampled steps [-].
        stretch: largest |l / l_rest - 1| over the strand's edges at the end [-].
        sag_error: |H - H_ref| / H_ref of the tip drop at the end [-].
        tip_speed: tip speed at the end [m/s].
    """
    th = thresholds or StabilityThresholds()
    if not finite or not all(math.isfinite(v) for v in (energy_gain, stretch, sag_error, tip_speed)):
        return "unstable", "non-finite values"
    if energy_gain > th.energy_tolerance:
        return "unstable", f"energy grew by {energy_gain:.3g} m g L"
    reasons = []
    if stretch > th.stretch:
        reasons.append(f"stretch {100 * stretch:.3g}%")
    if sag_error > th.sag:
        reasons.append(f"sag error {100 * sag_error:.3g}%")
    if tip_speed > th.settle_speed:
        reasons.append(f"not settled ({tip_speed:.3g} m/s)")
    if reasons:
        return "wrong", ", ".join(reasons)
    return "ok", ""


# --------------------------------------------------------------------------- cases
@dataclass
class RodCase:
    """One strand of the atlas: ``name``, length [m], edge lengths [m] (sum = length), E_s / E_b [-]."""

    name: str
    length: float
    edge_lengths: np.ndarray
    stretch_ratio: float = 1.0


def default_cases(seed: int = 0) -> list[RodCase]:
    rng = np.random.default_rng(seed)
    var = np.exp(rng.uniform(math.log(0.25), math.log(4.0), 40))
    var *= 0.10 / var.sum()
    return [RodCase("short", 0.05, np.full(20, 0.05 / 20)),
            RodCase("long", 0.50, np.full(200, 0.50 / 200)),
            RodCase("edge-variance", 0.10, var),
            RodCase("stretch-stiff", 0.10, np.full(40, 0.10 / 40), 1000.0)]


def build_case_model(cases):
    """One clamped horizontal (+x) strand per case, roots 1 cm apart along z [m]."""
    from ..builder import GroomBuilder
    from ..config import RodMaterial

    b = GroomBuilder()
    for i, c in enumerate(cases):
        x = np.concatenate([[0.0], np.cumsum(c.edge_lengths)])
        mat = RodMaterial(radius=HAIR["radius"], density=HAIR["density"],
                          youngs_modulus_bend=HAIR["youngs_modulus_bend"],
                          youngs_modulus_stretch=HAIR["youngs_modulus_bend"] * c.stretch_ratio,
                          poisson_ratio=HAIR["poisson_ratio"])
        b.add_strand(np.c_[x, np.zeros_like(x), np.full_like(x, 0.01 * i)], mat, root_director=(0.0, 0.0, 1.0))
    return b.finalize()


def reference_tip_drop(length: float) -> float:
    """Tip drop H [m] of the horizontally clamped heavy elastica of hair of this length."""
    from ..validation.elastica import cantilever_gamma, solve_heavy_elastica

    g = cantilever_gamma(length, HAIR["radius"], HAIR["density"], HAIR["youngs_modulus_bend"])
    return solve_heavy_elastica(g).height * length


# --------------------------------------------------------------------------- runs
class StrandMonitor:
    """Per-strand energy, stretch, tip drop and tip speed of a Model's State (host-side, float64).

    ``sample(state)`` records the largest growth of kinetic + gravitational energy seen so far.
    """

    def __init__(self, model, gravity=GRAVITY):
        h = model.host
        self.model = model
        self.starts = h["strand_vertex_start"].astype(np.int64)
        self.counts = h["strand_vertex_count"].astype(np.int64)
        self.tips = self.starts + self.counts - 1
        self.mass = h["vertex_mass"].astype(np.float64)
        self.strand = h["vertex_strand"].astype(np.int64)
        self.rest = h["vertex_rest_position"].astype(np.float64)
        self.rest_length = h["edge_rest_length"].astype(np.float64)
        self.gravity = gravity
        ns = len(self.starts)
        lengths = np.array([self.rest_length[s:s + c - 1].sum() for s, c in zip(self.starts, self.counts)])
        self.scale = np.bincount(self.strand, self.mass, ns) * gravity * lengths
        self.reset()

    def reset(self) -> None:
        ns = len(self.starts)
        self.energy0 = None
        self.energy_gain = np.full(ns, -np.inf)
        self.finite = np.ones(ns, bool)

    def _energy(self, x, v):
        e = 0.5 * self.mass * np.sum(v * v, axis=1) + self.mass * self.gravity * x[:, 1]
        return np.bincount(self.strand, e, len(self.starts))

    def sample(self, state) -> None:
        x = state.vertex_position.to_numpy().astype(np.float64)
        v = state.vertex_velocity.to_numpy().astype(np.float64)
        ok = np.isfinite(x).all(axis=1) & np.isfinite(v).all(axis=1)
        self.finite &= np.bincount(self.strand, ~ok, len(self.starts)) == 0
        with np.errstate(all="ignore"):
            e = self._energy(np.where(ok[:, None], x, 0.0), np.where(ok[:, None], v, 0.0))
        if self.energy0 is None:
            self.energy0 = e
        self.energy_gain = np.maximum(self.energy_gain, (e - self.energy0) / self.scale)

    def final(self, state):
        """(stretch, tip drop [m], tip speed [m/s]) per strand."""
        x = state.vertex_position.to_numpy().astype(np.float64)
        v = state.vertex_velocity.to_numpy().astype(np.float64)
        ns = len(self.starts)
        stretch = np.zeros(ns)
        with np.errstate(all="ignore"):
            for i, (s, c) in enumerate(zip(self.starts, self.counts)):
                le = np.linalg.norm(np.diff(x[s:s + c], axis=0), axis=1)
                stretch[i] = np.max(np.abs(le / self.rest_length[s:s + c - 1] - 1.0))
            drop = x[self.starts, 1] - x[self.tips, 1]
            speed = np.linalg.norm(v[self.tips], axis=1)
        return stretch, drop, speed


def make_solver(method: str, model, drag_rate: float, knob: int, dt: float):
    """A solver of ``method`` with the atlas's damping; its knob set by :func:`set_knob`."""
    rho_a = HAIR["density"] * math.pi * HAIR["radius"] ** 2
    from ..solvers import make_solver

    if is_admm(method):
        return make_solver("admm", model, admm_config(method, iterations=knob, air_viscosity=drag_rate * rho_a,
                                                      check_finite=False))
    if method == "shape":
        from ..solvers.shape.solver import ShapeRegion, SolverShapeConfig

        region = ShapeRegion(local_iterations=knob, length_iterations=knob,
                             damping=1.0 - math.exp(-drag_rate * dt))
        return make_solver("shape", model, SolverShapeConfig(regions=(region,), air_drag=0.0, check_finite=False))
    if method == "xpbd":
        from ..solvers.xpbd.solver import SolverXPBDConfig

        return make_solver("xpbd", model, SolverXPBDConfig(substeps=knob, iterations=1, damping=drag_rate,
                                                           check_finite=False))
    raise ValueError(f"method must be one of {METHODS}, got {method!r}")


def set_knob(method: str, solver, knob: int, dt: float, drag_rate: float) -> None:
    """Change a solver's knob (and its per-step damping for dt) between runs, without recompiling."""
    if is_admm(method):
        solver.config.iterations = int(knob)
        solver.reset_duals()
    elif method == "shape":
        r = solver.config.regions[0]
        r.local_iterations = r.length_iterations = int(knob)
        r.damping = 1.0 - math.exp(-drag_rate * dt)
        solver.upload_regions()
    else:
        solver.config.substeps = int(knob)


@dataclass
class Cell:
    method: str
    case: str
    dt: float
    knob: int
    label: str
    reason: str
    energy_gain: float
    stretch: float
    sag_error: float
    tip_speed: float
    seconds: float


def run_and_classify(model, solver, state, control, cases, dt: float, duration: float,
                     monitor: StrandMonitor | None = None, drop_reference=None,
                     thresholds: StabilityThresholds | None = None, samples: int = 30):
    """Reset ``state`` to rest, step ``solver`` for ``duration`` [s] at ``dt`` [s], classify every strand.

    Works with any solver having ``step(state, control, dt)`` and ``check_finite=False`` (so that
    a non-finite strand does not stop the others).  Returns (seconds, list of (label, reason,
    energy_gain, stretch, sag_error, tip_speed)) with one entry per case (= strand).
    """
    monitor = monitor or StrandMonitor(model)
    drop_ref = (np.array([reference_tip_drop(c.length) for c in cases]) if drop_reference is None
                else np.asarray(drop_reference, float))
    steps = max(1, int(round(duration / dt)))
    every = max(1, steps // samples)
    model.reset_state(state)
    monitor.reset()
    monitor.sample(state)
    t0 = time.perf_counter()
    for k in range(steps):
        solver.step(state, control, dt)
        if (k + 1) % every == 0 or k + 1 == steps:
            monitor.sample(state)
    seconds = time.perf_counter() - t0
    stretch, drop, speed = monitor.final(state)
    with np.errstate(all="ignore"):
        sag = np.abs(drop / drop_ref - 1.0)
    out = []
    for i in range(len(cases)):
        label, reason = classify(bool(monitor.finite[i]), float(monitor.energy_gain[i]), float(stretch[i]),
                                 float(sag[i]), float(speed[i]), thresholds)
        out.append((label, reason, float(monitor.energy_gain[i]), float(stretch[i]), float(sag[i]), float(speed[i])))
    return seconds, out


def run_atlas(methods=METHODS, dts=(1 / 24, 1 / 96, 1 / 384), knobs=None, cases=None, duration: float = 1.5,
              drag_rate: float = 8.0, samples: int = 30, thresholds: StabilityThresholds | None = None,
              progress=None) -> list[Cell]:
    """Run every (method, dt, knob) on one Model holding all ``cases``; one Cell per case.

    Args:
        methods: subset of :data:`METHODS`.
        dts: time steps per call to ``step`` [s].
        knobs: dict method -> knob values (default ADMM/Shape iterations 2, 10, 50; XPBD substeps 2, 10, 50).
        cases: list of :class:`RodCase` (default :func:`default_cases`).
        duration: simulated time per run [s].
        drag_rate: velocity relaxation rate of the damping [1/s].
        samples: energy samples per run (plus the first and last step).
        progress: optional callable(text).
    """
    th = thresholds or StabilityThresholds()
    cases = default_cases() if cases is None else cases
    knobs = knobs or {m: (2, 10, 50) for m in METHODS}
    for m in methods:
        if m not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {m!r}")
    model = build_case_model(cases)
    state, control = model.state(), model.control()
    control.gravity = (0.0, -GRAVITY, 0.0)
    monitor = StrandMonitor(model)
    drop_ref = np.array([reference_tip_drop(c.length) for c in cases])
    cells = []
    for method in methods:
        solver = None
        for dt in dts:
            for knob in knobs[method]:
                if solver is None:
                    solver = make_solver(method, model, drag_rate, knob, dt)
                    solver.step(state, control, dt)  # compile the kernels outside the timed runs
                set_knob(method, solver, knob, dt, drag_rate)
                seconds, res = run_and_classify(model, solver, state, control, cases, dt, duration, monitor,
                                                drop_ref, th, samples)
                for c, r in zip(cases, res):
                    cells.append(Cell(method, c.name, dt, int(knob), *r, seconds))
                if progress is not None:
                    got = ", ".join(f"{c.case}: {c.label}" for c in cells[-len(cases):])
                    progress(f"{method} dt = 1/{1 / dt:.0f} s, {KNOB_NAMES[method]} {knob}: {got} ({seconds:.1f} s)")
    return cells


# --------------------------------------------------------------------------- outputs
def write_outputs(cells: list[Cell], out_dir: str) -> list[str]:
    """``stability.csv`` and one heatmap ``stability_<method>.png`` per method; returns the paths."""
    os.makedirs(out_dir, exist_ok=True)
    paths = []
    csv_path = os.path.join(out_dir, "stability.csv")
    with open(csv_path + ".tmp", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["method", "case", "dt_s", "knob_name", "knob", "label", "reason", "energy_gain_mgL",
                    "max_stretch", "sag_error", "tip_speed_m_per_s", "run_seconds"])
        for c in cells:
            w.writerow([c.method, c.case, f"{c.dt:.6g}", KNOB_NAMES[c.method], c.knob, c.label, c.reason,
                        f"{c.energy_gain:.4g}", f"{c.stretch:.4g}", f"{c.sag_error:.4g}", f"{c.tip_speed:.4g}",
                        f"{c.seconds:.3f}"])
    os.replace(csv_path + ".tmp", csv_path)
    paths.append(csv_path)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap

    cmap = ListedColormap(["#d7301f", "#fdae61", "#1a9850"])
    for method in dict.fromkeys(c.method for c in cells):
        mc = [c for c in cells if c.method == method]
        case_names = list(dict.fromkeys(c.case for c in mc))
        knobs = sorted(set(c.knob for c in mc))
        dts = sorted(set(c.dt for c in mc), reverse=True)
        rows = [(cn, k) for cn in case_names for k in knobs]
        grid = np.full((len(rows), len(dts)), np.nan)
        text = [["" for _ in dts] for _ in rows]
        for c in mc:
            i, j = rows.index((c.case, c.knob)), dts.index(c.dt)
            grid[i, j] = LABELS.index(c.label)
            text[i][j] = {"unstable": "X", "wrong": "~", "ok": "ok"}[c.label]
        fig, ax = plt.subplots(figsize=(1.6 + 1.1 * len(dts), 1.2 + 0.32 * len(rows)))
        ax.imshow(grid, cmap=cmap, vmin=0, vmax=2, aspect="auto")
        for i in range(len(rows)):
            for j in range(len(dts)):
                ax.text(j, i, text[i][j], ha="center", va="center", fontsize=7)
        ax.set_xticks(range(len(dts)), [f"1/{1 / d:.0f}" for d in dts])
        ax.set_yticks(range(len(rows)), [f"{cn}, {KNOB_NAMES[method][:4]}. {k}" for cn, k in rows], fontsize=7)
        ax.set_xlabel("time step dt [s]")
        ax.set_title(f"{method}: green ok, orange stable but wrong (~), red unstable (X)", fontsize=8)
        fig.tight_layout()
        p = os.path.join(out_dir, f"stability_{method}.png")
        fig.savefig(p + ".tmp.png", dpi=110)
        plt.close(fig)
        os.replace(p + ".tmp.png", p)
        paths.append(p)
    summary = {m: {lab: sum(1 for c in cells if c.method == m and c.label == lab) for lab in LABELS}
               for m in dict.fromkeys(c.method for c in cells)}
    jp = os.path.join(out_dir, "stability_summary.json")
    with open(jp, "w") as fh:
        json.dump(summary, fh, indent=1)
    paths.append(jp)
    return paths


def format_summary(cells: list[Cell]) -> str:
    lines = []
    for m in dict.fromkeys(c.method for c in cells):
        mc = [c for c in cells if c.method == m]
        counts = ", ".join(f"{lab} {sum(1 for c in mc if c.label == lab)}" for lab in LABELS)
        lines.append(f"{m}: {len(mc)} cells: {counts}")
    return "\n".join(lines)
