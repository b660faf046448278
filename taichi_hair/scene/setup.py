"""Scene set-up from the tables of a scene file (:mod:`taichi_hair.scene.file`): the groom (a file or a
generator), the colliders and the solver with its config.
"""

from __future__ import annotations

import dataclasses
import os

import numpy as np

from .schema import SceneError, Table, at_least, dataclass_from, positive

SOLVERS = ("admm", "shape", "xpbd")
COLLIDER_TYPES = ("sphere", "capsule", "plane", "mesh")
#: [groom] rest_pose: "authored" (rest shape = the file's shape), "sag-free" (solvers/rest_pose.py) or
#: "file" (the file's rest curve, solvers/rest_curve.py).
REST_POSES = ("authored", "sag-free", "file")
UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254}
#: The up axis of a file: "y" (the simulator's: gravity along -y) or "z" (turned by (x, y, z) -> (x, z, -y)).
UP_AXES = ("y", "z")
#: Body meshes: trimesh's formats and TressFX's collision mesh.
MESH_EXTENSIONS = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf", ".tfxmesh", ".usd", ".usda", ".usdc")


def load_body_mesh(path: str, scale: float = 1.0, up: str = "y"):
    """A body mesh as a ``trimesh.Trimesh`` in metres and y-up: OBJ, PLY, STL, ... through trimesh, or a
    TressFX ``.tfxmesh`` (its triangles; bones and skin weights are not used: the body moves rigidly).

    Raises:
        ValueError: naming the file (cannot be read, no triangles).
    """
    import trimesh

    if path.lower().endswith(".tfxmesh"):
        from ..io import read_tfxmesh

        tm = read_tfxmesh(path)
        mesh = trimesh.Trimesh(vertices=np.asarray(tm.vertices, np.float64),
                               faces=np.asarray(tm.triangles, np.int64), process=False)
    elif path.lower().endswith((".usd", ".usda", ".usdc")):
        vertices, faces, stage_scale, stage_up = usd_mesh(path)
        scale = stage_scale if stage_scale is not None else scale
        up = stage_up if stage_up is not None else up
        mesh = trimesh.Trimesh(vertices=vertices, faces=faces, process=False)
    else:
        try:
            mesh = trimesh.load(path, force="mesh")
        except Exception as exc:  # noqa: BLE001 - trimesh raises many types
            raise ValueError(f"{path}: cannot load the mesh ({exc})") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise ValueError(f"{path}: the mesh has no triangles")
    v = np.asarray(mesh.vertices, np.float64) * scale
    if up == "z":
        v = np.stack([v[:, 0], v[:, 2], -v[:, 1]], axis=1)
    return trimesh.Trimesh(vertices=v, faces=np.asarray(mesh.faces), process=False)


def usd_mesh(path: str):
    """(vertices (V, 3) in the stage's units, triangles (T, 3), metres per unit or None, up axis or None) of
    every ``UsdGeom.Mesh`` of a USD file at its default time, each in world space (its prim's local-to-world
    transform), polygons fanned into triangles.  The stage's authored ``metersPerUnit`` and ``upAxis``, when
    it has them, win over the caller's units and up axis: a USD file says what its units are.

    Raises:
        ValueError: naming the file (usd-core missing, unreadable, no mesh).
    """
    from ..io.usd import _pxr

    try:
        _, _, Usd, UsdGeom, _ = _pxr()
    except ImportError as exc:
        raise ValueError(f"{path}: {exc}") from None
    try:
        stage = Usd.Stage.Open(path)
    except Exception as exc:  # noqa: BLE001 - pxr raises Tf.ErrorException and others
        raise ValueError(f"{path}: cannot open the USD file ({' '.join(str(exc).split())[:200]})") from None
    if stage is None:
        raise ValueError(f"{path}: cannot open the USD file")
    verts, faces, offset = [], [], 0
    t = Usd.TimeCode.Default()
    for prim in stage.Traverse():
        if not prim.IsA(UsdGeom.Mesh):
            continue
        m = UsdGeom.Mesh(prim)
        pts = np.asarray(m.GetPointsAttr().Get(t) or [], np.float64).reshape(-1, 3)
        counts = np.asarray(m.GetFaceVertexCountsAttr().Get(t) or [], np.int64)
        idx = np.asarray(m.GetFaceVertexIndicesAttr().Get(t) or [], np.int64)
        if not len(pts) or not len(counts) or counts.sum() != len(idx) or np.any(counts < 3) or \
                (len(idx) and (idx.min() < 0 or idx.max() >= len(pts))):
            raise ValueError(f"{path}: mesh {prim.GetPath()} has inconsistent faces (counts, indices, points)")
        M = np.asarray(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(t), np.float64)  # row vectors
        world = pts @ M[:3, :3] + M[3, :3]
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        tri = [np.stack([idx[starts + 0], idx[starts + k], idx[starts + k + 1]], axis=1)[counts > k + 1]
               for k in range(1, int(counts.max()) - 1)]
        verts.append(world)
        faces.append(np.concatenate(tri) + offset)
        offset += len(world)
    if not verts:
        raise ValueError(f"{path}: no UsdGeom.Mesh in the file")
    scale = float(UsdGeom.GetStageMetersPerUnit(stage)) if UsdGeom.StageHasAuthoredMetersPerUnit(stage) else None
    up = None
    if stage.HasAuthoredMetadata("upAxis"):
        up = str(UsdGeom.GetStageUpAxis(stage)).lower()
        if up not in UP_AXES:
            raise ValueError(f"{path}: upAxis {up!r} (known: Y, Z)")
    return np.concatenate(verts), np.concatenate(faces), scale, up


def resolve_path(base_dir: str, p: str) -> str:
    p = os.path.expanduser(p)
    return p if os.path.isabs(p) else os.path.normpath(os.path.join(base_dir, p))


def scale_and_up(t: Table):
    """(file units -> metres [-], up axis) of a table's ``scale`` or ``units`` and ``up`` keys ([groom] and a
    mesh [[colliders]] read them alike)."""
    scale = t.get("scale", "float", None, positive)
    units = t.get("units", "str", None, lambda v: None if v in UNITS else
                  f"must be one of {', '.join(UNITS)}, got {v!r}")
    if scale is not None and units is not None:
        t.fail("give 'scale' or 'units', not both")
    up = t.get("up", "str", "y", lambda v: None if v in UP_AXES else f"must be 'y' or 'z', got {v!r}")
    return (scale if scale is not None else UNITS[units] if units else 1.0), up


def subsample_groom(groom, count: int):
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
                 else groom.rest_points[verts], rest_twist=None if groom.rest_twist is None
                 else groom.rest_twist[verts], pinned=None if groom.pinned is None else groom.pinned[verts],
                 params=dict(groom.params), units=groom.units).validate()


def groom_from_table(t: Table, base: str, overrides: dict, desc: dict):
    from ..groom.generators import STYLES, GeneratorConfig, generate_groom, load_head, sphere_surface
    from ..io import UnitsWarning, load_groom, units_warning
    from ..io.groom import Groom

    root = t.get("root", "str", "clamped", lambda v: None if v in ("clamped", "free") else
                 f"must be 'clamped' or 'free', got {v!r}")
    body = t.get("body", "int", 0, at_least(0))
    rest_pose = t.get("rest_pose", "str", "authored", lambda v: None if v in REST_POSES else
                      f"must be one of {', '.join(REST_POSES)}, got {v!r}")
    rest_pose = overrides.get("rest_pose", rest_pose)
    check = t.get("rest_pose_check", "bool", False)
    if check:
        desc["rest_pose_check"] = True
    support = t.get("rest_pose_support", "str", "none", lambda v: None if v in ("none", "unheld", "all") else
                    f"must be 'none', 'unheld' or 'all', got {v!r}")
    if support != "none":
        desc["rest_pose_support"] = support
    change = t.get("rest_max_change", "float", 1.0, positive)
    if change != 1.0:
        desc["rest_max_change"] = change
    desc.update(root=root, body=body)
    if rest_pose != "authored":  # (absent from the description otherwise: old checkpoints still resume)
        desc["rest_pose"] = rest_pose
    if t.has("file") == t.has("generator"):
        t.fail("give either 'file' (a groom file) or 'generator' (one of " + ", ".join(STYLES) + ")")
    if t.has("file"):
        files = t.data["file"]
        t.used.add("file")
        files = [files] if isinstance(files, str) else files
        if not (isinstance(files, list) and files and all(isinstance(f, str) for f in files)):
            t.fail("must be a file name or a list of file names", "file")
        scale, up = scale_and_up(t)
        fmt = t.get("format", "str", None)
        strands = t.get("strands", "int", None, at_least(1))
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
            p = resolve_path(base, f)
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
        if up == "z":
            groom = groom.z_up_to_y_up()
            desc["up"] = up  # (absent for y: old checkpoints still resume)
        if strands is not None:
            if strands > groom.strand_count:
                warnings.warn(f"{t.path}: [groom] strands: {strands:,} asked, the file has {groom.strand_count:,}; "
                              "simulating all of them", UserWarning, stacklevel=2)
            groom = subsample_groom(groom, strands)
        desc.update(file=[resolve_path(base, f) for f in files], scale=scale, strands=groom.strand_count)
        return groom, root, body
    style = t.get("generator", "str", None, lambda v: None if v in STYLES else
                  f"must be one of {', '.join(STYLES)}, got {v!r}")
    surface = t.get("surface", "str", "head")
    sph_r = t.get("sphere_radius", "float", 0.09, positive)
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
    cfg = dataclass_from(t, GeneratorConfig, dict(values, style=style), "the generator")
    try:
        if surface == "sphere":
            surf = sphere_surface(sph_r, sph_c, cap)
        elif surface == "head":
            surf = load_head()
        else:
            surf = load_head(resolve_path(base, surface))
    except ValueError as exc:
        t.fail(str(exc), "surface")
    groom = generate_groom(surf, cfg)
    desc.update(generator=dataclasses.asdict(cfg), surface=surface, sphere=[sph_r, list(sph_c), cap])
    desc["generator"]["down"] = list(cfg.down)
    return groom, root, body


def collider_from_table(t: Table, base: str):
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
            p = resolve_path(base, f)
            if not os.path.exists(p):
                t.fail(f"no such file: {p}", "file")
            scale, up = scale_and_up(t)
            res = t.get("resolution", "int", 64)
            pad = t.get("padding", "float", 0.15)
            thick = t.get("thickness", "float", 1e-3)
            t.done()
            mesh = p
            if scale != 1.0 or up != "y" or p.lower().endswith(".tfxmesh"):
                try:
                    mesh = load_body_mesh(p, scale, up)
                except ValueError as exc:
                    t.fail(str(exc), "file")
            c = MeshCollider(mesh=mesh, resolution=res, padding=pad, thickness=thick, source=p, **common)
            desc.update(file=p, scale=scale, resolution=res, padding=pad, thickness=thick)
            if up != "y":
                desc["up"] = up
    except ValueError as exc:
        t.fail(str(exc))
    t.done()
    for k in ("center", "radius", "p0", "p1", "point", "normal"):
        if hasattr(c, k) and not isinstance(c, MeshCollider):
            v = getattr(c, k)
            desc[k] = np.asarray(v).tolist() if not isinstance(v, float) else v
    return c, desc



def solver_from_table(t: Table, overrides: dict, colliders: list):
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
    for key in ("integrator", "schedule"):  # (options of SolverADMMConfig only)
        if overrides.get(key):
            if kind != "admm":
                t.fail(f"--{key} applies to type = \"admm\", not {kind!r}", "type")
            values[key] = overrides[key]
    desc = {"type": kind, **{k: v for k, v in values.items()}}
    if kind == "admm":
        contacts = t.get("contacts", "table", None)
        if t.has("region"):
            t.fail("[solver.region] is for type = \"shape\"", "region")
        if contacts is None and overrides.get("continuous"):
            t.fail("--continuous needs hair contacts: add a [solver.contacts] table", "contacts")
        if contacts is not None:
            ct = Table(t.path, f"{t.name}.contacts", contacts)
            cvalues = ct.rest()
            if overrides.get("continuous"):
                cvalues["continuous_detections"] = overrides["continuous"]
            values["contacts"] = dataclass_from(ct, ContactConfig, cvalues, "ContactConfig")
            desc["contacts"] = cvalues
        cfg = dataclass_from(t, SolverADMMConfig, values, "SolverADMMConfig")
    elif kind == "shape":
        if t.has("contacts"):
            t.fail("[solver.contacts] is for type = \"admm\"", "contacts")
        region = t.get("region", "table", {})
        rt = Table(t.path, f"{t.name}.region", region)
        reg = dataclass_from(rt, ShapeRegion, rt.rest(), "ShapeRegion")
        desc["region"] = region
        cfg = dataclass_from(t, SolverShapeConfig, dict(values, regions=(reg,)), "SolverShapeConfig")
    else:
        for k in ("contacts", "region"):
            if t.has(k):
                t.fail(f"[solver.{k}] is not for type = \"xpbd\"", k)
        if colliders:
            raise SceneError(f"{t.path}: [[colliders]]: solver type \"xpbd\" has no collisions; remove the "
                             f"colliders or use type = \"admm\"")
        cfg = dataclass_from(t, SolverXPBDConfig, values, "SolverXPBDConfig")
    t.done()
    return kind, cfg, desc

