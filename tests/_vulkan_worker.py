"""Runs the GPU code paths on Taichi's Vulkan arch (a software device from Mesa on CI).

Invoked by ``test_gpu_paths.py`` in a subprocess (one ``ti.init`` per process).
Prints one JSON line: the arch actually used, the strand-block shared-memory
PCR error against a dense solve, and the largest position difference of a
short dynamic simulation between this arch (PCR, stage schedule) and the
reference positions passed in a file by the parent (CPU, Thomas).
"""

import json
import os
import sys

import numpy as np
import taichi as ti

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "tests"))

import taichi_hair  # noqa: E402
taichi_hair.init(arch=ti.vulkan, log_level=ti.ERROR)
arch = str(ti.lang.impl.current_cfg().arch).split(".")[-1]
out = {"arch": arch}
if arch != "vulkan":
    print(json.dumps(out))
    sys.exit(0)

from scene_for_arch_tests import build_scene, run_scene  # noqa: E402
from taichi_hair.tridiag import TridiagonalSolver  # noqa: E402
from test_tridiag import _dense_solve, _fields, _random_system  # noqa: E402

rng = np.random.default_rng(1)
errs = []
for ncomp in (1, 3):
    counts = np.array([1, 2, 3, 5, 16, 17, 33, 64, 129, 200, 31, 7])
    lower, diag, upper, rhs = _random_system(counts, rng, ncomp)
    expected = _dense_solve(counts, lower, diag, upper, rhs)
    n = int(counts.sum())
    s0, s1, vs = _fields(counts)
    solver = TridiagonalSolver(s0, s1, vs, counts, method="pcr")
    out["shared_memory_pcr"] = bool(solver.use_shared)
    fl, fd, fu = (ti.field(ti.f32, n) for _ in range(3))
    fr = ti.Vector.field(3, ti.f32, n) if ncomp == 3 else ti.field(ti.f32, n)
    for f, v in ((fl, lower), (fd, diag), (fu, upper), (fr, rhs)):
        f.from_numpy(v.astype(np.float32))
    solver.solve(fl, fd, fu, fr)
    errs.append(float(np.max(np.abs(fr.to_numpy() - expected)) / np.max(np.abs(expected))))
out["pcr_rel_error"] = max(errs)

positions, method = run_scene(build_scene(), tridiagonal="auto")
out["solver_tridiagonal"] = method
reference = np.load(sys.argv[1])
out["max_position_difference_m"] = float(np.max(np.abs(positions - reference)))
print(json.dumps(out))
