"""Largest edge stretch and penetration per substep of a small hairball, for contact settings:
full (the defaults), nocontact, nohh (body contacts only), nocorr (no geometric correction), ct
(continuous detection), sweeps (10 projection sweeps, 50 in the correction), mu0 (no friction), it50.

Run from the repository root: ``python3 benchmarks/probes/hairball_stretch.py MODE STRANDS FRAMES  # e.g. full 100 10``.  A diagnostic, not a benchmark:
it prints per-substep figures for the frames around the hairball's impact (Daviet 2023 Sec. 5.2 scene).
"""

import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "tests"))
import numpy as np
import taichi as ti

ti.init(arch=ti.cpu, log_level=ti.WARN)
from taichi_hair import SolverADMM, SolverADMMConfig
from taichi_hair.config import ContactConfig
from taichi_hair.contact.colliders import SphereCollider
from taichi_hair.scene.builtin import HairballScene, build_hairball, hairball_rotation
mode = sys.argv[1]; N = int(sys.argv[2]); frames = int(sys.argv[3])  # noqa: E702
scene = HairballScene(strands=N, length=0.3)
model = build_hairball(scene)
cc = dict(friction=scene.friction, projection_iterations=2, correction_iterations=10)
if mode == "nohh": cc["hair_hair"] = False
if mode == "nocorr": cc["correction_iterations"] = 0
if mode == "ct": cc["continuous_detections"] = 3
if mode == "sweeps": cc["projection_iterations"] = 10; cc["correction_iterations"] = 50
if mode == "mu0": cc["friction"] = 0.0
iters = 10
if mode == "it50": iters = 50
cfg = SolverADMMConfig(iterations=iters, mode="dynamic", contacts=None if mode == "nocontact" else ContactConfig(**cc))
cols = None if mode == "nocontact" else [SphereCollider(radius=scene.ball_radius, friction=scene.friction, body=0)]
solver = SolverADMM(model, cfg, colliders=cols)
st, ct = model.state(), model.control()
rl = model.host["edge_rest_length"]; real = rl > 0
dt = 1/96
for f in range(1, frames+1):
    for k in range(4):
        t = ((f-1)*4+k+1)*dt
        ct.set_body_transform(0, hairball_rotation(t), (0,0,0))
        solver.step(st, ct, dt)
        x = st.positions().astype(np.float64)
        e = np.linalg.norm(np.diff(x, axis=0, append=x[-1:]), axis=1)
        s = np.abs(e[real]/rl[real]-1)
        if f >= 8 and f <= 10:
            cs = solver.contact_stats if solver.contacts is not None else {}
            j = int(np.argmax(s))
            print(f, k, f"stretch {100*s.max():.2f}% (edge {j}, local {model.host['vertex_local_index'][np.where(real)[0][j]]})", cs.get("contacts"), f"pen {1e6*cs.get('max_penetration_m',0):.1f}um", flush=True)
