"""The measured points of the speed-against-accuracy study (:mod:`taichi_hair.bench.pareto`): the
:class:`Point` record, the Pareto front, the ``pareto.csv`` format, the data shipped with the package
(``data/pareto_cpu.csv``) and the choice of a measured point by error or cost (read by
:mod:`taichi_hair.bench.choice`).
"""

from __future__ import annotations

import csv
import math
import os
from dataclasses import dataclass

import numpy as np

DATA_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data")


@dataclass
class Point:
    scene: str
    method: str
    precision: str
    dt: float
    iterations: int
    substeps: int
    shape_method: int
    label: str
    cost: float        # wall s per simulated s per 1k vertices
    error: float
    on_front: bool = False


def pareto_front(costs, errors) -> np.ndarray:
    """Boolean mask of the non-dominated points (lower cost and lower error are better; inf never on it)."""
    c, e = np.asarray(costs, float), np.asarray(errors, float)
    mask = np.zeros(len(c), bool)
    for i in range(len(c)):
        if not (np.isfinite(c[i]) and np.isfinite(e[i])):
            continue
        dominated = np.any((c <= c[i]) & (e <= e[i]) & ((c < c[i]) | (e < e[i])) & np.isfinite(e))
        mask[i] = not dominated
    return mask


CSV_FIELDS = ("scene", "method", "precision", "dt_s", "iterations", "substeps", "shape_method",
              "cost_s_per_sim_s_per_kvertex", "error", "on_front")


def write_csv(points, path: str) -> None:
    with open(path + ".tmp", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(CSV_FIELDS)
        for p in points:
            w.writerow([p.scene, p.method, p.precision, f"{p.dt:.6g}", p.iterations, p.substeps, p.shape_method,
                        f"{p.cost:.10g}", "inf" if not math.isfinite(p.error) else f"{p.error:.10g}", int(p.on_front)])
    os.replace(path + ".tmp", path)


def read_csv(path: str) -> list[Point]:
    """Points of a ``pareto.csv`` (or the shipped ``data/pareto_cpu.csv``)."""
    pts = []
    with open(path, newline="") as fh:
        for row in csv.DictReader(fh):
            pts.append(Point(row["scene"], row["method"], row["precision"], float(row["dt_s"]), int(row["iterations"]),
                             int(row["substeps"]), int(row["shape_method"]), "",
                             float(row["cost_s_per_sim_s_per_kvertex"]), float(row["error"]), row["on_front"] == "1"))
    return pts


def load_shipped() -> list[Point]:
    """The measured points shipped with the package (``data/pareto_cpu.csv``)."""
    return read_csv(os.path.join(DATA_DIR, "pareto_cpu.csv"))


def choose(points, scene: str, max_error: float | None = None, max_cost: float | None = None) -> Point:
    """Pick a measured point of ``scene``: the cheapest with error <= ``max_error``, or the most accurate
    with cost <= ``max_cost`` [wall s / simulated s / 1k vertices] (exactly one of the two).

    Raises ValueError naming what cannot be met (the measured range is in the message).
    """
    if (max_error is None) == (max_cost is None):
        raise ValueError("choose: give exactly one of max_error and max_cost")
    ps = [p for p in points if p.scene == scene and math.isfinite(p.error)]
    if not ps:
        raise ValueError(f"choose: no measured points for scene {scene!r}")
    if max_error is not None:
        ok = [p for p in ps if p.error <= max_error]
        if not ok:
            raise ValueError(f"choose: no measured setting of scene {scene!r} reaches error {max_error:g} "
                             f"(best measured {min(p.error for p in ps):.3g})")
        return min(ok, key=lambda p: (p.cost, p.error))
    ok = [p for p in ps if p.cost <= max_cost]
    if not ok:
        raise ValueError(f"choose: no measured setting of scene {scene!r} costs <= {max_cost:g} "
                         f"(cheapest measured {min(p.cost for p in ps):.3g})")
    return min(ok, key=lambda p: (p.error, p.cost))
