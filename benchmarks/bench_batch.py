"""Batches on Dask: 8 variants of the hang scene, one ``simulate`` at a time against ``taichi-hair batch`` on
1 and 2 worker processes.

    python3 benchmarks/bench_batch.py                       # assets/batches/hang_variants.toml
    python3 benchmarks/bench_batch.py --spec my_batch.toml  # any batch file of built-in-scene runs

Figures (all wall-clock, from the launch of the command to its exit, in one run of this script, so that the
load of a shared machine affects them alike; the kernel cache is warmed by one run first):

- ``sequential_s``: each run as its own ``taichi-hair simulate`` process, one after the other (what a batch
  replaces: a process start, imports and ``ti.init`` per run);
- ``batch_1_s`` / ``batch_2_s``: ``taichi-hair batch`` with ``--workers 1`` / ``2`` at its default
  ``--pack 0``: runs that differ only in their grooms share a task and one Model (cli/simulate_pack.py);
- ``unpacked_1_s`` / ``unpacked_2_s``: the same with ``--pack 1`` (a LocalCluster's start, then one task per
  run in long-lived worker processes); ``pack_saving_1`` / ``pack_saving_2`` = unpacked / packed;
- ``speedup_2_over_1`` = batch_1_s / batch_2_s; ``speedup_2_over_sequential`` = sequential_s / batch_2_s;
- ``overhead_per_task_s`` = (batch_1_s - sequential_s) / runs: what one worker costs per run over running
  the same runs one ``simulate`` at a time (negative: the batch is cheaper per run);
- ``rerun_all_finished_s``: the same batch again once every run is done (reading the spec and the runs'
  records, no cluster started).

Writes ``benchmarks/results/batch.json``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time

from harness import ROOT, Bench, results_path  # benchmarks/harness.py (the script's folder is on sys.path)


def _cli(*args) -> float:
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    t = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "taichi_hair.cli", *map(str, args)], env=env,
                          capture_output=True, text=True)
    wall = time.perf_counter() - t
    if proc.returncode != 0:
        raise SystemExit(f"bench_batch: {' '.join(map(str, args))} failed ({proc.returncode}): "
                         f"{proc.stderr.strip()[-400:]}")
    return wall


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--spec", default=os.path.join(ROOT, "assets", "batches", "hang_variants.toml"))
    p.add_argument("--out", default=results_path("batch.json"))
    args = p.parse_args(argv)
    bench = Bench("batch", argv)

    sys.path.insert(0, ROOT)
    from taichi_hair.cli.batch import simulate_actions, run_argv
    from taichi_hair.scene.batch import read_batch

    actions = simulate_actions()
    runs = read_batch(args.spec, actions)
    tmp = tempfile.mkdtemp(prefix="bench_batch_")
    try:
        seq_dir = os.path.join(tmp, "seq")
        commands = [run_argv(r, seq_dir, actions) for r in runs]
        _cli(*commands[0][:-3], "--out", os.path.join(tmp, "warm"), "--quiet")  # warm the kernel cache
        t = time.perf_counter()
        for c in commands:
            _cli(*c)
        sequential = time.perf_counter() - t
        batch, unpacked = {}, {}
        for w in (1, 2):
            batch[w] = _cli("batch", args.spec, "--out", os.path.join(tmp, f"b{w}"), "--workers", w, "--quiet")
            unpacked[w] = _cli("batch", args.spec, "--out", os.path.join(tmp, f"u{w}"), "--workers", w, "--pack", 1,
                               "--quiet")
        rerun = _cli("batch", args.spec, "--out", os.path.join(tmp, "b1"), "--workers", 1, "--quiet")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    n = len(runs)
    figures = {
        "spec": os.path.relpath(args.spec, ROOT), "runs": n,
        "sequential_s": round(sequential, 2), "batch_1_s": round(batch[1], 2), "batch_2_s": round(batch[2], 2),
        "unpacked_1_s": round(unpacked[1], 2), "unpacked_2_s": round(unpacked[2], 2),
        "pack_saving_1": round(unpacked[1] / batch[1], 3), "pack_saving_2": round(unpacked[2] / batch[2], 3),
        "speedup_2_over_1": round(batch[1] / batch[2], 3),
        "speedup_2_over_sequential": round(sequential / batch[2], 3),
        "overhead_per_task_s": round((batch[1] - sequential) / n, 3),
        "rerun_all_finished_s": round(rerun, 2),
    }
    for k, v in figures.items():
        print(f"{k:28s} {v}")
    print(f"wrote {bench.write(args.out, figures)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
