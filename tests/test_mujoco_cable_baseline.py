"""Physics checks of the MuJoCo cable baseline (benchmarks/mujoco_cable.py).

The benchmark rod (10 cm hair, R = 0.05 mm, E = 3 GPa) has
Gamma = rho g A L^3 / (E I) = 6.8, far outside linear beam theory (which
would predict an 8.5 cm tip drop on a 10 cm rod), so it is checked against
the heavy elastica; the linear-theory check uses a 1 cm piece of the same
hair (Gamma = 0.0068), where linear theory is accurate to ~1e-5.
"""
import importlib.util
import math
import pathlib

import pytest

mujoco = pytest.importorskip("mujoco")
pytest.importorskip("scipy")

_PATH = pathlib.Path(__file__).resolve().parents[1] / "benchmarks" / "mujoco_cable.py"


@pytest.fixture(scope="module")
def mc():
    spec = importlib.util.spec_from_file_location("mujoco_cable", _PATH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_model_mass_and_units(mc):
    model = mc.build_cable_model()
    p = mc.model_params(model)
    mass = float(model.body_mass.sum()) * p["mass_unit"]
    assert mass == pytest.approx(1300.0 * math.pi * 5e-5 ** 2 * 0.1, rel=1e-12)
    assert model.nv == 3 * 40  # 40 ball joints, root edge hinged at the clamp


def test_short_rod_matches_linear_beam_theory(mc):
    # 1 cm of the same hair: Gamma = 0.0068, linear theory is the reference.
    res = mc.time_to_rest(length=0.01, repeats=1)
    lin = 1300.0 * 9.81 * math.pi * 5e-5 ** 2 * 0.01 ** 4 / (
        8.0 * 3e9 * math.pi * 5e-5 ** 4 / 4.0)
    assert res["linear_theory_tip_drop_m"] == pytest.approx(lin, rel=1e-12)
    assert res["gamma"] < 0.01
    assert res["final_tip_drop_m"] == pytest.approx(lin, rel=0.03)


def test_hair_matches_heavy_elastica(mc):
    res = mc.time_to_rest(repeats=1)
    assert res["gamma"] == pytest.approx(6.8016, rel=1e-4)
    # MuJoCo reproduces the exact equilibrium of its discretisation ...
    assert abs(res["rel_diff_vs_discrete_chain"]) < 1e-6
    # ... which is within 0.05 % of the continuous heavy elastica
    assert res["final_tip_drop_m"] == pytest.approx(
        res["heavy_elastica_tip_drop_m"], rel=0.03)
    assert res["heavy_elastica_tip_drop_m"] == pytest.approx(0.0592775, rel=1e-4)
    # the settle point is a proper point of the trajectory
    assert 1 <= res["steps"] <= res["rest_check_steps"]
    assert res["wall_s"] > 0.0
