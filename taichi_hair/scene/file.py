"""TOML scene files: a groom, body colliders and their animation, a solver, frames and output.

    from taichi_hair.scene.file import load_scene
    scene = load_scene("assets/scenes/head_turn.toml", overrides={"frames": 2, "strands": 20})
    model = scene.build_model()                 # after ti.init
    solver = scene.make_solver(model)
    for body, (R, T) in enumerate(scene.body_transforms(t)): control.set_body_transform(body, R, T)

A scene file (every table but ``[groom]`` optional; every length in metres, times in seconds, angles in
degrees; relative paths are relative to the scene file)::

    [scene]
    name = "head-turn"           # default: the file name
    frames = 48                  # frames to simulate [-]
    fps = 24.0                   # frames per second [1/s]
    substeps = 4                 # solver steps per frame [-]
    gravity = [0.0, -9.81, 0.0]  # [m/s^2]
    output = "out/head_turn.usd" # default output when the command line gives no --out

    [groom]                      # either a file ...
    file = "../ponytail/tail.tfx"   # or a list of files, concatenated
    scale = 0.0035               # file units -> metres (or units = "cm" / "mm" / "m" / "in")
    strands = 100                # optional: keep this many strands, evenly spaced through the file
    root = "clamped"             # "clamped" (roots follow `body`) or "free"
    body = 0                     # body the roots are clamped to
    # ... or a generator (taichi_hair.groom.generators.GeneratorConfig fields; style = the generator name):
    generator = "wavy"           # "straight", "wavy" or "curly"
    surface = "head"             # "head" (assets/head.obj), "sphere", or a mesh path (OBJ, group "scalp")
    sphere_radius = 0.09         # surface = "sphere": radius [m] ...
    sphere_center = [0, 0, 0]    # ... centre [m] ...
    scalp_min_y = 0.0            # ... and scalp cap (y - centre_y > scalp_min_y * radius)
    strands = 300                # and any other GeneratorConfig field: length, length_spread, radius, seed...

    [material]                   # taichi_hair.RodMaterial fields; radius defaults to the groom's radii
    youngs_modulus_bend = 3e9

    [solver]
    type = "admm"                # "admm" (Daviet 2023, the main solver), "shape" (Han & Harada) or "xpbd"
    iterations = 10              # and any other field of that solver's config dataclass
    integrator = "bdf2"          # admm: "backward_euler" (default, the paper's) or "bdf2" (second order)
    # shape (SolverShapeConfig): substeps = 2 (per scene substep), follow_the_leader = true,
    # length_velocity_correction = 1.0, shock_propagation = 0.0, shock_acceleration_threshold = 50.0 [m/s^2]
    [solver.contacts]            # admm: ContactConfig fields; the table turns hair-hair contacts on
    friction = 0.2
    [solver.region]              # shape: one ShapeRegion for every strand

    [[colliders]]                # type = "sphere" | "capsule" | "plane" | "mesh", then the collider's fields
    type = "mesh"
    file = "../head.obj"         # mesh: the file; scale = 1.0 multiplies its coordinates
    body = 0                     # -1: static world
    friction = 0.3

    [[bodies]]                   # body 0, body 1, ... (a body nobody animates stays at rest)
    preset = "head_turn"         # "still", "head_turn" (yaw about y), "nod" (pitch about x), "hairball"
    amplitude = 40.0             # head_turn, nod: peak angle [deg]
    period = 2.0                 # head_turn, nod: duration of one cycle [s]
    start = 0.25                 # head_turn, nod: rest time before the motion [s]
    cycles = 1                   # head_turn, nod: number of cycles [-]
    pivot = [0.0, 0.0, 0.0]      # rotations are about this point of the body frame [m]
    # ... or keyframes, slerped in rotation and linear in translation:
    # keys = [{time = 0.0, euler = [0, 0, 0], translation = [0, 0, 0]}, {time = 1.0, euler = [0, 45, 0]}]
    # interpolation = "smooth"   # "smooth" (ease in/out per segment: zero velocity at keys) or "linear"

Euler angles ``euler = [x, y, z]`` [deg] give R = Rz(z) Ry(y) Rx(x); a key may instead give
``quaternion = [w, x, y, z]``.  Before the first key and after the last the transform holds still.

Unknown tables and keys, wrong types and bad values raise ``SceneError`` (a ``ValueError``) naming the
file, the table and the key.
"""

from __future__ import annotations

import dataclasses
import math
import os
import tomllib
from dataclasses import dataclass, field

import numpy as np

SOLVERS = ("admm", "shape", "xpbd")
COLLIDER_TYPES = ("sphere", "capsule", "plane", "mesh")
PRESETS = ("still", "head_turn", "nod", "hairball")
UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254}
TOP_LEVEL = ("scene", "groom", "material", "solver", "colliders", "bodies")


class SceneError(ValueError):
    """A bad scene file: the message names the file, the table and the key."""


# --------------------------------------------------------------------------- table reader
class _Table:
    """Typed, strict access to one TOML table: every key must be read, or ``done`` names the unknown one."""

    def __init__(self, path: str, name: str, data):
        self.path, self.name = path, name
        if not isinstance(data, dict):
            self.fail(f"must be a table, got {type(data).__name__}")
        self.data = data
        self.used = set()

    def fail(self, msg: str, key: str | None = None):
        where = f"[{self.name}]" + (f" {key}" if key else "")
        raise SceneError(f"{self.path}: {where}: {msg}")

    def has(self, key) -> bool:
        return key in self.data

    def get(self, key, kind, default=None, check=None):
        """Value of ``key`` converted to ``kind`` ("float", "int", "str", "bool", "vec3", "list", "table")."""
        self.used.add(key)
        if key not in self.data:
            return default
        v = self.data[key]
        try:
            v = _convert(v, kind)
        except (TypeError, ValueError) as exc:
            self.fail(str(exc), key)
        if check is not None:
            msg = check(v)
            if msg:
                self.fail(msg, key)
        return v

    def rest(self, exclude=()) -> dict:
        """The keys not read yet (for a dataclass), marked as read."""
        out = {k: v for k, v in self.data.items() if k not in self.used and k not in exclude}
        self.used.update(out)
        return out

    def done(self, known=()):
        unknown = [k for k in self.data if k not in self.used]
        if unknown:
            names = sorted(set(self.used) | set(known))
            self.fail(f"unknown key {unknown[0]!r} (known: {', '.join(names)})", None)


def _convert(v, kind):
    if kind == "float":
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ValueError(f"expected a finite number, got {v!r}")
        return float(v)
    if kind == "int":
        if isinstance(v, bool) or not isinstance(v, int):
            raise ValueError(f"expected an integer, got {v!r}")
        return v
    if kind == "str":
        if not isinstance(v, str):
            raise ValueError(f"expected a string, got {v!r}")
        return v
    if kind == "bool":
        if not isinstance(v, bool):
            raise ValueError(f"expected true or false, got {v!r}")
        return v
    if kind in ("vec3", "vec4"):
        n = int(kind[-1])
        if not (isinstance(v, list) and len(v) == n and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                         and math.isfinite(x) for x in v)):
            raise ValueError(f"expected a list of {n} finite numbers, got {v!r}")
        return tuple(float(x) for x in v)
    if kind == "list":
        if not isinstance(v, list):
            raise ValueError(f"expected a list, got {v!r}")
        return v
    if kind == "table":
        if not isinstance(v, dict):
            raise ValueError(f"expected a table, got {v!r}")
        return v
    raise AssertionError(kind)


def _positive(v):
    return None if v > 0 else f"must be > 0, got {v!r}"


def _at_least(lo):
    return lambda v: None if v >= lo else f"must be >= {lo}, got {v!r}"


def _dataclass_from(table: _Table, cls, values: dict, what: str):
    """``cls(**values)`` with unknown keys and invalid values reported against the table."""
    names = {f.name for f in dataclasses.fields(cls)}
    for k in values:
        if k not in names:
            table.fail(f"unknown key {k!r} for {what} (known: {', '.join(sorted(names))})")
    try:
        return cls(**values)
    except (TypeError, ValueError) as exc:
        table.fail(str(exc))


# --------------------------------------------------------------------------- rotations and animation
def euler_to_matrix(euler_deg) -> np.ndarray:
    """R = Rz(z) Ry(y) Rx(x) for ``euler_deg = (x, y, z)`` [deg]."""
    x, y, z = (math.radians(a) for a in euler_deg)
    cx, sx, cy, sy, cz, sz = math.cos(x), math.sin(x), math.cos(y), math.sin(y), math.cos(z), math.sin(z)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def quat_to_matrix(q) -> np.ndarray:
    """Rotation matrix of the unit quaternion q = (w, x, y, z)."""
    w, x, y, z = np.asarray(q, np.float64) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def matrix_to_quat(R) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation matrix (Shepperd's method)."""
    R = np.asarray(R, np.float64)
    t = np.trace(R)
    if t > 0:
        s = 2 * math.sqrt(t + 1)
        q = [0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s]
    else:
        i = int(np.argmax(np.diag(R)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2 * math.sqrt(1 + R[i, i] - R[j, j] - R[k, k])
        q = [0.0] * 4
        q[0] = (R[k, j] - R[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (R[j, i] + R[i, j]) / s
        q[1 + k] = (R[k, i] + R[i, k]) / s
    q = np.asarray(q)
    return q / np.linalg.norm(q)


def slerp(q0, q1, u: float) -> np.ndarray:
    """Spherical linear interpolation of unit quaternions (shortest arc)."""
    q0, q1 = np.asarray(q0, np.float64), np.asarray(q1, np.float64)
    d = float(np.dot(q0, q1))
    if d < 0:
        q1, d = -q1, -d
    if d > 0.9995:
        q = q0 + u * (q1 - q0)
        return q / np.linalg.norm(q)
    th = math.acos(min(d, 1.0))
    return (math.sin((1 - u) * th) * q0 + math.sin(u * th) * q1) / math.sin(th)


@dataclass
class Keyframe:
    """One key of a rigid body animation.

    Attributes:
        time: time of the key [s].
        rotation: unit quaternion (w, x, y, z) of the body rotation [-].
        translation: body translation [m].
    """

    time: float
    rotation: np.ndarray
    translation: np.ndarray


@dataclass
class BodyAnimation:
    """Rigid transform of one body over time: keyframes, or a function of time.

    Attributes:
        keys: keyframes in increasing time (used when ``function`` is None).
        interpolation: ``"smooth"`` (smoothstep easing within each segment: the body stops at every
            key, so accelerations stay finite) or ``"linear"`` (constant angular velocity between keys).
        function: optional ``function(time [s]) -> 3x3 rotation`` (the named scenes' continuous motions).
        pivot: the rotation is about this point of the body frame [m]: T_total = T + pivot - R pivot.
        description: JSON-able description (for the checkpoint fingerprint and summaries).
    """

    keys: list = field(default_factory=list)
    interpolation: str = "smooth"
    function: object = None
    pivot: tuple = (0.0, 0.0, 0.0)
    description: dict = field(default_factory=dict)

    def transform(self, time: float):
        """(rotation 3x3 [-], translation (3,) [m]) at ``time`` [s]."""
        if self.function is not None:
            R, T = np.asarray(self.function(time), np.float64), np.zeros(3)
        elif not self.keys:
            R, T = np.eye(3), np.zeros(3)
        else:
            ks = self.keys
            if time <= ks[0].time:
                q, T = ks[0].rotation, ks[0].translation
            elif time >= ks[-1].time:
                q, T = ks[-1].rotation, ks[-1].translation
            else:
                i = int(np.searchsorted([k.time for k in ks], time, side="right")) - 1
                a, b = ks[i], ks[i + 1]
                u = (time - a.time) / (b.time - a.time)
                if self.interpolation == "smooth":
                    u = u * u * (3 - 2 * u)
                q = slerp(a.rotation, b.rotation, u)
                T = (1 - u) * a.translation + u * b.translation
            R = quat_to_matrix(q)
        p = np.asarray(self.pivot, np.float64)
        return R, np.asarray(T, np.float64) + p - R @ p


def _preset_keys(preset: str, axis, amplitude: float, period: float, start: float, cycles: int):
    """head_turn / nod as keys: rest, +amplitude, -amplitude, rest per cycle, about ``axis``."""
    keys = [Keyframe(0.0, np.array([1.0, 0, 0, 0]), np.zeros(3))]
    a = np.asarray(axis, np.float64)

    def q(angle_deg):
        h = math.radians(angle_deg) / 2
        return np.r_[math.cos(h), math.sin(h) * a]

    t = start
    for _ in range(cycles):
        for frac, ang in ((0.25, amplitude), (0.75, -amplitude), (1.0, 0.0)):
            keys.append(Keyframe(t + frac * period, q(ang), np.zeros(3)))
        t += period
    if start > 0:
        keys.insert(1, Keyframe(start, np.array([1.0, 0, 0, 0]), np.zeros(3)))
    return keys


# --------------------------------------------------------------------------- the scene
@dataclass
class Scene:
    """A resolved scene, ready to build (see the module docstring for the file format).

    Attributes:
        name: scene name.
        path: the scene file, or "" for a built-in scene.
        frames: frames to simulate [-].
        fps: frames per second [1/s].
        substeps: solver steps per frame [-].
        gravity: gravitational acceleration [m/s^2].
        groom: the strands (a :class:`~taichi_hair.io.groom.Groom` in metres).
        root: "clamped" or "free".
        root_body: body index the clamped roots follow [-].
        material: RodMaterial fields (dict); ``radius`` from the groom per strand unless given.
        solver: "admm", "shape" or "xpbd".
        solver_config: the solver's config dataclass.
        colliders: collider objects of :mod:`taichi_hair.contact.colliders`.
        bodies: one :class:`BodyAnimation` per body.
        output: default output path ("" when none), resolved against the current directory.
        description: JSON-able description of everything that determines the result
            (checkpoints compare it before resuming).
        model_builder: optional callable returning the Model (the built-in scenes use their own builders).
    """

    name: str
    path: str
    frames: int
    fps: float
    substeps: int
    gravity: tuple
    groom: object
    root: str = "clamped"
    root_body: int = 0
    material: dict = field(default_factory=dict)
    solver: str = "admm"
    solver_config: object = None
    colliders: list = field(default_factory=list)
    bodies: list = field(default_factory=list)
    output: str = ""
    description: dict = field(default_factory=dict)
    model_builder: object = None

    @property
    def body_count(self) -> int:
        """Bodies: those of [[bodies]], and at least up to the roots' body."""
        return max(len(self.bodies), 1 + self.root_body)

    def body_transforms(self, time: float):
        """[(R, T)] of every body at ``time`` [s]."""
        out = []
        for b in range(self.body_count):
            out.append(self.bodies[b].transform(time) if b < len(self.bodies) else (np.eye(3), np.zeros(3)))
        return out

    def build_model(self):
        """The Model (allocates Taichi fields: call after ``ti.init``)."""
        if self.model_builder is not None:
            return self.model_builder()
        from ..builder import GroomBuilder
        from ..config import RodMaterial

        b = GroomBuilder(body_count=self.body_count)
        g = self.groom
        radius = None if "radius" in self.material or g.radius is None else g.radius
        try:
            shared = RodMaterial(**self.material)
            for s in range(g.strand_count):
                mat = shared if radius is None else RodMaterial(**{**self.material, "radius": float(
                    np.mean(radius[g.strand_offsets[s]:g.strand_offsets[s + 1]]) if radius.shape[0] == g.vertex_count
                    else radius[s])})
                b.add_strand(g.strand(s).astype(np.float64), mat, root=self.root, body=self.root_body)
        except ValueError as exc:
            raise SceneError(f"{self.path or self.name}: [groom] {exc}") from None
        return b.finalize()

    def make_solver(self, model, profile: bool = False):
        """The solver of the scene, with its colliders."""
        from ..solvers import make_solver

        return make_solver(self.solver, model, self.solver_config, colliders=self.colliders, profile=profile)


def _resolve(base_dir: str, p: str) -> str:
    p = os.path.expanduser(p)
    return p if os.path.isabs(p) else os.path.normpath(os.path.join(base_dir, p))


def _subsample(groom, count: int):
    """``count`` strands evenly spaced through the groom (all when it has fewer)."""
    from ..io.groom import Groom

    ns = groom.strand_count
    if count >= ns:
        return groom
    idx = np.unique(np.linspace(0, ns - 1, count).round().astype(int))
    off = groom.strand_offsets
    verts = np.concatenate([np.arange(off[s], off[s + 1]) for s in idx])
    counts = off[idx + 1] - off[idx]

    def pick(a, per_vertex_ok=True):
        if a is None:
            return None
        if a.shape[0] == groom.vertex_count and per_vertex_ok:
            return a[verts]
        return a[idx]

    return Groom(points=groom.points[verts], strand_offsets=np.r_[0, np.cumsum(counts)].astype(np.int64),
                 radius=pick(groom.radius), color=pick(groom.color), region=pick(groom.region, False),
                 guide=pick(groom.guide, False), rest_points=None if groom.rest_points is None
                 else groom.rest_points[verts], pinned=None if groom.pinned is None else groom.pinned[verts],
                 params=dict(groom.params), units=groom.units).validate()


def _load_groom_table(t: _Table, base: str, overrides: dict, desc: dict):
    from ..groom.generators import STYLES, GeneratorConfig, generate_groom, load_head, sphere_surface
    from ..io import UnitsWarning, load_groom, units_warning
    from ..io.groom import Groom

    root = t.get("root", "str", "clamped", lambda v: None if v in ("clamped", "free") else
                 f"must be 'clamped' or 'free', got {v!r}")
    body = t.get("body", "int", 0, _at_least(0))
    desc.update(root=root, body=body)
    if t.has("file") == t.has("generator"):
        t.fail("give either 'file' (a groom file) or 'generator' (one of " + ", ".join(STYLES) + ")")
    if t.has("file"):
        files = t.data["file"]
        t.used.add("file")
        files = [files] if isinstance(files, str) else files
        if not (isinstance(files, list) and files and all(isinstance(f, str) for f in files)):
            t.fail("must be a file name or a list of file names", "file")
        scale = t.get("scale", "float", None, _positive)
        units = t.get("units", "str", None, lambda v: None if v in UNITS else
                      f"must be one of {', '.join(UNITS)}, got {v!r}")
        if scale is not None and units is not None:
            t.fail("give 'scale' or 'units', not both")
        scale = scale if scale is not None else UNITS[units] if units else 1.0
        fmt = t.get("format", "str", None)
        strands = t.get("strands", "int", None, _at_least(1))
        if "strands" in overrides:
            strands = overrides["strands"]
        for key in ("length", "seed", "vertices_per_strand"):
            if key in overrides:
                raise SceneError(f"{t.path}: [groom]: --{key.replace('_', '-')} applies to generated grooms; "
                                 f"this scene reads {files[0]}")
        t.done()
        parts = []
        import warnings
        for f in files:
            p = _resolve(base, f)
            if not os.path.exists(p):
                t.fail(f"no such file: {p}", "file")
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                g = load_groom(p, format=fmt, scale=scale)
            for w in caught:  # the reader's own notes pass; the unit check is redone below for the scene
                if not issubclass(w.category, UnitsWarning):
                    warnings.warn(w.message, w.category, stacklevel=2)
            msg = units_warning(g, f"{t.path}: [groom] file {f}", applied_scale=scale, context="scene")
            if msg:
                warnings.warn(msg, UnitsWarning, stacklevel=2)
            parts.append(g)
        if len(parts) == 1:
            groom = parts[0]
        else:
            polys = [pl.astype(np.float64) for g in parts for pl in g.to_polylines()]
            radii = [g.radius if g.radius is not None and g.radius.shape[0] == g.strand_count else None
                     for g in parts]
            radius = np.concatenate(radii) if all(r is not None for r in radii) else None
            groom = Groom.from_polylines(polys, radius=radius, units="m")
        if strands is not None:
            groom = _subsample(groom, strands)
        desc.update(file=[_resolve(base, f) for f in files], scale=scale, strands=groom.strand_count)
        return groom, root, body
    style = t.get("generator", "str", None, lambda v: None if v in STYLES else
                  f"must be one of {', '.join(STYLES)}, got {v!r}")
    surface = t.get("surface", "str", "head")
    sph_r = t.get("sphere_radius", "float", 0.09, _positive)
    sph_c = t.get("sphere_center", "vec3", (0.0, 0.0, 0.0))
    cap = t.get("scalp_min_y", "float", 0.0)
    if surface != "sphere" and any(t.has(k) for k in ("sphere_radius", "sphere_center", "scalp_min_y")):
        t.fail("sphere_radius, sphere_center and scalp_min_y need surface = \"sphere\"")
    values = t.rest()
    for key in ("strands", "length", "seed", "vertices_per_strand"):
        if key in overrides:
            values[key] = overrides[key]
    if "down" in values and isinstance(values["down"], list):
        values["down"] = tuple(values["down"])
    cfg = _dataclass_from(t, GeneratorConfig, dict(values, style=style), "the generator")
    try:
        if surface == "sphere":
            surf = sphere_surface(sph_r, sph_c, cap)
        elif surface == "head":
            surf = load_head()
        else:
            surf = load_head(_resolve(base, surface))
    except ValueError as exc:
        t.fail(str(exc), "surface")
    groom = generate_groom(surf, cfg)
    desc.update(generator=dataclasses.asdict(cfg), surface=surface, sphere=[sph_r, list(sph_c), cap])
    desc["generator"]["down"] = list(cfg.down)
    return groom, root, body


def _collider(t: _Table, base: str):
    from ..contact.colliders import CapsuleCollider, MeshCollider, PlaneCollider, SphereCollider

    kind = t.get("type", "str", None, lambda v: None if v in COLLIDER_TYPES else
                 f"must be one of {', '.join(COLLIDER_TYPES)}, got {v!r}")
    if kind is None:
        t.fail("missing key 'type' (one of " + ", ".join(COLLIDER_TYPES) + ")")
    common = dict(friction=t.get("friction", "float", 0.3), body=t.get("body", "int", -1))
    if t.has("strands"):
        s = t.get("strands", "list")
        common["strands"] = tuple(s)
    desc = {"type": kind, **common}
    try:
        if kind == "sphere":
            c = SphereCollider(center=t.get("center", "vec3", (0.0, 0.0, 0.0)),
                               radius=t.get("radius", "float", 0.1), **common)
        elif kind == "capsule":
            c = CapsuleCollider(p0=t.get("p0", "vec3", (0.0, 0.0, 0.0)), p1=t.get("p1", "vec3", (0.0, 0.1, 0.0)),
                                radius=t.get("radius", "float", 0.05), **common)
        elif kind == "plane":
            c = PlaneCollider(point=t.get("point", "vec3", (0.0, 0.0, 0.0)),
                              normal=t.get("normal", "vec3", (0.0, 1.0, 0.0)), **common)
        else:
            f = t.get("file", "str", None)
            if f is None:
                t.fail("missing key 'file' (the mesh)")
            p = _resolve(base, f)
            if not os.path.exists(p):
                t.fail(f"no such file: {p}", "file")
            scale = t.get("scale", "float", 1.0, _positive)
            res = t.get("resolution", "int", 64)
            pad = t.get("padding", "float", 0.15)
            thick = t.get("thickness", "float", 1e-3)
            t.done()
            mesh = p
            if scale != 1.0:
                import trimesh

                try:
                    mesh = trimesh.load(p, force="mesh")
                except Exception as exc:  # noqa: BLE001 - trimesh raises many types
                    t.fail(f"cannot load {p}: {exc}", "file")
                mesh.apply_scale(scale)
            c = MeshCollider(mesh=mesh, resolution=res, padding=pad, thickness=thick, **common)
            desc.update(file=p, scale=scale, resolution=res, padding=pad, thickness=thick)
    except ValueError as exc:
        t.fail(str(exc))
    t.done()
    for k in ("center", "radius", "p0", "p1", "point", "normal"):
        if hasattr(c, k) and not isinstance(c, MeshCollider):
            v = getattr(c, k)
            desc[k] = np.asarray(v).tolist() if not isinstance(v, float) else v
    return c, desc


def _body(t: _Table):
    pivot = t.get("pivot", "vec3", (0.0, 0.0, 0.0))
    if t.has("preset") and t.has("keys"):
        t.fail("give either 'preset' or 'keys', not both")
    if t.has("keys"):
        interp = t.get("interpolation", "str", "smooth", lambda v: None if v in ("smooth", "linear") else
                       f"must be 'smooth' or 'linear', got {v!r}")
        raw = t.get("keys", "list")
        keys, desc_keys = [], []
        for i, k in enumerate(raw):
            kt = _Table(t.path, f"{t.name}.keys[{i}]", k)
            time = kt.get("time", "float", None)
            if time is None:
                kt.fail("missing key 'time'")
            if kt.has("euler") and kt.has("quaternion"):
                kt.fail("give 'euler' or 'quaternion', not both")
            if kt.has("quaternion"):
                q = np.asarray(kt.get("quaternion", "vec4"))
                if np.linalg.norm(q) < 1e-12:
                    kt.fail("must not be zero", "quaternion")
                q = q / np.linalg.norm(q)
            else:
                q = matrix_to_quat(euler_to_matrix(kt.get("euler", "vec3", (0.0, 0.0, 0.0))))
            tr = np.asarray(kt.get("translation", "vec3", (0.0, 0.0, 0.0)))
            kt.done()
            if keys and time <= keys[-1].time:
                kt.fail(f"times must increase (key {i - 1} is at {keys[-1].time} s)", "time")
            keys.append(Keyframe(time, q, tr))
            desc_keys.append([time, q.tolist(), tr.tolist()])
        t.done()
        return BodyAnimation(keys=keys, interpolation=interp, pivot=pivot,
                             description={"keys": desc_keys, "interpolation": interp, "pivot": list(pivot)})
    preset = t.get("preset", "str", "still", lambda v: None if v in PRESETS else
                   f"must be one of {', '.join(PRESETS)}, got {v!r}")
    desc = {"preset": preset, "pivot": list(pivot)}
    if preset == "still":
        t.done()
        return BodyAnimation(pivot=pivot, description=desc)
    if preset == "hairball":
        t.done()
        from .builtin import hairball_rotation

        return BodyAnimation(function=hairball_rotation, pivot=pivot, description=desc)
    default_amp = 40.0 if preset == "head_turn" else 15.0
    amp = t.get("amplitude", "float", default_amp)
    period = t.get("period", "float", 2.0 if preset == "head_turn" else 1.5, _positive)
    start = t.get("start", "float", 0.25, _at_least(0.0))
    cycles = t.get("cycles", "int", 1, _at_least(1))
    t.done()
    axis = (0.0, 1.0, 0.0) if preset == "head_turn" else (1.0, 0.0, 0.0)
    desc.update(amplitude=amp, period=period, start=start, cycles=cycles)
    return BodyAnimation(keys=_preset_keys(preset, axis, amp, period, start, cycles), pivot=pivot,
                         description=desc)


def _solver(t: _Table, overrides: dict, colliders: list):
    from ..config import ContactConfig, SolverADMMConfig
    from ..solvers.shape.solver import ShapeRegion, SolverShapeConfig
    from ..solvers.xpbd.solver import SolverXPBDConfig

    kind = t.get("type", "str", "admm", lambda v: None if v in SOLVERS else
                 f"must be one of {', '.join(SOLVERS)}, got {v!r}")
    values = t.rest(exclude=("contacts", "region"))
    if kind != "admm" and overrides.get("continuous"):
        t.fail(f"--continuous applies to type = \"admm\", not {kind!r}", "type")
    if kind == "shape" and "iterations" in overrides:
        t.fail("--iterations applies to type = \"admm\" or \"xpbd\"; set [solver.region] "
               "local_iterations / length_iterations for \"shape\"", "type")
    if "iterations" in overrides:
        values["iterations"] = overrides["iterations"]
    if overrides.get("integrator"):
        if kind != "admm":
            t.fail(f"--integrator applies to type = \"admm\", not {kind!r}", "type")
        values["integrator"] = overrides["integrator"]
    desc = {"type": kind, **{k: v for k, v in values.items()}}
    if kind == "admm":
        contacts = t.get("contacts", "table", None)
        if t.has("region"):
            t.fail("[solver.region] is for type = \"shape\"", "region")
        if contacts is None and overrides.get("continuous"):
            t.fail("--continuous needs hair contacts: add a [solver.contacts] table", "contacts")
        if contacts is not None:
            ct = _Table(t.path, f"{t.name}.contacts", contacts)
            cvalues = ct.rest()
            if overrides.get("continuous"):
                cvalues["continuous_detections"] = overrides["continuous"]
            values["contacts"] = _dataclass_from(ct, ContactConfig, cvalues, "ContactConfig")
            desc["contacts"] = cvalues
        cfg = _dataclass_from(t, SolverADMMConfig, values, "SolverADMMConfig")
    elif kind == "shape":
        if t.has("contacts"):
            t.fail("[solver.contacts] is for type = \"admm\"", "contacts")
        region = t.get("region", "table", {})
        rt = _Table(t.path, f"{t.name}.region", region)
        reg = _dataclass_from(rt, ShapeRegion, rt.rest(), "ShapeRegion")
        desc["region"] = region
        cfg = _dataclass_from(t, SolverShapeConfig, dict(values, regions=(reg,)), "SolverShapeConfig")
    else:
        for k in ("contacts", "region"):
            if t.has(k):
                t.fail(f"[solver.{k}] is not for type = \"xpbd\"", k)
        if colliders:
            raise SceneError(f"{t.path}: [[colliders]]: solver type \"xpbd\" has no collisions; remove the "
                             f"colliders or use type = \"admm\"")
        cfg = _dataclass_from(t, SolverXPBDConfig, values, "SolverXPBDConfig")
    t.done()
    return kind, cfg, desc


def load_scene(path, overrides: dict | None = None) -> Scene:
    """Read and validate a TOML scene file.

    Args:
        path: the ``.toml`` file.
        overrides: command-line values that replace the file's: ``frames``, ``fps``, ``substeps``,
            ``strands`` (generator count, or the strands kept from a file), ``length``, ``seed`` and
            ``vertices_per_strand`` (generators only), ``iterations`` (solver), ``integrator`` (admm), ``continuous`` (admm
            contact detections).

    Raises:
        SceneError: naming the file, the table and the key.
    """
    path = os.fspath(path)
    overrides = {k: v for k, v in (overrides or {}).items() if v is not None}
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except OSError as exc:
        raise SceneError(f"{path}: cannot read the scene ({exc.strerror})") from None
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{path}: not valid TOML ({exc})") from None
    base = os.path.dirname(os.path.abspath(path))
    for k in data:
        if k not in TOP_LEVEL:
            raise SceneError(f"{path}: unknown table or key {k!r} (known: {', '.join(TOP_LEVEL)})")
    st = _Table(path, "scene", data.get("scene", {}))
    name = st.get("name", "str", os.path.splitext(os.path.basename(path))[0])
    frames = st.get("frames", "int", 48, _at_least(1))
    fps = st.get("fps", "float", 24.0, _positive)
    substeps = st.get("substeps", "int", 4, _at_least(1))
    gravity = st.get("gravity", "vec3", (0.0, -9.81, 0.0))
    output = st.get("output", "str", "")
    st.done()
    frames = overrides.get("frames", frames)
    fps = overrides.get("fps", fps)
    substeps = overrides.get("substeps", substeps)
    if "groom" not in data:
        raise SceneError(f"{path}: missing table [groom] (a 'file' or a 'generator')")
    gdesc = {}
    groom, root, body = _load_groom_table(_Table(path, "groom", data["groom"]), base, overrides, gdesc)
    mt = _Table(path, "material", data.get("material", {}))
    from ..config import RodMaterial

    material = mt.rest()
    _dataclass_from(mt, RodMaterial, material, "RodMaterial")  # validate now, with the table's name
    colliders, cdesc = [], []
    raw = data.get("colliders", [])
    if not isinstance(raw, list):
        raise SceneError(f"{path}: 'colliders' must be an array of tables ([[colliders]])")
    for i, c in enumerate(raw):
        col, d = _collider(_Table(path, f"colliders {i}", c), base)
        colliders.append(col)
        cdesc.append(d)
    raw = data.get("bodies", [])
    if not isinstance(raw, list):
        raise SceneError(f"{path}: 'bodies' must be an array of tables ([[bodies]])")
    bodies = [_body(_Table(path, f"bodies {i}", b)) for i, b in enumerate(raw)]
    kind, cfg, sdesc = _solver(_Table(path, "solver", data.get("solver", {})), overrides, colliders)
    import hashlib

    gdesc["points_sha1"] = hashlib.sha1(np.ascontiguousarray(groom.points).tobytes()).hexdigest()
    desc = {"name": name, "fps": fps, "substeps": substeps, "gravity": list(gravity), "groom": gdesc,
            "material": material, "solver": sdesc, "colliders": cdesc,
            "bodies": [b.description for b in bodies]}
    scene = Scene(name=name, path=path, frames=frames, fps=fps, substeps=substeps, gravity=gravity, groom=groom,
                  root=root, root_body=body, material=material, solver=kind, solver_config=cfg, colliders=colliders,
                  bodies=bodies, output=_resolve(base, output) if output else "", description=desc)
    for k, c in enumerate(colliders):
        if c.body >= scene.body_count:
            raise SceneError(f"{path}: [colliders {k}] body: {c.body} is not a body of the scene (it has "
                             f"{scene.body_count}: add [[bodies]] tables, or -1 for the static world)")
    return scene
