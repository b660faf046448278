"""Procedural scenes for the command line and the examples.

``hang``: strands planted on the lower half of a sphere (a stand-in head),
growing along the surface normal with a slight natural curl, clamped at the
root and left to hang under gravity while the sphere nods.  There are no
contacts yet (Sec. 4.5 is the contacts issue): roots sit on the cap y < -0.6 R
so the strands hang clear of the sphere rather than through it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..builder import GroomBuilder
from ..config import RodMaterial


@dataclass
class HangScene:
    """Parameters of the ``hang`` scene.

    Attributes:
        strands: number of strands [-].
        length: strand length [m].
        edge_length: target rest edge length [m].
        sphere_radius: radius of the sphere the roots are planted on [m].
        curl_radius: radius of the natural helical curl, 0 for straight [m].
        curl_pitch: pitch of the curl [m].
        nod_amplitude: amplitude of the sphere's nod about the x axis [rad].
        nod_period: period of the nod [s].
        seed: random seed for the small per-strand variations.
    """

    strands: int = 300
    length: float = 0.2
    edge_length: float = 5e-3
    sphere_radius: float = 0.09
    curl_radius: float = 2e-3
    curl_pitch: float = 0.03
    nod_amplitude: float = 0.25
    nod_period: float = 1.5
    seed: int = 0

    def __post_init__(self):
        if not (isinstance(self.strands, int) and self.strands >= 1):
            raise ValueError(f"HangScene.strands must be an integer >= 1, got {self.strands!r}")
        for name in ("length", "edge_length", "sphere_radius", "nod_period"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"HangScene.{name} must be a finite positive number, got {v!r}")
        if self.length < 2 * self.edge_length:
            raise ValueError("HangScene.length must be at least two edges long")

    @property
    def vertex_count(self) -> int:
        """Vertices :func:`build_hang` makes (before any is allocated) [-]."""
        return self.strands * max(3, int(round(self.length / self.edge_length)) + 1)


def _fibonacci_lower_cap(count: int, y_max: float) -> np.ndarray:
    """Unit normals spread evenly over the cap y <= y_max of the unit sphere (golden-angle spiral)."""
    golden = math.pi * (3.0 - math.sqrt(5.0))
    k = np.arange(count) + 0.5
    y = -1.0 + (y_max + 1.0) * k / count
    r = np.sqrt(np.maximum(0.0, 1.0 - y * y))
    phi = golden * np.arange(count)
    return np.c_[r * np.cos(phi), y, r * np.sin(phi)]


def strand_along(normal: np.ndarray, length: float, n: int, curl_radius: float, curl_pitch: float,
                 phase: float) -> np.ndarray:
    """A strand leaving the surface along ``normal`` with a helical curl around that direction."""
    t = normal / np.linalg.norm(normal)
    a = np.cross(t, [0.0, 1.0, 0.0] if abs(t[1]) < 0.9 else [1.0, 0.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(t, a)
    s = np.linspace(0.0, length, n)
    # Ramp the curl in so the root leaves along the normal.
    ramp = np.minimum(1.0, s / (0.2 * length))
    ang = 2 * np.pi * s / max(curl_pitch, 1e-9) + phase
    offset = curl_radius * ramp[:, None] * (np.cos(ang)[:, None] * a + np.sin(ang)[:, None] * b)
    offset -= offset[0]
    return s[:, None] * t + offset


def build_hang(scene: HangScene, material: RodMaterial | None = None, finalize: bool = True):
    """The scene's Model (its GroomBuilder, not finalized, with ``finalize=False``)."""
    rng = np.random.default_rng(scene.seed)
    material = material or RodMaterial()
    # Roots below 0.6 R under the centre: strands hanging from there clear the sphere.
    normals = _fibonacci_lower_cap(scene.strands, -0.6)
    n = max(3, int(round(scene.length / scene.edge_length)) + 1)
    b = GroomBuilder()
    for i, nrm in enumerate(normals):
        root = scene.sphere_radius * nrm
        pts = root + strand_along(nrm, scene.length * rng.uniform(0.85, 1.0), n, scene.curl_radius,
                                  scene.curl_pitch, rng.uniform(0, 2 * np.pi))
        b.add_strand(pts, material)
    return b.finalize() if finalize else b


def nod_rotation(scene: HangScene, time: float) -> np.ndarray:
    """Rotation of the sphere at ``time`` [s]: a nod about the x axis."""
    a = scene.nod_amplitude * math.sin(2 * math.pi * time / scene.nod_period)
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


# --------------------------------------------------------------------------- hairball (Daviet 2023 Sec. 5.2)
@dataclass
class HairballScene:
    """The "hairy ball" of Daviet 2023 Sec. 5.2 (after Daviet 2020 and Kaufman et al. 2014).

    Attributes:
        strands: number of strands planted on the top half of the ball [-].
        length: strand length L [m] (30 cm in the paper).
        radius: strand radius R [m] (0.037 mm).
        edge_length: rest edge length [m] (1 cm: 30 edges per strand, as the paper's 480k vertices for 16k).
        ball_radius: radius of the ball [m] (9 cm).
        friction: hair-hair and hair-ball friction mu [-] (0.2).
        helix_radius, helix_pitch: natural curl [m] (0.5 cm, 5 cm).
        seed: random seed for the curl phases.
    """

    strands: int = 1000
    length: float = 0.30
    radius: float = 3.7e-5
    edge_length: float = 0.01
    ball_radius: float = 0.09
    friction: float = 0.2
    helix_radius: float = 0.005
    helix_pitch: float = 0.05
    seed: int = 0

    def __post_init__(self):
        if not (isinstance(self.strands, int) and self.strands >= 1):
            raise ValueError(f"HairballScene.strands must be an integer >= 1, got {self.strands!r}")
        for name in ("length", "radius", "edge_length", "ball_radius", "helix_pitch"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"HairballScene.{name} must be a finite positive number, got {v!r}")
        if not (math.isfinite(self.friction) and self.friction >= 0):
            raise ValueError(f"HairballScene.friction must be >= 0, got {self.friction!r}")

    @property
    def vertex_count(self) -> int:
        """Vertices :func:`build_hairball` makes (before any is allocated) [-]."""
        return self.strands * max(3, int(round(self.length / self.edge_length)) + 1)


def build_hairball(scene: HairballScene, finalize: bool = True):
    """Model of the hairball: strands along the normals of the upper hemisphere, clamped to body 0 (its
    GroomBuilder, not finalized, with ``finalize=False``)."""
    rng = np.random.default_rng(scene.seed)
    material = RodMaterial(radius=scene.radius)
    normals = -_fibonacci_lower_cap(scene.strands, 0.0)  # the lower cap y <= 0, mirrored to the top half
    n = max(3, int(round(scene.length / scene.edge_length)) + 1)
    b = GroomBuilder()
    for nrm in normals:
        root = scene.ball_radius * nrm
        pts = root + strand_along(nrm, scene.length, n, scene.helix_radius, scene.helix_pitch,
                                  rng.uniform(0, 2 * np.pi))
        b.add_strand(pts, material)
    return b.finalize() if finalize else b


def _axis_rotation(axis, angle: float) -> np.ndarray:
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def hairball_rotation(time: float) -> np.ndarray:
    """Rotation of the ball at ``time`` [s].

    The papers give the sequence of Kaufman et al. 2014 only as a video; this
    is our reading of it, written down: 0.5 s at rest, a full turn about the
    vertical axis in 1.5 s (smooth start and stop), a 90 degree roll about the
    horizontal x axis and back (1 s each), then a half turn about the vertical
    axis in 0.75 s, then rest.  Smoothstep profiles keep the accelerations finite.
    """
    def smooth(t0, t1):
        u = min(max((time - t0) / (t1 - t0), 0.0), 1.0)
        return u * u * (3 - 2 * u)

    yaw = 2 * math.pi * smooth(0.5, 2.0) + math.pi * smooth(4.0, 4.75)
    roll = 0.5 * math.pi * (smooth(2.0, 3.0) - smooth(3.0, 4.0))
    return _axis_rotation((0, 1, 0), yaw) @ _axis_rotation((1, 0, 0), roll)
