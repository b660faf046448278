"""Reference geometry for tests, in NumPy float64 (independent of the Taichi kernels under test)."""

import numpy as np


def segment_distance(p0, p1, q0, q1) -> float:
    """Distance between segments [p0, p1] and [q0, q1] (Ericson, Real-Time Collision Detection 5.1.9)."""
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a, e, f = d1 @ d1, d2 @ d2, d2 @ r
    c, b = d1 @ r, d1 @ d2
    den = a * e - b * b
    s = np.clip((b * f - c * e) / den, 0, 1) if den > 1e-12 * a * e else 0.0
    t = (b * s + f) / e
    if t < 0:
        t, s = 0.0, np.clip(-c / a, 0, 1)
    elif t > 1:
        t, s = 1.0, np.clip((b - c) / a, 0, 1)
    return float(np.linalg.norm(p0 + s * d1 - q0 - t * d2))


def segment_distances(p0, p1, q0, q1) -> np.ndarray:
    """:func:`segment_distance` for many segment pairs at once: arrays of shape (..., 3), the same
    formulas element by element (tests check the two agree), result of shape (...)."""
    p0, p1, q0, q1 = (np.asarray(v, np.float64) for v in (p0, p1, q0, q1))
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a, e, f = (np.einsum("...j,...j->...", u, w) for u, w in ((d1, d1), (d2, d2), (d2, r)))
    c, b = np.einsum("...j,...j->...", d1, r), np.einsum("...j,...j->...", d1, d2)
    den = a * e - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(den > 1e-12 * a * e, np.clip((b * f - c * e) / den, 0, 1), 0.0)
    t = (b * s + f) / e
    low, high = t < 0, t > 1
    s = np.where(low, np.clip(-c / a, 0, 1), np.where(high, np.clip((b - c) / a, 0, 1), s))
    t = np.clip(t, 0.0, 1.0)
    return np.linalg.norm(p0 + s[..., None] * d1 - q0 - t[..., None] * d2, axis=-1)


def rotation_matrix(axis, angle) -> np.ndarray:
    """Rotation by ``angle`` [rad] about ``axis`` (Rodrigues' formula), 3x3."""
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * (k @ k)


def curly_strand(n, i) -> np.ndarray:
    """A curly strand of ``n`` vertices (one turn of a 4 mm helix down -y, 6.3 cm long), offset 1 cm along z per ``i``."""
    s = np.linspace(0.0, 2.0 * np.pi, n)
    return np.c_[0.004 * np.cos(s) - 0.004, -0.01 * s, 0.004 * np.sin(s) + 0.01 * i]


def move_two_bodies(control, t) -> None:
    """Body 0 turns 0.8 t rad about y while it shifts and bobs; body 1 turns -0.5 t rad about (1, 0.3, 0) and sinks:
    the end-of-step transforms at time fraction ``t`` of the schedule tests' moving-roots scenes."""
    control.set_body_transform(0, rotation_matrix((0, 1, 0), 0.8 * t), (0.02 * t, 0.01 * np.sin(6 * t), 0.0))
    control.set_body_transform(1, rotation_matrix((1, 0.3, 0), -0.5 * t), (0.0, 0.0, -0.01 * t))
