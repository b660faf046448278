"""benchmarks/harness.py (machine block, compile vs run timing, one JSON file) and the probes as modules.

No Taichi kernel runs here: the harness is timed on sleeps, and the probe and benchmark modules are only
imported (in a child process, which checks that importing them neither calls ``ti.init`` nor runs anything).
"""

import importlib.util
import json
import pathlib
import subprocess
import sys
import textwrap
import time

import pytest

BENCHMARKS = pathlib.Path(__file__).resolve().parents[1] / "benchmarks"
PROBES = sorted((BENCHMARKS / "probes").glob("*.py"))
SCRIPTS = sorted([*BENCHMARKS.glob("bench_*.py"), BENCHMARKS / "cantilever_convergence.py",
                  BENCHMARKS / "mujoco_cable.py"])
#: Probes another change is converting; checked once they define main().
PENDING = set()


@pytest.fixture(scope="module")
def harness():
    spec = importlib.util.spec_from_file_location("harness", BENCHMARKS / "harness.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_machine_block(harness):
    m = harness.machine()
    for key in ("platform", "processor", "cpu_count", "python", "load_average", "date_utc"):
        assert key in m
    assert m["cpu_count"] >= 1
    assert m["date_utc"].endswith("+00:00")
    json.dumps(m)  # writable as it is


def test_timed_separates_the_first_call(harness):
    calls = []

    def workload():  # the first call "compiles": it sleeps much longer than the others
        time.sleep(0.2 if not calls else 0.01)
        calls.append(1)

    t = harness.timed(workload, 3, warmup=1, each=True, sync=lambda: None)
    assert len(calls) == 1 + 1 + 3
    assert t["compile_s"] >= 0.19
    assert len(t["run_s"]) == t["calls"] == 3 and t["warmup"] == 1
    assert max(t["run_s"]) < 0.15 < t["compile_s"]
    assert t["run_mean_s"] == pytest.approx(t["run_total_s"] / 3)
    block = harness.timed(workload, 4, sync=lambda: None)  # back to back: one block
    assert "run_s" not in block and block["run_total_s"] >= 0.04
    assert harness.timed(workload, 2, first=False, sync=lambda: None)["compile_s"] is None


def test_sync_is_called_before_the_clock_is_read(harness):
    events = []
    t = harness.timed(lambda: events.append("call"), 2, sync=lambda: events.append("sync"))
    # first call between two syncs, then the block of two between two syncs
    assert events == ["sync", "call", "sync", "sync", "call", "call", "sync"]
    assert t["compile_s"] >= 0
    with harness.stopwatch(lambda: events.append("sw")) as sw:
        time.sleep(0.01)
    assert sw.seconds >= 0.009 and events[-2:] == ["sw", "sw"]


def test_json_has_machine_command_and_figures(harness, tmp_path):
    bench = harness.Bench("demo", ["--size", "3"], script=str(BENCHMARKS / "bench_demo.py"))
    timing = bench.timed(lambda: None, 2, sync=lambda: None)
    path = bench.write(str(tmp_path / "sub" / "demo.json"), {"size": 3, "timing": timing, "rows": [{"ms": 1.5}]})
    doc = json.loads(pathlib.Path(path).read_text())
    assert doc["benchmark"] == "demo"
    assert doc["command"] == "python3 benchmarks/bench_demo.py --size 3"
    assert doc["size"] == 3 and doc["rows"] == [{"ms": 1.5}] and doc["timing"]["calls"] == 2
    m = doc["machine"]
    for key in ("cpu_count", "load_average_start", "load_average_end", "date_utc", "started_utc", "python"):
        assert key in m
    with pytest.raises(ValueError):
        bench.write(str(tmp_path / "clash.json"), {"machine": "x"})


def test_every_probe_and_script_imports_without_running():
    """Importing a probe or a benchmark script defines main() and does nothing else: no ti.init, no output."""
    probes = [p for p in PROBES if p.name not in PENDING or "def main(" in p.read_text()]
    assert len(probes) >= 11
    code = textwrap.dedent(f"""
        import importlib.util, io, sys, contextlib, time
        import taichi as ti
        import taichi_hair  # noqa: F401  (imported before the clock: its first import is not the probes' cost)
        sys.path.insert(0, {str(BENCHMARKS)!r})  # as when a script there runs: harness, mujoco_cable
        sys.argv = ["probe"]  # a probe reading sys.argv at import would fail
        calls = []
        ti.init = lambda *a, **k: calls.append("ti.init")
        bad = []
        for path in {[str(p) for p in probes + SCRIPTS]!r}:
            out = io.StringIO()
            t = time.perf_counter()
            with contextlib.redirect_stdout(out):
                spec = importlib.util.spec_from_file_location("m_" + str(abs(hash(path))), path)
                mod = importlib.util.module_from_spec(spec)
                try:
                    spec.loader.exec_module(mod)
                except ImportError as exc:  # an optional dependency (mujoco) missing: not this test's matter
                    if "mujoco" not in str(exc):
                        raise
                    continue
            dt = time.perf_counter() - t
            if not callable(getattr(mod, "main", None)) or out.getvalue() or calls or dt > 2.0:
                bad.append((path, out.getvalue()[:200], list(calls), round(dt, 2)))
            calls.clear()
        assert ti.lang.impl.get_runtime().prog is None
        print("BAD", bad)
    """)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=240,
                       cwd=str(BENCHMARKS.parent))
    assert r.returncode == 0, r.stderr[-3000:]
    assert "BAD []" in r.stdout, r.stdout[-3000:]


def test_no_probe_edits_sys_path():
    for p in PROBES:
        if p.name in PENDING and "def main(" not in p.read_text():
            continue
        assert "sys.path" not in p.read_text(), p.name


def test_module_costs_sum_each_modules_phases_and_the_suite_starts_the_longest_module_first(tmp_path):
    """benchmarks/probes/module_costs.py sums setup + call + teardown per module from a --durations=0 report, and
    conftest's order puts the modules longest first, each module's tests together and in their written order."""
    spec = importlib.util.spec_from_file_location("module_costs", BENCHMARKS / "probes" / "module_costs.py")
    costs = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(costs)
    report = ["12.50s call     tests/test_b.py::test_one",
              "0.50s setup    tests/test_b.py::test_one",
              "3.00s call     tests/test_a.py::test_x[1]",
              "2.00s teardown tests/test_c.py::test_z",
              "(1 durations < 0.005s hidden.)"]
    assert costs.module_seconds(report) == {"test_b.py": 13.0, "test_a.py": 3.0, "test_c.py": 2.0}

    sys.path.insert(0, str(pathlib.Path(__file__).parent))
    try:
        import conftest
    finally:
        sys.path.pop(0)

    class Item:
        def __init__(self, nodeid):
            self.nodeid = nodeid

    ids = ["tests/test_a.py::t1", "tests/test_a.py::t2", "tests/test_b.py::t1", "tests/test_new.py::t1",
           "tests/test_c.py::t1", "tests/test_c.py::t2"]
    items = [Item(i) for i in ids]
    conftest._MODULE_SECONDS, kept = str(tmp_path / "seconds.txt"), conftest._MODULE_SECONDS
    try:
        (tmp_path / "seconds.txt").write_text("# a comment\ntest_a.py 3\ntest_b.py 13\ntest_c.py 2\n")
        conftest._longest_modules_first(items)
    finally:
        conftest._MODULE_SECONDS = kept
    # b (13 s), a (3 s), then test_new.py (absent: the median, 3 s, after a by first appearance), c (2 s).
    assert [i.nodeid for i in items] == ["tests/test_b.py::t1", "tests/test_a.py::t1", "tests/test_a.py::t2",
                                        "tests/test_new.py::t1", "tests/test_c.py::t1", "tests/test_c.py::t2"]
