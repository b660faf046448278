"""The seconds each test module took, from pytest's ``--durations=0`` report: the order in which the suite's workers take them.

Run from the repository root, after a run of the whole suite with every test's duration::

    python3 -m pytest -q -n 2 --dist loadfile tests --durations=0 > DURATIONS.txt
    python3 benchmarks/probes/module_costs.py DURATIONS.txt > tests/module_seconds.txt

Each line of the output is a test module and the seconds of its tests (setup, call and teardown summed, kernel
compilation included).  ``tests/conftest.py`` hands the modules to pytest-xdist's workers longest first (the longest
processing time rule), so that no long module starts last and leaves the other worker idle; a module not in the
file counts as the median.  The order changes no test and no result, only when each module starts.
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


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("durations", help="pytest's output with --durations=0")
    a = ap.parse_args(argv)
    with open(a.durations) as fh:
        seconds = module_seconds(fh)
    if not seconds:
        raise SystemExit(f"{a.durations}: no '--durations=0' lines found")
    print("# Seconds of each test module (setup + call + teardown, compilation included), longest first; written by")
    print("# benchmarks/probes/module_costs.py from a run of the whole suite with --durations=0.  tests/conftest.py")
    total, median = sum(seconds.values()), statistics.median(seconds.values())
    print(f"# starts the longest modules first.  Total {total:.0f} s, median {median:.0f} s.")
    for name, s in sorted(seconds.items(), key=lambda kv: -kv[1]):
        print(f"{name} {s:.0f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
