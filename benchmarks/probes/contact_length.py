"""Where the hairball's edge stretch comes from: per substep, strain and hair-pair crossings just before
and just after the end-of-step geometric correction (issue 12 item 1's diagnosis).

Run from the repository root:
    python3 benchmarks/probes/contact_length.py STRANDS FRAMES [key=value ...]
keys: iterations, sweeps (projection sweeps), corr (correction sweeps), corrmax (their cap), ct (continuous detections),
      mu, w0, wz (factor on the collision weights W_z), from (first frame printed).
A diagnostic, not a benchmark.  "crossed" counts hair-hair contacts whose two edges ended on the far side
of the begin-of-step contact normal by more than one contact thickness (signed gap n0 . (p_a - p_b) - r < -r
at the contact's begin-of-step barycentric points): pairs that passed through each other in the step.
"""

import sys

import numpy as np
import taichi as ti

from taichi_hair import SolverADMM, SolverADMMConfig
from taichi_hair.contact.colliders import SphereCollider
from taichi_hair.config import ContactConfig
from taichi_hair.scene.builtin import HairballScene, build_hairball, hairball_rotation


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    import taichi_hair

    taichi_hair.init(arch=ti.cpu, log_level=ti.WARN)
    N, frames = int(argv[0]), int(argv[1])
    kv = dict(a.split("=") for a in argv[2:])
    iters = int(kv.get("iterations", 10))
    first = int(kv.get("from", 1))
    scene = HairballScene(strands=N, length=0.3)
    model = build_hairball(scene)
    cc = ContactConfig(friction=float(kv.get("mu", scene.friction)), projection_iterations=int(kv.get("sweeps", 2)),
                       correction_iterations=int(kv.get("corr", 10)),
                       correction_max_iterations=int(kv.get("corrmax", 40)), continuous_detections=int(kv.get("ct", 0)))
    cfg = SolverADMMConfig(iterations=iters, mode="dynamic", contacts=cc, w0=float(kv.get("w0", 25.0)))
    solver = SolverADMM(model, cfg, colliders=[SphereCollider(radius=scene.ball_radius, friction=scene.friction,
                                                              body=0)])
    if "wz" in kv:  # scale the collision weights W_z = m / dt~^2 by this factor (a diagnostic knob)
        wb = solver.contacts.vertex_weight_base
        wb.from_numpy(wb.to_numpy() * float(kv["wz"]))
    st, ct = model.state(), model.control()
    rl = model.host["edge_rest_length"]
    real = np.where(rl > 0)[0]


    def strain(x):
        e = np.linalg.norm(x[real + 1] - x[real], axis=1)
        return np.abs(e / rl[real] - 1)


    def crossings(x):
        con = solver.contacts.con
        nc = solver.contacts.contact_count
        col = con.contact_collider.to_numpy()[:nc]
        hh = col < 0
        v = con.contact_vertex.to_numpy()[:nc][hh]
        w = con.contact_weight.to_numpy()[:nc][hh].astype(np.float64)
        n = con.contact_normal.to_numpy()[:nc][hh].astype(np.float64)
        r = 2 * scene.radius
        d = np.einsum("ck,ckj->cj", w, x[v])
        gap = np.einsum("cj,cj->c", n, d) - r
        return int((gap < -r).sum()), int((gap < 0).sum()), int(hh.sum())


    record = {}
    orig = solver.contacts.correct


    def correct(x, x0, sweeps):
        pre = x.to_numpy().astype(np.float64)
        record["pre"] = strain(pre)
        record["pre_cross"] = crossings(pre)
        orig(x, x0, sweeps)
        post = x.to_numpy().astype(np.float64)
        record["post_cross"] = crossings(post)


    solver.contacts.correct = correct
    dt = 1 / 96
    print("frame sub | before correction: p99 %  max %  crossed pen/contacts | after: p99 %  max %  edges>1% crossed"
          " | hair pen p99/max um, body max um")
    worst = 0.0
    for f in range(1, frames + 1):
        for k in range(4):
            t = ((f - 1) * 4 + k + 1) * dt
            ct.set_body_transform(0, hairball_rotation(t), (0, 0, 0))
            solver.step(st, ct, dt)
            s = strain(st.positions().astype(np.float64))
            worst = max(worst, s.max())
            cs = solver.contact_stats
            if f >= first and "pre" in record:
                p = record["pre"]
                c0, pen0, hh = record["pre_cross"]
                c1 = record["post_cross"][0]
                print(f"{f:4d} {k} | {100*np.percentile(p, 99):7.3f} {100*p.max():6.2f} {c0:6d} {pen0:5d}/{hh:<6d} | "
                      f"{100*np.percentile(s, 99):7.3f} {100*s.max():6.2f} {int((s > 0.01).sum()):6d} {c1:6d} | "
                      f"{1e6*cs['hair_penetration_p99_m']:6.1f} {1e6*cs['hair_penetration_max_m']:7.1f} "
                      f"{1e6*cs['body_penetration_max_m']:7.1f} sweeps {solver.contacts.correction_sweeps_last}",
                      flush=True)
    print(f"largest strain over the run {100*worst:.2f} %")
    return 0


if __name__ == "__main__":
    sys.exit(main())
