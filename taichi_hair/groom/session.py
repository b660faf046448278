"""Physics-based grooming without a window (Daviet 2023, Sec. 5.3).

A :class:`GroomingSession` holds a groom (:class:`taichi_hair.io.Groom`: the
current pose ``points`` and the rest pose ``rest_points``) inside a running
*quasistatic* simulation: each :meth:`~GroomingSession.advance` frame runs a
few ADMM iterations (``GroomingConfig.iterations``, 10 in the paper) of
:class:`SolverADMM` in ``mode="quasistatic"`` with proximity-only contacts
(``velocity_margin=0``), so the groom settles under gravity, elasticity and
contacts while it is edited.  As in the paper only a fraction of the strands
(``guide_ratio``) is simulated; the others follow by linear blend skinning
(:mod:`taichi_hair.groom.skinning`).

Editing actions are methods, each logged with its parameters (``session.log``,
written by :meth:`~GroomingSession.write_log` as ``session.json`` and replayed
by :meth:`~GroomingSession.replay`):

* selection: :meth:`select` (a sphere), :meth:`select_ray` (a screen ray: a
  cylinder of the given radius around a half-line), :meth:`select_strands`,
  :meth:`select_all`.  An edge within the radius selects both its vertices;
  a strand is selected when any of its vertices is.  ``mode`` is "replace",
  "add" or "remove".
* :meth:`drag` -- direct manipulation.  The solver has no per-vertex external
  force, so a drag makes the grabbed vertices *kinematic* (``vertex_is_fixed``
  of the Model, the mechanism that clamps roots) and, every frame before the
  step, moves their prescribed position a fraction ``stiffness`` of the way to
  the moving target (anchor + ``target_offset``): an overdamped spring seen
  frame by frame, with time constant -1/ln(1 - stiffness) frames.  The rest of
  each strand follows through elasticity and contacts.  :meth:`release` ends it.
* :meth:`comb` sweeps a comb through the hair: a capsule "tooth" of the given radius
  (a sphere brush when its length is 0), a frictional body collider of the ADMM
  contact pipeline (Sec. 4.5) on its own body (``COMB_BODY``), moved along a path
  of points, one quasistatic step (``config.iterations`` ADMM iterations) per
  ``step`` [m] of path.  Hair is pushed by the contacts and dragged by Coulomb
  friction, never moved directly.  The strands the comb touched then keep the
  combed shape as their rest pose (see :meth:`comb`).
* :meth:`trim` cuts the strands whose *current* polyline crosses a plane (the
  cut seen on screen); the same rest arc length cuts the rest pose.
* :meth:`scale_length` shortens (cut at the scaled rest arc length) or grows
  selected strands from the tip; growth continues the tip's discrete
  curvature and torsion (the screw motion taking the last-but-one edge pair to
  the last one), at the last rest edge length.
* Both keep every strand's vertex count: the edited strand is *resampled*
  along its new length (vertex i at the same arc fraction as before, linear
  between the old vertices, so edges get shorter or longer by the length
  ratio).  The layout of the simulation then never changes, and the Model is
  updated in place instead of rebuilt.  The price: a strong growth coarsens the
  strand (curls finer than the new edge spacing are smoothed), a strong trim
  makes short edges (slower ADMM convergence, Sec. 6.1).
* :meth:`scale_curl` multiplies the rest turning angle of every edge pair of
  the selected strands (the Bishop-frame curvature), keeping edge lengths and
  the root edge; 0 straightens.  The edited strands' current pose becomes the
  new rest pose and settles again when simulated.
* :meth:`pin` / :meth:`unpin` make the selected vertices kinematic where they
  are (``Groom.pinned``); :meth:`set_parameter` changes a
  :class:`GroomingConfig` field; :meth:`simulate` toggles the simulation.

Every edit is undoable (:meth:`undo`, :meth:`redo`): a snapshot of the groom
(both poses, topology, attributes), the parameters, the selection and the drag
is taken before it, so undo and redo restore the groom bit for bit.  The
solver's warm-start state (twists, multipliers) restarts from the restored
groom, as after loading it.

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

With ``guide_ratio < 1`` a selected vertex of a skinned strand acts through its
*proxy*: the vertex of the nearest guide (by root) at the nearest rest arc
fraction; pins and drags move guides, and skinned strands follow them.

Points on a guide strand are written back from the solver's State, whose
precision is Taichi's ``default_fp``; the groom keeps its own dtype.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
import time
from dataclasses import asdict, dataclass, fields, replace

import numpy as np

from ..io import Groom, load_groom, save_groom

MODES = ("replace", "add", "remove")
#: Actions that change the groom or the simulation set-up: each pushes an undo snapshot.
EDIT_ACTIONS = ("drag", "release", "comb", "trim", "scale_length", "scale_curl", "pin", "unpin", "set_parameter")
#: Every action a session log may hold (each is a method of :class:`GroomingSession`).
ACTIONS = ("select", "select_ray", "select_strands", "select_all", "simulate", "advance", "undo", "redo") \
    + EDIT_ACTIONS
#: Parameters whose change updates the Model and solver coefficients (the others apply to the running solver).
REBUILD_PARAMETERS = ("youngs_modulus", "radius", "density", "guide_ratio", "neighbour_count", "seed", "contacts",
                      "contact_margin", "w0")
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
        w0: scale of the ADMM elasticity weights [-] (SolverADMMConfig.w0).  Measured on 12
            strands x 10 vertices, 10 cm, 10 iterations per frame: 1 settles the sag to 3 % in 10
            frames and holds a strand dragged by its tip still; 0.2 settles faster but a strand
            with both ends kinematic keeps oscillating (centimetres) from frame to frame; 5 and
            the dynamic default 25 creep (the sag is half done after 20 frames at 5).
        autosave_every: write the autosave files every this many edits; 0 disables [-].
        undo_limit: most undo snapshots kept [-].
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
    w0: float = 1.0
    autosave_every: int = 1
    undo_limit: int = 100

    def __post_init__(self):
        for name in ("youngs_modulus", "radius", "density", "w0"):
            v = getattr(self, name)
            if not (_finite(v) and v > 0):
                raise ValueError(f"GroomingConfig.{name} must be a finite positive number, got {v!r}")
            setattr(self, name, float(v))
        for name in ("friction", "contact_margin"):
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
        for name, lo in (("iterations", 1), ("neighbour_count", 1), ("autosave_every", 0), ("undo_limit", 0),
                         ("seed", 0)):
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

    def to_dict(self) -> dict:
        """JSON-able dict of the fields (gravity as a list)."""
        d = asdict(self)
        d["gravity"] = list(self.gravity)
        return d


# =========================================================================== geometry helpers (NumPy, float64)
def _vec3(name: str, value) -> np.ndarray:
    try:
        a = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        a = np.zeros(0)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"'{name}' must be 3 finite numbers, got {value!r}")
    return a


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


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b of two 3-vectors: the products and differences of ``np.cross`` (same bits), without its
    per-call axis handling, which dominated the per-strand edits (measured: 60 us a call)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _rotate(v: np.ndarray, axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues rotation of v about unit ``axis`` by ``angle`` [rad]."""
    c, s = math.cos(angle), math.sin(angle)
    return v * c + _cross(axis, v) * s + axis * np.dot(axis, v) * (1.0 - c)


def _perpendicular(t: np.ndarray) -> np.ndarray:
    a = np.array([0.0, 0.0, 1.0]) if abs(t[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    d = _cross(t, a)
    return d / np.linalg.norm(d)


def _pair_frame(t0: np.ndarray, t1: np.ndarray):
    """Orthonormal frame (columns) from a unit tangent t0 and the next tangent t1, or None if parallel."""
    n = t1 - np.dot(t1, t0) * t0
    ln = np.linalg.norm(n)
    if ln < 1e-9:
        return None
    n /= ln
    return np.column_stack([t0, n, _cross(t0, n)])


def _min_rotation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Smallest rotation matrix taking unit a to unit b."""
    v = _cross(a, b)
    c = float(np.dot(a, b))
    if np.linalg.norm(v) < 1e-12:
        return np.eye(3) if c > 0 else _rotation_matrix(_perpendicular(a), math.pi)
    k = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + k + k @ k / (1.0 + c)


def _rotation_matrix(axis: np.ndarray, angle: float) -> np.ndarray:
    return np.column_stack([_rotate(e, axis, angle) for e in np.eye(3)])


def _tangents(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    e = np.diff(p, axis=0)
    le = np.linalg.norm(e, axis=1)
    return e / le[:, None], le


def _tip_rotation(p: np.ndarray) -> np.ndarray:
    """Rotation continuing the tip of polyline p: maps (t[-3], t[-2]) to (t[-2], t[-1]) (a screw for a helix)."""
    t, _ = _tangents(p)
    if len(t) >= 3:
        a, b = _pair_frame(t[-3], t[-2]), _pair_frame(t[-2], t[-1])
        if a is not None and b is not None:
            return b @ a.T
    return _min_rotation(t[-2], t[-1])


def _tip_frame_map(rest: np.ndarray, cur: np.ndarray) -> np.ndarray:
    """Rotation taking the rest tip frame (last two edges) to the current one."""
    tr, _ = _tangents(rest[-3:])
    tc, _ = _tangents(cur[-3:])
    fr, fc = _pair_frame(tr[0], tr[1]), _pair_frame(tc[0], tc[1])
    if fr is not None and fc is not None:
        return fc @ fr.T
    return _min_rotation(tr[1], tc[1])


def _arc(p: np.ndarray) -> np.ndarray:
    """Cumulative arc length at every vertex of polyline p [m], shape (m,)."""
    return np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))))


def _sample(knots: np.ndarray, points: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Points of the polyline ``points`` at arc parameters ``s``, linear between the vertices
    (``knots`` is the parameter of each vertex, increasing).  s = knots[0] gives points[0] exactly."""
    idx = np.clip(np.searchsorted(knots, s, side="right") - 1, 0, len(knots) - 2)
    u = np.clip((s - knots[idx]) / (knots[idx + 1] - knots[idx]), 0.0, 1.0)
    return points[idx] + u[:, None] * (points[idx + 1] - points[idx])


def _resample(cur: np.ndarray, rest: np.ndarray, phi: np.ndarray, length: float, tip=None):
    """Both poses of a strand resampled to ``len(phi)`` vertices along the first ``length`` [m] of
    the rest polyline ``rest`` (the strand, extended beyond its tip for a growth).

    Vertex i goes to the rest arc length phi_i * length, phi_i the old arc fraction of vertex i,
    so the relative spacing is kept (uniform stays uniform) and every edge is scaled by
    length / old length.  Both poses are parametrised by the *rest* arc length and interpolated
    linearly, so vertex i of the current pose is the point that corresponds to vertex i of the rest
    pose; new vertices lie on the old polylines (a corner between two old vertices is cut by the
    new chord: the rest length is ``length`` minus that chord shortening, and a curl finer than
    the new edge spacing is smoothed).  The root vertex is kept bit for bit.  ``tip`` (current,
    rest) overrides the last vertex (a trim puts it exactly on the cutting plane).
    """
    c = _arc(rest)
    s = phi * length
    new_cur, new_rest = _sample(c, cur, s), _sample(c, rest, s)
    new_cur[0], new_rest[0] = cur[0], rest[0]
    if tip is not None:
        new_cur[-1], new_rest[-1] = tip
    return new_cur, new_rest


def _turning(p: np.ndarray):
    """Bishop-frame curvature of a polyline: (angle, axis components (a.u, a.v)) per edge pair."""
    t, le = _tangents(p)
    u = _perpendicular(t[0])
    angles, comps = [], []
    for i in range(1, len(t)):
        b = _cross(t[i - 1], t[i])
        s, c = np.linalg.norm(b), float(np.dot(t[i - 1], t[i]))
        v = _cross(t[i - 1], u)
        if s < 1e-14:
            angles.append(0.0)
            comps.append((1.0, 0.0))
        else:
            a = b / s
            angles.append(math.atan2(s, c))
            comps.append((float(np.dot(a, u)), float(np.dot(a, v))))
            u = _rotate(u, a, angles[-1])
            u -= np.dot(u, t[i]) * t[i]
            u /= np.linalg.norm(u)
    return t, le, np.array(angles), np.array(comps)


def _scale_curl_polyline(p: np.ndarray, factor: float) -> np.ndarray:
    """Polyline with every Bishop turning angle multiplied by ``factor`` (edge lengths and root edge kept)."""
    t, le, angles, comps = _turning(p)
    out = np.empty_like(p)
    out[0], out[1] = p[0], p[1]
    ti_, u = t[0].copy(), _perpendicular(t[0])
    for i in range(1, len(t)):
        v = _cross(ti_, u)
        a = comps[i - 1][0] * u + comps[i - 1][1] * v
        na = np.linalg.norm(a)
        if angles[i - 1] != 0.0 and na > 0:
            a /= na
            ti_ = _rotate(ti_, a, factor * angles[i - 1])
            u = _rotate(u, a, factor * angles[i - 1])
            ti_ /= np.linalg.norm(ti_)
            u -= np.dot(u, ti_) * ti_
            u /= np.linalg.norm(u)
        out[i + 1] = out[i] + le[i] * ti_
    return out


def _edge_mask(offsets: np.ndarray, n: int) -> np.ndarray:
    """True for edge k (vertices k, k+1) when both lie on the same strand, shape (n - 1,)."""
    m = np.ones(max(n - 1, 0), dtype=bool)
    m[offsets[1:-1] - 1] = False
    return m


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


# =========================================================================== session log parsing
def _parse_log(source) -> list:
    """Entries of a session log (a list, or a JSON file) as (entry, line or None)."""
    if isinstance(source, (list, tuple)):
        return [(e, None) for e in source]
    path = os.fspath(source)
    with open(path, "r", encoding="utf-8") as fh:
        text = fh.read()
    dec = json.JSONDecoder()
    pos = len(text) - len(text.lstrip())
    if not text[pos:pos + 1] == "[":
        raise ValueError(f"{path}: line {text.count(chr(10), 0, pos) + 1}: a session log is a JSON list")
    pos += 1
    out = []
    while True:
        while pos < len(text) and text[pos] in " \t\r\n,":
            pos += 1
        line = text.count("\n", 0, pos) + 1
        if pos >= len(text):
            raise ValueError(f"{path}: line {line}: unterminated JSON list")
        if text[pos] == "]":
            return out
        try:
            entry, pos = dec.raw_decode(text, pos)
        except json.JSONDecodeError as exc:
            raise ValueError(f"{path}: line {exc.lineno}, entry {len(out)}: invalid JSON ({exc.msg})") from None
        out.append((entry, line))


# =========================================================================== the session
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
        groom: the edited :class:`Groom` (``points`` current pose, ``rest_points`` rest pose,
            ``pinned``); replaced, never mutated in place, by edits.
        config: the current :class:`GroomingConfig`.
        simulating: whether :meth:`advance` steps the solver.
        log: list of ``{"action": name, **params}`` of every action so far.
        timings: lists of seconds: ``rebuild`` (Model + solver + skinning + State),
            ``update`` (an in-place update of the Model after a rest-shape edit),
            ``first_frame`` (first frame after a rebuild: kernel compilation), ``frame``.
        rebuild_count: Models built so far [-].
        update_count: in-place Model updates so far [-].
    """

    def __init__(self, groom, config: GroomingConfig | None = None, colliders=None, autosave_path=None):
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
        if config is None:
            stored = g.params.get("grooming")
            try:
                config = GroomingConfig(**stored) if isinstance(stored, dict) else GroomingConfig()
            except TypeError as exc:
                raise ValueError(f"GroomingSession: params['grooming'] of the groom: {exc}") from None
        elif not isinstance(config, GroomingConfig):
            raise ValueError(f"GroomingSession: config must be a GroomingConfig, got {type(config).__name__}")
        self.groom = g
        self.config = replace(config)
        self.colliders = list(colliders) if colliders else []
        for k, c in enumerate(self.colliders):
            if getattr(c, "body", -1) not in (-1, 0):
                raise ValueError(f"GroomingSession: collider {k} is on body {c.body}; a grooming session has the "
                                 f"static world (-1) and the head (0) only (body {COMB_BODY} is the comb's)")
        self.autosave_path = None if autosave_path is None else os.fspath(autosave_path)
        self.simulating = True
        self.log: list[dict] = []
        self.timings = {"rebuild": [], "update": [], "first_frame": [], "frame": []}
        self.rebuild_count = 0
        self.update_count = 0
        self._selection = np.zeros(g.vertex_count, dtype=bool)
        self._drag = None
        self._undo: list[dict] = []
        self._redo: list[dict] = []
        self._edits_since_autosave = 0
        self._sim = None  # built lazily by _ensure_built
        self._proxy_cache = None

    @classmethod
    def open(cls, path, config: GroomingConfig | None = None, colliders=None, autosave: bool = True, **options):
        """Load a groom file (``taichi_hair.io.load_groom``) and autosave beside it
        (``<stem>.autosave.thair.npz`` and ``<stem>.autosave.session.json``)."""
        groom = load_groom(path, **options)
        auto = None
        if autosave:
            base = os.fspath(path)
            for ext in (".thair.npz", ".npz"):
                if base.lower().endswith(ext):
                    base = base[: -len(ext)]
                    break
            else:
                base = os.path.splitext(base)[0]
            auto = base + ".autosave.thair.npz"
        return cls(groom, config, colliders, auto)

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
        return np.logical_or.reduceat(self._selection, self.groom.strand_offsets[:-1])

    @property
    def dragging(self) -> bool:
        return self._drag is not None

    @property
    def guide_strands(self) -> np.ndarray:
        """Indices of the simulated strands (the others are skinned), int64, sorted."""
        return self._guide_strands()

    # ------------------------------------------------------------------ log, undo, autosave machinery
    def _record(self, action: str, **params) -> None:
        self.log.append({"action": action, **params})

    def _snapshot(self) -> dict:
        drag = None if self._drag is None else {k: (v.copy() if isinstance(v, np.ndarray) else v)
                                                for k, v in self._drag.items()}
        return {"groom": self.groom.copy(), "config": replace(self.config), "selection": self._selection.copy(),
                "drag": drag, "simulating": self.simulating}

    def _edit(self, action: str, params: dict, apply) -> None:
        """Run ``apply`` (which validates before it changes anything) as one undoable, logged edit."""
        snap = self._snapshot()
        apply()
        self._undo.append(snap)
        if len(self._undo) > self.config.undo_limit:
            del self._undo[: len(self._undo) - self.config.undo_limit]
        self._redo.clear()
        self._record(action, **params)
        self._count_edit()

    def _count_edit(self) -> None:
        self._edits_since_autosave += 1
        every = self.config.autosave_every
        if self.autosave_path is not None and every > 0 and self._edits_since_autosave >= every:
            self.autosave()

    def _restore(self, snap: dict) -> None:
        old = self.groom, self.config
        self.groom = snap["groom"].copy()
        self.config = replace(snap["config"])
        self._selection = snap["selection"].copy()
        self._drag = None if snap["drag"] is None else {k: (v.copy() if isinstance(v, np.ndarray) else v)
                                                        for k, v in snap["drag"].items()}
        self.simulating = snap["simulating"]
        same_layout = (np.array_equal(old[0].strand_offsets, self.groom.strand_offsets)
                       and np.array_equal(old[0].rest_points[old[0].strand_offsets[:-1]],
                                          self.groom.rest_points[self.groom.strand_offsets[:-1]])
                       and all(getattr(old[1], k) == getattr(self.config, k) for k in LAYOUT_PARAMETERS))
        same_rest = (same_layout and old[0].rest_points.dtype == self.groom.rest_points.dtype
                     and np.array_equal(old[0].rest_points, self.groom.rest_points)
                     and all(getattr(old[1], k) == getattr(self.config, k) for k in REBUILD_PARAMETERS))
        if not same_rest:
            self._invalidate(layout=not same_layout)
        elif self._sim is not None:
            self._apply_live_parameters()
            self._load_state()

    def undo(self) -> None:
        """Restore the groom, parameters, selection and drag as they were before the last edit."""
        if not self._undo:
            raise ValueError("undo: nothing to undo")
        self._redo.append(self._snapshot())
        self._restore(self._undo.pop())
        self._record("undo")
        self._count_edit()

    def redo(self) -> None:
        """Re-apply the last undone edit (restores exactly the state undo left)."""
        if not self._redo:
            raise ValueError("redo: nothing to redo")
        self._undo.append(self._snapshot())
        self._restore(self._redo.pop())
        self._record("redo")
        self._count_edit()

    @property
    def can_undo(self) -> bool:
        return bool(self._undo)

    @property
    def can_redo(self) -> bool:
        return bool(self._redo)

    def _groom_for_saving(self) -> Groom:
        g = self.groom.copy()
        g.params["grooming"] = self.config.to_dict()
        return g

    def save(self, path) -> None:
        """Write the edited groom (current pose, rest pose, pins, parameters in ``params["grooming"]``)
        in the native ``.thair.npz`` format, atomically.  Not logged."""
        save_groom(self._groom_for_saving(), path, format="thair")

    def autosave(self) -> None:
        """Write the groom to ``autosave_path`` and the log beside it, both atomically."""
        if self.autosave_path is None:
            raise ValueError("autosave: this session has no autosave_path")
        self.save(self.autosave_path)
        self.write_log(self.autosave_log_path)
        self._edits_since_autosave = 0

    @property
    def autosave_log_path(self) -> str | None:
        if self.autosave_path is None:
            return None
        base = self.autosave_path
        for ext in (".thair.npz", ".npz"):
            if base.lower().endswith(ext):
                base = base[: -len(ext)]
                break
        return base + ".session.json"

    def write_log(self, path) -> None:
        """Write the log as a JSON list, one action per line (line i + 2 holds entry i), atomically."""
        path = os.fspath(path)
        text = "[\n" + ",\n".join(json.dumps(e, allow_nan=False) for e in self.log) + "\n]\n"
        folder = os.path.dirname(os.path.abspath(path))
        fd, tmp = tempfile.mkstemp(prefix=".tmp-", suffix=".json", dir=folder)
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as fh:
                fh.write(text)
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, path)
        except BaseException:
            if os.path.exists(tmp):
                os.unlink(tmp)
            raise

    def replay(self, source, after_each=None) -> None:
        """Apply the actions of a session log (a list of dicts or a ``session.json`` path) in order.

        ``after_each(index, entry)``, if given, is called after each applied entry (the off-screen
        tool renders a frame there).

        Raises:
            ValueError naming the entry index (and the file's line), the action and the problem,
            for an unknown action, an unknown or missing parameter or a bad value.  Actions before
            the bad one stay applied.
        """
        entries = _parse_log(source)
        import inspect

        for i, (entry, line) in enumerate(entries):
            where = f"session entry {i}" + (f" (line {line})" if line is not None else "")
            if not isinstance(entry, dict) or "action" not in entry:
                raise ValueError(f"{where}: expected an object with an 'action' key, got {entry!r}")
            name = entry["action"]
            if name not in ACTIONS:
                raise ValueError(f"{where}: unknown action {name!r}; known: {', '.join(ACTIONS)}")
            params = {k: v for k, v in entry.items() if k != "action"}
            method = getattr(self, name)
            try:
                inspect.signature(method).bind(**params)
            except TypeError as exc:
                raise ValueError(f"{where}, action {name!r}: bad parameters ({exc})") from None
            try:
                method(**params)
            except ValueError as exc:
                raise ValueError(f"{where}, action {name!r}: {exc}") from None
            if after_each is not None:
                after_each(i, entry)

    # ------------------------------------------------------------------ selection
    def _apply_selection(self, hit: np.ndarray, mode: str) -> int:
        if mode not in MODES:
            raise ValueError(f"'mode' must be one of {MODES}, got {mode!r}")
        if mode == "replace":
            self._selection = hit
        elif mode == "add":
            self._selection = self._selection | hit
        else:
            self._selection = self._selection & ~hit
        return int(self.strand_selection.sum())

    def _edges(self):
        p = self.groom.points.astype(np.float64)
        mask = _edge_mask(self.groom.strand_offsets, p.shape[0])
        k = np.nonzero(mask)[0]
        return p, k, p[k], p[k + 1] - p[k]

    def _hit_from_edges(self, p, k, close) -> np.ndarray:
        hit = np.zeros(p.shape[0], dtype=bool)
        hit[k[close]] = True
        hit[k[close] + 1] = True
        return hit

    def select(self, center, radius, mode: str = "replace") -> int:
        """Select the vertices of every edge within ``radius`` [m] of ``center`` [m]; returns the
        number of selected strands."""
        c = _vec3("center", center)
        r = _positive("radius", radius)
        p, k, a, u = self._edges()
        s = np.clip(np.einsum("ij,ij->i", c - a, u) / np.einsum("ij,ij->i", u, u), 0.0, 1.0)
        d = np.linalg.norm(a + s[:, None] * u - c, axis=1)
        count = self._apply_selection(self._hit_from_edges(p, k, d <= r), mode)
        self._record("select", center=c.tolist(), radius=r, mode=mode)
        return count

    def select_ray(self, origin, direction, radius, mode: str = "replace") -> int:
        """Select the vertices of every edge within ``radius`` [m] of the half-line
        origin + t direction, t >= 0 (a screen pick ray); returns the number of selected strands."""
        o = _vec3("origin", origin)
        dvec = _vec3("direction", direction)
        nd = np.linalg.norm(dvec)
        if nd == 0:
            raise ValueError("'direction' must be a non-zero vector")
        d = dvec / nd
        r = _positive("radius", radius)
        p, k, a, u = self._edges()
        w = a - o
        aa = np.einsum("ij,ij->i", u, u)
        b = u @ d
        dd = np.einsum("ij,ij->i", u, w)
        e = w @ d

        def dist(s, t, i=slice(None)):
            return np.linalg.norm(w[i] + s[:, None] * u[i] - t[:, None] * d, axis=1)

        # Convex in (s, t): the minimum over s in [0, 1], t >= 0 is interior or on a boundary.
        best = dist(np.zeros_like(e), np.maximum(e, 0.0))
        best = np.minimum(best, dist(np.ones_like(e), np.maximum(e + b, 0.0)))
        best = np.minimum(best, dist(np.clip(-dd / aa, 0.0, 1.0), np.zeros_like(e)))
        den = aa - b * b
        with np.errstate(divide="ignore", invalid="ignore"):
            s_in = (b * e - dd) / den
        t_in = e + s_in * b
        ok = np.nonzero((den > 1e-14 * aa) & (s_in >= 0) & (s_in <= 1) & (t_in >= 0))[0]
        best[ok] = np.minimum(best[ok], dist(s_in[ok], t_in[ok], ok))
        count = self._apply_selection(self._hit_from_edges(p, k, best <= r), mode)
        self._record("select_ray", origin=o.tolist(), direction=dvec.tolist(), radius=r, mode=mode)
        return count

    def select_strands(self, strands, mode: str = "replace") -> int:
        """Select whole strands by index."""
        try:
            idx = np.asarray(strands, dtype=np.int64).reshape(-1)
        except (TypeError, ValueError):
            raise ValueError(f"'strands' must be a list of strand indices, got {strands!r}") from None
        ns = self.strand_count
        if idx.size and (idx.min() < 0 or idx.max() >= ns):
            raise ValueError(f"'strands' must lie in [0, {ns}), got {idx.tolist()}")
        strand_hit = np.zeros(ns, dtype=bool)
        strand_hit[idx] = True
        count = self._apply_selection(np.repeat(strand_hit, self.groom.strand_vertex_counts()), mode)
        self._record("select_strands", strands=idx.tolist(), mode=mode)
        return count

    def select_all(self) -> int:
        self._selection = np.ones(self.groom.vertex_count, dtype=bool)
        self._record("select_all")
        return self.strand_count

    # ------------------------------------------------------------------ topology edits
    def _replace_strands(self, new: dict) -> None:
        """Swap the poses of strands s -> (current, rest), each with the strand's vertex count.

        The layout (vertex and strand counts) is kept, so the simulation updates its Model in place
        instead of rebuilding it; per-vertex attributes (pins, selection, radius, colour) stay on
        their vertex index.  Unchanged strands are copied bit for bit.  Ends an active drag.
        """
        g = self.groom
        off = g.strand_offsets
        pts = g.points.copy()
        rest = g.rest_points.copy()
        for s, (cur, rp) in new.items():
            a, b = off[s], off[s + 1]
            pts[a:b] = cur.astype(pts.dtype)
            rest[a:b] = rp.astype(rest.dtype)
        self.groom = replace(g, points=pts, rest_points=rest, params=dict(g.params)).validate()
        self._drag = None
        self._invalidate(layout=False)

    def trim(self, plane_point, plane_normal, selected_only: bool = False) -> int:
        """Cut every strand whose current polyline crosses the plane (point, normal) [m] at its first
        crossing from the root; the part holding the root stays.  ``selected_only`` restricts it to
        the selected strands.  Strands not crossing are untouched.  Returns the number of strands cut.

        A cut strand keeps its vertex count: both poses are resampled along the kept part
        (:func:`_resample`), so its edges get shorter and its last vertex lies on the plane.
        Keeping the layout lets the solver update its Model in place (milliseconds) instead of
        building a new one (a kernel recompilation).
        """
        p0 = _vec3("plane_point", plane_point)
        n = _vec3("plane_normal", plane_normal)
        if np.linalg.norm(n) == 0:
            raise ValueError("'plane_normal' must be a non-zero vector")
        n = n / np.linalg.norm(n)
        if not isinstance(selected_only, bool):
            raise ValueError(f"'selected_only' must be true or false, got {selected_only!r}")
        g = self.groom
        off = g.strand_offsets
        dist = (g.points.astype(np.float64) - p0) @ n
        chosen = self.strand_selection if selected_only else np.ones(g.strand_count, dtype=bool)
        # Candidates: strands with a vertex on the other side of the plane from their root.
        side = np.repeat(np.sign(dist[off[:-1]]), g.strand_vertex_counts())
        crosses = np.logical_or.reduceat(dist * side <= 0.0, off[:-1]) & (dist[off[:-1]] != 0.0) & chosen
        new = {}
        for s in np.nonzero(crosses)[0]:
            a, b = off[s], off[s + 1]
            cur = g.points[a:b].astype(np.float64)
            rest = g.rest_points[a:b].astype(np.float64)
            d = dist[a:b]
            k = int(np.nonzero(d * np.sign(d[0]) <= 0.0)[0][0])
            j = k - 1
            u = d[j] / (d[j] - d[k])
            tip = (cur[j] + u * (cur[j + 1] - cur[j]), rest[j] + u * (rest[j + 1] - rest[j]))
            c = _arc(rest)
            new[int(s)] = _resample(cur, rest, c / c[-1], c[j] + u * (c[j + 1] - c[j]), tip)

        def apply():
            if new:
                self._replace_strands(new)

        self._edit("trim", {"plane_point": p0.tolist(), "plane_normal": _vec3("plane_normal", plane_normal).tolist(),
                            "selected_only": selected_only}, apply)
        return len(new)

    def scale_length(self, factor) -> None:
        """Multiply the rest length of the selected strands by ``factor`` > 0, from the tip.

        Shorter: the strand is cut at the scaled rest arc length.  Longer: the rest polyline is
        continued beyond the tip with the tip's curvature and torsion (the screw motion taking the
        last-but-one edge pair to the last one, at the last rest edge length; the current pose
        continues rigidly with the tip's frame).  Either way the strand keeps its vertex count and
        both poses are resampled along the new length (:func:`_resample`): edges scale by
        ``factor``, and the rest length is ``factor`` times the old one up to the chord shortening
        of the resampling.  A large growth of a curly strand therefore smooths curls finer than
        the new edge spacing; add vertices to the groom beforehand for that.
        """
        f = _positive("factor", factor)
        sel = np.nonzero(self.strand_selection)[0]
        if sel.size == 0:
            raise ValueError("scale_length: no strand is selected")
        g = self.groom
        off = g.strand_offsets
        new = {}
        for s in sel:
            if f == 1.0:
                break
            a, b = off[s], off[s + 1]
            cur = g.points[a:b].astype(np.float64)
            rest = g.rest_points[a:b].astype(np.float64)
            c = _arc(rest)
            total = float(c[-1])
            if f > 1.0:
                le = c[-1] - c[-2]
                extra = (f - 1.0) * total
                k = max(1, int(math.ceil(extra / le * (1.0 + 1e-12))))
                step = le  # the screw motion q belongs to this edge length: the helix continues exactly
                q = _tip_rotation(rest)
                t = rest[-1] - rest[-2]
                t /= np.linalg.norm(t)
                grown = []
                tip = rest[-1]
                for _ in range(k):
                    t = q @ t
                    t /= np.linalg.norm(t)
                    tip = tip + step * t
                    grown.append(tip)
                grown = np.array(grown)
                m = _tip_frame_map(rest, cur)
                cur_grown = cur[-1] + (grown - rest[-1]) @ m.T
                cur, ext = np.vstack([cur, cur_grown]), np.vstack([rest, grown])
            else:
                ext = rest
            new[int(s)] = _resample(cur, ext, c / total, f * total)

        def apply():
            if new:
                self._replace_strands(new)

        self._edit("scale_length", {"factor": f}, apply)

    def scale_curl(self, factor) -> None:
        """Multiply the rest curvature (every Bishop turning angle) of the selected strands by
        ``factor`` >= 0; edge lengths and the root edge are kept.  The edited strands' current
        pose is set to the new rest pose (it settles again when simulated)."""
        f = _positive("factor", factor, allow_zero=True)
        sel = np.nonzero(self.strand_selection)[0]
        if sel.size == 0:
            raise ValueError("scale_curl: no strand is selected")
        g = self.groom
        off = g.strand_offsets
        rest = g.rest_points.copy()
        pts = g.points.copy()
        for s in sel:
            a, b = off[s], off[s + 1]
            q = _scale_curl_polyline(g.rest_points[a:b].astype(np.float64), f)
            q[:2] = g.rest_points[a:a + 2]  # the clamped root edge, bit for bit
            rest[a:b] = q.astype(rest.dtype)
            pts[a:b] = rest[a:b]

        def apply():
            self.groom = replace(g, points=pts, rest_points=rest, params=dict(g.params))
            self._invalidate(layout=False)

        self._edit("scale_curl", {"factor": f}, apply)

    # ------------------------------------------------------------------ kinematic edits
    def _proxy(self) -> np.ndarray:
        """Groom vertex simulated in place of each groom vertex, int64 (vertex_count,): itself on a
        guide strand; on another strand, the vertex of its nearest guide (by root) at the nearest
        rest arc fraction."""
        if self._proxy_cache is not None:
            return self._proxy_cache
        g = self.groom
        off = g.strand_offsets
        guides = self._guide_strands()
        proxy = np.arange(g.vertex_count, dtype=np.int64)
        if guides.size < g.strand_count:
            rest = g.rest_points.astype(np.float64)
            roots = rest[off[:-1]]
            from scipy.spatial import cKDTree

            from .skinning import _arc_fractions

            _, nearest = cKDTree(roots[guides]).query(roots)
            counts = g.strand_vertex_counts()
            frac, _ = _arc_fractions(rest, counts)  # per vertex, each strand's own cumulative sum
            # Vectorised over vertices: the nearest rest arc fraction on the nearest guide, by a
            # search in keys 2 s + f (sorted: fractions lie in [0, 1], strands are contiguous).
            strand_of = np.repeat(np.arange(g.strand_count), counts)
            keys = 2.0 * strand_of + frac
            gs = guides[nearest[strand_of]]  # the guide strand each vertex follows
            first = off[gs]
            idx = np.searchsorted(keys, 2.0 * gs + frac, side="left") - first
            idx = np.clip(idx, 1, counts[gs] - 1)
            idx -= (frac - frac[first + idx - 1]) < (frac[first + idx] - frac)
            is_guide = np.zeros(g.strand_count, dtype=bool)
            is_guide[guides] = True
            skinned = ~is_guide[strand_of]
            proxy[skinned] = (first + idx)[skinned]
        self._proxy_cache = proxy
        return proxy

    def _guide_strands(self) -> np.ndarray:
        """Farthest-point sampled guides of the roots (cached: edits keep the roots)."""
        g, cfg = self.groom, self.config
        if cfg.guide_ratio >= 1.0:
            return np.arange(g.strand_count)
        from .skinning import select_guides

        roots = g.rest_points.astype(np.float64)[g.strand_offsets[:-1]]
        key = (roots.tobytes(), cfg.guide_ratio, cfg.seed)
        cached = getattr(self, "_guide_cache", None)
        if cached is not None and cached[0] == key:
            return cached[1].copy()
        guides = np.sort(select_guides(roots, cfg.guide_ratio, cfg.seed))
        self._guide_cache = (key, guides)
        return guides.copy()

    def _grabbable(self, mask: np.ndarray) -> np.ndarray:
        """Groom vertices (proxies) of ``mask``, without clamped root vertices (local index 0, 1)."""
        local = np.arange(self.groom.vertex_count) - np.repeat(self.groom.strand_offsets[:-1],
                                                               self.groom.strand_vertex_counts())
        v = np.unique(self._proxy()[mask & (local > 1)])
        local_v = local[v]
        return v[local_v > 1]

    def drag(self, target_offset, stiffness=0.5) -> None:
        """Pull the selected vertices toward anchor + ``target_offset`` [m] (anchor: their position
        when the drag began); each frame they move ``stiffness`` in (0, 1] of the remaining way.
        Call again with a new offset to move the target; :meth:`release` ends the drag."""
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

        The stroke moves the comb's position along the polyline ``path`` (world coordinates [m])
        in equal steps of at most ``step`` [m] (default ``radius / 2``), one quasistatic solver
        step (``config.iterations`` ADMM iterations) per step, with the comb's end-of-step
        transform in Control.  Contacts are detected at the beginning of a step and carry the
        comb's surface point to its end-of-step position (Sec. 4.5), so hair ahead of the comb is
        pushed (a vertex the comb overtakes stays in its front half as long as a step is shorter
        than the radius, and is pushed forward, not backward; a step longer than the diameter
        would jump over strands) and hair in touch is dragged along by friction, at most mu times
        the normal force.  The hair is never moved directly.

        Rest pose: afterwards every strand the comb touched (a comb contact in some step), and
        every skinned strand bound to such a guide, takes its current pose as its rest pose
        (the clamped root edge is kept bit for bit), so the combed shape stays when the
        simulation goes on; the other strands keep theirs (strands moved only through hair-hair
        contacts relax back).  ``drag``/``release`` never change the rest pose; a comb is a
        shape edit, like :meth:`scale_curl`.  A drag in progress ends.  The comb steps the solver
        even when the simulation is off (``simulate(False)``): the stroke is the edit.
        """
        pts = _path("path", path)
        r = _positive("radius", radius)
        ax = _vec3("axis", axis)
        if np.linalg.norm(ax) == 0:
            raise ValueError("'axis' must be a non-zero vector")
        length_ = _positive("length", length, allow_zero=True)
        mu = _positive("friction", friction, allow_zero=True)
        h = 0.5 * r if step is None else _positive("step", step)
        moving = np.r_[True, np.any(np.diff(pts, axis=0) != 0.0, axis=1)]
        knots = _arc(pts[moving])
        total = float(knots[-1])
        if total == 0.0:
            raise ValueError("'path' must move: its points are all equal")
        n = max(1, int(math.ceil(total / h * (1.0 - 1e-12))))
        if n > COMB_MAX_STEPS:
            raise ValueError(f"the path ({total:.4g} m) needs {n} steps of {h:.4g} m, more than {COMB_MAX_STEPS}; "
                             "pass a larger 'step'")
        positions = _sample(knots, pts[moving], np.linspace(0.0, total, n + 1))
        positions[-1] = pts[-1]

        def apply():
            if self._drag is not None:
                self._drag = None
                if self._sim is not None:
                    self._apply_kinematics()
            self._ensure_built()
            touched = self._sweep_comb(positions, r, ax / np.linalg.norm(ax), length_, mu)
            self._commit_combed(touched)

        self._combed_count = 0
        self._edit("comb", {"path": pts.tolist(), "radius": r, "axis": ax.tolist(), "length": length_,
                            "friction": mu, "step": h}, apply)
        return self._combed_count

    def _sweep_comb(self, positions: np.ndarray, radius: float, axis: np.ndarray, length: float,
                    friction: float) -> np.ndarray:
        """Move the comb collider through ``positions`` (n + 1, 3) [m], one solver step per move;
        returns which guides (Model strands) had a comb contact, bool (guide_count,)."""
        import taichi as ti

        sim = self._sim
        solver, control = sim.solver, sim.control
        cs = solver.contacts.colliders
        k = sim.comb_collider
        half = 0.5 * length * axis
        cs.collider_a[k] = (-half).tolist()
        cs.collider_b[k] = half.tolist()
        cs.collider_radius[k] = radius
        cs.collider_friction[k] = friction
        # The first move starts at positions[0]: the begin-of-step transform of the comb body is the end
        # transform the ColliderSet keeps from the previous step (body 0, the head, never moves).
        control.body_translation[COMB_BODY] = positions[0].tolist()
        if not cs.has_begin:
            cs.body_rotation_end.copy_from(control.body_rotation)
            cs.body_translation_end.copy_from(control.body_translation)
            cs.has_begin = True
        cs.body_translation_end[COMB_BODY] = positions[0].tolist()
        cs.collider_strands[k] = [0, 2**31 - 1]
        touched = np.zeros(sim.model.strand_count, dtype=bool)
        vertex_strand = sim.model.host["vertex_strand"]
        try:
            for q in positions[1:]:
                t0 = time.perf_counter()
                control.body_translation[COMB_BODY] = q.tolist()
                solver.step(sim.state, control, 1.0)
                con = solver.contacts
                nc = con.contact_count
                if nc:
                    mine = con.con.contact_collider.to_numpy()[:nc] == k
                    touched[vertex_strand[con.con.contact_vertex.to_numpy()[:nc, 0][mine]]] = True
                ti.sync()
                self.timings["frame"].append(time.perf_counter() - t0)
        finally:
            cs.collider_strands[k] = [0, 0]  # idle: acts on no strand
        self._write_back()
        return touched

    def _commit_combed(self, touched: np.ndarray) -> None:
        """Rest pose <- current pose on the guides ``touched`` and the skinned strands bound to them
        (root edge kept); sets ``_combed_count``."""
        sim, g = self._sim, self.groom
        combed = np.zeros(g.strand_count, dtype=bool)
        combed[self._guide_strands()[touched]] = True
        if sim.skin is not None:
            bound = sim.skin.host["render_strand_guides"]
            weight = sim.skin.host["render_strand_weights"]
            combed |= np.any(touched[bound] & (weight > 0.0), axis=1)
        self._combed_count = int(combed.sum())
        if not combed.any():
            return
        counts = g.strand_vertex_counts()
        local = np.arange(g.vertex_count) - np.repeat(g.strand_offsets[:-1], counts)
        mask = np.repeat(combed, counts) & (local >= 2)
        rest = g.rest_points.copy()
        rest[mask] = g.points[mask].astype(rest.dtype)
        self.groom = replace(g, rest_points=rest, params=dict(g.params)).validate()
        self._invalidate(layout=False)

    # ------------------------------------------------------------------ parameters, simulation
    def set_parameter(self, name, value) -> None:
        """Set one :class:`GroomingConfig` field (validated; errors name the field)."""
        names = [f.name for f in fields(GroomingConfig)]
        if name not in names:
            raise ValueError(f"set_parameter: unknown parameter {name!r}; known: {', '.join(names)}")
        new = replace(self.config, **{name: value})  # __post_init__ validates
        logged = new.to_dict()[name]

        def apply():
            self.config = new
            if name in REBUILD_PARAMETERS:
                self._invalidate(layout=name in LAYOUT_PARAMETERS)
            elif self._sim is not None:
                self._apply_live_parameters()

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
                if self._drag is not None:
                    d = self._drag
                    d["position"] += d["stiffness"] * (d["anchor"] + d["offset"] - d["position"])
                    sim.body[sim.drag_rows] = d["position"]
                    sim.model.vertex_body_position.from_numpy(sim.body.astype(sim.np_float))
                sim.solver.step(sim.state, sim.control, 1.0)
                ti.sync()
                (self.timings["first_frame"] if fresh and f == 0 else self.timings["frame"]).append(
                    time.perf_counter() - t0)
            self._write_back()
        self._record("advance", frames=frames)

    # ------------------------------------------------------------------ the simulation objects
    def _invalidate(self, layout: bool = True) -> None:
        """Mark the simulation out of date: ``layout`` -> build a new Model and solver at the next
        frame (Taichi recompiles the kernels); else update the Model in place (same fields)."""
        if layout:
            self._sim = None
        elif self._sim is not None:
            self._sim.stale = True
        self._proxy_cache = None

    def _guide_setup(self):
        """Guide strands, their rest vertices (float64, flat) and offsets, and the material of the
        current config."""
        from ..config import RodMaterial

        g, cfg = self.groom, self.config
        off = g.strand_offsets
        guides = self._guide_strands()
        counts = g.strand_vertex_counts()[guides]
        starts = off[guides]
        # Vertex indices of the guides, strand after strand (vectorised: no per-strand slices).
        rows = np.repeat(starts - np.concatenate([[0], np.cumsum(counts)[:-1]]), counts) + np.arange(counts.sum())
        points = g.rest_points[rows].astype(np.float64)
        offsets = np.concatenate([[0], np.cumsum(counts)])
        material = RodMaterial(radius=cfg.radius, density=cfg.density, youngs_modulus_bend=cfg.youngs_modulus,
                               youngs_modulus_stretch=cfg.youngs_modulus)
        return guides, (points, offsets), material

    @staticmethod
    def _guide_builder(guide_rest, material):
        """The guides' GroomBuilder (bulk :meth:`GroomBuilder.add_strands`): roots clamped to body 0
        (the head); two bodies, the second the comb's (``COMB_BODY``), so a comb stroke needs no new
        Model."""
        from ..builder import GroomBuilder

        builder = GroomBuilder(body_count=COMB_BODY + 1)
        builder.add_strands(guide_rest[0], guide_rest[1], material, root="clamped", body=0)
        return builder

    def _ensure_built(self) -> None:
        if self._sim is not None:
            if self._sim.stale:
                self._update_in_place()
            return
        from types import SimpleNamespace

        from ..contact.colliders import CapsuleCollider
        from ..config import ContactConfig, SolverADMMConfig
        from ..model import _np_float
        from .skinning import SkinningConfig, SkinningLBS
        from ..solver_admm import SolverADMM

        t0 = time.perf_counter()
        g, cfg = self.groom, self.config
        off = g.strand_offsets
        guides, guide_rest, material = self._guide_setup()
        model = self._guide_builder(guide_rest, material).finalize()
        # Proximity only (Sec. 5.3): no velocity-dependent margin growth.  The pipeline always exists:
        # it holds the comb, an idle collider on its own body until a stroke enables it.
        contacts = ContactConfig(hair_hair=cfg.contacts, friction=cfg.friction, margin=cfg.contact_margin,
                                 velocity_margin=0.0)
        comb = CapsuleCollider(p0=(0.0, 0.0, 0.0), p1=(0.0, 0.0, 0.0), radius=1.0e-3, friction=0.0, body=COMB_BODY,
                               strands=(0, 1))
        solver = SolverADMM(model, SolverADMMConfig(iterations=cfg.iterations, mode="quasistatic", w0=cfg.w0,
                                                    contacts=contacts), colliders=self.colliders + [comb])
        solver.contacts.colliders.collider_strands[len(self.colliders)] = [0, 0]  # idle: acts on no strand
        state = model.state()
        control = model.control()
        control.gravity = tuple(cfg.gravity)
        skin = None
        if guides.size < g.strand_count:
            rest = g.rest_points.astype(np.float64)
            polylines = [rest[off[s]:off[s + 1]] for s in range(g.strand_count)]
            skin = SkinningLBS(model, guides, polylines,
                               SkinningConfig(neighbour_count=min(cfg.neighbour_count, int(guides.size))),
                               strand_body=0)
        guide_vertex = np.concatenate([np.arange(off[s], off[s + 1]) for s in guides])
        row_of = np.full(g.vertex_count, -1, dtype=np.int64)
        row_of[guide_vertex] = np.arange(guide_vertex.size)
        self._sim = SimpleNamespace(model=model, solver=solver, state=state, control=control, skin=skin,
                                    comb_collider=len(self.colliders),
                                    guide_vertex=guide_vertex, row_of=row_of, stale=False,
                                    base_fixed=model.host["vertex_is_fixed"].copy(),
                                    base_body=model.host["vertex_body_position"].copy(), body=None,
                                    drag_rows=np.zeros(0, dtype=np.int64), np_float=_np_float())
        self._load_state()
        self.rebuild_count += 1
        self.timings["rebuild"].append(time.perf_counter() - t0)

    def _update_in_place(self) -> None:
        """New rest shapes and materials, same layout: :meth:`Model.update`, ``refresh_model`` and a
        new skinning binding, all into the existing Taichi fields (no new field, no recompilation)."""
        t0 = time.perf_counter()
        sim, g, cfg = self._sim, self.groom, self.config
        guides, guide_rest, material = self._guide_setup()
        host, materials = _host_of(self._guide_builder(guide_rest, material))
        sim.model.update(host, materials)
        sim.solver.config.w0 = cfg.w0
        sim.solver.refresh_model()
        if sim.skin is not None:
            rest = g.rest_points.astype(np.float64)
            off = g.strand_offsets
            sim.skin.rebind([rest[off[s]:off[s + 1]] for s in range(g.strand_count)])
        sim.base_fixed = host["vertex_is_fixed"].copy()
        sim.base_body = host["vertex_body_position"].copy()
        sim.stale = False
        self._load_state()
        self.update_count += 1
        self.timings["update"].append(time.perf_counter() - t0)

    def _apply_live_parameters(self) -> None:
        sim, cfg = self._sim, self.config
        sim.control.gravity = tuple(cfg.gravity)
        sim.solver.config.iterations = cfg.iterations
        if sim.solver.contacts is not None:
            sim.solver.contacts.config.friction = cfg.friction

    def _load_state(self) -> None:
        """State from the groom: rest frames and twists, current positions; fresh multipliers."""
        sim = self._sim
        sim.model.reset_state(sim.state)
        sim.state.vertex_position.from_numpy(self.groom.points[sim.guide_vertex].astype(sim.np_float))
        sim.solver.reset_duals()
        self._apply_kinematics()

    def _apply_kinematics(self) -> None:
        """Write vertex_is_fixed / vertex_body_position: clamped roots, pins (where the groom has the
        vertex now) and the drag (its current prescribed positions).  Body 0 stays the identity."""
        sim = self._sim
        fixed = sim.base_fixed.copy()
        body = sim.base_body.copy()
        if self.groom.pinned.any():  # (the proxy map costs a pass over every vertex)
            pinned = self._grabbable(self.groom.pinned)
            rows = sim.row_of[pinned]
            fixed[rows] = 1
            body[rows] = self.groom.points[pinned].astype(np.float64)
        sim.drag_rows = np.zeros(0, dtype=np.int64)
        if self._drag is not None:
            sim.drag_rows = sim.row_of[self._drag["vertices"]]
            fixed[sim.drag_rows] = 1
            body[sim.drag_rows] = self._drag["position"]
        sim.body = body
        sim.model.vertex_is_fixed.from_numpy(fixed.astype(np.int32))
        sim.model.vertex_body_position.from_numpy(body.astype(sim.np_float))

    def _write_back(self) -> None:
        """groom.points <- simulated guides (State) and skinned strands, in the groom's dtype."""
        sim = self._sim
        x = sim.state.vertex_position.to_numpy()
        if sim.skin is not None:
            sim.skin.deform(sim.state, sim.control)
            pts = sim.skin.positions().astype(self.groom.points.dtype)
        else:
            pts = self.groom.points.copy()
        pts[sim.guide_vertex] = x.astype(pts.dtype)
        self.groom = replace(self.groom, points=pts, params=dict(self.groom.params))
