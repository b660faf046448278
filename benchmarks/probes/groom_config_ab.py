"""The grooming tool's still step with different values of one ``ContactConfig`` field, side by side in one process
(issue 15, item 4).

Run from the repository root::

    python3 benchmarks/probes/groom_config_ab.py [--field margin] [--values 1e-4,8e-5] [--blocks 6] [--strands 86000]
    python3 benchmarks/probes/groom_config_ab.py --field projection_iterations:correction_iterations --values 2:10,1:5

The groom of ``benchmarks/bench_groom.py`` (wavy strands x 14 vertices on ``assets/head.obj``, 10 % sag-free guides,
hair-hair contacts, 10 iterations per step), its session built with the defaults.  Several fields joined by ``:``
take values joined by ``:`` (one setting per comma-separated item).  Each value first takes two steps
(its kernels and first detection), then ``--blocks`` rounds of: for each value in turn, the field set on the solver's
``ContactConfig``, one step not counted (a new margin forces a detection) and 6 counted steps of simulation and
skinning.  The VM's speed drifts by more than the difference between values from one minute to the next, so only steps
timed in alternating blocks of one process are compared.  Prints each block's median per value, then per value: the
median and mean step, the steps that kept the last detection's contacts (``ContactConfig.redetect_share``), the contact
count, the deepest hair pair, the most crossed pairs of a step and the median correction sweeps.  The values share one
groom, so each one's quality figures follow the others' steps too: a diagnostic of speed, not of quality.
"""

import argparse

import numpy as np


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--field", default="margin", help="a ContactConfig field (a number), or several joined by ':'")
    ap.add_argument("--values", default="1e-4,8e-5", help="comma-separated values of the field (':'-joined for several)")
    ap.add_argument("--blocks", type=int, default=6)
    ap.add_argument("--strands", type=int, default=86000)
    args = ap.parse_args(argv)
    names = args.field.split(":")
    from taichi_hair.config import ContactConfig

    kinds = [type(getattr(ContactConfig(), f)) for f in names]  # (int or float, as the field's default)
    values = [tuple(k(x) for k, x in zip(kinds, v.split(":"), strict=True)) for v in args.values.split(",")]

    def label(v) -> str:
        return ":".join(f"{x:g}" for x in v)

    def apply(v) -> None:
        for f, x in zip(names, v):
            setattr(pl.config, f, x)

    from groom_step_profile import grooming_session, timed_frame  # (this folder: a script's own comes first)

    ti, _, session = grooming_session(args.strands)
    sim = session._sim
    pl = sim.solver.contacts

    def step() -> float:
        return timed_frame(ti, sim)

    for m in values:
        apply(m)
        step()
        step()
    rows = {m: [] for m in values}
    for b in range(args.blocks):
        for m in values:
            apply(m)
            step()
            for _ in range(6):
                dt = step()
                st = dict(sim.solver.contact_stats)
                rows[m].append((dt, bool(pl.contacts_reused), pl.contact_count, st.get("hair_penetration_max_m", 0.0),
                                st.get("crossed_pairs", 0), st.get("correction_sweeps", 0)))
        print(f"block {b}: median step [ms] " + ", ".join(
            f"{label(m)} {1e3 * np.median([r[0] for r in rows[m][-6:]]):.1f}" for m in values), flush=True)
    for m in values:
        a = np.array(rows[m], dtype=np.float64)
        print(f"{args.field} {label(m)}: median {1e3 * np.median(a[:, 0]):.1f} ms, mean {1e3 * a[:, 0].mean():.1f} ms, "
              f"kept contacts in {int(a[:, 1].sum())}/{len(a)} steps, ~{int(np.median(a[:, 2]))} contacts, deepest hair "
              f"pair {1e6 * a[:, 3].max():.1f} um, crossed pairs at most {int(a[:, 4].max())}, correction sweeps median "
              f"{np.median(a[:, 5]):.0f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
