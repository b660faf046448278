"""Dense clamped guides with contacts, quasistatic: N generated wavy strands on assets/head.obj (the grooming
benchmark's guides), 6 steps of 10 ADMM iterations; prints contacts and the largest stretch per step.
The optional second argument is a JSON object of ContactConfig overrides, e.g. '{"correction_iterations": 0}'.

Run from the repository root: ``python3 benchmarks/probes/dense_guides.py 8600 [JSON]``.  A diagnostic, not a benchmark:
it prints per-step figures.
"""

import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "tests"))
import json
import time

import numpy as np
import taichi as ti

ti.init(arch=ti.cpu, log_level=ti.WARN)
from taichi_hair import GroomBuilder, SolverADMM, SolverADMMConfig, RodMaterial
from taichi_hair.config import ContactConfig
from taichi_hair.groom.generators import load_head, generate_groom, GeneratorConfig
N = int(sys.argv[1])
t = time.time()
g = generate_groom(load_head(), GeneratorConfig(style="wavy", strands=N, vertices_per_strand=14, length=0.25, seed=0))
print("generated", time.time() - t, flush=True)
b = GroomBuilder()
off = g.strand_offsets
for s in range(len(off) - 1):
    b.add_strand(g.points[off[s]:off[s+1]], RodMaterial(), root="clamped", body=0)
model = b.finalize()
cfg = SolverADMMConfig(iterations=10, mode="quasistatic", w0=1.0,
                       contacts=ContactConfig(friction=0.2, velocity_margin=0.0, **(json.loads(sys.argv[2]) if len(sys.argv) > 2 else {})))
solver = SolverADMM(model, cfg)
st, ct = model.state(), model.control()
for k in range(6):
    t = time.time()
    try:
        solver.step(st, ct, 1.0)
    except Exception as e:
        print("step", k, "FAILED:", e, flush=True)
        x = st.positions()
        break
    x = st.positions().astype(float)
    rl = model.host["edge_rest_length"]; real = rl > 0
    e = np.linalg.norm(np.diff(x, axis=0, append=x[-1:]), axis=1)
    print("step", k, round(time.time() - t, 1), "s", solver.contact_stats, "max stretch", np.abs(e[real]/rl[real]-1).max(), flush=True)
