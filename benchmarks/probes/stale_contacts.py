"""How stale the begin-of-step contact linearisation gets: per substep of a 100-strand hairball without
correction, the hair pairs whose linearised gap is below -0.2 mm, and how far apart their edges really are.

Run from the repository root: ``python3 benchmarks/probes/stale_contacts.py ``.  A diagnostic, not a benchmark:
it prints per-substep figures for the frames around the hairball's impact (Daviet 2023 Sec. 5.2 scene).
"""

import importlib.util
import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def segment_distance_function():
    """``segment_distance`` of tests/geometry.py (the tests' reference), loaded from its file."""
    spec = importlib.util.spec_from_file_location("_probe_geometry", os.path.join(ROOT, "tests", "geometry.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.segment_distance


def report(f, k, solver, st, segment_distance) -> None:
    """One substep's line: hair-hair contacts, those violated by > 0.2 mm, and their edges' real distance."""
    con = solver.contacts.con
    n = solver.contacts.contact_count
    V = con.contact_vertex.to_numpy()[:n]
    W = con.contact_weight.to_numpy()[:n].astype(float)
    N = con.contact_normal.to_numpy()[:n].astype(float)
    K = con.contact_kinematic.to_numpy()[:n].astype(float)
    x = st.positions().astype(float)
    hh = V[:, 2] >= 0
    u = np.zeros((n, 3))
    for j in range(4):
        idx = np.where(V[:, j] >= 0, V[:, j], 0)
        u += W[:, j:j + 1] * x[idx] * (V[:, j:j + 1] >= 0)
    u += K
    gl = np.sum(u * N, 1)
    bad = np.where(hh & (gl < -2e-4))[0]
    dact = np.array([segment_distance(x[V[c, 0]], x[V[c, 1]], x[V[c, 2]], x[V[c, 3]]) for c in bad])
    print(f, k, "hh", hh.sum(), "violated>0.2mm", len(bad),
          "min lin gap um", round(1e6 * gl[hh].min()) if hh.any() else 0,
          "of those actual dist > 0.5mm:", int((dact > 5e-4).sum()),
          "max actual mm", round(1e3 * dact.max(), 2) if len(dact) else 0, flush=True)


def run(frames: int = 10) -> None:
    from taichi_hair import SolverADMM, SolverADMMConfig
    from taichi_hair.config import ContactConfig
    from taichi_hair.contact.colliders import SphereCollider
    from taichi_hair.scene.builtin import HairballScene, build_hairball, hairball_rotation

    segment_distance = segment_distance_function()
    scene = HairballScene(strands=100, length=0.3)
    model = build_hairball(scene)
    cfg = SolverADMMConfig(iterations=10, contacts=ContactConfig(friction=0.2, projection_iterations=2,
                                                                 correction_iterations=0))
    solver = SolverADMM(model, cfg, colliders=[SphereCollider(radius=scene.ball_radius, friction=0.2, body=0)])
    st, ct = model.state(), model.control()
    dt = 1 / 96
    for f in range(1, frames + 1):
        for k in range(4):
            ct.set_body_transform(0, hairball_rotation(((f - 1) * 4 + k + 1) * dt), (0, 0, 0))
            solver.step(st, ct, dt)
            if f >= 8:
                report(f, k, solver, st, segment_distance)


def main(argv=None) -> int:
    import taichi as ti

    import taichi_hair

    taichi_hair.init(arch=ti.cpu, log_level=ti.WARN)
    run()
    return 0


if __name__ == "__main__":
    sys.exit(main())
