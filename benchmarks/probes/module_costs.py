"""The seconds each test module took, from pytest's ``--durations=0`` report: the order in which the suite's workers take them.

Run from the repository root, after a run of the whole suite with every test's duration::

    python3 -m pytest -q -n 2 --dist loadfile tests --durations=0 > DURATIONS.txt
    python3 benchmarks/probes/module_costs.py DURATIONS.txt > tests/module_seconds.txt

Each line of the output is a test module and the seconds of its tests (setup, call and teardown summed, kernel
compilation included).  With ``--collected FILE`` (the output of ``python3 -m pytest --collect-only -q tests``) it
prints instead a model of the run's wall time for two orders of the modules: pytest-xdist's own (by the number of
tests, largest first) and longest first, each worker holding up to two modules and taking the next in order when one
ends (a model, not a measurement: it assumes each module takes the seconds it took in the report).

``tests/conftest.py`` hands the modules to pytest-xdist's workers longest first (the longest processing time rule), so
that no long module starts last and leaves the other worker idle; a module not in the file counts as the median.  The
order changes no test and no result, only when each module starts.
"""

import argparse
import collections
import re
import statistics

_LINE = re.compile(r"^\s*([0-9.]+)s\s+(setup|call|teardown)\s+(\S+?\.py)::")


def module_seconds(lines) -> dict:
    """Seconds per test module (its file name) from the lines of a ``--durations=0`` report."""
    total = collections.defaultdict(float)
    for line in lines:
        m = _LINE.match(line)
        if m:
            total[m.group(3).split("/")[-1]] += float(m.group(1))
    return dict(total)


def makespan(order, seconds: dict, workers: int = 2) -> float:
    """The wall time of ``workers`` workers taking the modules in ``order`` (each holding up to two: pytest-xdist's
    ``loadfile`` hands out two at the start and one more when a worker's queue falls below two)."""
    queue = list(order)
    held = [[queue.pop(0)] if queue else [] for _ in range(workers)]
    for h in held:
        if queue:
            h.append(queue.pop(0))
    clock = [0.0] * workers
    while any(held):
        w = min((k for k in range(workers) if held[k]), key=lambda k: clock[k] + seconds.get(held[k][0], 0.0))
        clock[w] += seconds.get(held[w].pop(0), 0.0)
        if queue and len(held[w]) < 2:
            held[w].append(queue.pop(0))
    return max(clock)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("durations", help="pytest's output with --durations=0")
    ap.add_argument("--collected", default=None, help="pytest --collect-only -q output: model the two orders' wall time")
    a = ap.parse_args(argv)
    with open(a.durations) as fh:
        seconds = module_seconds(fh)
    if not seconds:
        raise SystemExit(f"{a.durations}: no '--durations=0' lines found")
    if a.collected:
        with open(a.collected) as fh:
            modules = [line.split("::", 1)[0].split("/")[-1] for line in fh if "::" in line]
        count = collections.Counter(modules)
        collected = sorted(set(modules))  # pytest collects a folder's files by name
        median = statistics.median(seconds.values())
        xdist = sorted(collected, key=lambda m: -count[m])
        longest = sorted(collected, key=lambda m: -seconds.get(m, median))
        known = {m: seconds.get(m, median) for m in collected}
        print(f"test time {sum(known.values()):.0f} s over {len(collected)} modules; modelled wall time on 2 workers: "
              f"pytest-xdist's order (by test count) {makespan(xdist, known):.0f} s, "
              f"longest first {makespan(longest, known):.0f} s")
        return 0
    print("# Seconds of each test module (setup + call + teardown, compilation included), longest first; written by")
    print("# benchmarks/probes/module_costs.py from a run of the whole suite with --durations=0.  tests/conftest.py")
    total, median = sum(seconds.values()), statistics.median(seconds.values())
    print(f"# starts the longest modules first.  Total {total:.0f} s, median {median:.0f} s.")
    for name, s in sorted(seconds.items(), key=lambda kv: -kv[1]):
        print(f"{name} {s:.0f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
