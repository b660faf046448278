"""Which sag-free strands of a generated groom are unstable equilibria, and what they look like (issue 14).

Run from the repository root:
    python3 benchmarks/probes/rest_pose_stability.py [--style straight|wavy|curly] [--strands 300] \
        [PERTURBATION_M,SECONDS ...]
    e.g. python3 benchmarks/probes/rest_pose_stability.py 1e-4,1 1e-4,2

The groom of ``assets/scenes/head_turn.toml`` with the generator style given, its sag-free rest pose
(``solve_rest_pose``), then ``check_stability`` for every PERTURBATION_M,SECONDS pair (default: the
function's defaults): the number of held strands flagged unstable and the time.  Then, for the last
check's sets (unstable / held and stable / not held): strand length, the root tangent's upward component,
the tip height over the root, and Greenhill's self-weight buckling length L_c = (7.837 E I / w)^(1/3) of
the groom's hair, and the closest approach of vertices of different strands at x* (contact support there).
A diagnostic, not a benchmark.
"""

import os
import sys
import tempfile
import time


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    style, strands = "straight", 300
    while argv[:1] and argv[0].startswith("--"):
        if argv[0] == "--style":
            style, argv = argv[1], argv[2:]
        elif argv[0] == "--strands":
            strands, argv = int(argv[1]), argv[2:]
        else:
            print(__doc__)
            return 2
    import numpy as np
    import taichi as ti
    from scipy.spatial import cKDTree

    import taichi_hair

    taichi_hair.init(arch=ti.cpu, log_level=ti.WARN)
    from taichi_hair.scene.file import load_scene
    from taichi_hair.solvers.rest_pose import apply_rest_pose, check_stability, solve_rest_pose

    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    src = open(os.path.join(root, "assets", "scenes", "head_turn.toml")).read()
    src = src.replace('generator = "wavy"', f'generator = "{style}"').replace("strands = 300", f"strands = {strands}")
    src = src.replace('file = "../head.obj"', f'file = "{os.path.join(root, "assets", "head.obj")}"')
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "scene.toml")
        with open(path, "w") as fh:
            fh.write(src)
        sc = load_scene(path)
        model = sc.build_model()
    g = sc._gravity_in_body()
    res = solve_rest_pose(model, sc.solver_config, gravity=g)
    apply_rest_pose(model, res)
    print(f"{style}, {model.strand_count} strands: {model.strand_count - len(res.unheld)} held")
    specs = [tuple(float(v) for v in a.split(",")) for a in argv] or [None]
    for spec in specs:
        t0 = time.perf_counter()
        kw = {} if spec is None else dict(perturbation=spec[0], seconds=spec[1])
        check_stability(model, res, sc.solver_config, gravity=g, **kw)
        what = "defaults" if spec is None else f"perturbation {spec[0]:g} m, {spec[1]:g} s"
        print(f"  check ({what}): {len(res.unstable)} unstable ({time.perf_counter() - t0:.1f} s)")
    h = model.host
    st, ct = h["strand_vertex_start"], h["strand_vertex_count"]
    x = np.asarray(h["vertex_rest_position"], np.float64)
    length = np.array([h["edge_rest_length"][a:a + c - 1].sum() for a, c in zip(st, ct)])
    rise = np.array([x[a + c - 1, 1] - x[a, 1] for a, c in zip(st, ct)])
    e1 = x[st + 2] - x[st + 1]
    up = e1[:, 1] / np.linalg.norm(e1, axis=1)
    unstable = sorted(s for s, _ in res.unstable)
    unheld = sorted(s for s, _ in res.unheld)
    stable = sorted(set(range(model.strand_count)) - set(unstable) - set(unheld))
    mat = model.materials[0]
    ei = mat.youngs_modulus_bend * np.pi * mat.radius ** 4 / 4
    w = mat.density * mat.area * 9.81
    print(f"  Greenhill's self-weight buckling length (7.837 E I / w)^(1/3): {100 * (7.837 * ei / w) ** (1 / 3):.1f} cm")
    for name, S in (("unstable", unstable), ("held, stable", stable), ("not held", unheld)):
        if not S:
            continue
        S = np.array(S)
        print(f"  {name}: {S.size} strands; length median {100 * np.median(length[S]):.1f} cm (min "
              f"{100 * length[S].min():.1f}); root tangent's upward component median {np.median(up[S]):+.2f}; "
              f"tip over root median {100 * np.median(rise[S]):+.1f} cm")
    pairs = cKDTree(x).query_pairs(1e-3, output_type="ndarray")
    sv = h["vertex_strand"]
    pairs = pairs[sv[pairs[:, 0]] != sv[pairs[:, 1]]]
    close = np.linalg.norm(x[pairs[:, 0]] - x[pairs[:, 1]], axis=1) if len(pairs) else np.array([np.inf])
    print(f"  closest vertices of different strands at x*: {1e3 * close.min():.2f} mm; pairs within 2 hair radii "
          f"({2e3 * mat.radius:.2f} mm): {int((close < 2 * mat.radius).sum())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
