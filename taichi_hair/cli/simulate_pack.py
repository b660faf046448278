"""Several ``simulate`` runs of one scene stepped as one Model: a batch pack (issue 18, item 4).

``taichi-hair batch`` packs runs that differ only in their grooms (seed, strands, length, vertices per strand,
``groom.*`` and ``material.*`` keys) into one task, where :class:`PackedSimulate` merges their grooms into one
Model (:meth:`~taichi_hair.builder.GroomBuilder.merged`), builds one solver, compiles its kernels once, steps
all of them together and writes each run's folder as ``simulate --out DIR/<name>`` would.  What a small run
costs is mostly set-up and kernel loading (~4 s against ~0.4 s of stepping for the hang scene's 20 strands,
BENCHMARKS.md "Batches on Dask"): a pack pays it once.

When (:func:`pack_refusal` says why not, and the runs then go one by one):

* the ADMM solver without a contact pipeline (no colliders, no hair-hair contacts): then nothing couples two
  strands.  Every stage of the step is per strand (the strand schedule runs a strand in one thread; no
  reduction over strands feeds back into the state) and the Model's host arrays are computed per strand, so
  each run's strands see the arithmetic of their own run and its frames are those of the run alone, bit for
  bit (tests/test_batch.py).  Two Model-wide choices are checked against each run's own after the solver is
  built: the twist unknowns dropped or solved (:func:`taichi_hair.frames.twist_choice`), and with it the
  Anderson window; and the schedule is each run's own (:func:`pack_schedule`: "auto" takes the lanes only for
  large Models, and a pack is larger than its runs);
* the authored rest pose, the same solver settings, fps, substeps, frames, gravity, body motion (sampled at
  every substep), arch and precision; no ``--equilibrium``, ``--max-error`` / ``--budget-ms``, ``--resume``
  (a run with a checkpoint resumes alone) or ``--profile``.

What each run gets: its own frames, ``stats.csv`` (its ``ms`` column is the pack's time per frame) and
``summary.json`` (timings are the pack's; a ``pack`` block names the runs stepped with it), no checkpoints (a
pack that is killed runs again whole).  A pack that diverges falls back to running each run alone, so a
failing run reports exactly what it would alone and the others are not lost.
"""

from __future__ import annotations

import json
import os
import time

import numpy as np

#: Most runs in one pack.
MAX_PACK = 64


class PackRefused(Exception):
    """The runs cannot be stepped as one Model (the message says why); run them one by one."""


class _RunModel:
    """What a run's reports read of its Model: its own host arrays (``GroomBuilder.host_arrays``) and counts."""

    def __init__(self, host: dict, materials: list, body_count: int):
        self.host, self.materials, self.body_count = host, materials, body_count
        self.vertex_count = int(host["vertex_strand"].shape[0])
        self.strand_count = int(host["strand_vertex_start"].shape[0])


class _HostField:
    """``.to_numpy()`` of a run's slice of a pack field, read once per frame by the pack."""

    def __init__(self, read):
        self._read = read

    def to_numpy(self):
        return self._read()


class _RunState:
    """A run's vertices [v0, v1) of the pack's State at the current frame."""

    def __init__(self, pack: "PackedSimulate", v0: int, v1: int):
        self._pack, self._v0, self._v1 = pack, v0, v1
        self.vertex_velocity = _HostField(lambda: pack.v[v0:v1])

    def positions(self):
        return self._pack.x[self._v0:self._v1]


def pack_refusal(runs: list) -> str | None:
    """Why the runs (each a :class:`~taichi_hair.cli.simulate_run.SimulateRun`, not yet run) cannot be packed,
    or None when they can (the checks that need no Model; see the module docstring)."""
    if len(runs) < 2:
        return "a single run"
    first = runs[0]
    for r in runs:
        sc, a = r.scene, r.args
        name = a.out
        if sc.solver != "admm":
            return f"{name}: solver {sc.solver!r} (packs are for the ADMM solver)"
        if getattr(sc.solver_config, "contacts", None) is not None or sc.colliders:
            return f"{name}: contacts or colliders couple strands"
        if sc.rest_pose != "authored":
            return f"{name}: rest pose {sc.rest_pose!r}"
        if a.equilibrium or a.max_error is not None or a.budget_ms is not None or a.resume or a.profile:
            return f"{name}: --equilibrium, --max-error, --budget-ms, --resume or --profile"
        for what, mine, theirs in (("solver settings", sc.solver_config, first.scene.solver_config),
                                   ("fps", sc.fps, first.scene.fps), ("substeps", sc.substeps, first.scene.substeps),
                                   ("frames", sc.frames, first.scene.frames),
                                   ("gravity", tuple(sc.gravity), tuple(first.scene.gravity)),
                                   ("bodies", sc.body_count, first.scene.body_count),
                                   ("arch", a.arch, first.args.arch), ("precision", a.precision, first.args.precision)):
            if mine != theirs:
                return f"{name}: other {what} than {first.args.out}"
    times = [((f - 1) * first.scene.substeps + k + 1) / (first.scene.fps * first.scene.substeps)
             for f in range(1, first.scene.frames + 1) for k in range(first.scene.substeps)]
    motion = [np.array([[np.r_[R.ravel(), T] for R, T in r.scene.body_transforms(t)] for t in [0.0, *times]])
              for r in runs]
    for r, m in zip(runs[1:], motion[1:]):
        if not np.array_equal(m, motion[0]):
            return f"{r.args.out}: other body motion than {first.args.out}"
    return None


def pack_schedule(config, run_vertices) -> str:
    """The schedule of a pack's solver (``config``: the runs' SolverADMMConfig; ``run_vertices``: each run's vertex
    count): each run's own.  ``"auto"`` resolves by Model size (``lanes.auto_schedule``) and a pack is larger than its
    runs, so it takes what the runs take alone; they must agree, and not on the lanes, which step strands in groups of
    eight across the runs of a pack (no longer each run's own arithmetic): :class:`PackRefused` otherwise."""
    from ..config import Schedule, StrainMeasure, Tridiagonal
    from ..lanes import auto_schedule
    from ..solver_base import on_gpu

    alone = {config.schedule} if config.schedule != Schedule.AUTO else {
        auto_schedule(on_gpu(), config.tridiagonal == Tridiagonal.PCR, config.strain_measure == StrainMeasure.KORNER, n)
        for n in run_vertices}
    if len(alone) > 1:
        raise PackRefused(f"alone the runs take the schedules {sorted(alone)}")
    schedule = alone.pop()
    if schedule == Schedule.LANES:
        raise PackRefused("the lanes schedule steps strands in groups of eight across the runs of a pack")
    return schedule


class PackedSimulate:
    """Step ``runs`` (SimulateRun objects made with their args, scene and layout, Taichi initialised once) as
    one Model; :meth:`run` returns each run's exit status, or raises :class:`PackRefused` (nothing kept: the
    caller runs them one by one)."""

    def __init__(self, runs: list):
        why = pack_refusal(runs)
        if why is not None:
            raise PackRefused(why)
        self.runs = runs
        self.x = self.v = None

    def run(self) -> list:
        from dataclasses import replace

        from .. import SimulationDivergedError
        from ..builder import GroomBuilder
        from ..solvers import make_solver
        from ..frames import twist_choice
        from .simulate_run import SimulateRun, _atomic_text

        runs, first = self.runs, self.runs[0]
        t = time.perf_counter()
        builders = [r.scene.builder() for r in runs]
        hosts = [b.host_arrays() for b in builders]
        counts = [int(h["vertex_strand"].shape[0]) for h, _, _ in hosts]
        config = replace(first.scene.solver_config, schedule=pack_schedule(first.scene.solver_config, counts))
        model = GroomBuilder.merged(builders).finalize()
        state, control = model.state(), model.control()
        control.gravity = tuple(first.scene.gravity)
        solver = make_solver(first.scene.solver, model, config, colliders=first.scene.colliders)
        t_build = time.perf_counter() - t
        starts = np.r_[0, np.cumsum(counts)]
        kappa = solver.buf.pair_rest_kappa.to_numpy()
        twist_why = []
        for r, (h, _, _), v0, v1 in zip(runs, hosts, starts[:-1], starts[1:]):
            alone, why = twist_choice(h, kappa[v0:v1])
            if alone != solver.twist_free:
                raise PackRefused(f"{r.args.out}: alone it would choose '{why}', the pack "
                                  f"'{solver.model_choices['twist']}'")
            twist_why.append(why)  # its own words (strand numbers of its own groom) for its summary
        # One warm-up step compiles every kernel (SimulateRun._compile), then the state is restored.
        pack = SimulateRun(first.args, first.scene, [], first.layout, first.arch)
        pack.model, pack.state, pack.control, pack.solver = model, state, control, solver
        pack.admm, pack.with_contacts = True, False
        pack._compile()
        if pack.diverged:
            raise PackRefused(f"the pack diverged in its warm-up step ({pack.diverged})")
        self.x, self.v = state.positions(), state.vertex_velocity.to_numpy()
        names = [os.path.basename(os.path.normpath(r.args.out)) for r in runs]
        for r, (h, mats, bodies), v0, v1 in zip(runs, hosts, starts[:-1], starts[1:]):
            r.model, r.state, r.control, r.solver = _RunModel(h, mats, bodies), _RunState(self, v0, v1), control, solver
            r.admm, r.with_contacts, r.choice, r.ckpt = True, False, None, None
            r.t_build, r.t_compile = t_build, pack.t_compile
            r._resume()  # no checkpoint: the frame buffers and frame 0
            r._prepare_outputs()
        t_all = time.perf_counter()
        for f in range(1, first.scene.frames + 1):
            t0 = time.perf_counter()
            try:
                pack._step_frame(f)
            except SimulationDivergedError as exc:
                raise PackRefused(f"the pack diverged at frame {f} ({exc})") from None
            self.x, self.v = state.positions(), state.vertex_velocity.to_numpy()
            for r in runs:
                row = r._frame_row(f, t0)
                r.stats_rows.append(row)
                r.completed = f
                r._write_frame_file(f)
        wall = time.perf_counter() - t_all
        codes = []
        for r, why in zip(runs, twist_why):
            r.wall = wall
            try:
                r._write_frames()
            finally:
                if r.buffer_files:
                    r._remove_frame_buffers()
            summary = r._summary()
            summary["model"]["twist"] = why
            summary["pack"] = dict(runs=names, strands=model.strand_count, vertices=model.vertex_count,
                                   note="stepped as one Model with the runs named here (taichi-hair batch, "
                                        "cli/simulate_pack.py); wall, setup, compile and ms figures are the pack's",
                                   mvertex_iterations_per_s=model.vertex_count * summary["iterations"]
                                   * first.scene.substeps * first.scene.frames / max(wall, 1e-9) / 1e6)
            _atomic_text(r.layout["summary"], lambda fh, s=summary: json.dump(s, fh, indent=2))
            codes.append(r._report(summary))
        return codes
