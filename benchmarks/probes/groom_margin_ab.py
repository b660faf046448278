"""The grooming tool's still step with different contact margins, side by side in one process (issue 15, item 4).

Run from the repository root::

    python3 benchmarks/probes/groom_margin_ab.py [--margins 1e-4,8e-5] [--blocks 6] [--strands 86000]

The groom of ``benchmarks/bench_groom.py`` (wavy strands x 14 vertices on ``assets/head.obj``, 10 % sag-free guides,
hair-hair contacts, 10 iterations per step), its session built with the default margin.  Each margin first takes two
steps (its kernels and first detection), then ``--blocks`` rounds of: for each margin in turn, ``ContactConfig.margin``
set, one step not counted (the change forces a detection) and 6 counted steps of simulation and skinning.  The VM's
speed drifts by more than the difference between margins from one minute to the next, so only steps timed in
alternating blocks of one process are compared.  Prints each block's median per margin, then per margin: the median
and mean step, the steps that kept the last detection's contacts (``ContactConfig.redetect_share``), the contact
count, the deepest hair pair, the most crossed pairs of a step and the median correction sweeps.
"""

import argparse
import os
import runpy
import time

import numpy as np


def grooming_session(strands: int):
    """``groom_step_profile.grooming_session`` (the grooming benchmark's groom and session, built), run by its path."""
    return runpy.run_path(os.path.join(os.path.dirname(os.path.abspath(__file__)), "groom_step_profile.py"))[
        "grooming_session"](strands)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--margins", default="1e-4,8e-5", help="comma-separated ContactConfig.margin values [m]")
    ap.add_argument("--blocks", type=int, default=6)
    ap.add_argument("--strands", type=int, default=86000)
    args = ap.parse_args(argv)
    margins = [float(v) for v in args.margins.split(",")]

    ti, _, session = grooming_session(args.strands)
    sim = session._sim
    pl = sim.solver.contacts

    def step() -> float:
        t = time.perf_counter()
        sim.step()
        sim.skin.deform(sim.state, sim.control)
        ti.sync()
        return time.perf_counter() - t

    for m in margins:
        pl.config.margin = m
        step()
        step()
    rows = {m: [] for m in margins}
    for b in range(args.blocks):
        for m in margins:
            pl.config.margin = m
            step()
            for _ in range(6):
                dt = step()
                st = dict(sim.solver.contact_stats)
                rows[m].append((dt, bool(pl.contacts_reused), pl.contact_count, st.get("hair_penetration_max_m", 0.0),
                                st.get("crossed_pairs", 0), st.get("correction_sweeps", 0)))
        print(f"block {b}: median step [ms] " + ", ".join(
            f"{1e6 * m:.0f} um {1e3 * np.median([r[0] for r in rows[m][-6:]]):.1f}" for m in margins), flush=True)
    for m in margins:
        a = np.array(rows[m], dtype=np.float64)
        print(f"margin {1e6 * m:.0f} um: median {1e3 * np.median(a[:, 0]):.1f} ms, mean {1e3 * a[:, 0].mean():.1f} ms, "
              f"kept contacts in {int(a[:, 1].sum())}/{len(a)} steps, ~{int(np.median(a[:, 2]))} contacts, deepest hair "
              f"pair {1e6 * a[:, 3].max():.1f} um, crossed pairs at most {int(a[:, 4].max())}, correction sweeps median "
              f"{np.median(a[:, 5]):.0f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
