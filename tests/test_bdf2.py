"""SolverADMMConfig.integrator = "bdf2": the second-order BDF step of SolverADMM's dynamic mode.

The model is a linear spring-mass analogue: a 3-vertex hair strand clamped along x (vertices 0, 1
fixed), no gravity, its tip displaced by A = 0.1 mm across the strand.  The tip then oscillates on
the bending spring of the middle pair, E_b = k_b kappa^2 / 2 with kappa ~ y / e, so
omega^2 = k_b / (e^2 m_tip) (k_b = ``buf.pair_bend_stiffness``); the axial motion is second order
in A.  Both integrators are linear one-mode maps there, with closed-form amplification per step,
z = omega dt:
  backward Euler:  |xi|^2 = 1 / (1 + z^2);
  BDF2:            xi the larger root of (3 - 2 i z) xi^2 - 4 xi + 1 = 0.
"""

import math

import numpy as np
import pytest

from taichi_hair import GroomBuilder, RodMaterial, SolverADMM, SolverADMMConfig

EDGE = 0.01  # [m]
AMPLITUDE = 1e-4  # [m]


def _oscillator():
    b = GroomBuilder()
    b.add_strand(np.c_[np.arange(3) * EDGE, np.zeros(3), np.zeros(3)], RodMaterial(), root_director=(0.0, 0.0, 1.0))
    return b.finalize()


@pytest.fixture(scope="module")
def oscillator():
    """One Model and one solver for the module (a new solver compiles its kernels again); the runs
    switch ``config.integrator`` and ``iterations`` between them, which needs no recompilation."""
    model = _oscillator()
    return model, SolverADMM(model, SolverADMMConfig())


def _omega(model, solver):
    kb = solver.buf.pair_bend_stiffness.to_numpy()[1]
    return math.sqrt(float(kb[0]) / (EDGE * EDGE * model.host["vertex_mass"][2]))


def _run(oscillator, integrator, dt, steps, iterations, energy=True):
    """Tip y and oscillator energy (kinetic + elastic) after each step, from the displaced rest state."""
    model, solver = oscillator
    st, ctl = model.state(), model.control()
    ctl.gravity = (0.0, 0.0, 0.0)
    x = st.vertex_position.to_numpy()
    x[2, 1] += AMPLITUDE
    st.vertex_position.from_numpy(x)
    solver.config.integrator, solver.config.iterations = integrator, iterations
    solver.reset_duals()  # also forgets the BDF2 history of the last run
    mass = model.host["vertex_mass"]
    ys, es = [], []
    for _ in range(steps):
        solver.step(st, ctl, dt)
        ys.append(float(st.vertex_position.to_numpy()[2, 1]))
        if energy:
            v = st.vertex_velocity.to_numpy().astype(np.float64)
            en = solver.energy(st, ctl)
            es.append(en["bend"] + en["stretch"] + 0.5 * float(np.sum(mass[:, None] * v * v)))
    return np.array(ys), np.array(es)


@pytest.mark.parametrize("z", [0.2, 0.4])
def test_energy_loss_per_step_follows_each_integrators_closed_form(oscillator, z):
    omega = _omega(*oscillator)
    dt, n = z / omega, 60
    predicted = {"backward_euler": 1.0 / (1.0 + z * z),
                 "bdf2": max(abs(np.roots([3.0 - 2.0j * z, -4.0, 1.0]))) ** 2}
    kept = {}
    for integrator, factor in predicted.items():
        _, energy = _run(oscillator, integrator, dt, n, iterations=20)
        # Energy factor per step over the last 40 steps (BDF2's spurious root, ~1/3 per step, is gone).
        measured = (energy[-1] / energy[n // 3]) ** (1.0 / (n - n // 3))
        # Loss per step 1 - |xi|^2 within 5 % of the closed form (measured: 2.3-2.4 % at z = 0.4).
        assert abs((1.0 - measured) - (1.0 - factor)) < 0.05 * (1.0 - factor), (integrator, measured, factor)
        kept[integrator] = energy[-1] / energy[0]
    # The claim of the issue: BDF2 keeps far more of the swing (measured in 60 steps: 94 % against 9.9 %
    # at z = 0.2, 55 % against 0.016 % at z = 0.4).
    assert kept["bdf2"] > 5.0 * kept["backward_euler"]


def test_bdf2_converges_at_second_order_backward_euler_at_first(oscillator):
    """RMS tip error against the linear solution A cos(omega t) over two periods, 16/32/64 steps a period.

    Measured ratios when dt halves: BDF2 3.42, 3.82 (order 1.77, 1.93; the first step is backward
    Euler, and the error at 16 steps is not yet asymptotic); backward Euler 1.4-1.6.
    """
    omega = _omega(*oscillator)
    errors = {}
    for integrator in ("backward_euler", "bdf2"):
        errors[integrator] = []
        for per_period in (16, 32, 64):
            dt = 2.0 * math.pi / (omega * per_period)
            y, _ = _run(oscillator, integrator, dt, 2 * per_period, iterations=60, energy=False)
            k = np.arange(per_period // 8 - 1, 2 * per_period, per_period // 8)  # 16 common sample times
            t = dt * (k + 1)
            errors[integrator].append(float(np.sqrt(np.mean((y[k] - AMPLITUDE * np.cos(omega * t)) ** 2))) / AMPLITUDE)
    bdf2, be = np.array(errors["bdf2"]), np.array(errors["backward_euler"])
    assert 3.5 < bdf2[1] / bdf2[2] < 4.5, bdf2
    assert be[1] / be[2] < 2.2, be
    assert bdf2[2] < 0.1 * be[2]


def test_first_step_and_reset_are_backward_euler_and_checkpoint_restores_the_history(oscillator):
    model, solver = oscillator
    dt = 0.3 / 380.0
    a, _ = _run(oscillator, "backward_euler", dt, 1, iterations=10, energy=False)
    b, _ = _run(oscillator, "bdf2", dt, 1, iterations=10, energy=False)
    assert a.tobytes() == b.tobytes()  # no history: the first BDF2 step is a backward Euler step
    # Resume: checkpoint after 5 steps, continue 5 more; the solver restored from it gives the same bits.
    st, ctl = model.state(), model.control()
    ctl.gravity = (0.0, -9.81, 0.0)
    solver.config.integrator = "bdf2"
    solver.reset_duals()
    for _ in range(5):
        solver.step(st, ctl, dt)
    snap_state, snap_solver = st.to_numpy(), solver.checkpoint()
    assert np.isfinite(snap_solver["history_dt"])
    for _ in range(5):
        solver.step(st, ctl, dt)
    straight = st.to_numpy()
    other = solver
    st2 = model.state()
    st2.load(snap_state)
    other.restore(snap_solver)
    for _ in range(5):
        other.step(st2, ctl, dt)
    for k, v in straight.items():
        assert v.tobytes() == st2.to_numpy()[k].tobytes(), k
    # Without the history (reset_duals after a state load) the continuation differs: a backward Euler step.
    st2.load(snap_state)
    other.restore(snap_solver)
    other.reset_duals()
    other.step(st2, ctl, dt)
    assert other.checkpoint()["history_dt"] == dt
    st3 = model.state()
    st3.load(snap_state)
    other.restore(snap_solver)
    other.step(st3, ctl, dt)
    assert st2.vertex_position.to_numpy().tobytes() != st3.vertex_position.to_numpy().tobytes()


def test_integrator_is_validated():
    with pytest.raises(ValueError, match=r"SolverADMMConfig\.integrator"):
        SolverADMMConfig(integrator="rk4")
