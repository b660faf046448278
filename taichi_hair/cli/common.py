"""Helpers shared by the ``taichi-hair`` sub-commands (no Taichi import at module load)."""

from __future__ import annotations

import ctypes
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
    from taichi_hair import init

    init(arch=archs[arch], default_fp=fp, log_level=ti.WARN)
    lighter_kernel_positions()
    no_numpy_huge_pages()
    keep_freed_memory()
    used = str(ti.lang.impl.current_cfg().arch).split(".")[-1]
    return ti, used


#: Environment switch: set to 1 to keep Taichi's own position messages (:func:`lighter_kernel_positions`).
STOCK_POSITIONS_ENV = "TAICHI_HAIR_STOCK_POSITIONS"


def lighter_kernel_positions() -> bool:
    """Make Taichi's frontend cheaper: its position message of an AST node becomes file, line, function and
    the source line, without the source wrapped to 80 columns under a caret line.  Returns whether it applied.

    Why: when a kernel is first called, Taichi's frontend turns its Python AST into IR, also when the compiled
    kernel then comes from the offline cache, and for every node it formats a position message
    (``ASTTransformerContext.get_pos_info``: ``textwrap`` on the source line and a caret line), which is only
    ever printed when a kernel fails to compile.  Measured on the 2-core VM (2026-12-04): cProfile of a warm
    ``taichi-hair groom --offscreen`` with one advance put 3.2 s of the frontend's 6.6 s in it (81,110 calls);
    wall time of that command 9.2-9.6 s with Taichi's messages, 7.9 s with these (twice each, same frames).
    The kernels and their results do not change (tests/test_cli.py compares a run's bits with and without).
    What a user loses: the caret under the failing expression in a Taichi compile error (file, line and code
    stay).  Skipped, keeping Taichi's own, when ``TAICHI_HAIR_STOCK_POSITIONS=1`` or when this Taichi has no such
    method (the project pins taichi 1.7).  Applied by the command line and the grooming app after ``ti.init``,
    and by the test suite's set-up; the library never applies it."""
    if os.environ.get(STOCK_POSITIONS_ENV) == "1":
        return False
    try:
        from taichi.lang.ast import ast_transformer_utils
    except ImportError:
        return False
    ctx = getattr(ast_transformer_utils, "ASTTransformerContext", None)
    if ctx is None or not callable(getattr(ctx, "get_pos_info", None)):
        return False
    if getattr(ctx.get_pos_info, "_taichi_hair_light", False):
        return True

    def get_pos_info(self, node):
        line = node.lineno + self.lineno_offset
        src = self.src[node.lineno - 1] if 0 < node.lineno <= len(self.src) else ""
        return f'File "{self.file}", line {line}, in {self.func.func.__name__}:\n{src}\n'

    get_pos_info._taichi_hair_light = True
    ctx.get_pos_info = get_pos_info
    return True


#: NumPy's own environment switch for transparent huge pages (read by NumPy at import; 0 off, 1 on).  Where a user
#: sets it, :func:`no_numpy_huge_pages` leaves NumPy as told.
NUMPY_HUGE_PAGES_ENV = "NUMPY_MADVISE_HUGEPAGE"


def no_numpy_huge_pages() -> bool:
    """Keep NumPy from asking the kernel for transparent huge pages for its large arrays (``madvise``), unless
    the environment's ``NUMPY_MADVISE_HUGEPAGE`` says otherwise.  Returns whether it switched them off.

    Why: NumPy (>= 1.20 on Linux >= 4.6) advises huge pages for every array of 4 MiB or more.  Where the kernel
    compacts memory on such a fault (``/sys/kernel/mm/transparent_hugepage/defrag`` = ``madvise``, the default),
    each 2 MiB fault can stall.  Measured on the 2-core VM (2026-12-05, ``benchmarks/probes/numpy_huge_pages.py``;
    the huge pages did come): copying a 29 MB array into new memory took 62-74 ms with the advice and 13-15 ms
    without, every time.  A grooming edit makes such arrays (the new groom, since undo keeps the old one): an edit
    of 8,600 of 86,000 strands went from 0.21 s host + 0.32 s update to 0.10 + 0.27 s
    (``benchmarks/bench_groom.py``).  Where huge pages come fast, the advice saves most page faults of a new array
    (the same copy into memory already touched takes ~4 ms here), so, as an estimate, the most this costs elsewhere
    is ~10 ms per 29 MB of new memory.  Applied by the command line and the grooming app with ``ti.init``; the
    library never applies it.  Skipped where this NumPy has no switch."""
    if os.environ.get(NUMPY_HUGE_PAGES_ENV) is not None:
        return False
    try:
        from numpy._core import multiarray
    except ImportError:  # NumPy 1.x
        from numpy.core import multiarray
    switch = getattr(multiarray, "_set_madvise_hugepage", None)
    if switch is None:
        return False
    switch(False)
    return True


#: Environment switch: set to 1 to keep glibc's own malloc thresholds (:func:`keep_freed_memory`); glibc's
#: ``MALLOC_MMAP_THRESHOLD_`` / ``MALLOC_TRIM_THRESHOLD_``, where set, are also left as the user set them.
STOCK_MALLOC_ENV = "TAICHI_HAIR_STOCK_MALLOC"
#: glibc's largest mmap threshold on 64-bit (4 MiB x sizeof(long)) and the trim threshold :func:`keep_freed_memory` sets [B].
MALLOC_MMAP_THRESHOLD = 32 << 20
MALLOC_TRIM_THRESHOLD = 1 << 30


def keep_freed_memory() -> bool:
    """Let glibc keep the memory NumPy frees for the next arrays instead of handing it back to the kernel: arrays up to
    32 MiB come from the heap (``M_MMAP_THRESHOLD``), and freed heap memory up to 1 GiB stays mapped
    (``M_TRIM_THRESHOLD``).  Returns whether it applied.

    Why: by default glibc maps each large array anew and unmaps it when freed, or trims the heap past twice the
    largest array freed, so the next array's first touch page-faults again, at a few microseconds a page on the VM.
    A grooming edit makes and drops many such arrays (the groom's 1.2 M vertices are 14-29 MB per array). Measured
    on the 2-core VM (2026-12-07, three pairs of processes, each pair alternating; the first two pairs a scratch
    form of ``benchmarks/probes/groom_edit_malloc.py [--keep]``, the third the probe itself; the grooming
    benchmark's groom, 4 edits of 8,600 strands each): host + update of the first edit 0.60 / 0.68 / 0.74 s stock,
    0.52 / 0.53 / 0.75 s with this; the three edits after it 0.44-0.50 / 0.45 / 0.49-0.58 s stock, 0.38-0.44 /
    0.36-0.41 / 0.43-0.47 s with this; peak memory 1,431-1,432 against 1,437 MB.  So the later edits gain ~10 %, the
    first one did in two of the three pairs.  What it costs: a process's resident memory stays near its peak instead
    of shrinking when arrays are freed (up to 1 GiB of freed memory is kept for the next arrays; the peak itself
    does not grow), per process: a batch's workers each keep theirs.  Applied by the command line and the grooming
    app with ``ti.init``; the library never applies it.  Skipped where the C library has no ``mallopt`` (not glibc:
    musl's does nothing and returns 0), when ``TAICHI_HAIR_STOCK_MALLOC=1``, or where the user set glibc's own
    variables."""
    if os.environ.get(STOCK_MALLOC_ENV) == "1" or any(
            k in os.environ for k in ("MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_")):
        return False
    if not sys.platform.startswith("linux"):
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    m_trim_threshold, m_mmap_threshold = -1, -3  # <malloc.h>
    return mallopt(m_mmap_threshold, MALLOC_MMAP_THRESHOLD) == 1 and mallopt(m_trim_threshold, MALLOC_TRIM_THRESHOLD) == 1


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
