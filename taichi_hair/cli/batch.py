"""``taichi-hair batch SPEC.toml --out DIR``: many ``simulate`` runs on Dask distributed.

    taichi-hair batch assets/batches/hang_variants.toml --out out/batch --workers 2
    taichi-hair batch spec.toml --out /shared/out --scheduler tcp://10.0.0.5:8786   # an existing cluster

The spec (:mod:`taichi_hair.scene.batch`) names a base scene and runs.  Each Dask task runs one run, or a
pack of small runs (below), in a worker process exactly as ``taichi-hair simulate SCENE ... --out
DIR/<name>`` would (the same arguments, so the same frames, bit for bit: tested), with stdout and stderr kept
in ``DIR/<name>/batch.log``.  Without ``--scheduler`` a ``LocalCluster`` of ``--workers`` processes with one
thread each runs them; each task initialises Taichi in its worker process (``ti.init`` resets the runtime, so
a task starts clean and the previous task's fields are freed) and its kernels come from Taichi's offline cache,
which the workers of one machine share (``TI_OFFLINE_CACHE_FILE_PATH``, default ``~/.cache/taichi``).

Small runs are packed (``--pack``, default auto): runs of the same scene that differ only in their grooms
(``seed``, ``strands``, ``length``, ``vertices_per_strand``, ``groom.*`` and ``material.*`` keys) go into one
task that steps them as one Model (:mod:`taichi_hair.cli.simulate_pack`: same frames, bit for bit, when the
scene has no contacts; otherwise the task runs them one by one), so set-up and kernel loading are paid once
per task, not per run.  ``--pack 1`` runs every run on its own.

A failed run (a bad parameter, a divergence, a worker killed) is recorded by name with its one-line error and
the others go on; the command then exits 1 and names the failed runs.  ``DIR/batch.csv`` and
``DIR/batch.json`` gather every run's status, wall time, ms per frame and quality figures.  Running the same
command again skips the runs that finished (``DIR/<name>/batch_done.json`` records their arguments; a run
whose arguments changed runs again) and resumes unfinished ones from their checkpoints (a worker that dies is
replaced by Dask and its task retried, resuming the same way).

With ``--scheduler`` the workers must see ``DIR`` (and a scene file) at the same absolute paths (shared
storage) and run the same environment (taichi-hair installed: the scheduler unpickles the task's function).

Dask is the only part of the project that needs ``distributed`` (``pip install -e .[batch]``, which
``setup.sh`` does); the library never imports it.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import sys
import time

from .common import CLIError

#: Columns of batch.csv (and keys of each run in batch.json).
COLUMNS = ("name", "status", "exit_code", "resumed_from_frame", "task_seconds", "wall_seconds", "ms_per_frame",
           "frames", "strands", "vertices", "strain_p50_max", "strain_p99_max", "strain_max", "body_penetration_max_m",
           "vertices_inside_max", "hair_penetration_max_m", "came_to_rest", "drift_p90_last_m", "shape_distance_p90_last_m",
           "diverged", "error", "packed_with", "command")
#: simulate options that change only a run's groom: runs differing in these (and in groom.* / material.* keys)
#: may share a pack (cli/simulate_pack.py decides whether they really can).
PACK_NEUTRAL_OPTIONS = ("seed", "strands", "length", "vertices_per_strand")
PACK_NEUTRAL_SETS = ("groom.", "material.")
DONE_FILE = "batch_done.json"
LOG_FILE = "batch.log"


# --------------------------------------------------------------------------- runs -> simulate arguments
def simulate_parser() -> argparse.ArgumentParser:
    """A parser of ``simulate`` alone (the same options as ``taichi-hair simulate``)."""
    return _simulate_parsers()[0]


def _simulate_parsers():
    from .simulate import register

    p = argparse.ArgumentParser(prog="taichi-hair", exit_on_error=False)
    sub = p.add_subparsers(dest="command", required=True)
    register(sub)
    return p, sub.choices["simulate"]


def simulate_actions() -> dict:
    """simulate's options by ``dest`` name (the argparse actions a batch run's keys map to)."""
    return {a.dest: a for a in _simulate_parsers()[1]._actions if a.option_strings}


def _literal(v) -> str:
    """A TOML literal of a spec value (numbers, booleans, strings, lists of them)."""
    return json.dumps(v)


def run_argv(run, out_dir: str, actions: dict) -> list:
    """``simulate`` arguments of one :class:`~taichi_hair.scene.batch.BatchRun` (without ``--resume``,
    which the task adds when a checkpoint is there)."""
    argv = ["simulate", run.scene]
    for dest, value in run.options.items():
        action = actions[dest]
        flag = max(action.option_strings, key=len)
        if isinstance(action, argparse._StoreTrueAction):
            if not isinstance(value, bool):
                raise CLIError(f"run {run.name}: {flag} is a switch: give true or false, got {value!r}")
            if value:
                argv.append(flag)
        elif isinstance(action, argparse._AppendAction) or action.nargs not in (None, "?"):
            values = value if isinstance(value, list) else [value]
            argv += [flag] + [str(v) for v in values]
        else:
            argv += [flag, str(value)]
    for key, value in run.sets.items():
        argv += ["--set", f"{key}={_literal(value)}"]
    return argv + ["--out", os.path.join(out_dir, run.name), "--quiet"]


# --------------------------------------------------------------------------- the task (in a worker)
def run_task(name: str, argv: list) -> dict:
    """One run in a worker process: ``simulate`` with its output redirected to ``DIR/<name>/batch.log``;
    ``--resume`` when the run's checkpoint exists (a rerun, or Dask's retry after a worker died)."""
    import contextlib
    import io

    out = argv[argv.index("--out") + 1]
    resumable = os.path.exists(os.path.join(out, "checkpoint.npz"))
    full = argv + (["--resume"] if resumable else [])
    buf = io.StringIO()
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(buf):
        try:
            args = simulate_parser().parse_args(full)
        except (argparse.ArgumentError, SystemExit) as exc:
            if isinstance(exc, argparse.ArgumentError):  # (argparse printed a SystemExit's message itself)
                print(f"error: {exc}", file=sys.stderr)
            rc = 2
        else:
            from .common import run_guarded

            try:
                rc = run_guarded(args.func, args)
            except Exception as exc:  # noqa: BLE001 - one run's bug must not stop the batch; recorded by name
                print(f"error: {type(exc).__name__}: {exc}", file=sys.stderr)
                rc = 1
    wall = time.perf_counter() - t0
    log = buf.getvalue()
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, LOG_FILE), "a") as fh:
        fh.write(f"$ taichi-hair {' '.join(full)}\n{log}\n")
    errors = [ln for ln in log.splitlines() if ln.startswith("error:")]
    error = errors[-1][len("error:"):].strip() if errors else ("" if rc == 0 else (log.strip().splitlines() or
                                                                                  [f"exit {rc}"])[-1])
    if rc == 0:
        with open(os.path.join(out, DONE_FILE), "w") as fh:
            json.dump({"argv": argv}, fh)
    return {"name": name, "exit_code": int(rc), "task_wall_seconds": wall, "error": error, "resumed": resumable}


def run_pack_task(names: list, argvs: list) -> list:
    """Several runs in one worker process, stepped as one Model when they can be (cli/simulate_pack.py), else
    one by one (:func:`run_task`); returns :func:`run_task`'s record per run, ``packed_with`` naming the
    pack's runs.  A run with a checkpoint (a rerun after a kill) resumes on its own."""
    import contextlib
    import io

    if len(names) == 1:
        return [run_task(names[0], argvs[0])]
    alone = [i for i, a in enumerate(argvs) if os.path.exists(os.path.join(a[a.index("--out") + 1], "checkpoint.npz"))]
    packed = [i for i in range(len(names)) if i not in alone]
    results = {}
    if len(packed) > 1:
        buf = io.StringIO()
        t0 = time.perf_counter()
        codes = None
        with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(buf):
            try:
                codes = _run_pack([argvs[i] for i in packed])
            except (Exception, SystemExit) as exc:  # noqa: BLE001 - PackRefused, a bad argument, anything: the
                # runs then go one by one, each reporting its own error
                print(f"note: not packed ({type(exc).__name__}: {exc}); running each run alone")
        wall = time.perf_counter() - t0
        log = buf.getvalue()
        if codes is not None:
            together = [names[i] for i in packed]
            for i, rc in zip(packed, codes):
                out = argvs[i][argvs[i].index("--out") + 1]
                os.makedirs(out, exist_ok=True)
                with open(os.path.join(out, LOG_FILE), "a") as fh:
                    fh.write(f"$ taichi-hair {' '.join(argvs[i])}  # packed with {', '.join(together)}\n{log}\n")
                if rc == 0:
                    with open(os.path.join(out, DONE_FILE), "w") as fh:
                        json.dump({"argv": argvs[i]}, fh)
                results[i] = {"name": names[i], "exit_code": int(rc), "task_wall_seconds": wall, "resumed": False,
                              "error": "" if rc == 0 else f"exit {rc} (see {LOG_FILE})", "packed_with": together}
        else:
            alone = sorted(alone + packed)
            for i in packed:  # why they run alone, at the head of each run's log
                out = argvs[i][argvs[i].index("--out") + 1]
                os.makedirs(out, exist_ok=True)
                with open(os.path.join(out, LOG_FILE), "a") as fh:
                    fh.write(log)
    for i in alone:
        if i not in results:
            results[i] = run_task(names[i], argvs[i])
    return [results[i] for i in range(len(names))]


def _run_pack(argvs: list) -> list:
    """Prepare every run as simulate would, initialise Taichi once, and step them as one Model."""
    from .common import _init_taichi
    from .simulate import prepare_simulate
    from .simulate_pack import PackedSimulate
    from .simulate_run import SimulateRun

    parser = simulate_parser()
    prepared = []
    for argv in argvs:
        args = parser.parse_args(argv)
        prepared.append((args, *prepare_simulate(args)))
    args0 = prepared[0][0]
    _, arch = _init_taichi(args0.arch, args0.precision)
    runs = [SimulateRun(args, scene, warnings, layout, arch) for args, scene, warnings, layout in prepared]
    return PackedSimulate(runs).run()


def pack_groups(runs: list, todo: list, workers: int, pack: int) -> list:
    """The tasks of a batch: lists of run names.  Runs whose simulate arguments differ only in
    ``PACK_NEUTRAL_OPTIONS`` and ``PACK_NEUTRAL_SETS`` keys share a group; a group is cut into packs of at most
    ``pack`` runs (0: auto, the runs to do spread evenly over the workers; 1: no packing)."""
    import math

    from .simulate_pack import MAX_PACK

    by_name = {r.name: r for r in runs}
    size = pack if pack > 0 else max(1, math.ceil(len(todo) / max(workers, 1)))
    size = min(size, MAX_PACK)
    groups: dict = {}
    for name in todo:
        r = by_name[name]
        opts = tuple(sorted((k, str(v)) for k, v in r.options.items() if k not in PACK_NEUTRAL_OPTIONS))
        sets = tuple(sorted((k, str(v)) for k, v in r.sets.items() if not k.startswith(PACK_NEUTRAL_SETS)))
        groups.setdefault((r.scene, opts, sets), []).append(name)
    tasks = []
    for members in groups.values():
        tasks += [members[i:i + size] for i in range(0, len(members), size)]
    return tasks


# --------------------------------------------------------------------------- the driver
def _finished(out: str, argv: list) -> bool:
    try:
        with open(os.path.join(out, DONE_FILE)) as fh:
            return json.load(fh).get("argv") == argv
    except (OSError, ValueError):
        return False


def _row(name: str, out: str, argv: list, status: str, result: dict | None) -> dict:
    row = dict.fromkeys(COLUMNS, "")
    row.update(name=name, status=status, command="taichi-hair " + " ".join(argv))
    try:
        with open(os.path.join(out, "summary.json")) as fh:
            s = json.load(fh)
    except (OSError, ValueError):
        s = None
    if s is not None:
        q = s.get("quality", {}) or {}
        row.update(resumed_from_frame=s.get("resumed_from_frame"), wall_seconds=s.get("wall_seconds"),
                   ms_per_frame=s.get("ms_per_frame"), frames=s.get("frames"), strands=s.get("strands"),
                   vertices=s.get("vertices"), diverged=s.get("diverged"))
        for k in ("strain_p50_max", "strain_p99_max", "strain_max", "body_penetration_max_m",
                  "vertices_inside_max", "came_to_rest", "drift_p90_last_m", "shape_distance_p90_last_m"):
            row[k] = q.get(k)
        row["hair_penetration_max_m"] = q.get("hair_penetration_max_m_max")
    if result is not None:
        row.update(exit_code=result.get("exit_code"), error=result.get("error", ""),
                   task_seconds=result.get("task_wall_seconds", ""),
                   packed_with=" ".join(result.get("packed_with", [])))
    elif status == "done":
        row["exit_code"] = 0
    return row


def _client(args):
    import logging

    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise CLIError("batch needs Dask distributed: pip install 'taichi-hair[batch]' (setup.sh installs it)") \
            from None
    import dask

    # A killed worker is replaced by its nanny and the task retried (resuming from the run's checkpoint);
    # after this many deaths the run is recorded as failed.
    dask.config.set({"distributed.scheduler.allowed-failures": 2})
    if args.scheduler:
        try:
            client = Client(args.scheduler, timeout=30)
            client.has_dashboard = True  # the cluster's own, when it runs one
            return client, None
        except (OSError, TimeoutError) as exc:
            raise CLIError(f"--scheduler {args.scheduler}: cannot connect ({exc})") from None
    try:
        import bokeh  # noqa: F401 - the dashboard needs it
        dashboard = ":0"
    except ImportError:
        dashboard = None
    cluster = LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True,
                           dashboard_address=dashboard, silence_logs=logging.ERROR)
    client = Client(cluster)
    client.has_dashboard = dashboard is not None
    return client, cluster


def cmd_batch(args) -> int:
    from ..progress import Progress
    from ..scene.batch import read_batch
    from ..scene.file import SceneError

    if not os.path.isfile(args.spec):
        raise CLIError(f"{args.spec}: no such batch file")
    if args.workers < 1 or args.workers > 256:
        raise CLIError(f"--workers must be in [1, 256], got {args.workers}")
    if args.pack < 0:
        raise CLIError(f"--pack must be >= 0 (0: auto, 1: no packing), got {args.pack}")
    actions = simulate_actions()
    try:
        runs = read_batch(args.spec, actions)
    except SceneError as exc:
        raise CLIError(str(exc)) from None
    out = os.path.abspath(args.out)  # the workers' working folders may differ (a cluster: shared storage)
    os.makedirs(out, exist_ok=True)
    argvs = {r.name: run_argv(r, out, actions) for r in runs}
    todo = [r.name for r in runs if not _finished(os.path.join(out, r.name), argvs[r.name])]
    skipped = len(runs) - len(todo)
    print(f"batch {args.spec}: {len(runs)} runs, {skipped} finished earlier, {len(todo)} to run", flush=True)
    results = {}
    t0 = time.perf_counter()
    if todo:
        from distributed import as_completed

        client, cluster = _client(args)
        try:
            if client.has_dashboard and client.dashboard_link and not args.quiet:
                print(f"Dask dashboard: {client.dashboard_link}", flush=True)
            tasks = pack_groups(runs, todo, args.workers, args.pack)
            futures = {client.submit(run_pack_task, names, [argvs[n] for n in names],
                                     key=f"runs-{names[0]}-{len(names)}-{time.time_ns()}", pure=False): names
                       for names in tasks}
            bar = Progress(len(todo), label="runs", enabled=not args.quiet)
            failed = done = 0
            for fut in as_completed(futures):
                names = futures[fut]
                try:
                    for res in fut.result():
                        results[res["name"]] = res
                except Exception as exc:  # noqa: BLE001 - KilledWorker and the like: recorded by name
                    msg = " ".join(str(exc).split()) or type(exc).__name__
                    for name in names:
                        results[name] = {"name": name, "exit_code": -1,
                                         "error": f"{type(exc).__name__}: {msg}"[:300]}
                failed += sum(results[n]["exit_code"] != 0 for n in names)
                done += len(names)
                bar.update(done, failed=failed)
            bar.close()
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    wall = time.perf_counter() - t0
    rows = []
    for r in runs:
        d = os.path.join(out, r.name)
        if r.name in results:
            res = results[r.name]
            status = "done" if res["exit_code"] == 0 else "failed"
            rows.append(_row(r.name, d, argvs[r.name], status, res))
        else:
            rows.append(_row(r.name, d, argvs[r.name], "done", None))
            rows[-1]["status"] = "done earlier"
    _write_tables(out, rows, args, wall)
    failed = [row["name"] for row in rows if row["status"] == "failed"]
    print(f"wrote {os.path.join(out, 'batch.csv')} and batch.json: {len(rows) - len(failed)} of {len(rows)} runs "
          f"done ({skipped} earlier), {wall:.1f} s")
    if failed:
        for row in rows:
            if row["status"] == "failed":
                print(f"failed: {row['name']}: {row['error']}", file=sys.stderr)
        return 1
    return 0


def _write_tables(out: str, rows: list, args, wall: float) -> None:
    tmp = os.path.join(out, "batch.csv.tmp")
    with open(tmp, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=COLUMNS)
        w.writeheader()
        w.writerows(rows)
    os.replace(tmp, os.path.join(out, "batch.csv"))
    meta = {"spec": os.path.abspath(args.spec), "workers": args.workers, "scheduler": args.scheduler,
            "wall_seconds": wall, "date": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "runs": rows}
    tmp = os.path.join(out, "batch.json.tmp")
    with open(tmp, "w") as fh:
        json.dump(meta, fh, indent=1, default=str)
    os.replace(tmp, os.path.join(out, "batch.json"))


def register(sub) -> None:
    b = sub.add_parser("batch", help="many simulate runs (named runs and sweeps of a base scene) on Dask",
                       description="Run the [[runs]] and [sweep] of a batch file (taichi_hair/scene/batch.py), each "
                                   "exactly as simulate --out DIR/<name> would, on a Dask LocalCluster or an "
                                   "existing cluster; DIR/batch.csv and batch.json gather the runs' figures.")
    b.add_argument("spec", help="the batch file (.toml)")
    b.add_argument("--out", required=True, help="output folder: one folder per run, batch.csv, batch.json")
    b.add_argument("--workers", type=int, default=max(1, (os.cpu_count() or 2) // 2),
                   help="LocalCluster worker processes, one thread each (default: half the CPUs)")
    b.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run on an existing Dask cluster (tcp://host:8786) instead of a LocalCluster")
    b.add_argument("--pack", type=int, default=0, metavar="N",
                   help="most runs per task: runs that differ only in their grooms share a task and, when nothing "
                        "couples their strands, one Model (0, default: spread the runs evenly over the workers; "
                        "1: every run on its own)")
    b.add_argument("--quiet", action="store_true", help="no progress bar")
    b.set_defaults(func=cmd_batch)
