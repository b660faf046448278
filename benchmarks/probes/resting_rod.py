"""Does a free rod lying across two clamped rods stay at rest?  (Issue 14: the contact warm start of dynamic runs.)

Run from the repository root:
    python3 benchmarks/probes/resting_rod.py [--thick 4] [--steps 288] [--friction 0.3]

Two clamped 1 cm cantilevers along +x, 6 mm apart, of ``--thick`` times the hair radius; a free hair rod along z laid
across them 20 um above contact; dynamic steps of 1/96 s, 10 ADMM iterations, hair-hair contacts.  Printed: over the
last second, the gap at the two crossings (segment distance minus r_a + r_b: negative is penetration, positive is the
rod floating), the largest speed of the free rod's vertices, and its mean height.  A rod at rest shows a gap of a few
um either way and a speed far below 1 cm/s; a rod that bounces shows gaps of a tenth of a millimetre and more.
The BENCHMARKS.md section "The contact warm start in dynamic runs" ran it on a scratch patch
(``benchmarks/results/warm_dynamic/warm_dynamic.patch``, whose ``TH_WARM_*`` environment variables it reads).
"""

import argparse
from dataclasses import replace

import numpy as np


def segment_distance(p0, p1, q0, q1) -> float:
    """Distance between segments [p0, p1] and [q0, q1], by dense sampling of one and the exact point distance to the
    other (the sampling error is at most half the sample spacing times the segments' relative slope: < 0.1 um here)."""
    t = np.linspace(0.0, 1.0, 201)[:, None]
    p = p0 + t * (p1 - p0)
    d = q1 - q0
    s = np.clip((p - q0) @ d / max(float(d @ d), 1e-300), 0.0, 1.0)[:, None]
    return float(np.min(np.linalg.norm(p - (q0 + s * d), axis=1)))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--thick", type=float, default=4.0, help="radius of the clamped rods, in hair radii")
    ap.add_argument("--steps", type=int, default=288)
    ap.add_argument("--friction", type=float, default=0.3)
    a = ap.parse_args(argv)
    import taichi as ti

    import taichi_hair

    taichi_hair.init(arch=ti.cpu, default_fp=ti.f32, log_level=ti.WARN)
    from taichi_hair import GroomBuilder, RodMaterial, SolverADMM, SolverADMMConfig
    from taichi_hair.config import ContactConfig

    hair = RodMaterial()
    r = hair.radius
    base = replace(hair, radius=a.thick * r)
    b = GroomBuilder()
    for z in (-0.003, 0.003):
        b.add_strand(np.linspace((0, 0, z), (0.01, 0, z), 9), base)
    y = a.thick * r + r + 2e-5
    b.add_strand(np.linspace((0.006, y, -0.006), (0.006, y, 0.006), 13), hair, root="free")
    model = b.finalize()
    st, ctl = model.state(), model.control()
    solver = SolverADMM(model, SolverADMMConfig(iterations=10, contacts=ContactConfig(friction=a.friction)))
    heights, speeds, gaps = [], [], []
    for _ in range(a.steps):
        solver.step(st, ctl, 1 / 96)
        x = st.positions().astype(np.float64)
        v = st.vertex_velocity.to_numpy().astype(np.float64)[18:]
        heights.append(x[18:, 1].mean())
        speeds.append(np.linalg.norm(v, axis=1).max())
        gaps.append([min(segment_distance(x[18 + i], x[19 + i], x[r0 + j], x[r0 + j + 1])
                         for i in range(12) for j in range(8)) - (r + a.thick * r) for r0 in (0, 9)])
    last = slice(-96, None)
    h, s, g = np.array(heights)[last], np.array(speeds)[last], np.array(gaps)[last]
    print(f"clamped rods {a.thick:g} hair radii thick, last second: gap at the crossings {1e6 * g.min():.2f} to "
          f"{1e6 * g.max():.2f} um, largest speed {1e3 * s.max():.3f} mm/s, mean height {1e6 * h.mean():.1f} um "
          f"(range {1e6 * np.ptp(h):.2f} um)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
