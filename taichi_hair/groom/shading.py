"""Strand shading for pictures a groomer would look at: Kajiya-Kay hair lighting, root-to-tip darkening.

Pure NumPy, per vertex: the colours are computed on the host for the camera and light of a frame and drawn
by :class:`taichi_hair.render.ViewerGGUI` as GGUI lines (GGUI does not light lines).

For a vertex with unit tangent t, unit direction to the light l and to the eye v (Kajiya & Kay 1989; the
two shifted highlights of Scheuermann 2004, "Practical real-time hair rendering and shading"):

    diffuse   = sin(t, l) = sqrt(1 - (t . l)^2)
    specular  = sin(t', h)^p,  h = (l + v) / |l + v|,  t' = t shifted along the strand's normal
    colour    = base * (ambient + k_d * diffuse) + k_s1 * spec_1 * light + k_s2 * spec_2 * base

with a primary highlight (light colour, sharp, shifted towards the tip) and a secondary one (hair colour,
broader, shifted towards the root).  ``base`` darkens from the tip to the root (``root_darkening``) as hair
shadows itself near the scalp.  This is a shading model, not a light transport simulation: no shadows
between strands, no multiple scattering.  Choices (the papers are silent on rendering): exponents 80 and
20, shifts +0.1 and -0.1, k_s 0.35 and 0.25, ambient 0.3, k_d 0.75, darkening to 0.45 at the root over
the first 30 % of the length.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Default hair colour (medium brown), linear RGB in [0, 1].
HAIR_BROWN = (0.36, 0.22, 0.12)


@dataclass
class HairShading:
    """Parameters of :func:`shade_strands` (see the module docstring)."""

    ambient: float = 0.3
    diffuse: float = 0.75
    specular_primary: float = 0.35
    specular_secondary: float = 0.25
    exponent_primary: float = 80.0
    exponent_secondary: float = 20.0
    shift_primary: float = 0.1
    shift_secondary: float = -0.1
    root_darkening: float = 0.45  # base at the root / base at the tip [-]
    darkening_length: float = 0.3  # fraction of the strand over which the root darkening fades [-]
    light_color: tuple = (1.0, 0.97, 0.92)


def vertex_tangents(points: np.ndarray, strand_offsets: np.ndarray) -> np.ndarray:
    """Unit tangents (N, 3) per vertex: central differences inside a strand, one-sided at its ends."""
    p = np.asarray(points, np.float64)
    off = np.asarray(strand_offsets, np.int64)
    n = p.shape[0]
    nxt = np.arange(1, n + 1)
    prv = np.arange(-1, n - 1)
    last = off[1:] - 1
    first = off[:-1]
    nxt[last] = last
    prv[first] = first
    t = p[np.minimum(nxt, n - 1)] - p[np.maximum(prv, 0)]
    norm = np.linalg.norm(t, axis=1)
    t[norm > 0] /= norm[norm > 0, None]
    t[norm == 0] = (0.0, 1.0, 0.0)
    return t


def arc_fraction(points: np.ndarray, strand_offsets: np.ndarray) -> np.ndarray:
    """Arc length from the root over the strand's length, per vertex, in [0, 1]."""
    p = np.asarray(points, np.float64)
    off = np.asarray(strand_offsets, np.int64)
    seg = np.zeros(p.shape[0])
    seg[1:] = np.linalg.norm(p[1:] - p[:-1], axis=1)
    seg[off[:-1]] = 0.0  # no segment across strands
    cum = np.cumsum(seg)
    start = np.repeat(cum[off[:-1]], np.diff(off))
    total = np.repeat(cum[off[1:] - 1] - cum[off[:-1]], np.diff(off))
    return np.where(total > 0, (cum - start) / np.where(total > 0, total, 1.0), 0.0)


def _sin_to(t: np.ndarray, d: np.ndarray) -> np.ndarray:
    c = np.sum(t * d, axis=1)
    return np.sqrt(np.clip(1.0 - c * c, 0.0, 1.0))


def shade_strands(points, strand_offsets, base_color, eye, light_direction=None,
                  shading: HairShading | None = None) -> np.ndarray:
    """Per-vertex RGB (N, 3) float32 in [0, 1] of strands seen from ``eye`` [m] (see the module docstring).

    Args:
        points: vertex positions (N, 3) [m].
        strand_offsets: (S + 1,) vertex offsets of the strands.
        base_color: one RGB, or per strand (S, 3), or per vertex (N, 3), in [0, 1].
        eye: camera position [m].
        light_direction: direction *to* the light (3,), default: from above, behind the camera's right.
        shading: :class:`HairShading` (default parameters when None).
    """
    sh = shading or HairShading()
    p = np.asarray(points, np.float64)
    off = np.asarray(strand_offsets, np.int64)
    n, ns = p.shape[0], off.shape[0] - 1
    base = np.asarray(base_color, np.float64)
    if base.ndim == 1:
        base = np.tile(base.reshape(1, 3), (n, 1))
    elif base.shape[0] == ns and ns != n:
        base = np.repeat(base, np.diff(off), axis=0)
    if base.shape != (n, 3):
        raise ValueError(f"shade_strands: base_color must be one RGB, (S, 3) or (N, 3); got {base.shape}")
    t = vertex_tangents(p, off)
    v = np.asarray(eye, np.float64)[None, :] - p
    v /= np.maximum(np.linalg.norm(v, axis=1), 1e-30)[:, None]
    if light_direction is None:
        # From above and to the right of the view: the eye direction turned up and right.
        centre = p.mean(axis=0) if n else np.zeros(3)
        view = np.asarray(eye, np.float64) - centre
        view /= max(np.linalg.norm(view), 1e-30)
        right = np.cross((0.0, 1.0, 0.0), view)
        right = right / np.linalg.norm(right) if np.linalg.norm(right) > 1e-9 else np.array([1.0, 0.0, 0.0])
        light_direction = view + 0.8 * np.array([0.0, 1.0, 0.0]) + 0.5 * right
    light = np.asarray(light_direction, np.float64)
    light = light / np.linalg.norm(light)
    h = light[None, :] + v
    h /= np.maximum(np.linalg.norm(h, axis=1), 1e-30)[:, None]
    # The strand's normal for the shifts: the component of v normal to t (what the eye sees of the fibre).
    nrm = v - np.sum(v * t, axis=1)[:, None] * t
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1), 1e-30)[:, None]

    def spec(shift, exponent):
        ts = t + shift * nrm
        ts /= np.maximum(np.linalg.norm(ts, axis=1), 1e-30)[:, None]
        return _sin_to(ts, h[:, :] if h.ndim == 2 else h) ** exponent

    diffuse = _sin_to(t, np.broadcast_to(light, t.shape))
    s = arc_fraction(p, off)
    dark = sh.root_darkening + (1.0 - sh.root_darkening) * np.clip(s / max(sh.darkening_length, 1e-9), 0.0, 1.0)
    b = base * dark[:, None]
    col = (b * (sh.ambient + sh.diffuse * diffuse)[:, None]
           + sh.specular_primary * spec(sh.shift_primary, sh.exponent_primary)[:, None]
           * np.asarray(sh.light_color)[None, :]
           + sh.specular_secondary * spec(sh.shift_secondary, sh.exponent_secondary)[:, None] * b)
    return np.clip(col, 0.0, 1.0).astype(np.float32)
