"""What NumPy's transparent-huge-page advice costs a new large array on this machine (issue 15 item 4, the edit).

Run from the repository root:
    python3 benchmarks/probes/numpy_huge_pages.py [ROWS]

Copies a (ROWS, 3) float64 array (default 1.2 M rows, 29 MB: the grooming benchmark's render vertices) into new
memory 6 times with NumPy's ``madvise`` of huge pages on, then off, twice, and prints the milliseconds of each
copy, the kernel's THP settings and ``AnonHugePages`` (how much memory did get huge pages).  The copies are kept
alive, so each one faults in fresh pages.  ``taichi_hair.cli.common.no_numpy_huge_pages`` switches the advice off
in the command line and the grooming app; BENCHMARKS.md has the figures.
"""

import sys
import time

import numpy as np

try:
    from numpy._core import multiarray
except ImportError:  # NumPy 1.x
    from numpy.core import multiarray


def _read(path):
    try:
        with open(path) as fh:
            return fh.read().strip()
    except OSError:
        return "n/a"


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    rows = int(argv[0]) if argv else 1_200_000
    a = np.random.default_rng(0).random((rows, 3))
    print(f"THP enabled: {_read('/sys/kernel/mm/transparent_hugepage/enabled')}; "
          f"defrag: {_read('/sys/kernel/mm/transparent_hugepage/defrag')}")
    keep = []
    for advice in (True, False, True, False):
        multiarray._set_madvise_hugepage(advice)
        ms = []
        for _ in range(6):
            t = time.perf_counter()
            keep.append(a.copy())
            ms.append(1e3 * (time.perf_counter() - t))
        print(f"huge-page advice {'on ' if advice else 'off'}: copy of {a.nbytes / 1e6:.0f} MB into new memory, ms: "
              + " ".join(f"{v:.1f}" for v in ms))
    meminfo = [line for line in _read("/proc/meminfo").splitlines() if line.startswith("AnonHugePages")]
    print(meminfo[0] if meminfo else "AnonHugePages: n/a")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
