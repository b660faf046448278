"""GPU code paths (strand-block PCR in shared memory, PCR in the solver) on Taichi's Vulkan arch.

CI installs Mesa's software Vulkan device (lavapipe), so these kernels run
without a GPU; on a machine with no Vulkan device at all the test is skipped.
The CUDA arch uses the same kernels through a different code generator and is
only exercised where a CUDA device is available (see BENCHMARKS.md).
"""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from scene_for_arch_tests import build_scene, run_scene

HERE = os.path.dirname(os.path.abspath(__file__))


def test_vulkan_pcr_and_solver_match_cpu(tmp_path):
    ref, method = run_scene(build_scene(), tridiagonal="thomas")
    assert method == "thomas"
    ref_path = tmp_path / "ref.npy"
    np.save(ref_path, ref)
    proc = subprocess.run([sys.executable, os.path.join(HERE, "_vulkan_worker.py"), str(ref_path)],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    res = json.loads(proc.stdout.strip().splitlines()[-1])
    if res["arch"] != "vulkan":
        pytest.skip("no Vulkan device (install mesa-vulkan-drivers)")
    assert res["shared_memory_pcr"] is True
    assert res["pcr_rel_error"] < 1e-5
    assert res["solver_tridiagonal"] == "pcr"
    # Same physics on a GPU-style arch with PCR: f32 round-off only (positions ~0.1 m).
    assert res["max_position_difference_m"] < 1e-5
