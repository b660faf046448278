"""The stability atlas of ADMM at two constraint weight scales w0 (issue 12 item 5's measurement).

Run from the repository root:
    python3 benchmarks/probes/atlas_w0.py W0_A,W0_B      # e.g. 1,25

Runs ``taichi_hair.bench.stability.run_atlas`` for its two ADMM rows with their w0
(``taichi_hair.bench.methods.ADMM_VARIANTS``) set to W0_A ("admm") and W0_B ("admm_w1") instead of the
study's 25 and 1, and prints the summary and every cell.  A diagnostic: the study itself
(``taichi-hair bench stability``) keeps its two rows.
"""

import sys


def run(w0_a: float, w0_b: float):
    """The atlas's cells with the two ADMM rows at w0 = w0_a ("admm") and w0_b ("admm_w1")."""
    from taichi_hair.bench import methods
    from taichi_hair.bench import stability as S

    # The variants' w0 live in bench/methods.py (the atlas and the Pareto study read them when they build a solver).
    methods.ADMM_VARIANTS["admm"]["w0"], methods.ADMM_VARIANTS["admm_w1"]["w0"] = w0_a, w0_b
    return S.run_atlas(methods=("admm", "admm_w1"))


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    import taichi as ti

    import taichi_hair

    taichi_hair.init(arch=ti.cpu, log_level=ti.WARN)
    from taichi_hair.bench import stability as S

    w = [float(a) for a in argv[0].split(",")]
    cells = run(w[0], w[1])
    print(f"admm = w0 {w[0]}, admm_w1 = w0 {w[1]}")
    print(S.format_summary(cells))
    for c in cells:
        print(c.method, c.case, f"dt=1/{1 / c.dt:.0f}", c.knob, c.label, c.reason,
              f"sag {c.sag_error:.3g} stretch {c.stretch:.3g} speed {c.tip_speed:.3g}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
