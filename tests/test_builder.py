"""Bad input gets a ValueError naming the strand and the field."""

import numpy as np
import pytest

from taichi_hair import GroomBuilder, RodMaterial, SolverADMM, SolverADMMConfig


def _line(n=5, length=0.05):
    return np.c_[np.linspace(0, length, n), np.zeros(n), np.zeros(n)]


def _builder_with_one_good_strand():
    b = GroomBuilder()
    b.add_strand(_line())
    return b


@pytest.mark.parametrize(
    "points, message",
    [
        (np.array([[0, 0, 0], [0.01, np.nan, 0], [0.02, 0, 0]]),
         r"strand 1: field 'points' has a non-finite coordinate at vertex 1"),
        (np.array([[0, 0, 0], [0.01, 0, 0], [0.02, np.inf, 0]]),
         r"strand 1: field 'points' has a non-finite coordinate at vertex 2"),
        (np.array([[0, 0, 0], [0.01, 0, 0], [0.01, 0, 0], [0.02, 0, 0]]),
         r"strand 1: field 'points' has a zero-length edge between vertices 1 and 2"),
        (np.array([[0, 0, 0], [0.01, 0, 0]]), r"strand 1: field 'points' has 2 vertices; a strand needs at least 3"),
        (np.array([[0, 0, 0]]), r"strand 1: field 'points' has 1 vertices"),
        (np.zeros((4, 2)), r"strand 1: field 'points' must have shape \(m, 3\)"),
        ("abc", r"strand 1: field 'points'"),
    ],
)
def test_bad_points(points, message):
    b = _builder_with_one_good_strand()
    with pytest.raises(ValueError, match=message):
        b.add_strand(points)


@pytest.mark.parametrize(
    "material, field",
    [
        ({"radius": 0.0}, "radius"),
        ({"radius": -1e-5}, "radius"),
        ({"density": 0.0}, "density"),
        ({"youngs_modulus_bend": -3e9}, "youngs_modulus_bend"),
        ({"youngs_modulus_stretch": 0.0}, "youngs_modulus_stretch"),
        ({"ellipticity": 1.0}, "ellipticity"),
        ({"ellipticity": -0.1}, "ellipticity"),
        ({"poisson_ratio": 0.7}, "poisson_ratio"),
        ({"radius": float("nan")}, "radius"),
    ],
)
def test_bad_material_names_strand_and_field(material, field):
    b = _builder_with_one_good_strand()
    with pytest.raises(ValueError, match=rf"strand 1: field 'material': RodMaterial\.{field}"):
        b.add_strand(_line(), material=material)


def test_mutated_material_is_revalidated():
    m = RodMaterial()
    m.radius = -1.0
    with pytest.raises(ValueError, match=r"strand 0: field 'material': RodMaterial\.radius"):
        GroomBuilder().add_strand(_line(), material=m)


def test_material_dataclass_validates_directly():
    with pytest.raises(ValueError, match=r"RodMaterial\.density"):
        RodMaterial(density=-1)


def test_bad_root_and_body():
    b = GroomBuilder(body_count=2)
    with pytest.raises(ValueError, match=r"strand 0: field 'root'"):
        b.add_strand(_line(), root="glued")
    with pytest.raises(ValueError, match=r"strand 0: field 'body'"):
        b.add_strand(_line(), body=2)


def test_bad_twist_and_director():
    b = GroomBuilder()
    with pytest.raises(ValueError, match=r"strand 0: field 'twist'"):
        b.add_strand(_line(), twist=np.zeros(3))
    with pytest.raises(ValueError, match=r"strand 0: field 'root_director'"):
        b.add_strand(_line(), root_director=(1.0, 0.0, 0.0))


def test_empty_builder():
    with pytest.raises(ValueError, match="no strands"):
        GroomBuilder().finalize()


def test_quasistatic_needs_clamped_roots():
    b = GroomBuilder()
    b.add_strand(_line())
    b.add_strand(_line(), root="free")
    model = b.finalize()
    with pytest.raises(ValueError, match=r"strand 1: field 'root' is 'free'"):
        SolverADMM(model, SolverADMMConfig(mode="quasistatic"))


@pytest.mark.parametrize(
    "kwargs, field",
    [({"iterations": 0}, "iterations"), ({"mode": "static"}, "mode"), ({"w0": -1.0}, "w0"),
     ({"strain_measure": "kirchhoff"}, "strain_measure"), ({"tridiagonal": "lu"}, "tridiagonal"),
     ({"air_viscosity": -1.0}, "air_viscosity"), ({"dual_frame": "vertex"}, "dual_frame")],
)
def test_bad_solver_config(kwargs, field):
    with pytest.raises(ValueError, match=rf"SolverADMMConfig\.{field}"):
        SolverADMMConfig(**kwargs)


def test_rest_quantities():
    """Rest lengths, Voronoi lengths, lumped masses and clamped vertices from the input shape."""
    mat = RodMaterial(radius=1e-4, density=1000.0)
    pts = np.array([[0, 0, 0], [0.01, 0, 0], [0.03, 0, 0], [0.06, 0, 0]], dtype=float)
    b = GroomBuilder()
    b.add_strand(pts, mat)
    m = b.finalize()
    h = m.host
    np.testing.assert_allclose(h["edge_rest_length"], [0.01, 0.02, 0.03, 0.0])
    np.testing.assert_allclose(h["vertex_voronoi_length"], [0.005, 0.015, 0.025, 0.015])
    np.testing.assert_allclose(h["vertex_mass"], 1000.0 * np.pi * 1e-8 * h["vertex_voronoi_length"])
    np.testing.assert_array_equal(h["vertex_is_fixed"], [1, 1, 0, 0])
    np.testing.assert_array_equal(h["edge_is_fixed"], [1, 0, 0, 1])
    np.testing.assert_array_equal(h["pair_is_active"], [0, 1, 1, 0])
    assert abs(sum(h["vertex_mass"]) - 1000.0 * np.pi * 1e-8 * 0.06) < 1e-15
