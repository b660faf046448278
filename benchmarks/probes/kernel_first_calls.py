"""Where a run's start-up goes, kernel by kernel: Taichi's Python frontend and each kernel's first launch.

Run any script under it, from the repository root (``PYTHONPATH=benchmarks`` lets a benchmark script find
``harness``); for a cold start, point Taichi's offline cache at an empty folder::

    TI_OFFLINE_CACHE_FILE_PATH=$(mktemp -d) PYTHONPATH=benchmarks python3 benchmarks/probes/kernel_first_calls.py \\
        benchmarks/bench_groom.py --no-draw --strands 86000 --frames 1 --rest-pose sag-free

For every kernel (by name, over all its template instances) it adds up the time of Taichi's frontend when an
instance is new (``Kernel.ensure_compiled``: the Python AST turned into IR, done even when the compiled kernel
then comes from the offline cache) and the time of each instance's first launch, synchronised (the IR passes and
LLVM's compilation, or the cache's load, plus one run of the kernel).  Printed at exit, largest first.  How
``taichi_hair.TAICHI_INIT_OPTIONS`` was chosen (BENCHMARKS.md, "Kernel compilation: Taichi's IR passes").  A
diagnostic, not a benchmark: the first launch's run is in its figure, and the synchronisation adds a little.
"""

import atexit
import collections
import runpy
import sys
import time


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(__doc__)
        return 0 if argv else 2
    import taichi as ti
    import taichi.lang.kernel_impl as kernel_impl

    frontend = collections.defaultdict(float)
    first = collections.defaultdict(float)
    instances = collections.Counter()
    launched = set()
    ensure_compiled, launch_kernel = kernel_impl.Kernel.ensure_compiled, kernel_impl.Kernel.launch_kernel

    def timed_ensure_compiled(self, *args):
        known = len(self.compiled_kernels)
        t = time.perf_counter()
        key = ensure_compiled(self, *args)
        if len(self.compiled_kernels) > known:
            frontend[self.func.__name__] += time.perf_counter() - t
            instances[self.func.__name__] += 1
        return key

    def timed_launch_kernel(self, t_kernel, *args):
        if id(t_kernel) in launched:
            return launch_kernel(self, t_kernel, *args)
        launched.add(id(t_kernel))
        t = time.perf_counter()
        out = launch_kernel(self, t_kernel, *args)
        ti.sync()
        first[self.func.__name__] += time.perf_counter() - t
        return out

    kernel_impl.Kernel.ensure_compiled = timed_ensure_compiled
    kernel_impl.Kernel.launch_kernel = timed_launch_kernel

    @atexit.register
    def report():
        total = {n: frontend[n] + first[n] for n in set(frontend) | set(first)}
        print(f"\n== kernels: {len(total)} names, {sum(instances.values())} instances, frontend "
              f"{sum(frontend.values()):.1f} s, first launches {sum(first.values()):.1f} s", file=sys.stderr)
        for n, v in sorted(total.items(), key=lambda kv: -kv[1])[:40]:
            print(f"{v:7.2f} s  frontend {frontend[n]:6.2f}  first {first[n]:6.2f}  x{instances[n]}  {n}",
                  file=sys.stderr)

    sys.argv = argv
    runpy.run_path(argv[0], run_name="__main__")
    return 0


if __name__ == "__main__":
    sys.exit(main())
