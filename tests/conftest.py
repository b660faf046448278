"""Test set-up: ``ti.init`` once per test module, on Taichi's CPU arch, single precision.

Single precision is the product default and validation must pass in it.  A
few derivative checks need double precision; they run in a subprocess (see
``test_strains.py``).
"""

import os
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)


@pytest.fixture(scope="module", autouse=True)
def taichi_cpu():
    """``ti.init`` at the start of every test module (not once per session).

    Taichi 1.7 keeps every field it ever allocated until the runtime is reset,
    and a single session that built a few hundred Models crashed inside
    ``launch_kernel`` (segfault, measured after ~215 tests).  Re-initialising
    per module frees them; the on-disk offline cache keeps the recompilation
    of the kernels cheap.
    """
    import taichi as ti

    ti.init(arch=ti.cpu, default_fp=ti.f32, random_seed=0, offline_cache=True, log_level=ti.WARN)
    yield ti


@pytest.fixture
def th():
    import taichi_hair

    return taichi_hair
