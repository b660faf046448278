"""Would lanes of strands make the strand schedule's scalar code vector code on the CPU?  (Issue 15, item 1.)

Run from the repository root: ``python3 benchmarks/probes/simd_lanes.py [--strands 8192] [--vertices 32]``.

The strand schedule's ADMM iteration is scalar code whose dependency chains (square roots, divisions, sin and
cos) leave the cores' vector units idle; issue 15 suggests stepping lanes of 8 strands together.  This probe
asks what Taichi 1.7's CPU backend makes of that, on a kernel shaped like one stage of the iteration (per edge
pair: two edge tangents, the curvature binormal 2 t0 x t1 / (1 + t0 . t1), its norm's cos and sin, a vector
written back; no branch unless ``--branch``), over the same strands and vertices, four ways:

* ``scalar``: one strand per loop iteration, vec3 arithmetic (the strand schedule's shape);
* ``interleaved_2``: two strands far apart in memory stepped in one loop body (more independent chains for the
  out-of-order core, the same scalar code);
* ``unrolled_8``: eight neighbouring strands stepped in one loop body by static unrolling, the data laid out
  vertex-major so that the eight strands' values are adjacent in memory (what LLVM's SLP vectoriser would need
  to fuse the eight copies);
* ``lanes_8``: the same layout, the arithmetic written on 8-wide vectors (``ti.types.vector(8, f32)``), one
  value per strand in each lane: the code a lanes schedule would need;
* ``gather_8``: the arithmetic of ``lanes_8`` on the strand-major data of ``scalar``, gathered into the lanes and
  scattered back at every vertex (what lanes would cost inside the strand schedule without a second layout).

Prints million vertex-iterations per second and each variant's ratio to ``scalar`` in one run, and the largest
difference of ``lanes_8``'s results from ``scalar``'s (the vector sin and cos round differently).  A diagnostic:
it measures what the compiler does with each shape, not the ADMM iteration itself.
"""

import argparse
import json
import time

import numpy as np
import taichi as ti


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--strands", type=int, default=8192)
    ap.add_argument("--vertices", type=int, default=32)
    ap.add_argument("--iterations", type=int, default=20)
    ap.add_argument("--branch", action="store_true", help="add a data-dependent branch to the stage (as the "
                    "parallel transport's reversed-tangent case)")
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    if a.strands % 8 or a.vertices < 3:
        raise SystemExit("--strands must be a multiple of 8 and --vertices at least 3")
    import taichi_hair

    taichi_hair.init(arch=ti.x64, default_fp=ti.f32, log_level=ti.WARN)
    S, M, L = a.strands, a.vertices, 8
    G = S // L
    branch = a.branch
    V8 = ti.types.vector(L, ti.f32)
    x_strand = ti.Vector.field(3, ti.f32, (S, M))   # strand-major [m]
    y_strand = ti.Vector.field(3, ti.f32, (S, M))
    x_vertex = ti.field(ti.f32, (M, 3, S))          # vertex-major, strands adjacent [m]
    y_vertex = ti.field(ti.f32, (M, 3, S))
    x_lane = ti.field(V8, (G, M, 3))                # groups of 8 strands, one per lane [m]
    y_lane = ti.field(V8, (G, M, 3))

    @ti.kernel
    def fill():
        for s, k in x_strand:
            p = ti.Vector([ti.sin(s * 0.1 + k), ti.cos(k * 0.3 + s), k * 0.01])
            x_strand[s, k] = p
            for c in ti.static(range(3)):
                x_vertex[k, c, s] = p[c]
                x_lane[s // L, k, c][s % L] = p[c]

    @ti.func
    def stage(p0, p1, p2):
        e0, e1 = p1 - p0, p2 - p1
        t0, t1 = e0 / e0.norm(), e1 / e1.norm()
        kb = 2.0 * t0.cross(t1) / (1.0 + t0.dot(t1))
        if ti.static(branch):
            if t0.dot(t1) < -0.999:
                kb = t0
        n = kb.norm()
        return kb * ti.cos(n) + t1 * ti.sin(n)

    @ti.func
    def at_vertex(s, k):
        return ti.Vector([x_vertex[k, 0, s], x_vertex[k, 1, s], x_vertex[k, 2, s]])

    @ti.kernel
    def scalar(iterations: ti.i32):
        for s in range(S):
            for _ in range(iterations):
                for k in range(1, M - 1):
                    y_strand[s, k] = stage(x_strand[s, k - 1], x_strand[s, k], x_strand[s, k + 1])

    @ti.kernel
    def interleaved_2(iterations: ti.i32):
        for h in range(S // 2):
            for _ in range(iterations):
                for k in range(1, M - 1):
                    for q in ti.static(range(2)):
                        s = h + q * (S // 2)
                        y_strand[s, k] = stage(x_strand[s, k - 1], x_strand[s, k], x_strand[s, k + 1])

    @ti.kernel
    def unrolled_8(iterations: ti.i32):
        for g in range(G):
            for _ in range(iterations):
                for k in range(1, M - 1):
                    for q in ti.static(range(L)):
                        s = g * L + q
                        r = stage(at_vertex(s, k - 1), at_vertex(s, k), at_vertex(s, k + 1))
                        for c in ti.static(range(3)):
                            y_vertex[k, c, s] = r[c]

    @ti.func
    def lanes_stage(p0, p1, p2):  # the stage on lists of three 8-wide vectors (one strand per lane)
        e0 = [p1[c] - p0[c] for c in ti.static(range(3))]
        e1 = [p2[c] - p1[c] for c in ti.static(range(3))]
        n0 = ti.sqrt(e0[0] * e0[0] + e0[1] * e0[1] + e0[2] * e0[2])
        n1 = ti.sqrt(e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2])
        t0 = [e0[c] / n0 for c in ti.static(range(3))]
        t1 = [e1[c] / n1 for c in ti.static(range(3))]
        d = t0[0] * t1[0] + t0[1] * t1[1] + t0[2] * t1[2]
        kb = [2.0 * (t0[1] * t1[2] - t0[2] * t1[1]) / (1.0 + d),
              2.0 * (t0[2] * t1[0] - t0[0] * t1[2]) / (1.0 + d),
              2.0 * (t0[0] * t1[1] - t0[1] * t1[0]) / (1.0 + d)]
        if ti.static(branch):
            for c in ti.static(range(3)):
                kb[c] = ti.select(d < -0.999, t0[c], kb[c])
        n = ti.sqrt(kb[0] * kb[0] + kb[1] * kb[1] + kb[2] * kb[2])
        cn, sn = ti.cos(n), ti.sin(n)
        return [kb[c] * cn + t1[c] * sn for c in ti.static(range(3))]

    @ti.kernel
    def lanes_8(iterations: ti.i32):
        for g in range(G):
            for _ in range(iterations):
                for k in range(1, M - 1):
                    r = lanes_stage([x_lane[g, k - 1, c] for c in ti.static(range(3))],
                                    [x_lane[g, k, c] for c in ti.static(range(3))],
                                    [x_lane[g, k + 1, c] for c in ti.static(range(3))])
                    for c in ti.static(range(3)):
                        y_lane[g, k, c] = r[c]

    @ti.func
    def gather(g, k):  # eight strands' vertex k from the strand-major layout, one strand per lane
        return [V8([x_strand[g * L + q, k][c] for q in ti.static(range(L))]) for c in ti.static(range(3))]

    @ti.kernel
    def gather_8(iterations: ti.i32):
        for g in range(G):
            for _ in range(iterations):
                for k in range(1, M - 1):
                    r = lanes_stage(gather(g, k - 1), gather(g, k), gather(g, k + 1))
                    for q in ti.static(range(L)):
                        y_strand[g * L + q, k] = ti.Vector([r[0][q], r[1][q], r[2][q]])

    fill()
    rates = {}
    for name, kernel in (("scalar", scalar), ("interleaved_2", interleaved_2), ("unrolled_8", unrolled_8),
                         ("lanes_8", lanes_8), ("gather_8", gather_8)):
        kernel(1)
        ti.sync()
        best = float("inf")
        for _ in range(3):
            t = time.perf_counter()
            kernel(a.iterations)
            ti.sync()
            best = min(best, time.perf_counter() - t)
        rates[name] = S * (M - 2) * a.iterations / best / 1e6
    gathered = y_strand.to_numpy()[:, 1:-1]  # (gather_8 ran last; scalar again for the reference)
    scalar(a.iterations)
    ref = y_strand.to_numpy()[:, 1:-1]
    lanes = y_lane.to_numpy().transpose(0, 3, 1, 2).reshape(S, M, 3)[:, 1:-1]
    unrolled = y_vertex.to_numpy().transpose(2, 0, 1)[:, 1:-1]
    diff = np.abs(lanes - ref)
    print(f"{S} strands x {M} vertices, {a.iterations} iterations, best of 3{', with a branch' if branch else ''}:")
    for name, r in rates.items():
        print(f"  {name:14s} {r:8.1f} M vertex-iterations/s  x{r / rates['scalar']:.2f}")
    print(f"  unrolled_8 against scalar: the same bits {bool(np.array_equal(unrolled, ref))}; lanes_8 against scalar: "
          f"largest difference {diff.max():.2e}, p99 {np.percentile(diff, 99):.2e} (|y| up to {np.abs(ref).max():.1f}); "
          f"gather_8 against lanes_8: the same bits {bool(np.array_equal(gathered, lanes))}")
    if a.json:
        with open(a.json, "w") as fh:
            json.dump({"strands": S, "vertices": M, "iterations": a.iterations, "branch": branch,
                       "m_vertex_iterations_per_s": rates, "lanes_max_difference": float(diff.max())}, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
