"""``taichi-hair validate``: the validation experiments of Daviet 2023 Sec. 5.1."""

from __future__ import annotations

import sys

from ..cli.common import CLIError, _add_common, _init_taichi

EXPERIMENTS = ("cantilever", "stick-slip", "bend-twist")


def cmd_validate(args) -> int:
    if args.experiment not in EXPERIMENTS:
        raise CLIError(f"unknown experiment {args.experiment!r} (available: {', '.join(EXPERIMENTS)})")
    if args.experiment == "bend-twist":
        _check_bend_twist_args(args)
    ti, arch = _init_taichi(args.arch, args.precision)
    if args.experiment == "stick-slip":
        return _validate_stick_slip(args, arch)
    if args.experiment == "bend-twist":
        return _validate_bend_twist(args, arch)
    from .cantilever import default_lengths, format_summary, run_cantilever, write_outputs

    if args.count is None:
        args.count = 100
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

    gravity = 0.0 if args.weightless else 9.81
    if not args.quiet:
        print(f"stick-slip: friction coefficients 0..0.6 in steps of 0.05 and of 0.01 around the reference mu_c, "
              f"{args.substeps} quasistatic substeps to 0.6 L, gravity {gravity:g} m/s^2 (reference with the same "
              f"weight), arch {arch}, {args.precision}")
    result = run_stick_slip(substeps=args.substeps, gravity=gravity, progress=progress)
    csv_path, png_path = write_outputs(result, args.out)
    print(format_summary(result))
    print(f"wrote {csv_path} and {png_path}")
    return 0


def _check_bend_twist_args(args) -> None:
    """Readable errors for bad bend-twist options (before Taichi starts)."""
    from .bend_twist import BendTwistConfig

    count = 8 if args.count is None else args.count
    if count < 2:
        raise CLIError(f"--count must be >= 2 for bend-twist (a count x count grid), got {count}")
    try:
        args.bend_twist_config = BendTwistConfig(
            steps=args.steps, tilt_steps=min(args.tilt_steps, args.steps), iterations=args.iterations,
            max_edges=args.max_edges, planarity_threshold=args.planarity_threshold, dt=args.dt)
    except ValueError as exc:
        raise CLIError(str(exc).replace("BendTwistConfig.", "--").replace("_", "-")) from None
    args.bend_twist_count = count


def _validate_bend_twist(args, arch) -> int:
    import time

    import numpy as np

    from .bend_twist import default_grid, format_summary, run_bend_twist, write_outputs

    cfg, n = args.bend_twist_config, args.bend_twist_count
    k, phi = default_grid(n)
    K, P = np.meshgrid(k, phi)
    K, P = K.ravel(), P.ravel()
    t0 = time.perf_counter()

    def progress(step, steps, speed):
        if not args.quiet:
            print(f"  step {step:5d}/{steps}: max speed {speed:.3g} m/s ({time.perf_counter() - t0:.0f} s)",
                  flush=True)

    if not args.quiet:
        print(f"bend-twist: {n} x {n} rods, kappa 0.175..2 /cm, phi 0.25..25 pi, {cfg.steps} damped steps of "
              f"{cfg.dt:g} s x {cfg.iterations} ADMM iterations, arch {arch}, {args.precision}", flush=True)
    result = run_bend_twist(K, P / K, cfg, progress=progress)
    if not args.quiet:
        print("  computing the linear-stability map for the figure...", flush=True)
    paths = write_outputs(result, args.out)
    print(format_summary(result))
    print(f"wrote {', '.join(paths)}")
    return 0


def register(sub) -> None:
    v = sub.add_parser("validate", help="validation experiments (Daviet 2023 Sec. 5.1)")
    v.add_argument("experiment", help="experiment name: cantilever, stick-slip or bend-twist")
    v.add_argument("--out", required=True, help="output folder")
    v.add_argument("--count", type=int, default=None,
                   help="cantilever: number of rod lengths (default 100); bend-twist: grid of count x count "
                        "(curvature, phi) rods (default 8)")
    v.add_argument("--w0", type=float, default=0.2, help="ADMM weight scale for the quasistatic solve")
    v.add_argument("--max-iterations", type=int, default=20000)
    v.add_argument("--tolerance", type=float, default=0.02, help="max relative error accepted (exit 1 above)")
    v.add_argument("--strain-measure", default="korner", choices=["korner", "bergou"])
    v.add_argument("--no-voronoi-rescaling", action="store_true", help="disable the Sec. 5.1 boundary rescaling")
    v.add_argument("--substeps", type=int, default=800, help="stick-slip: quasistatic substeps to 0.6 L")
    v.add_argument("--weightless", action="store_true",
                   help="stick-slip: gravity off, against the weightless elastica (default: the rod's weight in both)")
    v.add_argument("--steps", type=int, default=2500, help="bend-twist: damped dynamic steps")
    v.add_argument("--tilt-steps", type=int, default=100, help="bend-twist: first steps with tilted gravity")
    v.add_argument("--iterations", type=int, default=50, help="bend-twist: ADMM iterations per step")
    v.add_argument("--dt", type=float, default=0.02, help="bend-twist: time step [s]")
    v.add_argument("--max-edges", type=int, default=120, help="bend-twist: most edges per rod (2.5 mm below)")
    v.add_argument("--planarity-threshold", type=float, default=1e-4,
                   help="bend-twist: PCA min/mean eigenvalue below which a shape is planar")
    _add_common(v)
    v.set_defaults(func=cmd_validate)

