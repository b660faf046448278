"""Settings and argument checks of a grooming session (Daviet 2023, Sec. 5.3).

:class:`GroomingConfig` (the session's parameters, validated; errors name the field), the action
and parameter names of :class:`~taichi_hair.groom.session.GroomingSession`, the comb's body, and the
checks of the actions' arguments (3-vectors, positive numbers, paths), which raise ``ValueError``
naming the argument.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace

import numpy as np

MODES = ("replace", "add", "remove")
#: Actions that change the groom or the simulation set-up: each pushes an undo snapshot.
EDIT_ACTIONS = ("drag", "release", "comb", "trim", "scale_length", "scale_curl", "pin", "unpin", "set_parameter")
#: Every action a session log may hold (each is a method of :class:`GroomingSession`).
ACTIONS = ("select", "select_ray", "select_strands", "select_all", "simulate", "advance", "undo", "redo") \
    + EDIT_ACTIONS
#: Parameters whose change updates the Model and solver coefficients (the others apply to the running solver).
REBUILD_PARAMETERS = ("youngs_modulus", "radius", "density", "guide_ratio", "neighbour_count", "seed", "contacts",
                      "contact_margin", "w0", "rest_pose", "rest_max_change")
#: Of those, the ones that change the simulated layout (which strands are guides, the skinning
#: slots, the contact pipeline): a new Model and solver are built and Taichi recompiles the kernels.
#: The others update the Model in place (:meth:`Model.update`, no recompilation).
LAYOUT_PARAMETERS = ("guide_ratio", "neighbour_count", "seed", "contacts", "contact_margin")
#: Body of the comb in the guides' Model and Control (body 0 is the head, the identity).
COMB_BODY = 1
#: Most quasistatic steps one comb stroke may take (a longer path needs a larger ``step``).
COMB_MAX_STEPS = 2000


# =========================================================================== configuration
def _finite(v) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool) and math.isfinite(v)


@dataclass
class GroomingConfig:
    """Parameters of a :class:`GroomingSession` (validated; errors name the field).

    Attributes:
        youngs_modulus: Young modulus E of the hair, bending and stretching [Pa].
        radius: strand radius R [m] (every strand; the groom's own radius attribute is kept, not simulated).
        density: volumetric mass rho [kg/m^3].
        friction: hair-hair Coulomb coefficient mu [-] (colliders keep their own ``friction``).
        gravity: external acceleration g, 3 components [m/s^2].
        iterations: ADMM iterations per frame [-] (10 in the paper).
        guide_ratio: fraction of the strands simulated, in (0, 1] [-] (10 % in the paper); the
            others follow their guides by linear blend skinning.
        neighbour_count: guides each skinned strand follows [-].
        seed: seed of the guide selection [-].
        contacts: hair-hair proximity contacts on or off.
        contact_margin: proximity margin of the contact detection [m].
        contact_sweeps: Gauss-Seidel sweeps over the contacts in each ADMM iteration's z-step
            (``ContactConfig.projection_iterations``, 2 in the paper's hairball) [-].  The grooming tool is quasistatic
            and shows each frame's unconverged iterate (the paper, Sec. 5.3), so 1: measured 2026-12-07 on the grooming
            benchmark's groom, 293 and 297 against 348 and 343 ms per still step (simulation and skinning; ``benchmarks/probes/
            groom_config_ab.py``, alternating blocks in one process) and 0.83 of the frame time in two pairs of
            ``bench_groom.py`` runs, with the same drift (p90 0.015-0.016 mm), strain (max 1e-6) and drag (a 30 mm
            drag moved its vertices 20.2-20.6 mm) (BENCHMARKS.md, "Fewer contact sweeps for grooming").
        correction_sweeps: sweeps of the end-of-step correction before it first checks the depth
            (``ContactConfig.correction_iterations``; it goes on, 5 sweeps at a time, while a hair pair is deeper than
            the tolerance) [-].  10, the paper's: 5 saved time on a settled groom but, in the frames after a build,
            failed its first check and took 15 where 10 sufficed (same section).
        w0: scale of the ADMM elasticity weights [-] (SolverADMMConfig.w0).  Measured on 12
            strands x 10 vertices, 10 cm, 10 iterations per frame: 1 settles the sag to 3 % in 10
            frames and holds a strand dragged by its tip still; 0.2 settles faster but a strand
            with both ends kinematic keeps oscillating (centimetres) from frame to frame; 5 and
            the dynamic default 25 creep (the sag is half done after 20 frames at 5).
        rest_pose: ``"authored"`` (the groom's rest shape is its rest state: it sags under gravity) or
            ``"sag-free"`` (rest strains solved so that the rest shape is an equilibrium under gravity,
            :mod:`taichi_hair.solvers.rest_pose`; re-solved after every edit of the rest shape).
        rest_max_change: with ``rest_pose = "sag-free"``, the largest change of a pair's rest strain from its
            authored strain for a guide to count as held (``RestPoseConfig.max_rest_change``; a guide not held
            keeps its authored rest pose and sags) [-].  1.9 here (the grooming tool is where the authored shape
            is the point), 1.0 (about 60 degrees per vertex) in ``RestPoseConfig`` and scene files.  Measured
            at the paper's resolution (8,600 wavy guides x 14 vertices on ``assets/head.obj``, 19 mm edges):
            1.0 holds 5,976 guides, 568 of them flagged unstable by ``check_stability``; 1.9 holds 8,236, 773
            flagged (the same 9 %); the guides not held sag onto their neighbours, and the quasistatic steps
            and the correction then fight over their near-root vertices every frame: 1,458 against 978 ms per
            frame (BENCHMARKS.md, "Why the groom never comes to rest").
        unheld_shape_weight: with ``rest_pose = "sag-free"``, the guides the rest pose does not hold (``rest_max_change``)
            are held to their authored shape by zero-length springs on their free vertices, Han & Harada 2012's global
            shape constraint (the TressFX solver's, :mod:`taichi_hair.solvers.shape`), each of this many times the weight
            of a contact on the vertex (k = w m / dt~^2, as the drag's springs); 0 lets them sag [-].  A dragged vertex
            follows the drag's spring instead.  Measured on the grooming benchmark's groom (8,600 wavy guides, 364 not
            held at ``rest_max_change`` 1.9; BENCHMARKS.md, "Guides the rest pose cannot hold"): at 0 those guides sag
            ~5 mm (p90) onto their neighbours and the quasistatic steps and the end-of-step correction fight over them
            every frame, the correction at its 80-sweep cap; at 10 they stay within 0.12 mm (p90) of their authored
            shape, the groom comes to rest and the correction stops after 15 sweeps: 1,003 against 496 ms of simulation
            per frame (``bench_groom.py --rest-pose sag-free --unheld-shape-weight 0|10``, commit 1de4086).
        schedule: launch schedule of the guides' ADMM iterations, ``"auto"`` (``lanes.auto_schedule``: on a CPU lanes
            from 50,000 guide vertices, strand below; stage on a GPU),
            ``"stage"``, ``"strand"`` or ``"lanes"`` (SolverADMMConfig.schedule: the same results, to rounding for
            ``"lanes"``; other speed).
        autosave_every: write the autosave files every this many edits; 0 disables [-].
        undo_limit: most undo snapshots kept [-].
        undo_memory_mb: most memory the undo snapshots below the newest one may hold [MiB]; the oldest beyond it are
            dropped (the newest snapshot, a whole groom, is always kept).  0: no limit.  Each snapshot holds the rows
            its edit changed, and the whole current pose when the simulation moved it since the snapshot before
            (86,000 strands at float64: ~8 MB per edit without simulation, ~32-37 MB with a frame between edits;
            ``benchmarks/probes/groom_edit_memory.py``), so the default keeps ~30 live edits of such a groom.
    """

    youngs_modulus: float = 3.0e9
    radius: float = 5.0e-5
    density: float = 1300.0
    friction: float = 0.2
    gravity: tuple = (0.0, -9.81, 0.0)
    iterations: int = 10
    guide_ratio: float = 0.1
    neighbour_count: int = 4
    seed: int = 0
    contacts: bool = True
    contact_margin: float = 1.0e-4
    contact_sweeps: int = 1
    correction_sweeps: int = 10
    w0: float = 1.0
    rest_pose: str = "authored"
    rest_max_change: float = 1.9
    unheld_shape_weight: float = 10.0
    schedule: str = "auto"
    autosave_every: int = 1
    undo_limit: int = 100
    undo_memory_mb: float = 1024.0

    def __post_init__(self):
        for name in ("youngs_modulus", "radius", "density", "w0", "rest_max_change"):
            v = getattr(self, name)
            if not (_finite(v) and v > 0):
                raise ValueError(f"GroomingConfig.{name} must be a finite positive number, got {v!r}")
            setattr(self, name, float(v))
        for name in ("friction", "contact_margin", "unheld_shape_weight", "undo_memory_mb"):
            v = getattr(self, name)
            if not (_finite(v) and v >= 0):
                raise ValueError(f"GroomingConfig.{name} must be a finite number >= 0, got {v!r}")
            setattr(self, name, float(v))
        try:
            g = tuple(float(c) for c in self.gravity)
        except (TypeError, ValueError):
            g = ()
        if len(g) != 3 or not all(math.isfinite(c) for c in g):
            raise ValueError(f"GroomingConfig.gravity must be 3 finite numbers [m/s^2], got {self.gravity!r}")
        self.gravity = g
        for name, lo in (("iterations", 1), ("contact_sweeps", 1), ("correction_sweeps", 1), ("neighbour_count", 1),
                         ("autosave_every", 0), ("undo_limit", 0), ("seed", 0)):
            v = getattr(self, name)
            if not (isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= lo):
                raise ValueError(f"GroomingConfig.{name} must be an integer >= {lo}, got {v!r}")
            setattr(self, name, int(v))
        if not (_finite(self.guide_ratio) and 0.0 < self.guide_ratio <= 1.0):
            raise ValueError(f"GroomingConfig.guide_ratio must lie in (0, 1], got {self.guide_ratio!r}")
        self.guide_ratio = float(self.guide_ratio)
        if not isinstance(self.contacts, (bool, np.bool_)):
            raise ValueError(f"GroomingConfig.contacts must be true or false, got {self.contacts!r}")
        self.contacts = bool(self.contacts)
        if self.schedule not in ("auto", "stage", "strand", "lanes"):
            raise ValueError(f"GroomingConfig.schedule must be 'auto', 'stage', 'strand' or 'lanes', got {self.schedule!r}")
        if self.rest_pose not in ("authored", "sag-free"):
            raise ValueError(f"GroomingConfig.rest_pose must be 'authored' or 'sag-free', got {self.rest_pose!r}")

    def to_dict(self) -> dict:
        """JSON-able dict of the fields (gravity as a list)."""
        d = asdict(self)
        d["gravity"] = list(self.gravity)
        return d


# =========================================================================== argument checks
def _vec3(name: str, value) -> np.ndarray:
    try:
        a = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        a = np.zeros(0)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"'{name}' must be 3 finite numbers, got {value!r}")
    return a


def _direction(name: str, value) -> tuple[np.ndarray, np.ndarray]:
    """``(vector, unit vector)`` of 3 finite numbers, not all zero."""
    v = _vec3(name, value)
    n = np.linalg.norm(v)
    if n == 0:
        raise ValueError(f"'{name}' must be a non-zero vector")
    return v, v / n


def _positive(name: str, value, allow_zero: bool = False) -> float:
    if not _finite(value) or value < 0 or (value == 0 and not allow_zero):
        raise ValueError(f"'{name}' must be a finite {'non-negative' if allow_zero else 'positive'} number, "
                         f"got {value!r}")
    return float(value)


def _path(name: str, value) -> np.ndarray:
    """A polyline of at least 2 finite points (x, y, z) [m], float64 (m, 3)."""
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        a = np.zeros((0, 0))
    if a.ndim != 2 or a.shape[1] != 3 or a.shape[0] < 2:
        text = repr(value)
        raise ValueError(f"'{name}' must be a list of at least 2 points [x, y, z] [m], got "
                         f"{text if len(text) <= 80 else text[:77] + '...'}")
    bad = np.nonzero(~np.all(np.isfinite(a), axis=1))[0]
    if bad.size:
        raise ValueError(f"'{name}' has a non-finite coordinate at point {int(bad[0])}: {a[bad[0]].tolist()}")
    return a


# =========================================================================== the session's inputs
def session_groom(groom):
    """The groom a session edits: a copy of ``groom`` (a :class:`taichi_hair.io.Groom`, or a list
    of (m, 3) polylines [m]) with a rest pose (``points`` if it has none) and pins (none), without
    ``point_frames`` (an animation cache).  Raises for a strand of fewer than 3 vertices."""
    from ..io import Groom

    if not isinstance(groom, Groom):
        groom = Groom.from_polylines([np.asarray(p, dtype=np.float64) for p in groom], units="m")
    g = groom.copy().validate()
    g.point_frames = None
    g.frame_times = None
    if g.rest_points is None:
        g.rest_points = g.points.copy()
    if g.pinned is None:
        g.pinned = np.zeros(g.vertex_count, dtype=bool)
    counts = g.strand_vertex_counts()
    short = np.nonzero(counts < 3)[0]
    if short.size:
        raise ValueError(f"GroomingSession: strand {int(short[0])} has {int(counts[short[0]])} vertices; "
                         "a simulated strand needs at least 3")
    return g


def session_config(groom, config: GroomingConfig | None) -> GroomingConfig:
    """``config`` checked, or the groom's ``params["grooming"]`` (as a session saves it), or the defaults."""
    if config is None:
        stored = groom.params.get("grooming")
        try:
            config = GroomingConfig(**stored) if isinstance(stored, dict) else GroomingConfig()
        except TypeError as exc:
            raise ValueError(f"GroomingSession: params['grooming'] of the groom: {exc}") from None
    elif not isinstance(config, GroomingConfig):
        raise ValueError(f"GroomingSession: config must be a GroomingConfig, got {type(config).__name__}")
    return config


def session_colliders(colliders) -> list:
    """The scene colliders as a list, checked to be on the static world (-1) or the head (0)."""
    out = list(colliders) if colliders else []
    for k, c in enumerate(out):
        if getattr(c, "body", -1) not in (-1, 0):
            raise ValueError(f"GroomingSession: collider {k} is on body {c.body}; a grooming session has the "
                             f"static world (-1) and the head (0) only (body {COMB_BODY} is the comb's)")
    return out


def with_parameter(config: GroomingConfig, name, value) -> GroomingConfig:
    """A copy of ``config`` with the field ``name`` set to ``value`` (validated; errors name the field)."""
    names = [f.name for f in fields(GroomingConfig)]
    if name not in names:
        raise ValueError(f"set_parameter: unknown parameter {name!r}; known: {', '.join(names)}")
    return replace(config, **{name: value})  # __post_init__ validates
