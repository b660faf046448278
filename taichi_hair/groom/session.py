"""Physics-based grooming without a window (Daviet 2023, Sec. 5.3).

A :class:`GroomingSession` holds a groom (:class:`taichi_hair.io.Groom`: the current pose ``points`` and the
rest pose ``rest_points``) inside a running *quasistatic* simulation: each :meth:`~GroomingSession.advance`
frame runs a few ADMM iterations (``GroomingConfig.iterations``, 10 in the paper) of :class:`SolverADMM` in
``mode="quasistatic"`` with proximity-only contacts (``velocity_margin=0``), so the groom settles under
gravity, elasticity and contacts while it is edited.  As in the paper only a fraction of the strands
(``guide_ratio``) is simulated; the others follow by linear blend skinning
(:mod:`taichi_hair.groom.skinning`).

Editing actions are methods, each logged with its parameters (``session.log``, written by
:meth:`~GroomingSession.write_log` as ``session.json`` and replayed by :meth:`~GroomingSession.replay`):

* selection (:mod:`taichi_hair.groom.selection`): :meth:`select` (a sphere), :meth:`select_ray` (a screen
  ray: a cylinder of the given radius around a half-line), :meth:`select_strands`, :meth:`select_all`;
  ``mode`` is "replace", "add" or "remove".
* :meth:`drag` -- direct manipulation by "spring-like forces" (Sec. 5.3): every frame before the step, each
  grabbed vertex's target moves a fraction ``stiffness`` of the way to anchor + ``target_offset`` (an
  overdamped approach, time constant -1/ln(1 - stiffness) frames), and a zero-length spring with a contact's
  weight pulls the vertex to it (``SolverADMM.set_attachments``); the vertices stay free, so contacts stop
  them at the head and at other hair (kinematic, as before 2026-12-06, they went through both).  The rest of
  each strand follows through elasticity and contacts.  :meth:`release` ends it.
* :meth:`comb` sweeps a comb (a frictional capsule collider on its own body, Sec. 4.5) along a path through
  the hair; the strands it touched keep the combed shape as their rest pose (:mod:`taichi_hair.groom.comb`).
* :meth:`trim` cuts the strands whose *current* polyline crosses a plane (the cut seen on screen); the same
  rest arc length cuts the rest pose.
* :meth:`scale_length` shortens (cut at the scaled rest arc length) or grows selected strands from the tip;
  growth continues the tip's discrete curvature and torsion (the screw motion taking the last-but-one edge
  pair to the last one), at the last rest edge length.
* Both keep every strand's vertex count: the edited strand is *resampled* along its new length, so the Model
  is updated in place (:mod:`taichi_hair.groom.edits`).
* :meth:`scale_curl` multiplies the rest turning angle of every edge pair of the selected strands (the
  Bishop-frame curvature), keeping edge lengths and the root edge; 0 straightens.  The edited strands'
  current pose becomes the new rest pose and settles again when simulated.
* :meth:`pin` / :meth:`unpin` make the selected vertices kinematic where they are (``Groom.pinned``);
  :meth:`set_parameter` changes a :class:`GroomingConfig` field; :meth:`simulate` toggles the simulation.

Every edit is undoable (:meth:`undo`, :meth:`redo`): a snapshot of the groom (both poses, topology,
attributes), the parameters, the selection and the drag is taken before it, so undo and redo restore the
groom bit for bit.  The solver's warm-start state (twists, multipliers) restarts from the restored groom, as
after loading it.

Rest-pose changes (trim, scale_length, scale_curl, comb, undo/redo across them) and material parameters
update the Model in place, lazily at the next frame, without recompiling; only ``LAYOUT_PARAMETERS`` build a
new Model and solver (:mod:`taichi_hair.groom.simulation`).  ``session.timings`` records builds
(``rebuild``), in-place updates (``update``) and frames.

With ``guide_ratio < 1`` a selected vertex of a skinned strand acts through its *proxy*: the vertex of the
nearest guide (by root) at the nearest rest arc fraction; pins and drags move guides, skinned strands follow.

Guide points come back from the solver's State (Taichi's ``default_fp``); the groom keeps its dtype.
``GroomingConfig.rest_pose = "sag-free"`` keeps the rest shape an equilibrium.

The session composes collaborators that never call back into it (they get what they need as arguments and
return results; :mod:`taichi_hair.groom` lists them) and owns the live simulation (``GuideSimulation``).
"""

from __future__ import annotations

import inspect
import os
import time
from dataclasses import replace

import numpy as np

from ..io import load_groom, save_groom
from . import comb as comb_stroke
from . import history as hist
from . import selection as sel
from .binding import proxy_vertices
from .config import ACTIONS, COMB_BODY, COMB_MAX_STEPS, EDIT_ACTIONS, MODES  # noqa: F401  (names of this module, as before)
from .config import (LAYOUT_PARAMETERS, REBUILD_PARAMETERS, GroomingConfig, _direction, _positive, _vec3,
                     session_colliders, session_config, session_groom, with_parameter)
from .edits import rest_from_current, replace_strands, scale_curl_strands, scale_length_strands, trim_strands
from .guides import GuideChoice
from .simulation import GuideSimulation, _host_of  # noqa: F401  (_host_of: importable from here, as before)


class GroomingSession:
    """A groom being edited inside a running quasistatic simulation (Sec. 5.3), GUI-free.

    Args:
        groom: a :class:`taichi_hair.io.Groom` (lengths in metres; its ``rest_points`` is the
            rest pose, else ``points``) or a list of (m, 3) polylines (m >= 3).  Copied;
            ``point_frames`` (an animation cache) is dropped.
        config: :class:`GroomingConfig`; default: the groom's ``params["grooming"]`` if it has
            one (as :meth:`save` writes), else the defaults.
        colliders: body colliders for the solver (PlaneCollider, SphereCollider, ...); they are
            scene objects, not part of the log, so a replay needs the same ones.
        autosave_path: where :meth:`autosave` writes the groom (native ``.thair.npz``); the log
            goes beside it as ``<name>.session.json``.  None disables autosave.

    Attributes:
        groom: the edited :class:`Groom` (``points`` current pose, ``rest_points`` rest pose, ``pinned``);
            replaced, never mutated in place, by edits: its arrays are read-only (undo snapshots share them).
        config: the current :class:`GroomingConfig`.
        simulating: whether :meth:`advance` steps the solver.
        log: list of ``{"action": name, **params}`` of every action so far.
        history: the :class:`~taichi_hair.groom.history.History` of undo/redo snapshots.
        timings: lists of seconds: ``rebuild`` (Model + solver + skinning + State),
            ``update`` (an in-place update of the Model after a rest-shape edit),
            ``first_frame`` (first frame after a rebuild: kernel compilation), ``frame``.
        rebuild_count: Models built so far [-].
        update_count: in-place Model updates so far [-].
    """

    groom = hist.ReadOnlyGroom()  # (see Attributes)

    def __init__(self, groom, config: GroomingConfig | None = None, colliders=None, autosave_path=None):
        self.groom = session_groom(groom)
        self.config = replace(session_config(self.groom, config))
        self.colliders = session_colliders(colliders)
        self.autosave_path = None if autosave_path is None else os.fspath(autosave_path)
        self.simulating = True
        self.log: list[dict] = []
        self.history = hist.History()
        self.timings = {"rebuild": [], "update": [], "first_frame": [], "frame": []}
        self.rebuild_count = 0
        self.update_count = 0
        self._selection = np.zeros(self.groom.vertex_count, dtype=bool)
        self._drag = None
        self._edits_since_autosave = 0
        self._sim: GuideSimulation | None = None  # built lazily by _ensure_built
        self._proxy_cache = None
        self._guides = GuideChoice()

    @classmethod
    def open(cls, path, config: GroomingConfig | None = None, colliders=None, autosave: bool = True, **options):
        """Load a groom file (``io.load_groom``); autosave beside it (``<stem>.autosave.thair.npz``, ``.session.json``)."""
        groom = load_groom(path, **options)
        return cls(groom, config, colliders, hist.autosave_path_for(path) if autosave else None)

    # ------------------------------------------------------------------ read-only views
    @property
    def strand_count(self) -> int:
        return self.groom.strand_count

    @property
    def vertex_selection(self) -> np.ndarray:
        """Selected vertices, bool, shape (vertex_count,) (a copy)."""
        return self._selection.copy()

    @property
    def strand_selection(self) -> np.ndarray:
        """Selected strands (any vertex selected), bool, shape (strand_count,)."""
        return sel.strands_of(self._selection, self.groom.strand_offsets)

    dragging = property(lambda self: self._drag is not None)
    built = property(lambda self: self._sim is not None, doc="Whether the guides' simulation exists (built, maybe stale).")

    @property
    def guide_strands(self) -> np.ndarray:
        """Indices of the simulated strands (the others are skinned), int64, in the simulation's order (``GuideChoice``)."""
        return self._guide_strands()

    # ------------------------------------------------------------------ log, undo, autosave
    def _record(self, action: str, **params) -> None:
        self.log.append({"action": action, **params})

    def _snapshot(self) -> dict:
        return hist.snapshot(self.groom, self.config, self._selection, self._drag, self.simulating)

    def _edit(self, action: str, params: dict, apply) -> None:
        """Run ``apply`` (which validates before it changes anything) as one undoable, logged edit."""
        snap = self._snapshot()
        apply()
        self.history.push(snap, self.config.undo_limit, self.config.undo_memory_mb * 2**20)
        self._record(action, **params)
        self._count_edit()

    def _count_edit(self) -> None:
        self._edits_since_autosave += 1
        every = self.config.autosave_every
        if self.autosave_path is not None and every > 0 and self._edits_since_autosave >= every:
            self.autosave()

    def _restore(self, snap: dict) -> None:
        old = self.groom, self.config
        self.groom = hist.shared_copy(snap["groom"])
        self.config = replace(snap["config"])
        self._selection = snap["selection"].copy()
        self._drag = hist.copy_drag(snap["drag"])
        self.simulating = snap["simulating"]
        same_layout, same_rest = hist.what_changed(old[0], old[1], self.groom, self.config)
        if not same_rest:
            self._invalidate(layout=not same_layout)
        elif self._sim is not None:
            self._sim.apply_live_parameters(self.config)
            self._load_state()

    def undo(self) -> None:
        """Restore the groom, parameters, selection and drag as they were before the last edit."""
        if not self.history.can_undo:
            raise ValueError("undo: nothing to undo")
        self._restore(self.history.undo(self._snapshot()))
        self._record("undo")
        self._count_edit()

    def redo(self) -> None:
        """Re-apply the last undone edit (restores exactly the state undo left)."""
        if not self.history.can_redo:
            raise ValueError("redo: nothing to redo")
        self._restore(self.history.redo(self._snapshot()))
        self._record("redo")
        self._count_edit()

    @property
    def can_undo(self) -> bool:
        return self.history.can_undo

    @property
    def can_redo(self) -> bool:
        return self.history.can_redo

    def save(self, path) -> None:
        """Write the edited groom (current pose, rest pose, pins, parameters in ``params["grooming"]``)
        in the native ``.thair.npz`` format, atomically.  Not logged."""
        g = self.groom.copy()
        g.params["grooming"] = self.config.to_dict()
        save_groom(g, path, format="thair")

    def autosave(self) -> None:
        """Write the groom to ``autosave_path`` and the log beside it, both atomically."""
        if self.autosave_path is None:
            raise ValueError("autosave: this session has no autosave_path")
        self.save(self.autosave_path)
        self.write_log(self.autosave_log_path)
        self._edits_since_autosave = 0

    @property
    def autosave_log_path(self) -> str | None:
        return hist.autosave_log_path(self.autosave_path)

    def write_log(self, path) -> None:
        """Write the log as a JSON list, one action per line (line i + 2 holds entry i), atomically."""
        hist.write_log(self.log, path)

    def replay(self, source, after_each=None) -> None:
        """Apply the actions of a session log (a list of dicts or a ``session.json`` path) in order.

        ``after_each(index, entry)``, if given, is called after each applied entry (the off-screen
        tool renders a frame there).

        Raises:
            ValueError naming the entry (and the file's line), the action and the problem (unknown action,
            unknown, missing or bad parameter); actions before the bad one stay applied.
        """
        for i, (entry, line) in enumerate(hist.parse_log(source)):
            where, name, params = hist.check_entry(i, entry, line, ACTIONS)
            method = getattr(self, name)
            try:
                inspect.signature(method).bind(**params)
            except TypeError as exc:
                raise ValueError(f"{where}, action {name!r}: bad parameters ({exc})") from None
            try:
                result = method(**params)
            except ValueError as exc:
                raise ValueError(f"{where}, action {name!r}: {exc}") from None
            hist.warn_if_empty_select(source, where, name, params, result)
            if after_each is not None:
                after_each(i, entry)

    # ------------------------------------------------------------------ selection
    def _apply_selection(self, hit: np.ndarray, mode: str) -> int:
        self._selection = sel.combine(self._selection, hit, mode)
        return int(self.strand_selection.sum())

    def select(self, center, radius, mode: str = "replace") -> int:
        """Select the vertices of every edge within ``radius`` [m] of ``center`` [m]; returns the
        number of selected strands."""
        c, r = _vec3("center", center), _positive("radius", radius)
        count = self._apply_selection(sel.sphere_hits(self.groom.points, self.groom.strand_offsets, c, r), mode)
        self._record("select", center=c.tolist(), radius=r, mode=mode)
        return count

    def select_ray(self, origin, direction, radius, mode: str = "replace") -> int:
        """Select the vertices of every edge within ``radius`` [m] of the half-line
        origin + t direction, t >= 0 (a screen pick ray); returns the number of selected strands."""
        o, (dvec, d) = _vec3("origin", origin), _direction("direction", direction)
        r = _positive("radius", radius)
        count = self._apply_selection(sel.ray_hits(self.groom.points, self.groom.strand_offsets, o, d, r), mode)
        self._record("select_ray", origin=o.tolist(), direction=dvec.tolist(), radius=r, mode=mode)
        return count

    def select_strands(self, strands, mode: str = "replace") -> int:
        """Select whole strands by index."""
        idx = sel.strand_indices(strands, self.strand_count)
        count = self._apply_selection(sel.strand_hits(idx, self.groom.strand_offsets), mode)
        self._record("select_strands", strands=idx.tolist(), mode=mode)
        return count

    def select_all(self) -> int:
        self._selection = np.ones(self.groom.vertex_count, dtype=bool)
        self._record("select_all")
        return self.strand_count

    # ------------------------------------------------------------------ shape edits
    def _replace_strands(self, new: dict) -> None:
        """Swap the poses of strands s -> (current, rest), each with the strand's vertex count.

        The layout (vertex and strand counts) is kept, so the simulation updates its Model in place
        instead of rebuilding it; per-vertex attributes (pins, selection, radius, colour) stay on
        their vertex index.  Unchanged strands are copied bit for bit.  Ends an active drag.
        """
        g = self.groom
        pts, rest = replace_strands(g.points, g.rest_points, g.strand_offsets, new)
        self.groom = replace(g, points=pts, rest_points=rest, params=dict(g.params)).validate()
        self._drag = None
        self._invalidate(layout=False)

    def trim(self, plane_point, plane_normal, selected_only: bool = False) -> int:
        """Cut every strand whose current polyline crosses the plane (point, normal) [m] at its first
        crossing from the root; the part holding the root stays.  ``selected_only`` restricts it to
        the selected strands.  Strands not crossing are untouched.  Returns the number of strands cut.

        A cut strand keeps its vertex count (resampled, its last vertex on the plane:
        :func:`~taichi_hair.groom.edits.trim_strands`), so the Model is updated in place.
        """
        p0 = _vec3("plane_point", plane_point)
        normal, n = _direction("plane_normal", plane_normal)
        if not isinstance(selected_only, bool):
            raise ValueError(f"'selected_only' must be true or false, got {selected_only!r}")
        g = self.groom
        chosen = self.strand_selection if selected_only else np.ones(g.strand_count, dtype=bool)
        new = trim_strands(g.points, g.rest_points, g.strand_offsets, p0, n, chosen)

        def apply():
            if new:
                self._replace_strands(new)

        self._edit("trim", {"plane_point": p0.tolist(), "plane_normal": normal.tolist(),
                            "selected_only": selected_only}, apply)
        return len(new)

    def scale_length(self, factor) -> None:
        """Multiply the rest length of the selected strands by ``factor`` > 0, from the tip.

        Shorter: cut at the scaled rest arc length; longer: continued with the tip's curvature and
        torsion.  The vertex count is kept (resampled: edges scale by ``factor``); the details are
        those of :func:`~taichi_hair.groom.edits.scale_length_strands`.
        """
        f = _positive("factor", factor)
        chosen = np.nonzero(self.strand_selection)[0]
        if chosen.size == 0:
            raise ValueError("scale_length: no strand is selected")
        g = self.groom
        new = scale_length_strands(g.points, g.rest_points, g.strand_offsets, chosen, f)

        def apply():
            if new:
                self._replace_strands(new)

        self._edit("scale_length", {"factor": f}, apply)

    def scale_curl(self, factor) -> None:
        """Multiply the rest curvature (every Bishop turning angle) of the selected strands by
        ``factor`` >= 0; edge lengths and the root edge are kept.  The edited strands' current
        pose is set to the new rest pose (it settles again when simulated)."""
        f = _positive("factor", factor, allow_zero=True)
        chosen = np.nonzero(self.strand_selection)[0]
        if chosen.size == 0:
            raise ValueError("scale_curl: no strand is selected")
        g = self.groom
        pts, rest = scale_curl_strands(g.points, g.rest_points, g.strand_offsets, chosen, f)

        def apply():
            self.groom = replace(g, points=pts, rest_points=rest, params=dict(g.params))
            self._invalidate(layout=False)

        self._edit("scale_curl", {"factor": f}, apply)

    # ------------------------------------------------------------------ kinematic edits
    def _proxy(self) -> np.ndarray:
        """Groom vertex simulated in place of each groom vertex, int64 (vertex_count,): itself on a
        guide strand; on another strand, the vertex of its nearest guide (by root) at the nearest
        rest arc fraction (:func:`taichi_hair.groom.binding.proxy_vertices`, cached)."""
        if self._proxy_cache is None:
            self._proxy_cache = proxy_vertices(self.groom.rest_points, self.groom.strand_offsets,
                                               self._guide_strands())
        return self._proxy_cache

    def _guide_strands(self) -> np.ndarray:
        """Farthest-point sampled guides of the roots (cached: edits keep the roots)."""
        g = self.groom
        return self._guides.strands(g.rest_points, g.strand_offsets, self.config.guide_ratio, self.config.seed)

    def _grabbable(self, mask: np.ndarray) -> np.ndarray:
        """Groom vertices (proxies) of ``mask``, without clamped root vertices (local index 0, 1)."""
        return sel.grabbable(mask, self.groom.strand_offsets, self._proxy())

    def drag(self, target_offset, stiffness=0.5) -> None:
        """Pull the selected vertices toward anchor + ``target_offset`` [m] (anchor: their position when the drag
        began): each frame their targets move ``stiffness`` in (0, 1] of the remaining way, and springs pull the
        vertices to them (``GuideSimulation.drag_springs``: contacts stop them).  :meth:`release` ends the drag."""
        off = _vec3("target_offset", target_offset)
        s = _positive("stiffness", stiffness)
        if s > 1.0:
            raise ValueError(f"'stiffness' must lie in (0, 1], got {stiffness!r}")
        verts = None
        if self._drag is None:
            verts = self._grabbable(self._selection)
            if verts.size == 0:
                raise ValueError("drag: no selected vertex can move (nothing selected, or only clamped roots)")

        def apply():
            if self._drag is None:
                anchor = self.groom.points[verts].astype(np.float64)
                self._drag = {"vertices": verts, "anchor": anchor, "position": anchor.copy()}
            self._drag["offset"] = off
            self._drag["stiffness"] = s
            if self._sim is not None:
                self._apply_kinematics()

        self._edit("drag", {"target_offset": off.tolist(), "stiffness": s}, apply)

    def release(self) -> None:
        """End the drag: the dragged vertices are free again."""
        if self._drag is None:
            raise ValueError("release: no drag is active")

        def apply():
            self._drag = None
            if self._sim is not None:
                self._apply_kinematics()

        self._edit("release", {}, apply)

    def _set_pins(self, action: str, value: bool) -> None:
        if not self._selection.any():
            raise ValueError(f"{action}: nothing is selected")

        def apply():
            pinned = self.groom.pinned.copy()
            pinned[self._selection] = value
            self.groom = replace(self.groom, pinned=pinned, params=dict(self.groom.params))
            if self._sim is not None:
                self._apply_kinematics()

        self._edit(action, {}, apply)

    def pin(self) -> None:
        """Pin the selected vertices where they are (kinematic until unpinned; ``Groom.pinned``)."""
        self._set_pins("pin", True)

    def unpin(self) -> None:
        """Free the selected vertices."""
        self._set_pins("unpin", False)

    # ------------------------------------------------------------------ the comb
    def comb(self, path, radius, axis=(0.0, 0.0, 1.0), length=0.0, friction=0.3, step=None) -> int:
        """Sweep a comb through the hair along ``path``; returns the number of strands it combed.

        The comb is one capsule "tooth": the points within ``radius`` [m] of a segment of
        ``length`` [m] along ``axis`` centred on the comb's position (``length`` 0: a sphere
        brush).  It is a body collider of the ADMM contact pipeline (a :class:`CapsuleCollider` on
        body ``COMB_BODY`` with Coulomb coefficient ``friction`` [-]), present in the solver from
        its build on and idle between strokes (it acts on no strand), so a stroke compiles nothing.
        (A comb with several teeth would need one collider slot per tooth at the build.)

        The stroke moves the comb along the polyline ``path`` (world coordinates [m]) in equal
        steps of at most ``step`` [m] (default ``radius / 2``), one quasistatic solver step per
        step; hair is pushed by the contacts and dragged by friction, never moved directly (the
        details: :mod:`taichi_hair.groom.comb`).

        Rest pose: afterwards every strand the comb touched (a comb contact in some step), and
        every skinned strand bound to such a guide, takes its current pose as its rest pose
        (the clamped root edge is kept bit for bit), so the combed shape stays when the
        simulation goes on; the other strands keep theirs (strands moved only through hair-hair
        contacts relax back).  ``drag``/``release`` never change the rest pose; a comb is a
        shape edit, like :meth:`scale_curl`.  A drag in progress ends.  The comb steps the solver
        even when the simulation is off (``simulate(False)``): the stroke is the edit.
        """
        pts, r, ax, length_, mu, h = comb_stroke.check_stroke(path, radius, axis, length, friction, step)
        positions = comb_stroke.stroke_positions(pts, h)
        combed = [0]

        def apply():
            if self._drag is not None:
                self._drag = None
                if self._sim is not None:
                    self._apply_kinematics()
            self._ensure_built()
            sim = self._sim
            touched = comb_stroke.sweep(sim, positions, r, ax / np.linalg.norm(ax), length_, mu,
                                        self.timings["frame"])
            self._write_back()
            strands = comb_stroke.combed_strands(touched, self._guide_strands(), sim.skin, self.groom.strand_count)
            combed[0] = int(strands.sum())
            if strands.any():
                g = self.groom
                rest = rest_from_current(g.points, g.rest_points, g.strand_offsets, strands)
                self.groom = replace(g, rest_points=rest, params=dict(g.params)).validate()
                self._invalidate(layout=False)

        self._edit("comb", {"path": pts.tolist(), "radius": r, "axis": ax.tolist(), "length": length_,
                            "friction": mu, "step": h}, apply)
        return combed[0]

    # ------------------------------------------------------------------ parameters, simulation
    def set_parameter(self, name, value) -> None:
        """Set one :class:`GroomingConfig` field (validated; errors name the field)."""
        new = with_parameter(self.config, name, value)
        logged = new.to_dict()[name]

        def apply():
            self.config = new
            if name in REBUILD_PARAMETERS or (name == "gravity" and new.rest_pose == "sag-free"):  # (re-solved)
                self._invalidate(layout=name in LAYOUT_PARAMETERS)
            elif self._sim is not None:
                self._sim.apply_live_parameters(self.config)

        self._edit("set_parameter", {"name": name, "value": logged}, apply)

    def simulate(self, on: bool = True) -> None:
        """Turn the simulation on or off (when off, :meth:`advance` does nothing)."""
        if not isinstance(on, bool):
            raise ValueError(f"'on' must be true or false, got {on!r}")
        self.simulating = on
        self._record("simulate", on=on)

    def advance(self, frames: int = 1) -> None:
        """Run ``frames`` quasistatic frames (``config.iterations`` ADMM iterations each) and write the
        result into ``groom.points``.  Rebuilds the Model first if an edit asked for it."""
        if not (isinstance(frames, (int, np.integer)) and not isinstance(frames, bool) and frames >= 1):
            raise ValueError(f"'frames' must be an integer >= 1, got {frames!r}")
        frames = int(frames)
        if self.simulating:
            import taichi as ti

            fresh = self._sim is None
            self._ensure_built()
            sim = self._sim
            for f in range(frames):
                t0 = time.perf_counter()
                d = self._drag
                if d is not None:
                    d["position"] += d["stiffness"] * (d["anchor"] + d["offset"] - d["position"])
                sim.step(None if d is None else d["position"])
                ti.sync()
                (self.timings["first_frame"] if fresh and f == 0 else self.timings["frame"]).append(
                    time.perf_counter() - t0)
            self._write_back()
        self._record("advance", frames=frames)

    def quality(self, full: bool = True) -> dict:
        """Strain, hair-pair and head penetration, drift, the last step's move, the worst step (``GuideSimulation.quality``)."""
        self._ensure_built()
        return self._sim.quality(full)

    def rest_pose_report(self) -> dict:
        """Equilibrium residual, strands held, drift of the guides (:meth:`GuideSimulation.rest_pose_report`)."""
        self._ensure_built()
        return self._sim.rest_pose_report(self.groom, self.config)

    # ------------------------------------------------------------------ the simulation objects
    def _invalidate(self, layout: bool = True) -> None:
        """Mark the simulation out of date: ``layout`` -> build a new Model and solver at the next
        frame (Taichi recompiles the kernels); else update the Model in place (same fields)."""
        if layout:
            self._sim = None
        elif self._sim is not None:
            self._sim.stale = True
        self._proxy_cache = None

    def _ensure_built(self) -> None:
        """Build the :class:`GuideSimulation` if there is none, or update it in place if stale."""
        fresh = self._sim is None
        if not (fresh or self._sim.stale):
            return
        t0 = time.perf_counter()
        if fresh:
            self._sim = GuideSimulation(self.groom, self.config, self._guide_strands(), self.colliders)
        else:
            self._sim.update(self.groom, self.config, self._guide_strands())
        self._load_state()
        self.rebuild_count += int(fresh)
        self.update_count += int(not fresh)
        self.timings["rebuild" if fresh else "update"].append(time.perf_counter() - t0)

    def _load_state(self) -> None:
        """State from the groom: rest frames and twists, current positions; fresh multipliers."""
        self._sim.load_positions(self.groom.points)
        self._apply_kinematics()

    def _apply_kinematics(self) -> None:
        """Write vertex_is_fixed / vertex_body_position: clamped roots, pins (where the groom has the
        vertex now) and the drag (its current prescribed positions).  Body 0 stays the identity."""
        pinned = pinned_positions = None
        if self.groom.pinned.any():  # (the proxy map costs a pass over every vertex)
            pinned = self._grabbable(self.groom.pinned)
            pinned_positions = self.groom.points[pinned]
        d = self._drag
        self._sim.set_kinematics(pinned, pinned_positions, None if d is None else d["vertices"],
                                 None if d is None else d["position"])

    def _write_back(self) -> None:
        """groom.points <- simulated guides (State) and skinned strands, in the groom's dtype."""
        pts = self._sim.positions(self.groom.points)
        self.groom = replace(self.groom, points=pts, params=dict(self.groom.params))
