"""The contact pipeline of one Model (Daviet 2023 Sec. 4.5 and Algorithm 1): :class:`ContactPipeline` runs
detection (hash grid, strand broad phase, narrow phase of :mod:`taichi_hair.contact.narrow`, continuous
detection of :mod:`taichi_hair.contact.ccd`), the z-step projection of each ADMM iteration and the end-of-step
geometric correction (:mod:`taichi_hair.contact.projection`), and owns every contact field, allocated once
and grown when the contact count overflows.
"""

import numpy as np
import taichi as ti

from ..config import CorrectionContactOrder, MassSplitting, WeightTime
from ..fields import upload
from ..solver_base import on_gpu

from .narrow import (BEND_ALL, BEND_BODY, BEND_NONE, build_adjacency, count_contacts, write_contacts)
from .correction import warn_soft_rest_lengths
from .projection import SLAB_ORDER, SLABS
from .reuse import kept_contacts, prepare_reuse, reuse_key

#: Contacts under which the contact sweeps run serially on the CPU (``ContactPipeline._serial_contacts``) [-].  Measured
#: on 2 cores (2026-12-05, bit-identical either way): the head turn (6,148 contacts) 761 -> 529 ms per frame, the
#: ponytail (11,000) 1,001 -> 679; the 1,000-strand hairball (35,650 on average, 70k in the pile) 2,121 parallel,
#: 2,060 with this bound, 2,002 all serial.  Kept low so that machines with more cores keep their parallelism.
_SERIAL_CONTACTS = 20_000
#: CPU threads up to which the slab groups' sweeps (``contact.slabs``) run on the launching thread, in the same order
#: (``projection.SLAB_ORDER``; the same bits) [-].  Measured on 2 threads (grooming benchmark, 153k contacts, in one
#: process, ``benchmarks/probes/slab_sweeps.py``, 2026-12-06, medians of 6): a sweep 1.16 / 1.27 ms on one thread
#: (index order and slab order) against 1.63 / 1.78 ms in parallel in two runs, 1.90 against 1.89 in a third.  Not
#: measured with more threads: there the groups keep their threads.
_SLAB_THREADS = 2
#: Vertices under which the correction's edge passes and acceleration run serially on the CPU [-].
_SERIAL_VERTICES = 20_000
#: (v0, omega, c) of the world frame: hair-hair reaches from the plain velocities (``ContactConfig.rigid_reach`` off).
_WORLD_FRAME = (np.zeros(3), np.zeros(3), np.zeros(3))


# --------------------------------------------------------------------------- host orchestration
class ContactPipeline:
    """Detection, projection and correction for one Model (all fields allocated here, once).

    Used by :class:`~taichi_hair.solver_admm.SolverADMM`; the buffers grow (with
    a warning that gives the count) only when a detection overflows them.

    Args:
        model: the Model.
        config: :class:`~taichi_hair.config.ContactConfig`.
        colliders: a :class:`~taichi_hair.contact.colliders.ColliderSet` or ``None``.
    """

    def __init__(self, model, config, colliders=None):
        from .colliders import ColliderSet
        from ..fields import BoxGridFields, CCDFields, ContactFields, GridFields, PairFields, StrandBoxFields

        self.model = model
        self.config = config
        self.colliders = colliders if colliders is not None else ColliderSet([], model.body_count)
        warn_soft_rest_lengths(model, config)
        if config.hair_hair:
            from .grid import warn_overlapping_root_edges

            warn_overlapping_root_edges(model)
        n = model.vertex_count
        #: Contact radius of each vertex/edge (its strand's radius) [m], shape (vertex_count,).
        self.vertex_radius = ti.field(float, n)
        #: m_i, for W_z = m_i / dt~^2 [kg], shape (vertex_count,).
        self.vertex_weight_base = ti.field(float, n)
        #: Typical edge length L~ of the vertex's strand [m], shape (vertex_count,).
        self.vertex_typical_length = ti.field(float, n)
        #: Bending time 2 L~^2/R sqrt(rho/E_b) of the vertex's strand (Sec. 4.5) [s], shape (vertex_count,).
        self.vertex_dt_bend = ti.field(float, n)
        #: Slab of each vertex's strand for the slab-parallel sweeps (``contact.slabs``) [-], shape (vertex_count,).
        self.vertex_slab = ti.field(ti.i32, n)
        self.set_coefficients()
        table = 1
        while table < 2 * n:
            table *= 2
        self.grid = GridFields(n, config.max_contacts_per_edge)
        #: Hair-hair pairs within reach, each found once (``pairs.find_candidates``): a buffer of fixed size, the
        #: search runs in rounds when a step finds more pairs than it holds.
        self.pairs = PairFields(n, max(256, int(config.pairs_per_edge * n)), skin=config.pair_skin > 0)
        #: Edges that searched in the last detection with a skin (-1: no skin, or the search without it ran);
        #: whether the skin was given up (its pairs did not fit the buffer).
        self.pair_skin_searched, self._skin_off, self._skin_reach = -1, False, None
        #: Rounds of the last hair-hair search, and rounds past the first since the pipeline was made.
        self.pair_rounds_last = 0
        self.pair_extra_rounds = 0
        #: Multi-insert hash of edge boxes, shared by proximity and continuous detection.
        self.boxes = BoxGridFields(n, table, max(12 * n, 1 << 14))
        capacity = max(16, int(config.capacity_per_vertex * n))
        self.con = ContactFields(capacity, n)
        self.stats_out = ti.field(float, 7)
        #: Edge lengths the geometric correction holds (rest, or before the correction) [m], shape (vertex_count,).
        self.edge_held_length = ti.field(float, n)
        #: Sweeps of the geometric correction in the last step (reported in ``statistics``).
        self.correction_sweeps_last = 0
        #: z_{k-1}, z_k of the correction's Chebyshev acceleration (allocated here when the correction uses it, so a
        #: step allocates nothing; a config changed afterwards gets them on first use).
        self._cheb = None
        if config.correction_chebyshev_rho > 0 and config.correction_iterations > 0:
            self._cheb = (ti.Vector.field(3, float, n), ti.Vector.field(3, float, n))
        #: Whether the contact sweeps run their loops on the launching thread (CPU, fewer than ``_SERIAL_CONTACTS``
        #: contacts at the last detection: each of a sweep's 16 parallel loops costs a dispatch to the thread
        #: pool), and the correction's edge passes and acceleration too (CPU, fewer than ``_SERIAL_VERTICES``).
        self._serial_contacts = False
        #: Whether the sweeps one by one of this step run in slab groups (``contact.slabs``: a CPU, the slabs
        #: contiguous in memory, and at least ``_SERIAL_CONTACTS`` contacts at the detection, where the thread pool's
        #: dispatches pay).
        self._slabs = False
        #: How the slab groups sweep: on Taichi's threads (``projection.SLABS``) where it has more than
        #: ``_SLAB_THREADS``, else in the same order on the launching thread (``SLAB_ORDER``, the same bits).
        self._slab_sweep = SLABS if ti.lang.impl.current_cfg().cpu_max_num_threads > _SLAB_THREADS else SLAB_ORDER
        #: The last quasistatic step's contact impulses for the next detection (``contact.warm``; allocated at the
        #: first quasistatic step, so dynamic runs never allocate them), and whether they belong to this model.
        self._warm, self._warm_valid = None, False
        self._serial_strands = (not on_gpu()) and n < _SERIAL_VERTICES
        self._dynamic = True  # (the last detection's mode; ``detect`` sets it with its dt)
        #: Continuous-time detection buffers (allocated here when ``continuous_detections`` > 0, so a step
        #: allocates nothing; a direct call of ``detect_continuous`` without them allocates them then).
        self.ccd = CCDFields(n) if config.continuous_detections > 0 else None
        self.strand_boxes = StrandBoxFields(model.strand_count, velocity_moments=config.rigid_reach)
        #: (v0, omega, c) of the rigid field the last detection measured hair-hair reaches in (``rigid_reach``).
        self.reach_frame = _WORLD_FRAME
        #: Whether the last step skipped the hair-hair search (no strands within reach), and how many did.
        self.hair_search_skipped = False
        self.hair_search_skip_count = 0
        self.ccd_skipped = 0
        #: Continuous passes run or skipped, and skipped, since the pipeline was made.
        self.ccd_pass_total = 0
        self.ccd_skip_total = 0
        self.continuous_contacts = 0
        self.capped_queries = 0
        self.grow_events = 0
        self.detections = 0
        #: Body contacts added before the correction (``detect_late_body``) in the current step, and its
        #: per-vertex counts [-], shape (vertex_count + 1,): allocated here when ``late_body_contacts`` is on and
        #: there are colliders (so a step allocates nothing; a direct call allocates it then).
        self.late_body_contacts = 0
        #: Kept detections (``contact.reuse``): what the last detection shares with the steps that may keep its contacts
        #: (None: none may), the positions it ran at [m] (vertex_count,), whether the last step kept them, and how
        #: many steps did since the pipeline was made.
        self._detection_key, self.contacts_reused, self.reuse_count, self._reuse_ready = None, False, 0, False
        self._detected_at = ti.Vector.field(3, float, n)
        self._late_count = (ti.field(ti.i32, n + 1) if config.late_body_contacts and self.colliders.count > 0
                            else None)

    def set_coefficients(self) -> None:
        """(Re)compute the per-vertex contact coefficients from the Model (after an in-place Model update)."""
        import numpy as np

        from ..model import _np_float

        model = self.model
        h = model.host
        f = _np_float()
        strand = h["vertex_strand"]
        radius = np.array([model.materials[s].radius for s in range(model.strand_count)])[strand]
        # What the kept hair-hair pairs (a Verlet skin, ``pairs.find_candidates_skin``) depend on besides the
        # positions: the radii (the reach), the strands and their edges (adjacent edges are skipped) and the
        # kinematic vertices (pairs of kinematic edges are skipped).  An update that keeps them (a grooming edit:
        # new rest shapes, the layout kept) keeps the pairs; the edges it moved search again, as after any motion
        # (an edge searches once a vertex moved more than skin / 3 from where it last searched).  Anything else
        # searches every edge again.
        key = (radius.astype(f), np.asarray(strand).copy(), h["edge_rest_length"] > 0, h["vertex_is_fixed"] != 0)
        if hasattr(self, "pairs"):
            old = getattr(self, "_pair_key", None)
            if old is None or not all(np.array_equal(a, b) for a, b in zip(old, key)):
                self.pairs.skin_valid = False
            self._warm_valid = False  # (the carried impulses are dropped: the edited strands' pairs have moved)
            self._detection_key = None  # (new radii, masses or rest shapes: the next step detects)
        self._pair_key = key
        density = np.array([model.materials[s].density for s in range(model.strand_count)])[strand]
        e_bend = np.array([model.materials[s].youngs_modulus_bend for s in range(model.strand_count)])[strand]
        # Typical edge length L~ per strand (mean rest edge) for dt~ (Sec. 4.5).
        le = h["edge_rest_length"]
        counts = np.bincount(strand, weights=(le > 0).astype(float), minlength=model.strand_count)
        sums = np.bincount(strand, weights=le, minlength=model.strand_count)
        typical = (sums / np.maximum(counts, 1))[strand]
        from .slabs import slabs_are_runs, vertex_slabs

        slab = vertex_slabs(h["vertex_rest_position"][h["strand_vertex_start"]], strand)
        upload([(self.vertex_radius, radius.astype(f)), (self.vertex_weight_base, np.maximum(h["vertex_mass"], 1e-30).astype(f)),
                (self.vertex_typical_length, typical.astype(f)),
                (self.vertex_dt_bend, (2.0 * typical**2 / radius * np.sqrt(density / e_bend)).astype(f)),
                (self.vertex_slab, slab)])
        #: Whether each slab's vertices are one run of vertex indices (the model's strands ordered along the slabs'
        #: axis, either way, as the grooming tool's guides): only then do the slab sweeps run (``contact.slabs``).
        self.slabs_contiguous = slabs_are_runs(slab)
        self.max_radius = float(radius.max())

    def _bending_time(self, dynamic: bool) -> int:
        """Where W_z's dt~ takes the edge's bending time (``ContactConfig.weight_time``; ``narrow.BEND_*``)."""
        if self.config.weight_time == WeightTime.PAPER or not dynamic:
            return BEND_ALL
        return BEND_BODY if self.config.weight_time == WeightTime.HAIR_STEP else BEND_NONE

    def uses_batches(self, dynamic: bool) -> bool:
        """Whether a sweep of this step may run in the paper's 8 batches (the z-step's ``projection_contact_order``,
        the correction's ``correction_contact_order``; "auto": batches on a GPU, and on the CPU in the dynamic mode
        for the z-step), so the entry coefficients they read must be stored (``narrow.store_entry_coefficients``)."""
        from .projection import SEQUENTIAL

        return not {self._projection_order(dynamic), self._correction_order()} <= {SEQUENTIAL, SLABS, SLAB_ORDER}

    def _projection_order(self, dynamic: bool):
        """``serial`` of the z-step's sweeps (``sweep_order``; "auto": one by one in the quasistatic mode on a CPU)."""
        return self.sweep_order(self.config.projection_contact_order, not on_gpu() and not dynamic)

    def _correction_order(self):
        """``serial`` of the correction's sweeps (``sweep_order``; "auto": one by one on a CPU)."""
        return self.sweep_order(self.config.correction_contact_order, not on_gpu())

    def sweep_order(self, order, auto_one_by_one: bool):
        """``serial`` of the sweeps (``projection.sweep_contacts``) for a contact order: ``"sequential"`` one by one in
        index order; ``"auto"`` where ``auto_one_by_one``, one by one in slab groups (``contact.slabs``; in index
        order where the contacts are few), their groups on several threads only where Taichi has more than
        ``_SLAB_THREADS`` (else the same order on one: the same bits); otherwise the batches (on the launching thread
        where they are few)."""
        from .projection import SEQUENTIAL

        if order == CorrectionContactOrder.SEQUENTIAL:
            return SEQUENTIAL
        if order == CorrectionContactOrder.AUTO and auto_one_by_one:
            return self._slab_sweep if self._slabs else SEQUENTIAL
        return self._serial_contacts

    @property
    def contact_count(self) -> int:
        return min(int(self.con.contact_count[None]), self.con.capacity)

    def detect(self, state, dt: float, gravity, dynamic: bool) -> int:
        """Proximity detection at the beginning of a step (Algorithm 1, line 1); returns the contact count."""
        import warnings

        import numpy as np

        from ..fields import ContactFields
        from .grid import compute_edge_bounds, proximity_boxes, rigid_velocity_fit, strand_velocity_moments
        from .pairs import find_candidates, find_candidates_skin

        m, cfg, g = self.model, self.config, self.grid
        x, v = state.vertex_position, state.vertex_velocity
        key = reuse_key(self, dt, gravity, dynamic)
        if kept_contacts(self, x, key):  # (``contact.reuse``: the last detection's contacts, measured again)
            return self.contact_count
        fit = _WORLD_FRAME
        if dynamic and cfg.rigid_reach and cfg.hair_hair:
            # Hair-hair reaches from velocities relative to the hair's best-fit rigid motion (grid module).
            strand_velocity_moments(m.strand, x, v, self.strand_boxes.strand_velocity_moments)
            fit = rigid_velocity_fit(self.strand_boxes.strand_velocity_moments.to_numpy())
        self.reach_frame = fit
        compute_edge_bounds(m.edge, x, v, g, *(ti.Vector([float(c) for c in a]) for a in fit))
        max_edge = float(g.max_edge_length[None])
        speed = float(g.max_speed[None])
        # Reach of the step (dynamic mode): two edges may approach by their relative displacement,
        # bounded by velocity_margin dt (|v_a - v_b| + spreads) (pairs.find_pairs); a vertex may
        # approach a body by velocity_margin (|v| dt + |g| dt^2).  Proximity detection runs once per step.
        gn = float(np.linalg.norm(np.asarray(gravity, float)))
        sweep = cfg.velocity_margin * dt if dynamic else 0.0
        fall = cfg.velocity_margin * gn * dt * dt if dynamic else 0.0
        margin = cfg.margin
        # The velocity part of the reach is capped at one longest edge, so the cells (and the cost of the
        # query) stay about two edges wide; faster relative motion can tunnel within a step in the
        # proximity-only mode, as in the paper's (continuous_detections > 0 catches it).
        # Body contacts keep the full margin (it does not change the grid); hair-hair pairs get it capped.
        body_sweep, body_fall = sweep, fall
        if cfg.continuous_detections > 0:
            # Continuous-time detection catches the pairs that close during the step: hair-hair
            # proximity needs no velocity reach (bodies keep it: they have no continuous test).
            sweep, fall = 0.0, 0.0
        motion = sweep * 2.0 * speed + fall
        if motion > max_edge > 0.0:
            sweep *= max_edge / motion
            fall *= max_edge / motion
            motion = max_edge
        self.hair_search_skipped = False
        # A Verlet skin (``pair_skin``, ``pairs.find_candidates_skin``) where the reach has no velocity part.
        skin = cfg.pair_skin if cfg.hair_hair and sweep == 0.0 and fall == 0.0 and not self._skin_off else 0.0
        # (kept pairs hold what was within the reach + skin of their search: a changed margin or skin searches again)
        self.pairs.skin_valid = self.pairs.skin_valid and skin > 0.0 and (margin, skin) == self._skin_reach
        self.pair_skin_searched, self._skin_reach = -1, (margin, skin)
        if skin > 0.0:
            def fill_grid():  # the boxes grown by the skin, entered in the grid (which may grow: read it after)
                proximity_boxes(m.edge, x, self.vertex_radius, g, self.boxes, margin + skin, 0.0, 0.0)
                h_grid = self._fill_box_grid(max(max_edge, 1e-9))
                return h_grid, self.boxes

            self.pair_skin_searched = find_candidates_skin(m.vertex, m.edge, x, self.vertex_radius, g, self.pairs,
                                                           margin, skin, fill_grid)
            if self.pair_skin_searched < 0:  # (a failed try costs a search: not again for this pipeline)
                self._skin_off = True
                warnings.warn(f"ContactConfig.pair_skin = {skin:g} m: the pairs within reach + skin do not fit the "
                              f"pair buffer ({self.pairs.capacity} pairs, pairs_per_edge); searching every step "
                              "without a skin from now on", stacklevel=3)
        if cfg.hair_hair and self.pair_skin_searched < 0:
            proximity_boxes(m.edge, x, self.vertex_radius, g, self.boxes, margin, sweep, fall)
            if cfg.skip_when_apart and self._strands_apart(x, margin, sweep, fall):
                # No two strands within reach and none can touch itself: nothing to search (grid.strands_apart).
                g.edge_candidate_count.fill(0)
                self.hair_search_skipped = True
                self.hair_search_skip_count += 1
            else:
                h = self._fill_box_grid(max(max_edge, 1e-9))
                self.pair_rounds_last = find_candidates(m.vertex, m.edge, x, self.vertex_radius, g, self.boxes,
                                                        self.pairs, h, margin, sweep, fall)
                self.pair_extra_rounds += self.pair_rounds_last - 1
        elif not cfg.hair_hair:
            g.edge_candidate_count.fill(0)
        sweep, fall = body_sweep, body_fall
        while True:
            count_contacts(m.vertex, x, v, self.vertex_radius, g, self.colliders, margin, sweep, fall)
            write_contacts(m.vertex, m.strand, x, v, self.vertex_radius, g, self.colliders, self.con, cfg.friction, margin,
                           sweep, fall, cfg.keep_rest_overlaps)
            total = int(self.con.contact_count[None])
            if total <= self.con.capacity:
                break
            new_cap = max(2 * self.con.capacity, int(1.25 * total))
            warnings.warn(f"contact buffer overflow: {total} contacts for a capacity of {self.con.capacity}; "
                          f"growing it to {new_cap} and detecting again (no contact dropped)", stacklevel=3)
            self.con = ContactFields(new_cap, m.vertex_count)
            self.grow_events += 1
        self._slabs = (not on_gpu()) and total >= _SERIAL_CONTACTS and self.slabs_contiguous
        self._slabs = self._slabs and bool({SLABS, SLAB_ORDER} & {self._projection_order(dynamic), self._correction_order()})
        if self._slabs:
            from .slabs import group_contacts

            group_contacts(self.vertex_slab, self.con)  # (sorts the contacts by slab group)
        build_adjacency(m.vertex, self.con, self.vertex_weight_base, self.vertex_typical_length, self.vertex_dt_bend,
                        dt, gn, dynamic, 0, cfg.mass_splitting == MassSplitting.BATCH, self._bending_time(dynamic),
                        self.uses_batches(dynamic))
        if not dynamic and self._warm_valid:
            from .warm import warm_impulses

            warm_impulses(self.con, self._warm)  # (the last quasistatic step's impulses, contact by contact)
        self._warm_valid = self._warm_valid and not dynamic
        self._serial_contacts = (not on_gpu()) and total < _SERIAL_CONTACTS
        self.detections += 1
        # Per-step statistics of the continuous passes and the late body contacts of this step.
        self.late_body_contacts = 0
        self.continuous_contacts = 0
        self.capped_queries = 0
        self.ccd_skipped = 0
        self._dt, self._gn, self._dynamic = dt, gn, dynamic
        if key is not None:  # (kept for the next steps: ``contact.reuse``)
            self._detected_at.copy_from(x)
            if not self._reuse_ready:
                prepare_reuse(self, x)
        self._detection_key, self.contacts_reused = key, False
        return total

    def detect_continuous(self, x0, x) -> int:
        """Continuous-time detection from x0 (begin of step) to x (current iterate); appends the new
        impacts as contacts (module :mod:`taichi_hair.contact.ccd`) and returns how many it added."""
        from .ccd import count_impact_contacts, find_impacts, swept_boxes, write_impact_contacts
        from ..fields import CCDFields

        m, cfg = self.model, self.config
        if not cfg.hair_hair:
            return 0
        if self.ccd is None:
            self.ccd = CCDFields(m.vertex_count)
        ccd = self.ccd
        swept_boxes(m.edge, x0, x, self.vertex_radius, self.boxes, ccd)
        # Two edges outside each other's proximity reach approach by at most twice the largest
        # displacement: when that is within the proximity margin no impact is possible (skip the pass).
        self.ccd_pass_total += 1
        if cfg.skip_slow_continuous and 2.0 * float(ccd.max_displacement[None]) <= cfg.margin:
            self.ccd_skipped += 1
            self.ccd_skip_total += 1
            return 0
        # Cells of the longest edge (the paper's size), widened for very fast motion so no swept box spans
        # more than ~5 cells per axis.
        h = self._fill_box_grid(max(float(ccd.max_edge_length[None]), 0.25 * float(ccd.max_box_side[None]), 1e-9))
        find_impacts(m.vertex, m.edge, x0, x, self.vertex_radius, self.boxes, ccd, self.con, h)
        self.capped_queries += int(ccd.capped_queries[None])
        count_impact_contacts(ccd, self.con)
        first = min(int(self.con.contact_count[None]), self.con.capacity)
        while True:
            write_impact_contacts(m.vertex, x0, x, self.vertex_radius, ccd, self.con, first, cfg.friction,
                                  cfg.keep_rest_overlaps)
            total = int(self.con.contact_count[None])
            if total <= self.con.capacity:
                break
            self._grow_contacts(total, keep=first)
        added = total - first
        if added > 0:
            build_adjacency(m.vertex, self.con, self.vertex_weight_base, self.vertex_typical_length, self.vertex_dt_bend,
                            self._dt, self._gn, self._dynamic, first, cfg.mass_splitting == MassSplitting.BATCH,
                            self._bending_time(self._dynamic), self.uses_batches(self._dynamic))
        self.continuous_contacts += added
        if added > 0:
            self._detection_key = None
        return added

    def detect_late_body(self, x) -> int:
        """Body contacts for the vertices that reached a collider during the step's iterations without one
        (``ContactConfig.late_body_contacts``), appended before the end-of-step correction and at its restarts
        (``correct``); returns how many.

        The step's detection gives a vertex a body contact when its own motion (|v| dt + |g| dt^2) may bring
        it within reach; the hair of a dense pile can push it further within the step."""
        from .narrow import count_late_body_contacts, write_late_body_contacts

        if not self.colliders.any_acting():  # (none, or only the idle grooming comb: nothing to find)
            return 0
        m, con = self.model, self.con
        if self._late_count is None:
            self._late_count = ti.field(ti.i32, m.vertex_count + 1)
        count_late_body_contacts(m.vertex, x, self.vertex_radius, self.colliders, con, self.config.margin,
                                 self._late_count)
        added = int(self._late_count[m.vertex_count])
        if added == 0:
            return 0
        first = self.contact_count
        while True:
            write_late_body_contacts(m.vertex, x, self.vertex_radius, self.colliders, self.con, self.config.margin,
                                     first, self._late_count)
            total = int(self.con.contact_count[None])
            if total <= self.con.capacity:
                break
            self._grow_contacts(total, keep=first)
        build_adjacency(m.vertex, self.con, self.vertex_weight_base, self.vertex_typical_length, self.vertex_dt_bend,
                        self._dt, self._gn, self._dynamic, first, self.config.mass_splitting == MassSplitting.BATCH,
                        self._bending_time(self._dynamic), self.uses_batches(self._dynamic))
        self.late_body_contacts += added
        self._detection_key = None  # (the appended contacts: the next step detects)
        return added

    def _strands_apart(self, x, margin: float, sweep: float, fall: float) -> bool:
        """Strand-level broad phase on the edge boxes just computed (``grid.strands_apart``)."""
        from .grid import strands_apart
        from .grid import strand_boxes

        sb = self.strand_boxes
        strand_boxes(self.model.strand, self.model.edge, x, self.vertex_radius, self.grid, self.boxes, sb, margin, sweep, fall)
        return strands_apart(sb.strand_box_lo.to_numpy(), sb.strand_box_hi.to_numpy(),
                             sb.strand_self_clear.to_numpy())

    def _fill_box_grid(self, h: float) -> float:
        """Enter every edge box (already in ``self.boxes``) in the cells of size h [m] it overlaps; grow the
        entry buffer (reported) when it is too small.  Returns h as the kernels see it."""
        import warnings

        from ..fields import BoxGridFields
        from .grid import count_cells, fill_entries

        m, bx = self.model, self.boxes
        count_cells(m.edge, bx, h)
        entries = int(bx.edge_entry_start[m.vertex_count])
        if entries > bx.entry_capacity:
            new_cap = max(2 * bx.entry_capacity, int(1.25 * entries))
            warnings.warn(f"collision grid: {entries} cell entries for a capacity of {bx.entry_capacity}; "
                          f"growing it to {new_cap}", stacklevel=4)
            new = BoxGridFields(m.vertex_count, bx.table_size, new_cap)
            new.edge_box_lo.copy_from(bx.edge_box_lo)
            new.edge_box_hi.copy_from(bx.edge_box_hi)
            self.boxes = bx = new
            count_cells(m.edge, bx, h)
            self.grow_events += 1
        fill_entries(bx)
        return h

    def _grow_contacts(self, needed: int, keep: int) -> None:
        """Grow the contact buffers mid-step, keeping the first ``keep`` contacts and the duals."""
        import warnings

        from ..fields import ContactFields

        old = self.con
        new_cap = max(2 * old.capacity, int(1.25 * needed))
        warnings.warn(f"contact buffer overflow: {needed} contacts for a capacity of {old.capacity}; "
                      f"growing it to {new_cap} (no contact dropped)", stacklevel=4)
        new = ContactFields(new_cap, self.model.vertex_count)
        for name in ("contact_vertex", "contact_weight", "contact_normal", "contact_kinematic", "contact_friction",
                     "contact_thickness", "contact_delassus", "contact_accumulated", "contact_delta",
                     "contact_collider", "contact_status"):
            a = getattr(new, name).to_numpy()
            a[:keep] = getattr(old, name).to_numpy()[:keep]
            getattr(new, name).from_numpy(a)
        new.vertex_contact_dual.copy_from(old.vertex_contact_dual)
        new.contact_group_start.copy_from(old.contact_group_start)  # (the appended contacts join the last group)
        new.contact_count[None] = keep
        self.con = new
        self._detection_key = None
        self.grow_events += 1

    def project(self, x, buf, sweeps: int) -> None:
        """The z-step and lambda_z update of one ADMM iteration (Sec. 4.5), then W_z for the global step."""
        from .projection import projection_begin, projection_end, projection_sweep

        projection_begin(x, self.con, False)
        serial = self._projection_order(self._dynamic)
        for _ in range(sweeps):
            projection_sweep(self.con, serial)
        projection_end(x, self.con, buf)

    def correct(self, x, x0, sweeps: int) -> None:
        """Geometric contact correction at the end of the step (Alg. 1, last line): project x itself
        (:func:`taichi_hair.contact.correction.correct`)."""
        from .correction import correct

        correct(self, x, x0, sweeps)

    def clear(self, buf) -> None:
        from .projection import clear_contact_terms

        clear_contact_terms(self.con, buf)

    def count_status(self, x) -> None:
        """Record the sticking/sliding/separating counts of the last ADMM projection (before correction), and in the
        quasistatic mode each contact's impulse for the next detection (``contact.warm.keep_impulses``)."""
        from ..fields import WarmFields
        from .projection import contact_statistics
        from .warm import keep_impulses

        contact_statistics(x, self.vertex_radius, self.colliders, self.con, self.stats_out, True)
        if not self._dynamic:
            if self._warm is None or self._warm.capacity < self.con.capacity:
                self._warm = WarmFields(self.con.capacity, self.model.vertex_count)
            keep_impulses(self.con, self._warm)
            self._warm_valid = True

    def vertex_states(self, vertex_count: int):
        """Per vertex, the state of its contacts at the step's last ADMM projection (before the correction, as
        the sticking/sliding counts): 0 free (or separating), 1 sticking, 2 sliding (a vertex with both counts
        as sliding) [-], int8, shape (vertex_count,).

        A hair-hair contact marks the vertices of both edges that carry weight."""
        import numpy as np

        out = np.zeros(vertex_count, np.int8)
        nc = min(self.contact_count, self.con.capacity)
        if nc <= 0:
            return out
        vtx = self.con.contact_vertex.to_numpy()[:nc]
        w = self.con.contact_weight.to_numpy()[:nc]
        st = self.con.contact_status_admm.to_numpy()[:nc].astype(np.int8)
        used = (vtx >= 0) & (w != 0)
        np.maximum.at(out, vtx[used], np.broadcast_to(st[:, None], vtx.shape)[used])
        return out

    def statistics(self, x) -> dict:
        """Contact count, sticking/sliding/separating counts (last ADMM projection), penetrations [m].

        ``max_penetration_m`` is the deepest of all; ``hair_penetration_max_m`` / ``_p99_m`` and
        ``crossed_pairs`` are over the hair-hair contacts of the step (pairs within reach at its beginning),
        a crossed pair counting as more than r_a + r_b deep (``projection.contact_statistics``);
        ``body_penetration_max_m`` is against the solver's collider distance (a mesh's voxel SDF).
        A hair pair is measured past its contact thickness: r_a + r_b, or its rest distance where the pair
        was closer at rest (``ContactConfig.keep_rest_overlaps``); ``rest_overlap_contacts`` counts those.
        ``pair_skin_edges_searched``: edges that searched for pairs in the last detection with ``pair_skin``
        (-1 without a skin); ``contacts_reused``: whether the step kept the last detection's contacts (``contact.reuse``).
        """
        import numpy as np

        from .projection import OVERLAPS, contact_penetrations, contact_statistics

        con = self.con
        overlaps = self.config.hair_hair and self.config.keep_rest_overlaps
        contact_statistics(x, self.vertex_radius, self.colliders, con, self.stats_out, OVERLAPS if overlaps else False)
        o = self.stats_out.to_numpy()
        nc = self.contact_count
        p99 = 0.0
        kept = 0
        if self.config.hair_hair and nc > 0:
            nc_read = min(nc, con.capacity)
            pen, hair = np.zeros(nc_read, o.dtype), np.zeros(nc_read, np.int8)  # (o: the default float)
            contact_penetrations(con, nc_read, pen, hair)
            hair = hair.astype(bool)
            if hair.any():
                p99 = float(np.percentile(pen[hair], 99))
                if self.config.keep_rest_overlaps:
                    kept = int(o[6])
        return {"contacts": nc, "sticking": int(o[0]), "sliding": int(o[1]),
                "separating": int(o[2]), "max_penetration_m": max(float(o[3]), float(o[4]), 0.0),
                "body_penetration_max_m": max(float(o[3]), 0.0), "hair_penetration_max_m": max(float(o[4]), 0.0),
                "hair_penetration_p99_m": p99, "crossed_pairs": int(o[5]),
                "correction_sweeps": self.correction_sweeps_last,
                "continuous_contacts": self.continuous_contacts, "accd_capped": self.capped_queries,
                "continuous_passes_skipped": self.ccd_skipped, "hair_search_skipped": self.hair_search_skipped,
                "late_body_contacts": self.late_body_contacts, "rest_overlap_contacts": kept,
                "contacts_reused": self.contacts_reused,
                "pair_skin_edges_searched": self.pair_skin_searched}
