"""Test session set-up: one ``ti.init`` per process, on Taichi's CPU arch, single precision.

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


@pytest.fixture(scope="session", autouse=True)
def taichi_cpu():
    import taichi as ti

    ti.init(arch=ti.cpu, default_fp=ti.f32, random_seed=0, offline_cache=True, log_level=ti.WARN)
    yield ti


@pytest.fixture
def th():
    import taichi_hair

    return taichi_hair
