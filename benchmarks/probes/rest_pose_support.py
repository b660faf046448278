"""Does the body's support in the sag-free statics hold in the simulation? (issue 14, item 1)

Run from the repository root:
    [ITERATIONS=10] python3 benchmarks/probes/rest_pose_support.py [SECONDS]

Strands lying over a sphere (R = 9 cm, friction 0.3): each rooted on top, following the surface along a
meridian for 2-7 cm of arc, then leaving it along the tangent for 4-14 cm (an overhang held at the point
where it leaves), and three combed over the top (rooted 57 degrees down one side, over the crown
to 57 degrees down the other, then 10 cm along the tangent: 28 cm).  Rest poses: authored (rest = x*),
sag-free without support (each strand a cantilever from its root), sag-free with the sphere's support
(``support_from_colliders``) for the strands not held alone (the default rule), for every strand that
touches it (``RestPoseConfig(support_for="all")``), and the same without friction in the statics.  For
each: strands held, the largest rest moment, and after SECONDS (default 2) of dynamic simulation with the sphere collider
(dt = 1/96 s, drag 8 /s, ITERATIONS per step, defaults otherwise) the p90 / max vertex drift from x*
[mm], and per strand its largest drift and whether the statics use all the friction somewhere.
A diagnostic, not a benchmark.
"""

import math
import os
import sys

ITERATIONS = int(os.environ.get("ITERATIONS", "10"))


def groom(R, r):
    import numpy as np

    strands = []
    for k, (arc, over, phi) in enumerate([(0.02, 0.04, 0.0), (0.03, 0.06, 1.2), (0.04, 0.08, 2.4),
                                          (0.03, 0.05, 3.6), (0.025, 0.07, 4.8),
                                          (0.06, 0.10, 0.6), (0.07, 0.12, 1.8), (0.06, 0.14, 3.0)]):
        a = np.array([math.cos(phi), 0.0, math.sin(phi)])
        rr = R + r + 1e-6
        th = np.linspace(0.0, arc / R, max(3, int(round(arc / 2.5e-3)) + 1))
        on = np.array([rr * (math.sin(t) * a + math.cos(t) * np.array([0.0, 1.0, 0.0])) for t in th])
        t_end = th[-1]
        tangent = math.cos(t_end) * a - math.sin(t_end) * np.array([0.0, 1.0, 0.0])
        s = np.linspace(0.0, over, int(round(over / 2.5e-3)) + 1)[1:]
        strands.append(np.vstack([on, on[-1] + s[:, None] * tangent]))
    # Combed over the top: rooted 57 degrees down one side, over the crown to 57 degrees down the other,
    # then 10 cm along the tangent (28 cm in all).
    for phi in (0.3, 1.9, 3.5):
        a = np.array([math.cos(phi), 0.0, math.sin(phi)])
        rr = R + r + 1e-6
        th = np.linspace(-1.0, 1.0, int(round(2.0 * R / 2.5e-3)) + 1)
        on = np.array([rr * (math.sin(t) * a + math.cos(t) * np.array([0.0, 1.0, 0.0])) for t in th])
        tangent = math.cos(1.0) * a - math.sin(1.0) * np.array([0.0, 1.0, 0.0])
        s = np.linspace(0.0, 0.10, 41)[1:]
        strands.append(np.vstack([on, on[-1] + s[:, None] * tangent]))
    return strands


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    seconds = float(argv[0]) if argv else 2.0
    import numpy as np
    import taichi as ti

    import taichi_hair

    taichi_hair.init(arch=ti.cpu, log_level=ti.WARN)
    from taichi_hair import GroomBuilder, RodMaterial, SolverADMM, SolverADMMConfig
    from taichi_hair.contact.colliders import SphereCollider
    from taichi_hair.solvers.rest_pose import apply_rest_pose, clear_rest_pose, solve_rest_pose
    from taichi_hair.solvers.rest_support import support_from_colliders

    R, mat = 0.09, RodMaterial()
    sphere = SphereCollider(center=(0.0, 0.0, 0.0), radius=R, friction=0.3, body=-1)
    b = GroomBuilder()
    for pts in groom(R, mat.radius):
        b.add_strand(pts, mat)
    model = b.finalize()
    x0 = model.host["vertex_rest_position"].astype(np.float64)
    free = model.host["vertex_is_fixed"] == 0
    xi = 8.0 * mat.density * mat.area
    support = support_from_colliders(model, [sphere])
    print(f"{model.strand_count} strands, {int(free.sum())} free vertices, {support.vertex.size} on the sphere")
    from taichi_hair.solvers.rest_pose import RestPoseConfig

    from taichi_hair.solvers.rest_support import ContactSupport

    half = ContactSupport(support.vertex, support.normal, 0.0 * support.friction)
    for name in ("authored", "sag-free", "sag-free + support", "sag-free + support for all",
                 "support for all, mu = 0"):
        clear_rest_pose(model)
        held, change = model.strand_count, 0.0
        if name != "authored":
            sup = half if name.endswith("mu = 0") else support if "support" in name else None
            res = solve_rest_pose(model, SolverADMMConfig(), support=sup,
                                  config=RestPoseConfig(support_for="unheld" if name.endswith("support") else "all"))
            held = model.strand_count - len(res.unheld)
            active = model.host["pair_is_active"].astype(bool)
            kappa_change = np.linalg.norm(res.pair_rest_moment[:, :2], axis=1)
            change = float(np.max(np.where(active, kappa_change, 0.0)))
            apply_rest_pose(model, res)
        solver = SolverADMM(model, SolverADMMConfig(air_viscosity=xi, iterations=ITERATIONS), colliders=[sphere])
        st, ct = model.state(), model.control()
        for _ in range(int(round(seconds * 96))):
            solver.step(st, ct, 1 / 96)
        d = np.linalg.norm(st.positions().astype(np.float64) - x0, axis=1)[free]
        print(f"  {name:26s}: held {held}/{model.strand_count}, largest rest moment {change:.3g} J; after "
              f"{seconds:g} s drift p90 {1e3 * np.percentile(d, 90):.3f} mm, max {1e3 * d.max():.3f} mm")
        per = np.zeros(model.strand_count)
        np.maximum.at(per, model.host["vertex_strand"][free], d)
        limited = res.friction_limited if name != "authored" else []
        print("      per strand max drift [mm]:", " ".join(f"{1e3 * v:.2f}" for v in per),
              f"; friction at its limit: {limited}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
