"""How far 10 ADMM iterations stop from the backward-Euler step in the head turn (issue 14, item 3).

Run from the repository root:
    python3 benchmarks/probes/head_turn_convergence.py [--frame F] [--contacts all|body|none]
        [--iterations 10,20,40,80,160] [--reference 2000] [--strands 300] [--w0 W]

The scene is ``benchmarks/bench_rest_pose.py``'s head turn (the wavy groom on ``assets/head.obj``, sag-free,
hair-hair friction 0.2, a 40 degree turn of 2 s from 0.25 s).  It is simulated at the scene's 10 iterations
per substep up to frame F (default 12: 0.5 s, the head turning fastest), then one more substep is taken from
that same state (positions, velocities, twists, duals: ``SolverADMM.checkpoint``) with each iteration count,
and with ``--reference`` iterations as the reference.  Printed per count: the p90 and largest vertex distance
from the reference after the step, and the same for the step's displacement (x^{t+1} - x^t), as a fraction.
``--contacts body`` drops the hair-hair contacts (the head stays a collider), ``none`` drops the head too, to
separate the elastic iteration's convergence from the contacts'.  CPU runs are deterministic, so every count
starts from the same bits.  ``--w0`` sets ``SolverADMMConfig.w0`` (the elasticity weights' scale) for the whole
run; the step it converges to does not depend on it.  A diagnostic, not a benchmark.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))


def _load(name: str, path: str):
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _bench_rest_pose():
    """benchmarks/bench_rest_pose.py by its path (it imports ``harness``, beside it: loaded first)."""
    bench_dir = os.path.dirname(HERE)
    if "harness" not in sys.modules:
        sys.modules["harness"] = _load("harness", os.path.join(bench_dir, "harness.py"))
    return _load("_bench_rest_pose", os.path.join(bench_dir, "bench_rest_pose.py"))


def scene_file(contacts: str, work: str) -> str:
    brp = _bench_rest_pose()
    text = brp.scene_text("wavy", "head_turn").replace("[groom]\n", '[groom]\nrest_pose = "sag-free"\n', 1)
    if contacts in ("body", "none"):
        text = brp.without_hair_contacts(text)
    if contacts == "none":
        text = text[:text.index("[[colliders]]")] + text[text.index("[[bodies]]"):]
    path = os.path.join(work, "head_turn.toml")
    with open(path, "w") as fh:
        fh.write(text)
    return path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frame", type=int, default=12)
    ap.add_argument("--contacts", choices=("all", "body", "none"), default="all")
    ap.add_argument("--iterations", default="10,20,40,80,160")
    ap.add_argument("--reference", type=int, default=2000)
    ap.add_argument("--strands", type=int, default=300)
    ap.add_argument("--w0", type=float, default=None, help="SolverADMMConfig.w0 instead of the default 1")
    args = ap.parse_args(argv)
    counts = [int(c) for c in args.iterations.split(",")]

    import numpy as np
    import taichi as ti

    import taichi_hair

    taichi_hair.init(arch=ti.cpu, log_level=ti.WARN)
    from taichi_hair.scene.file import load_scene

    with tempfile.TemporaryDirectory() as work:
        scene = load_scene(scene_file(args.contacts, work), overrides={"strands": args.strands})
        model = scene.build_model()
    state, control = model.state(), model.control()
    control.gravity = tuple(scene.gravity)
    solver = scene.make_solver(model)
    if args.w0 is not None:
        solver.config.w0 = args.w0
        solver.refresh_model()
    dt = 1.0 / (scene.fps * scene.substeps)

    def set_bodies(t):
        for b, (R, T) in enumerate(scene.body_transforms(t)):
            control.set_body_transform(b, R, T)

    solver.prime_duals(state, control, dt)
    steps = args.frame * scene.substeps
    for k in range(steps):
        set_bodies((k + 1) * dt)
        solver.step(state, control, dt)
    x_begin = state.vertex_position.to_numpy().astype(np.float64)
    snap_state, snap_solver = state.to_numpy(), solver.checkpoint()
    set_bodies((steps + 1) * dt)

    def step(iterations):
        state.load(snap_state)
        solver.restore(snap_solver)
        solver.config.iterations = iterations
        solver.step(state, control, dt)
        return state.vertex_position.to_numpy().astype(np.float64)

    ref = step(args.reference)
    move = np.linalg.norm(ref - x_begin, axis=1)
    print(f"head turn, {args.strands} strands, contacts {args.contacts}, w0 {solver.config.w0}, state at frame {args.frame} "
          f"(t = {steps * dt:.3f} s), dt = {dt:.5f} s; reference {args.reference} iterations: step displacement "
          f"p90 {1e3 * np.percentile(move, 90):.3f} mm, max {1e3 * move.max():.3f} mm")
    print(f"{'iterations':>10} {'p90 error [mm]':>15} {'max error [mm]':>15} {'p90 / p90 move':>15}")
    for n in counts:
        err = np.linalg.norm(step(n) - ref, axis=1)
        print(f"{n:10d} {1e3 * np.percentile(err, 90):15.4f} {1e3 * err.max():15.4f} "
              f"{np.percentile(err, 90) / max(np.percentile(move, 90), 1e-30):15.3f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
