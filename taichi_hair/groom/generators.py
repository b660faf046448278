"""Procedural grooms on a head mesh or a sphere: straight, wavy and curly hair.

    from taichi_hair.groom.generators import GeneratorConfig, generate_groom, load_head, sphere_surface
    head = load_head()                                   # assets/head.obj and its scalp group
    groom = generate_groom(head, GeneratorConfig(style="wavy", strands=500, seed=1))

How a strand is made (all NumPy, vectorised over strands, deterministic by seed):

1. Roots: scalp triangles are drawn with probability proportional to their
   area, then a point uniformly inside the triangle (square-root barycentric
   sampling).  The root is lifted ``root_lift`` along the interpolated vertex
   normal, so it starts outside the surface.
2. Centreline: grown in ``4 * (vertices_per_strand - 1)`` small steps from the
   root, leaving at ``root_angle`` above the scalp's tangent plane, leaning
   toward the comb direction unit(t(down) + 0.2 t(back)) (t: the part in the
   tangent plane; ``back`` decides the crown, where gravity has no tangential
   part); ``root_angle = 90`` leaves along the normal.  The direction turns toward gravity
   (``down``) with curvature ``gravity_bend`` [1/m], and after each step a
   point closer than ``clearance`` to the surface is pushed out along the
   signed-distance gradient (so hair combs over the head instead of entering it).
3. Style: ``straight`` keeps the centreline; ``wavy`` adds a planar sine of
   amplitude ``wave_amplitude`` and wavelength ``wave_length``; ``curly`` adds a
   helix of radius ``curl_radius`` and pitch ``curl_pitch``, both in a frame
   parallel-transported along the centreline, faded in over ``style_ramp`` from
   the root so the root still leaves along the normal.  Each strand gets a
   random phase and a random amplitude factor in [1 - style_spread, 1 + style_spread].
   The styled curve is pushed out of the surface again.
4. Resampling: the styled curve is resampled to ``vertices_per_strand``
   vertices equally spaced along it, over an arc length adjusted (a few
   fixed-point steps) so that the final *polyline* is as long as the strand's
   drawn length: with few vertices per wave or turn the chords cut corners and
   the polyline covers more of the curve.  A curl or wave needs about 4
   vertices per wavelength or pitch to show at all; fewer alias it.

Distributions (per strand, uniform): length in [length (1 - length_spread),
length (1 + length_spread)], radius in [radius (1 - radius_spread),
radius (1 + radius_spread)].  The strand count is ``strands``, or
``round(density * scalp area)`` when ``density`` is set.

The signed distance used in steps 2 and 3 is analytic for a sphere and, for a
mesh, a voxel SDF (``mesh2sdf``, the same as :class:`~taichi_hair.contact.colliders.MeshCollider`)
sampled trilinearly; its gradient is the central difference of that sampler.
The voxel SDF is approximate (trilinear, 64 voxels across the padded head
by default: 6.5 mm voxels); the tests check every generated vertex against
the exact winding number of the mesh.
"""

from __future__ import annotations

import math
import os
from dataclasses import asdict, dataclass, field

import numpy as np

STYLES = ("straight", "wavy", "curly")

#: ``assets/head.obj`` of the repository (made by ``assets/make_head.py``).
HEAD_MESH_PATH = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "assets",
                              "head.obj")


# --------------------------------------------------------------------------- surfaces
@dataclass
class ScalpSurface:
    """A closed surface with a scalp region, and its signed distance.

    Attributes:
        vertices: mesh vertices [m], float64, shape (V, 3).
        faces: triangles, int64, shape (F, 3), counter-clockwise seen from outside.
        scalp: True for the faces roots may grow from, bool, shape (F,).
        name: where the surface came from (file path or "sphere"), for messages.
        sdf: callable ``sdf(points (P, 3)) -> (P,)`` signed distance [m], negative inside.
    """

    vertices: np.ndarray
    faces: np.ndarray
    scalp: np.ndarray
    name: str = "surface"
    sdf: object = field(default=None, repr=False)

    def __post_init__(self):
        self.vertices = np.asarray(self.vertices, np.float64)
        self.faces = np.asarray(self.faces, np.int64)
        self.scalp = np.asarray(self.scalp, bool)
        if self.vertices.ndim != 2 or self.vertices.shape[1] != 3 or not np.all(np.isfinite(self.vertices)):
            raise ValueError(f"{self.name}: vertices must be a finite (V, 3) array")
        if self.faces.ndim != 2 or self.faces.shape[1] != 3 or self.faces.size == 0:
            raise ValueError(f"{self.name}: faces must be a non-empty (F, 3) array")
        if self.faces.min() < 0 or self.faces.max() >= len(self.vertices):
            raise ValueError(f"{self.name}: a face refers to a vertex that does not exist")
        if self.scalp.shape != (len(self.faces),):
            raise ValueError(f"{self.name}: the scalp mask has shape {self.scalp.shape}, "
                             f"expected ({len(self.faces)},)")
        if not self.scalp.any():
            raise ValueError(f"{self.name}: the scalp region is empty (no face to grow hair from)")
        if self.sdf is None:
            self.sdf = _voxel_sdf(self.vertices, self.faces, 96, self.name)

    def face_areas(self) -> np.ndarray:
        """Triangle areas [m^2], shape (F,)."""
        t = self.vertices[self.faces]
        return 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)

    def scalp_area(self) -> float:
        """Area of the scalp region [m^2]."""
        return float(self.face_areas()[self.scalp].sum())

    def vertex_normals(self) -> np.ndarray:
        """Area-weighted unit vertex normals, shape (V, 3)."""
        t = self.vertices[self.faces]
        fn = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])  # length 2 area: area weighting
        vn = np.zeros_like(self.vertices)
        for k in range(3):
            np.add.at(vn, self.faces[:, k], fn)
        return vn / np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-30)


def _voxel_sdf(vertices, faces, resolution: int, name: str):
    """Trilinear sampler of a mesh2sdf voxel SDF over the padded bounding box (far outside: distance to the box)."""
    from ..contact.sdf_cache import mesh_sdf_grid

    lo, hi = vertices.min(0), vertices.max(0)
    side = float((hi - lo).max())
    if not side > 0:
        raise ValueError(f"{name}: the mesh is degenerate (zero extent)")
    center = 0.5 * (lo + hi)
    half = 0.5 * side * 1.3
    n = resolution
    grid = np.asarray(mesh_sdf_grid((vertices - center) / half, faces, n, 2.0 / n), np.float64) * half
    origin = center - half
    h = 2.0 * half / n  # grid point i sits at origin + i h (mesh2sdf's convention, see contact/colliders.py)

    def sdf(p):
        p = np.asarray(p, np.float64)
        u = (p - origin) / h
        i0 = np.clip(np.floor(u).astype(np.int64), 0, n - 2)
        f = np.clip(u - i0, 0.0, 1.0)
        out = np.zeros(len(p))
        for dx in (0, 1):
            wx = f[:, 0] if dx else 1 - f[:, 0]
            for dy in (0, 1):
                wy = f[:, 1] if dy else 1 - f[:, 1]
                for dz in (0, 1):
                    wz = f[:, 2] if dz else 1 - f[:, 2]
                    out += wx * wy * wz * grid[i0[:, 0] + dx, i0[:, 1] + dy, i0[:, 2] + dz]
        # Outside the grid the field is clamped; add the distance to the grid box so it keeps growing.
        box = np.linalg.norm(np.maximum(0.0, np.maximum(origin - p, p - (origin + (n - 1) * h))), axis=1)
        return out + box

    return sdf


def read_obj_groups(path) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Triangles of an OBJ in file order: (vertices (V, 3) [file units], faces (F, 3), group name per face).

    Polygons are fanned into triangles; ``v//vn`` and ``v/vt/vn`` references and
    negative indices are accepted.  Errors name the file and the line.
    """
    verts, faces, groups = [], [], []
    group = ""
    try:
        fh = open(path, "r", encoding="utf-8", errors="replace")
    except OSError as exc:
        raise ValueError(f"{path}: cannot open mesh ({exc.strerror})") from None
    with fh:
        for lineno, line in enumerate(fh, 1):
            parts = line.split()
            if not parts:
                continue
            try:
                if parts[0] == "v":
                    verts.append([float(parts[1]), float(parts[2]), float(parts[3])])
                elif parts[0] == "g":
                    group = " ".join(parts[1:])
                elif parts[0] == "f":
                    idx = []
                    for tok in parts[1:]:
                        k = int(tok.split("/")[0])
                        idx.append(k - 1 if k > 0 else len(verts) + k)
                    if len(idx) < 3:
                        raise ValueError("a face needs 3 vertices")
                    for j in range(1, len(idx) - 1):
                        faces.append((idx[0], idx[j], idx[j + 1]))
                        groups.append(group)
            except (ValueError, IndexError) as exc:
                raise ValueError(f"{path}: line {lineno}: cannot read {parts[0]!r} record ({exc})") from None
    if not faces:
        raise ValueError(f"{path}: no triangles")
    v = np.asarray(verts, np.float64)
    f = np.asarray(faces, np.int64)
    if f.min() < 0 or f.max() >= len(v):
        raise ValueError(f"{path}: a face refers to a vertex that does not exist")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{path}: non-finite vertex coordinates")
    return v, f, groups


def load_head(path=None, scalp_group: str = "scalp", scale: float = 1.0, sdf_resolution: int = 64) -> ScalpSurface:
    """A head mesh (default ``assets/head.obj``) whose faces in OBJ group ``scalp_group`` grow hair.

    ``scale`` multiplies the file's coordinates (to metres).  A mesh without that
    group grows hair everywhere above its centroid (faces whose centroid is in
    the upper half of the bounding box).
    """
    path = HEAD_MESH_PATH if path is None else os.fspath(path)
    if not (math.isfinite(scale) and scale > 0):
        raise ValueError(f"load_head: scale must be a finite positive number, got {scale!r}")
    v, f, groups = read_obj_groups(path)
    v = v * scale
    scalp = np.array([g == scalp_group for g in groups])
    if not scalp.any():
        c = v[f].mean(axis=1)
        lo, hi = v.min(0), v.max(0)
        scalp = c[:, 1] > 0.5 * (lo[1] + hi[1])
    return ScalpSurface(v, f, scalp, name=path, sdf=_voxel_sdf(v, f, sdf_resolution, path))


def sphere_surface(radius: float = 0.09, center=(0.0, 0.0, 0.0), scalp_min_y: float = 0.0,
                   subdivisions: int = 4) -> ScalpSurface:
    """An icosphere of ``radius`` [m] at ``center`` [m]; the scalp is the faces whose centroid has
    y - center_y > ``scalp_min_y`` * radius (default: the upper hemisphere).  Exact analytic SDF."""
    import trimesh

    if not (math.isfinite(radius) and radius > 0):
        raise ValueError(f"sphere_surface: radius must be a finite positive number, got {radius!r}")
    if not (math.isfinite(scalp_min_y) and -1.0 <= scalp_min_y < 1.0):
        raise ValueError(f"sphere_surface: scalp_min_y must lie in [-1, 1), got {scalp_min_y!r}")
    c = np.asarray(center, np.float64).reshape(3)
    m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    v = np.asarray(m.vertices) + c
    f = np.asarray(m.faces)
    scalp = v[f].mean(axis=1)[:, 1] - c[1] > scalp_min_y * radius

    def sdf(p):
        return np.linalg.norm(np.asarray(p, np.float64) - c, axis=1) - radius

    return ScalpSurface(v, f, scalp, name="sphere", sdf=sdf)


# --------------------------------------------------------------------------- configuration
@dataclass
class GeneratorConfig:
    """Parameters of :func:`generate_groom` (every length in metres).

    Attributes:
        style: ``"straight"``, ``"wavy"`` or ``"curly"``.
        strands: number of strands [-] (ignored when ``density`` is set).
        density: strands per scalp area [1/m^2] (human scalp: ~2e6), or None to use ``strands``.
        length: mean strand length [m].
        length_spread: lengths are uniform in length * [1 - spread, 1 + spread] [-], in [0, 1).
        radius: mean fibre radius [m].
        radius_spread: radii are uniform in radius * [1 - spread, 1 + spread] [-], in [0, 1).
        vertices_per_strand: vertices of each strand (>= 3) [-].
        seed: random seed; the same seed and surface give the same groom bit for bit.
        root_lift: the root sits this far outside the surface along its normal [m].
        clearance: growing hair is pushed out to at least this distance from the surface [m].
        gravity_bend: curvature with which the growth direction turns toward ``down`` [1/m].
        down: the direction hair falls toward (normalised here) [-].
        wave_amplitude: wavy: amplitude of the planar sine [m].
        wave_length: wavy: wavelength of the sine [m].
        curl_radius: curly: helix radius [m].
        curl_pitch: curly: helix pitch (length along the centreline per turn) [m].
        style_spread: per-strand random factor on the wave amplitude / curl radius, in [0, 1) [-].
        style_ramp: the wave or curl fades in over this arc length from the root [m].
        root_angle: angle of a strand's first direction above the scalp's tangent plane [deg], in (0, 90].
            Hair leaves a real scalp at a slant; 90 (along the normal) makes the crown's strands grow
            straight up, where gravity cannot turn them, and a 15-20 cm strand standing up is longer than
            hair's self-weight buckling length (~10 cm): no rest pose holds it (issue 14).
        back: the direction strands lean toward besides ``down`` (the comb direction is
            unit(t(down) + 0.2 t(back)), t the tangential part at the root); it decides the crown [-].
    """

    style: str = "straight"
    strands: int = 200
    density: float | None = None
    length: float = 0.2
    length_spread: float = 0.1
    radius: float = 5e-5
    radius_spread: float = 0.2
    vertices_per_strand: int = 32
    seed: int = 0
    root_lift: float = 5e-4
    clearance: float = 2e-3
    gravity_bend: float = 30.0
    down: tuple = (0.0, -1.0, 0.0)
    wave_amplitude: float = 6e-3
    wave_length: float = 0.05
    curl_radius: float = 5e-3
    curl_pitch: float = 0.02
    style_spread: float = 0.3
    style_ramp: float = 0.015
    root_angle: float = 30.0
    back: tuple = (0.0, 0.0, -1.0)

    def __post_init__(self):
        if self.style not in STYLES:
            raise ValueError(f"GeneratorConfig.style must be one of {STYLES}, got {self.style!r}")
        if not (isinstance(self.strands, (int, np.integer)) and not isinstance(self.strands, bool)
                and self.strands >= 1):
            raise ValueError(f"GeneratorConfig.strands must be an integer >= 1, got {self.strands!r}")
        if self.density is not None and not (_finite(self.density) and self.density > 0):
            raise ValueError(f"GeneratorConfig.density must be a finite positive number or None, got "
                             f"{self.density!r}")
        for name in ("length", "radius", "wave_length", "curl_pitch", "clearance"):
            v = getattr(self, name)
            if not (_finite(v) and v > 0):
                raise ValueError(f"GeneratorConfig.{name} must be a finite positive number, got {v!r}")
        for name in ("root_lift", "gravity_bend", "wave_amplitude", "curl_radius", "style_ramp"):
            v = getattr(self, name)
            if not (_finite(v) and v >= 0):
                raise ValueError(f"GeneratorConfig.{name} must be a finite number >= 0, got {v!r}")
        for name in ("length_spread", "radius_spread", "style_spread"):
            v = getattr(self, name)
            if not (_finite(v) and 0 <= v < 1):
                raise ValueError(f"GeneratorConfig.{name} must lie in [0, 1), got {v!r}")
        if not (isinstance(self.vertices_per_strand, (int, np.integer)) and self.vertices_per_strand >= 3):
            raise ValueError(f"GeneratorConfig.vertices_per_strand must be an integer >= 3, got "
                             f"{self.vertices_per_strand!r}")
        if not (isinstance(self.seed, (int, np.integer)) and self.seed >= 0):
            raise ValueError(f"GeneratorConfig.seed must be an integer >= 0, got {self.seed!r}")
        d = np.asarray(self.down, np.float64).reshape(-1)
        if d.shape != (3,) or not np.all(np.isfinite(d)) or np.linalg.norm(d) < 1e-12:
            raise ValueError(f"GeneratorConfig.down must be a non-zero finite 3-vector, got {self.down!r}")
        self.down = tuple(float(x) for x in d / np.linalg.norm(d))
        if not (_finite(self.root_angle) and 0.0 < self.root_angle <= 90.0):
            raise ValueError(f"GeneratorConfig.root_angle must lie in (0, 90] degrees, got {self.root_angle!r}")
        b = np.asarray(self.back, np.float64).reshape(-1)
        if b.shape != (3,) or not np.all(np.isfinite(b)):
            raise ValueError(f"GeneratorConfig.back must be a finite 3-vector, got {self.back!r}")
        self.back = tuple(float(x) for x in b)


def _finite(v) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool) and math.isfinite(v)


# --------------------------------------------------------------------------- generation
def sample_roots(surface: ScalpSurface, count: int, rng: np.random.Generator):
    """Area-weighted uniform points on the scalp: (points (count, 3) [m], unit normals (count, 3))."""
    areas = surface.face_areas() * surface.scalp
    face = rng.choice(len(areas), size=count, p=areas / areas.sum())
    r1, r2 = rng.random(count), rng.random(count)
    s = np.sqrt(r1)
    w = np.c_[1 - s, s * (1 - r2), s * r2]  # uniform barycentric coordinates
    tri = surface.faces[face]
    p = np.einsum("ck,ckd->cd", w, surface.vertices[tri])
    vn = surface.vertex_normals()
    n = np.einsum("ck,ckd->cd", w, vn[tri])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
    return p, n


def _push_out(surface: ScalpSurface, p: np.ndarray, clearance: float) -> np.ndarray:
    """Move points closer than ``clearance`` to the surface (or inside) out along the SDF gradient."""
    phi = surface.sdf(p)
    close = phi < clearance
    if not close.any():
        return p
    q = p[close]
    eps = 1e-4
    grad = np.stack([(surface.sdf(q + eps * e) - surface.sdf(q - eps * e)) / (2 * eps) for e in np.eye(3)], axis=1)
    grad /= np.maximum(np.linalg.norm(grad, axis=1, keepdims=True), 1e-12)
    p = p.copy()
    p[close] = q + (clearance - phi[close])[:, None] * grad
    return p


def _unit(v):
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-30)


def _resample(cum, curve, total, nv):
    """nv points of ``curve`` (K, 3) at arc lengths equally spaced in [0, total] (``cum``: arc length (K,))."""
    target = np.linspace(0.0, total, nv)
    return np.stack([np.interp(target, cum, curve[:, c]) for c in range(3)], axis=1)


def generate_groom(surface: ScalpSurface, config: GeneratorConfig | None = None):
    """A :class:`~taichi_hair.io.groom.Groom` grown on ``surface`` (see the module docstring).

    The Groom is in metres (float64 points), with per-strand ``radius`` and the
    configuration in ``params["generator"]``.
    """
    from ..io.groom import Groom

    cfg = config or GeneratorConfig()
    rng = np.random.default_rng(cfg.seed)
    count = int(cfg.strands)
    if cfg.density is not None:
        count = int(round(cfg.density * surface.scalp_area()))
        if count < 1:
            raise ValueError(f"GeneratorConfig.density {cfg.density} gives no strand on a scalp of "
                             f"{surface.scalp_area():.4g} m^2")
    from ..io.sizing import check_host

    check_host(count * int(cfg.vertices_per_strand), f"generating {count:,} strands", "use fewer strands")
    roots, normals = sample_roots(surface, count, rng)
    lengths = cfg.length * rng.uniform(1 - cfg.length_spread, 1 + cfg.length_spread, count)
    radii = cfg.radius * rng.uniform(1 - cfg.radius_spread, 1 + cfg.radius_spread, count)
    phases = rng.uniform(0, 2 * np.pi, count)
    amp_factor = rng.uniform(1 - cfg.style_spread, 1 + cfg.style_spread, count)
    nv = int(cfg.vertices_per_strand)
    down = np.asarray(cfg.down)

    # 2. Centreline, a little longer than the strand so resampling never runs short.
    steps = 4 * (nv - 1)
    h = 1.5 * lengths / steps  # per-strand step [m]
    x = np.empty((steps + 1, count, 3))
    x[0] = roots + cfg.root_lift * normals
    d = normals.copy()
    if cfg.root_angle < 90.0:
        def tangential(v):
            return v - np.sum(v * normals, axis=1, keepdims=True) * normals

        comb = _unit(tangential(down) + 0.2 * tangential(np.asarray(cfg.back)))
        a = math.radians(cfg.root_angle)
        # Where neither has a tangential part (comb ~ 0), leave along the normal.
        d = _unit(math.cos(a) * comb + math.sin(a) * normals)
    for k in range(steps):
        nxt = _push_out(surface, x[k] + h[:, None] * d, cfg.clearance)
        seg = nxt - x[k]
        d = _unit(seg)
        # Turn toward gravity: remove the component along d, bend by curvature gravity_bend over the step.
        g_perp = down - np.sum(down * d, axis=1, keepdims=True) * d
        d = _unit(d + (cfg.gravity_bend * h)[:, None] * g_perp)
        x[k + 1] = nxt

    # 3. Style offsets in a parallel-transported frame (b1, b2) along the centreline.
    if cfg.style != "straight":
        t = _unit(np.diff(x, axis=0))
        t = np.concatenate([t, t[-1:]], axis=0)
        b1 = _unit(np.cross(t[0], np.where(np.abs(t[0, :, 1:2]) < 0.9, [0.0, 1.0, 0.0], [1.0, 0.0, 0.0])))
        frames1 = np.empty_like(x)
        frames1[0] = b1
        for k in range(1, steps + 1):
            b = frames1[k - 1] - np.sum(frames1[k - 1] * t[k], axis=1, keepdims=True) * t[k]
            frames1[k] = _unit(b)
        frames2 = np.cross(t, frames1)
        s = np.arange(steps + 1)[:, None] * h[None, :]  # centreline arc length, (steps + 1, count)
        ramp = np.minimum(1.0, s / cfg.style_ramp) if cfg.style_ramp > 0 else np.ones_like(s)
        if cfg.style == "wavy":
            a = cfg.wave_amplitude * amp_factor
            ang = 2 * np.pi * s / cfg.wave_length + phases
            off = (ramp * a * (np.sin(ang) - np.sin(phases)))[..., None] * frames1
        else:
            r = cfg.curl_radius * amp_factor
            ang = 2 * np.pi * s / cfg.curl_pitch + phases
            off = (ramp * r)[..., None] * (np.cos(ang)[..., None] * frames1 + np.sin(ang)[..., None] * frames2)
        x = x + off
        x[0] = roots + cfg.root_lift * normals
        x = _push_out(surface, x.reshape(-1, 3), cfg.clearance).reshape(x.shape)
        x[0] = roots + cfg.root_lift * normals  # the root stays where it was planted

    # 4. Resample each strand to nv vertices equally spaced in arc length of the fine curve, choosing the
    # arc length T so that the *polyline* is as long as drawn (its chords cut corners of waves and curls).
    seg = np.linalg.norm(np.diff(x, axis=0), axis=2)  # (steps, count)
    cum = np.concatenate([np.zeros((1, count)), np.cumsum(seg, axis=0)], axis=0)
    points = np.empty((count, nv, 3))
    for i in range(count):
        total = min(lengths[i], cum[-1, i])
        for _ in range(20):  # fixed point T <- T L / polyline_length(T); a few steps unless aliased
            points[i] = _resample(cum[:, i], x[:, i], total, nv)
            poly = float(np.sum(np.linalg.norm(np.diff(points[i], axis=0), axis=1)))
            if abs(poly - lengths[i]) <= 1e-6 * lengths[i] or total >= cum[-1, i]:
                break
            total = min(total * lengths[i] / poly, cum[-1, i])
        points[i] = _resample(cum[:, i], x[:, i], total, nv)
    params = {"generator": {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(cfg).items()},
              "surface": surface.name}
    offsets = np.arange(count + 1, dtype=np.int64) * nv
    return Groom(points=points.reshape(-1, 3), strand_offsets=offsets, radius=radii, params=params,
                 units="m").validate()
