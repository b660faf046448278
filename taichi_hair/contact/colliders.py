"""Kinematic body colliders: planes, spheres, capsules and triangle meshes (signed distance fields).

Each collider is rigidly attached to a body of :class:`~taichi_hair.state.Control`
(the same bodies clamped roots follow; ``body=-1`` is the static world) and has
its own Coulomb friction coefficient.  Shapes are described in the body's
frame; at a step the solver evaluates them at the begin-of-step and the
end-of-step body transforms, so moving bodies push the hair (Sec. 4.5: contacts
against bodies enter the same feasible projection as hair-hair contacts).

Triangle meshes are loaded through trimesh and turned once into a voxel signed
distance field (``mesh2sdf``), sampled trilinearly in kernels, with the
gradient of the trilinear interpolant as normal.  The paper bisects SDFs for a
contact point; we take the vertex position minus the signed distance along the
normal, which is the same point to first order (a simplification).  A mesh that
is not watertight (a scanned bust open at the neck, a head with holes) is signed by
its generalized winding number (Jacobson et al. 2013, :mod:`taichi_hair.contact.mesh_query`)
at the SDF nodes, with a one-line warning naming the file and its holes: on the
assets/head.obj with a 3 cm hole cut in the cheek mesh2sdf's own sign was wrong at
1014 of 254072 nodes, the winding number at none (a repair with
``trimesh.repair.fill_holes`` left the mesh open and the signs unchanged;
``mesh2sdf``'s ``fix=True`` flood fill turned every inside node outside).  Only an
open surface that encloses nothing (the largest winding number below 3/4: a sheet)
falls back to the unsigned distance minus ``MeshCollider.thickness``.

Collider contacts are vertex-based (each free vertex against each collider):
hair edges (mm) are short compared with the curvature radii of bodies.
"""


import math
import warnings
from dataclasses import dataclass, field

import numpy as np
import taichi as ti

from ..fields import upload

vec3 = ti.math.vec3

PLANE, SPHERE, CAPSULE, MESH = 0, 1, 2, 3
#: Signed distance reported far from any mesh SDF grid [m].
FAR = 1.0e6


def _vec(name, v):
    a = np.asarray(v, dtype=np.float64).reshape(-1)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be a finite 3-vector, got {v!r}")
    return a


def _check_common(owner, body, friction, strands=None):
    if strands is not None:
        ok = (isinstance(strands, (tuple, list)) and len(strands) == 2
              and all(isinstance(v, (int, np.integer)) for v in strands) and 0 <= strands[0] < strands[1])
        if not ok:
            raise ValueError(f"{owner}.strands must be None or a range (first, last + 1) of strand indices, "
                             f"got {strands!r}")
    if not (isinstance(body, (int, np.integer)) and body >= -1):
        raise ValueError(f"{owner}.body must be an integer >= -1 (-1: static world), got {body!r}")
    if not (math.isfinite(friction) and friction >= 0):
        raise ValueError(f"{owner}.friction must be a finite number >= 0, got {friction!r}")


@dataclass
class PlaneCollider:
    """Half-space {p : (p - point) . normal >= 0} is free; the hair stays on the normal's side.

    Attributes:
        point: a point of the plane in the body frame [m].
        normal: outward normal in the body frame (normalised here) [-].
        friction: Coulomb coefficient mu against hair [-].
        body: body index in Control, -1 for the static world [-].
        strands: optional half-open range (first, last + 1) of the strands this collider
            acts on (a collision group); ``None``: all strands.
    """

    point: tuple = (0.0, 0.0, 0.0)
    normal: tuple = (0.0, 1.0, 0.0)
    friction: float = 0.3
    body: int = -1
    strands: tuple = None

    def __post_init__(self):
        self.point = _vec("PlaneCollider.point", self.point)
        n = _vec("PlaneCollider.normal", self.normal)
        if np.linalg.norm(n) < 1e-12:
            raise ValueError("PlaneCollider.normal must be non-zero")
        self.normal = n / np.linalg.norm(n)
        _check_common("PlaneCollider", self.body, self.friction, self.strands)


@dataclass
class SphereCollider:
    """Sphere of ``radius`` [m] centred at ``center`` (body frame) [m]; friction mu [-]; body index;
    optional strand range (see PlaneCollider)."""

    center: tuple = (0.0, 0.0, 0.0)
    radius: float = 0.1
    friction: float = 0.3
    body: int = -1
    strands: tuple = None

    def __post_init__(self):
        self.center = _vec("SphereCollider.center", self.center)
        if not (math.isfinite(self.radius) and self.radius > 0):
            raise ValueError(f"SphereCollider.radius must be a finite positive number, got {self.radius!r}")
        _check_common("SphereCollider", self.body, self.friction, self.strands)


@dataclass
class CapsuleCollider:
    """Capsule: points within ``radius`` [m] of the segment p0-p1 (body frame) [m]; friction; body;
    optional strand range (see PlaneCollider)."""

    p0: tuple = (0.0, 0.0, 0.0)
    p1: tuple = (0.0, 0.1, 0.0)
    radius: float = 0.05
    friction: float = 0.3
    body: int = -1
    strands: tuple = None

    def __post_init__(self):
        self.p0 = _vec("CapsuleCollider.p0", self.p0)
        self.p1 = _vec("CapsuleCollider.p1", self.p1)
        if not (math.isfinite(self.radius) and self.radius > 0):
            raise ValueError(f"CapsuleCollider.radius must be a finite positive number, got {self.radius!r}")
        _check_common("CapsuleCollider", self.body, self.friction, self.strands)


@dataclass
class MeshCollider:
    """A triangle mesh (trimesh.Trimesh or a path trimesh can load) turned into a voxel SDF.

    Attributes:
        mesh: ``trimesh.Trimesh`` or file path (OBJ, PLY, STL, ...), body-frame coordinates [m].
        resolution: SDF voxels along the longest side of the padded bounding box [-].
        padding: margin added around the bounding box, fraction of its largest side [-].
        thickness: for an open surface that encloses no volume only (a sheet): the unsigned
            distance minus this thickness is used as signed distance [m].
        friction: Coulomb coefficient mu against hair [-].
        body: body index in Control, -1 for the static world [-].
        strands: optional strand range (see PlaneCollider).
    """

    mesh: object = None
    resolution: int = 64
    padding: float = 0.15
    thickness: float = 1e-3
    friction: float = 0.3
    body: int = -1
    strands: tuple = None
    #: Filled at build time: the SDF grid (res, res, res) [m], its origin [m] and spacing [m].
    sdf: np.ndarray = field(default=None, repr=False)
    origin: np.ndarray = field(default=None, repr=False)
    spacing: float = 0.0
    watertight: bool = True
    #: Filled at build time: edges used by one face, and the holes (loops) they form [-].
    boundary_edge_count: int = 0
    hole_count: int = 0
    #: How inside/outside was decided: "mesh2sdf" (watertight), "winding" or "unsigned-shell".
    sign_method: str = "mesh2sdf"
    #: Where the mesh came from (file name or "mesh"), for messages.
    source: str = "mesh"

    def __post_init__(self):
        _check_common("MeshCollider", self.body, self.friction, self.strands)
        if not (isinstance(self.resolution, int) and 8 <= self.resolution <= 512):
            raise ValueError(f"MeshCollider.resolution must be an integer in [8, 512], got {self.resolution!r}")
        if not (math.isfinite(self.thickness) and self.thickness > 0):
            raise ValueError(f"MeshCollider.thickness must be a finite positive number, got {self.thickness!r}")
        self._build()

    def _build(self):
        import trimesh

        self._query = None

        mesh, source = self.mesh, self.source  # (a Trimesh keeps the source it was given: its file's name)
        if isinstance(mesh, (str, bytes)) or hasattr(mesh, "__fspath__"):
            source = str(mesh)
            try:
                mesh = trimesh.load(mesh, force="mesh")
            except Exception as exc:  # trimesh raises many types; report one readable line
                raise ValueError(f"MeshCollider: cannot load {source}: {exc}") from None
        if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
            raise ValueError(f"MeshCollider.mesh ({source}) must be a triangle mesh with at least one face")
        v = np.asarray(mesh.vertices, dtype=np.float64)
        if not np.all(np.isfinite(v)):
            raise ValueError(f"MeshCollider.mesh ({source}) has non-finite vertex coordinates")
        self.watertight = bool(mesh.is_watertight)
        self.source = source
        lo, hi = v.min(0), v.max(0)
        side = float((hi - lo).max())
        if side <= 0:
            raise ValueError(f"MeshCollider.mesh ({source}) is degenerate (zero extent)")
        center = 0.5 * (lo + hi)
        half = 0.5 * side * (1.0 + 2.0 * self.padding)
        from .sdf_cache import mesh_sdf_grid

        n = self.resolution
        normalized = (v - center) / half  # in [-1, 1]
        sdf = mesh_sdf_grid(normalized, np.asarray(mesh.faces, np.int64), n, 2.0 / n)  # mesh2sdf, cached on disk
        sdf = np.asarray(sdf, np.float64) * half
        if not self.watertight:
            sdf = self._sign_open_mesh(mesh, np.abs(sdf), center - half, 2.0 * half / n)
        # mesh2sdf samples grid point i at -1 + 2 i / n (checked against a sphere in the tests).
        self.sdf = sdf
        self.origin = center - half
        self.spacing = 2.0 * half / n
        self.mesh = mesh

    def _sign_open_mesh(self, mesh, unsigned, origin, spacing):
        """Sign the unsigned distances of a mesh with holes by its winding number at the SDF nodes."""
        from .mesh_query import TriangleMeshQuery, boundary_edges, count_boundary_loops, grid_winding_number

        edges = boundary_edges(mesh.faces)
        self.boundary_edge_count, self.hole_count = len(edges), count_boundary_loops(edges)
        self._query = TriangleMeshQuery(mesh.vertices, mesh.faces)
        w = grid_winding_number(self._query, origin, spacing, self.resolution, unsigned)
        what = (f"MeshCollider: {self.source} is not watertight ({self.boundary_edge_count} boundary edges in "
                f"{self.hole_count} holes)")
        # Nodes on the surface itself have no defined winding number; judge the enclosed volume off it.
        off = unsigned > 0.5 * spacing
        w_max = float(w[off].max()) if off.any() else 0.0
        if w_max < 0.75:
            self.sign_method = "unsigned-shell"
            warnings.warn(f"{what} and encloses no volume (largest winding number {w_max:.2f}); using the "
                          f"unsigned distance minus a thickness of {self.thickness} m", stacklevel=4)
            return unsigned - self.thickness
        self.sign_method = "winding"
        warnings.warn(f"{what}; inside/outside from its generalized winding number at the "
                      f"{self.resolution}^3 SDF nodes (inside where w >= 1/2)", stacklevel=4)
        # Over a hole the surface is the level w = 1/2 (the "cap"), far from every triangle: there the
        # distance is that to the level set, to first order (1/2 - w) / |grad w|, so that the field does
        # not jump from +d to -d across the cap.  Only at nodes away from the triangles (> 1.5 spacings)
        # where w is neither 0 nor 1.
        g = np.gradient(w, spacing)
        grad = np.sqrt(g[0] ** 2 + g[1] ** 2 + g[2] ** 2)
        cap = np.abs(0.5 - w) / np.maximum(grad, 1e-12)
        over_hole = (unsigned > 1.5 * spacing) & (w > 0.05) & (w < 0.95)
        dist = np.where(over_hole, np.minimum(unsigned, cap), unsigned)
        return np.where(w >= 0.5, -dist, dist)

    @property
    def triangle_query(self):
        """:class:`~taichi_hair.contact.mesh_query.TriangleMeshQuery` of the mesh (body frame), built on first use."""
        if self._query is None:
            from .mesh_query import TriangleMeshQuery

            self._query = TriangleMeshQuery(self.mesh.vertices, self.mesh.faces)
        return self._query

    def sdf_numpy(self, points_body) -> np.ndarray:
        """The voxel SDF at body-frame points, trilinear as the ``mesh_distance`` kernel, (N, 3) -> (N,) [m]
        (FAR outside the grid)."""
        p = np.asarray(points_body, np.float64).reshape(-1, 3)
        n = self.sdf.shape[0]
        q = (p - self.origin) / self.spacing
        inside = np.all((q >= 0.0) & (q <= n - 1.0), axis=1)
        i0 = np.clip(np.floor(q).astype(np.int64), 0, n - 2)
        f = np.clip(q - i0, 0.0, 1.0)
        out = np.zeros(len(p))
        for dx in (0, 1):
            for dy in (0, 1):
                for dz in (0, 1):
                    wgt = ((f[:, 0] if dx else 1 - f[:, 0]) * (f[:, 1] if dy else 1 - f[:, 1])
                           * (f[:, 2] if dz else 1 - f[:, 2]))
                    out += wgt * self.sdf[i0[:, 0] + dx, i0[:, 1] + dy, i0[:, 2] + dz]
        return np.where(inside, out, FAR)


class ColliderSet:
    """All colliders of a scene in Taichi fields (allocated once here).

    Fields (shape (collider_count,) unless stated):
        collider_kind: PLANE, SPHERE, CAPSULE or MESH [-].
        collider_body: body index in Control, -1 static [-].
        collider_friction: Coulomb coefficient mu [-].
        collider_a, collider_b: shape parameters in the body frame: plane (point, normal),
            sphere (center, -), capsule (p0, p1), mesh (grid origin [m], -) [m].
        collider_radius: sphere/capsule radius [m]; mesh: SDF grid spacing [m].
        collider_grid: mesh: (offset into sdf_value, resolution) [-].
        sdf_value: all mesh SDF grids, flattened x-major, shape (total voxels,) [m].
        body_rotation_begin, body_translation_begin: body transforms at the beginning
            of the current step, shape (body_count,) [-], [m].
        body_rotation_end, body_translation_end: the same at the end of the step (copied
            from Control), shape (body_count,) [-], [m].
    """

    def __init__(self, colliders, body_count: int):
        colliders = list(colliders)
        for k, c in enumerate(colliders):
            if not isinstance(c, (PlaneCollider, SphereCollider, CapsuleCollider, MeshCollider)):
                raise ValueError(f"collider {k}: unsupported type {type(c).__name__}")
            if c.body >= body_count:
                raise ValueError(f"collider {k}: body {c.body} does not exist (the model has {body_count} bodies)")
        self.colliders = colliders
        self.count = len(colliders)
        self.body_count = body_count
        nc = max(self.count, 1)
        self.collider_kind = ti.field(ti.i32, nc)
        self.collider_body = ti.field(ti.i32, nc)
        self.collider_friction = ti.field(float, nc)
        self.collider_a = ti.Vector.field(3, float, nc)
        self.collider_b = ti.Vector.field(3, float, nc)
        self.collider_radius = ti.field(float, nc)
        self.collider_grid = ti.Vector.field(2, ti.i32, nc)
        #: Strands the collider acts on: half-open range [first, last + 1) [-].
        self.collider_strands = ti.Vector.field(2, ti.i32, nc)
        grids = [c.sdf for c in colliders if isinstance(c, MeshCollider)]
        total = sum(int(g.size) for g in grids)
        self.sdf_value = ti.field(float, max(total, 1))
        #: Number of colliders, shape () (a field, so kernels loop over it without recompiling) [-].
        self.count_field = ti.field(ti.i32, ())
        self.count_field[None] = self.count
        self.body_rotation_begin = ti.Matrix.field(3, 3, float, body_count)
        self.body_translation_begin = ti.Vector.field(3, float, body_count)
        self.body_rotation_end = ti.Matrix.field(3, 3, float, body_count)
        self.body_translation_end = ti.Vector.field(3, float, body_count)
        self.has_begin = False
        f = np.float64 if ti.lang.impl.current_cfg().default_fp == ti.f64 else np.float32
        kind = np.zeros(nc, np.int32)
        body = np.full(nc, -1, np.int32)
        fr = np.zeros(nc)
        a = np.zeros((nc, 3))
        b = np.zeros((nc, 3))
        rad = np.zeros(nc)
        grid = np.zeros((nc, 2), np.int32)
        strands = np.tile(np.array([0, 2**31 - 1], np.int32), (nc, 1))
        flat, off = [], 0
        for k, c in enumerate(colliders):
            body[k], fr[k] = c.body, c.friction
            if c.strands is not None:
                strands[k] = c.strands
            if isinstance(c, PlaneCollider):
                kind[k], a[k], b[k] = PLANE, c.point, c.normal
            elif isinstance(c, SphereCollider):
                kind[k], a[k], rad[k] = SPHERE, c.center, c.radius
            elif isinstance(c, CapsuleCollider):
                kind[k], a[k], b[k], rad[k] = CAPSULE, c.p0, c.p1, c.radius
            else:
                kind[k], a[k], rad[k] = MESH, c.origin, c.spacing
                grid[k] = (off, c.sdf.shape[0])
                flat.append(c.sdf.reshape(-1))
                off += c.sdf.size
        upload([(self.collider_kind, kind), (self.collider_body, body), (self.collider_friction, fr.astype(f)),
                (self.collider_a, a.astype(f)), (self.collider_b, b.astype(f)), (self.collider_radius, rad.astype(f)),
                (self.collider_grid, grid), (self.collider_strands, strands)]
               + ([(self.sdf_value, np.concatenate(flat).astype(f))] if flat else []))

    def any_acting(self) -> bool:
        """Does any collider act on a strand (``collider_strands`` not empty)?  The grooming comb is idle,
        [0, 0), between strokes."""
        if self.count == 0:
            return False
        rng = self.collider_strands.to_numpy()[: self.count]
        return bool(np.any(rng[:, 1] > rng[:, 0]))

    def begin_step(self, control) -> None:
        """Take the end-of-step body transforms from ``control``; the begin-of-step ones are those of the
        previous step's end (on the first step: the current ones, i.e. no body motion in that step)."""
        # One kernel, not six field copies: each copy_from is a kernel instance of its own, compiled (or loaded from
        # the cache) in the first step (issue 15, item 5).
        _advance_body_transforms(self, control.body_rotation, control.body_translation, int(not self.has_begin))
        self.has_begin = True

    def distance_numpy(self, points: np.ndarray, control=None, k: int = 0) -> np.ndarray:
        """Signed distance of world points to collider k at the transforms of ``control`` (host, for tests) [m]."""
        out = ti.field(float, len(points))
        pts = ti.Vector.field(3, float, len(points))
        pts.from_numpy(np.asarray(points, np.float32 if out.dtype == ti.f32 else np.float64))
        rot = control.body_rotation if control is not None else self.body_rotation_begin
        tr = control.body_translation if control is not None else self.body_translation_begin
        _distance_kernel(self, rot, tr, k, pts, out)
        return out.to_numpy()


# --------------------------------------------------------------------------- distance functions
@ti.func
def _sdf_at(cs: ti.template(), off: ti.i32, res: ti.i32, i: ti.i32, j: ti.i32, k: ti.i32) -> float:
    return cs.sdf_value[off + (i * res + j) * res + k]


@ti.func
def mesh_distance(cs: ti.template(), c: ti.i32, p):
    """Trilinear SDF value at body-frame point p and the gradient of the interpolant (normalised)."""
    origin = cs.collider_a[c]
    h = cs.collider_radius[c]
    off = cs.collider_grid[c][0]
    res = cs.collider_grid[c][1]
    q = (p - origin) / h
    d = FAR
    n = vec3(0.0, 1.0, 0.0)
    if q.min() >= 0.0 and q.max() <= res - 1.0:
        i0 = ti.min(ti.cast(ti.floor(q[0]), ti.i32), res - 2)
        j0 = ti.min(ti.cast(ti.floor(q[1]), ti.i32), res - 2)
        k0 = ti.min(ti.cast(ti.floor(q[2]), ti.i32), res - 2)
        fx, fy, fz = q[0] - i0, q[1] - j0, q[2] - k0
        c000 = _sdf_at(cs, off, res, i0, j0, k0)
        c100 = _sdf_at(cs, off, res, i0 + 1, j0, k0)
        c010 = _sdf_at(cs, off, res, i0, j0 + 1, k0)
        c110 = _sdf_at(cs, off, res, i0 + 1, j0 + 1, k0)
        c001 = _sdf_at(cs, off, res, i0, j0, k0 + 1)
        c101 = _sdf_at(cs, off, res, i0 + 1, j0, k0 + 1)
        c011 = _sdf_at(cs, off, res, i0, j0 + 1, k0 + 1)
        c111 = _sdf_at(cs, off, res, i0 + 1, j0 + 1, k0 + 1)
        c00 = c000 * (1 - fx) + c100 * fx
        c10 = c010 * (1 - fx) + c110 * fx
        c01 = c001 * (1 - fx) + c101 * fx
        c11 = c011 * (1 - fx) + c111 * fx
        c0 = c00 * (1 - fy) + c10 * fy
        c1 = c01 * (1 - fy) + c11 * fy
        d = c0 * (1 - fz) + c1 * fz
        gx = ((c100 - c000) * (1 - fy) + (c110 - c010) * fy) * (1 - fz) + ((c101 - c001) * (1 - fy) + (c111 - c011) * fy) * fz
        gy = (c10 - c00) * (1 - fz) + (c11 - c01) * fz
        gz = c1 - c0
        g = vec3(gx, gy, gz)
        gn = g.norm()
        if gn > 1e-12:
            n = g / gn
    return d, n


@ti.func
def collider_distance(cs: ti.template(), c: ti.i32, p):
    """Signed distance [m] from body-frame point p to collider c, and the outward unit normal (body frame)."""
    kind = cs.collider_kind[c]
    d = FAR
    n = vec3(0.0, 1.0, 0.0)
    if kind == PLANE:
        n = cs.collider_b[c]
        d = (p - cs.collider_a[c]).dot(n)
    elif kind == SPHERE:
        r = p - cs.collider_a[c]
        rn = r.norm()
        if rn > 1e-12:
            n = r / rn
        d = rn - cs.collider_radius[c]
    elif kind == CAPSULE:
        a, b = cs.collider_a[c], cs.collider_b[c]
        ab = b - a
        t = ti.math.clamp((p - a).dot(ab) / ti.max(ab.dot(ab), 1e-30), 0.0, 1.0)
        r = p - (a + t * ab)
        rn = r.norm()
        if rn > 1e-12:
            n = r / rn
        d = rn - cs.collider_radius[c]
    else:
        d, n = mesh_distance(cs, c, p)
    return d, n


@ti.func
def acts_on(cs: ti.template(), c: ti.i32, strand: ti.i32) -> bool:
    rng = cs.collider_strands[c]
    return rng[0] <= strand and strand < rng[1]


@ti.func
def body_transform(rot: ti.template(), tr: ti.template(), body: ti.i32):
    R = ti.Matrix.identity(float, 3)
    T = vec3(0.0)
    if body >= 0:
        R = rot[body]
        T = tr[body]
    return R, T


@ti.kernel
def _advance_body_transforms(cs: ti.template(), rotation: ti.template(), translation: ti.template(), first: ti.i32):
    """begin <- end, end <- (rotation, translation); on the first step begin <- the new transforms too."""
    for b in rotation:
        if first:
            cs.body_rotation_end[b] = rotation[b]
            cs.body_translation_end[b] = translation[b]
        cs.body_rotation_begin[b] = cs.body_rotation_end[b]
        cs.body_translation_begin[b] = cs.body_translation_end[b]
        cs.body_rotation_end[b] = rotation[b]
        cs.body_translation_end[b] = translation[b]


@ti.kernel
def _distance_kernel(cs: ti.template(), rot: ti.template(), tr: ti.template(), c: ti.i32, pts: ti.template(),
                     out: ti.template()):
    for i in pts:
        R, T = body_transform(rot, tr, cs.collider_body[c])
        d, n = collider_distance(cs, c, R.transpose() @ (pts[i] - T))
        out[i] = d
