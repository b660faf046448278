"""Where the hair-hair broad phase spends its time: the candidate search taken apart on a dense pile.

Run from the repository root: ``python3 benchmarks/probes/find_candidates_split.py [STRANDS] [FRAMES]`` (default
1000 strands, 10 frames: the hairball just after its impact).  The hairball is simulated to FRAMES, then four
copies of the query loop run on its state, each doing one more part of the real kernel, so that the
differences give the cost of each part (same machine, same state, best of 3):

0. walk the buckets of every edge's cells, reading each entry's edge (the memory sweep alone);
1. + the entry test (``entry_pair_here``: the two boxes overlap and this is the first cell both share);
2. + the pair's reach (relative velocity) and the 18-DOP test;
3. + the closest points of the two segments;

then the search as it was until 2026-12-05, each pair tested from both sides (level 4: the loop + the sorted
insertion of the K closest), against the library's ``contact.pairs.find_candidates`` (each pair
tested once, from its lower edge, then gathered per edge), in the same run, and whether the two keep the same
lists.  It also prints the average count of overlapping boxes and of DOP survivors per edge.  A diagnostic.
"""

import sys
import time

import numpy as np
import taichi as ti

from taichi_hair.contact.grid import (bucket_of, cell_in_range, dops_overlap, edges_adjacent, edges_kinematic,
                                     entry_pair_here, insert_candidate, segment_closest_points)


@ti.kernel
def query_part(vertex: ti.template(), edge: ti.template(), x: ti.template(), radius: ti.template(),
               grid: ti.template(), boxes: ti.template(), h: float, margin: float, sweep: float, fall: float,
               level: ti.template(), out: ti.template()):
    """The search from both sides of each pair (the library's until 2026-12-05) up to part ``level`` (module
    docstring); per edge, a sum into ``out`` so the compiler keeps the work.  Level 4 is the whole search: it
    keeps each edge's K closest by sorted insertion into ``grid.edge_candidate``."""
    t = boxes.table_size
    K = ti.static(grid.candidates_per_edge)
    for a in grid.edge_candidate_count:
        acc = 0.0
        count = 0
        if edge.edge_rest_length[a] > 0.0:
            ca = grid.edge_dop_center[a]
            ea = grid.edge_dop_extent[a]
            ra = radius[a]
            sa = vertex.vertex_strand[a]
            va = grid.edge_velocity[a]
            sa_spread = grid.edge_velocity_spread[a]
            lo = boxes.edge_cell_lo[a]
            box_lo_a = boxes.edge_box_lo[a]
            box_hi_a = boxes.edge_box_hi[a]
            span = boxes.edge_cell_hi[a] - lo + 1
            for k in range(span[0] * span[1] * span[2]):
                cell = cell_in_range(lo, k, span)
                bkt = bucket_of(cell, t)
                for e in range(boxes.bucket_start[bkt], boxes.bucket_start[bkt + 1]):
                    if ti.static(level == 0):
                        acc += ti.cast(boxes.entry_edge[e] & 1, ti.f32)  # a read the compiler cannot drop
                    else:
                        if entry_pair_here(boxes, e, lo, box_lo_a, box_hi_a, cell, h):
                            b = boxes.entry_edge[e]
                            if ti.static(level == 1):
                                acc += 1.0
                            elif b != a and not edges_adjacent(vertex, a, b, sa):
                                rel = (va - grid.edge_velocity[b]).norm() + sa_spread + grid.edge_velocity_spread[b]
                                reach = ra + radius[b] + margin + sweep * rel + fall
                                if dops_overlap(ca, ea, grid.edge_dop_center[b], grid.edge_dop_extent[b], reach):
                                    if ti.static(level == 2):
                                        acc += 1.0
                                    else:
                                        s, u, dist = segment_closest_points(x[a], x[a + 1], x[b], x[b + 1])
                                        if dist < reach:
                                            if ti.static(level == 3):
                                                acc += dist
                                            elif not edges_kinematic(vertex, a, b):
                                                count = insert_candidate(grid, a, b, dist, count, K)
        out[a] = acc
        if ti.static(level == 4):
            grid.edge_candidate_count[a] = count


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    strands = int(argv[0]) if argv else 1000
    frames = int(argv[1]) if len(argv) > 1 else 10
    import taichi_hair

    taichi_hair.init(arch=ti.cpu, log_level=ti.WARN)
    from taichi_hair import SolverADMM, SolverADMMConfig
    from taichi_hair.config import ContactConfig
    from taichi_hair.contact.colliders import SphereCollider
    from taichi_hair.contact.pairs import find_candidates
    from taichi_hair.scene.builtin import HairballScene, build_hairball, hairball_rotation

    scene = HairballScene(strands=strands, length=0.3)
    model = build_hairball(scene)
    cfg = SolverADMMConfig(iterations=10, mode="dynamic", contacts=ContactConfig(
        friction=scene.friction, projection_iterations=2, correction_iterations=10))
    solver = SolverADMM(model, cfg, colliders=[SphereCollider(radius=scene.ball_radius, friction=scene.friction,
                                                               body=0)])
    st, ct = model.state(), model.control()
    dt = 1.0 / 96
    for f in range(1, frames + 1):
        for k in range(4):
            ct.set_body_transform(0, hairball_rotation(((f - 1) * 4 + k + 1) * dt), (0, 0, 0))
            solver.step(st, ct, dt)
    pipe = solver.contacts
    contacts = pipe.detect(st, dt, (0.0, -9.81, 0.0), True)  # the grid of this state
    g, bx, m = pipe.grid, pipe.boxes, model
    h = float(g.max_edge_length[None])
    # The sweep and fall of ContactPipeline.detect, capped as there.
    speed = float(g.max_speed[None])
    sweep, fall = cfg.contacts.velocity_margin * dt, cfg.contacts.velocity_margin * 9.81 * dt * dt
    motion = 2.0 * sweep * speed + fall
    if motion > h:
        sweep, fall = sweep * h / motion, fall * h / motion
    out = ti.field(ti.f32, m.vertex_count)
    args = (m.vertex, m.edge, st.vertex_position, pipe.vertex_radius, g, bx, h, cfg.contacts.margin, sweep, fall)

    def best(fn) -> float:
        fn()
        ti.sync()
        times = []
        for _ in range(3):
            t = time.perf_counter()
            fn()
            ti.sync()
            times.append(time.perf_counter() - t)
        return 1e3 * min(times)

    edges = int(np.count_nonzero(m.host["edge_rest_length"] > 0))
    print(f"hairball {strands} strands after {frames} frames: {contacts} contacts, {edges} edges, cells {1e3 * h:.1f} mm")
    prev = 0.0
    names = ("walk the buckets", "+ entry test (boxes overlap, first shared cell)", "+ reach and 18-DOP",
             "+ closest points")
    for level in range(4):
        ms = best(lambda: query_part(*args, level, out))
        per = float(out.to_numpy().sum()) / edges
        extra = {0: "", 1: f"overlapping boxes per edge {per:.1f}",
                 2: f"DOP survivors per edge {per:.1f}", 3: ""}[level]
        print(f"  {level}. {names[level]:48s} {ms:8.1f} ms  (+{ms - prev:6.1f})  {extra}")
        prev = ms
    ms = best(lambda: query_part(*args, 4, out))
    print(f"  both sides (+ sorted insertion of the K closest)        {ms:8.1f} ms  (+{ms - prev:6.1f})")

    def lists():
        cnt, cand = g.edge_candidate_count.to_numpy(), g.edge_candidate.to_numpy()
        return [frozenset(cand[a, :cnt[a]].tolist()) for a in range(cnt.size)]

    before = lists()
    from taichi_hair.fields import PairFields

    # The library's search with pair buffers of several sizes per vertex: one round when it holds every pair
    # within reach, else rounds (each edge resumes where the full buffer stopped it); the same lists either way.
    # Against the search from both sides, a list may differ where two candidates tie to the last bit at the K-th
    # place: there each side computed the pair's distance itself, here the lower edge computes it for both.
    one_round = None
    for per_vertex in (48.0, cfg.contacts.pairs_per_edge, 6.0, 3.0):
        pairs = PairFields(m.vertex_count, int(per_vertex * m.vertex_count))
        rounds = [0]

        def once():
            rounds[0] = find_candidates(*args[:6], pairs, *args[6:])

        ms_once = best(once)
        after = lists()
        differ = sum(1 for u, w in zip(before, after) if u != w)
        full = (g.edge_candidate_count.to_numpy(), g.edge_candidate.to_numpy(), g.edge_candidate_distance.to_numpy())
        one_round = full if one_round is None else one_round
        same = all(np.array_equal(u, w) for u, w in zip(full, one_round))
        total = int(pairs.pair_count[None]) + (rounds[0] - 1) * pairs.capacity
        print(f"  each pair once, buffer {per_vertex:4.0f} per vertex, {rounds[0]} round(s) {ms_once:8.1f} ms  "
              f"({ms / ms_once:.2f}x faster than both sides); {total} pairs; edges whose lists differ: {differ}; "
              f"lists, order and distances bit-identical to one round: {same}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
