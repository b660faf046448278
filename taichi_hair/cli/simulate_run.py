"""One ``taichi-hair simulate`` run, stage by stage (:class:`SimulateRun`), and the run's reports: frame
files, per-frame quality columns, the summary's quality block and its warning lines, the method choice."""

from __future__ import annotations

import csv
import json
import os
import sys
import time

import numpy as np

from .common import CLIError, _atomic_savez


class SimulateRun:
    """One ``taichi-hair simulate`` run once its arguments were checked (:func:`cmd_simulate`): refuse a
    checkpoint made for another scene, build the Model and the solver, compile every kernel on the real
    state, resume, step frame by frame (statistics, quality, frame files, checkpoints), then write the
    frames, ``stats.csv`` and ``summary.json`` and say what failed.  ``run()`` returns the exit status."""

    def __init__(self, args, scene, load_warnings: list, layout: dict, arch: str):
        self.args, self.scene, self.load_warnings, self.layout, self.arch = args, scene, load_warnings, layout, arch
        self.dt = 1.0 / (scene.fps * scene.substeps)
        self.diverged = None
        self.stats_rows = []
        self.start = 0
        self.completed = 0
        self.eq = None
        self.choice = None

    def run(self) -> int:
        self._read_checkpoint()
        self._build()
        self._compile()
        self._resume()
        self._prepare_outputs()
        self._print_header()
        try:
            self._step_frames()
            self._write_frames()
        finally:
            if self.buffer_files:
                self._remove_frame_buffers()
        summary = self._summary()
        return self._report(summary)

    # ------------------------------------------------------------------ set-up
    def _read_checkpoint(self) -> None:
        """Refuse a checkpoint made for another scene before anything is built or compiled."""
        args, scene, layout = self.args, self.scene, self.layout
        fingerprint = {"scene": scene.description, "arch": self.arch, "precision": args.precision,
                       "dt": self.dt, "solver": scene.solver, "version": 1,
                       "choice": {"max_error": args.max_error, "budget_ms": args.budget_ms,
                                  "data": args.pareto_data}}
        self.fingerprint = json.loads(json.dumps(fingerprint, default=str))
        self.ckpt = None
        if args.resume:
            if scene.solver != "admm":
                raise CLIError(f"--resume needs the admm solver (this scene uses {scene.solver!r}, which has no "
                               "checkpoints)")
            if os.path.exists(layout["checkpoint"]):
                from ..scene.checkpoint import CheckpointError, fingerprint_difference, read_checkpoint

                try:
                    self.ckpt = read_checkpoint(layout["checkpoint"])
                except CheckpointError as exc:
                    raise CLIError(f"--resume: {exc}") from None
                diff = fingerprint_difference(self.ckpt["fingerprint"], self.fingerprint)
                if diff:
                    raise CLIError(f"{layout['checkpoint']}: made for a different scene or settings (differs in "
                                   f"{diff}); remove it or drop --resume")
            elif not args.quiet:
                print(f"note: no checkpoint at {layout['checkpoint']}; starting from frame 0", file=sys.stderr)

    def _build(self) -> None:
        scene = self.scene
        t = time.perf_counter()
        self.model = model = scene.build_model()
        self.choice = _apply_method_choice(self.args, scene, model)
        self.dt = 1.0 / (scene.fps * scene.substeps)  # the method choice may change the substeps
        self.state, self.control = model.state(), model.control()
        self.control.gravity = tuple(scene.gravity)
        self.solver = scene.make_solver(model, profile=self.args.profile)
        self.admm = scene.solver == "admm"
        self.with_contacts = getattr(self.solver, "contacts", None) is not None
        self.t_build = time.perf_counter() - t

    def _set_bodies(self, t: float) -> None:
        for b, (R, T) in enumerate(self.scene.body_transforms(t)):
            self.control.set_body_transform(b, R, T)

    def _compile(self) -> None:
        """Compile every kernel on the real state (kernels are specialised per field), then restore it: one
        warm-up step of whichever solver, so that ``kernel compilation`` is reported for every solver and
        frame 1 is timed like the others."""
        from .. import SimulationDivergedError

        solver, state = self.solver, self.state
        self._set_bodies(0.0)
        t = time.perf_counter()
        snapshot = state.to_numpy()
        try:
            # BDF2: the first step is backward Euler (no history), the second compiles the BDF2 kernels.
            for _ in range(2 if getattr(self.scene.solver_config, "integrator", "") == "bdf2" else 1):
                solver.step(state, self.control, self.dt)
        except SimulationDivergedError as exc:
            self.diverged = f"frame 1: {exc}"
        state.load(snapshot)
        if self.admm:
            solver.reset_duals()
            if self.scene.rest_pose != "authored":
                # The groom starts at an equilibrium: start the duals there too (SolverADMM.prime_duals).
                solver.prime_duals(state, self.control, self.dt)
            solver.iteration_count = 0
        elif hasattr(solver, "reset_collider_motion"):
            solver.reset_collider_motion()  # SolverShape: the warm-up's body transforms are not motion
        if hasattr(solver, "vertex_iteration_count"):
            solver.vertex_iteration_count = 0
        solver.step_count = 0
        solver.stage_seconds = {k: 0.0 for k in solver.stage_seconds}
        self.t_compile = time.perf_counter() - t

    def _resume(self) -> None:
        args = self.args
        self._allocate_frame_buffers(np.float32 if args.precision == "f32" else np.float64)
        self.frames[0] = self.state.positions()
        if self.ckpt is not None:
            from ..scene.checkpoint import CheckpointError, check_layout

            ckpt = self.ckpt
            try:
                check_layout(self.layout["checkpoint"], ckpt, self.state.to_numpy(), self.solver.checkpoint())
            except CheckpointError as exc:
                raise CLIError(f"--resume: {exc}") from None
            self.state.load(ckpt["state"])
            self.solver.restore(ckpt["solver"])
            self.start = min(ckpt["frame"], self.scene.frames)
            self.frames[:self.start + 1] = ckpt["frame_positions"][:self.start + 1]
            if self.contact_states is not None:
                self.contact_states[1:self.start + 1] = -1
            self.stats_rows = [r for r in ckpt["stats"] if r["frame"] <= self.start]
        self.completed = self.start
        # The checkpoint restores the solver's step count; the stage timers only hold this process's steps.
        self.steps_before = getattr(self.solver, "step_count", 0)

    def _allocate_frame_buffers(self, dtype) -> None:
        """The positions of every frame, (F + 1, N, 3), and the contact states, (F + 1, N) int8: 0 free,
        1 sticking, 2 sliding (SolverADMM.vertex_contact_state), -1 unknown (frames before a --resume: the
        checkpoint keeps positions only).  In memory, or, when they would take more than a quarter of it
        (``io.sizing.frames_in_memory``), memory-mapped files ``.frames.buffer*.npy`` in the output folder
        (its disk space checked first), removed once the frames are written."""
        from ..io.sizing import check_disk, format_bytes, frame_buffer_bytes, frames_in_memory

        n, nf = self.model.vertex_count, self.scene.frames
        itemsize = np.dtype(dtype).itemsize
        shape = (nf + 1, n)
        self.buffer_files = []
        if frames_in_memory(n, nf, itemsize):
            self.frames = np.zeros(shape + (3,), dtype)
            self.contact_states = np.zeros(shape, np.int8) if self.with_contacts else None
            return
        folder = os.path.dirname(os.path.abspath(self.layout["stats"]))
        os.makedirs(folder, exist_ok=True)
        size = frame_buffer_bytes(n, nf, itemsize) + (nf + 1) * n * self.with_contacts  # + int8 contact states
        check_disk(2.0 * size, folder, f"the frame buffer of {nf} frames x {n:,} vertices and the frames written "
                                       "from it")
        if not self.args.quiet:
            print(f"note: the frames ({format_bytes(size)}) exceed a quarter of the available memory; they are "
                  f"streamed through {folder}/.frames.buffer.npy", file=sys.stderr)
        path = os.path.join(folder, ".frames.buffer.npy")
        self.buffer_files.append(path)
        self.frames = np.lib.format.open_memmap(path, "w+", dtype, shape + (3,))
        self.contact_states = None
        if self.with_contacts:
            path = os.path.join(folder, ".frames.buffer.contacts.npy")
            self.buffer_files.append(path)
            self.contact_states = np.lib.format.open_memmap(path, "w+", np.int8, shape)

    def _remove_frame_buffers(self) -> None:
        self.frames = self.contact_states = None
        for path in self.buffer_files:
            try:
                os.remove(path)
            except OSError:
                pass

    def _prepare_outputs(self) -> None:
        model, layout, args = self.model, self.layout, self.args
        radius = np.asarray(model.host["strand_radius"], np.float32) if "strand_radius" in model.host else None
        self.radius = radius if radius is not None and radius.shape == (model.strand_count,) else None
        os.makedirs(layout["frame_dir"] if layout["kind"] == "folder" else layout["dir"], exist_ok=True)
        self.frame_ext = {"thair": ".thair.npz", "usd": ".usdc"}.get(args.frame_format or "thair",
                                                                   "." + (args.frame_format or "thair"))
        if self.start == 0:
            self._write_frame_file(0)

    def _write_frame_file(self, f: int) -> None:
        if self.layout["kind"] != "folder":
            return
        from ..io import save_groom

        save_groom(_frame_groom(self.model, self.frames[f], self.radius, self.scene.fps),
                   os.path.join(self.layout["frame_dir"], f"frame_{f:05d}{self.frame_ext}"),
                   format=self.args.frame_format or "thair")

    def _print_header(self) -> None:
        scene, model, args = self.scene, self.model, self.args
        header = f"{'frame':>5} {'time s':>7} {'ms/frame':>9} {'max |v| m/s':>12} {'max stretch %':>13} " \
                 f"{'p99 strain %':>12} {'mean tip y m':>12} {'kinetic J':>11}"
        if scene.colliders:
            header += f" {'inside':>7} {'max depth mm':>12}"
        if self.with_contacts:
            header += f" {'contacts':>9} {'stick':>7} {'slide':>7} {'max pen. um':>11}"
        if args.quiet:
            return
        iters = getattr(scene.solver_config, "iterations", None)
        print(f"{scene.name}: {model.strand_count} strands, {model.vertex_count} vertices, solver {scene.solver}, "
              f"arch {self.arch}, {args.precision}, {scene.fps:g} fps x {scene.substeps} substeps"
              + (f" x {iters} iterations" if iters else "")
              + f" (set-up {self.t_build:.2f} s, kernel compilation {self.t_compile:.2f} s)"
              + (f"; resuming after frame {self.start}" if self.start else ""))
        for line in _model_lines(self.solver, self.choice):
            print("model: " + line)
        if scene.rest_pose_result is not None:
            print(scene.rest_pose_result.summary())
        print(header)

    # ------------------------------------------------------------------ stepping
    def _checkpoint(self, f: int) -> None:
        from ..scene.checkpoint import write_checkpoint

        write_checkpoint(self.layout["checkpoint"], self.state.to_numpy(), self.solver.checkpoint(), f,
                         self.frames[:f + 1], self.stats_rows, self.fingerprint)

    def _step_frame(self, f: int) -> None:
        """Advance one frame: the quasistatic solve to equilibrium, or the frame's substeps."""
        scene, args, solver, state = self.scene, self.args, self.solver, self.state
        if args.equilibrium:
            from ..solvers.equilibrium import equilibrium

            self.eq = equilibrium(solver, state, self.control, args.equilibrium_tolerance, args.max_steps, self.dt,
                                  callback=lambda k, d: self.bar.update(0, step=k, displacement=f"{d:.2e}"))
        else:
            for k in range(scene.substeps):
                self._set_bodies(((f - 1) * scene.substeps + k + 1) * self.dt)
                solver.step(state, self.control, self.dt)

    def _frame_row(self, f: int, t0: float) -> dict:
        """The frame's statistics (a stats.csv row); ms counts from ``t0`` to the frame's host copy."""
        model, scene = self.model, self.scene
        h = model.host
        x = self.state.positions()
        v = self.state.vertex_velocity.to_numpy()
        ms = 1e3 * (time.perf_counter() - t0)
        rest_len = h["edge_rest_length"]
        real_edge = rest_len > 0
        tips = h["strand_vertex_start"] + h["strand_vertex_count"] - 1
        e = np.linalg.norm(np.diff(x.astype(np.float64), axis=0, append=x[-1:]), axis=1)
        stretch = float(np.max(np.abs(e[real_edge] / rest_len[real_edge] - 1.0)))
        row = dict(frame=f, time=f / scene.fps, ms=ms, max_speed=float(np.max(np.linalg.norm(v, axis=1))),
                   max_stretch_percent=100 * stretch, mean_tip_y=float(np.mean(x[tips, 1])),
                   kinetic=float(0.5 * np.sum(h["vertex_mass"][:, None] * v.astype(np.float64) ** 2)))
        if self.with_contacts:
            cs = self.solver.contact_stats
            row.update(contacts=int(cs["contacts"]), sticking=int(cs["sticking"]), sliding=int(cs["sliding"]),
                       max_penetration_m=float(cs["max_penetration_m"]))
            self.contact_states[f] = self.solver.vertex_contact_state()
        row.update(_frame_quality(model, scene, self.control, x, v, getattr(self.solver, "contact_stats", None)))
        # The largest move over the frame, as a speed [m/s]: what a viewer sees, where max_speed is the last
        # substep's (a jitter within the frame shows in max_speed, not here).
        row["max_frame_speed"] = float(np.max(np.linalg.norm(x - self.frames[f - 1], axis=1))) * scene.fps
        self.frames[f] = x
        return row

    def _print_row(self, row: dict) -> None:
        with_contacts = self.with_contacts
        self.bar.write(f"{row['frame']:5d} {row['time']:7.3f} {row['ms']:9.1f} {row['max_speed']:12.4f} "
                       f"{row['max_stretch_percent']:13.4f} {100 * row['strain_p99']:12.4f} "
                       f"{row['mean_tip_y']:12.5f} {row['kinetic']:11.3e}"
                       + (f" {row['vertices_inside']:7d} {1e3 * row['body_penetration_max_m']:12.3f}"
                          if self.scene.colliders else "")
                       + (f" {row['contacts']:9d} {row['sticking']:7d} {row['sliding']:7d} "
                          f"{1e6 * row['max_penetration_m']:11.2f}" if with_contacts else ""))

    def _step_frames(self) -> None:
        from .. import SimulationDivergedError
        from ..progress import Progress

        scene, args = self.scene, self.args
        self.bar = Progress(scene.frames, initial=self.start, label="frames", enabled=not args.quiet)
        t_all = time.perf_counter()
        for f in range(self.start + 1, scene.frames + 1 if self.diverged is None else self.start + 1):
            t0 = time.perf_counter()
            try:
                self._step_frame(f)
            except SimulationDivergedError as exc:
                self.diverged = f"frame {f}: {exc}"
                break
            row = self._frame_row(f, t0)
            self.stats_rows.append(row)
            self.completed = f
            self._write_frame_file(f)
            if self.admm and args.checkpoint_every and not args.equilibrium and (f % args.checkpoint_every == 0
                                                                                 or f == scene.frames):
                self._checkpoint(f)
            if not args.quiet:
                self._print_row(row)
            self.bar.update(f, **{"p99 strain %": f"{100 * row['strain_p99']:.2f}"},
                            **({"contacts": row["contacts"]} if self.with_contacts else {}))
        self.bar.close()
        self.wall = time.perf_counter() - t_all

    # ------------------------------------------------------------------ outputs
    def _write_frames(self) -> None:
        layout, model, scene, completed = self.layout, self.model, self.scene, self.completed
        if layout["kind"] == "folder":
            self.written = layout["frames_npz"]
            params = scene.description.get("params", {})
            _atomic_savez(self.written, positions=self.frames[:completed + 1], fps=np.float64(scene.fps),
                          strand_vertex_start=model.host["strand_vertex_start"],
                          strand_vertex_count=model.host["strand_vertex_count"],
                          sphere_radius=np.float64(params.get("sphere_radius", params.get("ball_radius", 0.0))),
                          **_body_arrays(scene, completed),
                          **({} if self.contact_states is None else
                             {"vertex_contact_state": self.contact_states[:completed + 1]}))
        else:
            from ..io import save_groom

            self.written = layout["file"]
            save_groom(_frame_groom(model, None, self.radius, scene.fps, self.frames[:completed + 1]), self.written,
                       format="usd" if layout["kind"] == "usd" else "thair")
            _atomic_savez(layout["bodies"], **_body_arrays(scene, completed))  # for a render to pose the bodies
        rows = self.stats_rows

        def write_stats(fh):
            keys = list(dict.fromkeys(k for r in rows for k in r)) if rows else ["frame"]
            w = csv.DictWriter(fh, fieldnames=keys, restval="")
            w.writeheader()
            w.writerows(rows)

        _atomic_text(layout["stats"], write_stats)

    def _summary(self) -> dict:
        import resource

        args, scene, model, solver, eq, choice = self.args, self.scene, self.model, self.solver, self.eq, self.choice
        n, wall, run_frames = model.vertex_count, self.wall, self.completed - self.start
        peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
        iters = getattr(scene.solver_config, "iterations", 1)
        summary = dict(scene=scene.name, scene_file=scene.path or None, solver=scene.solver,
                       strands=model.strand_count, vertices=n, frames=self.completed,
                       resumed_from_frame=self.start or None, arch=self.arch, precision=args.precision,
                       output=self.written, wall_seconds=wall, setup_seconds=self.t_build,
                       compile_seconds=self.t_compile, ms_per_frame=1e3 * wall / max(run_frames, 1), iterations=iters,
                       substeps=scene.substeps,
                       mvertex_iterations_per_s=n * (eq.iterations if eq is not None else iters * scene.substeps
                                                     * run_frames) / max(wall, 1e-9) / 1e6,
                       peak_host_memory_mb=peak_mb, diverged=self.diverged,
                       load_average_1min_at_end=os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
                       cpu_count=os.cpu_count())
        if scene.rest_pose_result is not None:
            summary["rest_pose"] = _rest_pose_report(scene.rest_pose_result)
        summary["model"] = dict(_model_report(solver), **({"method_choice": choice.description} if choice else {}))
        if choice is not None:
            summary["method_choice"] = dict(method=choice.point.method, dt=choice.point.dt,
                                            iterations=choice.point.iterations, substeps=choice.point.substeps,
                                            shape_method=choice.point.shape_method, stand_in=choice.stand_in,
                                            measured_error=choice.point.error,
                                            estimated_ms_per_frame=choice.estimated_ms_per_frame)
        if eq is not None:
            summary["equilibrium"] = dict(converged=eq.converged, steps=eq.steps, iterations=eq.iterations,
                                          last_displacement_m=eq.last_displacement,
                                          estimated_distance_m=eq.estimated_distance,
                                          tolerance_m=args.equilibrium_tolerance, method=eq.method)
        rows = self.stats_rows
        if self.with_contacts and rows:
            summary["mean_contacts"] = float(np.mean([r["contacts"] for r in rows]))
            summary["max_penetration_m"] = float(max(r["max_penetration_m"] for r in rows))
        summary["quality"] = _run_quality(rows, eq)
        if not self.diverged:  # the last frame's shape distance and speeds
            from ..quality import last_frame_figures

            summary["quality"].update(last_frame_figures(
                self.state.positions(), self.state.vertex_velocity.to_numpy(), model.host, self.control.body_rotation.to_numpy(),
                self.control.body_translation.to_numpy(), "drift_p90_last_m" in summary["quality"], eq is None))
        summary["warnings"] = self.load_warnings
        if args.profile and not hasattr(solver, "stage_seconds"):
            print(f"note: --profile: solver {scene.solver!r} has no stage timers", file=sys.stderr)
        elif args.profile:
            steps = max(solver.step_count - self.steps_before, 1)
            summary["stage_steps"] = steps  # the steps this process ran (a --resume: not those before)
            summary["stage_ms_per_step"] = {k: 1e3 * v / steps for k, v in solver.stage_seconds.items() if v > 0}
            if not args.quiet:
                print("stage breakdown (ms per step): " + ", ".join(
                    f"{k} {v:.2f}" for k, v in summary["stage_ms_per_step"].items()))
        _atomic_text(self.layout["summary"], lambda fh: json.dump(summary, fh, indent=2))
        return summary

    def _report(self, summary: dict) -> int:
        """The last lines and the exit status: 1 diverged or no equilibrium, 3 failed quality with --strict."""
        args, eq, completed = self.args, self.eq, self.completed
        run_frames, wall = completed - self.start, self.wall
        print(f"wrote {completed} frames of {self.model.vertex_count} vertices to {self.written} "
              f"({1e3 * wall / max(run_frames, 1):.1f} ms/frame over {run_frames} frames run, {wall:.1f} s, "
              f"{summary['mvertex_iterations_per_s']:.2f} M vertex-iterations/s, peak memory "
              f"{summary['peak_host_memory_mb']:.0f} MB"
              + (f", mean contacts {summary['mean_contacts']:.0f}" if "mean_contacts" in summary else "") + ")")
        if self.diverged:
            print(f"error: simulation diverged at {self.diverged}; frames up to {completed} were kept",
                  file=sys.stderr)
            if completed <= 1:
                print(f"note: {_groom_size_note(self.scene, self.model)}", file=sys.stderr)
            return 1
        failed = _quality_lines(summary["quality"])
        for line in failed if not args.strict else ():
            print(f"warning: {line}", file=sys.stderr)
        if eq is not None:
            if not eq.converged:
                print(f"error: no equilibrium within {eq.steps} quasistatic steps (the last moved a vertex by "
                      f"{eq.last_displacement:.3g} m, estimated distance left {eq.estimated_distance:.3g} m, "
                      f"tolerance {args.equilibrium_tolerance:g} m); the last state was written", file=sys.stderr)
                return 1
            how = (f"{eq.steps} quasistatic step and a static Newton solve" if eq.method == "static Newton" else
                   f"{eq.steps} quasistatic steps")
            print(f"equilibrium after {how} ({eq.iterations} iterations; last displacement "
                  f"{eq.last_displacement:.3g} m, estimated distance left {eq.estimated_distance:.3g} m)")
        if failed and args.strict:
            print(f"error: --strict: {'; '.join(failed)}", file=sys.stderr)
            return 3
        return 0


# --------------------------------------------------------------------------- frames and reports
def _frame_groom(model, positions, radius, fps, frames=None):
    from ..io.groom import Groom

    h = model.host
    off = np.r_[h["strand_vertex_start"], h["strand_vertex_start"][-1] + h["strand_vertex_count"][-1]]
    g = Groom(points=np.ascontiguousarray(positions if frames is None else frames[0]),
              strand_offsets=off.astype(np.int64), radius=radius, units="m",
              params={"fps": float(fps), "usd_time_codes_per_second": float(fps)})
    if frames is not None:
        g.point_frames = np.ascontiguousarray(frames)
        g.frame_times = np.arange(frames.shape[0], dtype=np.float64)
    return g.validate()


def _body_arrays(scene, completed: int) -> dict:
    """The bodies for a render to pose (frames.npz): ``body_rotation`` (F, B, 3, 3) [-] and
    ``body_translation`` (F, B, 3) [m] at every written frame's time, and per mesh collider k
    ``collider_k_vertices`` (V, 3) [m, body frame], ``collider_k_faces`` (T, 3) and ``collider_k_body``."""
    times = np.arange(completed + 1) / scene.fps
    tf = [scene.body_transforms(float(t)) for t in times]
    out = {"body_rotation": np.array([[R for R, _ in f] for f in tf], np.float64).reshape(len(times), -1, 3, 3),
           "body_translation": np.array([[T for _, T in f] for f in tf], np.float64).reshape(len(times), -1, 3)}
    for k, c in enumerate(scene.colliders):
        mesh = getattr(c, "mesh", None)
        if mesh is not None and hasattr(mesh, "faces"):
            out[f"collider_{k}_vertices"] = np.asarray(mesh.vertices, np.float32)
            out[f"collider_{k}_faces"] = np.asarray(mesh.faces, np.int32)
            out[f"collider_{k}_body"] = np.int64(c.body)
    return out


def _atomic_text(path: str, write) -> None:
    tmp = path + ".tmp"
    with open(tmp, "w", newline="") as fh:
        write(fh)
    os.replace(tmp, path)


def _frame_quality(model, scene, control, x, v, contact_stats) -> dict:
    """This frame's figures of :func:`taichi_hair.quality.frame_quality`, as stats.csv columns."""
    from ..quality import frame_quality

    rot = control.body_rotation.to_numpy()
    tr = control.body_translation.to_numpy()
    q = frame_quality(x, v, model.host, scene.colliders, rot, tr, contact_stats)
    q.pop("max_speed_m_s")  # the row has it as max_speed
    return q


def _rest_pose_report(r) -> dict:
    """summary.json's ``rest_pose``: what the sag-free solve found (solvers/rest_pose.py)."""
    res = r.strand_residual[np.isfinite(r.strand_residual)]
    return dict(kind="sag-free", strands_held=r.held_count, strands=int(r.strand_rest_turn.shape[0]),
                largest_rest_turn=float(r.strand_rest_turn.max()),
                largest_residual_over_weight=float(res.max()) if res.size else None, seconds=r.seconds,
                not_held=[dict(strand=s, why=why) for s, why in r.unheld[:10000]], not_held_count=len(r.unheld),
                stability_checked=r.strand_stability_drift is not None,
                unstable=[dict(strand=s, why=why) for s, why in r.unstable[:10000]], unstable_count=len(r.unstable))


def _run_quality(rows, eq) -> dict:
    """The run's quality for summary.json: the worst frame of each figure and the last frame's rest."""
    from ..quality import HAIR_KEYS, INSIDE_TOLERANCE_M, REST_SPEED_M_S, STRAIN_WARNING

    rows = [r for r in rows if "strain_p99" in r]
    if not rows:
        return {}
    worst = max(rows, key=lambda r: r["strain_p99"])
    q = dict(strain_warning=STRAIN_WARNING, inside_tolerance_m=INSIDE_TOLERANCE_M,
             strain_p50_max=max(r["strain_p50"] for r in rows), strain_p99_max=worst["strain_p99"],
             strain_p99_worst_frame=worst["frame"], strain_max=max(r["strain_max"] for r in rows),
             strain_worst_strand=worst["strain_worst_strand"], strain_p99_last=rows[-1]["strain_p99"])
    if "vertices_inside" in rows[-1]:
        deep = max(rows, key=lambda r: (r["vertices_inside"], r["body_penetration_max_m"]))
        q.update(body_penetration_p99_max_m=max(r["body_penetration_p99_m"] for r in rows),
                 body_penetration_max_m=max(r["body_penetration_max_m"] for r in rows),
                 vertices_inside_max=deep["vertices_inside"], vertices_inside_worst_frame=deep["frame"],
                 penetration_worst_strand=deep["penetration_worst_strand"],
                 vertices_inside_last=rows[-1]["vertices_inside"])
    if "drift_p90_m" in rows[-1]:
        q.update(drift_p90_last_m=rows[-1]["drift_p90_m"], drift_p90_max_m=max(r["drift_p90_m"] for r in rows),
                 drift_max_m=max(r["drift_max_m"] for r in rows))
    for key in HAIR_KEYS:
        vals = [r[key] for r in rows if r.get(key) is not None]
        if vals:
            q[key + "_max"] = max(vals)
    last = rows[-1]["max_speed"]
    if eq is not None:
        q.update(rest_asked=True, came_to_rest=bool(eq.converged), rest_criterion="--equilibrium-tolerance")
    else:
        q.update(rest_asked=False, came_to_rest=bool(last < REST_SPEED_M_S),
                 rest_criterion=f"max vertex speed in the last frame < {REST_SPEED_M_S:g} m/s")
    q["last_frame_max_speed_m_s"] = last
    if "max_frame_speed" in rows[-1]:
        q["last_frame_max_move_speed_m_s"] = rows[-1]["max_frame_speed"]
    return q


def _quality_lines(q) -> list:
    """The run's failed quality figures, one line each (strain above 5 %, vertices left inside a body)."""
    lines = []
    if not q:
        return lines
    if q["strain_p99_max"] > q["strain_warning"]:
        lines.append(f"p99 edge strain reached {100 * q['strain_p99_max']:.2f} % at frame "
                     f"{q['strain_p99_worst_frame']} (above {100 * q['strain_warning']:g} %; worst strand "
                     f"{q['strain_worst_strand']}, max {100 * q['strain_max']:.2f} %)")
    if q.get("vertices_inside_max", 0) > 0:
        lines.append(f"{q['vertices_inside_max']} vertices deeper than {1e3 * q['inside_tolerance_m']:g} mm "
                     f"inside a body at frame {q['vertices_inside_worst_frame']} (worst strand "
                     f"{q['penetration_worst_strand']}, deepest {1e3 * q['body_penetration_max_m']:.2f} mm)")
    return lines


def _groom_size_note(scene, model) -> str:
    """Whether the groom's size looked wrong (a run that diverged at once)."""
    from ..io import Groom, describe_groom_size

    h = model.host
    off = np.r_[h["strand_vertex_start"], h["strand_vertex_start"][-1] + h["strand_vertex_count"][-1]]
    g = scene.groom if scene.groom is not None else Groom(points=np.asarray(h["vertex_rest_position"]),
                                                          strand_offsets=off.astype(np.int64))
    return describe_groom_size(g)


# --------------------------------------------------------------------------- method choice
def _apply_method_choice(args, scene, model):
    """--max-error / --budget-ms: the measured setting for this scene, applied to ``scene`` (solver, config,
    substeps); ``None`` without those options."""
    if args.max_error is None and args.budget_ms is None:
        return None
    from ..bench.pareto_data import load_shipped, read_csv
    from ..bench.choice import choose_for_scene, solver_config_for

    try:
        points = read_csv(args.pareto_data) if args.pareto_data else load_shipped()
    except (KeyError, ValueError, OSError) as exc:
        raise CLIError(f"{args.pareto_data or 'shipped Pareto data'}: not a pareto.csv of taichi-hair bench pareto "
                       f"({type(exc).__name__}: {exc})") from None
    cfg = scene.solver_config if scene.solver == "admm" else None
    hair_hair = cfg is not None and cfg.contacts is not None and cfg.contacts.hair_hair
    try:
        choice = choose_for_scene(points, model.strand_count, model.vertex_count, scene.fps, args.precision,
                                  hair_hair=hair_hair, colliders=bool(scene.colliders), max_error=args.max_error,
                                  budget_ms=args.budget_ms)
    except ValueError as exc:
        raise CLIError(f"{'--max-error' if args.max_error is not None else '--budget-ms'}: {exc}") from None
    scene.solver_config = solver_config_for(choice, cfg)
    scene.solver = choice.solver
    scene.substeps = choice.substeps
    return choice


def _model_report(solver) -> dict:
    if hasattr(solver, "model_report"):
        return solver.model_report()
    return {"solver": f"{type(solver).__name__}: no model simplification"}


def _model_lines(solver, choice) -> list:
    lines = [f"{k}: {v}" for k, v in _model_report(solver).items()]
    if choice is not None:
        lines.append(choice.description)
    return lines
