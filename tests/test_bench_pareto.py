"""Pareto study: the front, the error measures, a small sweep (deterministic, ordered by knob), the
shipped data file, and the CLI's errors."""

import math
import os

import numpy as np
import pytest

from taichi_hair.bench.pareto import cantilever_error, trajectory_error
from taichi_hair.bench.pareto_data import DATA_DIR, pareto_front, read_csv
from taichi_hair.bench.pareto_runs import SCENES, RunSpec, build_scene, run_specs, shake_rotation


def test_pareto_front_on_known_points():
    cost = [1, 2, 3, 4, 2.5, 5, 0.5]
    err = [0.5, 0.2, 0.1, 0.3, 0.25, math.inf, 2.0]
    # (4, 0.3) is dominated by (2, 0.2) and (3, 0.1); (2.5, 0.25) by (2, 0.2); inf never on the front.
    assert list(pareto_front(cost, err)) == [True, True, True, False, False, False, True]
    assert list(pareto_front([1, 1], [0.1, 0.1])) == [True, True]  # ties dominate neither


def test_error_measures():
    rng = np.random.default_rng(1)
    traj = rng.normal(size=(4, 6, 3))
    strand = np.array([0, 0, 0, 1, 1, 1])
    lengths = np.array([2.0, 4.0])
    assert trajectory_error(traj, traj, strand, lengths) == 0.0
    shifted = traj + np.array([0.0, 0.3, 0.4])  # |d| = 0.5 everywhere
    expected = math.sqrt(0.5 * (0.5 / 2) ** 2 + 0.5 * (0.5 / 4) ** 2)
    assert trajectory_error(shifted, traj, strand, lengths) == pytest.approx(expected, rel=1e-12)
    bad = traj.copy()
    bad[2, 1, 0] = np.nan
    assert trajectory_error(bad, traj, strand, lengths) == math.inf
    with pytest.raises(ValueError, match="shapes differ"):
        trajectory_error(traj[:2], traj, strand, lengths)
    R = shake_rotation(0.123)
    assert np.allclose(R @ R.T, np.eye(3)) and np.linalg.det(R) == pytest.approx(1.0)


def test_cantilever_error_against_the_elastica():
    from taichi_hair.validation.elastica import cantilever_gamma, solve_heavy_elastica
    from taichi_hair.validation.elasticity_params import HAIR

    model, scene = build_scene("cantilever")
    x = model.host["vertex_rest_position"].copy()
    starts, counts = model.host["strand_vertex_start"], model.host["strand_vertex_count"]
    for s0, c, L in zip(starts, counts, scene.strand_lengths):
        sol = solve_heavy_elastica(cantilever_gamma(L, HAIR["radius"], HAIR["density"], HAIR["youngs_modulus_bend"]))
        x[s0 + c - 1, 0] = x[s0, 0] + sol.width * L
        x[s0 + c - 1, 1] = x[s0, 1] - sol.height * L
    assert cantilever_error(x, model, scene.strand_lengths) < 1e-12
    s0, c, L = starts[2], counts[2], scene.strand_lengths[2]
    x[s0 + c - 1, 1] -= 0.05 * L
    assert cantilever_error(x, model, scene.strand_lengths) == pytest.approx(0.05, rel=1e-9)
    # The rest (horizontal) shape is wrong by the sag itself.
    assert cantilever_error(model.host["vertex_rest_position"], model, scene.strand_lengths) > 0.3


def test_swing_sweep_is_deterministic_and_converges_with_iterations():
    specs = [RunSpec("admm_w1", 1 / 96, iterations=2), RunSpec("admm_w1", 1 / 96, iterations=30),
             RunSpec("admm_w1", 1 / 96, iterations=30)]
    res, model, scene = run_specs("swing", specs)
    assert scene.name == "swing" and res[0]["trajectory"].shape == (48, 81, 3)
    assert np.array_equal(res[1]["trajectory"], res[2]["trajectory"])  # same knobs, same trajectory
    assert all(r["finite"] and r["seconds"] > 0 for r in res)
    # More iterations approach the 30-iteration answer more closely than 2 do; the strand swings down.
    strand, L = model.host["vertex_strand"], scene.strand_lengths
    assert trajectory_error(res[0]["trajectory"], res[1]["trajectory"], strand, L) > 1e-3
    assert res[1]["trajectory"][-1, -1, 1] < -0.1


def test_shipped_pareto_data():
    path = os.path.join(DATA_DIR, "pareto_cpu.csv")
    pts = read_csv(path)
    assert {p.scene for p in pts} == set(SCENES)
    assert {"admm", "shape", "xpbd"} <= {p.method for p in pts}
    for sc in SCENES:
        ps = [p for p in pts if p.scene == sc]
        assert all(p.cost > 0 for p in ps) and any(p.on_front for p in ps)
        # The stored front is the front of the stored points, up to the CSV's rounding (the data shipped
        # first were written with 5 significant digits, so near-ties may round to equal values).
        for p in ps:
            dominated = any(q.cost < p.cost * (1 - 1e-4) and q.error < p.error * (1 - 1e-4) for q in ps)
            weakly = any((q.cost <= p.cost and q.error <= p.error) and (q.cost < p.cost or q.error < p.error)
                         for q in ps)
            if p.on_front:
                assert not dominated, p
            else:
                assert weakly, p


def test_choose_from_measured_points():
    from taichi_hair.bench.pareto_data import Point, choose, load_shipped

    pts = [Point("s", "a", "f32", 0.01, 10, 0, 0, "", 1.0, 0.20),
           Point("s", "b", "f32", 0.01, 30, 0, 0, "", 3.0, 0.02),
           Point("s", "c", "f32", 0.01, 0, 80, 0, "", 2.0, 0.05),
           Point("s", "d", "f32", 0.01, 0, 5, 0, "", 0.5, math.inf)]
    assert choose(pts, "s", max_error=0.06).method == "c"    # cheapest within the error
    assert choose(pts, "s", max_error=0.01 + 0.01).method == "b"
    assert choose(pts, "s", max_cost=2.5).method == "c"      # most accurate within the budget (d diverged)
    with pytest.raises(ValueError, match="reaches error"):
        choose(pts, "s", max_error=0.001)
    with pytest.raises(ValueError, match="exactly one"):
        choose(pts, "s")
    # On the shipped data, the cantilever's most accurate setting is an ADMM one (measured).
    assert choose(load_shipped(), "cantilever", max_cost=1e9).method.startswith("admm")


def test_cli_errors(capsys, tmp_path):
    from taichi_hair.cli import main

    assert main(["bench", "pareto", "--out", str(tmp_path), "--scenes", "swing,tornado"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--scenes" in err[0]
    assert main(["bench", "pareto", "--out", str(tmp_path), "--methods", "admm,newton"]) == 2
    assert "--methods" in capsys.readouterr().err
