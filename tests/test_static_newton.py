"""The direct static solve (taichi_hair/solvers/static_newton.py): it finds the minimum of the same discrete energy
the ADMM solves, in one launch.

Claims pinned here:
* the equilibrium is a stationary point and a minimum of an independent NumPy (float64) implementation of
  E(x) = sum_pairs 1/2 S_i |t_{i-1} - t_i|^2 + sum_edges 1/2 k_j eps_j^2 - sum m g . x;
* in the small-deflection regime it reproduces the discrete rod's closed-form tip drop;
* on the 10 cm hair rod (Gamma = 6.8) it lands on the quasistatic ADMM's equilibrium;
* strands solved in parallel and one after the other agree, each path bit for bit run to run;
* with the twist as an unknown (curved rods) it lands on the quasistatic ADMM's equilibrium too;
* ``equilibrium()`` uses it where the model allows it and says so, and the scope is checked.
"""

import numpy as np
import pytest


def _rod(th, length, n=41, builder=None):
    b = builder or th.GroomBuilder()
    b.add_strand(np.c_[np.linspace(0, length, n), np.zeros(n), np.zeros(n)], th.RodMaterial())
    return b


def _energy(model, x, g, rescaling=True):
    """E(x) [J] in float64 from the Model's host arrays (the module docstring's formula, written again)."""
    h = model.host
    x = np.asarray(x, np.float64)
    active = h["pair_is_active"].astype(bool)
    S = np.where(active, h["pair_bending_modulus"][:, 0] / model.pair_voronoi_length(rescaling), 0.0)
    le = np.asarray(h["edge_rest_length"], np.float64)
    E = 0.0
    for j in np.nonzero(le > 0)[0]:
        e = x[j + 1] - x[j]
        eps = 0.5 * (e @ e / le[j] ** 2 - 1.0)
        E += 0.5 * h["edge_stretch_stiffness"][j] * eps**2
    for i in np.nonzero(active)[0]:
        ta = (x[i] - x[i - 1]) / np.linalg.norm(x[i] - x[i - 1])
        tb = (x[i + 1] - x[i]) / np.linalg.norm(x[i + 1] - x[i])
        E += 0.5 * S[i] * np.sum((ta - tb) ** 2)
    free = h["vertex_is_fixed"] == 0
    E -= float(np.sum(h["vertex_mass"][free, None] * x[free] * np.asarray(g)[None, :]))
    return E


def test_static_solve_is_a_stationary_minimum_of_the_energy(taichi_cpu):
    """At the solution of the 10 cm rod every free coordinate's central difference of E (h = 1e-9 m) is below
    1e-3 of the vertex's weight m g (the gradient is zero), and moving any free vertex by 1e-5 m in x or y
    raises E (a minimum; the energy is flat to round-off out of the plane, so z is not asked).  The step h:
    the difference's truncation error grows as h^2 (the stretch term's third derivative is large: 0.005 m g at
    h = 1e-7, 0.5 m g at 1e-6); its round-off, ~1e-23 J / h, is 3e-8 m g at 1e-9."""
    import taichi_hair as th
    from taichi_hair.solvers.static_newton import SolverStaticNewton

    model = _rod(th, 0.1).finalize()
    st, ctl = model.state(), model.control()
    solver = SolverStaticNewton(model)
    x, r = solver.solve_to(st.vertex_position.to_numpy(), ctl.gravity)
    assert r.all_converged and r.iterations[0] < 30
    g = np.asarray(ctl.gravity)
    E0 = _energy(model, x, g)
    assert abs(E0 - r.energy[0]) <= 1e-9 * abs(E0)
    free = np.nonzero(model.host["vertex_is_fixed"] == 0)[0]
    weight = model.host["vertex_mass"] * 9.81
    h = 1e-9
    for v in free:
        for c in range(3):
            xp, xm = x.copy(), x.copy()
            xp[v, c] += h
            xm[v, c] -= h
            grad = (_energy(model, xp, g) - _energy(model, xm, g)) / (2 * h)
            assert abs(grad) <= 1e-3 * weight[v], (v, c, grad, weight[v])
            if c < 2:
                xp[v, c] += 1e-5 - h
                assert _energy(model, xp, g) > E0


def test_static_solve_small_deflection_matches_the_discrete_closed_form(taichi_cpu):
    """A 1 cm piece of hair (Gamma = q L^3 / (E I) = 0.0068): tip drop = q L^4 / (E I) x
    discrete_linear_tip_deflection(40) (the clamped discrete rod's exact linear answer) within 1 % (the
    geometric nonlinearity at Gamma = 0.0068 is ~1e-5 of it)."""
    import taichi_hair as th
    from taichi_hair.solvers.static_newton import SolverStaticNewton
    from taichi_hair.validation.cantilever import discrete_linear_tip_deflection

    L = 0.01
    model = _rod(th, L).finalize()
    st, ctl = model.state(), model.control()
    x, r = SolverStaticNewton(model).solve_to(st.vertex_position.to_numpy(), ctl.gravity)
    mat = th.RodMaterial()
    area, inertia = np.pi * mat.radius**2, np.pi * mat.radius**4 / 4
    q = mat.density * area * 9.81
    expected = q * L**4 / (mat.youngs_modulus_bend * inertia) * discrete_linear_tip_deflection(40)
    assert r.all_converged
    assert -x[-1, 1] == pytest.approx(expected, rel=1e-2)


def test_static_solve_lands_on_the_quasistatic_admm_equilibrium(taichi_cpu):
    """The 10 cm rod: the static solve's tip and the quasistatic ADMM's (stepped to 1e-7 m, float32) agree to
    2e-4 of the length (the ADMM's own tolerance and single precision), and equilibrium() picks the static solve
    by itself ("auto") and reports it."""
    import taichi_hair as th
    from taichi_hair.solvers.equilibrium import equilibrium, static_solve_choice

    model = _rod(th, 0.1).finalize()
    cfg = th.SolverADMMConfig(mode="quasistatic", w0=0.2)
    admm = th.SolverADMM(model, cfg)
    st, ctl = model.state(), model.control()
    ref = equilibrium(admm, st, ctl, tolerance=1e-7, max_steps=4000, method="admm")
    assert ref.converged and ref.method == "admm"
    tip_admm = st.positions()[-1].astype(np.float64)
    assert static_solve_choice(admm)[0]
    st2 = model.state()
    res = equilibrium(admm, st2, ctl, tolerance=1e-7)
    assert res.converged and res.method == "static Newton" and res.steps == 1
    tip_newton = st2.positions()[-1].astype(np.float64)
    assert np.linalg.norm(tip_newton - tip_admm) <= 2e-4 * 0.1
    assert float(np.max(np.abs(st2.vertex_velocity.to_numpy()))) == 0.0


def test_static_solve_is_deterministic_and_its_parallel_and_serial_paths_agree(taichi_cpu):
    """Twelve rods of different lengths: each path (in parallel: more than SERIAL_STRANDS strands; one after the
    other) gives the same bits run to run, and the two agree within 1e-9 m, their iteration counts within one (each
    strand's iteration is independent and sequential, but the two paths are compiled apart and round
    differently: measured 3e-11 m apart)."""
    import taichi_hair as th
    from taichi_hair.solvers.static_newton import SolverStaticNewton

    b = th.GroomBuilder()
    for k in range(12):
        _rod(th, 0.02 + 0.01 * k, n=21, builder=b)
    model = b.finalize()
    st, ctl = model.state(), model.control()
    solver = SolverStaticNewton(model)
    assert model.strand_count > solver.SERIAL_STRANDS
    x0 = st.vertex_position.to_numpy()
    x_par, r_par = solver.solve_to(x0, ctl.gravity)
    assert np.array_equal(x_par, solver.solve_to(x0, ctl.gravity)[0])
    solver.SERIAL_STRANDS = 100
    x_ser, r_ser = solver.solve_to(x0, ctl.gravity)
    assert np.array_equal(x_ser, solver.solve_to(x0, ctl.gravity)[0])
    assert r_par.all_converged and r_ser.all_converged
    assert float(np.max(np.abs(x_par - x_ser))) <= 1e-9
    assert np.max(np.abs(r_par.iterations - r_ser.iterations)) <= 1  # the last move rounds across the tolerance


def test_static_solve_with_the_twist_lands_on_the_quasistatic_admm_equilibrium_of_curved_rods(taichi_cpu):
    """An arc and a helix-like curly strand (naturally curved: the twist is an unknown, 4 per vertex): the
    static solve and the quasistatic ADMM (w0 = 1, stepped to an estimated 1e-7 m) end within 1e-6 m of each
    other (measured 2e-7 m), the rods having moved by centimetres; the state's frames come back consistent
    with its positions (unit tangents along the edges)."""
    import taichi_hair as th
    from taichi_hair.solvers.equilibrium import equilibrium
    from taichi_hair.solvers.static_newton import SolverStaticNewton

    b = th.GroomBuilder()
    s = np.linspace(0, 1, 31)
    b.add_strand(np.c_[0.1 * s, 0.01 * np.cos(12 * s) - 0.01, 0.01 * np.sin(12 * s)], th.RodMaterial())
    b.add_strand(np.c_[0.08 * np.sin(2 * s), -0.08 * (1 - np.cos(2 * s)), np.full(31, 0.05)], th.RodMaterial())
    model = b.finalize()
    newton = SolverStaticNewton(model)
    assert newton.twist and newton.D == 4
    admm = th.SolverADMM(model, th.SolverADMMConfig(mode="quasistatic", w0=1.0))
    st, ctl = model.state(), model.control()
    assert equilibrium(admm, st, ctl, 1e-7, 20000, method="admm").converged
    st2 = model.state()
    r = newton.solve(st2, ctl)
    assert r.all_converged
    x_admm, x_newton = st.positions().astype(np.float64), st2.positions().astype(np.float64)
    assert np.max(np.abs(x_newton - model.host["vertex_rest_position"])) > 0.02
    assert np.max(np.abs(x_newton - x_admm)) <= 1e-6
    h = model.host
    real = h["edge_rest_length"] > 0
    e = np.diff(x_newton, axis=0, append=x_newton[-1:])[real]
    t = st2.edge_tangent.to_numpy()[real]
    assert np.max(np.abs(t - e / np.linalg.norm(e, axis=1)[:, None])) < 1e-6
    # equilibrium(): "auto" steps the ADMM here (the twist is solved), "newton" takes the static solve.
    from taichi_hair.solvers.equilibrium import static_solve_choice

    assert not static_solve_choice(admm)[0] and static_solve_choice(admm, "newton")[0]


def test_static_solve_refuses_what_it_does_not_model(taichi_cpu):
    """The Bergou measure is refused with a one-line reason (and equilibrium() then steps the ADMM); bad configs
    and bad positions are refused."""
    import taichi_hair as th
    from taichi_hair.solvers.equilibrium import static_solve_choice
    from taichi_hair.solvers.static_newton import SolverStaticNewton, StaticNewtonConfig

    straight = _rod(th, 0.05, n=11).finalize()
    with pytest.raises(ValueError, match="Korner"):
        SolverStaticNewton(straight, th.SolverADMMConfig(strain_measure="bergou"))
    admm = th.SolverADMM(straight, th.SolverADMMConfig(mode="quasistatic", strain_measure="bergou"))
    ok, why = static_solve_choice(admm)
    assert not ok and "quasistatic ADMM" in why
    for bad in (dict(max_iterations=0), dict(tolerance=-1.0), dict(tolerance=float("nan")), dict(line_search_steps=0)):
        with pytest.raises(ValueError, match="StaticNewtonConfig"):
            StaticNewtonConfig(**bad)
    solver = SolverStaticNewton(straight)
    with pytest.raises(ValueError, match="shape"):
        solver.solve_to(np.zeros((3, 3)), (0, -9.81, 0))
    x = straight.state().vertex_position.to_numpy()
    x[3, 1] = np.nan
    with pytest.raises(ValueError, match="not finite"):
        solver.solve_to(x, (0, -9.81, 0))
