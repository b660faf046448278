"""The stability atlas for ADMM variants given on the command line (issue 12 item 5: w0 and Anderson window).

Run from the repository root:
    python3 benchmarks/probes/atlas_variants.py [--dts 24,96,384] KNOBS SPEC [SPEC ...]
    e.g. python3 benchmarks/probes/atlas_variants.py 10,50 '{"w0": 1.0, "anderson_window": 5}' '{"w0": 2.0}'
         python3 benchmarks/probes/atlas_variants.py --dts 24 10,50 '{"w0": 0.5, "anderson_window": 5}' \
             '{"w0": 0.5, "anderson_window": 0}'

--dts: the steps as 1/dt (default the study's 24, 96, 384).

KNOBS: comma-separated iteration counts per step (the study uses 2,10,50); each SPEC a JSON object of
``SolverADMMConfig`` fields (up to four).  Runs ``taichi_hair.bench.stability.run_atlas`` (dt 1/24, 1/96,
1/384 s x KNOBS x the four rods, drag 8 /s, 1.5 s) with the study's ADMM rows replaced by the SPECs, and
prints, per SPEC, the counts of ok / wrong / unstable cells and every cell that is not ok.  A diagnostic:
the study itself (``taichi-hair bench stability``) keeps its rows (``taichi_hair.bench.methods``).
"""

import json
import sys


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    dts = (1 / 24, 1 / 96, 1 / 384)
    if argv[:1] == ["--dts"] and len(argv) > 1:
        dts = tuple(1.0 / float(d) for d in argv[1].split(","))
        argv = argv[2:]
    if len(argv) < 2:
        print(__doc__)
        return 2
    import taichi as ti

    import taichi_hair

    taichi_hair.init(arch=ti.cpu, log_level=ti.WARN)
    from taichi_hair.bench import methods
    from taichi_hair.bench import stability as S

    knobs = tuple(int(k) for k in argv[0].split(","))
    specs = [json.loads(a) for a in argv[1:5]]
    names = ("admm", "admm_w1", "admm_aa", "admm_bdf2")[:len(specs)]
    for name, spec in zip(names, specs):
        methods.ADMM_VARIANTS[name] = spec
    cells = S.run_atlas(methods=names, dts=dts, knobs={n: knobs for n in names})
    for name, spec in zip(names, specs):
        cs = [c for c in cells if c.method == name]
        counts = " / ".join(f"{sum(c.label == lab for c in cs)} {lab}" for lab in ("ok", "wrong", "unstable"))
        print(f"{json.dumps(spec)}: {counts} of {len(cs)}")
        for c in cs:
            if c.label != "ok":
                print(f"    {c.case} dt=1/{1 / c.dt:.0f} s, {c.knob} iterations: {c.label} ({c.reason})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
