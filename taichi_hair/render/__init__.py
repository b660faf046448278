"""Drawing grooms with Taichi GGUI, on screen and off screen (Daviet 2023, Sec. 5.3 tool).

* :class:`CameraConfig` and the pure-NumPy camera of GGUI: :func:`view_matrix`,
  :func:`projection_matrix` (the matrices ``ti.ui.Camera`` builds, in the
  column-vector convention; a test compares them with the camera's own),
  :func:`project` (world points to pixel coordinates of the saved image) and
  :func:`pick_ray` (a pixel back to a world ray, for selecting strands).
* :func:`strand_colors`: per-vertex colours by ``"region"`` (root direction
  around the groom's centre, or ``Groom.region`` when the file has it),
  ``"strand"`` (a fixed random colour per strand), ``"groom"`` (the file's
  ``color``), ``"error"`` (per-vertex values through
  :func:`taichi_hair.groom.skinning.error_colors`) and a selection highlight.
* :class:`ViewerGGUI`: the strands as GGUI lines (one segment per edge, by an
  index field), optional points (selection, pins) and a head mesh, all in
  fields allocated once per layout, drawn by GGUI or, where Taichi runs on the
  CPU, by the Taichi rasteriser of :mod:`taichi_hair.render.raster` (the same
  picture, ~7x faster than Mesa's software Vulkan device draws 86,000 strands:
  ``ViewerGGUI(drawing=...)``); :meth:`ViewerGGUI.render` draws a frame,
  :meth:`ViewerGGUI.image` reads it back as an (H, W, 3) uint8 array, top row
  first, as :func:`save_png` writes it.  ``show_window=False`` renders off
  screen.

GGUI needs a Vulkan device.  On a machine without a GPU, Mesa's software
Vulkan driver (lavapipe, Debian's ``mesa-vulkan-drivers``) provides one;
GGUI then works with ``ti.init(arch=ti.cpu)`` (checked on the 2-core CI VM:
Taichi 1.7.4, x64 arch).  Lines are drawn with the device's line width (a
``width`` above 1 pixel may be ignored by a software device).

Image conventions: ``Window.get_image_buffer_as_numpy()`` returns (W, H, 4)
floats with the first row at the *bottom*; :meth:`ViewerGGUI.image` flips it to
(H, W, 3) uint8, row 0 at the top, and :func:`project` returns (column, row)
in that image: a point projecting to NDC (x, y) lands at column
(x + 1) / 2 W and row (1 - y) / 2 H (pixel i covers [i, i + 1)).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

COLOR_MODES = ("region", "strand", "groom", "error", "uniform")


# =========================================================================== camera (NumPy)
@dataclass
class CameraConfig:
    """A perspective camera, as GGUI's ``ti.ui.Camera`` takes it.

    Attributes:
        eye: camera position, 3 components [m].
        target: the point looked at, 3 components [m].
        up: the up direction (need not be unit or orthogonal to the view direction) [-].
        fov: vertical field of view [degrees], in (0, 180).
        z_near: distance of the near clipping plane [m] (> 0).
        z_far: distance of the far clipping plane [m] (> z_near).
    """

    eye: tuple = (0.0, 0.05, 0.6)
    target: tuple = (0.0, 0.0, 0.0)
    up: tuple = (0.0, 1.0, 0.0)
    fov: float = 45.0
    z_near: float = 0.01
    z_far: float = 100.0

    def __post_init__(self):
        for name in ("eye", "target", "up"):
            try:
                v = tuple(float(c) for c in getattr(self, name))
            except (TypeError, ValueError):
                v = ()
            if len(v) != 3 or not all(math.isfinite(c) for c in v):
                raise ValueError(f"CameraConfig.{name} must be 3 finite numbers, got {getattr(self, name)!r}")
            setattr(self, name, v)
        f = np.subtract(self.target, self.eye)
        if np.linalg.norm(f) == 0:
            raise ValueError("CameraConfig: eye and target must differ")
        if np.linalg.norm(np.cross(f, self.up)) <= 1e-12 * np.linalg.norm(f) * max(np.linalg.norm(self.up), 1e-300):
            raise ValueError("CameraConfig.up must not be parallel to the view direction (target - eye)")
        if not (isinstance(self.fov, (int, float)) and math.isfinite(self.fov) and 0 < self.fov < 180):
            raise ValueError(f"CameraConfig.fov must lie in (0, 180) degrees, got {self.fov!r}")
        if not (math.isfinite(self.z_near) and self.z_near > 0 and math.isfinite(self.z_far)
                and self.z_far > self.z_near):
            raise ValueError(f"CameraConfig: need 0 < z_near < z_far, got {self.z_near!r}, {self.z_far!r}")
        self.fov, self.z_near, self.z_far = float(self.fov), float(self.z_near), float(self.z_far)

    @classmethod
    def framing(cls, points, direction=(0.0, 0.15, 1.0), fov: float = 35.0, margin: float = 1.15) -> "CameraConfig":
        """A camera looking at the bounding sphere of ``points`` [m] from ``direction``, far enough
        that the sphere (times ``margin``) fits the vertical field of view."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        lo, hi = p.min(axis=0), p.max(axis=0)
        center = 0.5 * (lo + hi)
        radius = max(0.5 * float(np.linalg.norm(hi - lo)), 1e-6) * margin
        d = np.asarray(direction, dtype=np.float64)
        d = d / np.linalg.norm(d)
        dist = radius / math.sin(math.radians(fov) / 2)
        return cls(eye=tuple(center + dist * d), target=tuple(center), fov=fov,
                   z_near=max(dist - 2 * radius, dist * 1e-3), z_far=dist + 4 * radius)


def _basis(cam: CameraConfig):
    eye = np.asarray(cam.eye, dtype=np.float64)
    f = np.asarray(cam.target, dtype=np.float64) - eye
    f /= np.linalg.norm(f)
    s = np.cross(f, np.asarray(cam.up, dtype=np.float64))
    s /= np.linalg.norm(s)
    u = np.cross(s, f)
    return eye, f, s, u


def view_matrix(cam: CameraConfig) -> np.ndarray:
    """World -> camera 4x4 matrix (column vectors: x_cam = V @ [x, 1]), right-handed, looking down -z.
    ``ti.ui.Camera.get_view_matrix()`` returns its transpose."""
    eye, f, s, u = _basis(cam)
    v = np.eye(4)
    v[0, :3], v[1, :3], v[2, :3] = s, u, -f
    v[:3, 3] = -v[:3, :3] @ eye
    return v


def projection_matrix(cam: CameraConfig, aspect: float) -> np.ndarray:
    """Camera -> clip 4x4 matrix of GGUI (column vectors; ``get_projection_matrix(aspect)`` returns
    its transpose): vertical ``fov``, ``aspect`` = width / height, reversed depth (near -> 1, far -> 0)."""
    t = 1.0 / math.tan(math.radians(cam.fov) / 2)
    n, fz = cam.z_near, cam.z_far
    p = np.zeros((4, 4))
    p[0, 0] = t / aspect
    p[1, 1] = t
    p[2, 2] = n / (fz - n)
    p[2, 3] = fz * n / (fz - n)
    p[3, 2] = -1.0
    return p


def project(points, cam: CameraConfig, width: int, height: int):
    """Pixel coordinates of world points in the (height, width) image of :meth:`ViewerGGUI.image`.

    Returns:
        ``(pixels, depth, visible)``: (n, 2) float (column, row) with row 0 at the top; (n,) distance
        along the view direction [m]; (n,) bool, in front of the near plane and inside the image.
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    clip = (projection_matrix(cam, width / height) @ view_matrix(cam) @ np.c_[p, np.ones(len(p))].T).T
    w = clip[:, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        ndc = clip[:, :2] / w[:, None]
    col = (ndc[:, 0] + 1.0) * 0.5 * width
    row = (1.0 - ndc[:, 1]) * 0.5 * height
    depth = w  # -z_cam
    visible = (depth > cam.z_near) & (depth < cam.z_far) & (col >= 0) & (col < width) & (row >= 0) & (row < height)
    return np.c_[col, row], depth, visible


def pick_ray(cam: CameraConfig, width: int, height: int, column: float, row: float):
    """World ray (origin, unit direction) through the image point (column, row) [pixels, row 0 at the top]."""
    eye, f, s, u = _basis(cam)
    t = math.tan(math.radians(cam.fov) / 2)
    x = (2.0 * column / width - 1.0) * t * width / height
    y = (1.0 - 2.0 * row / height) * t
    d = f + x * s + y * u
    return eye.copy(), d / np.linalg.norm(d)


# =========================================================================== colours (NumPy)
def _hsv(h, s, v):
    h = np.mod(h, 1.0) * 6.0
    i = np.floor(h).astype(np.int64) % 6
    f = h - np.floor(h)
    p, q, t = v * (1 - s), v * (1 - s * f), v * (1 - s * (1 - f))
    table = np.stack([np.c_[v, t, p], np.c_[q, v, p], np.c_[p, v, t], np.c_[p, q, v], np.c_[t, p, v],
                      np.c_[v, p, q]])
    return table[i, np.arange(len(h))]


def strand_colors(groom, mode: str = "region", values=None, selection=None, vmax=None) -> np.ndarray:
    """Per-vertex RGB in [0, 1], float32, shape (vertex_count, 3).

    Args:
        groom: a :class:`taichi_hair.io.Groom`.
        mode: ``"region"`` (``groom.region`` if present, else the root's direction around the roots'
            centre as a hue, so neighbouring strands share a colour), ``"strand"`` (a random colour per
            strand, seeded by its index), ``"groom"`` (the file's ``color``; region colours when it has
            none), ``"error"`` (``values`` per vertex or per strand [m] on the ramp of
            :func:`taichi_hair.groom.skinning.error_colors`, up to ``vmax``), ``"uniform"`` (hair brown).
        selection: optional bool per vertex: selected vertices are drawn in bright orange.
    """
    if mode not in COLOR_MODES:
        raise ValueError(f"colour mode must be one of {COLOR_MODES}, got {mode!r}")
    counts = groom.strand_vertex_counts()
    ns, nv = groom.strand_count, groom.vertex_count
    if mode == "groom" and groom.color is not None:
        c = np.asarray(groom.color, dtype=np.float32)
        col = np.repeat(c, counts, axis=0) if c.shape[0] == ns else c.copy()
    elif mode == "error":
        if values is None:
            raise ValueError("colour mode 'error' needs per-vertex or per-strand error values")
        v = np.asarray(values, dtype=np.float64).reshape(-1)
        if v.shape[0] == ns and ns != nv:
            v = np.repeat(v, counts)
        if v.shape[0] != nv:
            raise ValueError(f"error values: {v.shape[0]} entries for {nv} vertices / {ns} strands")
        from ..groom.skinning import error_colors

        col = error_colors(v, vmax)
    elif mode == "strand":
        rng = np.random.default_rng(12345)
        per = _hsv(rng.random(ns), 0.55 + 0.3 * rng.random(ns), 0.6 + 0.35 * rng.random(ns))
        col = np.repeat(per, counts, axis=0)
    elif mode == "uniform":
        col = np.tile(np.array([[0.45, 0.3, 0.18]]), (nv, 1))
    else:
        if groom.region is not None:
            r = np.asarray(groom.region, dtype=np.int64)
            per = _hsv(np.mod(r * 0.618034, 1.0), np.full(ns, 0.65), np.full(ns, 0.9))
        else:
            roots = np.asarray(groom.points, dtype=np.float64)[groom.strand_offsets[:-1]]
            d = roots - roots.mean(axis=0)
            hue = (np.arctan2(d[:, 0], d[:, 2]) / (2 * np.pi)) % 1.0
            top = np.ptp(d[:, 1]) if ns > 1 else 0.0
            val = 0.65 + 0.3 * ((d[:, 1] - d[:, 1].min()) / top if top > 0 else np.zeros(ns))
            per = _hsv(hue, np.full(ns, 0.6), val)
        col = np.repeat(per, counts, axis=0)
    col = np.asarray(col, dtype=np.float32)
    if selection is not None:
        sel = np.asarray(selection, dtype=bool).reshape(-1)
        if sel.shape[0] != nv:
            raise ValueError(f"selection has {sel.shape[0]} entries for {nv} vertices")
        col[sel] = (1.0, 0.55, 0.05)
    return col


def edge_indices(strand_offsets) -> np.ndarray:
    """Index pairs (2 E,) int32 of every edge (consecutive vertices of one strand), for GGUI lines."""
    off = np.asarray(strand_offsets, dtype=np.int64)
    n = int(off[-1])
    keep = np.ones(max(n - 1, 0), dtype=bool)
    keep[off[1:-1] - 1] = False
    k = np.nonzero(keep)[0]
    return np.c_[k, k + 1].reshape(-1).astype(np.int32)


def sphere_mesh(center=(0.0, 0.0, 0.0), radius: float = 0.09, rings: int = 24, segments: int = 48):
    """A UV sphere (vertices (n, 3) [m], triangles (m, 3) int) for drawing a spherical head."""
    th = np.linspace(0.0, np.pi, rings + 1)
    ph = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    t, p = np.meshgrid(th, ph, indexing="ij")
    v = np.c_[np.sin(t).ravel() * np.cos(p).ravel(), np.cos(t).ravel(), np.sin(t).ravel() * np.sin(p).ravel()]
    v = np.asarray(center, dtype=np.float64) + radius * v
    tris = []
    for i in range(rings):
        for j in range(segments):
            a, b = i * segments + j, i * segments + (j + 1) % segments
            c, d = a + segments, b + segments
            tris += [(a, c, b), (b, c, d)]
    return v, np.asarray(tris, dtype=np.int64)


def save_png(path, image: np.ndarray) -> None:
    """Write an (H, W, 3) uint8 image as PNG (matplotlib's writer; no Taichi needed)."""
    import matplotlib.image as mpimg

    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] not in (3, 4) or img.dtype != np.uint8:
        raise ValueError(f"save_png: expected an (H, W, 3) uint8 image, got {img.shape} {img.dtype}")
    mpimg.imsave(str(path), img)


def _copy_kernel():
    import taichi as ti

    @ti.kernel
    def copy_prefix(src: ti.template(), dst: ti.template()):
        for i in src:
            dst[i] = ti.cast(src[i], ti.f32)

    return copy_prefix


_COPY = []


def _copy_prefix(src, dst) -> None:
    if not _COPY:
        _COPY.append(_copy_kernel())
    _COPY[0](src, dst)


# =========================================================================== the viewer
#: ``ViewerGGUI(drawing=...)``: "auto" draws with the Taichi rasteriser when Taichi runs on the CPU (a CPU
#: machine, whose Vulkan device is then usually Mesa's software one), else with GGUI lines.
DRAWINGS = ("auto", "lines", "raster")


class ViewerGGUI:
    """Strands (lines), points and a head mesh drawn with GGUI, on screen or off screen.

    Args:
        width, height: image size [pixels].
        show_window: False renders off screen (no display needed).
        title: window title.
        background: RGB in [0, 1].
        line_width: line width [pixels] (GGUI's may be ignored by the device; the rasteriser rounds it).
        drawing: :data:`DRAWINGS`: GGUI's scene (``"lines"``) or the Taichi rasteriser of
            :mod:`taichi_hair.render.raster` (``"raster"``: the same picture, ~6x faster than lavapipe on
            a CPU machine; no Vulkan readback off screen, ``canvas.set_image`` on screen).

    Fields are allocated by :meth:`set_strands` / :meth:`set_head` when the layout (vertex or edge
    count) changes and reused otherwise, so drawing an edited groom of the same layout allocates
    nothing.  Taichi must be initialised first (any arch; GGUI itself runs on Vulkan).
    """

    #: Ambient light and the point light's level (above the eye), for GGUI's scene and the rasteriser alike [-].
    AMBIENT = 0.45
    DIFFUSE = 0.7

    def __init__(self, width: int = 640, height: int = 480, show_window: bool = False, title: str = "taichi-hair",
                 background=(0.12, 0.12, 0.14), line_width: float = 1.0, drawing: str = "auto"):
        import taichi as ti

        for name, v in (("width", width), ("height", height)):
            if not (isinstance(v, (int, np.integer)) and 8 <= v <= 16384):
                raise ValueError(f"ViewerGGUI: {name} must be an integer in [8, 16384] pixels, got {v!r}")
        if drawing not in DRAWINGS:
            raise ValueError(f"ViewerGGUI: drawing must be one of {', '.join(DRAWINGS)}, got {drawing!r}")
        if drawing == "auto":
            drawing = "raster" if ti.lang.impl.current_cfg().arch in (ti.x64, ti.arm64) else "lines"
        #: "lines" (GGUI lines on the Vulkan device) or "raster" (:mod:`taichi_hair.render.raster`).
        self.drawing = drawing
        self.show_window = bool(show_window)
        self.width, self.height = int(width), int(height)
        self._raster = None
        if drawing == "raster":
            from .raster import Rasterizer

            self._raster = Rasterizer(self.width, self.height)
        self.window = ti.ui.Window(title, (self.width, self.height), show_window=show_window, vsync=show_window)
        self.canvas = self.window.get_canvas()
        self.scene = self.window.get_scene()
        self.camera = ti.ui.Camera()
        self.background = tuple(float(c) for c in background)
        self.line_width = float(line_width)
        self.camera_config = CameraConfig()
        #: Strand vertex positions [m], shape (V,); colours RGB, shape (V,); edge index pairs, shape (2 E,).
        self.vertex_position = None
        self.vertex_color = None
        self.edge_index = None
        self._edge_key = None
        #: The offsets and colour array of the last :meth:`set_strands` (what it can skip when they come again).
        self._offsets_in = None
        self._colors_in = None
        #: Highlighted points (selection, pins) [m] and colours, shape (P,), P = capacity.
        self.point_position = None
        self.point_color = None
        self.point_count = 0
        self.point_radius = 1e-3
        #: Head mesh: vertices [m], normals, triangle indices (3 T,).
        self.head_vertex = None
        self.head_normal = None
        self.head_index = None
        self.head_color = (0.78, 0.66, 0.58)

    # ------------------------------------------------------------------ data
    def set_camera(self, cam: CameraConfig) -> None:
        self.camera_config = cam

    def set_strands(self, points, strand_offsets, colors) -> None:
        """Upload strand polylines (points (V, 3) [m], strand_offsets (S + 1,)) and per-vertex RGB.  Called again with
        the same offsets, only the positions are uploaded, and the colours too unless ``colors`` is the very array
        object of the last call (taken as unchanged: pass a new array, not the old one changed in place)."""
        import taichi as ti

        p = np.ascontiguousarray(points, dtype=np.float32).reshape(-1, 3)
        c = np.ascontiguousarray(colors, dtype=np.float32).reshape(-1, 3)
        if c.shape[0] != p.shape[0]:
            raise ValueError(f"set_strands: {c.shape[0]} colours for {p.shape[0]} vertices")
        # GGUI cuts an odd vertex count to the even number below (even with an index buffer):
        # the fields hold an even count, one unused padding vertex if needed.
        n = p.shape[0] + (p.shape[0] % 2)
        if p.shape[0] % 2:
            p = np.vstack([p, p[-1:]])
            c = np.vstack([c, c[-1:]])
        # The same strands (offsets) as the last call: the fields and edge indices stay, and the colours too when
        # they are the same array object (the grooming window calls this every frame; 86,000 strands: ~40 ms).
        off = np.asarray(strand_offsets)
        same_strands = (self._offsets_in is not None and self._offsets_in.shape == off.shape
                        and np.array_equal(self._offsets_in, off) and self.vertex_position is not None
                        and self.vertex_position.shape[0] == n)
        if not same_strands:
            self._offsets_in = off.copy()
            self._colors_in = None
            idx = edge_indices(off)
            if self.vertex_position is None or self.vertex_position.shape[0] != n:
                self.vertex_position = ti.Vector.field(3, ti.f32, n)
                self.vertex_color = ti.Vector.field(3, ti.f32, n)
            if self.edge_index is None or self.edge_index.shape[0] != idx.shape[0]:
                self.edge_index = ti.field(ti.i32, max(idx.shape[0], 2))
                self._edge_key = None
            key = (idx.shape[0], hash(idx.tobytes()))
            if self._edge_key != key:
                buf = np.zeros(self.edge_index.shape[0], dtype=np.int32)
                buf[: idx.shape[0]] = idx
                self.edge_index.from_numpy(buf)
                self._edge_key = key
        self.vertex_position.from_numpy(p)
        if colors is not self._colors_in:
            self.vertex_color.from_numpy(c)
            self._colors_in = colors

    def set_positions_field(self, field) -> None:
        """Copy strand positions from a Taichi vector field (no host round trip); its size must be the
        vertex count of :meth:`set_strands` (the padding vertex, if any, keeps its value)."""
        if field.shape[0] == self.vertex_position.shape[0]:
            self.vertex_position.copy_from(field)
        else:
            _copy_prefix(field, self.vertex_position)

    def set_points(self, points, colors=None, radius: float = 1e-3) -> None:
        """Highlighted points (e.g. selected or pinned vertices) [m]; an empty array hides them."""
        import taichi as ti

        p = np.asarray(points, dtype=np.float32).reshape(-1, 3)
        n = p.shape[0]
        self.point_count = n
        self.point_radius = float(radius)
        if n == 0:
            return
        cap = 1 << max(4, int(math.ceil(math.log2(n))))
        if self.point_position is None or self.point_position.shape[0] < n:
            self.point_position = ti.Vector.field(3, ti.f32, cap)
            self.point_color = ti.Vector.field(3, ti.f32, cap)
        m = self.point_position.shape[0]
        buf = np.zeros((m, 3), dtype=np.float32)
        buf[:n] = p
        self.point_position.from_numpy(buf)
        col = np.tile(np.array([[1.0, 0.9, 0.1]], dtype=np.float32), (m, 1))
        if colors is not None:
            col[:n] = np.asarray(colors, dtype=np.float32).reshape(-1, 3)
        self.point_color.from_numpy(col)

    def set_head(self, vertices, triangles, color=(0.78, 0.66, 0.58)) -> None:
        """A head (or body) triangle mesh [m]; smooth vertex normals are computed here."""
        import taichi as ti

        v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
        t = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
        if t.size and (t.min() < 0 or t.max() >= len(v)):
            raise ValueError("set_head: a triangle index is out of range")
        n = np.zeros_like(v)
        fn = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
        for k in range(3):
            np.add.at(n, t[:, k], fn)
        n /= np.maximum(np.linalg.norm(n, axis=1), 1e-30)[:, None]
        if self.head_vertex is None or self.head_vertex.shape[0] != len(v):
            self.head_vertex = ti.Vector.field(3, ti.f32, len(v))
            self.head_normal = ti.Vector.field(3, ti.f32, len(v))
        if self.head_index is None or self.head_index.shape[0] != t.size:
            self.head_index = ti.field(ti.i32, t.size)
        self.head_vertex.from_numpy(v.astype(np.float32))
        self.head_normal.from_numpy(n.astype(np.float32))
        self.head_index.from_numpy(t.reshape(-1).astype(np.int32))
        self.head_color = tuple(float(c) for c in color)

    # ------------------------------------------------------------------ drawing
    def ggui_camera(self, c: CameraConfig):
        """The viewer's ``ti.ui.Camera`` set to ``c`` (what :meth:`render` draws GGUI's scene with)."""
        cam = self.camera
        cam.position(*c.eye)
        cam.lookat(*c.target)
        cam.up(*c.up)
        cam.fov(c.fov)
        cam.z_near(c.z_near)
        cam.z_far(c.z_far)
        return cam

    def render(self) -> None:
        """Draw one frame into the window's image (call :meth:`show` afterwards on screen)."""
        c = self.camera_config
        eye = np.asarray(c.eye)
        light = tuple(eye + np.array([0.0, 0.5, 0.0]) * np.linalg.norm(eye - np.asarray(c.target)))  # [m]
        if self._raster is not None:
            self._raster.draw(self, projection_matrix(c, self.width / self.height) @ view_matrix(c), light,
                              self.AMBIENT, self.DIFFUSE)
            if self.show_window:
                self.canvas.set_image(self._raster.image)
            return
        s = self.scene
        s.set_camera(self.ggui_camera(c))
        s.ambient_light((self.AMBIENT,) * 3)
        s.point_light(pos=light, color=(self.DIFFUSE,) * 3)
        if self.head_vertex is not None:
            s.mesh(self.head_vertex, indices=self.head_index, normals=self.head_normal, color=self.head_color)
        if self.vertex_position is not None and self._edge_key[0] > 0:
            s.lines(self.vertex_position, self.line_width, indices=self.edge_index,
                    per_vertex_color=self.vertex_color, index_count=self._edge_key[0])
        if self.point_count > 0:
            s.particles(self.point_position, self.point_radius, per_vertex_color=self.point_color,
                        index_count=self.point_count)
        self.canvas.set_background_color(self.background)
        self.canvas.scene(s)

    def image(self) -> np.ndarray:
        """The last rendered frame as (height, width, 3) uint8, row 0 at the top."""
        if self._raster is not None and not self.show_window:
            buf = self._raster.image.to_numpy()  # (on screen: the window's own buffer below, what it shows)
        else:
            buf = self.window.get_image_buffer_as_numpy()  # (W, H, 4), first row at the bottom
        rgb = np.clip(buf[:, :, :3], 0.0, 1.0)
        return np.ascontiguousarray((np.flipud(rgb.transpose(1, 0, 2)) * 255.0 + 0.5).astype(np.uint8))

    def save(self, path) -> np.ndarray:
        """Render and write a PNG; returns the image."""
        self.render()
        img = self.image()
        save_png(path, img)
        return img

    def show(self) -> None:
        self.window.show()

    def close(self) -> None:
        """Destroy the window (and its Vulkan resources); do it before ``ti.init`` runs again."""
        if self.window is not None:
            self.window.destroy()
            self.window = None


# =========================================================================== one-call still
def render_groom(groom, path=None, camera: CameraConfig | None = None, width: int = 640, height: int = 480,
                 color: str = "region", values=None, head=None, viewer: ViewerGGUI | None = None,
                 head_color=(0.78, 0.66, 0.58)) -> np.ndarray:
    """Render ``groom.points`` off screen (Taichi must be initialised); write a PNG if ``path``.

    Args:
        camera: default :meth:`CameraConfig.framing` of the strands (and head).
        color, values: see :func:`strand_colors`.
        head: optional (vertices, triangles) mesh [m], drawn in ``head_color`` (RGB in [0, 1]).
        viewer: reuse an off-screen viewer of the same size (its fields are reused).
    Returns:
        the (height, width, 3) uint8 image.
    """
    v = viewer or ViewerGGUI(width, height, show_window=False)
    if camera is None:
        pts = groom.points if head is None else np.vstack([groom.points, np.asarray(head[0]).reshape(-1, 3)])
        camera = CameraConfig.framing(pts)
    v.set_camera(camera)
    v.set_strands(groom.points, groom.strand_offsets, strand_colors(groom, color, values))
    if head is not None:
        v.set_head(*head, color=head_color)
    v.render()
    img = v.image()
    if path is not None:
        save_png(path, img)
    return img
