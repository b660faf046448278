"""Benchmark of SolverADMM without contacts (issue: core simulator).

1. Throughput: milliseconds per ADMM iteration and million vertex-iterations
   per second for 1k x 32, 10k x 32 and 1k x 128 strands x vertices (curly
   clamped hair under gravity, dynamic mode, 10 iterations per step), and a
   per-stage split (local, global, twist, frames) from a separate profiled
   run (profiling synchronises after each stage, so its total is a little
   higher than the unprofiled figure).  In the same run, in rounds interleaved with the ADMM's, the Thomas
   bound: one Thomas solve with 3 right-hand sides over the same groom, strands in parallel (the cost floor
   of one iteration's global step), and the ADMM's throughput as a share of it (issue 15, item 1 aims at
   >= 1/5; the median of the rounds' shares).
2. One 10 cm hair rod of 40 edges clamped horizontally (Gamma = 6.8): wall
   time of the quasistatic ADMM to bring the tip height within 0.1 % of its
   final value, side by side with MuJoCo's cable (benchmarks/mujoco_cable.py)
   in the same run, and of the direct static solve (``taichi_hair.solvers.static_newton``: Gauss-Newton,
   banded Cholesky, every iteration in one launch) to the same 0.1 % and to its 1e-10 m tolerance.  Kernel
   compilation is reported apart.

Usage:
    python benchmarks/bench_admm.py [--arch cpu|cuda] [--sizes 1000x32,10000x32,1000x128] [--rod-only | --no-rod] [--out FILE]

Figures are printed and written as JSON (default benchmarks/results/admm_<arch>.json).
"""

import argparse
import os
import time

import numpy as np

from harness import Bench, results_path, stopwatch, timed  # benchmarks/harness.py (the script's folder is on sys.path)


def curly_groom(ti_hair, strands, vertices, seed=0):
    rng = np.random.default_rng(seed)
    b = ti_hair.GroomBuilder()
    L = 0.0025 * (vertices - 1)
    s = np.linspace(0.0, L, vertices)
    side = int(np.ceil(np.sqrt(strands)))
    for k in range(strands):
        ph = rng.uniform(0, 2 * np.pi)
        r = 0.002 * np.minimum(1.0, s / (0.2 * L))
        pts = np.c_[r * np.cos(s / 0.01 + ph) - r[0] * np.cos(ph), -s, r * np.sin(s / 0.01 + ph)]
        pts += [0.002 * (k % side), 0.0, 0.002 * (k // side)]
        b.add_strand(pts)
    return b.finalize()


class ThomasBound:
    """The cost floor of one ADMM iteration's global step (issue 15, item 1): the solver's own Thomas kernel
    (``tridiag.thomas_solve``, strands in parallel) with 3 right-hand sides over the groom, one launch per
    solve.  Thomas works in place, so the matrix and right-hand side are restored before each launch
    (untimed).  :meth:`rate` times ``launches`` launches and returns M vertices solved per second (their median).

    The bound is measured in rounds interleaved with the ADMM's (:func:`throughput`): this VM's speed swings up to 2x
    within minutes (the bound alone moved between 85 and 177 M vertices/s in six runs of one commit), and a share
    taken from two measurements minutes apart carried that swing."""

    def __init__(self, ti, model):
        from taichi_hair.tridiag import thomas_solve

        self.ti, self.model, self.solve = ti, model, thomas_solve
        n = model.vertex_count
        self.lower, self.diag, self.upper = (ti.field(ti.f32, n) for _ in range(3))
        self.rhs = ti.Vector.field(3, ti.f32, n)
        self.b0 = np.random.default_rng(0).standard_normal((n, 3)).astype(np.float32)
        self.upper0 = np.full(n, -1.0, np.float32)
        self.lower.from_numpy(np.full(n, -1.0, np.float32))
        self.diag.from_numpy(np.full(n, 4.0, np.float32))
        self.rate(5)  # compilation and warm-up

    def rate(self, launches):
        ti, m = self.ti, self.model
        ts = []
        for _ in range(launches):
            self.upper.from_numpy(self.upper0)
            self.rhs.from_numpy(self.b0)
            ti.sync()
            t = time.perf_counter()
            self.solve(m.strand_vertex_start, m.strand_vertex_count, self.lower, self.diag, self.upper, self.rhs)
            ti.sync()
            ts.append(time.perf_counter() - t)
        return m.vertex_count / float(np.median(ts)) / 1e6


def throughput(th, ti, strands, vertices, iterations=10, steps=10, schedule="auto", anderson=None, rounds=8):
    """ADMM vertex-iterations per second without contacts, and its share of the Thomas bound measured in
    ``rounds`` interleaved rounds (each: ``steps`` ADMM steps back to back, then 40 Thomas launches); the share is
    the median of the rounds' shares, the throughput the median of the rounds' rates.  A second, profiled pass
    gives the per-stage split."""
    model = curly_groom(th, strands, vertices)
    res = {"strands": strands, "vertices_per_strand": vertices, "vertices": model.vertex_count}
    cfg = dict(iterations=iterations)
    if anderson is not None:
        cfg["anderson_window"] = anderson
    if schedule != "auto":
        cfg["schedule"] = schedule
    for profile in (False, True):
        st, ctl = model.state(), model.control()
        solver = th.SolverADMM(model, th.SolverADMMConfig(**cfg), profile=profile)
        step = lambda: solver.step(st, ctl, 1 / 96)
        first = timed(step, 0, sync=ti.sync)  # the first step: kernel compilation
        its = steps * iterations
        if not profile:
            res["anderson_window"] = solver.anderson.window
            res["compile_and_first_step_s"] = first["compile_s"]
            res["schedule"] = getattr(solver, "schedule", "stage")
            res["tridiagonal"] = solver.tridiagonal_method
            bound = ThomasBound(ti, model)
            rates, bounds = [], []
            for _ in range(rounds):
                el = timed(step, steps, first=False, sync=ti.sync)["run_total_s"]
                rates.append(model.vertex_count * its / el / 1e6)
                bounds.append(bound.rate(40))
            shares = np.array(rates) / np.array(bounds)
            res["ms_per_iteration"] = 1e3 * model.vertex_count / (float(np.median(rates)) * 1e6)
            res["mvertex_iterations_per_s"] = float(np.median(rates))
            res["mvertex_iterations_per_s_rounds"] = [float(v) for v in rates]
            # The Thomas bound in the same rounds, and the ADMM's share of it (aim: >= 1/5).
            res["thomas_bound_mvertices_per_s"] = float(np.median(bounds))
            res["thomas_bound_mvertices_per_s_rounds"] = [float(v) for v in bounds]
            res["fraction_of_thomas_bound"] = float(np.median(shares))
            res["fraction_of_thomas_bound_range"] = [float(shares.min()), float(shares.max())]
        else:
            solver.stage_seconds = {k: 0.0 for k in solver.stage_seconds}
            el = timed(step, steps, first=False, sync=ti.sync)["run_total_s"]
            res["stage_ms_per_iteration"] = {k: 1e3 * v / its for k, v in solver.stage_seconds.items() if v > 0}
    return res


def rod_to_rest(th, ti, w0=0.2, chunk=10, rel_tol=1e-3, schedule="auto", anderson=None):
    """Quasistatic ADMM: iterations and wall time until the tip height stays within rel_tol of its final value."""
    n, L = 41, 0.1

    def make():
        b = th.GroomBuilder()
        b.add_strand(np.c_[np.linspace(0, L, n), np.zeros(n), np.zeros(n)], th.RodMaterial())
        model = b.finalize()
        cfg = dict(iterations=chunk, mode="quasistatic", w0=w0)
        if anderson is not None:
            cfg["anderson_window"] = anderson
        if schedule != "auto":
            cfg["schedule"] = schedule
        return model, th.SolverADMM(model, th.SolverADMMConfig(**cfg))

    # Pass 1 (untimed): the final tip height, then the first chunk after which it stays within rel_tol.
    model, solver = make()
    st, ctl = model.state(), model.control()
    straight = st.to_numpy()
    heights = []
    with stopwatch(ti.sync) as sw:
        solver.step(st, ctl, 1.0)
    compile_s = sw.seconds
    heights.append(st.positions()[-1, 1])
    for _ in range(4000):
        solver.step(st, ctl, 1.0)
        heights.append(float(st.positions()[-1, 1]))
        if len(heights) > 200 and abs(heights[-1] - heights[-101]) < 1e-7 * abs(heights[-1]):
            break
    h = np.array(heights)
    final = h[-1]
    outside = np.where(np.abs(h / final - 1.0) > rel_tol)[0]
    chunks = int(outside[-1]) + 2 if outside.size else 1
    # Pass 2 (timed): exactly that many chunks from the straight state, compiled already.
    timings = []
    for _ in range(5):
        st.load(straight)  # same fields: no recompilation
        solver.reset_duals()
        with stopwatch(ti.sync) as sw:
            for _ in range(chunks):
                solver.step(st, ctl, 1.0)
        timings.append(sw.seconds)
    tip = float(st.positions()[-1, 1])
    return {"iterations": chunks * chunk, "wall_s": float(np.median(timings)), "compile_s": compile_s,
            "final_tip_drop_m": -float(final), "tip_drop_m_after_timed_run": -tip, "w0": w0,
            "iterations_per_call": chunk, "anderson_window": solver.anderson.window}


def rod_to_rest_newton(th, ti, rel_tol=1e-3, repeats=51):
    """The direct static solve (taichi_hair.solvers.static_newton) on the same 10 cm rod: the Gauss-Newton
    iterations until the tip height stays within rel_tol of its converged value (found untimed, as the ADMM's
    chunks and MuJoCo's steps are), then the wall time of one solve with exactly that many iterations (one
    kernel launch; median of ``repeats``), and of the solve to its default tolerance (1e-10 m)."""
    from taichi_hair.solvers.static_newton import SolverStaticNewton, StaticNewtonConfig

    n, L = 41, 0.1
    b = th.GroomBuilder()
    b.add_strand(np.c_[np.linspace(0, L, n), np.zeros(n), np.zeros(n)], th.RodMaterial())
    model = b.finalize()
    st, ctl = model.state(), model.control()
    x0 = st.vertex_position.to_numpy().astype(np.float64)
    solver = SolverStaticNewton(model)
    t0 = time.perf_counter()
    x, full = solver.solve_to(x0, ctl.gravity)
    compile_s = time.perf_counter() - t0
    final = float(x[-1, 1])
    needed = int(full.iterations[0])
    for k in range(1, needed + 1):
        solver.config = StaticNewtonConfig(max_iterations=k)
        xk, _ = solver.solve_to(x0, ctl.gravity)
        if abs(xk[-1, 1] / final - 1.0) <= rel_tol:
            needed = k
            break

    def wall(max_iterations):
        solver.config = StaticNewtonConfig(max_iterations=max_iterations)
        ts = []
        for _ in range(repeats):
            t = time.perf_counter()
            xr, _ = solver.solve_to(x0, ctl.gravity)
            ts.append(time.perf_counter() - t)
        return float(np.median(ts)), float(min(ts)), float(xr[-1, 1])

    wall_s, wall_min, tip = wall(needed)
    conv_s, conv_min, _ = wall(200)
    return {"iterations": needed, "wall_s": wall_s, "wall_s_min": wall_min, "tip_drop_m_after_timed_run": -tip,
            "final_tip_drop_m": -final, "iterations_to_tolerance": int(full.iterations[0]),
            "wall_s_to_tolerance": conv_s, "wall_s_to_tolerance_min": conv_min, "compile_s": compile_s,
            "converged": bool(full.converged[0])}


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--arch", default="cpu")
    p.add_argument("--sizes", default="1000x32,10000x32,1000x128")
    p.add_argument("--schedule", default="auto")
    p.add_argument("--no-mujoco", action="store_true")
    p.add_argument("--anderson", default=None,
                   help="comma-separated Anderson windows to compare in one run (default: the solver's default)")
    p.add_argument("--rod-only", action="store_true", help="only the rod-to-rest comparison (no throughput runs)")
    p.add_argument("--no-rod", action="store_true", help="only the throughput runs (no rod-to-rest comparison)")
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)
    bench = Bench("admm", argv)
    import taichi as ti

    import taichi_hair as th

    th.init(arch={"cpu": ti.cpu, "cuda": ti.cuda}[args.arch], log_level=ti.WARN)

    arch = str(ti.lang.impl.current_cfg().arch).split(".")[-1]
    out = {"date": time.strftime("%Y-%m-%d"), "arch": arch, "throughput": []}
    print(f"SolverADMM benchmark on {arch} ({os.cpu_count()} cores), taichi {ti.__version__}")
    windows = [None] if args.anderson is None else [int(w) for w in args.anderson.split(",")]
    print(f"{'strands x verts':>16} {'anderson':>8} {'ms/iter':>9} {'Mvert-it/s':>11} {'Thomas Mv/s':>11} "
          f"{'share':>6} {'compile s':>10}  stage ms/iter")
    for size in ([] if args.rod_only else args.sizes.split(",")):
        ns, nv = (int(v) for v in size.split("x"))
        for w in windows:
            r = throughput(th, ti, ns, nv, schedule=args.schedule, anderson=w)
            out["throughput"].append(r)
            stages = " ".join(f"{k}={v:.2f}" for k, v in r["stage_ms_per_iteration"].items())
            print(f"{size:>16} {r['anderson_window']:8d} {r['ms_per_iteration']:9.3f} {r['mvertex_iterations_per_s']:11.2f} "
                  f"{r['thomas_bound_mvertices_per_s']:11.1f} {r['fraction_of_thomas_bound']:6.3f} "
                  f"{r['compile_and_first_step_s']:10.2f}  {stages}  (share per round "
                  f"{r['fraction_of_thomas_bound_range'][0]:.3f}-{r['fraction_of_thomas_bound_range'][1]:.3f})", flush=True)
    out["rod_to_rest_by_window"] = []
    for w in ([] if args.no_rod else windows):
        rest = rod_to_rest(th, ti, schedule=args.schedule, anderson=w)
        out["rod_to_rest_by_window"].append(rest)
        print(f"10 cm rod, 40 edges, to rest within 0.1% (quasistatic ADMM, w0={rest['w0']}, Anderson window "
              f"{rest['anderson_window']}): {rest['iterations']} iterations, {1e3 * rest['wall_s']:.2f} ms wall "
              f"(compile {rest['compile_s']:.2f} s), tip drop {1e3 * rest['final_tip_drop_m']:.3f} mm", flush=True)
    if not args.no_rod:
        out["rod_to_rest"] = rest
        newton = rod_to_rest_newton(th, ti)
        out["rod_to_rest_static_newton"] = newton
        print(f"10 cm rod, static Newton solve (solvers/static_newton.py): {newton['iterations']} Gauss-Newton iterations "
              f"to 0.1%, {1e3 * newton['wall_s']:.3f} ms wall (min {1e3 * newton['wall_s_min']:.3f}); to 1e-10 m "
              f"{newton['iterations_to_tolerance']} iterations, {1e3 * newton['wall_s_to_tolerance']:.3f} ms "
              f"(compile {newton['compile_s']:.2f} s), tip drop {1e3 * newton['final_tip_drop_m']:.3f} mm", flush=True)
        if not args.no_mujoco:
            try:
                import mujoco_cable  # benchmarks/mujoco_cable.py (the script's folder is on sys.path)

                mj = mujoco_cable.time_to_rest()
                out["mujoco_rod_to_rest"] = mj
                print(f"MuJoCo cable, same rod: {mj['steps']} steps, {1e3 * mj['wall_s']:.2f} ms wall "
                      f"(compile {1e3 * mj['compile_s']:.1f} ms), tip drop {1e3 * mj['final_tip_drop_m']:.3f} mm; "
                      f"ratio ADMM/MuJoCo wall time = {rest['wall_s'] / mj['wall_s']:.1f}, static Newton/MuJoCo "
                      f"{newton['wall_s'] / mj['wall_s']:.3f} (to 1e-10 m: {newton['wall_s_to_tolerance'] / mj['wall_s']:.3f})")
            except ImportError as exc:
                print(f"MuJoCo comparison skipped: {exc}")
    path = bench.write(args.out or results_path(f"admm_{arch}.json"), out)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
