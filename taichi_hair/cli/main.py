"""The ``taichi-hair`` command line.

    taichi-hair simulate hang --strands 300 --frames 48 --out out/hang
    taichi-hair validate cantilever --out out/validation

Errors are one readable line on stderr and a non-zero exit code.
"""

from __future__ import annotations

import argparse
import sys


# --------------------------------------------------------------------------- main
def build_parser() -> argparse.ArgumentParser:
    from .. import __version__

    p = argparse.ArgumentParser(prog="taichi-hair", description="Hair simulation on Taichi (Daviet 2023 ADMM).")
    p.add_argument("--version", action="version", version=f"taichi-hair {__version__}")
    sub = p.add_subparsers(dest="command", required=True)

    # One module per command family; each owns its arguments and its work.
    from ..bench.cli import register as register_bench
    from .simulate import register as register_simulate
    from .groom import register as register_groom
    from .render import register as register_render
    from .batch import register as register_batch
    from .rest_pose import register as register_rest_pose
    from ..io.cli import register as register_io
    from ..validation.cli import register as register_validate

    register_simulate(sub)
    register_validate(sub)
    register_io(sub)
    register_groom(sub)
    register_render(sub)
    register_batch(sub)
    register_rest_pose(sub)
    register_bench(sub)
    return p


def main(argv=None) -> int:
    from .common import run_guarded

    args = build_parser().parse_args(argv)
    return run_guarded(args.func, args)


if __name__ == "__main__":
    sys.exit(main())
