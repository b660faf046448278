"""Frictional contacts (Sec. 4.5): local Coulomb solve, detection, projection in the solver, colliders."""

import math

import numpy as np
import pytest
import taichi as ti

from taichi_hair import GroomBuilder, RodMaterial, SolverADMM, SolverADMMConfig
from taichi_hair.contact.colliders import CapsuleCollider, ColliderSet, MeshCollider, PlaneCollider, SphereCollider
from taichi_hair.config import ContactConfig
from taichi_hair.contact.projection import hold_strand_lengths

from geometry import segment_distance, segment_distances

HAIR = RodMaterial()
R = HAIR.radius


def line(p0, p1, n):
    return np.linspace(np.asarray(p0, float), np.asarray(p1, float), n)


# --------------------------------------------------------------------------- local solve
def _solve_many(w, n, mu):
    from taichi_hair.contact.projection import coulomb_local_solve

    k = len(w)
    wf = ti.Vector.field(3, float, k)
    nf = ti.Vector.field(3, float, k)
    mf = ti.field(float, k)
    rf = ti.Vector.field(3, float, k)
    sf = ti.field(ti.i32, k)
    wf.from_numpy(np.asarray(w, np.float32))
    nf.from_numpy(np.asarray(n, np.float32))
    mf.from_numpy(np.asarray(mu, np.float32))

    @ti.kernel
    def run():
        for i in wf:
            r, s = coulomb_local_solve(wf[i], nf[i], mf[i])
            rf[i] = r
            sf[i] = s

    run()
    return rf.to_numpy().astype(np.float64), sf.to_numpy()


def test_coulomb_local_solve_hand_cases():
    n = [0.0, 1.0, 0.0]
    w = [[0.3, 0.5, 0.0],     # separating: normal part >= 0
         [0.1, -1.0, 0.2],    # inside the cone: |w_T| = 0.224 <= 0.5 * 1
         [2.0, -1.0, 0.0]]    # outside: slides
    r, s = _solve_many(w, [n] * 3, [0.5] * 3)
    assert s.tolist() == [0, 1, 2]
    np.testing.assert_allclose(r[0], 0.0, atol=0)
    np.testing.assert_allclose(r[1], [-0.1, 1.0, -0.2], rtol=1e-6)          # r = -w, u = 0
    np.testing.assert_allclose(r[2], [-0.5, 1.0, 0.0], rtol=1e-6)           # r_N = 1, |r_T| = mu r_N
    u = np.asarray(w[2]) + r[2]
    np.testing.assert_allclose(u, [1.5, 0.0, 0.0], rtol=1e-6)               # slides on, with less speed


def test_coulomb_local_solve_satisfies_the_law_on_random_inputs():
    rng = np.random.default_rng(3)
    k = 2000
    w = rng.normal(size=(k, 3))
    n = rng.normal(size=(k, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    mu = rng.uniform(0, 1.2, k)
    r, s = _solve_many(w, n, mu)
    u = w + r
    rn = np.sum(r * n, 1)
    un = np.sum(u * n, 1)
    rt = r - rn[:, None] * n
    ut = u - un[:, None] * n
    tol = 1e-5 * (1 + np.abs(w).max(1))
    assert np.all(rn >= -tol)                                             # compressive only
    assert np.all(np.linalg.norm(rt, axis=1) <= mu * rn + tol)            # inside the cone
    assert np.all(un >= -tol)                                             # no penetration
    assert np.all(np.abs(rn * un) <= tol * (1 + np.abs(rn)))              # complementarity
    slide = s == 2
    assert slide.any() and (s == 1).any() and (s == 0).any()
    # Sliding: force on the cone boundary, opposed to the slip (maximal dissipation).
    cosang = np.sum(rt[slide] * ut[slide], 1) / (np.linalg.norm(rt[slide], axis=1) * np.linalg.norm(ut[slide], axis=1))
    assert np.all(cosang < -1 + 1e-4)
    stick = s == 1
    assert np.all(np.linalg.norm(u[stick], axis=1) <= tol[stick])


# --------------------------------------------------------------------------- detection
def _brute_force_contacts(x, strand_of, edges, reach, K):
    """All pairs closer than ``reach(a, b)``, then the paper's rule: keep a pair if it is among the K closest of
    either edge."""
    from itertools import combinations

    near = {a: [] for a in edges}
    for a, b in combinations(edges, 2):
        if strand_of[a] == strand_of[b] and abs(a - b) <= 1:
            continue
        d = segment_distance(x[a], x[a + 1], x[b], x[b + 1])
        if d < reach(a, b):
            near[a].append((d, b))
            near[b].append((d, a))
    top = {a: {b for _, b in sorted(v)[:K]} for a, v in near.items()}
    crowded = sum(len(v) > K for v in near.values())
    return {(min(a, b), max(a, b)) for a in edges for b in top[a]}, crowded


def _random_groom(seed, strands=80, edge=2e-3, box=0.012):
    rng = np.random.default_rng(seed)
    b = GroomBuilder()
    mat = RodMaterial(radius=6e-4)
    for s in range(strands):
        p0 = rng.uniform(0, box, 3)
        d = rng.normal(size=(4, 3))
        b.add_strand(p0 + np.cumsum(edge * d / np.linalg.norm(d, axis=1, keepdims=True), axis=0), mat, root="free")
    return b.finalize(), mat


def test_detection_matches_brute_force_on_random_edges():
    """Random short strands in a small box: the hash grid + DOP + top-K finds exactly the brute-force set.
    Then again with a pair buffer of 7 pairs (``contact.pairs``: the search runs in rounds, each edge resuming
    where the full buffer stopped it, 7 not a multiple of the 8 pairs an edge appends at once): the same set,
    and every edge's list, its order and its distances bit-identical to the one-round search."""
    from taichi_hair.contact.pipeline import ContactPipeline
    from taichi_hair.fields import PairFields

    model, mat = _random_groom(7)
    st = model.state()
    cfg = ContactConfig(margin=2e-4, max_contacts_per_edge=6)
    pipe = ContactPipeline(model, cfg)
    pipe.colliders.begin_step(model.control())
    x = st.positions().astype(np.float64)
    edges = [i for i in range(model.vertex_count) if model.host["edge_rest_length"][i] > 0]
    expected, crowded = _brute_force_contacts(x, model.host["vertex_strand"], edges,
                                              lambda a, b: 2 * mat.radius + cfg.margin, 6)
    assert crowded > 10  # the 6-closest rule is exercised
    lists = []
    for buffer in (None, 7):
        if buffer is not None:
            pipe.pairs = PairFields(model.vertex_count, buffer)
        total = pipe.detect(st, 1e-3, (0, -9.81, 0), True)
        vtx = pipe.con.contact_vertex.to_numpy()[:total]
        found = {(min(v[0], v[2]), max(v[0], v[2])) for v in vtx}
        assert len(found) == total  # emitted once each
        assert found == expected
        assert total > 100
        g = pipe.grid
        lists.append([g.edge_candidate_count.to_numpy(), g.edge_candidate.to_numpy(),
                      g.edge_candidate_distance.to_numpy()])
        rounds = pipe.pair_rounds_last
        assert (rounds == 1) if buffer is None else (rounds > 50), rounds  # > 350 pairs within reach: > 50 rounds
    for one, many in zip(*lists):
        assert np.array_equal(one, many)


def test_a_verlet_skin_gives_the_pairs_of_a_search_every_step():
    """``ContactConfig.pair_skin`` (``pairs.find_candidates_skin``): pairs within reach + skin are kept between
    quasistatic detections and an edge searches again only once a vertex moved more than skin / 3 since its last
    search.  Over 12 detections of the random groom, a third of its strands moving 0.05-0.5 mm between
    detections and the rest 0-10 um (the brute-force test's groom: 0.6 mm radii, 0.2 mm margin), every edge's
    list holds the same edges as with a search every step (equally near edges at its farthest kept distance may
    swap; a pair left out was >= reach + skin apart at the
    later of its edges' searches and came <= skin closer), their distances within 1e-8 m: the same segment
    test, compiled into another kernel (with fast math the two round differently; float32 coordinates of ~1 cm
    round at ~1e-9 m: 2.5e-11 m measured on the closest pair).  A detection where nothing moved searches no
    edge, the others a part of them (at least 8 of 12 fewer than half).  A Model update that keeps the radii,
    strands and kinematic vertices (a grooming edit: ``set_coefficients`` at step 8) keeps the pairs, and only the
    edges that moved search; one that changes a radius (step 10), or a margin changed on the config (step 11),
    searches every edge again.  Every stored pair's distance is its distance or a lower bound of it (a pair that
    cannot have come within reach keeps a bound, not measured again), and some pairs keep a bound."""
    from dataclasses import replace
    from taichi_hair.contact.pipeline import ContactPipeline

    model, _ = _random_groom(7)
    st = model.state()
    skin = 6e-4
    pipes = [ContactPipeline(model, ContactConfig(margin=2e-4, max_contacts_per_edge=6, pair_skin=k)) for k in (skin, 0.0)]
    for p in pipes:
        p.colliders.begin_step(model.control())
    rng = np.random.default_rng(3)
    x = st.positions().astype(np.float64)
    strand = model.host["vertex_strand"]
    fast = rng.random(model.strand_count) < 1 / 3
    edges = int(np.count_nonzero(model.host["edge_rest_length"] > 0))
    searched = []
    bounded = 0
    for step in range(12):
        if step > 0 and step != 5:  # (step 5: nothing moves)
            size = np.where(fast[strand], rng.uniform(5e-5, 5e-4), rng.uniform(0.0, 1e-5))[:, None]
            x = x + size * rng.normal(size=x.shape) / np.sqrt(3)
            st.vertex_position.from_numpy(x.astype(np.float32))
        if step == 8:
            for p in pipes:
                p.set_coefficients()  # (what refresh_model runs after a Model update)
        if step == 10:  # a thicker strand: its reach grows, so the kept pairs may miss some
            model.materials[0] = replace(model.materials[0], radius=1.5 * model.materials[0].radius)
            for p in pipes:
                p.set_coefficients()
        if step == 11:  # a wider margin, set on the config between steps: every edge searches again
            for p in pipes:
                p.config.margin = 3e-4
        lists = []
        for p in pipes:
            p.detect(st, 1.0, (0, -9.81, 0), False)
            g = p.grid
            lists.append([g.edge_candidate_count.to_numpy(), g.edge_candidate.to_numpy(),
                          g.edge_candidate_distance.to_numpy()])
        (c0, e0, d0), (c1, e1, d1) = lists
        # Each stored pair's distance is its distance now or a lower bound of it (``lists_from_pairs`` measures only
        # the pairs that may be within reach; a segment distance moves by at most its vertices' largest displacement):
        # float64 distances of the float32 positions, 1e-8 m for the kernels' rounding.
        pr, xs = pipes[0].pairs, st.vertex_position.to_numpy().astype(np.float64)
        npair = int(pr.pair_count[None])
        pe, pd = pr.pair_edge.to_numpy()[:npair], pr.pair_distance.to_numpy()[:npair]
        true = segment_distances(xs[pe[:, 0]], xs[pe[:, 0] + 1], xs[pe[:, 1]], xs[pe[:, 1] + 1])
        assert np.all(pd <= true + 1e-8), step
        bounded += int(np.count_nonzero(pd < true - 1e-8))
        assert np.array_equal(c0, c1), step
        for a in np.nonzero(c0)[0]:
            k = c0[a]
            # The same candidates, but for ties at the farthest kept distance: two edges of a strand that share the
            # nearest vertex are equally near (seen: edges 292 and 293 both at 1.13094 mm), and either may be kept.
            far = d0[a, :k].max() - 1e-8
            assert set(e0[a, :k][d0[a, :k] < far]) == set(e1[a, :k][d1[a, :k] < far]), (step, a)
            assert np.allclose(d0[a, :k], d1[a, :k], rtol=0.0, atol=1e-8), (step, a)
        assert c0.sum() > 100
        searched.append(pipes[0].statistics(st.vertex_position)["pair_skin_edges_searched"])
    assert bounded > 0  # (some pairs kept a bound: at step 5 nothing moved)
    assert searched[0] == edges and searched[10] == edges and searched[11] == edges, searched
    assert 0 < searched[8] < edges // 2, searched
    assert searched[5] == 0 and sum(0 < k < edges // 2 for k in searched) >= 8, searched
    assert pipes[1].pair_skin_searched == -1


def test_a_skin_whose_pairs_overflow_the_buffer_is_given_up_with_a_warning_and_nothing_is_lost():
    """A skin of 5 mm on the random groom (a 12 mm box) keeps thousands of pairs, more than a 256-pair buffer: the
    detection warns once, searches without the skin (the lists of a pipeline without one, bit for bit: the same
    kernel), and the next detections do not try the skin again."""
    import warnings

    from taichi_hair.contact.pipeline import ContactPipeline

    model, _ = _random_groom(7)
    st = model.state()
    pipes = [ContactPipeline(model, ContactConfig(margin=2e-4, pairs_per_edge=0.5, pair_skin=k)) for k in (5e-3, 0.0)]
    for p in pipes:
        p.colliders.begin_step(model.control())
    assert pipes[0].pairs.capacity == 256
    with pytest.warns(UserWarning, match="pair_skin = 0.005 m: the pairs within reach \\+ skin do not fit"):
        pipes[0].detect(st, 1.0, (0, -9.81, 0), False)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        pipes[0].detect(st, 1.0, (0, -9.81, 0), False)
    assert pipes[0].pair_skin_searched == -1
    pipes[1].detect(st, 1.0, (0, -9.81, 0), False)
    for a, b in zip((pipes[0].grid.edge_candidate_count, pipes[0].grid.edge_candidate),
                    (pipes[1].grid.edge_candidate_count, pipes[1].grid.edge_candidate)):
        assert np.array_equal(a.to_numpy(), b.to_numpy())
    assert pipes[1].grid.edge_candidate_count.to_numpy().sum() > 100


def _detected_pairs(pipe, st, dt):
    total = pipe.detect(st, dt, (0, -9.81, 0), True)
    vtx = pipe.con.contact_vertex.to_numpy()[:total]
    return {(min(v[0], v[2]), max(v[0], v[2])) for v in vtx if v[2] >= 0}


def test_a_rigid_motion_of_the_whole_groom_adds_no_hair_hair_reach():
    """``ContactConfig.rigid_reach``: a rigid motion changes no distance (d/dt |p_a - p_b| gets nothing from
    omega x (p_a - p_b)), so the groom of the brute-force test moving rigidly (v = v0 + omega x (x - c),
    |v0| = 2 m/s, |omega| = 300 rad/s: up to 4.5 m/s, 4.5 cm per 1/100 s step, 20x the 2 mm edges) gets exactly
    the hair-hair contacts it has at rest, from as many grid entries.  With the world velocities
    (``rigid_reach=False``) every edge box grows by its speed (capped at one longest edge, the fall term
    scaled down with it): more entries (4,853 against 4,605 measured: the growth is capped at one 2 mm edge),
    and another set of pairs."""
    from taichi_hair.contact.pipeline import ContactPipeline

    model, _ = _random_groom(7)
    st = model.state()

    def detect_both():
        pairs, entries, omega = {}, {}, None
        for rigid in (True, False):
            pipe = ContactPipeline(model, ContactConfig(margin=2e-4, rigid_reach=rigid))
            pipe.colliders.begin_step(model.control())
            pairs[rigid] = _detected_pairs(pipe, st, 1e-2)
            entries[rigid] = int(pipe.boxes.edge_entry_start[model.vertex_count])
            omega = pipe.reach_frame[1] if rigid else omega
        return pairs, entries, omega

    rest, rest_entries, _ = detect_both()
    assert rest[True] == rest[False] and rest_entries[True] == rest_entries[False]  # at rest they agree
    x = st.positions().astype(np.float64)
    omega = np.array([100.0, -200.0, 200.0])
    v = np.array([1.0, 1.5, -0.9]) + np.cross(omega, x - x.mean(0) + 0.003)
    st.vertex_velocity.from_numpy(v.astype(np.float32))
    found, entries, w = detect_both()
    assert np.allclose(w, omega, rtol=1e-4), w   # the fit recovers the motion (f32 sums)
    assert found[True] == rest[True] and entries[True] == rest_entries[True]
    assert entries[False] > entries[True] and found[False] != rest[True], (entries, len(found[False]))


def test_detection_with_relative_velocities_matches_brute_force():
    """Random velocities plus a fast rotation: the hash grid + DOP + top-K with ``rigid_reach`` finds exactly
    the brute-force set of pairs whose distance is below r_a + r_b + margin + sweep (|v'_a - v'_b| + s'_a +
    s'_b) + fall, v' the velocities less the fitted rigid field (``pipe.reach_frame``), the edges' means and
    half-differences, sweep = dt, fall = |g| dt^2: the boxes grown by |v'_e| + s'_e miss no such pair."""
    from taichi_hair.contact.pipeline import ContactPipeline

    model, mat = _random_groom(11)
    st = model.state()
    x = st.positions().astype(np.float64)
    rng = np.random.default_rng(3)
    v = rng.normal(scale=0.05, size=x.shape) + np.cross([0.0, 40.0, 0.0], x - x.mean(0))
    st.vertex_velocity.from_numpy(v.astype(np.float32))
    dt, K = 2e-3, 6
    cfg = ContactConfig(margin=2e-4, max_contacts_per_edge=K, rigid_reach=True)
    pipe = ContactPipeline(model, cfg)
    pipe.colliders.begin_step(model.control())
    found = _detected_pairs(pipe, st, dt)
    v0, w, c = pipe.reach_frame
    assert np.linalg.norm(w) > 30   # the fit took the rotation out
    vr = st.vertex_velocity.to_numpy().astype(np.float64)
    vr = vr - v0 - np.cross(w, x - c)
    edges = [i for i in range(model.vertex_count) if model.host["edge_rest_length"][i] > 0]
    strand_of = model.host["vertex_strand"]
    mean = {a: 0.5 * (vr[a] + vr[a + 1]) for a in edges}
    spread = {a: 0.5 * np.linalg.norm(vr[a + 1] - vr[a]) for a in edges}
    speed = max(np.linalg.norm(mean[a]) + spread[a] for a in edges)
    longest = max(np.linalg.norm(x[a + 1] - x[a]) for a in edges)
    assert 2 * dt * speed + 9.81 * dt * dt < 0.9 * longest   # the reach's cap at one edge is not reached

    def reach(a, b):
        return (2 * mat.radius + cfg.margin + dt * (np.linalg.norm(mean[a] - mean[b]) + spread[a] + spread[b])
                + 9.81 * dt * dt)

    expected, _ = _brute_force_contacts(x, strand_of, edges, reach, K)
    assert found == expected
    assert len(found) > 100


# --------------------------------------------------------------------------- solver scenes
def _solver(model, colliders=None, iterations=10, **contact):
    cfg = SolverADMMConfig(iterations=iterations, contacts=ContactConfig(**contact))
    return SolverADMM(model, cfg, colliders=colliders)


def test_rod_resting_on_a_plane_stays_there():
    b = GroomBuilder()
    b.add_strand(line((0, R, 0), (0.03, R, 0), 13), HAIR, root="free")
    model = b.finalize()
    st, ctl = model.state(), model.control()
    x0 = st.positions().astype(np.float64)
    solver = _solver(model, [PlaneCollider(friction=0.3)])
    for _ in range(60):
        solver.step(st, ctl, 1 / 240)
    x = st.positions().astype(np.float64)
    assert np.abs(x[:, 1] - R).max() < 0.05 * R
    assert np.abs(x[:, [0, 2]] - x0[:, [0, 2]]).max() < 1e-6
    assert solver.contact_stats["contacts"] == 13
    assert solver.contact_stats["sticking"] == 13


@pytest.mark.parametrize("weight_time", ["paper", "step", "hair-step"])
def test_collision_weights_follow_the_chosen_time_scale(weight_time):
    # Closed form (Sec. 4.5; ContactConfig.weight_time): 1/W_z = dt~^2 / m_i for a vertex in contact, with
    # dt~ = min(dt, sqrt(L~/|g|), 2 L~^2/R sqrt(rho/E_b)) ("paper") or min(dt, sqrt(L~/|g|)) ("step", dynamic
    # mode), the sqrt term dropped without gravity; "hair-step" (the default) takes the second on a vertex
    # whose contacts are all hair-hair, the first on a vertex with a body contact.  Rod A (2.5 mm edges) lies
    # on a plane, rod B crosses on top of it, touching A only; dt = 1/240 s.  The bending time (1.6e-4 s) is
    # below dt, so the two differ by (dt / t_b)^2 ~ 160.  Tolerance 1e-5 relative (float32 fields).
    b = GroomBuilder()
    b.add_strand(line((0, R, 0), (0.03, R, 0), 13), HAIR, root="free")
    b.add_strand(line((0.015, 3 * R, -0.015), (0.015, 3 * R, 0.015), 13), HAIR, root="free")
    model = b.finalize()
    st, ctl = model.state(), model.control()
    ctl.gravity = (0.0, 0.0, 0.0)  # no fall within the step to reach for: B (2R above the plane) touches A only
    dt = 1 / 240
    solver = _solver(model, [PlaneCollider(friction=0.3)], weight_time=weight_time, margin=2e-5)
    solver.step(st, ctl, dt)
    inv_w = solver.contacts.con.vertex_contact_inv_weight.to_numpy().astype(np.float64)
    m = model.host["vertex_mass"].astype(np.float64)
    L = 0.0025
    t_bend = 2 * L**2 / HAIR.radius * math.sqrt(HAIR.density / HAIR.youngs_modulus_bend)
    assert t_bend < dt / 10  # the two choices do differ here
    t_paper = min(dt, t_bend)  # without gravity the sqrt(L~/|g|) term drops out
    t_step = dt
    t_body = t_step if weight_time == "step" else t_paper
    t_hair = t_paper if weight_time == "paper" else t_step
    np.testing.assert_allclose(inv_w[:13], t_body**2 / m[:13], rtol=1e-5)  # rod A: every vertex on the plane
    touching = inv_w[13:] > 0
    assert 2 <= touching.sum() <= 4  # rod B: the vertices of the edges that cross A
    np.testing.assert_allclose(inv_w[13:][touching], t_hair**2 / m[13:][touching], rtol=1e-5)


def _incline_runs(angles_deg, mu, steps=48, dt=1 / 240, plane_deg=30.0):
    """A free rod (5 cm, 1 cm edges) lying along the slope of an inclined plane (through the origin), for each
    slope angle of ``angles_deg``: (distance slid down the slope, largest distance off the plane, the
    vertices' contact states after the last step: 1 sticking, 2 sliding).

    One plane (inclined by ``plane_deg``), one Model and one solver for every angle: the slope angle is the
    angle between gravity and the plane's normal, so each angle is the usual set-up (gravity straight down,
    plane inclined by the angle) turned rigidly about z, with gravity tilted by angle - plane_deg instead.
    The solver is set back to the start between angles (``State.load`` + ``SolverADMM.restore``), so its
    contact kernels compile once instead of once per angle.

    1 cm edges keep W_z = m / dt~^2 within a few times m / dt^2 (dt~ of Sec. 4.5 shrinks with the edge
    length squared); with 2 mm edges W_z is ~1700 m/dt^2 and 20 ADMM iterations recover only ~1 % of
    the sliding motion (measured), which is the paper's weight choice, not a bug in the friction law.
    """
    p = math.radians(plane_deg)
    down = np.array([math.cos(p), -math.sin(p), 0.0])
    normal = np.array([math.sin(p), math.cos(p), 0.0])
    b = GroomBuilder()
    pts = line(-0.025 * down, 0.025 * down, 6) + R * normal
    b.add_strand(pts, HAIR, root="free")
    model = b.finalize()
    st, ctl = model.state(), model.control()
    solver = _solver(model, [PlaneCollider(normal=normal, friction=mu)], iterations=20)
    start, ck = st.to_numpy(), solver.checkpoint()
    c0 = st.positions().astype(np.float64).mean(0)
    out = []
    for angle in angles_deg:
        st.load(start)
        solver.restore(ck)
        tilt = math.radians(angle) - p
        ctl.gravity = (9.81 * math.sin(tilt), -9.81 * math.cos(tilt), 0.0)
        for _ in range(steps):
            solver.step(st, ctl, dt)
        x = st.positions().astype(np.float64)
        out.append((float((x.mean(0) - c0) @ down), float(np.abs((x - R * normal) @ normal).max()),
                    solver.vertex_contact_state()))
    return out


def test_a_strand_through_a_spheres_centre_is_pushed_out_without_nan():
    """A hanging strand (1 cm edges) whose vertex 5 sits exactly at the centre of a 2 cm sphere: the
    projection pushes its inner vertices out and flips edges in the first step, which made the frames'
    parallel transport 0 / 0 = NaN (a divergence at step 1).  Now: finite at every step, and after 2 s no
    vertex is inside (by more than 0.1 mm) and every edge keeps its length within 1 % (measured 0.39 %: the
    folded strand rests on itself, hair-hair contacts on)."""
    b = GroomBuilder()
    pts = line((0, 0, 0), (0, -0.09, 0), 10)
    b.add_strand(pts, HAIR, root="clamped")
    model = b.finalize()
    st, ctl = model.state(), model.control()
    c = np.asarray(pts[5], np.float64)
    solver = _solver(model, [SphereCollider(center=tuple(c), radius=0.02, friction=0.2)])
    for _ in range(192):
        solver.step(st, ctl, 1 / 96)  # raises SimulationDivergedError on a non-finite state
    x = st.positions().astype(np.float64)
    assert (np.linalg.norm(x - c, axis=1) < 0.02 - 1e-4).sum() == 0
    e = np.linalg.norm(np.diff(x, axis=0), axis=1)
    assert np.abs(e / 0.01 - 1).max() < 1e-2


@pytest.mark.parametrize("late", [True, False], ids=["late_contacts", "without"])
def test_a_vertex_pushed_into_a_body_within_the_step_gets_a_contact_and_is_pushed_out(late):
    """ContactConfig.late_body_contacts: the step's detection finds no body contact for a strand 1 cm above a
    sphere; then (as the hair of a dense pile does within a substep) the strand is pushed down until vertex 5
    is 0.5 mm inside it.  With the late detection it gets a contact and the end-of-step correction pushes it
    out (to within 0.1 mm of the surface); without, nothing acts on it and it stays 0.5 mm inside (what the
    4,000-strand hairball showed, BENCHMARKS.md)."""
    b = GroomBuilder()
    b.add_strand(line((0, 0, 0), (0.1, 0, 0), 11), HAIR, root="free")
    model = b.finalize()
    st = model.state()
    sphere = SphereCollider(center=(0.05, -0.03, 0.0), radius=0.02, friction=0.0)  # its top at y = -1 cm
    solver = _solver(model, [sphere], late_body_contacts=late)
    pipe = solver.contacts
    pipe.detect(st, 1 / 96, (0.0, 0.0, 0.0), True)
    assert pipe.contact_count == 0
    x0 = ti.Vector.field(3, float, model.vertex_count)
    x0.copy_from(st.vertex_position)
    x = st.positions()
    x[:, 1] -= 0.0105  # the whole strand moved down (its lengths kept): vertex 5 is 0.5 mm inside, 4 and 6 outside
    st.vertex_position.from_numpy(x)
    if late:
        assert pipe.detect_late_body(st.vertex_position) == 1 and pipe.contact_count == 1
    pipe.correct(st.vertex_position, x0, 10)
    depth = 0.02 - np.linalg.norm(st.positions()[5].astype(np.float64) - [0.05, -0.03, 0.0])  # > 0: inside
    if late:
        assert depth < 1e-4, depth
    else:
        assert depth > 4e-4, depth


def test_a_vertex_the_correction_pushes_into_a_body_gets_a_contact_and_stays_out():
    """The end-of-step correction's own pushes can carry a vertex without a body contact into a body: the
    hair of a dense pile pressing it down (the 16,000-strand hairball, BENCHMARKS.md: vertices 0.3-0.9 mm
    outside the ball before the correction, inside after it, no body contact).  Here thin rod B (r = 50 um)
    lies along z 0.2 mm above a floor's reach (no contact), thick rod A (r = 150 um, 9x the mass per length)
    crosses it above; the step's iterations leave A's middle 3 mm below B's axis (crossed, and inside the floor:
    A gets its late contacts).  Uncrossing pushes B down.  Claim: B gets its floor contact during the
    correction and ends no deeper into the floor than a quarter radius (the correction's tolerance); measured
    0.18 r.  Without it (the code before) B's axis ended 268 um below the floor, 6.4 r past touching."""
    r, ra = 5e-5, 1.5e-4
    yb = 2.5e-4
    ya = yb + r + ra + 2e-5
    b = GroomBuilder()
    b.add_strand(line((-0.01, ya, 0.0003), (0.01, ya, 0.0003), 11), RodMaterial(radius=ra), root="free")  # A
    b.add_strand(line((0.0003, yb, -0.01), (0.0003, yb, 0.01), 11), RodMaterial(radius=r), root="free")   # B
    model = b.finalize()
    st = model.state()
    cfg = ContactConfig(friction=0.2, velocity_margin=0.0)
    con = SolverADMM(model, SolverADMMConfig(contacts=cfg), colliders=[PlaneCollider(friction=0.0)]).contacts
    con.detect(st, 1 / 96, (0.0, 0.0, 0.0), True)
    assert con.contact_count == 1   # the pair; B is beyond the floor's reach r + margin
    x0 = ti.Vector.field(3, float, model.vertex_count)
    x0.copy_from(st.vertex_position)
    x1 = st.positions().astype(np.float64)
    x1[:11, 1] -= (ya - yb + 0.003) * np.exp(-(x1[:11, 0] / 0.003) ** 2)   # A's middle 3 mm below B's axis
    st.vertex_position.from_numpy(x1.astype(np.float32))
    assert con.detect_late_body(st.vertex_position) > 0   # A's vertices inside the floor (as step() does)
    con.correct(st.vertex_position, x0, cfg.correction_iterations)
    xc = st.positions().astype(np.float64)
    assert xc[11:, 1].min() > 0.75 * r, xc[11:, 1].min()
    assert con.statistics(st.vertex_position)["crossed_pairs"] == 0


@pytest.mark.parametrize("lift", [0.0, 0.001], ids=["still", "moving_1mm"])
def test_a_body_moving_into_hair_within_the_step_gets_its_frictional_contact_at_detection(lift):
    """A body contact's reach adds how far the body carries its nearest point within the step.  A strand
    rests 0.5 mm (+ r) above a sphere's top; quasistatic detection (no velocity reach): the still sphere gives
    no contact (0.5 mm + r > r + margin), the sphere lifted 1 mm in the step gives the closest vertex a
    contact with the sphere's friction (before, none: the comb of tests/test_grooming.py met hair without a
    contact and lost its drag)."""
    b = GroomBuilder()
    b.add_strand(line((-0.01, 0.0205 + R, 0), (0.01, 0.0205 + R, 0), 11), HAIR, root="free")
    model = b.finalize()
    st, ctl = model.state(), model.control()
    solver = _solver(model, [SphereCollider(center=(0.0, 0.0, 0.0), radius=0.02, friction=0.7, body=0)],
                     hair_hair=False)
    pipe = solver.contacts
    pipe.colliders.begin_step(ctl)                             # the first step: no motion
    ctl.set_body_transform(0, np.eye(3), (0.0, lift, 0.0))
    pipe.colliders.begin_step(ctl)                             # this step: lifted by `lift`
    pipe.detect(st, 1 / 96, (0.0, 0.0, 0.0), False)
    if lift == 0.0:
        assert pipe.contact_count == 0
    else:
        assert pipe.contact_count >= 1
        fr = pipe.con.contact_friction.to_numpy()[:pipe.contact_count]
        assert np.allclose(fr, 0.7), fr
        assert 5 in pipe.con.contact_vertex.to_numpy()[:pipe.contact_count, 0]  # the vertex over the top


def test_incline_sticks_below_the_friction_angle_and_slides_with_coulomb_acceleration_above():
    mu = 0.4
    steps, dt = 48, 1 / 240
    (along, off, state), *sliding = _incline_runs((15.0, 30.0, 45.0), mu, steps, dt)
    assert abs(along) < 1e-6 and off < 0.05 * R  # tan 15 deg = 0.27 < 0.4: sticks
    assert state.tolist() == [1] * 6  # and every vertex reports sticking (what render --color contact draws)
    for angle, (along, off, state) in zip((30.0, 45.0), sliding):
        assert state.tolist() == [2] * 6, (angle, state)  # tan > mu: slides with a = g (sin - mu cos)
        a = 9.81 * (math.sin(math.radians(angle)) - mu * math.cos(math.radians(angle)))
        # Backward Euler from rest: s_n = a dt^2 n (n + 1) / 2.
        expected = a * dt * dt * steps * (steps + 1) / 2
        assert abs(along / expected - 1) < 0.02, (angle, along, expected)
        assert off < 0.05 * R


def test_crossing_rods_pressed_together_do_not_pass_through():
    """Rod B falls across clamped rod A near A's root and is pressed on it by a strong gravity: it stays above A."""
    b = GroomBuilder()
    b.add_strand(line((0, 0, 0), (0.01, 0, 0), 9), HAIR)                        # A: short clamped cantilever
    b.add_strand(line((0.005, 0.0003, -0.004), (0.005, 0.0003, 0.004), 9), HAIR, root="free")  # B across it
    model = b.finalize()
    st, ctl = model.state(), model.control()
    ctl.gravity = (0.0, -50.0, 0.0)
    solver = _solver(model, iterations=20, friction=0.5)
    for _ in range(40):
        solver.step(st, ctl, 1 / 480)
    x = st.positions().astype(np.float64)
    a, bb = x[:9], x[9:]
    k = int(np.argmin(np.abs(bb[:, 2])))           # B's vertex over A
    j = int(np.argmin(np.abs(a[:, 0] - bb[k, 0])))  # A's vertex under it
    assert bb[k, 1] > a[j, 1] + R, (bb[k], a[j])
    assert bb[k, 1] < 0.0002                       # it did fall onto A
    assert solver.contact_stats["contacts"] > 0
    assert solver.contact_stats["max_penetration_m"] < 0.2 * R


@pytest.mark.parametrize("kind", ["sphere", "capsule", "mesh"])
def test_rod_dropped_on_a_body_does_not_penetrate(kind):
    import trimesh

    radius = 0.01
    if kind == "sphere":
        col = SphereCollider(radius=radius, friction=0.3)
    elif kind == "capsule":
        col = CapsuleCollider(p0=(0, 0, -0.02), p1=(0, 0, 0.02), radius=radius, friction=0.3)
    else:
        col = MeshCollider(trimesh.creation.icosphere(4, radius), resolution=48, friction=0.3)
    b = GroomBuilder()
    b.add_strand(line((-0.008, radius + 0.002, 0.001), (0.008, radius + 0.002, 0.001), 11), HAIR, root="free")
    model = b.finalize()
    st, ctl = model.state(), model.control()
    solver = _solver(model, [col], iterations=15)
    cs = solver.contacts.colliders
    # The positions after every step, measured in one call at the end: the body does not move, so the
    # distance at the end's transforms is each step's distance (each distance_numpy call allocates
    # fields and so compiles its kernel again: one call per step cost 50 compilations).
    frames = []
    for _ in range(50):
        solver.step(st, ctl, 1 / 240)
        frames.append(st.positions())
    assert np.array_equal(ctl.body_rotation.to_numpy()[0], np.eye(3))
    assert not ctl.body_translation.to_numpy()[0].any()
    worst = float(R - cs.distance_numpy(np.concatenate(frames), ctl, 0).min())
    # Fell and touched (the middle rests on top), never more than a tenth of a radius inside (+ SDF error).
    tol = 0.1 * R + (1e-4 * radius if kind != "mesh" else 2e-5)
    assert worst < tol, worst
    assert st.positions()[:, 1].min() < radius + 0.002


def test_mesh_sdf_matches_the_analytic_distance_and_orientation():
    import trimesh

    box = trimesh.creation.box(extents=(0.04, 0.02, 0.01))
    box.apply_translation((0.01, -0.005, 0.002))
    col = MeshCollider(box, resolution=64)
    cs = ColliderSet([col], 1)
    rng = np.random.default_rng(0)
    p = rng.uniform(-0.03, 0.03, (500, 3)) * [1, 0.6, 0.4] + [0.01, -0.005, 0.002]
    q = np.abs(p - [0.01, -0.005, 0.002]) - [0.02, 0.01, 0.005]
    exact = np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(1), 0)
    d = cs.distance_numpy(p.astype(np.float32), None, 0)
    near = np.abs(exact) < 0.004
    # Trilinear interpolation of a box SDF: exact on faces, rounded near edges by about a voxel.
    assert np.median(np.abs(d - exact)[near]) < 0.2 * col.spacing
    assert np.all(np.sign(d[np.abs(exact) > 2 * col.spacing]) == np.sign(exact[np.abs(exact) > 2 * col.spacing]))


def test_non_watertight_mesh_warns_and_is_signed_by_its_winding_number():
    """A half sphere (an open bowl) is not watertight: it is signed by its generalized winding number
    (issue 12 item 4; the flat-sheet fallback and holed meshes are tested in test_quality.py), so a point
    far outside is outside and one just under the bowl's surface, inside the sphere it came from, is inside."""
    import trimesh

    sphere = trimesh.creation.icosphere(3, 0.01)
    open_mesh = trimesh.Trimesh(sphere.vertices, sphere.faces[: len(sphere.faces) // 2], process=False)
    with pytest.warns(UserWarning, match="not watertight"):
        col = MeshCollider(open_mesh, resolution=32, thickness=5e-4)
    assert not col.watertight
    assert col.sign_method == "winding"
    far = np.array([[0.0, 0.0, 0.03], [0.03, 0.0, 0.0]])
    assert np.all(col.sdf_numpy(far) > 0)
    tri = open_mesh.vertices[open_mesh.faces].mean(axis=1)
    under = 0.0095 * tri.mean(axis=0) / np.linalg.norm(tri.mean(axis=0))   # 0.5 mm under the bowl's middle
    assert col.sdf_numpy(under[None])[0] < 0


def test_bad_collider_parameters_name_the_field():
    with pytest.raises(ValueError, match="SphereCollider.radius"):
        SphereCollider(radius=-1.0)
    with pytest.raises(ValueError, match="PlaneCollider.normal"):
        PlaneCollider(normal=(0, 0, 0))
    with pytest.raises(ValueError, match="friction"):
        CapsuleCollider(friction=float("nan"))
    with pytest.raises(ValueError, match="ContactConfig.friction"):
        ContactConfig(friction=-0.1)
    for bad in (0.0, -1.0, float("nan"), float("inf"), 1e6):
        with pytest.raises(ValueError, match="ContactConfig.pairs_per_edge"):
            ContactConfig(pairs_per_edge=bad)
    for bad in (-1e-4, float("nan"), float("inf"), "1"):
        with pytest.raises(ValueError, match="ContactConfig.pair_skin"):
            ContactConfig(pair_skin=bad)
    for bad in (-0.1, 0.5, float("nan"), "0.25"):
        with pytest.raises(ValueError, match="ContactConfig.redetect_share"):
            ContactConfig(redetect_share=bad)
    with pytest.raises(ValueError, match="body 3 does not exist"):
        ColliderSet([SphereCollider(body=3)], 1)


def _two_layer_model():
    rng = np.random.default_rng(11)
    b = GroomBuilder()
    for s in range(12):
        z = 0.002 * (s - 6) + rng.uniform(-2e-4, 2e-4)
        y = 0.0004 * (s % 2)
        b.add_strand(line((0, y, z), (0.02, y - 0.002, z + 0.001 * (s % 3 - 1)), 9), HAIR)
    return b.finalize()


def _run_layers(capacity_per_vertex=2.0, steps=12, reruns=0):
    """Positions after ``steps`` steps of the two-layer scene, and the solver; with ``reruns`` the same
    solver is set back to the start (``State.load`` + ``SolverADMM.restore``, everything a step depends on)
    and run again, each rerun's positions returned too (one solver: its kernels compile once)."""
    model = _two_layer_model()
    st, ctl = model.state(), model.control()
    solver = _solver(model, [SphereCollider(center=(0.015, -0.012, 0), radius=0.01)],
                     capacity_per_vertex=capacity_per_vertex, margin=5e-4)
    start, ck = st.to_numpy(), solver.checkpoint()
    out = []
    for k in range(reruns + 1):
        if k:
            st.load(start)
            solver.restore(ck)
        for _ in range(steps):
            solver.step(st, ctl, 1 / 120)
        out.append(st.positions())
    return (out if reruns else out[0]), solver


def test_contacts_are_bitwise_deterministic_and_overflow_grows_without_dropping():
    """Bitwise: the same solver, set back to the start, repeats its run bit for bit (two runs of a
    fresh solver each, as before, cost one more compilation of the contact kernels and check no more:
    the rerun starts from the restored state and warm-start buffers, and the contacts are detected
    afresh every step).  Overflow: a buffer far too small grows and keeps every contact."""
    (x1, x2), s1 = _run_layers(reruns=1)
    assert np.array_equal(x1, x2)
    assert s1.contact_stats["contacts"] > 0
    with pytest.warns(UserWarning, match="contact buffer overflow"):
        x3, s3 = _run_layers(capacity_per_vertex=0.01)
    assert s3.contacts.grow_events >= 1
    assert np.array_equal(x1, x3)  # same contacts, same order: the same bits


def test_mass_splitting_by_batch_and_by_vertex_reach_the_same_solution():
    """Four rods piled crosswise on a plane fall for a few steps with many iterations: the Delassus splitting
    only changes how fast the projection converges, not where (the paper's D_hat splits by all contacts of
    a vertex, the default by the contacts of the same batch).  200 iterations: with the default collision
    weights (``weight_time = "hair-step"``: the upper rods touch hair only and get the lighter inertia
    weight) the pile converges more slowly than with the paper's; measured largest difference between the
    two splittings 4.8 um at 100 iterations, 1.6 um at 200 ("paper": 0.004 / 0.010 um)."""
    mat = RodMaterial(radius=2e-4)
    results = {}
    for split in ("batch", "vertex"):
        b = GroomBuilder()
        for k in range(4):
            y = mat.radius * (1 + 2 * k) + 1e-5
            if k % 2 == 0:
                b.add_strand(line((-0.01, y, 0.001 * k), (0.01, y, 0.001 * k), 11), mat, root="free")
            else:
                b.add_strand(line((0.001 * k, y, -0.01), (0.001 * k, y, 0.01), 11), mat, root="free")
        model = b.finalize()
        st, ctl = model.state(), model.control()
        cfg = SolverADMMConfig(iterations=200, contacts=ContactConfig(friction=0.3, mass_splitting=split,
                                                                      projection_iterations=4))
        solver = SolverADMM(model, cfg, colliders=[PlaneCollider(friction=0.3)])
        for _ in range(5):
            solver.step(st, ctl, 1 / 240)
        results[split] = st.positions().astype(np.float64)
        assert solver.contact_stats["contacts"] >= 14   # 11 on the plane, the three crossings
        assert solver.contact_stats["max_penetration_m"] < 0.05 * mat.radius
    np.testing.assert_allclose(results["batch"], results["vertex"], rtol=0, atol=0.02 * mat.radius)


def test_contact_next_to_clamped_vertices_is_not_amplified():
    """Two clamped strands cross right next to their clamped second vertices (weights ~0.98 on the
    clamped vertices, ~0.02 on the free ones). Moving the free vertices by Delta u / h would be a
    fiftyfold lever; counting the clamped vertices in D_hat keeps the motion to the size of the overlap."""
    mat = RodMaterial(radius=5e-5)
    b = GroomBuilder()
    b.add_strand(line((0, 0, 0), (0, 0.05, 0), 6), mat)                       # A along +y, vertex 1 at y = 1 cm
    pts = np.array([[0.0004, 0.0, 0.0], [0.0004, 0.0101, 0.0], [-0.0196, 0.0103, 0.00003],
                    [-0.0396, 0.0105, 0.0], [-0.0596, 0.0107, 0.0]])
    b.add_strand(pts, mat)                                                    # B: its edge 1-2 grazes A at y ~ 1 cm
    model = b.finalize()
    st, ctl = model.state(), model.control()
    ctl.gravity = (0.0, 0.0, 0.0)
    x0 = st.positions().astype(np.float64)
    cfg = SolverADMMConfig(iterations=20, mode="quasistatic", w0=1.0,
                           contacts=ContactConfig(friction=0.2, velocity_margin=0.0))
    solver = SolverADMM(model, cfg)
    for _ in range(5):
        solver.step(st, ctl, 1.0)
    assert solver.contact_stats["contacts"] >= 1
    moved = np.linalg.norm(st.positions().astype(np.float64) - x0, axis=1).max()
    assert moved < 2e-3, moved


def test_a_free_edge_pressed_into_a_clamped_root_edge_is_pushed_out_in_one_correction_sweep():
    """Rod B (free) lies across clamped rod A right at A's root (A's closest point at s = 0.05 of its root edge,
    both of whose vertices are clamped; h = 0.95, 0.05 there and -0.5, -0.5 on B), 60 um deeper than touching.
    Only B can move and it can resolve the contact alone, so D_hat is the paper's sum over B's free vertices
    (``narrow._delassus``: the lever bound max |h| / W = 0.5 / W equals it, so it does not act).  Claim:
    one correction sweep takes B out to within a quarter radius (12.5 um; measured 0.07 um).  The rule before
    counted A's clamped vertices in D_hat with the weight a free vertex would have there; A's 1 cm edges bend
    slowly, so that weight is light and D_hat ~80x the paper's: B moved 0.7 um per sweep, and the head turn's
    correction needed 100-200 sweeps (BENCHMARKS.md)."""
    mat = RodMaterial(radius=5e-5)
    r = mat.radius
    b = GroomBuilder()
    b.add_strand(line((0, 0, 0), (0, 0.04, 0), 5), mat)            # A along +y, root edge to y = 1 cm, clamped
    y = 0.0005
    b.add_strand(line((2 * r + 2e-5, y, -0.01), (2 * r + 2e-5, y, 0.01), 10), mat, root="free")  # B along z, 20 um off
    model = b.finalize()
    st = model.state()
    cfg = ContactConfig(friction=0.2, velocity_margin=0.0, correction_iterations=1, correction_max_iterations=1)
    con = SolverADMM(model, SolverADMMConfig(contacts=cfg)).contacts
    con.detect(st, 1 / 96, (0.0, 0.0, 0.0), False)
    assert con.contact_count == 1
    x1 = st.positions().astype(np.float64)
    x1[5:, 0] -= 8e-5                                                  # the step leaves B 60 um deep in A
    x = ti.Vector.field(3, float, model.vertex_count)
    x.from_numpy(x1.astype(np.float32))
    con.correct(x, st.vertex_position, 1)
    assert con.correction_sweeps_last == 1
    xc = x.to_numpy().astype(np.float64)
    d = min(segment_distance(xc[0], xc[1], xc[j], xc[j + 1]) for j in range(5, 14))
    assert d > 2 * r - 0.25 * r, d


def test_two_clamped_root_edges_that_overlap_get_no_contact_and_the_correction_stops_at_its_sweeps():
    """Two clamped strands whose root edges (vertices 0 and 1 fixed) cross 40 um apart, less than their radii's
    sum (100 um); the free parts are centimetres apart.  Nothing can separate the root edges, so they form no
    contact (a warning says so), the correction stops after its configured sweeps instead of sweeping to its cap
    every step, and (gravity off) nothing moves (below 1 um)."""
    mat = RodMaterial(radius=5e-5)
    b = GroomBuilder()
    b.add_strand(line((0, 0, 0), (0, 0.04, 0), 5), mat)                        # A along +y, root edge to y = 1 cm
    b.add_strand(line((-0.005, 0.005, 4e-5), (0.035, 0.005, 4e-5), 5), mat)    # B along +x, crosses A's root edge
    model = b.finalize()
    st, ctl = model.state(), model.control()
    ctl.gravity = (0.0, 0.0, 0.0)
    x0 = st.positions().astype(np.float64)
    cc = ContactConfig(friction=0.2)
    # The overlap is reported once, naming the strands and the depth (100 - 40 = 60 um).
    with pytest.warns(UserWarning, match=r"1 pair of clamped root edges overlap \(deepest: strands 0 and 1, 60 um"):
        solver = SolverADMM(model, SolverADMMConfig(iterations=10, contacts=cc))
    for _ in range(3):
        solver.step(st, ctl, 1 / 96)
        assert solver.contact_stats["contacts"] == 0, solver.contact_stats
        assert solver.contacts.correction_sweeps_last <= cc.correction_iterations, solver.contacts.correction_sweeps_last
    assert np.abs(st.positions().astype(np.float64) - x0).max() < 1e-6


@pytest.mark.parametrize("keep", [True, False])
def test_a_pair_authored_closer_than_two_radii_keeps_its_rest_distance_and_does_not_pass_through(keep):
    """Rod B lies across clamped rod A, its axis 40 um above A's at rest: closer than r_a + r_b = 100 um.
    With ``keep_rest_overlaps`` the pair's contact thickness is its rest distance, 40 um: gravity off, nothing
    moves (< 1 um); pressed onto A by 50 m/s^2 B rests 40 um above A's axis (within 0.2 r = 10 um), it neither
    sinks nor passes through.  Without it (the paper's r_a + r_b) the first steps push B out to 100 um."""
    mat = RodMaterial(radius=5e-5)
    b = GroomBuilder()
    b.add_strand(line((0, 0, 0), (0.01, 0, 0), 9), mat)                            # A: clamped along +x
    b.add_strand(line((0.005, 4e-5, -0.004), (0.005, 4e-5, 0.004), 9), mat, root="free")  # B across, 40 um up
    model = b.finalize()
    st, ctl = model.state(), model.control()
    ctl.gravity = (0.0, 0.0, 0.0)
    x0 = st.positions().astype(np.float64)
    solver = _solver(model, iterations=20, friction=0.5, keep_rest_overlaps=keep)

    def separation():
        x = st.positions().astype(np.float64)
        # The closest of A's two edges under B (vertices 3-5) and B's two edges over A (vertices 12-14).
        return min(segment_distance(x[i], x[i + 1], x[j], x[j + 1]) for i in (3, 4) for j in (12, 13))

    solver.step(st, ctl, 1 / 480)
    assert solver.contact_stats["contacts"] > 0
    if keep:
        for _ in range(5):
            solver.step(st, ctl, 1 / 480)
        assert np.abs(st.positions().astype(np.float64) - x0).max() < 1e-6
        assert solver.contact_stats["rest_overlap_contacts"] > 0
    else:  # pushed out in the first step (and B flies off with the push's velocity)
        assert separation() > 2 * mat.radius - 0.2 * mat.radius, separation()
    ctl.gravity = (0.0, -50.0, 0.0)
    for _ in range(40):
        solver.step(st, ctl, 1 / 480)
    x = st.positions().astype(np.float64)
    k = int(np.argmin(np.abs(x[9:, 2]))) + 9      # B's vertex over A
    assert x[k, 1] > x[4, 1], (x[k], x[4])      # still above A: not passed through
    expected = 4e-5 if keep else 2 * mat.radius
    assert abs(separation() - expected) < 0.2 * mat.radius, (separation(), expected)


def test_z_step_contacts_one_by_one_and_in_the_papers_batches_reach_the_same_projection():
    """The z-step (Sec. 4.5, problem 5) without friction is a strictly convex QP, min 1/2 |z - (x - lambda_z)|^2_{W_z}
    subject to every linearised contact gap >= 0, so its solution is unique: the sweeps in the paper's 8 Jacobi
    batches (``projection_contact_order="batches"``: the GPU's, and the CPU's in the dynamic mode) and one contact
    after the other (the CPU's in the quasistatic mode, pure Gauss-Seidel) converge to the same z.  Twelve rods across
    one edge of a thirteenth, their middles pushed 0.3 mm through it (135 contact vertices, the z-step moves them up to
    0.25 mm): after one sweep the two orders differ (measured 99 um: the option changes the sweep), after 400 they agree
    to 1e-7 m (f32; measured 1.2e-10)."""
    mat = RodMaterial(radius=5e-5)
    b = GroomBuilder()
    b.add_strand(line((-0.01, 0, 0.0), (0.01, 0, 0.0), 11), mat, root="free")
    for k in range(12):
        x0 = 0.0001 + 0.00015 * k  # (all across A's edge [0, 2 mm]: their contacts share its two vertices)
        b.add_strand(line((x0, 1.2e-4, -0.01), (x0, 1.2e-4, 0.01), 11), mat, root="free")
    model = b.finalize()
    st = model.state()
    x1 = st.positions().astype(np.float64)
    z = x1[11:, 2]
    x1[11:, 1] -= 3e-4 * np.exp(-(z / 0.003) ** 2)
    out = {}
    for order in ("batches", "sequential"):
        cfg = ContactConfig(friction=0.0, velocity_margin=0.0, projection_contact_order=order)
        solver = SolverADMM(model, SolverADMMConfig(contacts=cfg))
        con = solver.contacts
        con.detect(st, 1 / 96, (0.0, 0.0, 0.0), False)
        assert con.contact_count > 8  # (more than one in a batch)
        x = ti.Vector.field(3, float, model.vertex_count)
        x.from_numpy(x1.astype(np.float32))
        active = con.con.active_vertex.to_numpy()[:con.con.active_vertex_count[None]]
        for sweeps in (1, 400):
            con.clear(solver.buf)
            con.con.vertex_contact_dual.fill(0.0)
            con.con.contact_accumulated.fill(0.0)
            con.project(x, solver.buf, sweeps)
            out[order, sweeps] = con.con.vertex_z.to_numpy().astype(np.float64)[active]
    first = np.abs(out["batches", 1] - out["sequential", 1]).max()
    diff = np.abs(out["batches", 400] - out["sequential", 400]).max()
    assert first > 1e-6 and diff < 1e-7, (first, diff)


@pytest.mark.parametrize("order", ["batches", "sequential"])
def test_the_collision_dual_equals_the_sum_of_the_contact_pushes_so_each_z_step_starts_at_x(order):
    """lambda_z = W_z^-1 H^T D_hat^-1 r~ after every projection of a step (``projection.begin_projection``: both start
    at zero at the detection, every contact update adds its push to z and to the sum alike, and the dual update
    lambda <- lambda + z - x makes lambda the new sum), so the z-step's warm start x - lambda_z + W_z^-1 H^T D_hat^-1 r~
    is x itself.  The twelve rods pushed 0.3 mm through a thirteenth (above), friction 0.2, three projections of two
    sweeps each, x moved by up to 20 um between them (as a global step would): the two agree to 1e-5 of the largest
    push on every contact vertex (f32 rounding; measured 0.85-0.95 nm against pushes of 0.79-0.84 mm)."""
    mat = RodMaterial(radius=5e-5)
    b = GroomBuilder()
    b.add_strand(line((-0.01, 0, 0.0), (0.01, 0, 0.0), 11), mat, root="free")
    for k in range(12):
        x0 = 0.0001 + 0.00015 * k
        b.add_strand(line((x0, 1.2e-4, -0.01), (x0, 1.2e-4, 0.01), 11), mat, root="free")
    model = b.finalize()
    st = model.state()
    x1 = st.positions().astype(np.float64)
    x1[11:, 1] -= 3e-4 * np.exp(-(x1[11:, 2] / 0.003) ** 2)
    cfg = ContactConfig(friction=0.2, velocity_margin=0.0, projection_contact_order=order)
    solver = SolverADMM(model, SolverADMMConfig(contacts=cfg))
    con = solver.contacts
    con.detect(st, 1 / 96, (0.0, 0.0, 0.0), False)
    c = con.con
    x = ti.Vector.field(3, float, model.vertex_count)
    rng = np.random.default_rng(0)
    active = c.active_vertex.to_numpy()[:c.active_vertex_count[None]]
    for _ in range(3):
        x.from_numpy(x1.astype(np.float32))
        con.project(x, solver.buf, 2)
        x1 = x1 + rng.uniform(-2e-5, 2e-5, x1.shape)
    iw = c.vertex_contact_inv_weight.to_numpy().astype(np.float64)
    nc = con.contact_count
    vtx = c.contact_vertex.to_numpy()[:nc]
    h = c.contact_weight.to_numpy().astype(np.float64)[:nc]
    dh = c.contact_delassus.to_numpy().astype(np.float64)[:nc]
    acc = c.contact_accumulated.to_numpy().astype(np.float64)[:nc]
    lam = c.vertex_contact_dual.to_numpy().astype(np.float64)
    push = np.zeros_like(lam)  # sum over contacts c of i: W_z,i^-1 h_ci / D_hat_c r~_c
    for k in range(4):
        on = (vtx[:, k] >= 0) & (dh > 0)
        np.add.at(push, vtx[on, k], (iw[vtx[on, k]] * h[on, k] / dh[on])[:, None] * acc[on])
    largest = np.abs(push[active]).max()
    assert largest > 1e-5, largest
    assert np.abs(lam[active] - push[active]).max() < 1e-5 * largest, (np.abs(lam[active] - push[active]).max(), largest)


def test_the_slab_parallel_sweep_keeps_every_contact_touches_disjoint_vertices_and_reaches_the_same_projection(
        monkeypatch):
    """``contact.slabs``: 16 parallel clamped rods side by side (roots along x, 90 um apart: each overlaps its
    neighbours by 10 um) and a free rod across them all (strand 0, its root first along x: the slabs are runs of
    vertex indices), pushed 0.2 mm into them.  The slab groups (forced on here:
    the pipeline's threshold of 20,000 contacts set to 0) keep every contact of the detection (the same vertex
    tuples and weights, sorted), the groups of each parallel phase touch disjoint vertex sets, every phase has
    contacts, and the frictionless z-step (a strictly convex QP, unique solution) swept 400 times reaches the
    projection of the plain one-by-one order (the detection's order, unsorted) to 1e-7 m (f32; measured 1.5 nm),
    after one sweep it differs (another Gauss-Seidel order: 16 um measured); the slab groups on threads and in their
    order on one thread (``projection.SLAB_ORDER``) give the same bits.  532
    contacts: 223 in the slabs' own groups, 285 between neighbours, 24 in the rest.  With the cross rod last the
    slabs are not runs of vertex indices, and the pipeline does not use them; with the rods in reverse order as well
    they are runs again, descending, and it does."""
    from taichi_hair.contact import pipeline as pipeline_module
    from taichi_hair.contact.projection import SEQUENTIAL, SLAB_ORDER, SLABS
    from taichi_hair.contact.slabs import REST_GROUP
    from taichi_hair.fields import CONTACT_SLABS as S

    monkeypatch.setattr(pipeline_module, "_SERIAL_CONTACTS", 0)
    mat = RodMaterial(radius=5e-5)
    b = GroomBuilder()
    b.add_strand(line((-0.001, 1e-4, 0.0), (0.0024, 1e-4, 0.02), 11), mat, root="free")  # across, first along x
    for k in range(16):
        b.add_strand(line((9e-5 * k, 0.0, 0.0), (9e-5 * k, 0.0, 0.02), 11), mat)
    model = b.finalize()
    st = model.state()
    x1 = st.positions().astype(np.float64)
    x1[:11, 1] -= 2e-4
    out, keys = [], []
    for order, threads in (("sequential", 0), ("auto", 1 << 30), ("auto", 0)):
        # ("sequential" with the correction in batches: no slab groups, the detection's own order.)  The slab groups
        # in their order on one thread (``SLAB_ORDER``: Taichi's threads up to ``_SLAB_THREADS``), then on threads.
        monkeypatch.setattr(pipeline_module, "_SLAB_THREADS", threads)
        cfg = ContactConfig(friction=0.0, velocity_margin=0.0, projection_contact_order=order,
                            correction_contact_order="batches" if order == "sequential" else "auto")
        solver = SolverADMM(model, SolverADMMConfig(contacts=cfg))
        pl = solver.contacts
        pl.detect(st, 1 / 96, (0.0, 0.0, 0.0), False)
        assert pl.slabs_contiguous and pl._slabs == (order == "auto")
        assert pl._projection_order(False) == {"sequential": SEQUENTIAL, 1 << 30: SLAB_ORDER, 0: SLABS}[
            order if order == "sequential" else threads]
        c, nc = pl.con, pl.contact_count
        vtx = c.contact_vertex.to_numpy()[:nc]
        w = c.contact_weight.to_numpy()[:nc]
        if order == "auto" and not out[1:]:
            start = c.contact_group_start.to_numpy()
            slab = pl.vertex_slab.to_numpy()
            group = np.repeat(np.arange(2 * S), np.diff(start))
            group[start[REST_GROUP]:] = REST_GROUP
            phases = [range(S), range(S, REST_GROUP, 2), range(S + 1, REST_GROUP, 2)]
            for phase in phases:
                assert sum(start[g + 1] - start[g] for g in phase) > 0, (phase, start)
                seen = {}
                for g in phase:
                    for v in vtx[group == g].ravel():
                        if v >= 0:
                            assert seen.setdefault(int(v), g) == g, (v, g, seen[int(v)])
            assert start[-1] - start[REST_GROUP] > 0
            assert set(np.unique(slab[vtx[vtx >= 0]])) == set(range(S))
        keys.append(sorted(map(tuple, np.c_[vtx, np.round(w, 6)].tolist())))
        x = ti.Vector.field(3, float, model.vertex_count)
        x.from_numpy(x1.astype(np.float32))
        active = c.active_vertex.to_numpy()[:c.active_vertex_count[None]]
        for sweeps in (1, 400):
            pl.clear(solver.buf)
            c.vertex_contact_dual.fill(0.0)
            c.contact_accumulated.fill(0.0)
            pl.project(x, solver.buf, sweeps)
            out.append(c.vertex_z.to_numpy().astype(np.float64)[active])
    assert keys[0] == keys[1] == keys[2]  # the same contacts, whatever their order
    first = np.abs(out[0] - out[2]).max()  # one sweep: another Gauss-Seidel order, another iterate
    assert first > 1e-7, first
    assert np.abs(out[1] - out[3]).max() < 1e-7, np.abs(out[1] - out[3]).max()
    assert np.array_equal(out[2], out[4]) and np.array_equal(out[3], out[5])
    # The cross rod last instead: slab 0 is no run of vertex indices (threads of a phase would share cache lines),
    # so the pipeline keeps the plain order.
    b = GroomBuilder()
    for k in range(16):
        b.add_strand(line((9e-5 * k, 0.0, 0.0), (9e-5 * k, 0.0, 0.02), 11), mat)
    b.add_strand(line((-0.001, 1e-4, 0.0), (0.0024, 1e-4, 0.02), 11), mat, root="free")
    pl = SolverADMM(b.finalize(), SolverADMMConfig(contacts=ContactConfig(friction=0.0))).contacts
    assert not pl.slabs_contiguous
    # The rods in the reverse order, the cross rod (first along x) last: the slabs are runs in descending order.
    b = GroomBuilder()
    for k in range(15, -1, -1):
        b.add_strand(line((9e-5 * k, 0.0, 0.0), (9e-5 * k, 0.0, 0.02), 11), mat)
    b.add_strand(line((-0.001, 1e-4, 0.0), (0.0024, 1e-4, 0.02), 11), mat, root="free")
    pl = SolverADMM(b.finalize(), SolverADMMConfig(contacts=ContactConfig(friction=0.0))).contacts
    assert pl.slabs_contiguous


def test_the_principal_axis_order_of_the_same_points_in_another_order_is_the_same_sequence_never_reversed():
    """``slabs.principal_axis_order`` orders the grooming tool's guides (``groom.guides.GuideChoice``) and, again,
    the Model's strands for the slabs (``slabs.vertex_slabs``): the same roots in another order.  The SVD's sign is
    arbitrary; before the axis was oriented (2026-12-06) the two came out reversed on the grooming benchmark, and
    23 of 50 random sets came out reversed under a permutation, so the slab sweeps were off there.  Now 50 random
    anisotropic sets of 300 points, each permuted: the same sequence of points, exactly."""
    from taichi_hair.contact.slabs import principal_axis_order

    rng = np.random.default_rng(0)
    for _ in range(50):
        pts = rng.normal(size=(300, 3)) * [3.0, 1.0, 0.5]
        perm = rng.permutation(300)
        assert np.array_equal(pts[principal_axis_order(pts)], pts[perm][principal_axis_order(pts[perm])])


def test_slabs_are_runs_in_either_order_and_a_split_slab_is_not():
    """``slabs.slabs_are_runs`` (``ContactPipeline.slabs_contiguous``): each slab one run of vertex indices, the runs
    ascending or descending; a slab met twice is not."""
    from taichi_hair.contact.slabs import slabs_are_runs

    assert slabs_are_runs(np.repeat(np.arange(8), 5))
    assert slabs_are_runs(np.repeat(np.arange(8)[::-1], 5))
    assert slabs_are_runs(np.zeros(0, np.int32))
    assert not slabs_are_runs(np.r_[np.repeat(np.arange(8), 5), 0])


def test_the_grooming_guides_put_each_slab_in_one_run_of_vertex_indices():
    """The grooming tool orders its guides along the principal axis of their roots so that each slab of the contact
    sweeps is one run of vertex indices (``contact.slabs``); the pipeline ranks the Model's roots again (float32 in
    the groom, float64 there).  For 2,000 random roots on a cap, 10 % guides (three seeds): the slabs of the guides'
    order are ascending runs."""
    from taichi_hair.contact.slabs import slabs_are_runs, vertex_slabs
    from taichi_hair.groom.guides import GuideChoice

    rng = np.random.default_rng(1)
    d = rng.normal(size=(2000, 3))
    d[:, 1] = np.abs(d[:, 1])
    roots = (0.09 * d / np.linalg.norm(d, axis=1)[:, None]).astype(np.float32)
    rest = np.repeat(roots, 2, axis=0)
    rest[1::2, 1] -= 0.01
    offsets = np.arange(0, 2 * 2000 + 1, 2)
    for seed in range(3):
        guides = GuideChoice().strands(rest, offsets, 0.1, seed)
        slab = vertex_slabs(roots[guides].astype(np.float64), np.arange(guides.size))
        assert slabs_are_runs(slab) and np.all(np.diff(slab) >= 0), seed


def test_a_contact_buffer_grown_within_a_step_keeps_every_field_of_its_contacts():
    """``ContactPipeline._grow_contacts`` (continuous detection or late body contacts overflowing the buffer mid-step)
    keeps the first contacts' fields, their duals and the slab groups.  The contact thickness was left out until
    2026-12-06: a pair grown past would have been re-linearised by the correction at thickness 0 (r_a + r_b of overlap
    allowed).  Twelve rods pushed through a thirteenth (above); every kept field equal bit for bit."""
    mat = RodMaterial(radius=5e-5)
    b = GroomBuilder()
    b.add_strand(line((-0.01, 0, 0.0), (0.01, 0, 0.0), 11), mat, root="free")
    for k in range(12):
        b.add_strand(line((0.0001 + 0.00015 * k, 1.2e-4, -0.01), (0.0001 + 0.00015 * k, 1.2e-4, 0.01), 11), mat,
                     root="free")
    model = b.finalize()
    solver = SolverADMM(model, SolverADMMConfig(contacts=ContactConfig(friction=0.2, velocity_margin=0.0)))
    pl = solver.contacts
    pl.detect(model.state(), 1 / 96, (0.0, 0.0, 0.0), False)
    nc = pl.contact_count
    names = ("contact_vertex", "contact_weight", "contact_normal", "contact_kinematic", "contact_friction",
             "contact_thickness", "contact_delassus", "contact_collider")
    before = {n: getattr(pl.con, n).to_numpy()[:nc].copy() for n in names}
    starts = pl.con.contact_group_start.to_numpy().copy()
    capacity = pl.con.capacity
    with pytest.warns(UserWarning, match="growing it"):
        pl._grow_contacts(2 * capacity, keep=nc)
    assert pl.con.capacity >= 2 * capacity and pl.contact_count == nc
    for n in names:
        assert np.array_equal(getattr(pl.con, n).to_numpy()[:nc], before[n]), n
    assert np.array_equal(pl.con.contact_group_start.to_numpy(), starts)
    assert before["contact_thickness"].min() > 0


def test_quasistatic_steps_carry_each_contacts_impulse_so_a_resting_rod_sinks_less_in_each_steps_iterations():
    """``contact.warm``: rod B (2 cm, clamped at one end) lies across clamped rod A under 50 m/s^2, quasistatic steps of 10 ADMM
    iterations.  Each detection gives a contact the impulse of the last step's contact with the same two edges, and
    lambda_z the pushes of those impulses (so each z-step still starts at x: checked to 1e-5 of the largest push).
    Without it every step's iterations start from zero contact force and B sinks into A before the end-of-step
    correction lifts it back.  Measured over steps 3-8, the deepest hair pair before the correction: with the carried
    impulses at most half the depth without (measured 0.085 against 0.30 um; at 50 m/s^2 and 10 iterations neither
    sinks measurably: on the grooming benchmark's groom 1,167 -> 39-53 contacts deeper than 10 um, BENCHMARKS.md)."""
    mat = RodMaterial(radius=5e-5)
    b = GroomBuilder()
    b.add_strand(line((-0.01, 0.0, 0.0), (0.01, 0.0, 0.0), 11), mat, root="clamped")
    b.add_strand(line((0.0, 1.0e-4, -0.01), (0.0, 1.0e-4, 0.01), 11), mat, root="clamped")
    model = b.finalize()
    depth = {}
    for warm in (True, False):
        st, ctl = model.state(), model.control()
        ctl.gravity = (0.0, -2000.0, 0.0)
        solver = SolverADMM(model, SolverADMMConfig(iterations=3, mode="quasistatic",
                                                    contacts=ContactConfig(friction=0.3, velocity_margin=0.0)))
        pl = solver.contacts
        orig, seen = pl.correct, []

        def correct(x, x0, sweeps, pl=pl, orig=orig, seen=seen):
            seen.append(pl.statistics(x)["hair_penetration_max_m"])
            orig(x, x0, sweeps)
        pl.correct = correct
        for _ in range(8):
            if not warm:
                pl._warm_valid = False
            solver.step(st, ctl, 1.0)
        depth[warm] = max(seen[2:])
        if warm:
            pl.detect(st, 1.0, ctl.gravity, False)
            c, nc = pl.con, pl.contact_count
            acc = c.contact_accumulated.to_numpy().astype(np.float64)[:nc]
            assert np.abs(acc).max() > 0  # (carried: a fresh detection starts at zero)
            vtx, h = c.contact_vertex.to_numpy()[:nc], c.contact_weight.to_numpy().astype(np.float64)[:nc]
            dh = c.contact_delassus.to_numpy().astype(np.float64)[:nc]
            iw = c.vertex_contact_inv_weight.to_numpy().astype(np.float64)
            push = np.zeros((model.vertex_count, 3))
            for k in range(4):
                on = (vtx[:, k] >= 0) & (dh > 0)
                np.add.at(push, vtx[on, k], (iw[vtx[on, k]] * h[on, k] / dh[on])[:, None] * acc[on])
            lam = c.vertex_contact_dual.to_numpy().astype(np.float64)
            assert np.abs(lam - push).max() <= 1e-5 * np.abs(push).max(), (np.abs(lam - push).max(), np.abs(push).max())
    assert depth[True] <= 0.5 * depth[False], depth


@pytest.mark.parametrize("lengths", ["rest", "before", "free", "rest_along_strands", "rest_contact_batches"])
def test_geometric_correction_uncrosses_a_pair_and_holds_edge_lengths(lengths):
    """Rod B lies across rod A, 20 um above contact at x^t, and ends the ADMM iterations 1 mm below A's
    axis at the crossing (a pair that passed through each other).  The end-of-step correction pushes it
    back above A.  Holding lengths (``"rest"``, the default, or ``"before"``) it leaves every edge within
    0.5 % of the length it holds (0.36 % measured for "before": Gauss-Seidel edge passes leave a remainder);
    the paper's correction (``"free"``), moving the contact vertices alone, stretches the edges at the
    crossing by more than 1 % (what the hairball's impact measured).  With the edges passed along each strand
    (``correction_edge_order="strands"``) instead of in two colours, within 0.01 %.  The contacts solved in the 8
    batches (``correction_contact_order="batches"``, the GPU's order) instead of one by one (the CPU's) hold as
    ``"rest"`` does."""
    mat = RodMaterial(radius=5e-5)
    r = mat.radius
    b = GroomBuilder()
    b.add_strand(line((-0.01, 0, 0.0003), (0.01, 0, 0.0003), 11), mat, root="free")   # A along x, 2 mm edges
    y0 = 2 * r + 2e-5
    b.add_strand(line((0.0003, y0, -0.01), (0.0003, y0, 0.01), 11), mat, root="free")  # B along z, above A
    model = b.finalize()
    st = model.state()
    x0 = st.positions().astype(np.float64)
    x1 = x0.copy()
    z = x1[11:, 2]
    x1[11:, 1] -= (y0 + 1e-3) * np.exp(-(z / 0.003) ** 2)   # B's middle dips 1 mm below A's axis
    order = "strands" if lengths.endswith("_along_strands") else "colours"
    # The contacts one by one (``correction_contact_order``: "auto" is "sequential" on the CPU) or in the 8 batches.
    contact_order = "batches" if lengths.endswith("_contact_batches") else "auto"
    lengths = lengths.removesuffix("_along_strands").removesuffix("_contact_batches")
    cfg = ContactConfig(friction=0.2, correction_lengths=lengths, velocity_margin=0.0, correction_edge_order=order,
                        correction_contact_order=contact_order)
    con = SolverADMM(model, SolverADMMConfig(contacts=cfg)).contacts
    con.detect(st, 1 / 96, (0.0, 0.0, 0.0), False)
    assert con.contact_count >= 1
    x = ti.Vector.field(3, float, model.vertex_count)
    x.from_numpy(x1.astype(np.float32))
    con.correct(x, st.vertex_position, cfg.correction_iterations)
    xc = x.to_numpy().astype(np.float64)
    stats = con.statistics(x)
    rest = model.host["edge_rest_length"]
    idx = np.where(rest > 0)[0]
    before = np.linalg.norm(x1[idx + 1] - x1[idx], axis=1)
    after = np.linalg.norm(xc[idx + 1] - xc[idx], axis=1)
    held = rest[idx] if lengths == "rest" else before
    change = np.abs(after / held - 1)
    if lengths != "free":
        assert stats["crossed_pairs"] == 0
        d = min(segment_distance(xc[i], xc[i + 1], xc[j], xc[j + 1]) for i in range(10) for j in range(11, 21))
        # Apart again, within half a radius of touching (issue 12 asks for one radius; "rest" measured 0.3 r:
        # B's dipped edges go back to rest length, so it has less slack to pass over A).
        assert d > 2 * r - 0.5 * r, d
        k = int(np.argmin(np.abs(xc[11:, 2])))
        j = int(np.argmin(np.abs(xc[:11, 0] - xc[11 + k, 0])))
        assert xc[11 + k, 1] > xc[j, 1] + r            # B back on top of A (both moved: both are free)
        # Colour passes carry a push one edge per sweep and leave 0.23 % (measured); passes along each strand
        # carry it along the whole strand in one sweep: 3.5e-5 measured.
        assert change.max() < (5e-3 if order == "colours" else 1e-4), change.max()
    else:
        assert change.max() > 0.01, change.max()


def test_hairball_hair_pairs_stay_within_one_radius_and_keep_their_lengths():
    """Issue 12 item 1 at a small size: the hairball (100 strands, the CLI's settings: 10 ADMM iterations,
    4 substeps of 1/96 s, 2 projection sweeps, 10 + adaptive correction sweeps, defaults otherwise) through
    its first turn (11 frames; contacts from step ~30, ~3,500 hair pairs at the end).  Claim, each step: the
    hair-pair penetration p99 (``ContactPipeline.statistics``: r_a + r_b minus the gap along the contact
    normal, a crossed pair counting as more than 2r) is at most one hair radius r = 37 um, and edge strain
    |e|/e_rest - 1 stays under 1 % at p99 and 5 % at most.  Measured with the defaults: p99 <= 12.4 um,
    strain p99 <= 0.51 %, max 0.84 %; the correction before issue 12 item 1 (one linearisation, batch mass
    splitting, friction, no acceleration) gave p99 48-70 um from step 34 on, so the bound r tells them
    apart with a 3x margin on the new side."""
    from taichi_hair.scene.builtin import HairballScene, build_hairball, hairball_rotation

    scene = HairballScene(strands=100, length=0.3)
    model = build_hairball(scene)
    cc = ContactConfig(friction=scene.friction, projection_iterations=2, correction_iterations=10)
    solver = SolverADMM(model, SolverADMMConfig(iterations=10, mode="dynamic", contacts=cc),
                        colliders=[SphereCollider(radius=scene.ball_radius, friction=scene.friction, body=0)])
    st, ct = model.state(), model.control()
    rest = model.host["edge_rest_length"]
    real = np.where(rest > 0)[0]
    dt = 1 / 96
    p99s, contacts = [], 0
    for s in range(44):
        ct.set_body_transform(0, hairball_rotation((s + 1) * dt), (0, 0, 0))
        solver.step(st, ct, dt)
        x = st.positions().astype(np.float64)
        strain = np.abs(np.linalg.norm(x[real + 1] - x[real], axis=1) / rest[real] - 1)
        assert np.percentile(strain, 99) < 0.01 and strain.max() < 0.05, (s, strain.max())
        p99s.append(solver.contact_stats["hair_penetration_p99_m"])
        contacts = solver.contact_stats["contacts"]
    assert contacts > 2000, contacts                      # the dense phase was reached
    assert max(p99s) <= scene.radius, max(p99s)


@ti.kernel
def _hold_passes(vertex: ti.template(), edge: ti.template(), strand: ti.template(), z: ti.template(),
                 length: ti.template()):
    hold_strand_lengths(vertex, edge, strand, z, length, False, 2)


def test_the_lockstep_edge_passes_equal_one_strand_at_a_time():
    """``projection.hold_strand_lengths`` steps HOLD_LANES (8) strands in lockstep: on 13 strands of 3 to 20
    vertices (a partial last group, lanes of different lengths, clamped roots) two symmetric Gauss-Seidel passes
    give what a plain NumPy loop of the same projections (Mueller et al. 2007: each end moves by w_i / (w_a + w_b)
    of the length error along the edge) gives strand by strand, to float32 rounding (2e-7 m on positions ~0.1 m)."""
    rng = np.random.default_rng(5)
    counts = [3, 20, 3, 14, 14, 7, 20, 5, 9, 3, 11, 16, 4]
    b = GroomBuilder()
    for k, m in enumerate(counts):
        b.add_strand(line((0.01 * k, 0.0, 0.0), (0.01 * k, -0.005 * (m - 1), 0.0), m), HAIR, root="clamped")
    model = b.finalize()
    rest = model.host["edge_rest_length"].astype(np.float64)
    x = model.host["vertex_rest_position"].astype(np.float64) + rng.normal(scale=1e-3, size=(model.vertex_count, 3))
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    fixed = model.host["vertex_is_fixed"] != 0
    x[fixed] = model.host["vertex_rest_position"][fixed]  # the clamped root edges stay where they are
    z = ti.Vector.field(3, ti.f32, model.vertex_count)
    length = ti.field(ti.f32, model.vertex_count)
    z.from_numpy(x.astype(np.float32))
    length.from_numpy(rest.astype(np.float32))
    _hold_passes(model.vertex, model.edge, model.strand, z, length)
    inv_mass = np.where(fixed, 0.0, 1.0 / model.host["vertex_mass"].astype(np.float64))
    ref = x.astype(np.float32).astype(np.float64)

    def hold(j):
        d = ref[j + 1] - ref[j]
        n = np.linalg.norm(d)
        wa, wb = inv_mass[j], inv_mass[j + 1]
        if wa + wb > 0 and n > 0:
            c = (n - rest[j]) / ((wa + wb) * n) * d
            ref[j] += wa * c
            ref[j + 1] -= wb * c

    for s, m in zip(starts, counts):
        for _ in range(2):
            for j in range(s, s + m - 1):
                hold(j)
            for j in range(s + m - 2, s - 1, -1):
                hold(j)
    assert np.abs(z.to_numpy() - ref).max() < 2e-7, np.abs(z.to_numpy() - ref).max()
    # and the passes did something: the worst length error of the 1 mm noise shrinks >= 4x in two passes (3.6 -> 0.54 mm)
    real = rest[:-1] > 0
    before, after = (np.abs(np.linalg.norm(np.diff(p, axis=0), axis=1)[real] - rest[:-1][real]).max() for p in (x, ref))
    assert after < 0.25 * before, (before, after)


def test_a_quasistatic_step_keeps_the_last_detections_contacts_measured_as_a_detection_measures_them():
    """``contact.reuse`` (``ContactConfig.redetect_share``, 0.25): rod B (clamped at one end) lies across clamped rod A,
    quasistatic steps of 10 ADMM iterations under 50 m/s^2, a 0.4 mm margin.  B settles by ~20 um per step, under a
    quarter of the margin, so steps keep the last detection's contacts.  Kept contacts equal a detection's at the same
    positions: the same pairs, weights, normals, u_kin and D_hat to 1e-6 (relative to the largest; the same float32
    formulas compiled into other kernels), the same carried impulses r~ and collision duals lambda_z to 1e-6 of the
    largest.  A vertex moved by more than a quarter of the margin since the detection, or ``redetect_share = 0``:
    the step detects."""
    mat = RodMaterial(radius=5e-5)
    b = GroomBuilder()
    b.add_strand(line((-0.01, 0.0, 0.0), (0.01, 0.0, 0.0), 11), mat, root="clamped")
    b.add_strand(line((0.0, 1.0e-4, -0.01), (0.0, 1.0e-4, 0.01), 11), mat, root="clamped")
    model = b.finalize()
    st, ctl = model.state(), model.control()
    ctl.gravity = (0.0, -50.0, 0.0)
    solver = SolverADMM(model, SolverADMMConfig(iterations=10, mode="quasistatic",
                                                contacts=ContactConfig(friction=0.3, velocity_margin=0.0, margin=4e-4)))
    pl = solver.contacts
    kept = []
    for _ in range(12):
        solver.step(st, ctl, 1.0)
        kept.append(pl.contacts_reused)
    assert any(kept[4:]), kept
    names = ("contact_vertex", "contact_weight", "contact_normal", "contact_kinematic", "contact_delassus",
             "contact_accumulated")

    def contacts():
        nc = pl.contact_count
        out = {n: getattr(pl.con, n).to_numpy()[:nc].astype(np.float64) for n in names}
        order = np.lexsort((out["contact_vertex"][:, 2], out["contact_vertex"][:, 0]))
        out = {n: a[order] for n, a in out.items()}
        out["dual"] = pl.con.vertex_contact_dual.to_numpy().astype(np.float64)
        return out

    solver.step(st, ctl, 1.0)  # (a step that keeps them leaves the impulses a detection carries: the next check)
    assert pl.detect(st, 1.0, ctl.gravity, False) > 0 and pl.contacts_reused
    a = contacts()
    pl._detection_key = None  # the same positions, detected
    pl._warm_valid = True
    pl.detect(st, 1.0, ctl.gravity, False)
    assert not pl.contacts_reused
    d = contacts()
    assert np.array_equal(a["contact_vertex"], d["contact_vertex"])
    assert np.abs(a["contact_accumulated"]).max() > 0
    for n in names[1:] + ("dual",):
        scale = max(np.abs(d[n]).max(), 1e-30)
        assert np.abs(a[n] - d[n]).max() <= 1e-6 * scale, (n, np.abs(a[n] - d[n]).max(), scale)
    # Moved beyond a quarter of the margin (1e-4 m): detected.
    solver.step(st, ctl, 1.0)
    x = st.positions()
    x[15] += np.array([0.0, 0.0, 1.2e-4], np.float32)
    st.vertex_position.from_numpy(x)
    solver.step(st, ctl, 1.0)
    assert not pl.contacts_reused
    again = []
    for _ in range(4):  # (the moved vertex springs back: the steps after it may detect too)
        solver.step(st, ctl, 1.0)
        again.append(pl.contacts_reused)
    assert any(again), again
    pl.config.redetect_share = 0.0
    solver.step(st, ctl, 1.0)
    assert not pl.contacts_reused
