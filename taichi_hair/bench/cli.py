"""``taichi-hair bench``: speed-against-accuracy studies.

    taichi-hair bench stability --out DIR [--full] [--methods admm,shape,xpbd]
    taichi-hair bench pareto --out DIR [--full] [--scenes cantilever,swing,groom] [--update-data]
"""

from __future__ import annotations

import time

from ..cli.common import CLIError, _add_common, _init_taichi

STUDIES = ("stability", "pareto")


#: Methods each study knows (the ADMM variants: :mod:`taichi_hair.bench.methods`).
STUDY_METHODS = {"stability": ("admm", "admm_w1", "admm_aa", "admm_bdf2", "shape", "xpbd"),
                 "pareto": ("admm", "admm_w1", "admm_aa", "admm_bdf2", "admm_f64", "shape", "xpbd")}


def _parse_methods(text, study: str) -> tuple:
    allowed = STUDY_METHODS[study]
    if text is None:
        return allowed
    methods = tuple(m.strip() for m in text.split(",") if m.strip())
    bad = [m for m in methods if m not in allowed]
    if not methods or bad:
        raise CLIError(f"--methods must be a comma-separated subset of {','.join(allowed)} for {study}, "
                       f"got {text!r}")
    return methods


def cmd_bench(args) -> int:
    if args.study not in STUDIES:
        raise CLIError(f"unknown study {args.study!r} (available: {', '.join(STUDIES)})")
    methods = _parse_methods(args.methods, args.study)
    if args.duration is not None and not (args.duration > 0):
        raise CLIError(f"--duration must be > 0, got {args.duration}")
    if args.study == "pareto":
        from .pareto import cmd_pareto

        return cmd_pareto(args, methods)
    ti, arch = _init_taichi(args.arch, args.precision)
    from .stability import format_summary, run_atlas, write_outputs

    if args.full:
        dts = (1 / 24, 1 / 48, 1 / 96, 1 / 192, 1 / 384, 1 / 768)
        knobs = {m: (1, 2, 5, 10, 20, 50, 100) for m in methods}
    else:
        dts = (1 / 24, 1 / 96, 1 / 384)
        knobs = {m: (2, 10, 50) for m in methods}
    duration = 1.5 if args.duration is None else args.duration
    t0 = time.perf_counter()

    def progress(text):
        if not args.quiet:
            print(f"  [{time.perf_counter() - t0:6.0f} s] {text}", flush=True)

    if not args.quiet:
        print(f"stability atlas: methods {', '.join(methods)}, dt {', '.join(f'1/{1 / d:.0f}' for d in dts)} s, "
              f"{duration:g} s simulated per run, arch {arch}, {args.precision}", flush=True)
    cells = run_atlas(methods, dts, knobs, duration=duration, progress=progress)
    paths = write_outputs(cells, args.out)
    print(format_summary(cells))
    print(f"wrote {', '.join(paths)} in {time.perf_counter() - t0:.0f} s")
    return 0


def register(sub) -> None:
    """Add the ``bench`` command family to an argparse subparsers object."""
    p = sub.add_parser("bench", help="speed-against-accuracy studies: stability atlas, Pareto chart")
    p.add_argument("study", help="stability or pareto")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--full", action="store_true", help="the bigger grid (longer)")
    p.add_argument("--methods", default=None,
                   help="comma-separated subset of admm (w0 = 25, plain: the paper), admm_w1 (w0 = 1, "
                        "plain), admm_aa (w0 = 1, Anderson: the default on straight rods), admm_bdf2 (w0 = 1, "
                        "BDF2), admm_f64 (pareto only), shape, xpbd (default: all)")
    p.add_argument("--duration", type=float, default=None, help="stability: simulated seconds per run")
    p.add_argument("--scenes", default="cantilever,swing,groom", help="pareto: comma-separated scenes")
    p.add_argument("--groom-strands", type=int, default=192, help="pareto: strands of the groom scene")
    p.add_argument("--update-data", action="store_true",
                   help="pareto: also replace the shipped taichi_hair/bench/data/pareto_cpu.csv")
    _add_common(p)
    p.set_defaults(func=cmd_bench)
