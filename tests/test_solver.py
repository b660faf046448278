"""Physics of SolverADMM without contacts (pytest on Taichi's CPU arch, single precision)."""

import math

import numpy as np
import pytest

from taichi_hair import GroomBuilder, RodMaterial, SimulationDivergedError, SolverADMM, SolverADMMConfig
from taichi_hair.validation.cantilever import discrete_linear_tip_deflection
from taichi_hair.validation.elastica import cantilever_gamma, heavy_elastica_h_over_w

HAIR = RodMaterial()


def straight(length, n, direction=(1.0, 0.0, 0.0), origin=(0.0, 0.0, 0.0)):
    d = np.asarray(direction, float)
    return np.asarray(origin, float) + np.linspace(0.0, length, n)[:, None] * d


def helix(n=60, radius=0.005, pitch=0.01, turns=2.0):
    s = np.linspace(0, 2 * np.pi * turns, n)
    return np.c_[radius * np.cos(s) - radius, pitch * s / (2 * np.pi), radius * np.sin(s)]


def run_quasistatic(model, iterations, w0=0.2, chunk=250, measure="korner", rescale=True, gravity=(0, -9.81, 0)):
    st, ctl = model.state(), model.control()
    ctl.gravity = gravity
    solver = SolverADMM(model, SolverADMMConfig(iterations=chunk, mode="quasistatic", w0=w0, strain_measure=measure,
                                                voronoi_rescaling=rescale))
    for _ in range(iterations // chunk):
        solver.step(st, ctl, 1.0)
    return st, solver


def tip_drop(state, model, strand=0):
    x = state.positions().astype(np.float64)
    a = model.host["strand_vertex_start"][strand]
    c = model.host["strand_vertex_count"][strand]
    return x[a, 1] - x[a + c - 1, 1], x[a + c - 1, 0] - x[a, 0]


@pytest.mark.parametrize("rescale", [True, False])
def test_converged_sag_equals_exact_discrete_solution(rescale):
    """Small Gamma: the converged tip drop equals the closed-form small-deflection answer
    of the *discrete* model (lumped loads, hinges with Voronoi-length stiffness)."""
    L, N = 0.02, 16
    b = GroomBuilder()
    b.add_strand(straight(L, N + 1), HAIR)
    model = b.finalize()
    st, _ = run_quasistatic(model, 3000, rescale=rescale)
    drop, _ = tip_drop(st, model)
    gamma = cantilever_gamma(L, HAIR.radius, HAIR.density, HAIR.youngs_modulus_bend)
    expected = gamma * L * discrete_linear_tip_deflection(N, rescale)
    assert abs(drop / expected - 1) < 3e-3, (drop, expected)
    # The rescaling brings the discrete model close to beam theory (q L^4 / 8 E I).
    continuum = gamma * L / 8
    assert abs(drop / continuum - 1) < (0.02 if rescale else 0.13)
    if not rescale:
        assert drop / continuum - 1 < -0.1


def test_an_attachment_spring_meets_the_discrete_cantilever_it_pulls():
    """``SolverADMM.set_attachments``: without gravity, the tip of a clamped straight rod pulled by a zero-length spring
    of weight k toward a target delta to the side.  A tip load P deflects the discrete rod by w = c P with
    c = sum_k (s_N - s_k)^2 v_k / (E I) (hinges k = 1..N-1 as in ``discrete_linear_tip_deflection``, v_k with the
    Voronoi rescaling), and the spring loads it by P = k (delta - w), so w = delta c k / (1 + c k): delta / 2 for
    k = 1 / c.  Converged quasistatic run, small deflection (delta = 1e-4 L); tolerance 1e-4 (measured 5e-7: the
    model is linear in delta here, so only single precision separates them).
    Clearing the attachments lets the rod spring back straight."""
    L, N = 0.02, 16
    b = GroomBuilder()
    b.add_strand(straight(L, N + 1), HAIR)
    model = b.finalize()
    h = L / N
    s = np.arange(N + 1) * h
    v = np.full(N + 1, h)
    v[1] = v[N - 1] = 1.5 * h
    ei = HAIR.youngs_modulus_bend * math.pi * HAIR.radius**4 / 4
    c = sum((s[N] - s[k]) ** 2 * v[k] for k in range(1, N)) / ei
    delta = 1e-4 * L
    st, ctl = model.state(), model.control()
    ctl.gravity = (0.0, 0.0, 0.0)
    solver = SolverADMM(model, SolverADMMConfig(iterations=250, mode="quasistatic", w0=0.2))
    tip0 = st.positions()[N].astype(np.float64)
    solver.set_attachments([N], [tip0 + [0.0, delta, 0.0]], 1.0 / c)
    for _ in range(12):
        solver.step(st, ctl, 1.0)
    w = float(st.positions()[N, 1]) - tip0[1]
    assert abs(w / (delta / 2) - 1) < 1e-4, (w, delta / 2)
    solver.set_attachments([], np.zeros((0, 3)), [])
    for _ in range(12):
        solver.step(st, ctl, 1.0)
    assert abs(float(st.positions()[N, 1]) - tip0[1]) < 1e-3 * delta
    for bad in (([N], [[0.0, float("nan"), 0.0]], 1.0), ([N + 1], [[0.0, 0.0, 0.0]], 1.0), ([-1], [[0.0, 0.0, 0.0]], 1.0),
                ([N], [[0.0, 0.0, 0.0]], -1.0), ([N], [[0.0, 0.0, 0.0]], [1.0, 2.0])):
        with pytest.raises(ValueError, match=r"set_attachments: vertices in \[0, 17\)"):
            solver.set_attachments(*bad)


def test_large_deflection_matches_heavy_elastica():
    """Gamma = 6.8 (10 cm hair, 40 edges): H/W within 1% of the scipy elastica, in f32."""
    L = 0.1
    b = GroomBuilder()
    b.add_strand(straight(L, 41), HAIR)
    model = b.finalize()
    st, _ = run_quasistatic(model, 4000)
    H, W = tip_drop(st, model)
    gamma = cantilever_gamma(L, HAIR.radius, HAIR.density, HAIR.youngs_modulus_bend)
    ref = heavy_elastica_h_over_w([gamma])[0]
    assert abs((H / W) / ref - 1) < 0.01, (H / W, ref)


def test_strain_measures_agree_on_small_curvatures():
    L = 0.05
    drops = {}
    for measure in ("korner", "bergou"):
        b = GroomBuilder()
        b.add_strand(straight(L, 21), HAIR)
        model = b.finalize()
        st, _ = run_quasistatic(model, 2000, measure=measure)
        drops[measure] = tip_drop(st, model)[0]
    assert abs(drops["korner"] / drops["bergou"] - 1) < 5e-3


def test_stiffer_rod_sags_less():
    b = GroomBuilder()
    for i, E in enumerate((1.5e9, 3e9, 6e9, 12e9)):
        b.add_strand(straight(0.08, 33, origin=(0, 0, 0.01 * i)), RodMaterial(youngs_modulus_bend=E))
    model = b.finalize()
    st, _ = run_quasistatic(model, 2000)
    drops = [tip_drop(st, model, s)[0] for s in range(4)]
    assert all(d > 0 for d in drops)
    assert drops[0] > drops[1] > drops[2] > drops[3]
    # Large deflection: not exactly 1/E, but close to it for the stiffest rods.
    assert 1.6 < drops[2] / drops[3] < 2.05


def test_quasistatic_energy_decreases_monotonically():
    b = GroomBuilder()
    b.add_strand(straight(0.06, 25), HAIR)
    model = b.finalize()
    st, ctl = model.state(), model.control()
    solver = SolverADMM(model, SolverADMMConfig(iterations=20, mode="quasistatic", w0=0.2))
    energies = [solver.energy(st, ctl)["total"]]
    for _ in range(60):
        solver.step(st, ctl, 1.0)
        energies.append(solver.energy(st, ctl)["total"])
    e = np.array(energies)
    scale = abs(e[-1] - e[0])
    assert e[-1] < e[0]
    assert np.all(np.diff(e) <= 1e-4 * scale), np.diff(e).max() / scale


@pytest.mark.parametrize("measure", ["korner", "bergou"])
def test_curly_rod_without_gravity_keeps_rest_shape(measure):
    """A helix with an elliptic section and rest twist is its own rest state."""
    b = GroomBuilder()
    pts = helix()
    b.add_strand(pts, RodMaterial(ellipticity=0.3), twist=np.linspace(0, 1.0, len(pts)))
    b.add_strand(helix(n=40, radius=0.003, pitch=0.02) + [0.02, 0, 0], HAIR)
    model = b.finalize()
    for mode in ("dynamic", "quasistatic"):
        st, ctl = model.state(), model.control()
        ctl.gravity = (0.0, 0.0, 0.0)
        solver = SolverADMM(model, SolverADMMConfig(iterations=20, mode=mode, strain_measure=measure))
        for _ in range(20):
            solver.step(st, ctl, 1 / 96)
        x = st.positions()
        rest = model.host["vertex_rest_position"]
        assert np.max(np.abs(x - rest)) < 2e-6, (mode, np.max(np.abs(x - rest)))
        np.testing.assert_allclose(st.edge_twist.to_numpy(), model.host["edge_rest_twist"], atol=1e-4)


def test_two_identical_runs_give_identical_bits():
    def run():
        b = GroomBuilder()
        for i in range(5):
            b.add_strand(helix(n=30 + i) + [0.01 * i, 0, 0], HAIR)
        model = b.finalize()
        st, ctl = model.state(), model.control()
        solver = SolverADMM(model, SolverADMMConfig(iterations=10, damping_time=0.0) if False else
                            SolverADMMConfig(iterations=10))
        for k in range(10):
            ctl.set_body_transform(0, _rot_y(0.05 * k), (0.0, 0.001 * k, 0.0))
            solver.step(st, ctl, 1 / 96)
        return st.to_numpy()

    a, b = run(), run()
    for name in a:
        assert a[name].tobytes() == b[name].tobytes(), name


def _rot_y(angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rot_x(angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def test_thomas_and_pcr_give_the_same_motion():
    out = {}
    for method in ("thomas", "pcr"):
        b = GroomBuilder()
        for i in range(4):
            b.add_strand(straight(0.05 + 0.02 * i, 20 + 7 * i, origin=(0, 0, 0.01 * i)), HAIR)
        model = b.finalize()
        st, ctl = model.state(), model.control()
        # The plain iteration: Anderson's restart and noise-floor branches turn the two solves' round-off
        # into differences up to the iteration's convergence error (measured 1.8e-4 m here, anderson.py).
        solver = SolverADMM(model, SolverADMMConfig(iterations=10, tridiagonal=method, anderson_window=0))
        assert solver.tridiagonal_method == method
        for _ in range(20):
            solver.step(st, ctl, 1 / 96)
        out[method] = st.positions().astype(np.float64)
    scale = np.max(np.abs(out["thomas"]))
    assert np.max(np.abs(out["thomas"] - out["pcr"])) < 1e-5 * scale


def test_free_fall_follows_backward_euler_exactly():
    """A free strand falls rigidly: x_n = x_0 + g dt^2 n (n + 1) / 2 (backward Euler)."""
    b = GroomBuilder()
    b.add_strand(helix(n=30), HAIR, root="free")
    model = b.finalize()
    st, ctl = model.state(), model.control()
    ctl.gravity = (0.0, -9.81, 0.0)
    dt, n = 1 / 200, 40
    solver = SolverADMM(model, SolverADMMConfig(iterations=5))
    for _ in range(n):
        solver.step(st, ctl, dt)
    drop = model.host["vertex_rest_position"][:, 1] - st.positions()[:, 1]
    expected = 9.81 * dt * dt * n * (n + 1) / 2
    np.testing.assert_allclose(drop, expected, rtol=2e-4)
    np.testing.assert_allclose(st.positions()[:, [0, 2]], model.host["vertex_rest_position"][:, [0, 2]], atol=2e-6)
    np.testing.assert_allclose(st.vertex_velocity.to_numpy()[:, 1], -9.81 * dt * n, rtol=2e-4)


def test_linear_drag_reaches_terminal_velocity():
    """Force balance m g = xi v_len v: terminal speed rho A g / xi for a uniform strand."""
    xi = 2e-4  # Pa s
    b = GroomBuilder()
    b.add_strand(straight(0.05, 21), HAIR, root="free")
    model = b.finalize()
    st, ctl = model.state(), model.control()
    solver = SolverADMM(model, SolverADMMConfig(iterations=5, air_viscosity=xi))
    for _ in range(200):
        solver.step(st, ctl, 1 / 100)
    v = st.vertex_velocity.to_numpy()[:, 1]
    terminal = -HAIR.density * HAIR.area * 9.81 / xi
    np.testing.assert_allclose(v, terminal, rtol=1e-3)


def test_air_velocity_drives_a_weightless_strand():
    b = GroomBuilder()
    b.add_strand(straight(0.05, 21), HAIR, root="free")
    model = b.finalize()
    st, ctl = model.state(), model.control()
    ctl.gravity = (0.0, 0.0, 0.0)
    ctl.air_velocity = (0.0, 0.0, 0.7)
    solver = SolverADMM(model, SolverADMMConfig(iterations=5, air_viscosity=1e-3))
    for _ in range(300):
        solver.step(st, ctl, 1 / 100)
    np.testing.assert_allclose(st.vertex_velocity.to_numpy()[:, 2], 0.7, rtol=1e-3)


def test_clamped_root_follows_a_rigid_motion():
    """No gravity: turning and moving the body carries the rod rigidly, frames and twist included."""
    b = GroomBuilder()
    b.add_strand(helix(n=40), RodMaterial(ellipticity=0.2))
    model = b.finalize()
    st, ctl = model.state(), model.control()
    ctl.gravity = (0.0, 0.0, 0.0)
    solver = SolverADMM(model, SolverADMMConfig(iterations=50, mode="quasistatic", w0=1.0))
    R = _rot_x(0.6) @ _rot_y(1.0)
    T = np.array([0.01, -0.02, 0.005])
    steps = 40
    for k in range(1, steps + 1):
        a = k / steps
        ctl.set_body_transform(0, _rot_x(0.6 * a) @ _rot_y(1.0 * a), a * T)
        solver.step(st, ctl, 1.0)
    rest = model.host["vertex_rest_position"]
    errors = []
    for _ in range(6):  # a free rigid rotation is a slow mode of quasistatic ADMM (Sec. 4.4)
        for _ in range(20):
            solver.step(st, ctl, 1.0)
        errors.append(np.max(np.abs(st.positions() - (rest @ R.T + T))))
    assert all(b < a for a, b in zip(errors, errors[1:])), errors
    assert errors[-1] < 5e-5, errors
    m1_rest = model.state().edge_material_d1.to_numpy()[:-1]
    np.testing.assert_allclose(st.edge_material_d1.to_numpy()[:-1], m1_rest @ R.T, atol=5e-3)


def test_twisting_the_root_turns_the_whole_free_end():
    """Rotating the clamp about the rod axis: no torque at the free end, so every
    material frame turns with the root (the twist step propagates it)."""
    b = GroomBuilder()
    b.add_strand(straight(0.05, 21), HAIR, root_director=(0, 1, 0))
    model = b.finalize()
    st, ctl = model.state(), model.control()
    ctl.gravity = (0.0, 0.0, 0.0)
    solver = SolverADMM(model, SolverADMMConfig(iterations=30, mode="quasistatic"))
    angle = 1.2
    c, s = math.cos(angle), math.sin(angle)
    Rx = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    for k in range(1, 11):
        ctl.set_body_transform(0, _rot_x(angle * k / 10), (0, 0, 0))
        solver.step(st, ctl, 1.0)
    for _ in range(10):
        solver.step(st, ctl, 1.0)
    m1 = st.edge_material_d1.to_numpy()[:-1]
    np.testing.assert_allclose(m1, np.tile(Rx @ [0, 1, 0], (20, 1)), atol=2e-3)
    np.testing.assert_allclose(st.positions(), model.host["vertex_rest_position"], atol=1e-6)


def test_strain_rate_damping_dissipates_energy():
    def swing(tau):
        b = GroomBuilder()
        b.add_strand(straight(0.03, 13), RodMaterial(damping_time=tau))
        model = b.finalize()
        st, ctl = model.state(), model.control()
        ctl.gravity = (0.0, -9.81, 0.0)
        solver = SolverADMM(model, SolverADMMConfig(iterations=20))
        for _ in range(60):
            solver.step(st, ctl, 1 / 500)
        v = st.vertex_velocity.to_numpy()
        return 0.5 * float(np.sum(model.host["vertex_mass"][:, None] * v * v))

    assert swing(2e-3) < 0.8 * swing(0.0)


def test_non_finite_values_stop_the_step_and_name_the_strand():
    b = GroomBuilder()
    for i in range(4):
        b.add_strand(straight(0.03, 11, origin=(0, 0, 0.01 * i)), HAIR)
    model = b.finalize()
    st, ctl = model.state(), model.control()
    solver = SolverADMM(model, SolverADMMConfig(iterations=5))
    solver.step(st, ctl, 1 / 96)
    before = st.to_numpy()
    v = st.vertex_velocity.to_numpy()
    v[model.host["strand_vertex_start"][2] + 5] = [np.nan, 0, 0]
    st.vertex_velocity.from_numpy(v)
    with pytest.raises(SimulationDivergedError, match="strand 2") as info:
        solver.step(st, ctl, 1 / 96)
    assert info.value.strand == 2
    assert info.value.field == "vertex_position"
    # The state is the one handed to the failed step, not garbage.
    np.testing.assert_array_equal(st.positions(), before["vertex_position"])


def test_bad_time_step():
    b = GroomBuilder()
    b.add_strand(straight(0.03, 11), HAIR)
    model = b.finalize()
    solver = SolverADMM(model)
    st, ctl = model.state(), model.control()
    for dt in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="dt must be a finite positive number"):
            solver.step(st, ctl, dt)


def test_stretch_a_thousand_times_stiffer_than_bending_stays_finite_in_single_precision():
    """Daviet 2023 Sec. 6.1's hard case, E_s = 1000 E_b (10 cm, 40 edges), dynamic at w0 = 1, dt = 1/96 s:
    the local 6x6 matrix then holds k_s / w ~ 4e7, past single precision's 1 / eps = 1.7e7, and the dense
    LDL^T of it went non-finite at step 17 (measured, this test).  The local step solves the stretch as two rank-one
    updates (Woodbury), so the rod falls and stays a rod: finite, edges within 1e-4 of rest, tip below the
    root, for 96 steps (1 s)."""
    mat = RodMaterial(youngs_modulus_stretch=1000 * RodMaterial().youngs_modulus_bend)
    b = GroomBuilder()
    b.add_strand(np.c_[np.linspace(0, 0.1, 41), np.zeros(41), np.zeros(41)], mat, root_director=(0.0, 0.0, 1.0))
    model = b.finalize()
    st, ctl = model.state(), model.control()
    solver = SolverADMM(model, SolverADMMConfig(iterations=10, w0=1.0))
    for _ in range(96):
        solver.step(st, ctl, 1 / 96)          # raises SimulationDivergedError on a non-finite value
    x = st.positions().astype(np.float64)
    e = np.linalg.norm(np.diff(x, axis=0), axis=1)
    assert np.abs(e / model.host["edge_rest_length"][:40] - 1).max() < 1e-4
    assert x[-1, 1] < -0.01
