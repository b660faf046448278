"""Test set-up: ``ti.init`` once per test module, on Taichi's CPU arch, single precision.

Single precision is the product default and validation must pass in it.  A
few derivative checks need double precision; they run in a subprocess (see
``test_strains.py``).
"""

import os
import statistics
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

# Taichi's offline cache of compiled kernels, for this process and every subprocess the tests start
# (command-line runs, workers): its own folder, and room for the whole suite.  Taichi's default cap is
# 100 MiB, shared with every other Taichi program of the user; the suite compiles more than that (kernels
# are specialised per field, and the tests build hundreds of Models), so with the default the cache
# evicted the kernels before the next run could use them (least recently used first) and every run
# compiled everything again: a session's Model + solver took 22 s cold against 7.5 s warm (measured on
# the shared 2-core VM).  The cache only skips compilation; the kernels run are the same.  A user's own
# TI_OFFLINE_CACHE_* settings win.
os.environ.setdefault("TI_OFFLINE_CACHE_FILE_PATH",
                      os.path.join(os.path.expanduser("~"), ".cache", "taichi-hair-tests", "ticache"))
# 2 GiB - 1 (the setting is a 32-bit int): past it Taichi drops the least recently used quarter of the cache, and the
# suite's kernels (one set per Model size) and the earlier commits' stood at 0.96 of the 1 GiB it was (2026-12-07).
os.environ.setdefault("TI_OFFLINE_CACHE_MAX_SIZE_OF_FILES", str(2**31 - 1))


@pytest.fixture(scope="module", autouse=True)
def taichi_cpu():
    """``ti.init`` at the start of every test module (not once per session).

    Taichi 1.7 keeps every field it ever allocated until the runtime is reset,
    and a single session that built a few hundred Models crashed inside
    ``launch_kernel`` (segfault, measured after ~215 tests).  Re-initialising
    per module frees them; the on-disk offline cache keeps the recompilation
    of the kernels cheap.
    """
    import taichi as ti

    import taichi_hair

    taichi_hair.init(arch=ti.cpu, default_fp=ti.f32, random_seed=0, offline_cache=True, log_level=ti.WARN)
    from taichi_hair.cli.common import lighter_kernel_positions

    lighter_kernel_positions()  # as the command line does: a cheaper kernel frontend, the same kernels
    yield ti


@pytest.fixture
def th():
    import taichi_hair

    return taichi_hair


# --------------------------------------------------------------------------- the slow tier
_SLOW_LIST = os.path.join(os.path.dirname(os.path.abspath(__file__)), "slow_tests.txt")


def _slow_ids() -> set:
    """Node ids of tests/slow_tests.txt, keyed as 'file.py::name[params]' (independent of the rootdir)."""
    ids = set()
    with open(_SLOW_LIST) as fh:
        for line in fh:
            line = line.split("#", 1)[0].strip()
            if line:
                ids.add(line.split("/")[-1])
    return ids


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    """Mark the tests listed in tests/slow_tests.txt as ``slow`` (the fast tier: ``-m "not slow"``).

    When the whole suite is collected, a listed test that no longer exists fails the run, so the list is
    kept in step with the tests."""
    slow = _slow_ids()
    seen = set()
    for item in items:
        key = item.nodeid.split("/")[-1]
        if key in slow:
            item.add_marker(pytest.mark.slow)
            seen.add(key)
    full = len(items) > 400 and not config.getoption("keyword") and not config.getoption("markexpr")
    if full and slow - seen:
        raise pytest.UsageError(f"tests/slow_tests.txt names tests that do not exist: {sorted(slow - seen)}")
    _longest_modules_first(items)


# --------------------------------------------------------------------------- the order of the modules
_MODULE_SECONDS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "module_seconds.txt")


def _module_seconds() -> dict:
    """tests/module_seconds.txt: the seconds of each module in a measured run (``benchmarks/probes/module_costs.py``)."""
    seconds = {}
    if os.path.exists(_MODULE_SECONDS):
        with open(_MODULE_SECONDS) as fh:
            for line in fh:
                parts = line.split("#", 1)[0].split()
                if len(parts) == 2:
                    seconds[parts[0]] = float(parts[1])
    return seconds


def _longest_modules_first(items) -> None:
    """Order the modules longest first, each module's tests in their own order and together.

    pytest-xdist's ``--dist loadfile`` hands each worker a whole module at a time, in the collection's order (its own
    reordering, by the number of tests, is switched off in :func:`pytest_configure`).  A module's time is mostly its
    kernels' compilation, not its count of tests, and a long module taken last left the other worker idle while it
    ran.  Longest first (the longest processing time rule) ends the two workers close together.  A module missing from
    tests/module_seconds.txt counts as the median.  Nothing else changes: every module still starts Taichi afresh
    (``taichi_cpu``) and runs its tests in their written order."""
    seconds = _module_seconds()
    median = statistics.median(seconds.values()) if seconds else 0.0  # (as module_costs.py reports it)

    def module(item):
        return item.nodeid.split("::", 1)[0].split("/")[-1]

    first = {}
    for k, item in enumerate(items):
        first.setdefault(module(item), k)
    order = {name: (-seconds.get(name, median), k) for name, k in first.items()}
    items.sort(key=lambda item: order[module(item)])  # stable: a module's tests keep their order


def pytest_configure(config):
    # Keep the collection's order (longest modules first, above); pytest-xdist would reorder by the number of tests.
    if hasattr(config.option, "loadscopereorder"):
        config.option.loadscopereorder = False
