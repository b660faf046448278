"""The "lanes" schedule (``taichi_hair.lanes``: the strand schedule's arithmetic on lanes of eight strands) against the
strand schedule.

The two do the same operations per strand, but the compiler orders and fuses the vector code's products otherwise
(fast math), so they agree to f32 rounding, not to the bit: after 25 dynamic steps the largest position difference is
~3e-8 m on strands of a few centimetres (measured), and the tolerance below is 1e-6 of the largest coordinate.  The
lanes schedule itself is deterministic (the same bits twice).  Each case compiles a variant of the lanes kernel (~12-25 s cold:
it is large), so the cases are few and each covers several branches.
"""


import numpy as np
import pytest

from geometry import curly_strand, move_two_bodies, rotation_matrix
from taichi_hair import GroomBuilder, RodMaterial, SolverADMM, SolverADMMConfig


def _groom():
    """11 strands of 9 vertices (a full group of eight and a padded one), 3 of 14 and one of 3 (padded groups), on two
    moving bodies, with damping on some, elliptic sections (the twist is solved) and one free root."""
    b = GroomBuilder(body_count=2)
    counts = [9] * 11 + [14] * 3 + [3]
    for i, n in enumerate(counts):
        mat = RodMaterial(damping_time=(0.02 if i % 2 == 0 else 0.0), ellipticity=0.2 * (i % 3))
        b.add_strand(curly_strand(n, i), mat, root=("free" if i == 12 else "clamped"), body=i % 2)
    return b.finalize()


def _run(schedule, dual_frame):
    model = _groom()
    st, ctl = model.state(), model.control()
    ctl.air_velocity = (0.1, 0.0, 0.05)
    solver = SolverADMM(model, SolverADMMConfig(iterations=6, schedule=schedule, dual_frame=dual_frame,
                                                air_viscosity=2e-5))
    assert solver.schedule == schedule and not solver.twist_free
    for k in range(25):
        move_two_bodies(ctl, (k + 1) / 25)
        solver.step(st, ctl, 1 / 96)
    return st.to_numpy(), solver


def _assert_close(a, b, rel=1e-6, angle=1e-4):
    """Positions within rel x the largest coordinate [m]; twists within ``angle`` [rad]; every field finite."""
    scale = float(np.max(np.abs(a["vertex_position"])))
    for name in a:
        assert np.isfinite(b[name]).all(), name
    assert np.max(np.abs(a["vertex_position"] - b["vertex_position"])) <= rel * scale
    assert np.max(np.abs(a["edge_twist"] - b["edge_twist"])) <= angle


def test_lanes_equal_the_strand_schedule_to_rounding_on_moving_roots_and_are_deterministic():
    # dual_frame "root" (the default): the local step rotates the duals by each lane's body rotation.  (The "pair"
    # frame, read from the lanes' own frames, passed the same check when written; it is left out here to spare the
    # suite a third compilation of the kernel.)
    a, sa = _run("strand", "root")
    b, sb = _run("lanes", "root")
    assert sb._lanes.group_count == 4 and sb._lanes.padded_lanes == 4 * 8 - 15
    assert np.max(np.abs(a["vertex_velocity"])) > 1e-2  # the scene really moves
    assert np.max(np.abs(a["edge_angular_velocity"])) > 1e-3
    assert sa.iteration_count == sb.iteration_count == 25 * 6
    _assert_close(a, b)
    c, _ = _run("lanes", "root")
    for name in b:
        assert b[name].tobytes() == c[name].tobytes(), name


def test_lanes_equal_the_strand_schedule_quasistatic_twist_free():
    """Straight cantilevers of three lengths under gravity, quasistatic, the twist-free frames (twist "auto")."""
    out = {}
    for schedule in ("strand", "lanes"):
        b = GroomBuilder()
        for i, n in enumerate((5, 17, 33, 17, 17)):
            b.add_strand(np.c_[np.linspace(0.0, 0.03, n), np.zeros(n), np.full(n, 0.01 * i)], RodMaterial())
        model = b.finalize()
        st, ctl = model.state(), model.control()
        solver = SolverADMM(model, SolverADMMConfig(iterations=40, mode="quasistatic", w0=0.2, schedule=schedule,
                                                    anderson_window=0))
        assert solver.twist_free
        for _ in range(5):
            solver.step(st, ctl, 1.0)
        out[schedule] = st.to_numpy()
    rest = model.host["vertex_rest_position"]
    assert np.max(rest[:, 1] - out["strand"]["vertex_position"][:, 1]) > 1e-5  # they sag
    _assert_close(out["strand"], out["lanes"])


def test_lanes_need_the_korner_measure():
    b = GroomBuilder()
    b.add_strand(np.c_[np.linspace(0.0, 0.03, 5), np.zeros(5), np.zeros(5)], RodMaterial())
    with pytest.raises(ValueError, match="schedule='lanes'.*korner"):
        SolverADMM(b.finalize(), SolverADMMConfig(schedule="lanes", strain_measure="bergou"))
    with pytest.raises(ValueError, match=r"tridiagonal='pcr'.*schedule='lanes'"):
        SolverADMMConfig(schedule="lanes", tridiagonal="pcr")


def test_auto_takes_the_lanes_on_a_cpu_only_for_large_models_with_korner_strains(monkeypatch):
    """``schedule = "auto"`` (``lanes.auto_schedule``): "stage" on a GPU or with the PCR solve; on a CPU "lanes" from
    ``AUTO_LANES_VERTICES`` vertices with Korner strains, "strand" one vertex below it or with Bergou's; a solver
    resolves its "auto" so (the threshold set to a 5-vertex Model's size; no step, so nothing compiles the lanes)."""
    from taichi_hair import lanes
    from taichi_hair.lanes import AUTO_LANES_VERTICES as n, auto_schedule

    assert auto_schedule(True, False, True, n) == "stage" and auto_schedule(False, True, True, n) == "stage"
    assert auto_schedule(False, False, True, n) == "lanes"
    assert auto_schedule(False, False, True, n - 1) == "strand" and auto_schedule(False, False, False, n) == "strand"
    b = GroomBuilder()
    b.add_strand(np.c_[np.linspace(0.0, 0.03, 5), np.zeros(5), np.zeros(5)], RodMaterial())
    model = b.finalize()
    assert SolverADMM(model).schedule == "strand"
    monkeypatch.setattr(lanes, "AUTO_LANES_VERTICES", model.vertex_count)
    assert SolverADMM(model).schedule == "lanes"
    assert SolverADMM(model, SolverADMMConfig(strain_measure="bergou")).schedule == "strand"


def test_lanes_with_hair_contacts_follow_the_strand_schedule():
    """A step with contacts runs the z-step between single iterations: the lanes are gathered once per step, take the
    z-step's weights and targets before each iteration and give x back after it.  Twelve wavy strands hang in a tight
    bundle (0.3 mm apart: ~480 hair contacts on 144 vertices) while their root turns.  After one step the two
    schedules differ by rounding (measured 7e-9 m on an Intel Xeon; on an AMD EPYC, where LLVM's vector code rounds
    otherwise, 1.05-1.43e-6 m on 23 of the 144 vertices, the contact counts and statuses equal, the step moving
    vertices 0.23 mm; tolerance 1e-4 of the largest coordinate, 6e-6 m: the lanes without contacts keep 1e-6); in so dense a
    bundle a contact switches at a slightly different iterate now and then and the difference grows (measured 1.0e-5 m
    after 12 steps under Taichi's default IR passes, 8.8e-5 m under ``taichi_hair.init``'s opt_level 0; tolerance 5e-3
    of the largest coordinate, 2.9e-4 m), with the same contact counts within 1 %.  The growth is the bundle's, not
    the lanes': the strand schedule itself, with one strand's input moved by at most 6 nm, ends 1.1e-5 m (default
    passes) / 2.1e-4 m (opt_level 0) from its unmoved run (scratch probe, 2026-12-07).  Then
    one more step with springs pulling two tips 5 mm aside (``set_attachments``, ~10 m/dt^2; the lanes gather them
    once per step, not per iteration): the tips move 3.1-3.3 mm in it, 1.2-1.3 mm of it from the springs (measured),
    the same in both schedules within 5e-5 m (the states already differ by ~1e-5 m; lanes that dropped the springs
    fail it by 1.3 mm)."""
    from taichi_hair import ContactConfig

    out, counts, pulled = {}, {}, {}
    for schedule in ("strand", "lanes"):
        b = GroomBuilder()
        for i in range(12):
            s = np.linspace(0.0, 0.06, 12)
            b.add_strand(np.c_[0.0003 * (i % 4) + 0.002 * np.sin(40 * s + i), -s, 0.0003 * (i // 4) + 0.01 * s],
                         RodMaterial())
        model = b.finalize()
        st, ctl = model.state(), model.control()
        solver = SolverADMM(model, SolverADMMConfig(iterations=6, schedule=schedule, contacts=ContactConfig()))
        for k in range(12):
            ctl.set_body_transform(0, rotation_matrix((0, 0, 1), 0.3 * (k + 1) / 12), (0.0, 0.0, 0.0))
            solver.step(st, ctl, 1 / 96)
            if k == 0:
                out[schedule, "first"] = st.to_numpy()
        out[schedule], counts[schedule] = st.to_numpy(), solver.contact_stats["contacts"]
        tips = np.array([11, 71])
        before = st.positions()[tips]
        solver.set_attachments(tips, before + [0.005, 0.0, 0.0], 3e-3)
        solver.step(st, ctl, 1 / 96)
        pulled[schedule] = st.positions()[tips] - before
    print("tips pulled [mm]", 1e3 * pulled["strand"][:, 0], 1e3 * pulled["lanes"][:, 0])
    assert np.all(pulled["strand"][:, 0] > 1e-3) and np.max(np.abs(pulled["lanes"] - pulled["strand"])) <= 5e-5
    assert counts["strand"] > 400 and abs(counts["lanes"] - counts["strand"]) <= 0.01 * counts["strand"]
    _assert_close(out["strand", "first"], out["lanes", "first"], rel=1e-4, angle=1e-4)
    _assert_close(out["strand"], out["lanes"], rel=5e-3, angle=1e-2)


def test_the_lanes_sin_and_cos_are_within_2_ulp_of_float64_with_every_quadrant_sign():
    """``lanes.layout.sincos`` (Cephes' polynomials on lanes, the remainder r = theta - q pi/2 in float64) against
    numpy's float64 sin and cos of the same float32 angles over |theta| <= 10 rad, zeros and quadrant edges included.
    Closed form: sin and cos themselves; the tolerance is 2 float32 ulp of the value (measured: 1.5), and 1e-7
    absolute near the zeros, where Taichi's fast math once folded the reduction's constants (3e-7 then)."""
    import taichi as ti

    from taichi_hair.lanes.layout import V8

    n = 4096
    theta = np.concatenate([np.linspace(-10.0, 10.0, n * 8 - 16), np.pi / 2 * np.arange(-4, 4), [0.0, -0.0] * 4])
    theta = theta.astype(np.float32).reshape(n, 8)
    t_f, s_f, c_f = (ti.field(V8, n) for _ in range(3))
    t_f.from_numpy(theta)
    _sincos_kernel(t_f, s_f, c_f)
    s, c = s_f.to_numpy(), c_f.to_numpy()
    exact = theta.astype(np.float64)
    for got, want in ((s, np.sin(exact)), (c, np.cos(exact))):
        err = np.abs(got.astype(np.float64) - want)
        ulp = np.spacing(np.abs(want).astype(np.float32)).astype(np.float64)
        assert np.all((err <= 2.0 * ulp) | (err <= 1e-7)), float(np.max(err / ulp))
        assert np.all(np.sign(got[np.abs(want) > 1e-6]) == np.sign(want[np.abs(want) > 1e-6]))


def _sincos_kernel(t_f, s_f, c_f):
    import taichi as ti

    from taichi_hair.lanes.layout import sincos

    @ti.kernel
    def run(t: ti.template(), s: ti.template(), c: ti.template()):
        for i in t:
            s[i], c[i] = sincos(t[i])

    run(t_f, s_f, c_f)
