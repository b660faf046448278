"""ADMM's stability atlas at one time step for several constraint weight scales w0 (issue 12 item 5).

Run from the repository root:
    python3 benchmarks/probes/atlas_large_dt.py W0[,W0...] DT_INVERSE[,...] [ITERATIONS,...]
    # e.g.  python3 benchmarks/probes/atlas_large_dt.py 0.25,0.5,1,2,4 24 10,50

For each w0, runs ``taichi_hair.bench.stability.run_atlas`` for the rows ``admm_aa`` (Anderson, the default
on the atlas's straight rods) and ``admm_w1`` (the plain iteration) with their w0 set to it
(``taichi_hair.bench.methods.ADMM_VARIANTS``), at the given steps dt = 1 / DT_INVERSE s and iteration counts
(default 10 and 50), and prints one line per cell.  A diagnostic: the study itself
(``taichi-hair bench stability``) keeps w0 = 1.
"""

import sys


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if len(argv) < 2:
        print(__doc__)
        return 2
    import taichi as ti

    ti.init(arch=ti.cpu, log_level=ti.WARN)
    from taichi_hair.bench import methods
    from taichi_hair.bench import stability as S

    dts = [1.0 / float(d) for d in argv[1].split(",")]
    iterations = tuple(int(k) for k in argv[2].split(",")) if len(argv) > 2 else (10, 50)
    for w in argv[0].split(","):
        for row in ("admm_aa", "admm_w1"):
            methods.ADMM_VARIANTS[row]["w0"] = float(w)
        cells = S.run_atlas(methods=("admm_aa", "admm_w1"), dts=dts,
                            knobs={"admm_aa": iterations, "admm_w1": iterations})
        for c in cells:
            print(f"w0 {w} {c.method} {c.case} dt=1/{1 / c.dt:.0f} {c.knob} {c.label} {c.reason} "
                  f"sag {c.sag_error:.3g} speed {c.tip_speed:.3g}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
