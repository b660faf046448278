"""``step()`` allocates no Taichi field: every buffer is created at finalize / solver construction."""

import numpy as np
import pytest
import taichi as ti

from taichi_hair import GroomBuilder, SolverADMM, SolverADMMConfig


def test_step_allocates_no_fields(monkeypatch):
    b = GroomBuilder()
    for i in range(3):
        n = 12 + i
        b.add_strand(np.c_[np.linspace(0, 0.03, n), np.zeros(n), np.full(n, 0.01 * i)])
    model = b.finalize()
    st, ctl = model.state(), model.control()
    solvers = [SolverADMM(model, SolverADMMConfig(iterations=3, mode=m)) for m in ("dynamic", "quasistatic")]

    def forbidden(*args, **kwargs):
        raise AssertionError("a Taichi field was allocated inside step()")

    monkeypatch.setattr(ti, "field", forbidden)
    monkeypatch.setattr(ti.Vector, "field", forbidden)
    monkeypatch.setattr(ti.Matrix, "field", forbidden)
    for solver in solvers:
        for _ in range(3):
            solver.step(st, ctl, 1 / 96)
        solver.energy(st, ctl)
