"""Largest edge stretch and penetration per substep of a small hairball, for contact settings:
full (the defaults), nocontact, nohh (body contacts only), nocorr (no geometric correction), ct
(continuous detection), sweeps (10 projection sweeps, 50 in the correction), mu0 (no friction), it50.

Run from the repository root: ``python3 benchmarks/probes/hairball_stretch.py MODE STRANDS FRAMES  # e.g. full 100 10``.
A diagnostic, not a benchmark:
it prints per-substep figures for the frames around the hairball's impact (Daviet 2023 Sec. 5.2 scene).
"""

import sys

import numpy as np

MODES = ("full", "nocontact", "nohh", "nocorr", "ct", "sweeps", "mu0", "it50")


def contact_settings(mode: str, friction: float) -> dict:
    """ContactConfig fields of a mode (the probe's baseline: 2 projection sweeps, 10 correction sweeps)."""
    cc = dict(friction=friction, projection_iterations=2, correction_iterations=10)
    if mode == "nohh":
        cc["hair_hair"] = False
    if mode == "nocorr":
        cc["correction_iterations"] = 0
    if mode == "ct":
        cc["continuous_detections"] = 3
    if mode == "sweeps":
        cc["projection_iterations"] = 10
        cc["correction_iterations"] = 50
    if mode == "mu0":
        cc["friction"] = 0.0
    return cc


def run(mode: str, n: int, frames: int) -> None:
    from taichi_hair import SolverADMM, SolverADMMConfig
    from taichi_hair.config import ContactConfig
    from taichi_hair.contact.colliders import SphereCollider
    from taichi_hair.scene.builtin import HairballScene, build_hairball, hairball_rotation

    scene = HairballScene(strands=n, length=0.3)
    model = build_hairball(scene)
    cc = contact_settings(mode, scene.friction)
    iters = 50 if mode == "it50" else 10
    cfg = SolverADMMConfig(iterations=iters, mode="dynamic",
                           contacts=None if mode == "nocontact" else ContactConfig(**cc))
    cols = None if mode == "nocontact" else [SphereCollider(radius=scene.ball_radius, friction=scene.friction, body=0)]
    solver = SolverADMM(model, cfg, colliders=cols)
    st, ct = model.state(), model.control()
    rl = model.host["edge_rest_length"]
    real = rl > 0
    dt = 1 / 96
    for f in range(1, frames + 1):
        for k in range(4):
            t = ((f - 1) * 4 + k + 1) * dt
            ct.set_body_transform(0, hairball_rotation(t), (0, 0, 0))
            solver.step(st, ct, dt)
            x = st.positions().astype(np.float64)
            e = np.linalg.norm(np.diff(x, axis=0, append=x[-1:]), axis=1)
            s = np.abs(e[real] / rl[real] - 1)
            if 8 <= f <= 10:
                cs = solver.contact_stats if solver.contacts is not None else {}
                j = int(np.argmax(s))
                local = model.host["vertex_local_index"][np.where(real)[0][j]]
                print(f, k, f"stretch {100 * s.max():.2f}% (edge {j}, local {local})", cs.get("contacts"),
                      f"pen {1e6 * cs.get('max_penetration_m', 0):.1f}um", flush=True)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    mode, n, frames = argv[0], int(argv[1]), int(argv[2])
    import taichi as ti

    import taichi_hair

    taichi_hair.init(arch=ti.cpu, log_level=ti.WARN)
    run(mode, n, frames)
    return 0


if __name__ == "__main__":
    sys.exit(main())
