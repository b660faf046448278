"""Speed against accuracy for the quasistatic cantilever: error vs ADMM iterations for several w0.

Runs the 100-rod cantilever sweep of ``taichi-hair validate cantilever`` for each
constraint-weight scale w0 (Daviet 2023 Sec. 4.4 uses w0 = 25) and records the
largest relative H/W error against the heavy elastica every 250 iterations,
with the wall time.  Writes ``cantilever_convergence.csv`` and ``.png``, and ``.json`` (the harness's
machine block, the command, a summary per w0 and the same rows as the CSV).

Usage: python benchmarks/cantilever_convergence.py [--w0 0.1,0.2,0.5,1,5,25] [--iterations 10000] [--out DIR]
"""

import argparse
import csv
import os
import time

from harness import Bench, results_path  # benchmarks/harness.py (the script's folder is on sys.path)


def main(argv=None):
    p = argparse.ArgumentParser()
    p.add_argument("--w0", default="0.1,0.2,0.5,1,5,25")
    p.add_argument("--iterations", type=int, default=10000)
    p.add_argument("--count", type=int, default=100)
    p.add_argument("--out", default=results_path())
    args = p.parse_args(argv)
    bench = Bench("cantilever_convergence", argv)
    import taichi as ti

    import taichi_hair

    taichi_hair.init(arch=ti.cpu, log_level=ti.WARN)
    from taichi_hair import SimulationDivergedError
    from taichi_hair.validation.cantilever import default_lengths, run_cantilever

    rows, summary = [], []
    for w0 in (float(v) for v in args.w0.split(",")):
        t0 = time.perf_counter()
        hist = []

        def progress(it, change, err, hist=hist, t0=t0):
            hist.append((it, err, time.perf_counter() - t0))

        status = "ok"
        try:
            run_cantilever(default_lengths(args.count), w0=w0, max_iterations=args.iterations, tolerance=0.0,
                           progress=progress)
        except SimulationDivergedError as exc:
            status = f"diverged ({exc.field}, strand {exc.strand})"
        for it, err, wall in hist:
            rows.append({"w0": w0, "iterations": it, "max_abs_rel_error": err, "wall_s": wall, "status": status})
        last = hist[-1] if hist else (0, float("nan"), 0.0)
        below = next((h[0] for h in hist if h[1] < 0.02), None)
        summary.append({"w0": w0, "status": status, "iterations": last[0], "max_abs_rel_error": last[1],
                        "wall_s": last[2], "first_iterations_below_2_percent": below})
        print(f"w0 = {w0:6g}: {status}; after {last[0]} iterations max |error| {100 * last[1]:.2f}% "
              f"({last[2]:.1f} s); first below 2%: "
              f"{'never' if below is None else below}", flush=True)
    os.makedirs(args.out, exist_ok=True)
    path = os.path.join(args.out, "cantilever_convergence.csv")
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0].keys()))
        w.writeheader()
        w.writerows(rows)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for w0 in sorted({r["w0"] for r in rows}):
        rr = [r for r in rows if r["w0"] == w0]
        ax.semilogy([r["iterations"] for r in rr], [100 * r["max_abs_rel_error"] for r in rr], "-o", ms=2,
                    label=f"w0 = {w0:g}" + (" (diverged)" if rr[0]["status"] != "ok" else ""))
    ax.axhline(2.0, color="k", lw=0.8, ls="--")
    ax.set_xlabel("quasistatic ADMM iterations")
    ax.set_ylabel("max |H/W error| over 100 rods [%]")
    ax.set_title("Cantilever sweep: convergence vs constraint weight scale w0")
    ax.legend(fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.path.join(args.out, "cantilever_convergence.png"), dpi=120)
    bench.write(os.path.join(args.out, "cantilever_convergence.json"),
                {"count": args.count, "max_iterations": args.iterations, "summary": summary, "rows": rows})
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
