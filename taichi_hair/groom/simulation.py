"""The live quasistatic simulation of a grooming session's guides (Daviet 2023, Sec. 5.3).

:class:`GuideSimulation` owns the guides' :class:`Model`, the :class:`SolverADMM` in
``mode="quasistatic"`` with proximity-only contacts, the State and Control, and the
:class:`SkinningLBS` of the other strands.  It is given the groom, the config and the guide strands
as arguments and returns positions; it never calls the session.

Rest-pose changes (trim, scale_length, scale_curl, comb, undo/redo across them) and
material parameters (youngs_modulus, radius, density, w0) update the Model in
place, *lazily* at the next frame (a burst of edits costs one update):
:meth:`Model.update` with the host arrays a :class:`GroomBuilder` computes for
the new rest shapes, ``SolverADMM.refresh_model`` and ``SkinningLBS.rebind``,
all into the fields that exist already, so Taichi compiles nothing again.  The
frames after an in-place update are bit for bit those of a new session opened
on the edited groom (tested).  The guides' Model has two bodies (the head and the comb) and the
solver always has a contact pipeline (hair-hair contacts as configured, the scene colliders and the
idle comb), so the comb never needs a new Model either.  Only parameters that change which strands are
simulated or the contact set-up (``LAYOUT_PARAMETERS``: guide_ratio,
neighbour_count, seed, contacts, contact_margin) build a new Model and solver,
and then Taichi recompiles every kernel (kernels are specialised per field;
measured 8-185 s for the first frame on the shared 2-core CPU before in-place
updates existed, 15-25 s with a warm offline cache).  ``session.timings``
records builds (``rebuild``), in-place updates (``update``) and frames.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..fields import download, upload
from .config import COMB_BODY

#: The hair-hair pairs of a grooming session are kept between frames with a Verlet skin of this many contact
#: margins (``ContactConfig.pair_skin``; quasistatic steps have no velocity reach).  Measured on the grooming
#: benchmark's 8,600 sag-free guides (frames 2-7, ``/tmp/p/groom_skin.py``): skin 0 (a search every frame)
#: 2,248 ms per frame, 3 margins 2,097, 5 margins 1,969 (27-50 % of the edges search), 8 margins more pairs
#: than the buffer holds (the skin is then given up, with a warning).
PAIR_SKIN_MARGINS = 5.0
#: The drag's spring weight in units of a contact's weight on the same vertex (``GuideSimulation.drag_springs``) [-].
#: Measured (BENCHMARKS.md, "The grooming drag ..."): a tip dragged toward a sphere's centre stays on its surface at 1
#: and 3 and pops off it at 10 and 100 (the iterate goes k / (k + W_z) of the way to a target inside the body); a
#: grabbed tip trails its target by 1.96 / 0.75 / 0.25 / 0.027 mm in free space.
DRAG_WEIGHT = 1.0
#: No springs: ``(rows, targets, weights)`` of :meth:`GuideSimulation.shape_springs`.
_NO_SPRINGS = (np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0))
#: ``GuideSimulation.quality_worst`` before any step.
WORST_RESET = {"steps": 0, "crossed_pairs_worst": 0, "hair_penetration_max_m_worst": 0.0}


def reachable_targets(colliders, x, target, clearance, iterations: int = 24) -> np.ndarray:
    """Drag targets (k, 3) [m] moved out of the scene's bodies: a target closer than ``clearance`` (k,) [m] to a body
    (:func:`taichi_hair.quality.static_signed_distance`) becomes the farthest point of the segment from the vertex's
    position ``x`` (k, 3) to it that keeps the clearance (bisection, ``iterations`` halvings); a vertex itself inside
    keeps its place.  Why: a spring pulled toward a point deep inside the head drew the iterate halfway there every
    step, where the SDF's gradient says little, and the correction threw the vertex 6-29 mm about the head's surface
    each frame (a lock of the generated groom dragged toward the head's centre, BENCHMARKS.md)."""
    from ..quality import static_signed_distance

    out = np.array(target, np.float64)
    deep = np.nonzero(static_signed_distance(colliders, out) < clearance)[0]
    if deep.size:
        start, c = np.asarray(x, np.float64)[deep], clearance[deep]
        a, b = start, out[deep]
        for _ in range(iterations):
            m = 0.5 * (a + b)
            ok = (static_signed_distance(colliders, m) >= c)[:, None]
            a, b = np.where(ok, m, a), np.where(ok, b, m)
        out[deep] = np.where((static_signed_distance(colliders, start) < c)[:, None], start, a)
    return out


def _host_of(builder) -> tuple[dict, list]:
    """``(host, materials)`` that ``builder.finalize()`` would give its Model, without allocating
    the Model's Taichi fields (allocating them would make Taichi compile the kernels again).

    GroomBuilder has no host-only finalize; this calls ``finalize`` with the module's ``Model``
    class swapped for a capture for the duration of the call (single-threaded use only).
    """
    from .. import builder as builder_module

    class _Captured(Exception):
        pass

    def capture(host, materials, body_count):
        raise _Captured(host, materials)

    saved = builder_module.Model
    builder_module.Model = capture
    try:
        builder.finalize()
    except _Captured as got:
        return got.args[0], got.args[1]
    finally:
        builder_module.Model = saved
    raise RuntimeError("GroomBuilder.finalize returned without building its Model")


def guide_setup(groom, config, guides: np.ndarray):
    """The guides' rest vertices (float64, flat) and offsets, and the material of ``config``."""
    from ..config import RodMaterial

    g, cfg = groom, config
    off = g.strand_offsets
    counts = g.strand_vertex_counts()[guides]
    starts = off[guides]
    from .binding import vertex_rows

    rows = vertex_rows(starts, counts)  # (the guides' vertices, strand after strand)
    points = g.rest_points[rows].astype(np.float64)
    offsets = np.concatenate([[0], np.cumsum(counts)])
    material = RodMaterial(radius=cfg.radius, density=cfg.density, youngs_modulus_bend=cfg.youngs_modulus,
                           youngs_modulus_stretch=cfg.youngs_modulus)
    return (points, offsets), material


def guide_host(guide_rest, material, old=None) -> tuple[dict, list, np.ndarray | None]:
    """``(host, materials, rebuilt)`` of the guides' Model for the rest shapes ``guide_rest`` (:func:`guide_setup`).

    ``old``: ``(host, material)`` of the last build (its authored host arrays).  Where the layout and the material are
    the same and at most half the guides changed, only those guides are built (a ``GroomBuilder`` of their own) and
    their rows put into a copy of the old arrays: the same arrays, bit for bit, as a full build, because every array
    of ``GroomBuilder.host_arrays`` is computed strand by strand and vertex by vertex (what ``GroomBuilder.merged``
    relies on too; tested).  ``rebuilt``: the guides built so (sorted), or None after a full build.  A guide that
    fails the builder's checks sends the call to the full build, whose message names it by its own index.  Measured on
    the grooming benchmark's edit (``scale_length`` of every tenth strand; cProfile, scratch ``/tmp/p/s27/editprof.py``,
    2026-12-06): 20 ms, against 67 ms for the full build of the 8,600 guides."""
    points, offsets = guide_rest
    counts = np.diff(offsets)
    if old is not None and old[1] == material and np.array_equal(old[0]["strand_vertex_count"], counts):
        from .binding import _strands_differ, vertex_rows

        prev = old[0]
        changed = np.nonzero(_strands_differ(prev["vertex_rest_position"], points, offsets[:-1]))[0]
        if changed.size <= counts.size // 2:
            rows = vertex_rows(offsets[changed], counts[changed])
            host = dict(prev)
            if changed.size:
                try:
                    part, _ = _host_of(guide_builder((points[rows], np.concatenate([[0], np.cumsum(counts[changed])])),
                                                     material))
                except ValueError:  # (the full build below names the guide by its own index)
                    return (*_host_of(guide_builder(guide_rest, material)), None)
                for key, value in part.items():
                    if key not in ("vertex_strand", "strand_vertex_start"):  # (indices: the part's own)
                        host[key] = prev[key].copy()
                        host[key][changed if key.startswith("strand_") else rows] = value
            return host, [material] * counts.size, changed
    return (*_host_of(guide_builder(guide_rest, material)), None)


def guide_builder(guide_rest, material):
    """The guides' GroomBuilder (bulk :meth:`GroomBuilder.add_strands`): roots clamped to body 0
    (the head); two bodies, the second the comb's (``COMB_BODY``), so a comb stroke needs no new
    Model."""
    from ..builder import GroomBuilder

    builder = GroomBuilder(body_count=COMB_BODY + 1)
    builder.add_strands(guide_rest[0], guide_rest[1], material, root="clamped", body=0)
    return builder


class GuideSimulation:
    """The guides of a groom in a quasistatic ADMM simulation, with the skinning of the others.

    Args:
        groom: the :class:`taichi_hair.io.Groom` (its rest pose builds the Model).
        config: the session's :class:`~taichi_hair.groom.config.GroomingConfig`.
        guides: sorted int64 indices of the simulated strands.
        colliders: the scene's body colliders (the comb is added after them).

    Attributes:
        model, solver, state, control: the guides' Model, SolverADMM, State and Control.
        guides: the groom strand of each Model strand, int64.
        solver_config: the SolverADMMConfig of the solver, contacts aside (the rest pose is solved for it).
        rest_pose_result: the RestPoseResult of the sag-free rest pose, None when authored.
        skin: the :class:`SkinningLBS` of every strand, or None when every strand is a guide.
        comb_collider: index of the comb in the solver's ColliderSet [-].
        guide_vertex: groom vertex of each Model vertex, int64 (guide vertex count,).
        row_of: Model vertex of each groom vertex, -1 off the guides, int64 (vertex_count,).
        stale: the rest shapes or materials changed; :meth:`update` before the next step.
        base_fixed, base_body: ``vertex_is_fixed`` and ``vertex_body_position`` of the Model
            without pins (clamped roots only).
        drag_rows: Model vertices of the drag (held by springs, :meth:`drag_springs`), int64.
        np_float: NumPy dtype of Taichi's ``default_fp``.
    """

    def __init__(self, groom, config, guides: np.ndarray, colliders):
        from ..contact.colliders import CapsuleCollider
        from ..config import ContactConfig, SolverADMMConfig
        from ..model import _np_float
        from .skinning import SkinningConfig, SkinningLBS
        from ..solver_admm import SolverADMM

        g, cfg = groom, config
        off = g.strand_offsets
        guide_rest, material = guide_setup(g, cfg, guides)
        model = guide_builder(guide_rest, material).finalize()
        self._guide_material = material  # (with the authored host: what an edit's ``guide_host`` starts from)
        self.model, self.guides = model, np.asarray(guides)
        self.solver_config = SolverADMMConfig(iterations=cfg.iterations, mode="quasistatic", w0=cfg.w0,
                                              schedule=cfg.schedule)
        self._solve_rest_pose(cfg)
        # Proximity only (Sec. 5.3): no velocity-dependent margin growth.  The pipeline always exists:
        # it holds the comb, an idle collider on its own body until a stroke enables it.
        contacts = ContactConfig(hair_hair=cfg.contacts, friction=cfg.friction, margin=cfg.contact_margin,
                                 velocity_margin=0.0, pair_skin=PAIR_SKIN_MARGINS * cfg.contact_margin,
                                 projection_iterations=cfg.contact_sweeps, correction_iterations=cfg.correction_sweeps)
        comb = CapsuleCollider(p0=(0.0, 0.0, 0.0), p1=(0.0, 0.0, 0.0), radius=1.0e-3, friction=0.0, body=COMB_BODY,
                               strands=(0, 1))
        solver = SolverADMM(model, replace(self.solver_config, contacts=contacts), colliders=list(colliders) + [comb])
        solver.contacts.colliders.collider_strands[len(colliders)] = [0, 0]  # idle: acts on no strand
        state = model.state()
        control = model.control()
        control.gravity = tuple(cfg.gravity)
        skin = None
        self._rest_buffers = []
        if guides.size < g.strand_count:
            rest = g.rest_points.astype(np.float64)
            polylines = [rest[off[s]:off[s + 1]] for s in range(g.strand_count)]
            skin = SkinningLBS(model, guides, polylines,
                               SkinningConfig(neighbour_count=min(cfg.neighbour_count, int(guides.size))),
                               strand_body=0)
            # Two float64 copies of the render rest points for the edits' rebinds, touched now (the binding
            # takes the skinning's per-strand copy, so ``rest`` is free to be one of them).
            spare = np.empty_like(rest)
            np.copyto(spare, rest)
            self._rest_buffers = [rest, spare]
            skin.prepare_rebind()  # (the first edit's upload then costs what the later ones do: 106 -> ~25 ms)
        guide_vertex = np.concatenate([np.arange(off[s], off[s + 1]) for s in guides])
        row_of = np.full(g.vertex_count, -1, dtype=np.int64)
        row_of[guide_vertex] = np.arange(guide_vertex.size)
        self.model, self.solver, self.state, self.control, self.skin = model, solver, state, control, skin
        self.comb_collider = len(colliders)
        self.scene_colliders = list(colliders)
        self.quality_worst = dict(WORST_RESET)
        self.guide_vertex, self.row_of, self.stale = guide_vertex, row_of, False
        self.base_fixed = model.host["vertex_is_fixed"].copy()
        self.base_body = model.host["vertex_body_position"].copy()
        self.drag_rows = np.zeros(0, dtype=np.int64)
        self.np_float = _np_float()
        self.shape_weight = cfg.unheld_shape_weight
        self._shape_key, self._shape, self._drag_position = None, _NO_SPRINGS, None

    def update(self, groom, config, guides: np.ndarray) -> None:
        """New rest shapes and materials, same layout: :meth:`Model.update`, ``refresh_model`` and a
        new skinning binding, all into the existing Taichi fields (no new field, no recompilation).
        The State is not touched: load it again (:meth:`load_positions`)."""
        g, cfg = groom, config
        guide_rest, material = guide_setup(g, cfg, guides)
        self.guides = np.asarray(guides)
        host, materials, rebuilt = guide_host(guide_rest, material, (self._authored_host, self._guide_material))
        self._guide_material = material
        before = (self._authored_host, self.rest_pose_result, self._rest_pose_gravity, self._rest_max_change)
        self.model.update(host, materials)
        self._solve_rest_pose(cfg, before, rebuilt)
        self.solver.config.w0 = cfg.w0
        self.solver.refresh_model()
        self._shape_key = None  # (new rest pose, new contact weights: the shape springs are computed again)
        self.apply_live_parameters(cfg)  # (the gravity the rest pose was solved for; after the new contact weights)
        if self.skin is not None:
            rest = self._render_rest(g.rest_points)  # (read-only, ours alone: the binding takes it without a copy)
            off = np.asarray(g.strand_offsets)
            counts = np.diff(off)
            if counts.size and np.all(counts == counts[0]):  # one (strands, vertices, 3) array: no per-strand slices
                self.skin.rebind(rest.reshape(counts.size, int(counts[0]), 3))
            else:
                self.skin.rebind([rest[off[s]:off[s + 1]] for s in range(g.strand_count)])
        self.base_fixed = host["vertex_is_fixed"].copy()
        self.base_body = host["vertex_body_position"].copy()
        self.stale = False

    def _render_rest(self, points: np.ndarray) -> np.ndarray:
        """``points`` (the groom's rest points) as float64, read-only, in whichever of the two buffers kept for it
        the skinning's binding does not hold.  A new 1.2 M-vertex array (29 MB) costs its page faults on the first
        touch: timed side by side inside the grooming benchmark's edits (NumPy's huge pages off, as in the app),
        ``astype`` took 12-20 ms, the copy into a buffer touched before 3.4-4.5 ms (cProfile had charged ``astype``
        42 ms).  The price: the two buffers stay allocated (58 MB for that groom)."""
        held = self.skin.host["render_vertex_rest_position"]
        buf = next((b for b in self._rest_buffers if b.shape == points.shape and not np.may_share_memory(b, held)), None)
        if buf is None:  # (not after an edit of the same layout, which is all ``update`` takes: a new array then)
            buf = np.empty(points.shape, np.float64)
        buf.flags.writeable = True
        np.copyto(buf, points)
        buf.flags.writeable = False
        return buf

    def _solve_rest_pose(self, config, before=None, rebuilt=None) -> None:
        """With ``config.rest_pose == "sag-free"``: the guides' rest pose solved for the session's gravity
        (:mod:`taichi_hair.solvers.rest_pose`) and written into the Model; the result in
        ``rest_pose_result`` (None for an authored rest pose).  Call ``refresh_model`` after it.

        ``before``: (authored host, result, gravity, rest_max_change) of the last solve.  For the same gravity,
        ``rest_max_change`` and layout only the
        guides whose authored host rows changed are solved again (``rest_pose_edit.resolve_rest_pose``; equal to a
        whole solve to rounding): an edit of 860 of 8,600 guides no longer solves all of them.  ``rebuilt``: the guides
        ``guide_host`` built alone, exactly the guides whose authored rows changed (the others' rows are the old
        arrays), so ``changed_strands`` need not compare the hosts (15 ms on the grooming benchmark's edit)."""
        from ..solvers.rest_pose import RestPoseConfig, apply_rest_pose, solve_rest_pose
        from ..solvers.rest_pose_edit import changed_strands, resolve_rest_pose

        authored, gravity = self.model.host, tuple(float(v) for v in config.gravity)
        self._authored_host, self._rest_pose_gravity = authored, gravity
        self._rest_max_change = config.rest_max_change
        self.rest_pose_result = None
        if config.rest_pose == "sag-free":
            rest_config = RestPoseConfig(max_rest_change=config.rest_max_change)
            old_host, old_result, old_gravity, old_change = before or (None, None, None, None)
            changed = None
            if old_result is not None and old_gravity == gravity and old_change == config.rest_max_change:
                changed = rebuilt if rebuilt is not None else changed_strands(old_host, authored)
            if changed is None:
                result = solve_rest_pose(self.model, self.solver_config, gravity=gravity, config=rest_config)
            else:
                result = resolve_rest_pose(self.model, old_result, changed, self.solver_config, gravity=gravity,
                                           config=rest_config)
            self.rest_pose_result = result
            apply_rest_pose(self.model, result)

    def apply_live_parameters(self, config) -> None:
        """Gravity, iterations, friction, contact sweeps and the unheld guides' shape springs of ``config`` into the
        running solver."""
        self.control.gravity = tuple(config.gravity)
        self.solver.config.iterations = config.iterations
        if self.solver.contacts is not None:
            self.solver.contacts.config.friction = config.friction
            self.solver.contacts.config.projection_iterations = config.contact_sweeps
            self.solver.contacts.config.correction_iterations = config.correction_sweeps
        if config.unheld_shape_weight != self.shape_weight:
            self.shape_weight = config.unheld_shape_weight
            self.drag_springs(self._drag_position)

    def load_positions(self, points: np.ndarray) -> None:
        """State from the groom's current pose ``points`` (vertex_count, 3) [m]: rest frames and
        twists, current positions; fresh multipliers."""
        self.model.reset_state(self.state)
        self.state.vertex_position.from_numpy(points[self.guide_vertex].astype(self.np_float))
        self.solver.reset_duals()
        if self.rest_pose_result is not None:  # sag-free: the rest shape is an equilibrium, start the duals there
            self.solver.prime_duals(self.state, self.control)

    def set_kinematics(self, pinned=None, pinned_positions=None, drag_vertices=None, drag_position=None) -> None:
        """Write vertex_is_fixed / vertex_body_position (clamped roots, and the pinned groom vertices ``pinned``
        (guide vertices) at ``pinned_positions`` [m]; body 0 stays the identity) and the drag: the groom vertices
        ``drag_vertices`` held by springs to ``drag_position`` [m] (:meth:`drag_springs`)."""
        fixed = self.base_fixed.copy()
        body = self.base_body.copy()
        if pinned is not None:
            rows = self.row_of[pinned]
            fixed[rows] = 1
            body[rows] = pinned_positions.astype(np.float64)
        self.drag_rows = np.zeros(0, dtype=np.int64) if drag_vertices is None else self.row_of[drag_vertices]
        # The springs' weights and the targets' clearance, per drag vertex: fixed until the next call (after every
        # Model build or update, and at every drag and release), so a frame reads nothing back.
        con, rows = self.solver.contacts, self.drag_rows
        base, dt_bend, radius = download((con.vertex_weight_base, con.vertex_dt_bend, con.vertex_radius))
        self._drag_weight = DRAG_WEIGHT * base[rows].astype(np.float64) / dt_bend[rows] ** 2
        self._drag_clearance = radius[rows].astype(np.float64)
        upload([(self.model.vertex_is_fixed, fixed.astype(np.int32)),
                (self.model.vertex_body_position, body.astype(self.np_float))])
        self.drag_springs(drag_position)

    def shape_springs(self) -> tuple:
        """``(rows, targets [m], weights [N/m])`` of the springs that hold the guides the sag-free rest pose does not
        hold (``rest_pose_result.unheld``) to their authored shape: every free vertex of such a guide, toward its rest
        position, with ``GroomingConfig.unheld_shape_weight`` times the weight of a contact on it (Han & Harada 2012's
        global shape constraint; the drag's spring form, :meth:`drag_springs`); none with an authored rest pose or a
        zero weight.  Computed again only after a new rest pose or weight."""
        r, weight = self.rest_pose_result, self.shape_weight
        if self._shape_key is not None and self._shape_key[0] is r and self._shape_key[1] == weight:
            return self._shape
        self._shape_key, self._shape = (r, weight), _NO_SPRINGS
        if r is not None and r.unheld and weight > 0:
            host = self.model.host
            unheld = np.array(sorted(s for s, _ in r.unheld), dtype=np.int64)
            start, count = host["strand_vertex_start"][unheld], host["strand_vertex_count"][unheld]
            rows = np.repeat(start - np.concatenate([[0], np.cumsum(count)[:-1]]), count) + np.arange(count.sum())
            rows = rows[self.base_fixed[rows] == 0]
            con = self.solver.contacts
            k = weight * con.vertex_weight_base.to_numpy()[rows].astype(np.float64) / con.vertex_dt_bend.to_numpy()[rows] ** 2
            target = host["vertex_rest_position"][rows].astype(np.float64)
            if self.scene_colliders:  # (an authored vertex inside the head: its spring stops at the surface)
                clearance = con.vertex_radius.to_numpy()[rows].astype(np.float64)
                target = reachable_targets(self.scene_colliders, self.state.vertex_position.to_numpy()[rows], target,
                                           clearance)
            self._shape = (rows, target, k)
        return self._shape

    def shape_springs_follow(self, strands: np.ndarray) -> None:
        """During a comb stroke: the shape springs of the guides ``strands`` (bool, guide count) hold them where they
        are now, not at their authored shape, so the comb moves them and they stay where it leaves them (the stroke
        then makes that their rest shape); the other guides keep theirs.  Called after each of the stroke's steps."""
        rows, target, k = self.shape_springs()
        moved = strands[self.model.host["vertex_strand"][rows]]
        if moved.any():
            target = target.copy()
            target[moved] = self.state.vertex_position.to_numpy()[rows[moved]]
            self.solver.set_attachments(rows, target, k)

    def drag_springs(self, drag_position=None) -> None:
        """Hold the drag's vertices (``drag_rows``) at ``drag_position`` [m] by zero-length springs
        (``SolverADMM.set_attachments``), the "spring-like forces" of the paper's direct manipulation (Sec. 5.3): the
        dragged hair stays free, so the contacts and the end-of-step correction keep it out of the head and out of
        the other hair it is pulled against (held kinematically, it went through both: a strand tip dragged toward a
        3.5 cm sphere's centre ended 32.5 mm inside it).  Each spring has ``DRAG_WEIGHT`` times the weight of a
        contact on its vertex, k_i = m_i / dt~_i^2 (the quasistatic W_z of Sec. 4.5, dt~ the bending time of one
        edge): in free space the vertex trails its target by its strand's pull over k (1.96 mm for the tests' 10 cm
        strands pulled 3 cm); where a contact stops it, the correction keeps it outside.  A target inside a body is
        replaced by the point where the straight way to it from the vertex meets the body (:func:`reachable_targets`)."""
        self._drag_position = drag_position
        rows = self.drag_rows
        shape_rows, shape_target, shape_weight = self.shape_springs()
        if drag_position is None or rows.size == 0:
            self.solver.set_attachments(shape_rows, shape_target, shape_weight)
            return
        target = np.asarray(drag_position, np.float64)
        if self.scene_colliders:
            target = reachable_targets(self.scene_colliders, self.state.vertex_position.to_numpy()[rows], target,
                                       self._drag_clearance)
        keep = ~np.isin(shape_rows, rows)  # (a dragged vertex of an unheld guide follows the drag)
        self.solver.set_attachments(np.concatenate([shape_rows[keep], rows]),
                                    np.concatenate([shape_target[keep], target]),
                                    np.concatenate([shape_weight[keep], self._drag_weight]))

    def step(self, drag_position=None) -> None:
        """One quasistatic step (``config.iterations`` ADMM iterations); ``drag_position`` [m], if
        given, are the drag's new targets (the rows of :meth:`set_kinematics`)."""
        if drag_position is not None:
            self.drag_springs(drag_position)
        self.solver.step(self.state, self.control, 1.0)
        self.note_step()

    def note_step(self) -> None:
        """Fold the last solver step's hair-hair figures (``SolverADMM.contact_stats``, measured every step) into
        ``quality_worst``: the most crossed pairs and the deepest hair pair of any step since the build (every
        step of ``step`` and of a comb stroke calls it)."""
        cs, w = self.solver.contact_stats, self.quality_worst
        w["steps"] += 1
        w["crossed_pairs_worst"] = max(w["crossed_pairs_worst"], int(cs.get("crossed_pairs", 0)))
        w["hair_penetration_max_m_worst"] = max(w["hair_penetration_max_m_worst"],
                                                float(cs.get("hair_penetration_max_m", 0.0)))

    def quality(self, full: bool = True) -> dict:
        """How good the guides' current frame is: :func:`taichi_hair.quality.frame_quality` of the State (edge
        strain, penetration into the scene's bodies against their true surface, drift from the Model's authored
        shape, the last step's hair-hair figures: penetration p99 and max, crossed pairs), and

        * ``max_step_motion_m``: the largest move of a vertex in the last step [m] (quasistatic steps have no
          velocity: a groom at rest moves ~0 per step);
        * ``contacts``, ``correction_sweeps``: the last step's contact count and end-of-step correction sweeps;
          ``hair_contacts``: whether hair-hair contacts are on (without them the hair-pair figures are 0);
        * ``quality_worst``'s figures (``*_worst``, ``steps``): the worst step since the build.

        The idle comb is not a body here (it acts on no strand between strokes).  Strands are named by their
        groom index.  ``full`` False: only the last step's contact figures and the worst step, which cost no pass
        over the State (the grooming window's panel, every frame)."""
        from ..quality import HAIR_KEYS, frame_quality

        cs = dict(self.solver.contact_stats, hair_contacts=bool(self.solver.contacts.config.hair_hair))
        if not full:
            keys = HAIR_KEYS + ("contacts", "correction_sweeps", "hair_contacts")
            return dict({k: cs[k] for k in keys if k in cs}, **self.quality_worst)
        x = self.state.vertex_position.to_numpy()
        x0 = self.solver.buf.vertex_position_begin.to_numpy()
        q = frame_quality(x, np.zeros_like(x), self.model.host, self.scene_colliders, contact_stats=cs)
        q.pop("max_speed_m_s")
        for key in ("strain_worst_strand", "penetration_worst_strand"):  # Model strand -> groom strand
            if q.get(key, -1) >= 0:
                q[key] = int(self.guides[q[key]])
        q["max_step_motion_m"] = float(np.max(np.linalg.norm(x - x0, axis=1))) if len(x) else 0.0
        q["contacts"] = int(cs.get("contacts", 0))
        q["correction_sweeps"] = int(cs.get("correction_sweeps", 0))
        q["hair_contacts"] = cs["hair_contacts"]
        q.update(self.quality_worst)
        return q

    def positions(self, points: np.ndarray) -> np.ndarray:
        """A new current pose: the simulated guides (State) and the skinned strands, in the dtype of
        ``points`` (the groom's pose, kept where nothing is simulated)."""
        x = self.state.vertex_position.to_numpy()
        if self.skin is not None:
            self.skin.deform(self.state, self.control)
            pts = self.skin.positions().astype(points.dtype)
        else:
            pts = points.copy()
        pts[self.guide_vertex] = x.astype(pts.dtype)
        return pts

    def rest_pose_report(self, groom, config) -> dict:
        """The equilibrium residual of the guides' Model under ``config.gravity`` (largest unbalanced vertex
        force over the strand's weight: round-off when sag-free, ~1 when authored), the strands the sag-free
        solve holds (groom indices of those it does not; ``held_by_springs``: how many of them the shape springs hold,
        :meth:`shape_springs`), and the drift of ``groom.points`` from
        ``groom.rest_points`` over the free guide vertices (p90 and max) [m]."""
        from ..solvers.rest_pose import equilibrium_residual

        res = equilibrium_residual(self.model, self.solver_config, gravity=tuple(config.gravity))
        rows = self.guide_vertex[self.model.host["vertex_is_fixed"] == 0]
        d = np.linalg.norm(groom.points[rows].astype(np.float64) - groom.rest_points[rows], axis=1)
        r = self.rest_pose_result
        return dict(rest_pose=config.rest_pose, guides=int(self.model.strand_count),
                    residual_max=float(np.nanmax(res)), residual_p50=float(np.nanmedian(res)),
                    strands_held=None if r is None else r.held_count,
                    not_held=[] if r is None else [int(self.guides[s]) for s, _ in r.unheld],
                    held_by_springs=0 if r is None or self.shape_weight <= 0 else len(r.unheld),
                    may_buckle=[] if r is None else [int(self.guides[s]) for s, _ in r.unstable],
                    drift_p90_m=float(np.percentile(d, 90)) if d.size else 0.0,
                    drift_max_m=float(d.max()) if d.size else 0.0)
