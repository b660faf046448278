"""Dataclass configurations: rod materials and solver settings.

Every field carries its unit and meaning; ``__post_init__`` validates so that
impossible parameters fail early with a message naming the field.

Choices are enums inside (:class:`Mode`, :class:`StrainMeasure`, ...): ``StrEnum`` members, so the strings of
the TOML / CLI boundary and of Python callers (``SolverADMMConfig(mode="quasistatic")``) are accepted and
converted once, in ``__post_init__``; a member compares equal to its string and serialises as it (JSON,
checkpoint fingerprints), and the code inside compares members (``cfg.mode == Mode.QUASISTATIC``: ``==``, so a
field set to a plain string after construction still compares right).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum


class StrainMeasure(StrEnum):
    KORNER = "korner"
    BERGOU = "bergou"


class Mode(StrEnum):
    DYNAMIC = "dynamic"
    QUASISTATIC = "quasistatic"


class Tridiagonal(StrEnum):
    AUTO = "auto"
    THOMAS = "thomas"
    PCR = "pcr"


class DualFrame(StrEnum):
    ROOT = "root"
    PAIR = "pair"
    NONE = "none"


class Schedule(StrEnum):
    AUTO = "auto"
    STAGE = "stage"
    STRAND = "strand"
    LANES = "lanes"


class Twist(StrEnum):
    AUTO = "auto"
    SOLVE = "solve"


class Integrator(StrEnum):
    BACKWARD_EULER = "backward_euler"
    BDF2 = "bdf2"


class CorrectionLengths(StrEnum):
    REST = "rest"
    BEFORE = "before"
    FREE = "free"


class CorrectionEdgeOrder(StrEnum):
    AUTO = "auto"
    COLOURS = "colours"
    STRANDS = "strands"


class CorrectionContactOrder(StrEnum):
    AUTO = "auto"
    BATCHES = "batches"
    SEQUENTIAL = "sequential"


class MassSplitting(StrEnum):
    BATCH = "batch"
    VERTEX = "vertex"
    NONE = "none"


class WeightTime(StrEnum):
    """The time dt~ of the collision weights W_z = m / dt~^2 (``ContactConfig.weight_time``)."""

    PAPER = "paper"  # dt~ = min(dt, sqrt(L~/|g|), 2 L~^2/R sqrt(rho/E_b)) in both modes (Sec. 4.5)
    STEP = "step"    # dynamic mode: min(dt, sqrt(L~/|g|)), the bending time left out; quasistatic: the paper's
    HAIR_STEP = "hair-step"  # dynamic mode: "step" on vertices whose contacts are all hair-hair, else the paper's


def as_choice(enum: type, owner: str, name: str, value):
    """``value`` (a string or a member) as a member of ``enum``, or a ValueError naming ``owner.name`` and the
    choices."""
    try:
        return enum(value)
    except ValueError:
        choices = tuple(m.value for m in enum)
        raise ValueError(f"{owner}.{name} must be one of {choices}, got {value!r}") from None


def _check_positive(owner: str, name: str, value: float) -> None:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise ValueError(f"{owner}.{name} must be a finite positive number, got {value!r}")


@dataclass
class RodMaterial:
    """Physical parameters of one strand (defaults: human hair, Daviet 2023 Sec. 5).

    Attributes:
        radius: mean cross-section radius R [m].
        ellipticity: flatness l in [0, 1); major/minor radii are (1+l)R and (1-l)R [-].
        density: volumetric mass rho [kg/m^3].
        youngs_modulus_bend: bending Young modulus E_b [Pa].
        youngs_modulus_stretch: stretching Young modulus E_s [Pa]; ``None`` means E_b.
        poisson_ratio: nu, sets the twisting stiffness (K_33 of Sec. 4.1) [-].
        damping_time: strain-rate damping relaxation time tau (Sec. 4.4 "Dynamic
            damping") [s]; 0 disables it.  Used in the dynamic mode only.
    """

    radius: float = 5.0e-5
    ellipticity: float = 0.0
    density: float = 1300.0
    youngs_modulus_bend: float = 3.0e9
    youngs_modulus_stretch: float | None = None
    poisson_ratio: float = 0.45
    damping_time: float = 0.0

    def __post_init__(self):
        if self.youngs_modulus_stretch is None:
            self.youngs_modulus_stretch = self.youngs_modulus_bend
        _check_positive("RodMaterial", "radius", self.radius)
        _check_positive("RodMaterial", "density", self.density)
        _check_positive("RodMaterial", "youngs_modulus_bend", self.youngs_modulus_bend)
        _check_positive("RodMaterial", "youngs_modulus_stretch", self.youngs_modulus_stretch)
        if not (math.isfinite(self.ellipticity) and 0.0 <= self.ellipticity < 1.0):
            raise ValueError(f"RodMaterial.ellipticity must lie in [0, 1), got {self.ellipticity!r}")
        if not (math.isfinite(self.poisson_ratio) and -1.0 < self.poisson_ratio <= 0.5):
            raise ValueError(f"RodMaterial.poisson_ratio must lie in (-1, 0.5], got {self.poisson_ratio!r}")
        if not (math.isfinite(self.damping_time) and self.damping_time >= 0.0):
            raise ValueError(f"RodMaterial.damping_time must be >= 0, got {self.damping_time!r}")

    # Cross-section quantities of Sec. 4.1.
    @property
    def area(self) -> float:
        """A = pi R^2 (1 - l^2) [m^2]."""
        return math.pi * self.radius**2 * (1.0 - self.ellipticity**2)

    @property
    def polar_inertia(self) -> float:
        """Polar second moment of area A R^2 (1 + l^2) / 2 [m^4].

        The paper prints I = A (1 + l^2)/2; the R^2 factor is needed for the
        units (and gives pi R^4 / 2 for a circle), so we include it.
        """
        return self.area * self.radius**2 * (1.0 + self.ellipticity**2) / 2.0

    def stiffness_matrix_diag(self) -> tuple[float, float, float]:
        """Diagonal of K (Sec. 4.1): A R^2/4 ((1-l)^2, (1+l)^2, (1+l^2)/(1+nu)) [m^4].

        Component a of the bending strain is the rotation-vector component along
        the material director d_a; d_3 is the tangent (twist).
        """
        l = self.ellipticity
        c = self.area * self.radius**2 / 4.0
        return (c * (1 - l) ** 2, c * (1 + l) ** 2, c * (1 + l * l) / (1 + self.poisson_ratio))


STRAIN_MEASURES = tuple(m.value for m in StrainMeasure)
MODES = tuple(m.value for m in Mode)
TRIDIAGONAL_METHODS = tuple(m.value for m in Tridiagonal)
DUAL_FRAMES = tuple(m.value for m in DualFrame)
SCHEDULES = tuple(m.value for m in Schedule)
TWIST_MODES = tuple(m.value for m in Twist)
INTEGRATORS = tuple(m.value for m in Integrator)


@dataclass
class ContactConfig:
    """Frictional contacts of :class:`SolverADMM` (Daviet 2023, Sec. 4.5).

    Attributes:
        hair_hair: detect and resolve hair-hair contacts (body colliders are
            always resolved when the solver has any).
        friction: hair-hair Coulomb coefficient mu [-].
        margin: proximity margin added to the contact distance r_a + r_b at
            detection [m].  Pairs within reach at the beginning of the step
            become contacts (inactive while apart: the Signorini condition
            only acts when the gap would close).
        velocity_margin: in the dynamic mode the reach of a pair of edges
            also grows by this factor times how much closer they can get in a
            step, dt (|v_a - v_b| + the edges' velocity spreads), and that of a
            vertex and a body by the factor times |v| dt + |g| dt^2 [-], so
            fast hair does not tunnel between detections (proximity detection
            runs once per step; hair moving together gets no extra margin).
        rigid_reach: hair-hair reaches (``velocity_margin``) take the vertex velocities relative to the
            hair's best-fit rigid motion (v0 + omega x (x - c), least squares over every vertex) instead of
            the world's: a rigid motion changes no distance, so the bound holds as well, and the edges'
            detection boxes no longer grow with the motion the whole groom shares (a turning head, the
            spinning hairball).  Off (default): the world velocities, as the paper.  Not a speed-up where
            it was measured (2026-12-04, A/B in one session, BENCHMARKS.md): ``head_turn.toml`` detection
            12.5 -> 11 ms per step, the same frame time; ``hairball --strands 1000 --frames 16`` detection
            256 -> 288 ms per step (the reach's cap at one edge scales every edge's velocity term down by the
            fastest edge's speed, and the fastest relative speed is lower, so the cap bites less), strain max
            0.045 -> 0.033 %, hair-pair max 206 -> 174 um.  Opt-in.
        max_contacts_per_edge: keep only the closest contacts of each edge
            (6 in the paper) [-].
        projection_iterations: Gauss-Seidel sweeps over the 8 batches per
            ADMM iteration (2 in the paper's hairball) [-].
        projection_contact_order: the z-step's sweeps, as ``correction_contact_order`` ("auto": one by one in the
            quasistatic mode on a CPU, the paper's 8 Jacobi batches otherwise); 2-core CPU, 2026-12-06: grooming 258 -> 111
            ms per step, the same figures; dynamic runs keep the batches (BENCHMARKS.md, "The z-step one by one") [-].
        correction_iterations: sweeps of the final geometric correction on x
            (10 in the paper's hairball; 0 disables it) [-].
        capacity_per_vertex: initial contact buffer size per vertex; grown
            (doubled, and the detection redone) when a step overflows it [-].
        pairs_per_edge: size of the hair-hair pair buffer per vertex, allocated
            once; a step that finds more pairs within reach searches in rounds,
            each edge resuming where the full buffer stopped it (the same
            lists; ``contact.pairs``) [-].
        pair_skin: Verlet skin of the hair-hair pairs [m] where the reach has no
            velocity part (quasistatic steps, or ``continuous_detections`` > 0): the
            pairs within reach + skin are kept between steps, and an edge searches
            again only once a vertex of it moved more than skin / 3 since its last
            search; the lists hold the pairs of a search every step, their
            distances to rounding (``contact.pairs.find_candidates_skin``).
            0: search every step.
        relinearize_correction: re-linearise the contacts at the current
            positions before the geometric correction (closest points and
            normals at x, kept on the begin-of-step side; body distance at x),
            so pairs that slid apart are not pulled back onto a stale plane
            (``contacts.relinearize_contacts``; the paper keeps the
            begin-of-step linearisation, which measured up to 75 % edge stretch
            on the hairball's impact) [-].
        correction_lengths: what the geometric correction does to edge lengths.
            ``"rest"`` (default): each of its sweeps projects the 8 contact
            batches, then every edge back to its rest length (two colours,
            mass-weighted position projections of an inextensibility
            constraint, Mueller et al. 2007), and edge passes end it; hair
            stretches by ~1e-6 under its own weight (E = 3 GPa), so the rest
            length is its length to that accuracy, and ADMM's own unconverged
            stretch goes too.  ``"before"``: the same, holding the lengths the
            edges had before the correction (keeps a real stretch of a soft
            material).  ``"free"``: the paper's correction, which moves the
            contact vertices alone.  Measured on the hairball (300 strands, 12
            frames, ``benchmarks/probes/contact_length.py``): at the end of a
            step of dense, fast contact 20-40 % of the hair pairs have crossed
            by 0.1-2 mm; pushing them back by their contact vertices alone
            stretched the edges beside them by up to 18 % [-].
        correction_edge_order: how each correction sweep passes over the edge lengths it holds.
            ``"colours"``: the edges of even, then odd local index, each set in parallel (a push travels
            one edge per sweep); ``"strands"``: root to tip and back along each strand, one strand per
            thread (a symmetric Gauss-Seidel pass: a push travels the whole strand in one sweep);
            ``"auto"`` (default): strands on a CPU, colours on a GPU (one thread per element), as the
            solver's schedule.  Measured on the CPU (2026-12-04, BENCHMARKS.md): the hairball's strain
            p99 / max 0.074 / 0.65 % -> 0.008 / 0.13 % (300 strands) and 0.014 / 0.17 % -> 0.000 / 0.05 %
            (1,000), hair-pair penetration about the same, the time per frame within this VM's noise
            (+-15 %; the correction itself +2 % and +19 % at 1,000 strands in two runs) [-].
        correction_contact_order: ``"batches"``: each correction sweep passes the projection's 8 batches (Jacobi
            within a batch); ``"sequential"``: every contact in index order on one thread, its push applied before
            the next is solved (Gauss-Seidel); ``"auto"`` (default): sequential on a CPU, batches on a GPU.  On the
            2-core CPU (2026-12-05, BENCHMARKS.md) the correction took 275 -> 150 ms per step on the 1,000-strand
            hairball and 47 -> 35 on the ponytail; not measured on more cores [-].
        correction_max_iterations: after its ``correction_iterations`` sweeps the correction goes on, 5
            sweeps at a time, while a contact is still deeper than ``correction_tolerance``, up to this
            many sweeps in all (equal to ``correction_iterations``: the paper's fixed count) [-].
        correction_tolerance: the deepest penetration the correction leaves without sweeping on [m];
            0 (default) means a quarter of the largest hair radius of the model (9 um for human hair).  A
            hair pair counts its crossing depth (``ContactPipeline.statistics``) [-].  With the radius itself
            and 40 sweeps (the defaults before 2026-12-02) hair-pair p99 penetration over 12 hairball frames
            was 25 / 25 / 37 um for seeds 1-3 at 300 strands and 44 um at 1,000 (r = 37 um: at and over one
            radius); with 10 um and 80 sweeps 3.3 / - / 5.5 um and 1.7 um, p99 strain 0.07 % (was 0.23-0.37 %),
            at 600-650 ms/frame for 300 strands (was 484-505) and the same 2.24 s/frame for 1,000 (the
            tolerance lets easy steps stop early); ``taichi-hair simulate hairball --strands N --seed S
            --frames 12``, load ~1.
        correction_relinearize_every: the correction re-linearises the contacts at the corrected
            positions (as ``relinearize_correction`` does at its start) and restarts from them every this
            many sweeps; 0 only at the start [-].  Deep pairs' closest points and normals move by more than
            their penetration while they are pushed apart: measured on the hairball (300 strands, the last
            substep of frame 10, ``benchmarks/probes/penetration.py``, no acceleration, frictionless, no
            splitting) the hair-pair penetration p99 after 80 sweeps was 63 um with 0, 34 um with 20, 29 um
            with 10 and 30 um with 5 (75 um for the correction before issue 12 item 1: no re-linearisation,
            batch splitting, friction); 10 is the default.
        correction_mass_splitting: the Delassus diagonal of the correction's contacts: ``"none"``
            (default: the plain diagonal D of Eq. 6, each contact gets its vertices' whole weights),
            ``"batch"`` or ``"vertex"`` (as ``mass_splitting``) [-].  Within a batch the Jacobi update may
            overshoot where a vertex carries several of its contacts, which the hairball's clumps of 17-20
            contacts per vertex did not show: "none" converged faster (p99 at 80 sweeps 29 um against 57 um
            for "batch", same probe) with strain p99 0.01 %.
        correction_hair_friction: whether the correction keeps Coulomb friction on hair-hair contacts [-].
            The ADMM iterations resolve friction (their z-step and lambda_z carry it); in the correction a
            sticking pair must also undo its relative slip since the beginning of the step, and in a clump
            those tangential constraints lock each other: with friction, p99 41 um after 80 sweeps against
            29 um without (same probe, no acceleration), and accelerated (rho 0.98, batch splitting) it
            stalled at 56 um after 160 sweeps against 1 um.  False (default) projects hair pairs onto
            non-penetration alone; body contacts keep their friction.
        correction_chebyshev_rho: Chebyshev semi-iterative acceleration of the correction's sweeps (Wang
            2015, as for position-based dynamics): after 3 plain sweeps from each (re)start,
            z <- omega_k (z_sweep - z_{k-1}) + z_{k-1}, omega_k from the spectral radius estimate rho; 0 turns
            it off, it must be < 1 [-].  Measured (same probe, 40 / 80 sweeps): p99 88 / 55 um without, 58 /
            24 with 0.9, 32 / 7 with 0.98, 20 / 3 with 0.99 (default), 27 / 3 with 0.995 (another run's
            frame 10 than above: the runs are chaotic); strain p99 at most 0.02 % after 40 sweeps in all.
        mass_splitting: how many virtual copies of a vertex the Delassus diagonal D_hat uses (Sec. 4.5 "Hybrid contact
            solve"): ``"vertex"`` splits each vertex among all its contacts n_i (the paper's D_hat); ``"batch"`` (default)
            among its contacts in the same batch only, since only those are updated together by the Jacobi step (batches
            follow one another Gauss-Seidel style).  The same fixed point; ``"batch"`` converges faster where vertices have
            many contacts (measured on the hairball, ``BENCHMARKS.md``).
        redetect_share: a quasistatic step keeps the last detection's contacts, measured again, while no vertex has
            moved more than this share of ``margin`` since, the bodies still (``contact.reuse``); 0 detects every step;
            under 0.5 (every pair within (1 - 2 share) margin is kept) [-].
        continuous_detections: continuous-time detections per step (Sec. 4.5: ACCD, the two earliest impacts per edge),
            run at regular intervals of the ADMM iterations (the paper's "CT" hairball uses 3) and once more before the
            final geometric correction; 0 uses proximity detection only [-].
        skip_when_apart: skip the hair-hair candidate search of a step in which no two strands come within reach and no
            strand can touch itself (exact: ``grid.strands_apart``); the statistics count the skipped steps [-].
        skip_slow_continuous: skip a continuous-detection pass when twice
            the largest displacement since the beginning of the step is
            within ``margin`` (pairs out of proximity reach cannot have met;
            the README, "Model no more than a scene needs") [-].
        late_body_contacts: before the end-of-step correction and at its restarts, give a body contact to
            every vertex within r + ``margin`` of a collider without one (issue 12; ``ContactPipeline.correct``).  The
            step's detection reaches as far as a vertex's own motion; in a dense pile the hair above
            pushes vertices into the body within one substep, and without a contact the correction
            cannot push them out.  Measured (hairball, 4,000 strands, frames 10-11, a scratch probe): every
            vertex found more than 0.5 mm inside the ball had no body contact in that step and had been
            2.7-9.8 mm outside at its beginning; with this on, none in frames 9-12.  The late contacts are
            frictionless (where the vertex first touched the body within the step is not known), so they are
            kept for what the step's detection cannot foresee: its reach includes the vertex's own motion
            and, since the comb's case below, the body's motion at the vertex.  (Before that a comb tooth
            swept 1 mm per step met vertices without a contact every step; frictionless late contacts then
            let a strand slip off the tooth, which is why this was off by default for a while.) [-].
        keep_rest_overlaps: a hair pair whose edges are closer at rest (x*, the groom as authored) than
            r_a + r_b gets that rest distance as its contact thickness, not r_a + r_b (``narrow.pair_thickness``):
            the pair keeps its authored separation instead of being pushed apart in the first steps, and
            the authored shape stays an equilibrium with contacts (a sag-free groom holds).  Strands of real
            grooms are authored this close: guides stand for wisps, and a ponytail's tail is packed tighter
            than two radii.  Measured on ``ponytail.toml`` (r = 110 um), head still, sag-free, 2 s
            (2026-12-05): p90 drift 1.32 mm, max 27 mm, not at rest, 792 ms/frame with the pushes (False;
            ~6,450 contacts at rest); 0.047 mm, max 0.64 mm, at rest, 269 ms/frame with this on.  The
            statistics count the contacts that hold a rest overlap (``rest_overlap_contacts``), and their
            penetration is measured past the reduced thickness.  False: the paper's r_a + r_b for every
            pair [-].
        weight_time: ``"hair-step"`` (default): in the dynamic mode, dt~ = min(dt, sqrt(L~/|g|)) on a vertex
            whose contacts are all hair-hair (W_z of the order of the inertia m/dt^2, Daviet 2020's scaling)
            and the paper's dt~ = min(dt, sqrt(L~/|g|), bending time) on a vertex with a body contact; the
            quasistatic mode, which has no dt, takes the paper's everywhere.  ``"paper"``: the paper's on
            every vertex.  ``"step"``: the inertia's on every vertex (dynamic mode).  Measured 2026-12-05
            (BENCHMARKS.md, issue 14, "The head turn's return"): in the head turn (sag-free wavy groom,
            hair-hair and head contacts, mid-turn) 10 iterations leave 4.5 % of a substep's displacement with
            the inertia's weight against 12 % with the paper's (``benchmarks/probes/head_turn_convergence.py``):
            with the paper's, hair slides slowly, a numerical stiction.  After a 40 degree turn the wavy
            groom ends 8.6 mm p90 from its authored shape with "paper", 1.39 mm with "hair-step", 1.00 mm
            with "step", and 1.28 mm with "paper" at 40 iterations (nearer convergence: 5.5 % of a step left).  But where a
            contact must bend a strand against its stiffness the lighter weight converges too slowly: a
            strand threaded through a 2 cm sphere's centre keeps 4 vertices 2.6-18 mm inside after 2 s with
            "step" (none with "paper" or "hair-step", ``tests/test_contacts.py``), hence the paper's weight
            on body contacts.  The hairball (300 strands, 12 frames) keeps its quality with "hair-step":
            strain p99 0.003 % (0.008 % with "paper"), hair-pair penetration p99 5.5 um either way, 0 crossed
            pairs (4).

    Collision weights W_z = m / dt~^2 (``weight_time``).  The paper's
    dt~ = min(dt, sqrt(L~/|g|), 2 L~^2/R sqrt(rho/E_b)) takes the bending time of one
    edge, which for thin hair is far below dt (2 mm edges, R = 0.05 mm:
    W_z ~ 1700 m/dt^2 at dt = 1/240 s; 7.5 mm edges at dt = 1/96 s: ~50 m/dt^2), and
    ADMM then needs many iterations to let hair *slide* along a collider or another
    strand: measured on an incline, 20 iterations give ~1 % of the Coulomb sliding
    distance with 2 mm edges and 0.1 % error with 1 cm edges (``tests/test_contacts.py``,
    paper weights).
    """

    hair_hair: bool = True
    friction: float = 0.2
    margin: float = 1.0e-4
    velocity_margin: float = 1.0
    max_contacts_per_edge: int = 6
    projection_iterations: int = 2
    correction_iterations: int = 10
    capacity_per_vertex: float = 3.0
    pairs_per_edge: float = 8.0
    pair_skin: float = 0.0
    continuous_detections: int = 0
    mass_splitting: MassSplitting = MassSplitting.BATCH
    relinearize_correction: bool = True
    correction_lengths: CorrectionLengths = CorrectionLengths.REST
    correction_edge_order: CorrectionEdgeOrder = CorrectionEdgeOrder.AUTO
    correction_contact_order: CorrectionContactOrder = CorrectionContactOrder.AUTO
    projection_contact_order: CorrectionContactOrder = CorrectionContactOrder.AUTO
    correction_max_iterations: int = 80
    correction_tolerance: float = 0.0
    correction_relinearize_every: int = 10
    correction_mass_splitting: MassSplitting = MassSplitting.NONE
    correction_hair_friction: bool = False
    correction_chebyshev_rho: float = 0.99
    skip_when_apart: bool = True
    skip_slow_continuous: bool = True
    late_body_contacts: bool = True
    rigid_reach: bool = False
    keep_rest_overlaps: bool = True
    weight_time: WeightTime = WeightTime.HAIR_STEP
    redetect_share: float = 0.25

    def __post_init__(self):
        if not (math.isfinite(self.friction) and self.friction >= 0):
            raise ValueError(f"ContactConfig.friction must be a finite number >= 0, got {self.friction!r}")
        if not (isinstance(self.correction_chebyshev_rho, (int, float)) and 0 <= self.correction_chebyshev_rho < 1):
            raise ValueError("ContactConfig.correction_chebyshev_rho must be a number in [0, 1), got "
                             f"{self.correction_chebyshev_rho!r}")
        for name in ("margin", "velocity_margin", "correction_tolerance", "pair_skin", "redetect_share"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ValueError(f"ContactConfig.{name} must be a finite number >= 0, got {v!r}")
        if self.redetect_share >= 0.5:
            raise ValueError(f"ContactConfig.redetect_share must be < 0.5, got {self.redetect_share!r}")
        for name, lo in (("max_contacts_per_edge", 1), ("projection_iterations", 1), ("correction_iterations", 0),
                        ("continuous_detections", 0), ("correction_relinearize_every", 0)):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= lo):
                raise ValueError(f"ContactConfig.{name} must be an integer >= {lo}, got {v!r}")
        if not (isinstance(self.correction_max_iterations, int) and self.correction_max_iterations >= 0):
            raise ValueError("ContactConfig.correction_max_iterations must be an integer >= 0, got "
                             f"{self.correction_max_iterations!r}")
        for name, kind in (("correction_lengths", CorrectionLengths), ("correction_edge_order", CorrectionEdgeOrder),
                           ("correction_contact_order", CorrectionContactOrder), ("weight_time", WeightTime),
                           ("projection_contact_order", CorrectionContactOrder),
                           ("correction_mass_splitting", MassSplitting)):
            setattr(self, name, as_choice(kind, "ContactConfig", name, getattr(self, name)))
        if not isinstance(self.correction_hair_friction, bool):
            raise ValueError("ContactConfig.correction_hair_friction must be a bool, got "
                             f"{self.correction_hair_friction!r}")
        if self.mass_splitting not in (MassSplitting.BATCH, MassSplitting.VERTEX):
            raise ValueError(f"ContactConfig.mass_splitting must be 'batch' or 'vertex', got {self.mass_splitting!r}")
        self.mass_splitting = MassSplitting(self.mass_splitting)
        if not (math.isfinite(self.capacity_per_vertex) and self.capacity_per_vertex > 0):
            raise ValueError(f"ContactConfig.capacity_per_vertex must be > 0, got {self.capacity_per_vertex!r}")
        if not (math.isfinite(self.pairs_per_edge) and 0 < self.pairs_per_edge <= 1000):
            raise ValueError(f"ContactConfig.pairs_per_edge must be in (0, 1000], got {self.pairs_per_edge!r}")


@dataclass
class SolverADMMConfig:
    """Settings of :class:`taichi_hair.SolverADMM` (Daviet 2023, Sec. 4).

    Attributes:
        iterations: ADMM iterations per step (Algorithm 1's loop) [-].  Measured in the head-turn scene
            (sag-free wavy groom, mid-turn; ``benchmarks/probes/head_turn_convergence.py``): 10 iterations
            leave 0.5 % of a substep's displacement without contacts but 12 % with hair-hair and head
            contacts (40: 5.5 %, 160: 0.3 %), and the less converged groom swings further and settles
            with more strands reordered (BENCHMARKS.md, issue 14).
        mode: ``"dynamic"`` (implicit time integration, Sec. 4.2; see
            ``integrator``) or ``"quasistatic"`` (inertia and drag dropped;
            each call to ``step`` runs more iterations of the same minimisation).
        integrator: time discretisation of the dynamic mode [-]:
            ``"backward_euler"`` (the paper's, first order; its numerical
            damping takes most of a slow swing's energy at dt = 1/96 s,
            BENCHMARKS.md) or ``"bdf2"`` (second-order backward
            differentiation, v_{n+1} = (3 x_{n+1} - 4 x_n + x_{n-1}) / (2 dt):
            the same ADMM step with the inertia term M (x - x_pred) / h^2,
            h = 2 dt / 3; see :class:`taichi_hair.SolverADMM`).  BDF2 falls
            back to backward Euler on a step without history: the first
            step, after ``reset_duals``/``reset_history`` (teleport, state
            load), after a failed step, or when dt changes.  Ignored in the
            quasistatic mode.
        strain_measure: ``"korner"`` (Korner et al. 2021: bending from the
            rotation between adjacent material frames, 2 sin(phi/2);
            hyperelastic stretch) or ``"bergou"`` (Bergou et al. 2008:
            curvature binormal, 2 tan(phi/2); linear stretch).
        w0: scale of the elasticity constraint weights
            W_y = w0 E_b A R^2 / (4 v^3) (Sec. 4.4) [-].  Default 1; the
            paper's value is 25 (``w0=25.0``).  Chosen by measurement
            (BENCHMARKS.md, issue 12, "Weights" and "Anderson acceleration"):
            with Anderson acceleration (the default on straight rods) the stability atlas (dt
            1/24-1/384 s x 2-50 iterations x 4 rods) has 23 of 36 cells stable
            and accurate at w0 = 1 (w0 = 2: 20 of the 24 cells with 10-50
            iterations, w0 = 5: 16 of 24); plain, 18 at w0 = 1 and 5 at w0 = 25.
            Rods clamped horizontally with drag 8/s end 2 s within
            0.015-0.19 % of L with Anderson (plain: 0.08-6.6 %; w0 = 25:
            5-48 %; ``benchmarks/probes/admm_convergence.py settle``,
            ``weight_scale.py``); the hang scene with the same drag within
            1.8e-4 L (``benchmarks/probes/hang_settle.py``).  Too large a W_y
            makes each iteration move x only a little towards its minimum (W_y
            is ~1e5 times the inertia m/dt^2 on 2.5 mm edges at w0 = 25), so 10
            iterations stop far from the backward-Euler step (w0 = 25 never
            does).  No weight rule alone converges in 10 iterations (module
            docstring of :mod:`taichi_hair.anderson`).  The cost: with 2
            iterations at dt = 1/384 s the long and uneven-edge rods gain energy;
            weights scaled by the inertia instead diverge (measured).  With
            contacts the end-of-step correction holds the edge lengths
            (``ContactConfig.correction_lengths``), which the lower W_y would
            otherwise let stretch.
        inertia_floor: in the dynamic mode W_y,i is at least this times the
            inertia m_i / dt^2 (m_i / h^2 with BDF2); 0 keeps the w0 weight
            alone, as the paper [-].  Where dt resolves the bending motion the
            w0 weight falls below the inertia (W_y / (m/dt^2) = w0 (omega dt)^2
            for a one-mode oscillator), and then 10-20 iterations of the
            unconverged ADMM step gained energy: measured on a 3-vertex
            oscillator at omega dt = 0.2 with w0 = 1, an energy factor of 1.29 per
            step against backward Euler's 0.96; with the floor, 0.963.  On hair
            at dt = 1/96 s the w0 weight is thousands of times the inertia and
            the floor does nothing.
        voronoi_rescaling: use v_1* = e_0 + e_1/2 and its tip mirror for the
            bending Voronoi lengths of the second and penultimate vertices
            (Sec. 5.1 "Cantilever").
        dual_frame: frame Q in which the elasticity duals lambda_y are stored
            (Sec. 4.4 "Local frame"): ``"root"`` the root attachment frame of
            each strand (the paper's choice: warm-started duals follow a
            rotating head), ``"pair"`` the current material frame of each
            pair's second edge (the per-vertex frame the paper tried; the duals
            then follow every edge's rotation), or ``"none"`` (world).
        warm_start_duals: keep lambda_y from one step to the next.  The paper
            is silent; without it, ``local_frame_rotation`` would have no effect.
        air_viscosity: linear drag coefficient xi, force per unit length
            xi (v_air - v) [Pa s].  Dynamic mode only.
        tridiagonal: ``"thomas"`` (per-strand sequential, best on CPU),
            ``"pcr"`` (parallel cyclic reduction; strand blocks in shared
            memory on CUDA), or ``"auto"`` (Thomas on CPU, PCR on GPU).
            The strand schedule always uses Thomas: ``"pcr"`` with
            ``schedule="strand"`` is an error.
        schedule: how the ADMM iterations of a step are launched (same
            results; see :mod:`taichi_hair.schedule_strand`): ``"stage"``
            runs each stage as a kernel parallel over all vertices (about nine
            launches per iteration; suits GPUs), ``"strand"`` runs all
            iterations in one kernel parallel over strands, each strand's
            stages serially (suits CPUs; bit-identical to ``"stage"`` on CPU),
            ``"lanes"`` (CPU, Korner) the strand schedule on lanes of eight strands (:mod:`taichi_hair.lanes`);
            ``"auto"``: ``"stage"`` on GPU archs and with ``tridiagonal="pcr"``, on a CPU ``"lanes"`` for Models of
            50,000 vertices or more (``lanes.auto_schedule``), ``"strand"`` below.
        check_finite: after each step, check every state value for NaN/inf
            and raise :class:`SimulationDivergedError` naming the strand.
        contacts: :class:`ContactConfig` to enable frictional contacts
            (Sec. 4.5), or ``None`` (no hair-hair contacts; body colliders
            given to the solver still use the default ContactConfig).
        twist: ``"auto"`` drops the twist unknowns (steps 4f-g of
            Algorithm 1) when every strand is naturally straight, of round
            section and free to untwist, where the twist-free frame is their
            exact value (``frames.twist_choice``; the solver's
            ``model_choices`` says which it did and why); ``"solve"`` always
            solves them, as the paper does.
        anderson_window: Anderson acceleration of the iterations (:mod:`taichi_hair.anderson`): the
            number of past iterates each strand extrapolates from [-]; 0 is the paper's plain iteration.
            Default None (auto): 5 in the dynamic mode with backward Euler on rods whose twist is
            dropped (naturally straight, ``twist`` "auto"), the plain iteration in the quasistatic mode,
            with BDF2 and where the twist is solved (curved rods), each for a measured reason
            (``anderson.anderson_auto_window``; ``model_choices["acceleration"]`` says which ran and why).
            It mixes only with at least ``taichi_hair.anderson.ANDERSON_MIN_ITERATIONS`` (10) iterations
            per step and no contacts (``contacts`` or colliders).  Measured (BENCHMARKS.md, issue 12):
            the atlas' rods settle in 2 s to 0.015-0.19 % of L (plain 0.08-6.6 %); atlas cells with
            10-50 iterations stable and accurate 21 of 24 (plain 16); the Pareto cantilever at 10
            iterations 0.24 % against 1.9 %.  On the bend-twist validation (curved rods, twist solved)
            a forced window converged to a different motion than the plain iteration, whose 50 and 200
            iterations per step agree (max speed after 100 steps 4.82 / 4.82 m/s plain, 1.20 / 0.73 m/s
            with window 5): hence plain there.  Cost ~3-25 % per iteration.
    """

    iterations: int = 10
    mode: Mode = Mode.DYNAMIC
    strain_measure: StrainMeasure = StrainMeasure.KORNER
    w0: float = 1.0
    inertia_floor: float = 1.0
    voronoi_rescaling: bool = True
    dual_frame: DualFrame = DualFrame.ROOT
    warm_start_duals: bool = True
    air_viscosity: float = 0.0
    tridiagonal: Tridiagonal = Tridiagonal.AUTO
    schedule: Schedule = Schedule.AUTO
    check_finite: bool = True
    contacts: ContactConfig | None = None
    twist: Twist = Twist.AUTO
    integrator: Integrator = Integrator.BACKWARD_EULER
    anderson_window: int | None = None

    def __post_init__(self):
        owner = "SolverADMMConfig"
        self.integrator = as_choice(Integrator, owner, "integrator", self.integrator)
        self.twist = as_choice(Twist, owner, "twist", self.twist)
        if isinstance(self.contacts, dict):
            self.contacts = ContactConfig(**self.contacts)
        if self.contacts is not None and not isinstance(self.contacts, ContactConfig):
            raise ValueError(f"SolverADMMConfig.contacts must be a ContactConfig or None, got {self.contacts!r}")
        if not (isinstance(self.iterations, int) and self.iterations >= 1):
            raise ValueError(f"SolverADMMConfig.iterations must be an integer >= 1, got {self.iterations!r}")
        self.mode = as_choice(Mode, owner, "mode", self.mode)
        self.strain_measure = as_choice(StrainMeasure, owner, "strain_measure", self.strain_measure)
        self.tridiagonal = as_choice(Tridiagonal, owner, "tridiagonal", self.tridiagonal)
        self.schedule = as_choice(Schedule, owner, "schedule", self.schedule)
        if self.schedule in ("strand", "lanes") and self.tridiagonal == "pcr":
            raise ValueError(f"SolverADMMConfig.tridiagonal='pcr' cannot be used with SolverADMMConfig.schedule="
                             f"'{self.schedule}' (it solves each strand with Thomas); use schedule='stage' or 'auto'")
        self.dual_frame = as_choice(DualFrame, owner, "dual_frame", self.dual_frame)
        _check_positive("SolverADMMConfig", "w0", self.w0)
        if self.anderson_window is not None and not (
                isinstance(self.anderson_window, int) and not isinstance(self.anderson_window, bool)
                and 0 <= self.anderson_window <= 16):
            raise ValueError(f"SolverADMMConfig.anderson_window must be None (auto) or an integer in 0..16, "
                             f"got {self.anderson_window!r}")
        if not (isinstance(self.inertia_floor, (int, float)) and math.isfinite(self.inertia_floor)
                and self.inertia_floor >= 0):
            raise ValueError(f"SolverADMMConfig.inertia_floor must be a finite number >= 0, got {self.inertia_floor!r}")
        if not (math.isfinite(self.air_viscosity) and self.air_viscosity >= 0):
            raise ValueError(f"SolverADMMConfig.air_viscosity must be >= 0, got {self.air_viscosity!r}")
