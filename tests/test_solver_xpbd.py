"""SolverXPBD, the local XPBD Cosserat baseline (pytest on Taichi's CPU arch, single precision)."""

import math

import numpy as np
import pytest

from taichi_hair import GroomBuilder, RodMaterial, SimulationDivergedError
from taichi_hair.solvers.xpbd.solver import SolverXPBD, SolverXPBDConfig
from taichi_hair.validation.cantilever import discrete_linear_tip_deflection
from taichi_hair.validation.elastica import cantilever_gamma

HAIR = RodMaterial()


def straight(length, n, direction=(1.0, 0.0, 0.0), origin=(0.0, 0.0, 0.0)):
    d = np.asarray(direction, float)
    return np.asarray(origin, float) + np.linspace(0.0, length, n)[:, None] * d


def helix(n=60, radius=0.005, pitch=0.01, turns=2.0):
    s = np.linspace(0, 2 * np.pi * turns, n)
    return np.c_[radius * np.cos(s) - radius, pitch * s / (2 * np.pi), radius * np.sin(s)]


def _rot_y(angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def test_curly_rod_without_gravity_keeps_rest_shape():
    """A helix with an elliptic section and rest twist is its own rest state (rest Darboux vectors)."""
    b = GroomBuilder()
    pts = helix()
    b.add_strand(pts, RodMaterial(ellipticity=0.3), twist=np.linspace(0, 1.0, len(pts)))
    b.add_strand(helix(n=40, radius=0.003, pitch=0.02) + [0.02, 0, 0], HAIR)
    model = b.finalize()
    st, ctl = model.state(), model.control()
    ctl.gravity = (0.0, 0.0, 0.0)
    solver = SolverXPBD(model, SolverXPBDConfig(substeps=10))
    for _ in range(20):
        solver.step(st, ctl, 1 / 96)
    x = st.positions()
    assert np.max(np.abs(x - model.host["vertex_rest_position"])) < 2e-6
    np.testing.assert_allclose(st.edge_twist.to_numpy(), model.host["edge_rest_twist"], atol=1e-4)


def _hanging_stretches(settings, steps=20):
    """Largest edge stretch of a 10 cm hanging strand after ``steps`` damped steps, per (substeps, iterations).

    One model and one solver (kernels compile once per solver); substeps and iterations are read at
    each step, so the config is changed between runs from the same initial state."""
    b = GroomBuilder()
    b.add_strand(straight(0.1, 33, direction=(0.0, -1.0, 0.0)), HAIR)
    model = b.finalize()
    st, ctl = model.state(), model.control()
    start = st.to_numpy()
    solver = SolverXPBD(model, SolverXPBDConfig(damping=20.0))
    out = []
    for substeps, iterations in settings:
        st.load(start)
        solver.config.substeps, solver.config.iterations = substeps, iterations
        for _ in range(steps):
            solver.step(st, ctl, 1 / 96)
        out.append(float(np.max(solver.edge_stretch(st))))
    return out


def test_stretch_of_a_hanging_strand_shrinks_with_substeps_and_iterations():
    """Local solves leave a stretch that only more work removes (stiff stretch: E_s A ~ 24 N).
    Measured (single precision): 4.3 (!), 0.31, 0.020 with 2, 8, 32 substeps; 1.2 with 2 substeps
    x 4 iterations."""
    s2, s8, s32, s2x4 = _hanging_stretches([(2, 1), (8, 1), (32, 1), (2, 4)])
    assert s2 > 4 * s8 > 16 * s32, (s2, s8, s32)
    assert s2 > 2 * s2x4, (s2, s2x4)


def _cantilever_ratios(substeps_list, edges=8, steps=30):
    """Tip drop of a 2 cm hair cantilever after ``steps`` damped steps over the exact discrete answer,
    per substep count; and the continuum answer q L^4 / 8 E I over the discrete one."""
    L = 0.02
    b = GroomBuilder()
    b.add_strand(straight(L, edges + 1), HAIR)
    model = b.finalize()
    st, ctl = model.state(), model.control()
    start = st.to_numpy()
    solver = SolverXPBD(model, SolverXPBDConfig(damping=50.0))
    gamma = cantilever_gamma(L, HAIR.radius, HAIR.density, HAIR.youngs_modulus_bend)
    expected = gamma * L * discrete_linear_tip_deflection(edges, True)
    ratios = []
    for substeps in substeps_list:
        st.load(start)
        solver.config.substeps = substeps
        for _ in range(steps):
            solver.step(st, ctl, 1 / 96)
        x = st.positions().astype(np.float64)
        ratios.append((x[0, 1] - x[-1, 1]) / expected)
    return ratios, gamma * L / 8 / expected


def test_cantilever_sag_needs_many_substeps():
    """Small-deflection sag of a short stiff cantilever: close to the discrete beam answer (the one
    the ADMM solver converges to, ~q L^4 / 8 E I) only with many substeps; far too soft with few."""
    (few, many), continuum = _cantilever_ratios([CANTILEVER_FEW, CANTILEVER_MANY])
    assert few > 3.0, few  # measured 4.6 (and 38 with 30 substeps)
    assert abs(many - 1.0) < CANTILEVER_TOL, many
    assert abs(continuum - 1.0) < 0.08  # 8 edges: the discrete answer is 7% below q L^4 / 8 E I


#: Substeps per 1/96 s step (dt_s = 104 us and 10 us) and the tolerance on the converged ratio
#: (measured 1.11 in single precision with 1000 substeps; 1.47 with 300).
CANTILEVER_FEW = 100
CANTILEVER_MANY = 1000
CANTILEVER_TOL = 0.2


def test_velocity_damping_calms_a_swinging_strand():
    """SolverXPBDConfig.damping c multiplies velocities by exp(-c dt_s) each substep: released from
    rest under gravity, a curly strand moves much less at c = 20/s than undamped."""
    b = GroomBuilder()
    b.add_strand(helix(n=25), HAIR)
    model = b.finalize()
    st, ctl = model.state(), model.control()
    start = st.to_numpy()
    solver = SolverXPBD(model, SolverXPBDConfig(substeps=20))
    late = []
    for c in (0.0, 20.0):
        st.load(start)
        solver.config.damping = c
        speeds = []
        for k in range(30):
            solver.step(st, ctl, 1 / 96)
            if k >= 15:
                speeds.append(np.linalg.norm(st.vertex_velocity.to_numpy().astype(np.float64), axis=1).mean())
        late.append(float(np.mean(speeds)))
    assert late[1] < 0.6 * late[0], late  # measured 0.097 vs 0.234 m/s


def test_free_strand_centre_of_mass_falls_like_symplectic_euler():
    """Internal constraints conserve linear momentum: the centre of mass of a free strand follows
    the substep integrator exactly, x = x0 + g dt_s^2 K (K + 1) / 2 after K substeps."""
    b = GroomBuilder()
    b.add_strand(helix(n=30), HAIR, root="free")
    model = b.finalize()
    st, ctl = model.state(), model.control()
    mass = model.host["vertex_mass"]
    com0 = (mass[:, None] * st.positions()).sum(0) / mass.sum()
    solver = SolverXPBD(model, SolverXPBDConfig(substeps=4))
    dt = 1 / 96
    for _ in range(6):
        solver.step(st, ctl, dt)
    com = (mass[:, None] * st.positions().astype(np.float64)).sum(0) / mass.sum()
    k = 24
    drop = 9.81 * (dt / 4) ** 2 * k * (k + 1) / 2
    np.testing.assert_allclose(com - com0, [0.0, -drop, 0.0], atol=2e-3 * drop)


@pytest.fixture(scope="module")
def shared():
    """One groom and solver for the tests that need no particular shape (kernels compile per solver)."""
    b = GroomBuilder()
    b.add_strand(helix(n=20), HAIR)
    for i in range(3):
        b.add_strand(straight(0.03, 11, origin=(0.01, 0, 0.01 * i)), HAIR)
    model = b.finalize()
    return model, SolverXPBD(model, SolverXPBDConfig(substeps=5))


def test_clamped_root_follows_a_rigid_motion(shared):
    model, solver = shared
    st, ctl = model.state(), model.control()
    fixed = model.host["vertex_is_fixed"] != 0
    xb = model.host["vertex_body_position"][fixed]
    for k in range(1, 6):
        R, T = _rot_y(0.1 * k), np.array([0.0, 0.002 * k, 0.001])
        ctl.set_body_transform(0, R, T)
        solver.step(st, ctl, 1 / 96)
        np.testing.assert_allclose(st.positions()[fixed], xb @ R.T + T, atol=1e-6)
    # The root edge's material frame turned with the body (its twist is kinematic).
    d1 = st.edge_material_d1.to_numpy()[0]
    rest = model.state().edge_material_d1.to_numpy()[0]
    np.testing.assert_allclose(d1, _rot_y(0.5) @ rest, atol=1e-5)


def test_two_identical_runs_give_identical_bits():
    """Colors have no write conflicts and no atomics: reruns from the same state are bitwise equal."""
    b = GroomBuilder()
    for i in range(5):
        b.add_strand(helix(n=30 + i) + [0.01 * i, 0, 0], HAIR)
    b.add_strand(helix(n=25) + [0.0, 0.0, 0.02], HAIR, root="free")
    model = b.finalize()
    st, ctl = model.state(), model.control()
    start = st.to_numpy()
    solver = SolverXPBD(model, SolverXPBDConfig(substeps=4, iterations=2, damping=1.0, air_viscosity=1e-5))

    def run():
        st.load(start)
        for k in range(10):
            ctl.set_body_transform(0, _rot_y(0.05 * k), (0.0, 0.001 * k, 0.0))
            solver.step(st, ctl, 1 / 96)
        return st.to_numpy()

    a, b = run(), run()
    assert np.max(np.abs(a["vertex_position"] - start["vertex_position"])) > 1e-3  # it moved
    for name in a:
        assert a[name].tobytes() == b[name].tobytes(), name


def test_stage_and_strand_schedules_agree():
    """The two schedules run the same per-element functions in the same order per strand."""
    b = GroomBuilder()
    for i in range(3):
        b.add_strand(helix(n=20 + 3 * i) + [0.01 * i, 0, 0], HAIR)
    b.add_strand(straight(0.02, 9, origin=(0.0, 0.0, 0.02)), HAIR, root="free")
    model = b.finalize()
    finals = []
    for schedule in ("stage", "strand"):
        st, ctl = model.state(), model.control()
        solver = SolverXPBD(model, SolverXPBDConfig(substeps=3, iterations=2, damping=2.0, schedule=schedule))
        assert solver.schedule == schedule
        for k in range(8):
            ctl.set_body_transform(0, _rot_y(0.05 * k), (0.0, 0.001 * k, 0.0))
            solver.step(st, ctl, 1 / 96)
        finals.append(st.to_numpy())
    moved = np.max(np.abs(finals[0]["vertex_position"] - model.host["vertex_rest_position"]))
    assert moved > 1e-3
    for name in ("vertex_position", "edge_twist", "edge_material_d1"):
        np.testing.assert_allclose(finals[1][name], finals[0][name], atol=1e-5 * max(1.0, moved), err_msg=name)


@pytest.mark.parametrize("field, value", [
    ("substeps", 0), ("substeps", 2.5), ("iterations", 0), ("iterations", True), ("damping", -1.0),
    ("damping", float("nan")), ("air_viscosity", -0.1), ("frame_inertia", "heavy"),
    ("frame_inertia_scale", 0.0), ("strain_rate_damping", 1), ("voronoi_rescaling", "yes"), ("schedule", "gpu"),
])
def test_bad_config_names_the_field(field, value):
    with pytest.raises(ValueError, match=f"SolverXPBDConfig.{field}"):
        SolverXPBDConfig(**{field: value})


def test_non_finite_values_stop_the_step_and_name_the_strand(shared):
    model, solver = shared
    st, ctl = model.state(), model.control()
    solver.step(st, ctl, 1 / 96)
    v = st.vertex_velocity.to_numpy()
    v[model.host["strand_vertex_start"][2] + 5] = [np.nan, 0, 0]
    st.vertex_velocity.from_numpy(v)
    before = st.to_numpy()
    with pytest.raises(SimulationDivergedError, match="strand 2") as info:
        solver.step(st, ctl, 1 / 96)
    assert info.value.strand == 2
    assert info.value.field == "vertex_position"
    after = st.to_numpy()
    for name in ("vertex_position", "edge_twist", "edge_tangent", "edge_material_d1"):
        np.testing.assert_array_equal(after[name], before[name], err_msg=name)


def test_bad_time_step(shared):
    model, solver = shared
    st, ctl = model.state(), model.control()
    for dt in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="dt must be a finite positive number"):
            solver.step(st, ctl, dt)
