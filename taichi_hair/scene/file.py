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
    rest_pose = "authored"       # "sag-free": rest strains solved so the shape holds under gravity;
                                 # "file": the file's rest curve (rest points, e.g. from taichi-hair rest-pose)
    rest_pose_check = false      # sag-free: also find the held strands that are unstable equilibria (a 2 s run)
    rest_pose_support = "none"   # sag-free: "unheld" lets the colliders carry the strands that cannot hold
                                 # themselves (contact forces in the Coulomb cones), "all" every strand on them
    rest_max_change = 1.0        # sag-free: largest rest strain change of a held strand (~60 degrees per vertex)
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
``quaternion = [w, x, y, z]`` (scalar first; :mod:`taichi_hair.rotation` stores (x, y, z, w), the key is
converted when read).  Before the first key and after the last the transform holds still.

Unknown tables and keys, wrong types and bad values raise ``SceneError`` (a ``ValueError``) naming the
file, the table and the key.  The format is read by :mod:`.schema` (the table reader), :mod:`.setup`
(groom, colliders, solver) and :mod:`.animation` (the bodies); this module holds :class:`Scene` and
:func:`load_scene`.
"""

from __future__ import annotations

import os
import tomllib
from dataclasses import dataclass, field

import numpy as np

from .animation import PRESETS, BodyAnimation, Keyframe, body_from_table
from .schema import SceneError, Table, at_least, dataclass_from, positive
from .setup import COLLIDER_TYPES, SOLVERS, UNITS, collider_from_table, groom_from_table, resolve_path, solver_from_table

__all__ = ["BodyAnimation", "COLLIDER_TYPES", "Keyframe", "PRESETS", "SOLVERS", "Scene", "SceneError", "TOP_LEVEL",
           "UNITS", "load_scene"]
TOP_LEVEL = ("scene", "groom", "material", "solver", "colliders", "bodies")


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
        groom_builder: optional callable returning the groom's
            :class:`~taichi_hair.builder.GroomBuilder`, not finalized (the built-in scenes use their own).
        rest_pose: "authored", "sag-free" or "file" ([groom] rest_pose; :mod:`taichi_hair.solvers.rest_pose`).
        rest_pose_check: also run ``check_stability`` after a sag-free solve ([groom] rest_pose_check).
        rest_pose_support: ``"none"``, ``"unheld"`` or ``"all"``: which strands the colliders may carry in the
            sag-free solve ([groom] rest_pose_support; :mod:`taichi_hair.solvers.rest_support`).
        rest_max_change: the sag-free solve's ``RestPoseConfig.max_rest_change`` ([groom] rest_max_change).
        rest_pose_result: the :class:`~taichi_hair.solvers.rest_pose.RestPoseResult` of the last
            :meth:`build_model` of a sag-free scene (None otherwise).
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
    groom_builder: object = None
    rest_pose: str = "authored"
    rest_pose_check: bool = False
    rest_pose_support: str = "none"
    rest_max_change: float = 1.0
    rest_pose_result: object = None
    #: Vertices a ``groom_builder`` will make (built-in scenes; 0 when unknown), for the size checks.
    vertex_count_hint: int = 0

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
        """The Model (allocates Taichi fields: call after ``ti.init``), with its sag-free rest pose solved
        when ``rest_pose = "sag-free"`` (the result in :attr:`rest_pose_result`)."""
        model = self.builder().finalize()
        if self.rest_pose == "sag-free":
            self.rest_pose_result = self.solve_rest_pose(model)
        elif self.rest_pose == "file":
            self.rest_pose_result = self.rest_pose_from_file(model)
        return model

    def _gravity_in_body(self):
        R, _ = self.body_transforms(0.0)[self.root_body]
        return np.asarray(R, np.float64).T @ np.asarray(self.gravity, np.float64)

    def rest_pose_from_file(self, model):
        """Apply the rest curve the groom file carries (``rest_points``, ``rest_twist``: e.g. written by
        ``taichi-hair rest-pose``) as the rest pose of ``model``; returns its RestPoseResult (residual under
        this scene's gravity)."""
        g = self.groom
        where = f"{self.path or self.name}: [groom] rest_pose"
        if self.solver != "admm":
            raise SceneError(f"{where}: 'file' is read into the ADMM model; the scene's solver is {self.solver!r}")
        if g is None or g.rest_points is None:
            raise SceneError(f"{where}: 'file' needs a groom file with rest points (rest_points / USD primvars:rest; "
                             "taichi-hair rest-pose writes them)")
        from ..solvers.rest_curve import rest_pose_from_curve
        from ..solvers.rest_pose import apply_rest_pose

        try:
            result = rest_pose_from_curve(model, g.rest_points, g.rest_twist, self.solver_config,
                                          gravity=self._gravity_in_body())
        except ValueError as exc:
            raise SceneError(f"{where}: {exc}") from None
        apply_rest_pose(model, result)
        return result

    def solve_rest_pose(self, model):
        """Solve and apply the sag-free rest pose of ``model`` for this scene's solver and gravity (in the
        roots' body frame at time 0); returns the :class:`~taichi_hair.solvers.rest_pose.RestPoseResult`."""
        if self.solver != "admm":
            raise SceneError(f"{self.path or self.name}: [groom] rest_pose: 'sag-free' is solved for the ADMM "
                             f"model (Discrete Elastic Rods); the scene's solver is {self.solver!r}")
        from ..solvers.rest_pose import RestPoseConfig, apply_rest_pose, solve_rest_pose

        support = None
        if self.rest_pose_support != "none":
            from ..solvers.rest_support import support_from_colliders

            # Colliders on the roots' body share its frame; world colliders only while that body sits at
            # the origin at time 0 (the frame the rest pose is solved in).
            R, t = self.body_transforms(0.0)[self.root_body]
            at_origin = np.allclose(R, np.eye(3)) and np.allclose(t, 0.0)
            usable = [c for c in self.colliders if c.body == self.root_body or (c.body < 0 and at_origin)]
            support = support_from_colliders(model, usable)
        rcfg = RestPoseConfig(max_rest_change=self.rest_max_change,
                              **({} if support is None else {"support_for": self.rest_pose_support}))
        result = solve_rest_pose(model, self.solver_config, gravity=self._gravity_in_body(), config=rcfg,
                                 support=support)
        apply_rest_pose(model, result)
        if self.rest_pose_check:
            from ..solvers.rest_pose import check_stability

            check_stability(model, result, self.solver_config, gravity=self._gravity_in_body())
        return result

    def builder(self):
        """The groom's :class:`~taichi_hair.builder.GroomBuilder` with every strand added, not finalized (no
        field allocated): ``build_model`` finalizes it; a batch pack merges several (cli/simulate_pack.py)."""
        return self.groom_builder() if self.groom_builder is not None else self._groom_builder()

    def _groom_builder(self):
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
        return b

    def make_solver(self, model, profile: bool = False):
        """The solver of the scene, with its colliders."""
        from ..solvers import make_solver

        return make_solver(self.solver, model, self.solver_config, colliders=self.colliders, profile=profile)


def read_toml(path: str, what: str) -> dict:
    """The tables of a TOML file; a one-line SceneError naming the file when it cannot be read or parsed."""
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except OSError as exc:
        raise SceneError(f"{path}: cannot read {what} ({exc.strerror})") from None
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{path}: not valid TOML ({exc})") from None


def parse_set(text: str, what: str = "--set") -> tuple:
    """``KEY=VALUE`` of ``--set`` -> (KEY, value): VALUE is read as a TOML value (``0.3``, ``true``,
    ``"mesh.obj"``, ``[0, 1, 0]``); anything TOML cannot read is kept as a string."""
    key, sep, value = text.partition("=")
    key = key.strip()
    if not sep or not key:
        raise SceneError(f"{what} {text!r}: expected KEY=VALUE, e.g. solver.contacts.friction=0.3")
    try:
        return key, tomllib.loads("v = " + value.strip())["v"]
    except tomllib.TOMLDecodeError:
        return key, value.strip()


def apply_sets(data: dict, sets: dict, path: str) -> dict:
    """A copy of a scene file's tables with dotted keys set: ``solver.contacts.friction`` ->
    ``data["solver"]["contacts"]["friction"]``; an integer part indexes an array of tables
    (``colliders.0.friction``).  Unknown keys are then refused by the scene's own validation; a path through
    something that is not a table is refused here, naming the key."""
    import copy

    out = copy.deepcopy(data)
    for key, value in sets.items():
        parts = key.split(".")
        node = out
        for i, part in enumerate(parts[:-1]):
            where = ".".join(parts[:i + 1])
            if isinstance(node, list):
                if not part.isdigit() or int(part) >= len(node):
                    raise SceneError(f"{path}: set {key}: {'.'.join(parts[:i])} has {len(node)} entries, "
                                     f"{part!r} is not one of them")
                node = node[int(part)]
            elif isinstance(node, dict):
                node = node.setdefault(part, {})
            else:
                raise SceneError(f"{path}: set {key}: {where} is not a table")
            if not isinstance(node, (dict, list)):
                raise SceneError(f"{path}: set {key}: {where} is a value, not a table")
        if isinstance(node, list):
            raise SceneError(f"{path}: set {key}: {'.'.join(parts[:-1])} is an array of tables; name an entry "
                             f"({'.'.join(parts[:-1])}.0.{parts[-1]})")
        node[parts[-1]] = value
    return out


def load_scene(path, overrides: dict | None = None, sets: dict | None = None) -> Scene:
    """Read and validate a TOML scene file.

    Args:
        path: the ``.toml`` file.
        overrides: command-line values that replace the file's: ``frames``, ``fps``, ``substeps``,
            ``strands`` (generator count, or the strands kept from a file), ``length``, ``seed`` and
            ``vertices_per_strand`` (generators only), ``iterations`` (solver), ``integrator`` and ``schedule``
            (admm), ``continuous`` (admm contact detections), ``rest_pose`` ([groom] rest_pose).
        sets: any scene-file key by its dotted name (``{"solver.contacts.friction": 0.3}``;
            :func:`apply_sets`), applied to the file's tables before validation (``simulate --set``, batches).

    Raises:
        SceneError: naming the file, the table and the key.
    """
    path = os.fspath(path)
    overrides = {k: v for k, v in (overrides or {}).items() if v is not None}
    data = read_toml(path, "the scene")
    if sets:
        data = apply_sets(data, sets, path)
    return scene_from_data(data, path, os.path.dirname(os.path.abspath(path)), overrides)


def scene_from_data(data: dict, path: str, base: str, overrides: dict | None = None) -> Scene:
    """A scene from the tables of a scene file already read (``data``, as ``tomllib`` gives them).

    ``path`` names the source in messages; relative file names are relative to ``base``.  See
    :func:`load_scene` for ``overrides``."""
    overrides = {k: v for k, v in (overrides or {}).items() if v is not None}
    for k in data:
        if k not in TOP_LEVEL:
            raise SceneError(f"{path}: unknown table or key {k!r} (known: {', '.join(TOP_LEVEL)})")
    st = Table(path, "scene", data.get("scene", {}))
    name = st.get("name", "str", os.path.splitext(os.path.basename(path))[0])
    frames = st.get("frames", "int", 48, at_least(1))
    fps = st.get("fps", "float", 24.0, positive)
    substeps = st.get("substeps", "int", 4, at_least(1))
    gravity = st.get("gravity", "vec3", (0.0, -9.81, 0.0))
    output = st.get("output", "str", "")
    st.done()
    frames = overrides.get("frames", frames)
    fps = overrides.get("fps", fps)
    substeps = overrides.get("substeps", substeps)
    if "groom" not in data:
        raise SceneError(f"{path}: missing table [groom] (a 'file' or a 'generator')")
    gdesc = {}
    groom, root, body = groom_from_table(Table(path, "groom", data["groom"]), base, overrides, gdesc)
    mt = Table(path, "material", data.get("material", {}))
    from ..config import RodMaterial

    material = mt.rest()
    dataclass_from(mt, RodMaterial, material, "RodMaterial")  # validate now, with the table's name
    colliders, cdesc = [], []
    raw = data.get("colliders", [])
    if not isinstance(raw, list):
        raise SceneError(f"{path}: 'colliders' must be an array of tables ([[colliders]])")
    for i, c in enumerate(raw):
        col, d = collider_from_table(Table(path, f"colliders {i}", c), base)
        colliders.append(col)
        cdesc.append(d)
    raw = data.get("bodies", [])
    if not isinstance(raw, list):
        raise SceneError(f"{path}: 'bodies' must be an array of tables ([[bodies]])")
    bodies = [body_from_table(Table(path, f"bodies {i}", b)) for i, b in enumerate(raw)]
    kind, cfg, sdesc = solver_from_table(Table(path, "solver", data.get("solver", {})), overrides, colliders)
    import hashlib

    gdesc["points_sha1"] = hashlib.sha1(np.ascontiguousarray(groom.points).tobytes()).hexdigest()
    desc = {"name": name, "fps": fps, "substeps": substeps, "gravity": list(gravity), "groom": gdesc,
            "material": material, "solver": sdesc, "colliders": cdesc,
            "bodies": [b.description for b in bodies]}
    scene = Scene(name=name, path=path, frames=frames, fps=fps, substeps=substeps, gravity=gravity, groom=groom,
                  root=root, root_body=body, material=material, solver=kind, solver_config=cfg, colliders=colliders,
                  bodies=bodies, output=resolve_path(base, output) if output else "", description=desc,
                  rest_pose=gdesc.get("rest_pose", "authored"), rest_pose_check=bool(gdesc.get("rest_pose_check")),
                  rest_pose_support=gdesc.get("rest_pose_support", "none"),
                  rest_max_change=float(gdesc.get("rest_max_change", 1.0)))
    if scene.rest_pose == "sag-free" and kind != "admm":
        raise SceneError(f"{path}: [groom] rest_pose: 'sag-free' is solved for the ADMM model; the scene's "
                         f"[solver] type is {kind!r}")
    _warn_if_hair_far_from_colliders(scene)
    for k, c in enumerate(colliders):
        if c.body >= scene.body_count:
            raise SceneError(f"{path}: [colliders {k}] body: {c.body} is not a body of the scene (it has "
                             f"{scene.body_count}: add [[bodies]] tables, or -1 for the static world)")
    return scene


def mesh_box(c):
    """(lo, hi) [m] of a mesh collider's body-frame bounding box: its SDF box less the padding."""
    lo = np.asarray(c.origin, np.float64)
    hi = lo + c.spacing * (np.asarray(c.sdf.shape) - 1)
    pad = (hi - lo) * c.padding / (1.0 + 2.0 * c.padding)
    return lo + pad, hi - pad


def roots_near_collider(c, roots: np.ndarray) -> np.ndarray:
    """Which roots (R, 3) [m, body frame] lie near a collider's surface: within a quarter of its size (a
    mesh: nearest SDF voxel; a sphere or capsule: exact distance; a plane: everything is near)."""
    if getattr(c, "sdf", None) is not None:
        n = np.asarray(c.sdf.shape)
        lo = np.asarray(c.origin, np.float64)
        lo_box, hi_box = mesh_box(c)
        size = float(np.max(hi_box - lo_box))
        ijk = np.round((roots - lo) / c.spacing).astype(np.int64)
        inside = np.all((ijk >= 0) & (ijk < n), axis=1)
        near = np.zeros(len(roots), bool)
        ii = ijk[inside]
        near[inside] = np.abs(c.sdf[ii[:, 0], ii[:, 1], ii[:, 2]]) < 0.25 * size
        return near
    if hasattr(c, "p0"):
        a, b = np.asarray(c.p0, np.float64), np.asarray(c.p1, np.float64)
        u = np.clip((roots - a) @ (b - a) / max(float((b - a) @ (b - a)), 1e-30), 0.0, 1.0)
        d = np.linalg.norm(roots - (a + u[:, None] * (b - a)), axis=1)
        return np.abs(d - c.radius) < 0.25 * max(c.radius, float(np.linalg.norm(b - a)))
    if hasattr(c, "center"):
        d = np.linalg.norm(roots - np.asarray(c.center, np.float64), axis=1)
        return np.abs(d - c.radius) < 0.5 * c.radius
    return np.ones(len(roots), bool)


def _warn_if_hair_far_from_colliders(scene) -> None:
    """A warning when no strand root lies near any collider's surface: a groom and a body in different units
    or up axes, which would otherwise run silently with no contact at all (or with the roots deep inside)."""
    import warnings

    if not scene.colliders or scene.groom is None or scene.groom.strand_count == 0:
        return
    roots = np.asarray(scene.groom.points, np.float64)[scene.groom.strand_offsets[:-1]]
    if any(np.any(roots_near_collider(c, roots)) for c in scene.colliders):
        return
    rlo, rhi = roots.min(axis=0), roots.max(axis=0)
    warnings.warn(f"{scene.path}: no strand root lies near a collider's surface (roots span "
                  f"{np.round(rlo, 3).tolist()} to {np.round(rhi, 3).tolist()} m): check the units and the up "
                  "axis of the groom and the body", UserWarning, stacklevel=2)
