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


def _strands(scale=1.0):
    b = GroomBuilder()
    for i in range(3):
        n = 12 + i
        t = np.linspace(0, 0.03 * scale, n)
        b.add_strand(np.c_[t, 0.002 * np.sin(200 * t), np.full(n, 0.01 * i)])
    return b


def test_model_update_in_place_matches_fresh_model(monkeypatch):
    """Model.update + SolverADMM.refresh_model (no new fields) == a Model built from scratch."""
    cfg = SolverADMMConfig(iterations=4, mode="dynamic")
    fresh = _strands(0.7).finalize()
    st_f, ctl = fresh.state(), fresh.control()
    sol_f = SolverADMM(fresh, cfg)
    for _ in range(3):
        sol_f.step(st_f, ctl, 1 / 96)

    model = _strands(1.0).finalize()
    st = model.state()
    solver = SolverADMM(model, cfg)
    solver.step(st, ctl, 1 / 96)
    new = _strands(0.7).finalize()  # same layout, shorter rest shape (built before fields are forbidden)

    def forbidden(*args, **kwargs):
        raise AssertionError("a Taichi field was allocated by an in-place update")

    monkeypatch.setattr(ti, "field", forbidden)
    monkeypatch.setattr(ti.Vector, "field", forbidden)
    monkeypatch.setattr(ti.Matrix, "field", forbidden)
    model.update(new.host, new.materials)
    solver.refresh_model()
    solver.reset_duals()
    model.reset_state(st)
    for _ in range(3):
        solver.step(st, ctl, 1 / 96)
    np.testing.assert_array_equal(st.positions(), st_f.positions())


def test_model_update_rejects_other_layout():
    model = _strands().finalize()
    b = GroomBuilder()
    b.add_strand(np.c_[np.linspace(0, 0.03, 5), np.zeros(5), np.zeros(5)])
    with pytest.raises(ValueError, match="vertex_strand"):
        model.update(b.finalize().host)


def test_checkpoint_restore_continues_bit_for_bit():
    """State.to_numpy + SolverADMM.checkpoint, restored into a new solver, continue exactly."""
    model = _strands().finalize()
    cfg = SolverADMMConfig(iterations=5, mode="dynamic")
    st, ctl = model.state(), model.control()
    solver = SolverADMM(model, cfg)
    for _ in range(3):
        solver.step(st, ctl, 1 / 96)
    snap, ck = st.to_numpy(), solver.checkpoint()
    for _ in range(3):
        solver.step(st, ctl, 1 / 96)
    other = SolverADMM(model, cfg)
    st2 = model.state()
    st2.load(snap)
    other.restore(ck)
    for _ in range(3):
        other.step(st2, ctl, 1 / 96)
    np.testing.assert_array_equal(st2.positions(), st.positions())
    assert other.step_count == solver.step_count
