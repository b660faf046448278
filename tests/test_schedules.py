"""The "stage" and "strand" schedules of SolverADMM give bit-identical states on CPU.

Both schedules call the same per-element ``ti.func`` s in the same order per
element; only the launch structure differs (see ``taichi_hair.schedule_strand``).
"""


import numpy as np
import pytest

from geometry import curly_strand, move_two_bodies
from taichi_hair import GroomBuilder, RodMaterial, SolverADMM, SolverADMMConfig


def _groom(free=True):
    """Strands of different lengths (3 to 40 vertices) on two bodies, mixed damping, one free strand."""
    b = GroomBuilder(body_count=2)
    counts = (12, 3, 25, 40, 7)
    for i, n in enumerate(counts):
        mat = RodMaterial(damping_time=(0.02 if i % 2 == 0 else 0.0), ellipticity=0.2 * (i % 3))
        root = "free" if (free and i == 4) else "clamped"
        b.add_strand(curly_strand(n, i), mat, root=root, body=i % 2)
    return b.finalize()


def _cantilevers():
    b = GroomBuilder()
    for i, n in enumerate((5, 17, 33)):
        b.add_strand(np.c_[np.linspace(0.0, 0.03, n), np.zeros(n), np.full(n, 0.01 * i)], RodMaterial())
    return b.finalize()


def _assert_identical(a, b):
    assert a.keys() == b.keys()
    for name in a:
        assert a[name].dtype == b[name].dtype, name
        assert a[name].tobytes() == b[name].tobytes(), (name, float(np.max(np.abs(a[name] - b[name]))))


def _run_dynamic(schedule, measure, dual_frame="root", warm_start=True, tridiagonal="auto",
                 integrator="backward_euler"):
    model = _groom()
    st, ctl = model.state(), model.control()
    ctl.air_velocity = (0.1, 0.0, 0.05)
    cfg = SolverADMMConfig(iterations=6, strain_measure=measure, schedule=schedule, dual_frame=dual_frame,
                           warm_start_duals=warm_start, air_viscosity=2e-5, tridiagonal=tridiagonal,
                           integrator=integrator)
    solver = SolverADMM(model, cfg)
    assert solver.schedule == schedule
    for k in range(25):
        move_two_bodies(ctl, (k + 1) / 25)
        solver.step(st, ctl, 1 / 96)
    return st.to_numpy(), solver


@pytest.mark.parametrize("measure, dual_frame, warm_start", [("korner", "root", True), ("bergou", "pair", False)])
def test_dynamic_moving_roots_identical(measure, dual_frame, warm_start):
    a, sa = _run_dynamic("stage", measure, dual_frame, warm_start)
    b, sb = _run_dynamic("strand", measure, dual_frame, warm_start)
    # The scene really moves (the roots rotate, strands swing and twist).
    assert np.max(np.abs(a["vertex_velocity"])) > 1e-2
    assert np.max(np.abs(a["edge_angular_velocity"])) > 1e-3
    assert sa.iteration_count == sb.iteration_count == 25 * 6
    _assert_identical(a, b)
    if measure == "korner":
        # PCR is still usable with the stage schedule: same motion up to f32 round-off.
        c, sc = _run_dynamic("stage", measure, tridiagonal="pcr")
        assert sc.tridiagonal_method == "pcr"
        scale = np.max(np.abs(a["vertex_position"]))
        assert np.max(np.abs(c["vertex_position"] - b["vertex_position"])) < 1e-5 * scale


def test_dynamic_bdf2_identical():
    """BDF2 (the origins written by begin_step, h = 2 dt / 3 in the assembly): still the same bits."""
    a, _ = _run_dynamic("stage", "korner", integrator="bdf2")
    b, _ = _run_dynamic("strand", "korner", integrator="bdf2")
    assert np.max(np.abs(a["vertex_velocity"])) > 1e-2
    _assert_identical(a, b)


@pytest.mark.parametrize("measure", ["korner", "bergou"])
def test_quasistatic_cantilever_identical(measure):
    out = {}
    for schedule in ("stage", "strand"):
        model = _cantilevers()
        st, ctl = model.state(), model.control()
        # twist="solve": the straight cantilevers would otherwise drop the twist stage (fidelity.py), whose
        # schedule identity tests/test_fidelity.py checks.
        cfg = SolverADMMConfig(iterations=40, mode="quasistatic", w0=0.2, strain_measure=measure, schedule=schedule,
                               twist="solve")
        solver = SolverADMM(model, cfg, profile=True)
        for _ in range(5):
            solver.step(st, ctl, 1.0)
        out[schedule] = st.to_numpy()
        # Profiling: the strand schedule records its fused loop under "iterations".
        t = solver.stage_seconds
        if schedule == "strand":
            assert t["iterations"] > 0 and t["local"] == t["global"] == t["twist"] == 0
        else:
            assert t["iterations"] == 0 and min(t["local"], t["global"], t["frames"], t["twist"]) > 0
    # The cantilevers sag under gravity.
    rest = _cantilevers().host["vertex_rest_position"]
    assert np.max(rest[:, 1] - out["stage"]["vertex_position"][:, 1]) > 1e-5
    _assert_identical(out["stage"], out["strand"])


def test_schedule_resolution_and_tridiagonal_method():
    model = _cantilevers()
    # CPU: auto -> strand, which always solves with Thomas.
    s = SolverADMM(model, SolverADMMConfig())
    assert (s.schedule, s.tridiagonal_method) == ("strand", "thomas")
    s = SolverADMM(model, SolverADMMConfig(schedule="strand", tridiagonal="thomas"))
    assert (s.schedule, s.tridiagonal_method) == ("strand", "thomas")
    s = SolverADMM(model, SolverADMMConfig(schedule="stage"))
    assert (s.schedule, s.tridiagonal_method) == ("stage", "thomas")
    # An explicit PCR request keeps the stage schedule under auto.
    s = SolverADMM(model, SolverADMMConfig(tridiagonal="pcr"))
    assert (s.schedule, s.tridiagonal_method) == ("stage", "pcr")
    with pytest.raises(ValueError, match=r"SolverADMMConfig\.tridiagonal.*SolverADMMConfig\.schedule"):
        SolverADMMConfig(schedule="strand", tridiagonal="pcr")
    cfg = SolverADMMConfig(schedule="strand")
    cfg.tridiagonal = "pcr"  # changed after validation: the solver checks again
    with pytest.raises(ValueError, match=r"SolverADMMConfig\.tridiagonal.*SolverADMMConfig\.schedule"):
        SolverADMM(model, cfg)
    with pytest.raises(ValueError, match=r"SolverADMMConfig\.schedule"):
        SolverADMMConfig(schedule="vertex")
