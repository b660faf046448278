"""The boundary Voronoi rescaling (SolverADMMConfig.voronoi_rescaling, Daviet 2023 Sec. 5.1 "Cantilever")
amounts to clamping the rod at its root vertex; without it the rod is clamped half an edge further out."""

from taichi_hair.validation.cantilever import clamp_convention_tip_drops


def test_voronoi_rescaling_clamps_at_root_vertex_and_plain_voronoi_at_half_an_edge():
    # References: heavy elastica (validation/elastica.py) of the 10 cm hair (Gamma = 6.80, 40 edges of 2.5 mm),
    # clamped at vertex 0 (free length L; drop 59.28 mm) or at s = h/2 (free length L - h/2, Gamma (1 - h/2L)^3;
    # drop 57.40 mm): the two conventions are 3.2 % apart.  Closed form of the discrete model, small deflection
    # (cantilever.discrete_linear_tip_deflection, 40 edges): 0.9970 of the root-vertex drop with rescaling,
    # 0.9506 of the continuum = 0.9997 of the half-edge drop (1 - 1/80)^4 without.  Tolerance 0.5 % (measured:
    # -0.25 % and -0.02 %, benchmarks/results/validation/cantilever_clamp.txt).
    r = clamp_convention_tip_drops(0.1, tolerance=1e-5)
    assert r.edge_count == 40
    assert abs(r.drop_root_vertex / r.drop_half_edge - 1) > 0.03
    assert abs(r.drop_rescaled / r.drop_root_vertex - 1) < 0.005
    assert abs(r.drop_plain / r.drop_half_edge - 1) < 0.005
