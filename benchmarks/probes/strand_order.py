"""Did a run's strands change their over/under order?  (Issue 14, item 3: why the ponytail does not come back.)

Run from the repository root on any run's output folder (``taichi-hair simulate ... --out DIR``):
    python3 benchmarks/probes/strand_order.py DIR [--within 1e-3]

For every pair of edges of two different strands that cross within ``--within`` metres of each other in the first
AND the last frame, with their closest points inside both edges (not at an end), crossing at ``--angle`` degrees or
more in both frames, the sign of (e_a x e_b) . (c_a - c_b) (c the closest points) says which strand passes over the
other.  Non-penetrating strands cannot change that sign without one going around the other's free end, or without
the two edges turning through parallel (e_a x e_b reverses while neither strand passes the other); pairs whose
crossing normal e_a x e_b turned by more than 60 degrees between the two frames are left out for that reason, and
what is left is still measured on two frames only, not tracked in between: read "flipped" as an estimate.  A flipped
pair is a reordering that no restoring force undoes: the rest pose holds each strand's own shape, and contacts keep
the new order.  Also printed: the p90 drift by vertex index, the mean displacement (the groom's centroid) and its
spread, and the radius of gyration of each vertex index's cross-section, first and last frame.  Uniform strand
lengths are assumed (vertices / strands per strand), as in the generated grooms and the ponytail."""

import argparse
import json
import os

import numpy as np
from scipy.spatial import cKDTree


def closest_points(p1, q1, p2, q2):
    """Closest points of segment pairs [p1, q1], [p2, q2] (arrays (n, 3)): points, distances and parameters."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a, e = (d1 * d1).sum(-1), (d2 * d2).sum(-1)
    b, c, f = (d1 * d2).sum(-1), (d1 * r).sum(-1), (d2 * r).sum(-1)
    den = a * e - b * b
    s = np.where(den > 1e-20, np.clip((b * f - c * e) / np.maximum(den, 1e-30), 0, 1), 0.0)
    t = np.clip((b * s + f) / e, 0, 1)
    s = np.clip((b * t - c) / a, 0, 1)
    t = np.clip((b * s + f) / e, 0, 1)
    ca, cb = p1 + d1 * s[:, None], p2 + d2 * t[:, None]
    return ca, cb, np.linalg.norm(ca - cb, axis=1), s, t


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("run", help="a simulate --out folder (frames.npz, summary.json)")
    ap.add_argument("--within", type=float, default=1e-3, help="largest crossing distance of a pair counted [m]")
    ap.add_argument("--angle", type=float, default=10.0, help="smallest crossing angle of a pair counted, both frames [deg]")
    args = ap.parse_args(argv)
    with np.load(os.path.join(args.run, "frames.npz")) as z:
        frames = z["positions" if "positions" in z.files else z.files[0]].astype(np.float64)
    with open(os.path.join(args.run, "summary.json")) as fh:
        s = json.load(fh)
    ns = s["strands"]
    m = s["vertices"] // ns
    x0, x1 = frames[0], frames[-1]
    strand = np.repeat(np.arange(ns), m)
    edges = np.nonzero(np.arange(ns * m) % m != m - 1)[0]
    mid = 0.5 * (x0[edges] + x0[edges + 1])
    reach = float(np.linalg.norm(x0[edges + 1] - x0[edges], axis=1).max()) + args.within
    p = cKDTree(mid).query_pairs(reach, output_type="ndarray")
    a, b = edges[p[:, 0]], edges[p[:, 1]]
    keep = strand[a] != strand[b]
    a, b = a[keep], b[keep]
    seen = []
    for x in (x0, x1):
        ca, cb, dist, sa, sb = closest_points(x[a], x[a + 1], x[b], x[b + 1])
        ta = (x[a + 1] - x[a]) / np.linalg.norm(x[a + 1] - x[a], axis=1)[:, None]
        tb = (x[b + 1] - x[b]) / np.linalg.norm(x[b + 1] - x[b], axis=1)[:, None]
        normal = np.cross(ta, tb)
        sine = np.linalg.norm(normal, axis=1)
        normal /= np.maximum(sine, 1e-30)[:, None]
        side = np.sign(np.einsum("ij,ij->i", normal, ca - cb))
        inner = (sa > 0.02) & (sa < 0.98) & (sb > 0.02) & (sb < 0.98)
        seen.append(((dist < args.within) & inner & (side != 0) & (sine > np.sin(np.radians(args.angle))), side, normal))
    # The sign can also change by the two edges turning through parallel between the frames (e_a x e_b reverses
    # while neither passes the other): only pairs whose crossing normal kept its direction (within 60 degrees) count.
    counted = seen[0][0] & seen[1][0] & (np.einsum("ij,ij->i", seen[0][2], seen[1][2]) > 0.5)
    flipped = counted & (seen[0][1] != seen[1][1])
    pairs = {(int(i), int(j)) for i, j in zip(strand[a[counted]], strand[b[counted]])}
    flips = {(int(i), int(j)) for i, j in zip(strand[a[flipped]], strand[b[flipped]])}
    print(f"{args.run}: {ns} strands x {m} vertices, {frames.shape[0]} frames")
    print(f"edge pairs crossing within {1e3 * args.within:g} mm in the first and last frame: {int(counted.sum())}, "
          f"over/under order flipped: {int(flipped.sum())}; strand pairs {len(pairs)}, flipped {len(flips)}")
    y0, y1 = x0.reshape(ns, m, 3), x1.reshape(ns, m, 3)
    dx = y1 - y0
    print("p90 drift by vertex index [mm]:", np.round(1e3 * np.percentile(np.linalg.norm(dx, axis=2), 90, axis=0), 2))
    print("mean displacement of the tips [mm]:", np.round(1e3 * dx[:, -1].mean(0), 2),
          "spread (std per axis) [mm]:", np.round(1e3 * dx[:, -1].std(0), 2))
    r0 = np.sqrt(((y0 - y0.mean(0)) ** 2).sum(2).mean(0))
    r1 = np.sqrt(((y1 - y1.mean(0)) ** 2).sum(2).mean(0))
    print("radius of gyration by vertex index, first frame [mm]:", np.round(1e3 * r0, 1))
    print("radius of gyration by vertex index, last frame [mm]: ", np.round(1e3 * r1, 1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
