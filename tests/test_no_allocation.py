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


# --------------------------------------------------------------------------- host transfers by group (fields.upload)
def test_upload_and_download_move_the_same_bits_as_from_numpy_and_to_numpy():
    """fields.upload / fields.download against Taichi's own from_numpy / to_numpy on twin fields, for scalar, integer,
    vector and matrix elements: equal bit for bit (both cast float64 to the field's type with round-to-nearest), and one
    kernel launch per element type."""
    from taichi_hair import fields
    from taichi_hair.fields import download, upload

    rng = np.random.default_rng(3)
    n = 7
    kinds = [lambda: ti.field(float, n), lambda: ti.field(ti.i32, n), lambda: ti.Vector.field(3, float, n),
             lambda: ti.Matrix.field(3, 3, float, n), lambda: ti.Vector.field(2, ti.i32, n)]
    ours, theirs = [k() for k in kinds], [k() for k in kinds]
    values = [rng.normal(size=n), rng.integers(-9, 9, n), rng.normal(size=(n, 3)), rng.normal(size=(n, 3, 3)),
              rng.integers(0, 2**30, (n, 2))]
    instances = len(fields._transfer_kernel._primal.compiled_kernels)
    upload(list(zip(ours, values)))
    # The float group and the integer group: two new instances for these five fields.
    assert len(fields._transfer_kernel._primal.compiled_kernels) == instances + 2
    for f, v in zip(theirs, values):
        f.from_numpy(v.astype(f.to_numpy().dtype))
    for a, b in zip(download(ours), theirs):
        assert a.dtype == b.to_numpy().dtype
        np.testing.assert_array_equal(a, b.to_numpy())
    with pytest.raises(ValueError, match=r"upload: an array of shape \(6, 3\) for a field of shape \(7, 3\)"):
        upload([(ours[2], np.zeros((6, 3)))])


def test_a_model_and_its_state_compile_none_of_taichis_per_field_copy_kernels(monkeypatch):
    """Taichi's from_numpy / copy_from / fill compile one kernel instance per field, and a new Model's fields are new
    instances (30-60 ms each even from the kernel cache, measured); the Model and its State upload by group instead."""
    import taichi.lang.kernel_impl as kernel_impl

    copies = {"ext_arr_to_tensor", "ext_arr_to_matrix", "tensor_to_tensor", "fill_field", "field_fill_python_scope",
              "fill_matrix", "tensor_to_ext_arr", "matrix_to_ext_arr"}
    compiled = []
    ensure = kernel_impl.Kernel.ensure_compiled

    def counting(self, *args):
        known = len(self.compiled_kernels)
        key = ensure(self, *args)
        if len(self.compiled_kernels) > known:
            compiled.append(self.func.__name__)
        return key

    monkeypatch.setattr(kernel_impl.Kernel, "ensure_compiled", counting)
    model = _strands(0.9).finalize()
    model.state()
    assert compiled and not copies & set(compiled), compiled
