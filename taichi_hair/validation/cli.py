"""``taichi-hair validate``: the validation experiments of Daviet 2023 Sec. 5.1."""

from __future__ import annotations

import sys

from ..cli_common import CLIError, _add_common, _init_taichi


def cmd_validate(args) -> int:
    if args.experiment not in ("cantilever", "stick-slip"):
        raise CLIError(f"unknown experiment {args.experiment!r} (available: cantilever, stick-slip)")
    ti, arch = _init_taichi(args.arch, args.precision)
    if args.experiment == "stick-slip":
        return _validate_stick_slip(args, arch)
    from .cantilever import default_lengths, format_summary, run_cantilever, write_outputs

    if args.count < 2:
        raise CLIError("--count must be >= 2")

    def progress(it, change, err):
        if not args.quiet:
            print(f"  {it:6d} iterations: max change of H/W over the last chunk {change:.2e}, "
                  f"max |error| {100 * err:.2f}%", flush=True)

    if not args.quiet:
        print(f"cantilever: {args.count} rods from 0.5 cm to 128 cm, quasistatic ADMM, w0 = {args.w0:g}, "
              f"arch {arch}, {args.precision}")
    result = run_cantilever(default_lengths(args.count), w0=args.w0, max_iterations=args.max_iterations,
                            progress=progress, voronoi_rescaling=not args.no_voronoi_rescaling,
                            strain_measure=args.strain_measure)
    csv_path, png_path = write_outputs(result, args.out)
    print(format_summary(result))
    print(f"wrote {csv_path} and {png_path}")
    if result.max_abs_rel_error > args.tolerance:
        print(f"error: max relative error {100 * result.max_abs_rel_error:.2f}% exceeds the tolerance "
              f"{100 * args.tolerance:.2f}%", file=sys.stderr)
        return 1
    return 0


def _validate_stick_slip(args, arch) -> int:
    from .stick_slip import format_summary, run_stick_slip, write_outputs

    def progress(j, d, n):
        if not args.quiet:
            print(f"  substep {j:4d}: clamp displacement {d:.3f} L, {n} rods have slid", flush=True)

    if not args.quiet:
        print(f"stick-slip: 13 friction coefficients 0..0.6, 800 quasistatic substeps to 0.6 L, arch {arch}, "
              f"{args.precision}")
    result = run_stick_slip(substeps=args.substeps, progress=progress)
    csv_path, png_path = write_outputs(result, args.out)
    print(format_summary(result))
    print(f"wrote {csv_path} and {png_path}")
    return 0



def register(sub) -> None:
    v = sub.add_parser("validate", help="validation experiments (Daviet 2023 Sec. 5.1)")
    v.add_argument("experiment", help="experiment name: cantilever or stick-slip")
    v.add_argument("--out", required=True, help="output folder")
    v.add_argument("--count", type=int, default=100, help="number of rod lengths")
    v.add_argument("--w0", type=float, default=0.2, help="ADMM weight scale for the quasistatic solve")
    v.add_argument("--max-iterations", type=int, default=20000)
    v.add_argument("--tolerance", type=float, default=0.02, help="max relative error accepted (exit 1 above)")
    v.add_argument("--strain-measure", default="korner", choices=["korner", "bergou"])
    v.add_argument("--no-voronoi-rescaling", action="store_true", help="disable the Sec. 5.1 boundary rescaling")
    v.add_argument("--substeps", type=int, default=800, help="stick-slip: quasistatic substeps to 0.6 L")
    _add_common(v)
    v.set_defaults(func=cmd_validate)

