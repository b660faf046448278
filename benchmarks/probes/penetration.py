"""Why the hairball's hair-pair penetration p99 stayed above one radius (issue 12 item 1's diagnosis).

Run from the repository root:
    python3 benchmarks/probes/penetration.py STRANDS FRAMES [key=value ...] [profile]
keys: from (first frame printed), variants (a frame: at its last substep, run the code's correction under the
      config variants of ``VARIANTS`` from the same pre-correction state, 20 / 40 / 80 / 160 sweeps, and print
      p99 / max / deeper than r / crossed and strain p99 / max), corrmax, relin (correction_relinearize_every),
      split (correction_mass_splitting), hfric (correction_hair_friction 0/1), admm_relin (experiment:
      re-linearise the contacts before every k-th ADMM z-step; not kept, no clear change).  ``profile``: Taichi's
      kernel profiler table at the end.
The scene is the CLI's hairball (10 iterations, 4 substeps, 2 projection sweeps, 10 + adaptive correction sweeps,
the default w0).  Per substep it prints the hair-pair penetration p99 / max [um] and the contacts deeper than
r = 37 um before the correction (with the detection's linearisation) and after it (``ContactPipeline.statistics``:
p99 over all hair-hair contacts), the sweep count, the crossed pairs (n . (p_a - p_b) < 0 along the normal kept on
the begin-of-step side) of which deep, the median contact load (most contacts on one of the pair's vertices) of all
and of the deep contacts, and where the deep ones sit on the strand (0 root, 1 tip); then, per substep, what the
crossed pairs are (apart at the end? closest point at an edge end? edge-pair orientation flipped in the step?) and
a distance-based penetration (2r - |p_a - p_b| at the current closest points) beside the statistic.
The split quoted in BENCHMARKS.md (after the sweeps / after the final edge passes, old code) was measured by an
earlier, uncommitted version of this probe that re-ran the old correction kernel by kernel.
A diagnostic, not a benchmark.
"""

import sys

import numpy as np
import taichi as ti

from taichi_hair import SolverADMM, SolverADMMConfig
from taichi_hair.contact import narrow as C
from taichi_hair.contact import projection as P
from taichi_hair.contact.colliders import SphereCollider
from taichi_hair.config import ContactConfig
from taichi_hair.scene.builtin import HairballScene, build_hairball, hairball_rotation


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    import taichi_hair

    taichi_hair.init(arch=ti.cpu, log_level=ti.WARN, kernel_profiler="profile" in argv[2:])
    N, frames = int(argv[0]), int(argv[1])
    kv = dict(a.split("=") for a in argv[2:] if "=" in a)
    first = int(kv.get("from", 1))
    scene = HairballScene(strands=N, length=0.3)
    model = build_hairball(scene)
    extra = {}
    if "corrmax" in kv:
        extra["correction_max_iterations"] = int(kv["corrmax"])
    if "relin" in kv:
        extra["correction_relinearize_every"] = int(kv["relin"])
    if "split" in kv:
        extra["correction_mass_splitting"] = kv["split"]
    if "hfric" in kv:
        extra["correction_hair_friction"] = bool(int(kv["hfric"]))
    cc = ContactConfig(friction=scene.friction, projection_iterations=2, correction_iterations=10, **extra)
    cfg = SolverADMMConfig(iterations=10, mode="dynamic", contacts=cc)
    solver = SolverADMM(model, cfg, colliders=[SphereCollider(radius=scene.ball_radius, friction=scene.friction, body=0)])
    pipe = solver.contacts
    h = model.host
    local = np.zeros(model.vertex_count)
    for s0, n in model.strand_ranges() if hasattr(model, "strand_ranges") else zip(h["strand_vertex_start"],
                                                                                     h["strand_vertex_count"]):
        local[s0:s0 + n] = np.arange(n) / (n - 1)
    r = scene.radius
    st, ct = model.state(), model.control()


    def hair_pen(field_x):
        """Per hair-hair contact: penetration [m] (>= 0), crossed flag, vertices; via the code's statistic."""
        P.contact_statistics(field_x, pipe.vertex_radius, pipe.colliders, pipe.con, pipe.stats_out, False)
        nc = pipe.contact_count
        con = pipe.con
        hh = con.contact_collider.to_numpy()[:nc] < 0
        pen = con.contact_penetration.to_numpy()[:nc][hh].astype(np.float64)
        vtx = con.contact_vertex.to_numpy()[:nc][hh]
        crossed = pen > 2 * r
        return pen, crossed, vtx


    def summary(pen):
        if pen.size == 0:
            return 0.0, 0.0, 0
        return np.percentile(pen, 99) * 1e6, pen.max() * 1e6, int((pen > r).sum())


    record = {}


    x0g = [None]
    orig = pipe.correct


    def correct(x, x0, sweeps):
        """ContactPipeline.correct, measured before (after the first re-linearisation) and after."""
        x0g[0] = x0
        pre = summary(hair_pen(x)[0])  # with the detection's linearisation (re-linearising here would perturb the run)
        saved = None
        if record.get("variants"):
            saved = {k: getattr(pipe.con, k).to_numpy() for k in ("contact_weight", "contact_normal",
                     "contact_kinematic", "contact_delassus", "contact_friction")}
            saved["x"] = x.to_numpy()
            variants(x, saved)
        orig(x, x0, sweeps)
        pen, crossed, vtx = hair_pen(x)
        record.update(pre=pre, post=summary(pen), sweeps=pipe.correction_sweeps_last, crossed=int(crossed.sum()),
                      ncontacts=pen.size)
        deep = pen > r
        cnt = pipe.con.vertex_contact_count.to_numpy()
        load = cnt[vtx].max(axis=1)  # most contacts on one of the pair's 4 vertices
        record["load_all"] = np.median(load) if load.size else 0
        record["load_deep"] = np.median(load[deep]) if deep.any() else 0
        record["tip_deep"] = np.median(local[vtx[deep, 0]]) if deep.any() else 0
        record["crossed_deep"] = int((deep & crossed).sum())
        if record.get("crossinfo"):
            crossinfo(x0, x, pen, crossed)


    def seg_closest(p0, p1, q0, q1):
        """Closest points of segments (vectorised, clamped; Ericson's algorithm): s, t, distance."""
        d1, d2, rr = p1 - p0, q1 - q0, p0 - q0
        a = (d1 * d1).sum(1)
        e = (d2 * d2).sum(1)
        f = (d2 * rr).sum(1)
        c = (d1 * rr).sum(1)
        b = (d1 * d2).sum(1)
        den = a * e - b * b
        s = np.where(den > 1e-30, np.clip((b * f - c * e) / np.maximum(den, 1e-30), 0, 1), 0.0)
        t = (b * s + f) / e
        s = np.where(t < 0, np.clip(-c / a, 0, 1), np.where(t > 1, np.clip((b - c) / a, 0, 1), s))
        t = np.clip(t, 0, 1)
        dist = np.linalg.norm(p0 + s[:, None] * d1 - q0 - t[:, None] * d2, axis=1)
        return s, t, dist


    def crossinfo(x0f, zf, pen, crossed):
        """Crossed pairs: are they geometrically in contact at the end, did their edges really pass through each other?"""
        con = pipe.con
        nc = pipe.contact_count
        hh = con.contact_collider.to_numpy()[:nc] < 0
        vtx = con.contact_vertex.to_numpy()[:nc][hh]
        X0 = x0f.to_numpy().astype(np.float64)
        Z = zf.to_numpy().astype(np.float64)
        a, b = vtx[:, 0], vtx[:, 2]
        s, t, dist = seg_closest(Z[a], Z[a + 1], Z[b], Z[b + 1])
        s0, t0, dist0 = seg_closest(X0[a], X0[a + 1], X0[b], X0[b + 1])

        def orient(X):
            return np.einsum("ij,ij->i", np.cross(X[a + 1] - X[a], X[b + 1] - X[b]), X[b] - X[a])
        flip = np.sign(orient(X0)) != np.sign(orient(Z))
        interior = (s > 1e-3) & (s < 1 - 1e-3) & (t > 1e-3) & (t < 1 - 1e-3)
        true_pen = np.maximum(2 * r - dist, 0)
        c = crossed
        print(f"   crossed {int(c.sum())}: end distance median {1e6*np.median(dist[c]) if c.any() else 0:.0f} um, "
              f"apart (> 2r) {int((dist[c] > 2*r).sum())}, closest point at an edge end {int((~interior[c]).sum())}, "
              f"orientation flipped in the step {int(flip[c].sum())} (interior & flipped {int((flip & interior & c).sum())}); "
              f"begin distance median {1e6*np.median(dist0[c]) if c.any() else 0:.0f} um", flush=True)
        deep = (pen > r) & ~c
        if true_pen.size == 0 or not (~c).any():
            return
        print(f"   deep not crossed {int(deep.sum())}; distance-based pen (2r - |pa-pb| at closest points) p99 "
              f"{1e6*np.percentile(true_pen, 99):.1f} max {1e6*true_pen.max():.1f} um, > r {int((true_pen > r).sum())}; "
              f"the statistic's p99 {1e6*np.percentile(pen, 99):.1f}; without crossed pairs "
              f"{1e6*np.percentile(pen[~c], 99):.1f}", flush=True)


    def strain_of(zz):
        rl = h["edge_rest_length"]
        real = np.where(rl > 0)[0]
        zz = zz.astype(np.float64)
        return np.abs(np.linalg.norm(zz[real + 1] - zz[real], axis=1) / rl[real] - 1)


    VARIANTS = dict(
        cheb98=dict(correction_chebyshev_rho=0.98),
        cheb99=dict(correction_chebyshev_rho=0.99),
        cheb995=dict(correction_chebyshev_rho=0.995),
        cheb98_relin20=dict(correction_chebyshev_rho=0.98, correction_relinearize_every=20),
        cheb99_relin20=dict(correction_chebyshev_rho=0.99, correction_relinearize_every=20),
        cheb98_batch_friction=dict(correction_chebyshev_rho=0.98, correction_mass_splitting="batch",
                                   correction_hair_friction=True),
    )


    def variants(x, saved):
        """From the same pre-correction x and contacts, the correction (the code's) under config variants, at
        20 / 40 / 80 / 160 sweeps in all (fixed count: correction_iterations = correction_max_iterations)."""
        cfg = pipe.config
        keep = dict(vars(cfg))
        for name, o in VARIANTS.items():
            line = []
            for n in (20, 40, 80, 160):
                for k, a in saved.items():
                    if k != "x":
                        getattr(pipe.con, k).from_numpy(a)
                x.from_numpy(saved["x"])
                for k, v in dict(o, correction_max_iterations=n).items():
                    setattr(cfg, k, v)
                orig(x, x0g[0], n)
                pen, crossed, _ = hair_pen(x)
                a = summary(pen)
                st = strain_of(x.to_numpy())
                line.append(f"{n}: {a[0]:5.1f}/{a[1]:6.1f}/{a[2]}/x{int(crossed.sum())} s{100*np.percentile(st, 99):.2f}/"
                            f"{100*st.max():.1f}")
                for k, v in keep.items():
                    setattr(cfg, k, v)
            print(f"   {name:20s} " + " | ".join(line), flush=True)
        for k, a in saved.items():
            if k != "x":
                getattr(pipe.con, k).from_numpy(a)
        x.from_numpy(saved["x"])


    pipe.correct = correct
    if "admm_relin" in kv:
        # Experiment: re-linearise the contacts at the iterate before every k-th ADMM z-step of a step.
        every_it = int(kv["admm_relin"])
        orig_project, orig_detect = pipe.project, pipe.detect
        calls = [0]

        def detect(*a, **k):
            calls[0] = 0
            return orig_detect(*a, **k)

        def project(x, buf, sweeps):
            if calls[0] > 0 and calls[0] % every_it == 0:
                C.relinearize_contacts(x, solver.buf.vertex_position_begin, pipe.vertex_radius, pipe.colliders, pipe.con,
                                       pipe.config.mass_splitting == "batch", False, pipe.uses_batches(pipe._dynamic))
            calls[0] += 1
            orig_project(x, buf, sweeps)
        pipe.project, pipe.detect = project, detect
    dt = 1 / 96
    print("frame sub | pre-corr p99/max/deep | after the correction p99/max/deep | sweeps | "
          "crossed (deep) / contacts | vertex load median all/deep | deep at strand pos (0 root 1 tip)")
    for f in range(1, frames + 1):
        for k in range(4):
            t = ((f - 1) * 4 + k + 1) * dt
            ct.set_body_transform(0, hairball_rotation(t), (0, 0, 0))
            record["crossinfo"] = f >= first
            record["variants"] = (f == int(kv.get("variants", -1)) and k == 3)
            solver.step(st, ct, dt)
            if f >= first and "pre" in record:
                R = record
                print(f"{f:3d} {k} | {R['pre'][0]:6.1f} {R['pre'][1]:7.1f} {R['pre'][2]:5d} | "
                      f"{R['post'][0]:6.1f} {R['post'][1]:7.1f} {R['post'][2]:5d} | "
                      f"{R['sweeps']:3d} | {R['crossed']:4d} ({R['crossed_deep']:4d}) / {R['ncontacts']:5d} | "
                      f"{R['load_all']:4.0f} {R['load_deep']:4.0f} | {R['tip_deep']:.2f}", flush=True)
    if "profile" in argv[2:]:
        ti.profiler.print_kernel_profiler_info()
    return 0


if __name__ == "__main__":
    sys.exit(main())
