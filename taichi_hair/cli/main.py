"""The ``taichi-hair`` command line.

    taichi-hair simulate hang --strands 300 --frames 48 --out out/hang
    taichi-hair validate cantilever --out out/validation

Errors are one readable line on stderr and a non-zero exit code.
"""

from __future__ import annotations

import argparse
import sys

from .common import CLIError


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
    from .rest_pose import register as register_rest_pose
    from ..io.cli import register as register_io
    from ..validation.cli import register as register_validate

    register_simulate(sub)
    register_validate(sub)
    register_io(sub)
    register_groom(sub)
    register_render(sub)
    register_rest_pose(sub)
    register_bench(sub)
    return p


def _one_line_warning(message, category, filename, lineno, file=None, line=None):
    """Warnings as one ``warning: ...`` line on stderr (the message names its file, strand or field), not
    Python's two lines with the source file, line number and code."""
    text = " ".join(str(message).split("\n"))
    print(f"warning: {text}", file=file if file is not None else sys.stderr)


def main(argv=None) -> int:
    import warnings

    parser = build_parser()
    args = parser.parse_args(argv)
    shown = warnings.showwarning
    warnings.showwarning = _one_line_warning
    try:
        return args.func(args)
    except CLIError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except (ValueError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except RuntimeError as exc:  # SimulationDivergedError and Taichi runtime failures
        print(f"error: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 1
    except MemoryError:
        from ..io.sizing import available_memory, format_bytes

        print(f"error: out of memory ({format_bytes(available_memory())} available now); use fewer strands, "
              "vertices or frames", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    finally:
        warnings.showwarning = shown


if __name__ == "__main__":
    sys.exit(main())
