"""Helpers shared by the ``taichi-hair`` sub-commands (no Taichi import at module load)."""

from __future__ import annotations

import os
import sys

import numpy as np


class CLIError(Exception):
    """A user-facing error: printed as one line, exit code 2."""


def _init_taichi(arch: str, precision: str):
    import taichi as ti

    archs = {"cpu": ti.cpu, "cuda": ti.cuda, "gpu": ti.gpu, "vulkan": ti.vulkan}
    if arch not in archs:
        raise CLIError(f"--arch must be one of {sorted(archs)}, got {arch!r}")
    fp = {"f32": ti.f32, "f64": ti.f64}[precision]
    ti.init(arch=archs[arch], default_fp=fp, log_level=ti.WARN)
    used = str(ti.lang.impl.current_cfg().arch).split(".")[-1]
    return ti, used


def _atomic_savez(path: str, **arrays):
    tmp = path + ".tmp.npz"
    np.savez_compressed(tmp, **arrays)
    os.replace(tmp, path)


def _add_common(p):
    p.add_argument("--arch", default="cpu", help="Taichi arch: cpu (default), cuda, gpu, vulkan")
    p.add_argument("--precision", default="f32", choices=["f32", "f64"], help="floating point precision")
    p.add_argument("--quiet", action="store_true", help="print only the summary")




def _one_line_warning(message, category, filename, lineno, file=None, line=None):
    """Warnings as one ``warning: ...`` line on stderr (the message names its file, strand or field), not
    Python's two lines with the source file, line number and code."""
    text = " ".join(str(message).split("\n"))
    print(f"warning: {text}", file=file if file is not None else sys.stderr)


def run_guarded(func, args) -> int:
    """Run a command's function with every expected failure as one ``error:`` line on stderr and an exit
    status: 2 for bad input (CLIError, ValueError, OSError) and out of memory, 1 for a run that failed
    (SimulationDivergedError, Taichi runtime errors), 130 for Ctrl-C; warnings as one line each."""
    import warnings

    shown = warnings.showwarning
    warnings.showwarning = _one_line_warning
    try:
        return func(args)
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
