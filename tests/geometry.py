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
