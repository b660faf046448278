"""What a new Model costs in a running process: Taichi kernel instances, and the seconds to build it and step it once.

Run from the repository root (``--cache`` points Taichi's offline kernel cache at a folder of its own; run twice,
the first run fills it, the second reads it)::

    python3 benchmarks/probes/model_instances.py --cache /tmp/model_instances_cache [--reps 4] [--json OUT]

Each of ``--reps`` rounds builds the same 4-strand x 10-vertex Model, its State, a ``SolverADMM`` and Control, and
steps once, in one process.  Printed per round: the seconds of Model + State, of solver + step, and the kernel
instances Taichi made (its frontend ran, ``Kernel.ensure_compiled``), by name.  Every round makes its instances anew:
Taichi specialises a kernel per field object, and a new Model's fields are new objects.  Taichi's offline cache keys
a kernel by its IR, in which the fields' tree and offsets appear, so the second round's kernels are other cache
entries than the first's (a second run of this probe reads them all; a fresh folder compiles every round).  The
BENCHMARKS.md section "Kernel instances per Model" ran it.
"""

import argparse
import collections
import json
import os
import time


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", default=None, help="Taichi's offline cache folder (default: taichi_hair.init's)")
    ap.add_argument("--reps", type=int, default=4)
    ap.add_argument("--json", default=None, help="write the rounds' figures to this file")
    a = ap.parse_args(argv)
    import numpy as np
    import taichi as ti
    import taichi.lang.kernel_impl as kernel_impl

    import taichi_hair

    init = {"offline_cache_file_path": os.path.abspath(a.cache)} if a.cache else {}
    taichi_hair.init(arch=ti.x64, default_fp=ti.f32, log_level=ti.WARN, **init)
    from taichi_hair import GroomBuilder, SolverADMM
    from taichi_hair.cli.common import lighter_kernel_positions

    lighter_kernel_positions()  # as the command line and the app do
    names = collections.Counter()
    ensure_compiled = kernel_impl.Kernel.ensure_compiled

    def counting(self, *args):
        known = len(self.compiled_kernels)
        key = ensure_compiled(self, *args)
        if len(self.compiled_kernels) > known:
            names[self.func.__name__] += 1
        return key

    kernel_impl.Kernel.ensure_compiled = counting
    rounds = []
    for rep in range(a.reps):
        names.clear()
        t = time.perf_counter()
        b = GroomBuilder()
        for s in range(4):
            b.add_strand(np.stack([np.zeros(10) + 0.01 * s, -np.linspace(0.0, 0.1, 10), np.zeros(10)], 1))
        model = b.finalize()
        state = model.state()
        t_model = time.perf_counter() - t
        t = time.perf_counter()
        solver = SolverADMM(model)
        solver.step(state, model.control(), 1e-3)
        ti.sync()
        t_solver = time.perf_counter() - t
        rounds.append({"round": rep, "model_state_s": t_model, "solver_step_s": t_solver,
                       "instances": sum(names.values()), "by_kernel": dict(names.most_common())})
        print(f"round {rep}: Model + State {t_model:.2f} s, solver + step {t_solver:.2f} s, "
              f"{sum(names.values())} kernel instances: {dict(names.most_common(6))}")
    if a.json:
        with open(a.json, "w") as fh:
            json.dump({"cache": a.cache, "rounds": rounds}, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
