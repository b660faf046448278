"""BDF2 against backward Euler in SolverADMM (issue 12 item 7): swing error, stability atlas cells, cost.

    python3 benchmarks/probes/bdf2_probe.py swing   # f64: the Pareto swing at dt = 1/96, 1/384 s
    python3 benchmarks/probes/bdf2_probe.py atlas   # f32: the stability atlas's default cases, and cost/step

swing: taichi_hair.bench.pareto's swing scene (40 cm strand, 80 edges, released from horizontal,
1 s, drag 0.5 /s), w0 = 25.  Reference: BDF2 in f64, 50 iterations, dt = 1/3840 s; its
self-difference against BDF2 at 1/1920 s and against the Pareto's backward Euler reference
(Richardson of 1/1920 and 1/3840 s) is printed.  Error: pareto.trajectory_error (RMS over 48
sample times and all vertices, over the length).
atlas: taichi_hair.bench.stability.run_and_classify on default_cases (short, long,
edge-variance, stretch-stiff), drag 8 /s, 1.5 s, each (dt, iterations) for both integrators.
cost: wall time of 400 steps at dt = 1/96 s, 10 iterations, on the atlas model, each integrator
twice, interleaved (the machine is shared).
"""

import sys
import time

import numpy as np
import taichi as ti  # ti.init is in swing() and atlas() (f64 and f32)


def swing():
    import taichi_hair

    taichi_hair.init(arch=ti.cpu, default_fp=ti.f64, log_level=ti.WARN)
    from taichi_hair.bench import pareto as P
    from taichi_hair.bench import pareto_runs as PR

    import math

    # pareto_runs.RunSpec has no integrator knob: one solver here, the integrator switched between runs.
    from taichi_hair import SolverADMM, SolverADMMConfig
    from taichi_hair.validation.elasticity_params import GRAVITY, HAIR

    model, scene = PR.build_scene("swing")
    rho_a = HAIR["density"] * math.pi * HAIR["radius"] ** 2
    solver = SolverADMM(model, SolverADMMConfig(iterations=10, w0=25.0, air_viscosity=scene.drag_rate * rho_a,
                                                check_finite=False))
    state, control = model.state(), model.control()
    control.gravity = (0.0, -GRAVITY, 0.0)

    def traj(integrator, dt, iterations):
        solver.config.integrator, solver.config.iterations = integrator, iterations
        model.reset_state(state)
        solver.reset_duals()
        per = int(round(PR.SAMPLE_INTERVAL / dt))
        out = []
        t0 = time.perf_counter()
        for k in range(int(round(scene.duration / dt))):
            solver.step(state, control, dt)
            if (k + 1) % per == 0:
                out.append(state.vertex_position.to_numpy().astype(np.float64))
        return np.array(out), time.perf_counter() - t0

    t0 = time.perf_counter()
    ref, _ = traj("bdf2", 1 / 3840, 50)
    ref2, _ = traj("bdf2", 1 / 1920, 50)
    be_f, _ = traj("backward_euler", 1 / 3840, 50)
    be_c, _ = traj("backward_euler", 1 / 1920, 50)
    strand_of, L = model.host["vertex_strand"], scene.strand_lengths
    err = lambda a, b: P.trajectory_error(a, b, strand_of, L)
    print(f"reference: BDF2 f64 dt=1/3840 it=50 ({time.perf_counter() - t0:.0f} s for the four reference runs)")
    print(f"  BDF2 1/1920 vs 1/3840: {100 * err(ref2, ref):.3f} %")
    print(f"  Pareto reference (BE Richardson 2 x_3840 - x_1920) vs BDF2 1/3840: {100 * err(2 * be_f - be_c, ref):.3f} %")
    print(f"  BE 1/3840 vs BDF2 1/3840: {100 * err(be_f, ref):.3f} %")
    for dt in (1 / 96, 1 / 384):
        for it in (10, 30):
            for integ in ("backward_euler", "bdf2"):
                tr, sec = traj(integ, dt, it)
                fin = np.all(np.isfinite(tr))
                print(f"swing dt=1/{1 / dt:.0f} it={it:2d} {integ:15s}: error {100 * err(tr, ref):6.2f} % "
                      f"(vs BE-Richardson ref {100 * err(tr, 2 * be_f - be_c):6.2f} %), finite {fin}, {sec:.2f} s")


def atlas():
    import taichi_hair

    taichi_hair.init(arch=ti.cpu, log_level=ti.WARN)
    from taichi_hair.bench import stability as S

    cases = S.default_cases()
    model = S.build_case_model(cases)
    state, control = model.state(), model.control()
    control.gravity = (0.0, -S.GRAVITY, 0.0)
    monitor = S.StrandMonitor(model)
    drop = np.array([S.reference_tip_drop(c.length) for c in cases])
    solver = S.make_solver("admm", model, 8.0, 10, 1 / 96)
    for integ in ("backward_euler", "bdf2"):
        solver.config.integrator = integ
        solver.step(state, control, 1 / 96)
        solver.step(state, control, 1 / 96)  # compile both variants
    for dt in (1 / 24, 1 / 96, 1 / 384):
        for it in (2, 10, 50):
            for integ in ("backward_euler", "bdf2"):
                S.set_knob("admm", solver, it, dt, 8.0)
                solver.config.integrator = integ
                sec, res = S.run_and_classify(model, solver, state, control, cases, dt, 1.5, monitor, drop)
                cells = ", ".join(f"{c.name}: {r[0]} (gain {r[2]:.2g}, stretch {100 * r[3]:.2g} %, sag {100 * r[4]:.2g} %)"
                                  for c, r in zip(cases, res))
                print(f"atlas dt=1/{1 / dt:.0f} it={it:2d} {integ:15s}: {cells} [{sec:.1f} s]", flush=True)
    # Cost per step, interleaved.
    S.set_knob("admm", solver, 10, 1 / 96, 8.0)
    times = {"backward_euler": [], "bdf2": []}
    for _ in range(2):
        for integ in times:
            solver.config.integrator = integ
            model.reset_state(state)
            solver.reset_duals()
            ti.sync()
            t0 = time.perf_counter()
            for _ in range(400):
                solver.step(state, control, 1 / 96)
            ti.sync()
            times[integ].append((time.perf_counter() - t0) / 400)
    be, b2 = min(times["backward_euler"]), min(times["bdf2"])
    print(f"cost/step ({model.vertex_count} vertices, 10 iterations, best of 2 x 400 steps): backward Euler "
          f"{1e3 * be:.3f} ms, BDF2 {1e3 * b2:.3f} ms, ratio {b2 / be:.3f}; all runs {times}")


PROBES = {"swing": swing, "atlas": atlas}


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    PROBES[argv[0]]()  # each calls ti.init with its precision
    return 0


if __name__ == "__main__":
    sys.exit(main())
