"""Sag-free rest pose (issue 14): the statics of :mod:`taichi_hair.solvers.rest_pose`.

Closed forms pinned here:

* a straight horizontal strand: the solved rest moment of pair i is the moment about vertex i of the weight
  carried beyond it, |mu_i| = |sum_{k > i} (x_k - x_i) x m_k g| (exact for the discrete model: with straight
  edges the recursion G_j = sum_{k > j} f_k, u_j = u_{j+1} + e_j x G_j is the moment recursion);
* the solved rest pose makes the authored shape an equilibrium of the solver's own energy: the quasistatic
  ADMM solve started there stays there (float32), while the authored rest pose sags.
"""

import numpy as np
import pytest

from taichi_hair import GroomBuilder, RodMaterial, SolverADMM, SolverADMMConfig
from taichi_hair.solvers.rest_pose import (
    RestPoseConfig,
    apply_rest_pose,
    clear_rest_pose,
    pair_strain_jacobians,
    rest_frames,
    solve_rest_pose,
)

HAIR = RodMaterial()


def horizontal(L, n):
    return np.c_[np.linspace(0.0, L, n), np.zeros(n), np.zeros(n)]


def wavy(L, n, amp=0.002, turns=1.0):
    s = np.linspace(0.0, L, n)
    return np.c_[0.3 * s, -0.95 * s + amp * np.sin(2 * np.pi * turns * s / L), amp * np.cos(2 * np.pi * turns * s / L)]


@pytest.mark.parametrize("measure", ["korner", "bergou"])
def test_numpy_strains_equal_the_solver_rest_strains_and_their_jacobians_finite_differences(measure):
    """The float64 NumPy strains equal the solver's rest strains (f32 frames transported along 24 edges:
    within 1e-5 rad, measured 2.5e-6 at the tip) and their edge
    Jacobians match central differences of the strains (relative 1e-6, step 1e-7 of an edge)."""
    b = GroomBuilder()
    b.add_strand(wavy(0.05, 21), HAIR)
    model = b.finalize()
    solver = SolverADMM(model, SolverADMMConfig(strain_measure=measure, twist="solve"))
    rk = solver.buf.pair_rest_kappa.to_numpy()
    h = model.host
    m1, m2, t, e, le = rest_frames(h)
    ip = np.nonzero(h["pair_is_active"])[0]
    a = ip - 1
    th = h["edge_rest_twist"]
    kappa, Ja, Jb, _, _ = pair_strain_jacobians(measure, m1[a], m2[a], t[a], le[a], m1[ip], m2[ip], t[ip], le[ip],
                                                twist=th[ip] - th[a])
    assert np.max(np.abs(kappa - rk[ip])) < 1e-5
    assert np.max(np.abs(kappa)) > 1e-2  # the wave is curved: the check is not on zeros

    # Finite differences: move edge b of pair k (parallel-transporting its frame, the strains' convention).
    def strain_of(ea, eb, k):
        la, lb = np.linalg.norm(ea), np.linalg.norm(eb)
        ta, tb = ea / la, eb / lb

        def transport(u, t0, t1):
            bb = np.cross(t0, t1)
            c = t0 @ t1
            return c * u + np.cross(bb, u) + (bb @ u) / (1 + c) * bb
        m1a, m2a = transport(m1[a[k]], t[a[k]], ta), transport(m2[a[k]], t[a[k]], ta)
        m1b, m2b = transport(m1[ip[k]], t[ip[k]], tb), transport(m2[ip[k]], t[ip[k]], tb)
        # Bergou's kappa_3: the angle from frame a, transported along the curve to edge b, to frame b.
        ma = transport(m1a, ta, tb)
        twist = np.arctan2(np.cross(ma, m1b) @ tb, ma @ m1b)
        return pair_strain_jacobians(measure, m1a[None], m2a[None], ta[None], np.array([la]), m1b[None], m2b[None],
                                     tb[None], np.array([lb]), twist=np.array([twist]))[0][0]

    for k in (0, 7, 15):
        ea, eb = e[a[k]], e[ip[k]]
        step = 1e-7 * le[ip[k]]
        for c in range(3):
            d = np.zeros(3)
            d[c] = step
            fd_b = (strain_of(ea, eb + d, k) - strain_of(ea, eb - d, k)) / (2 * step)
            fd_a = (strain_of(ea + d, eb, k) - strain_of(ea - d, eb, k)) / (2 * step)
            scale = np.max(np.abs(Jb[k])) + np.max(np.abs(Ja[k]))
            assert np.max(np.abs(fd_b - Jb[k][:, c])) < 1e-6 * scale
            assert np.max(np.abs(fd_a - Ja[k][:, c])) < 1e-6 * scale


def test_horizontal_strand_rest_moment_is_the_weight_carried_beyond_each_vertex():
    """|mu_i| = |sum_{k>i} (x_k - x_i) x m_k g| for a straight horizontal strand (relative 1e-9, float64);
    kappa_bar_i = -mu_i / S_i with S_i = E I / v_i* the solver's stiffness; the tension is 0 (horizontal)."""
    L, n = 0.05, 21
    b = GroomBuilder()
    b.add_strand(horizontal(L, n), HAIR)
    model = b.finalize()
    g = np.array([0.0, -9.81, 0.0])
    res = solve_rest_pose(model, SolverADMMConfig(), gravity=g)
    assert not res.unheld
    h = model.host
    x = h["vertex_rest_position"]
    mass = h["vertex_mass"]
    for i in range(1, n - 1):
        M = np.sum(np.cross(x[i + 1:] - x[i], mass[i + 1:, None] * g[None]), axis=0)
        assert abs(np.linalg.norm(res.pair_rest_moment[i]) / np.linalg.norm(M) - 1.0) < 1e-9, i
    # The root moment of a uniform cantilever: lambda L^2 / 2 with lambda = rho A g (lumped: within 1 %).
    lam = HAIR.density * HAIR.area * 9.81
    assert abs(np.linalg.norm(res.pair_rest_moment[1]) / (lam * (L - x[1, 0]) ** 2 / 2) - 1) < 0.01
    vstar = model.pair_voronoi_length(True)
    S = h["pair_bending_modulus"] / vstar[:, None]
    ip = np.arange(1, n - 1)
    np.testing.assert_allclose(res.pair_rest_strain[ip, :2], -res.pair_rest_moment[ip, :2] / S[ip, :2], rtol=1e-12)
    np.testing.assert_allclose(res.edge_rest_length, h["edge_rest_length"], rtol=1e-12)  # no tension
    assert res.strand_residual[0] < 1e-12


def test_authored_shape_is_an_equilibrium_of_the_solver_with_the_sag_free_rest_pose():
    """Quasistatic ADMM from the authored shape: with the solved rest pose the tip stays within 1 um
    (float32 round-off of moments ~1e-7 N m), without it the 5 cm horizontal strand's tip sags > 1 mm.
    Also a wavy hanging strand (tension and twist): within 1 um, and clearing the rest pose restores the sag."""
    b = GroomBuilder()
    b.add_strand(horizontal(0.05, 21), HAIR)
    b.add_strand(wavy(0.06, 25) + [0.0, 0.0, 0.02], HAIR)
    model = b.finalize()
    cfg = SolverADMMConfig(mode="quasistatic", iterations=10)
    x0 = model.host["vertex_rest_position"].copy()

    def settle(steps=400):
        solver = SolverADMM(model, cfg)
        st, ctl = model.state(), model.control()
        for _ in range(steps):
            solver.step(st, ctl, 1.0)
        return np.linalg.norm(st.vertex_position.to_numpy() - x0, axis=1)

    authored = settle()
    res = solve_rest_pose(model, cfg)
    assert not res.unheld, res.unheld
    apply_rest_pose(model, res)
    held = settle()
    assert authored[20] > 1e-3, authored[20]
    assert held.max() < 1e-6, held.max()
    clear_rest_pose(model)
    assert abs(settle()[20] - authored[20]) < 1e-6


def test_a_strand_too_heavy_to_hold_is_reported_and_keeps_its_authored_rest_pose():
    """A 40 cm horizontal strand needs a rest strain change above 1 (> 60 degrees per vertex): reported by index
    with its turn; a free strand too; the short strand beside them is solved."""
    b = GroomBuilder()
    b.add_strand(horizontal(0.02, 9), HAIR)
    b.add_strand(horizontal(0.4, 81) + [0, 0, 0.01], HAIR)
    b.add_strand(horizontal(0.02, 9) + [0, 0, 0.02], HAIR, root="free")
    model = b.finalize()
    res = solve_rest_pose(model, SolverADMMConfig(), config=RestPoseConfig(max_rest_change=1.0))
    assert [s for s, _ in res.unheld] == [1, 2]
    assert "rest turn" in res.unheld[0][1] and "free" in res.unheld[1][1]
    assert np.all(res.pair_rest_moment[model.host["vertex_strand"] == 1] == 0.0)
    assert np.any(res.pair_rest_moment[model.host["vertex_strand"] == 0] != 0.0)
    assert "1/3 strands" in res.summary() or "strand 1" in res.summary()


def test_a_rest_pose_for_another_strain_measure_is_refused():
    b = GroomBuilder()
    b.add_strand(horizontal(0.02, 9), HAIR)
    model = b.finalize()
    apply_rest_pose(model, solve_rest_pose(model, SolverADMMConfig(strain_measure="bergou")))
    with pytest.raises(ValueError, match="strain measure 'bergou'"):
        SolverADMM(model, SolverADMMConfig(strain_measure="korner"))


def test_rest_curve_round_trips_the_rest_moments_and_has_the_rest_strains():
    """rest_curve(kappa_bar) is a polyline (with twists) whose Korner strains are kappa_bar (1e-9, float64), with
    the authored root edge and the solved rest lengths; moments_from_rest_curve gives back mu (relative 1e-7);
    the rest curve of a horizontal strand bends upwards (it sags into the authored shape)."""
    from taichi_hair.solvers.rest_curve import moments_from_rest_curve, rest_curve

    b = GroomBuilder()
    b.add_strand(horizontal(0.05, 21), HAIR)
    b.add_strand(wavy(0.06, 25) + [0.0, 0.0, 0.02], HAIR)
    model = b.finalize()
    res = solve_rest_pose(model, SolverADMMConfig())
    apply_rest_pose(model, res)
    xr, tw = rest_curve(model, res.pair_rest_strain, res.edge_rest_length)
    h = model.host
    np.testing.assert_allclose(xr[[0, 1, 21, 22]], h["vertex_rest_position"][[0, 1, 21, 22]], atol=1e-15)
    le = np.linalg.norm(np.diff(xr, axis=0), axis=1)
    real = h["edge_rest_length"][:-1] > 0
    np.testing.assert_allclose(le[real], h["edge_rest_length"][:-1][real], rtol=1e-12)
    assert xr[20, 1] > 1e-3  # the horizontal strand's rest tip sits above its authored (y = 0) tip
    mu = moments_from_rest_curve(model, xr, tw)
    ref = res.pair_rest_moment
    assert np.max(np.abs(mu - ref)) < 1e-7 * np.max(np.abs(ref))


def _cli(*args, cwd=None):
    import os
    import subprocess
    import sys

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = dict(os.environ, PYTHONPATH=root + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-m", "taichi_hair.cli", *args], capture_output=True, text=True, cwd=cwd or root,
                          env=env, timeout=600)


@pytest.mark.parametrize("ext", [".thair.npz", ".usdc"])
def test_rest_pose_command_writes_a_rest_curve_that_a_scene_reads_back_as_an_equilibrium(tmp_path, ext):
    """taichi-hair rest-pose on a groom with a broken strand (zero-length edge) and one too heavy to hold: exit 0,
    both named by index, the rest solved; the written rest curve read by a scene with rest_pose = "file"
    gives the solved equilibrium back, against ~1 for the authored rest pose.  The native file keeps float64
    (residual 5e-7 of the weight: the bending stiffness read back uses the authored rest lengths, the solve
    the tension-corrected ones, 1e-6 apart; bound 1e-5); USD stores points and rest points as float32, and the moment is a small
    difference of two curvatures: residual 2.1e-3 of the weight measured on the short wavy strand (bound
    5e-3; a force imbalance of 0.2 % of its weight)."""
    from taichi_hair.io import load_groom, save_groom
    from taichi_hair.io.groom import Groom
    from taichi_hair.scene.file import load_scene
    from taichi_hair.solvers.rest_pose import equilibrium_residual

    broken = horizontal(0.02, 9) + [0, 0, 0.02]
    broken[4] = broken[3]
    polys = [wavy(0.06, 25), horizontal(0.4, 81) + [0, 0, 0.01], broken, horizontal(0.03, 13) + [0, 0, 0.03]]
    src = tmp_path / "g.thair.npz"
    save_groom(Groom.from_polylines(polys, units="m"), str(src))
    out = tmp_path / ("sag" + ext)
    p = _cli("rest-pose", str(src), "--units", "m", "--out", str(out))
    assert p.returncode == 0, p.stderr
    assert "strand 1:" in p.stdout and "strand 2:" in p.stdout and "zero-length edge" in p.stdout, p.stdout
    assert "2/4 strands sag-free" in p.stdout, p.stdout
    g = load_groom(str(out))
    assert g.rest_points is not None and g.rest_twist is not None
    np.testing.assert_allclose(g.points, Groom.from_polylines(polys).points, atol=1e-7)
    off = g.strand_offsets
    assert np.abs(g.rest_points[off[3]:off[4]] - g.points[off[3]:off[4]]).max() > 1e-4  # rest curve differs
    np.testing.assert_array_equal(g.rest_points[off[1]:off[3]], g.points[off[1]:off[3]])  # not held: authored
    keep = Groom.from_polylines([g.strand(0), g.strand(3)], units="m")
    keep.rest_points = np.concatenate([g.rest_points[off[0]:off[1]], g.rest_points[off[3]:off[4]]])
    keep.rest_twist = np.concatenate([g.rest_twist[off[0]:off[1]], g.rest_twist[off[3]:off[4]]])
    kept = tmp_path / ("kept" + ext)
    save_groom(keep.validate(), str(kept))
    scene = tmp_path / "s.toml"
    scene.write_text(f'[groom]\nfile = "{kept.name}"\nunits = "m"\nrest_pose = "file"\n[solver]\ntype = "admm"\n')
    sc = load_scene(str(scene))
    model = sc.build_model()
    tol = 5e-3 if ext == ".usdc" else 1e-5
    assert np.nanmax(sc.rest_pose_result.strand_residual) < tol, sc.rest_pose_result.strand_residual
    assert np.nanmax(equilibrium_residual(model, sc.solver_config)) < tol
    scene.write_text(f'[groom]\nfile = "{kept.name}"\nunits = "m"\n[solver]\ntype = "admm"\n')
    assert np.nanmin(equilibrium_residual(load_scene(str(scene)).build_model())) > 0.3


def test_primed_duals_keep_a_sag_free_strand_still_in_the_dynamic_mode():
    """Dynamic ADMM (dt = 1/96 s, 2 s) from a sag-free equilibrium: with the duals primed at the fixed point
    (SolverADMM.prime_duals) no vertex moves more than 1 um (measured 0.34 um, float32); with zero duals the
    first steps sag while the duals build up (measured 117 um), the transient the priming removes."""
    b = GroomBuilder()
    b.add_strand(horizontal(0.05, 21), HAIR)
    b.add_strand(wavy(0.06, 25) + [0.0, 0.0, 0.02], HAIR)
    model = b.finalize()
    cfg = SolverADMMConfig()
    apply_rest_pose(model, solve_rest_pose(model, cfg))
    x0 = model.host["vertex_rest_position"].copy()
    drift = {}
    for prime in (False, True):
        solver = SolverADMM(model, cfg)
        st, ctl = model.state(), model.control()
        if prime:
            solver.prime_duals(st, ctl, 1 / 96)
        worst = 0.0
        for _ in range(192):
            solver.step(st, ctl, 1 / 96)
            worst = max(worst, float(np.linalg.norm(st.vertex_position.to_numpy() - x0, axis=1).max()))
        drift[prime] = worst
    assert drift[True] < 1e-6, drift
    assert drift[False] > 20 * drift[True], drift


def test_grooming_session_keeps_a_sag_free_groom_through_an_edit_and_a_new_gravity(tmp_path):
    """GroomingSession(rest_pose = "sag-free"): after 60 quasistatic frames the guides sit within 1 um of their
    rest shape (p90; measured 10 nm) and the residual is round-off, against a sag of > 1 mm when authored;
    a length edit and a new gravity re-solve the rest pose (still within 1 um); the config is saved with the groom
    and a reopened session solves it again."""
    from taichi_hair.groom.config import GroomingConfig
    from taichi_hair.groom.session import GroomingSession

    polys = [horizontal(0.05, 21) + [0, 0, 0.01 * k] for k in range(4)] + \
        [wavy(0.06, 25) + [0.01 * k, 0, 0.05] for k in range(4)]
    reports = {}
    for rp in ("authored", "sag-free"):
        s = GroomingSession(polys, GroomingConfig(rest_pose=rp, guide_ratio=1.0, contacts=False))
        s.advance(60)
        reports[rp] = s.rest_pose_report()
    assert reports["authored"]["drift_p90_m"] > 1e-3 and reports["authored"]["residual_max"] > 0.3
    assert reports["sag-free"]["drift_p90_m"] < 1e-6 and reports["sag-free"]["residual_max"] < 1e-9
    assert reports["sag-free"]["strands_held"] == 8
    s.select_all()
    s.scale_length(0.8)
    s.advance(60)
    assert s.rest_pose_report()["drift_p90_m"] < 1e-6
    s.set_parameter("gravity", (0.0, -20.0, 0.0))
    s.advance(60)
    r = s.rest_pose_report()
    assert r["drift_p90_m"] < 1e-6 and r["residual_max"] < 1e-9
    # Saved with the groom: reopening solves the rest pose again.
    s.save(str(tmp_path / "saved.thair.npz"))
    reopened = GroomingSession.open(str(tmp_path / "saved.thair.npz"), autosave=False)
    assert reopened.config.rest_pose == "sag-free"
    reopened.advance(10)
    assert reopened.rest_pose_report()["strands_held"] == 8


def test_grooming_rest_max_change_lets_the_session_hold_a_guide_that_1_leaves_to_sag():
    """GroomingConfig.rest_max_change (RestPoseConfig.max_rest_change): a 15 cm horizontal guide of 9 vertices needs a
    rest strain change of 1.65 (solve_rest_pose, measured) to hold its own weight, so 1.0 (RestPoseConfig's default)
    leaves it to sag (> 1 mm after 60 quasistatic frames, without the shape springs that would hold it:
    ``unheld_shape_weight`` 0) while the 5 cm guide beside it is held; with 1.9 (the
    grooming default) both guides are held
    and every vertex stays within 1 um of its authored place (p90 and max).  Set in a running session, the rest
    pose is solved again (both held; the state goes on from where it is).  A value <= 0 is a one-line error naming
    the field."""
    from taichi_hair.groom.config import GroomingConfig
    from taichi_hair.groom.session import GroomingSession

    polys = [horizontal(0.15, 9), horizontal(0.05, 21) + [0, 0, 0.01]]
    assert GroomingConfig().rest_max_change == 1.9
    reports = {}
    for change in (1.0, 1.9):
        s = GroomingSession(polys, GroomingConfig(rest_pose="sag-free", rest_max_change=change, guide_ratio=1.0,
                                                  contacts=False, unheld_shape_weight=0.0))
        s.advance(60)
        reports[change] = s.rest_pose_report()
    assert reports[1.0]["strands_held"] == 1 and reports[1.0]["drift_max_m"] > 1e-3
    assert reports[1.9]["strands_held"] == 2
    assert reports[1.9]["drift_p90_m"] < 1e-6 and reports[1.9]["drift_max_m"] < 1e-6
    s.set_parameter("rest_max_change", 1.0)
    s.advance(1)
    assert s.rest_pose_report()["strands_held"] == 1
    with pytest.raises(ValueError, match="rest_max_change"):
        GroomingConfig(rest_max_change=0.0)


def test_a_sag_free_grooming_edit_solves_only_the_edited_guides_and_equals_a_whole_solve(monkeypatch):
    """GroomingSession(rest_pose = "sag-free"): a length edit of one of eight guides solves the rest pose of that
    guide alone (``rest_pose_edit.resolve_rest_pose``: a Model of 1 strand is solved), and the session's rest
    pose equals a solve of the whole edited guide Model within 1e-9 of the largest moment; a new gravity
    solves all eight again."""
    from types import SimpleNamespace

    import taichi_hair.solvers.rest_pose_edit as rpe
    from taichi_hair.groom.config import GroomingConfig
    from taichi_hair.groom.session import GroomingSession

    polys = [wavy(0.06, 25, turns=1.0 + 0.2 * k) + [0.01 * k, 0, 0.02 * (k % 2)] for k in range(8)]
    s = GroomingSession(polys, GroomingConfig(rest_pose="sag-free", guide_ratio=1.0, contacts=False))
    s.advance(1)
    solved = []
    real = rpe.solve_rest_pose
    monkeypatch.setattr(rpe, "solve_rest_pose", lambda m, *a, **k: solved.append(m.strand_count) or real(m, *a, **k))
    s.select_strands([3])
    s.scale_length(1.2)
    s.advance(1)
    assert solved == [1]
    sim = s._sim
    authored = sim._authored_host
    whole = solve_rest_pose(SimpleNamespace(host=authored, vertex_count=sim.model.vertex_count,
                                            strand_count=sim.model.strand_count), sim.solver_config)
    mine = sim.rest_pose_result.pair_rest_moment
    assert np.abs(mine - whole.pair_rest_moment).max() <= 1e-9 * np.abs(whole.pair_rest_moment).max()
    assert sim.rest_pose_result.held_count == 8
    s.set_parameter("gravity", (0.0, -12.0, 0.0))
    s.advance(1)
    assert solved == [1]  # a new gravity: the whole Model again (solve_rest_pose in the session, not here)
    assert s.rest_pose_report()["residual_max"] < 1e-9


def test_soft_material_with_rest_length_correction_gets_a_warning_naming_the_strand():
    """Issue 12 doubt (c): with ContactConfig.correction_lengths='rest' the end-of-step correction would erase the
    stretch of a material that stretches rho g L / E_s > 1e-3 under its weight: a warning names the strand;
    hair (E_s = 3 GPa, 1e-6) and correction_lengths='before' get none."""
    import warnings

    from taichi_hair.config import ContactConfig

    b = GroomBuilder()
    b.add_strand(wavy(0.06, 25), HAIR)
    b.add_strand(wavy(0.06, 25) + [0, 0, 0.01], RodMaterial(youngs_modulus_stretch=2e3))
    soft = b.finalize()
    with pytest.warns(UserWarning, match="strand 1 stretches"):
        SolverADMM(soft, SolverADMMConfig(contacts=ContactConfig()))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        SolverADMM(soft, SolverADMMConfig(contacts=ContactConfig(correction_lengths="before")))
        hb = GroomBuilder()
        hb.add_strand(wavy(0.06, 25), HAIR)
        SolverADMM(hb.finalize(), SolverADMMConfig(contacts=ContactConfig()))


def test_stability_check_finds_an_upright_strand_above_its_self_weight_buckling_length():
    """A straight upright strand is an equilibrium with no rest moment at all (held), but above Greenhill's
    self-weight buckling length L_c = 1.986 (E I / (rho A g))^(1/3) (8.6 cm for human hair, R = 37 um) it is an
    unstable one: check_stability (2 s without contacts, every strand tipped about its root by 0.1 mm at the
    tip) flags the 15 cm strand (falls by more than 1 mm) and neither the 4 cm upright one nor a short
    horizontal one (they stay within 0.2 mm: the perturbation itself is 0.1 mm)."""
    from taichi_hair.solvers.rest_pose import check_stability

    up = lambda L, n: np.c_[np.zeros(n), np.linspace(0.0, L, n), np.zeros(n)]  # noqa: E731
    b = GroomBuilder()
    b.add_strand(up(0.15, 31), HAIR)
    b.add_strand(up(0.04, 9) + [0.02, 0, 0], HAIR)
    b.add_strand(horizontal(0.03, 13) + [0, 0, 0.02], HAIR)
    model = b.finalize()
    cfg = SolverADMMConfig()
    res = solve_rest_pose(model, cfg)
    assert not res.unheld
    apply_rest_pose(model, res)
    check_stability(model, res, cfg)
    assert [s for s, _ in res.unstable] == [0], (res.unstable, res.strand_stability_drift)
    assert res.strand_stability_drift[1] < 2e-4 and res.strand_stability_drift[2] < 2e-4
    assert "unstable" in res.summary()


def test_rest_pose_command_names_roots_off_the_body_and_strands_inside_it(tmp_path):
    """taichi-hair rest-pose --body MESH: a strand rooted 3 cm off the sphere and one that starts inside it are
    named on stderr (one line each), exit 0, and the strand on the body is solved all the same."""
    import trimesh

    from taichi_hair.io import save_groom
    from taichi_hair.io.groom import Groom

    mesh = trimesh.creation.icosphere(subdivisions=3, radius=0.05)
    body = tmp_path / "ball.obj"
    mesh.export(str(body))
    on = np.c_[np.zeros(9), 0.05 + np.linspace(0, 0.02, 9), np.zeros(9)]        # root on top, growing up
    off = on + [0.0, 0.03, 0.0]                                                # root 3 cm above the surface
    inside = np.c_[np.zeros(9), np.linspace(0.05, 0.03, 9), np.full(9, 0.001)]  # grows into the ball
    src = tmp_path / "g.thair.npz"
    save_groom(Groom.from_polylines([on, off, inside], units="m"), str(src))
    p = _cli("rest-pose", str(src), "--units", "m", "--body", str(body), "--no-check", "--out",
             str(tmp_path / "o.thair.npz"))
    assert p.returncode == 0, p.stderr
    assert "from the body: 1 of 3 strands (farthest: strand 1, " in p.stderr, p.stderr
    assert "inside the body at the start: 1 strands (first: strand 2;" in p.stderr, p.stderr
    assert "3/3 strands sag-free" in p.stdout, p.stdout


def test_prestress_weight_keeps_the_admm_iteration_at_a_curly_sag_free_equilibrium():
    """The hang scene's curly strands (20 cm, 2 mm curls) sag-free, quasistatic ADMM at the default w0 = 1 from
    the authored shape: within 10 um after 600 steps (measured 2.8 um).  The Gauss-Newton local step leaves out
    mu . d2kappa; without the prestress weight (PRESTRESS_WEIGHT = 0) the iteration leaves the equilibrium
    (measured 17 cm after 200 steps on 20 strands with the plain iteration; here, with the default Anderson
    acceleration, 0.55 mm after 300 steps: bound 0.1 mm)."""
    import taichi_hair.solver_admm as sa
    from taichi_hair.scene.builtin import HangScene, build_hang

    model = build_hang(HangScene(strands=5, length=0.2, seed=0))
    cfg = SolverADMMConfig(mode="quasistatic")
    apply_rest_pose(model, solve_rest_pose(model, cfg))
    x0 = model.host["vertex_rest_position"].copy()

    def drift(steps):
        solver = SolverADMM(model, cfg)
        st, ctl = model.state(), model.control()
        solver.prime_duals(st, ctl)
        for _ in range(steps):
            solver.step(st, ctl, 1.0)
        return float(np.linalg.norm(st.vertex_position.to_numpy() - x0, axis=1).max())

    assert drift(600) < 1e-5
    saved = sa.PRESTRESS_WEIGHT
    try:
        sa.PRESTRESS_WEIGHT = 0.0
        assert drift(300) > 1e-4
    finally:
        sa.PRESTRESS_WEIGHT = saved


def _floor_support(model, friction):
    """Every free vertex of the Model may lean on a floor under it (outward normal +y)."""
    from taichi_hair.solvers.rest_support import ContactSupport

    free = np.nonzero(model.host["vertex_is_fixed"] == 0)[0]
    return ContactSupport(vertex=free, normal=np.tile([0.0, 1.0, 0.0], (free.size, 1)), friction=friction)


def test_a_strand_lying_on_the_floor_needs_no_rest_moment_the_floor_carries_its_weight():
    """Issue 14 item 1, contacts in the statics.  A horizontal 30 cm strand lying on a floor (alone it is not
    held: it would need a rest turn of ~1.4 rad per edge at the root): the rule (the smallest change of rest
    strain, forces in the Coulomb cones) has the exact optimum 0: each free vertex's weight carried by the
    floor, f_i = -m_i g, and no moment anywhere.  A 5 cm strand beside it holds itself and gets no force
    (support only for strands that cannot hold themselves).  Tolerances: moments below 1e-4 of the unsupported root moment; the
    floor's forces in total within 1e-3 of the weight, each within 3 % (the objective is flat in the forces:
    a vertex's force error of 1 % changes its neighbours' rest strain by ~2e-7; accelerated projected gradient,
    2,000 iterations, float64)."""
    L, n = 0.30, 121
    b = GroomBuilder()
    b.add_strand(horizontal(L, n), HAIR)
    b.add_strand(horizontal(0.05, 21) + [0.0, 0.0, 0.01], HAIR)
    model = b.finalize()
    g = np.array([0.0, -9.81, 0.0])
    bare = solve_rest_pose(model, SolverADMMConfig(), gravity=g)
    assert [s for s, _ in bare.unheld] == [0]
    res = solve_rest_pose(model, SolverADMMConfig(), gravity=g, support=_floor_support(model, 0.3))
    assert not res.unheld and not res.friction_limited
    x, mass = model.host["vertex_rest_position"], model.host["vertex_mass"]
    root = np.linalg.norm(np.sum(np.cross(x[2:n] - x[1], mass[2:n, None] * g[None]), axis=0))  # unsupported
    assert np.abs(res.pair_rest_moment[:n]).max() < 1e-4 * root
    assert np.all(res.vertex_support_force[n:] == 0.0)       # the 5 cm strand holds itself
    np.testing.assert_allclose(res.pair_rest_moment[n:], bare.pair_rest_moment[n:], rtol=1e-12)
    free = model.host["vertex_is_fixed"] == 0
    free[n:] = False
    expected = -model.host["vertex_mass"][free, None] * g[None]
    assert abs(res.vertex_support_force[free, 1].sum() / expected[:, 1].sum() - 1.0) < 1e-3
    np.testing.assert_allclose(res.vertex_support_force[free], expected, atol=0.03 * np.abs(expected).max())
    assert np.all(res.vertex_support_force[~free] == 0.0)
    # The statics are exact for the forces found: the solver's own residual with them as loads.
    assert np.nanmax(res.strand_residual) < 1e-9


@pytest.mark.parametrize("slope", [0.2, 0.5])
def test_friction_carries_a_sideways_slope_up_to_mu_and_bending_carries_the_rest(slope):
    """The floor of the test above with gravity tilted sideways (across the strand, along z) by tan(alpha) =
    ``slope``, friction mu = 0.3 (the 30 cm strand).  Within the cone (0.2 < mu) friction holds every vertex: no moment, the
    floor's force minus the weight.  Beyond it (0.5) each vertex's weight lies outside the cone, and the rule
    (smallest change of rest strain) takes the force nearest to it, the cone projection of the weight:
    f_n = m g cos(alpha) + mu q / (1 + mu^2) with q = m g (sin(alpha) - mu cos(alpha)) and |f_t| = mu f_n
    (a little more pressure buys more friction), leaving every vertex the same residual load
    |r| = q / sqrt(1 + mu^2) for bending: the moment at the first free pair is |r| sum_{k>1} (x_k - x_1)
    (closed form; tolerances 1e-3 on the forces, 1 % on the moment), and the strand is reported as held by
    friction at its limit."""
    L, n, mu = 0.30, 121, 0.3
    b = GroomBuilder()
    b.add_strand(horizontal(L, n), HAIR)
    model = b.finalize()
    a = np.arctan(slope)
    g = 9.81 * np.array([0.0, -np.cos(a), -np.sin(a)])
    res = solve_rest_pose(model, SolverADMMConfig(), gravity=g, support=_floor_support(model, mu))
    assert not res.unheld
    h = model.host
    x, mass = h["vertex_rest_position"], h["vertex_mass"]
    free = h["vertex_is_fixed"] == 0
    f = res.vertex_support_force[free]
    mg = mass[free] * 9.81
    if slope < mu:
        np.testing.assert_allclose(f, -mass[free, None] * g[None], rtol=1e-3, atol=1e-3 * mg.max())
        assert np.abs(res.pair_rest_moment).max() < 1e-4 * mg.sum() * L
        assert not res.friction_limited
    else:
        q = mg * (np.sin(a) - mu * np.cos(a))
        np.testing.assert_allclose(f[:, 1], mg * np.cos(a) + mu * q / (1 + mu * mu), rtol=1e-3)
        np.testing.assert_allclose(np.linalg.norm(f[:, [0, 2]], axis=1), mu * f[:, 1], rtol=1e-3)
        r = mass * 9.81 * (np.sin(a) - mu * np.cos(a)) / np.sqrt(1 + mu * mu)
        M = np.sum((x[2:, 0] - x[1, 0]) * r[2:])
        assert abs(np.linalg.norm(res.pair_rest_moment[1]) / M - 1.0) < 0.01
        assert res.friction_limited == [0]


def test_contact_support_rejects_bad_input():
    from taichi_hair.solvers.rest_support import ContactSupport

    with pytest.raises(ValueError, match="normals"):
        ContactSupport(vertex=[1, 2], normal=[[0, 1, 0]])
    with pytest.raises(ValueError, match="non-zero"):
        ContactSupport(vertex=[1], normal=[[0, 0, 0]])
    with pytest.raises(ValueError, match="friction"):
        ContactSupport(vertex=[1], normal=[[0, 1, 0]], friction=-1)
    with pytest.raises(ValueError, match="twice"):
        ContactSupport(vertex=[1, 1], normal=[[0, 1, 0], [0, 1, 0]])
    with pytest.raises(ValueError, match="support_for"):
        RestPoseConfig(support_for="some")


def test_scene_rest_max_change_holds_a_strand_the_default_reports(tmp_path):
    """[groom] rest_max_change (RestPoseConfig.max_rest_change): the 15 cm horizontal strand of 9 vertices needs a
    rest strain change of 1.65 (measured), so the default 1.0 reports it as not held and 1.9 holds it (residual
    below 1e-9 of its weight); 0 is a SceneError naming the key."""
    from taichi_hair.io import save_groom
    from taichi_hair.io.groom import Groom
    from taichi_hair.scene.file import SceneError, load_scene

    save_groom(Groom(points=horizontal(0.15, 9), strand_offsets=np.array([0, 9]), units="m"),
               str(tmp_path / "strand.thair.npz"))
    text = '[scene]\nframes = 1\n[groom]\nfile = "strand.thair.npz"\nrest_pose = "sag-free"\n{change}\n' \
           '[solver]\ntype = "admm"\n'
    held = {}
    for i, change in enumerate(("", "rest_max_change = 1.9", "rest_max_change = 0")):
        path = tmp_path / f"scene{i}.toml"
        path.write_text(text.format(change=change))
        if change.endswith("= 0"):
            with pytest.raises(SceneError, match="rest_max_change"):
                load_scene(str(path))
            continue
        scene = load_scene(str(path))
        scene.build_model()
        held[i] = scene.rest_pose_result
    assert [s for s, _ in held[0].unheld] == [0]
    assert not held[1].unheld and held[1].strand_residual.max() < 1e-9


def test_scene_rest_pose_support_lets_a_floor_carry_a_strand_that_cannot_hold_itself(tmp_path):
    """[groom] rest_pose_support = "unheld": the scene's colliders carry the strands the sag-free solve cannot
    hold alone.  A 30 cm strand lying 1 um above a floor (plane collider, friction 0.3): without support it is
    reported as not held; with it, held, the floor's forces carrying its weight (total within 1e-3)."""
    from taichi_hair.io import save_groom
    from taichi_hair.io.groom import Groom
    from taichi_hair.scene.file import load_scene

    n = 121
    pts = horizontal(0.30, n) + [0.0, HAIR.radius + 1e-6, 0.0]
    save_groom(Groom(points=pts, strand_offsets=np.array([0, n]), units="m"), str(tmp_path / "strand.thair.npz"))
    text = """[scene]
frames = 1
[groom]
file = "strand.thair.npz"
rest_pose = "sag-free"
{support}
[material]
radius = {radius}
[solver]
type = "admm"
[[colliders]]
type = "plane"
point = [0.0, 0.0, 0.0]
normal = [0.0, 1.0, 0.0]
friction = 0.3
[[bodies]]
preset = "still"
"""
    from taichi_hair.scene.file import SceneError

    results = {}
    for i, support in enumerate(("", 'rest_pose_support = "unheld"', 'rest_pose_support = "sometimes"')):
        path = tmp_path / f"scene{i}.toml"
        path.write_text(text.format(support=support, radius=HAIR.radius))
        if "sometimes" in support:
            with pytest.raises(SceneError, match="rest_pose_support"):
                load_scene(str(path))
            continue
        scene = load_scene(str(path))
        model = scene.build_model()
        results[i] = scene.rest_pose_result
    assert [s for s, _ in results[0].unheld] == [0]
    res = results[1]
    assert not res.unheld
    free = model.host["vertex_is_fixed"] == 0
    weight = 9.81 * model.host["vertex_mass"][free].sum()
    assert abs(res.vertex_support_force[free, 1].sum() / weight - 1.0) < 1e-3


def test_support_from_a_mesh_matches_the_analytic_sphere():
    """support_from_colliders on a triangulated sphere (icosphere, 5,120 faces, R = 5 cm) and on the analytic
    sphere: a strand lying along the top (1 um above the fibre's contact) gets the same supported vertices,
    and the mesh's normals (central differences of the exact triangle distance) are within 2 degrees of the
    radial ones (the facets' own tilt)."""
    import trimesh

    from taichi_hair.contact.colliders import MeshCollider, SphereCollider
    from taichi_hair.solvers.rest_support import support_from_colliders

    R = 0.05
    th = np.linspace(0.0, 0.5, 21)
    rr = R + HAIR.radius + 1e-6
    b = GroomBuilder()
    b.add_strand(np.c_[rr * np.sin(th), rr * np.cos(th), np.zeros_like(th)], HAIR)
    b.add_strand(np.c_[np.zeros(5), 0.08 + 0.01 * np.arange(5), np.zeros(5)], HAIR)   # far off: no support
    model = b.finalize()
    exact = support_from_colliders(model, [SphereCollider(radius=R, friction=0.2)], reach=5e-4)
    mesh = support_from_colliders(model, [MeshCollider(mesh=trimesh.creation.icosphere(subdivisions=4, radius=R),
                                                       friction=0.2)], reach=5e-4)
    np.testing.assert_array_equal(exact.vertex, np.arange(2, 21))
    np.testing.assert_array_equal(mesh.vertex, exact.vertex)
    cos = np.sum(mesh.normal * exact.normal, axis=1)
    assert np.all(cos > np.cos(np.radians(2.0))), cos.min()
    assert np.all(mesh.friction == 0.2)


def test_resolving_only_the_edited_strands_equals_a_solve_of_the_whole_edited_groom():
    """After an edit of two of eight strands (one longer, one curled), ``changed_strands`` names exactly those two,
    and ``resolve_rest_pose`` (the previous result for the others, the two solved as a Model of their own)
    equals a full solve of the edited Model: moments within 1e-9 of their largest (the edge loads are a
    cumulative sum over the flat array, whose rounding depends on the strands that follow), rest lengths
    within 1e-15 m, the same strands held, and the one strand too heavy to hold reported by its index in
    the whole groom."""
    from taichi_hair.solvers.rest_pose_edit import changed_strands, resolve_rest_pose

    def groom(polys):
        b = GroomBuilder()
        for p in polys:
            b.add_strand(p, HAIR)
        return b.finalize()

    polys = [wavy(0.06, 25, turns=1.0 + 0.2 * k) + [0.01 * k, 0, 0] for k in range(6)]
    polys += [horizontal(0.05, 21) + [0, 0, 0.02], horizontal(0.30, 41) + [0, 0, 0.04]]  # the last: not held
    old = groom(polys)
    first = solve_rest_pose(old, SolverADMMConfig())
    assert [s for s, _ in first.unheld] == [7]
    edited = list(polys)
    edited[2] = edited[2][0] + 1.2 * (edited[2] - edited[2][0])
    edited[5] = wavy(0.06, 25, amp=0.004, turns=2.0) + [0.05, 0, 0]
    new = groom(edited)
    assert changed_strands(old.host, new.host).tolist() == [2, 5]
    assert changed_strands(old.host, groom(polys[:-1] + [horizontal(0.30, 40)]).host) is None  # another layout
    full = solve_rest_pose(new, SolverADMMConfig())
    part = resolve_rest_pose(new, first, [2, 5], SolverADMMConfig())
    scale = np.abs(full.pair_rest_moment).max()
    assert scale > 0 and np.abs(part.pair_rest_moment - full.pair_rest_moment).max() <= 1e-9 * scale
    assert np.abs(part.edge_rest_length - full.edge_rest_length).max() <= 1e-15
    assert np.allclose(part.strand_rest_turn, full.strand_rest_turn, rtol=1e-9, atol=0.0)
    assert part.unheld == full.unheld and [s for s, _ in part.unheld] == [7]
    assert not np.array_equal(part.pair_rest_moment, first.pair_rest_moment)  # the edit shows
    with pytest.raises(ValueError, match="strands"):
        resolve_rest_pose(new, first, [8], SolverADMMConfig())
