"""Benchmark of guide skinning (Daviet 2023, Sec. 5.3: 86,000 render curves, 8,600 simulated).

A procedural groom on the upper half of a 9 cm sphere: ``--strands`` render
strands of ``--vertices`` vertices (default 86,000 x 14 = 1.2M render
vertices), slightly curly, 30 cm long; ``--guide-ratio`` of them (10 %: 8,600
guides, 120k guide vertices) chosen by farthest-point sampling and built into
a guide Model.  Each frame the guides are moved by a head rotation plus a sway
(a kernel, not timed), then ``SkinningLBS.deform`` skins every render strand
from its k = 4 nearest guides.  Reported: milliseconds per frame for the
skinning (guide frames + blend), the split between the two kernels from a
separate synchronised run, and the one-off set-up (FPS, guide Model, binding)
and first-call compile times.

Usage:
    python benchmarks/bench_skinning.py [--arch cpu|cuda] [--strands 86000] [--vertices 14]
        [--guide-ratio 0.1] [--neighbours 4] [--frames 50] [--out FILE]

Figures are printed and written as JSON (default benchmarks/results/skinning_<arch>.json).
"""

import argparse
import math
import os

import numpy as np

from harness import Bench, results_path, stopwatch  # benchmarks/harness.py (the script's folder is on sys.path)


def sphere_groom(strands, vertices, radius=0.09, length=0.3, curl_radius=5e-3, curl_pitch=0.05, seed=0):
    """(strands, vertices, 3) polylines: roots on the upper half sphere (golden spiral), growing
    along the normal with a helical curl ramped in from the root (vectorised)."""
    rng = np.random.default_rng(seed)
    golden = math.pi * (3.0 - math.sqrt(5.0))
    k = np.arange(strands) + 0.5
    y = k / strands  # upper half: y in (0, 1)
    r = np.sqrt(1.0 - y * y)
    phi = golden * np.arange(strands)
    n = np.c_[r * np.cos(phi), y, r * np.sin(phi)]
    helper = np.where(np.abs(n[:, 1:2]) < 0.9, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]])
    a = np.cross(n, helper)
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b = np.cross(n, a)
    L = length * rng.uniform(0.85, 1.0, strands)
    s = np.linspace(0.0, 1.0, vertices)[None, :] * L[:, None]
    ramp = np.minimum(1.0, s / (0.2 * L[:, None]))
    ang = 2 * np.pi * s / curl_pitch + rng.uniform(0, 2 * np.pi, strands)[:, None]
    off = curl_radius * ramp[..., None] * (np.cos(ang)[..., None] * a[:, None] + np.sin(ang)[..., None] * b[:, None])
    return radius * n[:, None] + s[..., None] * n[:, None] + off


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--arch", default="cpu", choices=["cpu", "cuda"])
    ap.add_argument("--strands", type=int, default=86000)
    ap.add_argument("--vertices", type=int, default=14)
    ap.add_argument("--guide-ratio", type=float, default=0.1)
    ap.add_argument("--neighbours", type=int, default=4)
    ap.add_argument("--frames", type=int, default=50)
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    bench = Bench("skinning", argv)

    import taichi as ti

    import taichi_hair

    taichi_hair.init(arch=getattr(ti, args.arch), default_fp=ti.f32, offline_cache=True, log_level=ti.WARN)
    from taichi_hair.groom.skinning import SkinningConfig, SkinningLBS, build_guides

    # The date, the machine's name and the load average at the start: the harness's machine block.
    result = {"arch": args.arch, "strands": args.strands, "vertices_per_strand": args.vertices,
              "guide_ratio": args.guide_ratio, "neighbours": args.neighbours, "frames": args.frames}
    cfg = SkinningConfig(guide_ratio=args.guide_ratio, neighbour_count=args.neighbours)

    with stopwatch(ti.sync) as groom_t:
        strands = sphere_groom(args.strands, args.vertices)
    with stopwatch(ti.sync) as guides_t:
        guides, gmodel = build_guides(strands, None, cfg)
    with stopwatch(ti.sync) as binding_t:
        sk = SkinningLBS(gmodel, guides, strands, cfg)
    result.update(guides=int(gmodel.strand_count), guide_vertices=int(gmodel.vertex_count),
                  render_vertices=int(sk.render_vertex_count),
                  setup_seconds={"groom": groom_t.seconds, "select_and_build_guides": guides_t.seconds,
                                 "binding": binding_t.seconds})

    state, control = gmodel.state(), gmodel.control()
    rest = gmodel.vertex_rest_position
    local = gmodel.vertex_local_index

    @ti.kernel
    def animate(t: float):
        # Head turn about y plus a sway growing along each strand (not timed).
        c, s = ti.cos(0.6 * ti.sin(t)), ti.sin(0.6 * ti.sin(t))
        for i in rest:
            p = rest[i]
            q = ti.Vector([c * p[0] + s * p[2], p[1], -s * p[0] + c * p[2]])
            w = ti.cast(local[i], float) ** 2 * 2e-4
            state.vertex_position[i] = q + w * ti.Vector([ti.sin(3 * t + p[1] * 20), 0.0, ti.cos(2 * t + p[0] * 20)])

    def set_frame(f):
        t = 0.1 * f
        a = 0.6 * math.sin(t)
        R = np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])
        control.set_body_transform(0, R, np.zeros(3))
        animate(t)

    # First call: compile.
    set_frame(0)
    with stopwatch(ti.sync) as sw:
        sk.deform(state, control)
    result["first_deform_seconds"] = sw.seconds

    # Timed: deform only, synchronised per frame.
    times = []
    for f in range(1, args.frames + 1):
        set_frame(f)
        with stopwatch(ti.sync) as sw:
            sk.deform(state, control)
        times.append(sw.seconds)
    ms = 1e3 * np.array(times)
    result["ms_per_frame"] = {"mean": float(ms.mean()), "median": float(np.median(ms)), "min": float(ms.min()),
                              "max": float(ms.max())}

    # Split between the two kernels (synchronised after each).
    from taichi_hair.groom import skinning as skm

    frames_t, blend_t = [], []
    for f in range(1, args.frames + 1):
        set_frame(f)
        with stopwatch(ti.sync) as frames_sw:
            skm.compute_guide_frames_transport(gmodel, gmodel, control.body_rotation, state.vertex_position,
                                               sk.fields.guide_edge_frame)
        with stopwatch(ti.sync) as blend_sw:
            skm.apply_skinning(sk.fields, sk.neighbour_count, state.vertex_position, control.body_rotation,
                               control.body_translation, sk.fields.render_vertex_position)
        frames_t.append(frames_sw.seconds)
        blend_t.append(blend_sw.seconds)
    result["ms_per_stage_median"] = {"guide_frames": 1e3 * float(np.median(frames_t)),
                                     "blend": 1e3 * float(np.median(blend_t))}
    x = sk.positions()
    result["finite"] = bool(np.all(np.isfinite(x)))
    if not result["finite"]:
        raise SystemExit("bench_skinning: non-finite skinned positions")

    out = bench.write(args.out or results_path(f"skinning_{args.arch}.json"), result)
    s = result["setup_seconds"]
    print(f"skinning {args.strands} render strands x {args.vertices} vertices ({sk.render_vertex_count} vertices) "
          f"from {gmodel.strand_count} guides ({gmodel.vertex_count} vertices), k={sk.neighbour_count}, "
          f"arch={args.arch}, {os.cpu_count()} CPUs")
    print(f"  per frame: {result['ms_per_frame']['median']:.2f} ms median, {result['ms_per_frame']['mean']:.2f} ms "
          f"mean over {args.frames} frames (guide frames {result['ms_per_stage_median']['guide_frames']:.2f} ms, "
          f"blend {result['ms_per_stage_median']['blend']:.2f} ms)")
    print(f"  set-up: groom {s['groom']:.2f} s, FPS + guide Model {s['select_and_build_guides']:.2f} s, "
          f"binding {s['binding']:.2f} s; first deform (compile) {result['first_deform_seconds']:.2f} s")
    print(f"  written to {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
