"""Strands, a head mesh and highlighted points drawn by Taichi kernels (``ViewerGGUI(drawing="raster")``).

Why: on a CPU workstation GGUI's Vulkan device is Mesa's lavapipe, which draws the 1.1 M lines of 86,000
render strands (14 vertices each) with their head at 960 x 720 in 633-668 ms per frame on 2 cores, read-back
included (``benchmarks/bench_groom.py --drawing lines``); without the lines the same frame took 9-12 ms (a probe,
BENCHMARKS.md).  Drawn here, by a parallel loop over edges on Taichi's CPU arch: 90-92 ms (``--drawing
raster``).  The picture is the one GGUI draws, to within
the rasterisation rules: unlit hair lines of ``line_width`` pixels in their per-vertex colours (interpolated
along each edge), a Gouraud-lit head (ambient plus one point light, as ``ViewerGGUI.render`` sets them) and
points as lit disks; no anti-aliasing in either.

The camera is :func:`taichi_hair.render.projection_matrix` @ :func:`view_matrix` (GGUI's own, checked by
``tests/test_render.py``).  Each pixel keeps the nearest fragment with one 64-bit ``atomic_min`` per
fragment: the key is the fragment's depth (28 bits of 1 - z_near / w, w the distance along the view
direction, which is affine in screen space) above 36 bits of payload (the primitive's id, then 6 bits of the
position along an edge).  The nearest fragment wins whatever order the threads run in, and equal depths are
broken by the id: the image is deterministic.  Primitives with a vertex behind the near plane are skipped
(GGUI clips them; the grooming tool and the renderer keep the groom in front of the camera), and nothing is cut at
the far plane (GGUI cuts there; the cameras of ``CameraConfig.framing`` put it behind the groom).

Image layout: ``image`` is (W, H) RGB in [0, 1] with row 0 at the *bottom*, as GGUI's
``canvas.set_image`` takes it and ``Window.get_image_buffer_as_numpy`` returns it.
"""


import numpy as np
import taichi as ti

vec3 = ti.math.vec3
vec4 = ti.math.vec4

#: Payload bits below the depth in a pixel's key: 30 bits of primitive id, 6 of edge position.
_ID_BITS = 30
_T_BITS = 6
_DEPTH_SCALE = float(1 << 28)
EMPTY = np.uint64(0xFFFFFFFFFFFFFFFF)
#: Longest screen-space step count of one edge (an edge across a 16k image).
_MAX_STEPS = 32768


@ti.func
def _key(depth, pid, t):
    """Pixel key: 28 bits of depth (0 at the near plane), 30 of primitive id, 6 of edge position t in [0, 1]."""
    q = ti.cast(ti.min(ti.max(depth, 0.0), 0.99999994) * _DEPTH_SCALE, ti.u64)
    tq = ti.cast(t * ((1 << _T_BITS) - 1) + 0.5, ti.u64)
    return (q << ti.u64(36)) | (ti.cast(pid, ti.u64) << ti.u64(_T_BITS)) | tq


@ti.kernel
def _clear(key: ti.template()):
    for i, j in key:
        key[i, j] = ti.u64(0xFFFFFFFFFFFFFFFF)


@ti.kernel
def _project(p: ti.template(), n: ti.i32, mvp: ti.types.matrix(4, 4, float), w_px: ti.i32, h_px: ti.i32,
             near: float, out: ti.template()):
    """Screen position of the first n points: (column, row from the bottom) [pixels], depth key in [0, 1)
    (1 - near / w) and w [m] (<= near: behind the near plane)."""
    for i in range(n):
        q = mvp @ vec4(p[i][0], p[i][1], p[i][2], 1.0)
        w = q[3]
        s = vec4(0.0, 0.0, 1.0, w)
        if w > near:
            s[0] = (q[0] / w + 1.0) * 0.5 * w_px
            s[1] = (q[1] / w + 1.0) * 0.5 * h_px
            s[2] = 1.0 - near / w
        out[i] = s


@ti.kernel
def _draw_edges(screen: ti.template(), index: ti.template(), edge_count: ti.i32, id0: ti.i32, width: ti.i32,
                near: float, key: ti.template()):
    """Every edge (index[2 e], index[2 e + 1]) as a DDA line of ``width`` pixels: a sample per pixel along the
    major axis, both ends included, its depth and edge position interpolated (affine in screen space)."""
    w_px, h_px = key.shape
    for e in range(edge_count):
        a = screen[index[2 * e]]
        b = screen[index[2 * e + 1]]
        if a[3] > near and b[3] > near:
            d = b - a
            n = ti.min(ti.cast(ti.max(ti.abs(d[0]), ti.abs(d[1])), ti.i32) + 1, _MAX_STEPS)
            lo = -((width - 1) // 2)
            for k in range(n + 1):
                t = k / n
                x = a[0] + t * d[0]
                y = a[1] + t * d[1]
                z = a[2] + t * d[2]
                kk = _key(z, id0 + e, t)
                i0 = ti.cast(ti.floor(x), ti.i32) + lo
                j0 = ti.cast(ti.floor(y), ti.i32) + lo
                for u in range(width):
                    for v in range(width):
                        i = i0 + u
                        j = j0 + v
                        if 0 <= i < w_px and 0 <= j < h_px:
                            if kk < key[i, j]:  # (most fragments of a dense groom are hidden: read first)
                                ti.atomic_min(key[i, j], kk)


@ti.func
def _edge_fn(a, b, px, py):
    return (b[0] - a[0]) * (py - a[1]) - (b[1] - a[1]) * (px - a[0])


@ti.kernel
def _draw_triangles(screen: ti.template(), index: ti.template(), count: ti.i32, near: float, key: ti.template()):
    """Every triangle whose three vertices are in front of the near plane, both faces, at the pixel centres
    it covers (depth interpolated by the barycentric coordinates)."""
    w_px, h_px = key.shape
    for t in range(count):
        a = screen[index[3 * t]]
        b = screen[index[3 * t + 1]]
        c = screen[index[3 * t + 2]]
        area = _edge_fn(a, b, c[0], c[1])
        if a[3] > near and b[3] > near and c[3] > near and area != 0.0:
            i0 = ti.max(ti.cast(ti.floor(ti.min(a[0], b[0], c[0])), ti.i32), 0)
            i1 = ti.min(ti.cast(ti.floor(ti.max(a[0], b[0], c[0])), ti.i32), w_px - 1)
            j0 = ti.max(ti.cast(ti.floor(ti.min(a[1], b[1], c[1])), ti.i32), 0)
            j1 = ti.min(ti.cast(ti.floor(ti.max(a[1], b[1], c[1])), ti.i32), h_px - 1)
            for i, j in ti.ndrange((i0, i1 + 1), (j0, j1 + 1)):
                px = i + 0.5
                py = j + 0.5
                l0 = _edge_fn(b, c, px, py) / area
                l1 = _edge_fn(c, a, px, py) / area
                l2 = 1.0 - l0 - l1
                if l0 >= 0.0 and l1 >= 0.0 and l2 >= 0.0:
                    kk = _key(l0 * a[2] + l1 * b[2] + l2 * c[2], t, 0.0)
                    if kk < key[i, j]:
                        ti.atomic_min(key[i, j], kk)


@ti.kernel
def _draw_points(screen: ti.template(), radius_px: ti.template(), count: ti.i32, id0: ti.i32, radius: float,
                 near: float, key: ti.template()):
    """Every point as a sphere of ``radius`` [m], ``radius_px[p]`` pixels on screen: a disk whose depth is
    the sphere's front (w - radius sqrt(1 - rho^2), rho the distance from the centre over the screen radius)."""
    w_px, h_px = key.shape
    for p in range(count):
        s = screen[p]
        r = radius_px[p]
        if s[3] > near:
            i0 = ti.max(ti.cast(ti.floor(s[0] - r), ti.i32), 0)
            i1 = ti.min(ti.cast(ti.floor(s[0] + r), ti.i32), w_px - 1)
            j0 = ti.max(ti.cast(ti.floor(s[1] - r), ti.i32), 0)
            j1 = ti.min(ti.cast(ti.floor(s[1] + r), ti.i32), h_px - 1)
            for i, j in ti.ndrange((i0, i1 + 1), (j0, j1 + 1)):
                rho2 = ((i + 0.5 - s[0]) ** 2 + (j + 0.5 - s[1]) ** 2) / (r * r)
                if rho2 <= 1.0:
                    kk = _key(1.0 - near / ti.max(s[3] - radius * ti.sqrt(1.0 - rho2), near), id0 + p, 0.0)
                    if kk < key[i, j]:
                        ti.atomic_min(key[i, j], kk)


@ti.kernel
def _light_vertices(p: ti.template(), normal: ti.template(), n: ti.i32, eye: vec3, light: vec3, base: vec3,
                    ambient: float, diffuse: float, out: ti.template()):
    """Gouraud colour of each head vertex: base (ambient + diffuse max(0, n . l)), the normal turned
    towards the eye (both faces lit, as GGUI's two-sided mesh)."""
    for i in range(n):
        nn = normal[i]
        if nn.dot(eye - p[i]) < 0.0:
            nn = -nn
        lit = ambient + diffuse * ti.max(0.0, nn.dot((light - p[i]).normalized()))
        out[i] = base * lit


@ti.kernel
def _shade(key: ti.template(), background: vec3, tri_index: ti.template(), tri_screen: ti.template(),
           tri_color: ti.template(), tri_count: ti.i32, edge_index: ti.template(), edge_color: ti.template(),
           edge_count: ti.i32, point_color: ti.template(), point_screen: ti.template(),
           point_radius_px: ti.template(), image: ti.template()):
    """Each pixel's colour from its nearest fragment (the background where there is none)."""
    for i, j in key:
        k = key[i, j]
        c = background
        if k != ti.u64(0xFFFFFFFFFFFFFFFF):
            pid = ti.cast((k >> ti.u64(_T_BITS)) & ti.u64((1 << _ID_BITS) - 1), ti.i32)
            tq = ti.cast(k & ti.u64((1 << _T_BITS) - 1), ti.i32)
            if pid < tri_count:
                a = tri_screen[tri_index[3 * pid]]
                b = tri_screen[tri_index[3 * pid + 1]]
                cc = tri_screen[tri_index[3 * pid + 2]]
                area = _edge_fn(a, b, cc[0], cc[1])
                l0 = _edge_fn(b, cc, i + 0.5, j + 0.5) / area
                l1 = _edge_fn(cc, a, i + 0.5, j + 0.5) / area
                c = (l0 * tri_color[tri_index[3 * pid]] + l1 * tri_color[tri_index[3 * pid + 1]]
                     + (1.0 - l0 - l1) * tri_color[tri_index[3 * pid + 2]])
            elif pid < tri_count + edge_count:
                e = pid - tri_count
                t = tq / ((1 << _T_BITS) - 1)
                c = (1.0 - t) * edge_color[edge_index[2 * e]] + t * edge_color[edge_index[2 * e + 1]]
            else:
                q = pid - tri_count - edge_count
                s = point_screen[q]
                r = point_radius_px[q]
                rr = ((i + 0.5 - s[0]) ** 2 + (j + 0.5 - s[1]) ** 2) / ti.max(r * r, 1e-12)
                c = point_color[q] * (0.45 + 0.7 * ti.sqrt(ti.max(0.0, 1.0 - rr)))
        image[i, j] = ti.min(c, 1.0)


@ti.kernel
def _point_radii(screen: ti.template(), n: ti.i32, radius: float, focal_px: float, out: ti.template()):
    """Screen radius [pixels] of a sphere of ``radius`` [m] at each point (focal_px / w per metre), >= 1."""
    for i in range(n):
        out[i] = ti.max(1.0, radius * focal_px / ti.max(screen[i][3], 1e-9))


class Rasterizer:
    """The image of one :class:`taichi_hair.render.ViewerGGUI` (fields allocated once per image size, and per
    vertex, head and point count as they grow).

    Attributes:
        key: nearest fragment of each pixel (depth above payload, module docstring), uint64 (W, H).
        image: RGB in [0, 1], float32 (W, H, 3), row 0 at the bottom.
    """

    def __init__(self, width: int, height: int):
        self.width, self.height = int(width), int(height)
        self.key = ti.field(ti.u64, (self.width, self.height))
        self.image = ti.Vector.field(3, ti.f32, (self.width, self.height))
        self._fields = {}
        # Stand-ins for what a frame does not have (no head, no strands, no points): the shading kernel reads
        # none of them then, but takes a field for each.
        self._none3 = ti.Vector.field(3, ti.f32, 1)
        self._none_index = ti.field(ti.i32, 3)

    def _field(self, name: str, n: int, components: int):
        """Scratch field ``name`` of at least n entries (``components`` floats each), grown in powers of two (each
        new field compiles the kernels that take it again: a pin more must not)."""
        f = self._fields.get(name)
        if f is None or f.shape[0] < n:
            size = 1 << max(4, (max(n, 1) - 1).bit_length())
            f = ti.field(ti.f32, size) if components == 1 else ti.Vector.field(components, ti.f32, size)
            self._fields[name] = f
        return f

    def draw(self, viewer, mvp: np.ndarray, light, ambient: float, diffuse: float) -> None:
        """Draw the viewer's strands, head and points into :attr:`image`; ``mvp``: its camera's 4x4 world ->
        clip matrix (``projection_matrix @ view_matrix`` of :mod:`taichi_hair.render`); ``light``: the point
        light's position [m]; ``ambient``, ``diffuse``: the head's light levels (those ``ViewerGGUI`` gives GGUI)."""
        cam = viewer.camera_config
        mvp = np.asarray(mvp, dtype=np.float32)
        M = ti.Matrix(mvp.tolist())
        near = float(cam.z_near)
        _clear(self.key)
        tri_count = 0
        tri_screen = point_screen = self._field("points", viewer.point_count, 4)
        tri_color = edge_color = self._none3
        tri_index = edge_index = self._none_index
        if viewer.head_vertex is not None and viewer.head_index.shape[0] >= 3:
            nv = viewer.head_vertex.shape[0]
            tri_screen = self._field("head", nv, 4)
            tri_color = self._field("head_color", nv, 3)
            tri_index = viewer.head_index
            tri_count = tri_index.shape[0] // 3
            _project(viewer.head_vertex, nv, M, self.width, self.height, near, tri_screen)
            _light_vertices(viewer.head_vertex, viewer.head_normal, nv, vec3(*cam.eye), vec3(*light),
                            vec3(*viewer.head_color), ambient, diffuse, tri_color)
            _draw_triangles(tri_screen, tri_index, tri_count, near, self.key)
        edge_count = 0
        if viewer.vertex_position is not None and viewer._edge_key[0] > 0:
            nv = viewer.vertex_position.shape[0]
            edge_screen = self._field("strands", nv, 4)
            edge_index, edge_color = viewer.edge_index, viewer.vertex_color
            edge_count = viewer._edge_key[0] // 2
            _project(viewer.vertex_position, nv, M, self.width, self.height, near, edge_screen)
            width = max(1, int(round(viewer.line_width)))
            _draw_edges(edge_screen, edge_index, edge_count, tri_count, width, near, self.key)
        point_radius = self._field("point_radius", point_screen.shape[0], 1)
        point_color = self._none3
        if viewer.point_count > 0:
            point_color = viewer.point_color
            _project(viewer.point_position, viewer.point_count, M, self.width, self.height, near, point_screen)
            _point_radii(point_screen, viewer.point_count, viewer.point_radius, float(mvp[1, 1]) * 0.5 * self.height,
                         point_radius)
            _draw_points(point_screen, point_radius, viewer.point_count, tri_count + edge_count, viewer.point_radius,
                         near, self.key)
        _shade(self.key, vec3(*viewer.background), tri_index, tri_screen, tri_color, tri_count, edge_index,
               edge_color, edge_count, point_color, point_screen, point_radius, self.image)
