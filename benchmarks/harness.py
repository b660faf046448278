"""The shared harness of the benchmark scripts: machine block, compile vs run timing, one JSON file.

Every ``benchmarks/bench_*.py`` (and ``cantilever_convergence.py``, ``mujoco_cable.py``) does::

    from harness import Bench          # benchmarks/ is on sys.path when a script there is run
    bench = Bench("admm", argv)        # load average and date at the start
    t = bench.timed(step, calls=10)    # first call = compilation, then the steady state (ti.sync())
    bench.write(path, figures)         # {"benchmark", "command", "machine", **figures}

* :func:`machine` describes the machine: platform, CPU model, cores, Python and NumPy, the load average,
  the Taichi version and, once ``ti.init`` ran, the arch (and the GPU name on CUDA), the git commit, the
  date (UTC).  :class:`Bench` records the load average at its start and again when it writes.
* :func:`timed` separates the first call of a workload (Taichi compiles its kernels then) from the
  steady-state calls after it; :func:`stopwatch` times a block.  Both call the synchronisation (``ti.sync``
  when Taichi is initialised) before reading the clock, so asynchronous kernel launches are counted.
* :meth:`Bench.write` writes one JSON file (atomically: a temporary file then a rename).

No Taichi import here: a script that does not use Taichi (``mujoco_cable.py``, ``bench_io.py``) gets no
Taichi fields, and the functions work with any callables (the tests use sleeps).
"""

from __future__ import annotations

import contextlib
import datetime
import json
import os
import platform
import shlex
import statistics
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _utc_now() -> str:
    return datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")


def load_average() -> list | None:
    """The 1, 5 and 15-minute load averages, or None where the platform has none."""
    try:
        return [round(v, 2) for v in os.getloadavg()]
    except (OSError, AttributeError):
        return None


def _taichi_initialised():
    """The taichi module if it is imported and ``ti.init`` ran, else None (never imports taichi)."""
    ti = sys.modules.get("taichi")
    if ti is None:
        return None
    try:
        return ti if ti.lang.impl.get_runtime().prog is not None else None
    except Exception:  # an unusual taichi build: no arch rather than a failed benchmark
        return None


def taichi_info() -> dict:
    """Taichi's version and, once initialised, its arch, default float type and IR opt_level ({} without taichi)."""
    ti = sys.modules.get("taichi")
    if ti is None:
        return {}
    version = ti.__version__
    info = {"taichi": ".".join(map(str, version)) if isinstance(version, tuple) else str(version)}
    if _taichi_initialised() is not None:
        cfg = ti.lang.impl.current_cfg()
        info["arch"] = str(cfg.arch).split(".")[-1]
        info["default_fp"] = str(cfg.default_fp).split(".")[-1] if getattr(cfg, "default_fp", None) else None
        info["opt_level"] = getattr(cfg, "opt_level", None)  # 0 under taichi_hair.init (TAICHI_INIT_OPTIONS)
        if info["arch"] == "cuda":
            gpu = _run(["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"])
            if gpu:
                info["gpu"] = gpu
    return info


def _run(cmd, cwd=None) -> str | None:
    try:
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=20, cwd=cwd)
    except (OSError, subprocess.SubprocessError):
        return None
    return r.stdout.strip() if r.returncode == 0 else None


def git_commit(root: str = ROOT) -> dict:
    """The repository's HEAD commit (short) and whether the working tree has changes ({} outside git)."""
    commit = _run(["git", "rev-parse", "--short", "HEAD"], cwd=root)
    if not commit:
        return {}
    status = _run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=root)
    return {"git_commit": commit, "git_dirty": bool(status)}


def cpu_model() -> str | None:
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return None


def machine() -> dict:
    """The machine block: platform, processor, CPU model, cores, Python, NumPy, load average, Taichi, git, date."""
    info = {"platform": platform.platform(), "processor": platform.processor() or platform.machine(),
            "cpu_model": cpu_model(), "cpu_count": os.cpu_count(), "node": platform.node(),
            "python": platform.python_version()}
    np = sys.modules.get("numpy")
    if np is not None:
        info["numpy"] = np.__version__
    info["load_average"] = load_average()
    info.update(taichi_info())
    info.update(git_commit())
    info["date_utc"] = _utc_now()
    return info


def default_sync():
    """``ti.sync`` when Taichi is initialised, else a no-op."""
    ti = _taichi_initialised()
    return ti.sync if ti is not None else (lambda: None)


class Stopwatch:
    """What :func:`stopwatch` yields: ``seconds`` once the block ends."""

    seconds: float = float("nan")


@contextlib.contextmanager
def stopwatch(sync=None):
    """Time a block: synchronise, read the clock, run the block, synchronise, read the clock."""
    sync = sync or default_sync()
    sw = Stopwatch()
    sync()
    t0 = time.perf_counter()
    yield sw
    sync()
    sw.seconds = time.perf_counter() - t0


def timed(fn, calls: int = 1, *, warmup: int = 0, each: bool = False, first: bool = True, sync=None) -> dict:
    """Time a workload: its first call apart (compilation), ``warmup`` untimed calls, then ``calls`` calls.

    ``fn`` takes no argument.  The clock is read after ``sync()`` (default :func:`default_sync`).  With
    ``each`` every steady-state call is timed on its own (a sync around each: ``run_s`` lists them and
    median, min and max are given); without it the ``calls`` run back to back as one block (only a sync at
    the end: what a simulation loop pays), ``run_total_s`` / ``calls`` is ``run_mean_s``.  ``first=False``
    skips the separate first call (the workload was compiled already).  Returns a dict:
    ``compile_s`` (the first call, compilation included; None with ``first=False``), ``calls``,
    ``warmup``, ``run_total_s``, ``run_mean_s`` and, with ``each``, ``run_s``, ``run_median_s``,
    ``run_min_s``, ``run_max_s``.
    """
    sync = sync or default_sync()
    res = {"compile_s": None}
    if first:
        with stopwatch(sync) as sw:
            fn()
        res["compile_s"] = sw.seconds
    for _ in range(warmup):
        fn()
    res.update(calls=int(calls), warmup=int(warmup))
    if each:
        times = []
        for _ in range(calls):
            with stopwatch(sync) as sw:
                fn()
            times.append(sw.seconds)
        res.update(run_s=times, run_total_s=sum(times))
        if times:
            res.update(run_median_s=statistics.median(times), run_min_s=min(times), run_max_s=max(times))
    else:
        with stopwatch(sync) as sw:
            for _ in range(calls):
                fn()
        res["run_total_s"] = sw.seconds
    res["run_mean_s"] = res["run_total_s"] / calls if calls else float("nan")
    return res


def command_line(script: str | None = None, argv=None) -> str:
    """The command that reproduces a run: ``python3 benchmarks/SCRIPT ARGS`` (the script relative to the root)."""
    script = os.path.abspath(script or sys.argv[0])
    rel = os.path.relpath(script, ROOT)
    args = sys.argv[1:] if argv is None else list(argv)
    return " ".join(["python3", rel] + [shlex.quote(str(a)) for a in args])


class Bench:
    """One benchmark run: the machine at the start, the command line, and :meth:`write` at the end."""

    def __init__(self, name: str, argv=None, script: str | None = None):
        self.name = name
        self.command = command_line(script, argv)
        self.started_utc = _utc_now()
        self.load_average_start = load_average()
        self._t0 = time.perf_counter()

    timed = staticmethod(timed)
    stopwatch = staticmethod(stopwatch)

    def machine(self) -> dict:
        """The machine block now, with the load average at the start and now (the end)."""
        info = machine()
        info["load_average_start"] = self.load_average_start
        info["load_average_end"] = info.pop("load_average")
        info["started_utc"] = self.started_utc
        info["wall_s"] = round(time.perf_counter() - self._t0, 3)
        return info

    def document(self, figures: dict) -> dict:
        doc = {"benchmark": self.name, "command": self.command, "machine": self.machine()}
        clash = set(doc) & set(figures)
        if clash:
            raise ValueError(f"figures use the harness's keys {sorted(clash)}")
        doc.update(figures)
        return doc

    def write(self, path: str, figures: dict, indent: int = 2) -> str:
        """Write ``{"benchmark", "command", "machine", **figures}`` to ``path`` (folders made); returns it."""
        doc = self.document(figures)
        folder = os.path.dirname(os.path.abspath(path))
        os.makedirs(folder, exist_ok=True)
        tmp = path + ".tmp"
        with open(tmp, "w") as fh:
            json.dump(doc, fh, indent=indent, default=_jsonable)
            fh.write("\n")
        os.replace(tmp, path)
        return path


def _jsonable(v):
    """NumPy scalars and arrays, tuples of them: what ``json`` cannot write by itself."""
    if hasattr(v, "tolist"):
        return v.tolist()
    if hasattr(v, "item"):
        return v.item()
    return str(v)


def results_path(*parts: str) -> str:
    """``benchmarks/results/<parts>``."""
    return os.path.join(ROOT, "benchmarks", "results", *parts)
