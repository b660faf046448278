"""Per-strand tridiagonal solvers (Thomas and PCR) against a dense NumPy solve."""

import numpy as np
import pytest
import taichi as ti

from taichi_hair.tridiag import TridiagonalSolver, _pack_blocks


def _random_system(counts, rng, ncomp):
    n = int(np.sum(counts))
    lower = rng.uniform(-1.0, 0.0, n)
    upper = rng.uniform(-1.0, 0.0, n)
    start = 0
    for c in counts:
        lower[start] = 0.0
        upper[start + c - 1] = 0.0
        start += c
    # Strictly diagonally dominant (like the ADMM systems): |b| > |a| + |c|.
    diag = np.abs(lower) + np.abs(upper) + rng.uniform(0.01, 1.0, n)
    rhs = rng.normal(size=(n, ncomp)) if ncomp > 1 else rng.normal(size=n)
    return lower, diag, upper, rhs


def _dense_solve(counts, lower, diag, upper, rhs):
    out = np.zeros_like(rhs)
    start = 0
    for c in counts:
        M = np.diag(diag[start:start + c])
        if c > 1:
            M += np.diag(lower[start + 1:start + c], -1) + np.diag(upper[start:start + c - 1], 1)
        out[start:start + c] = np.linalg.solve(M, rhs[start:start + c])
        start += c
    return out


def _fields(counts):
    counts = np.asarray(counts)
    n = int(counts.sum())
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int32)
    s_start = ti.field(ti.i32, len(counts))
    s_count = ti.field(ti.i32, len(counts))
    v_strand = ti.field(ti.i32, n)
    s_start.from_numpy(starts)
    s_count.from_numpy(counts.astype(np.int32))
    v_strand.from_numpy(np.repeat(np.arange(len(counts)), counts).astype(np.int32))
    return s_start, s_count, v_strand


COUNTS = [1, 2, 3, 5, 16, 17, 33, 64, 129, 1030]


@pytest.mark.parametrize("method", ["thomas", "pcr"])
@pytest.mark.parametrize("ncomp", [1, 3])
def test_tridiagonal_matches_dense_solve(method, ncomp):
    rng = np.random.default_rng(7)
    counts = np.array(COUNTS)
    lower, diag, upper, rhs = _random_system(counts, rng, ncomp)
    expected = _dense_solve(counts, lower, diag, upper, rhs)
    n = int(counts.sum())
    s_start, s_count, v_strand = _fields(counts)
    solver = TridiagonalSolver(s_start, s_count, v_strand, counts, method=method, use_shared=False)
    fl, fd, fu = ti.field(ti.f32, n), ti.field(ti.f32, n), ti.field(ti.f32, n)
    fr = ti.Vector.field(3, ti.f32, n) if ncomp == 3 else ti.field(ti.f32, n)
    for f, v in ((fl, lower), (fd, diag), (fu, upper), (fr, rhs)):
        f.from_numpy(v.astype(np.float32))
    solver.solve(fl, fd, fu, fr)
    got = fr.to_numpy()
    err = np.max(np.abs(got - expected)) / np.max(np.abs(expected))
    assert err < 2e-5, err


def test_thomas_and_pcr_agree_on_admm_like_systems():
    """SPD systems shaped like the global step: clamped root rows, a small mass diagonal
    and a weighted edge Laplacian (condition number ~ 4 m^2)."""
    rng = np.random.default_rng(3)
    counts = np.array([40] * 20 + [130, 3])
    n = int(counts.sum())
    w = rng.uniform(1.0, 100.0, n)
    lower = np.concatenate([[0.0], -w[:-1]])
    upper = -w.copy()
    start = 0
    for c in counts:
        lower[start] = 0.0
        upper[start + c - 1] = 0.0
        start += c
    diag = -lower - upper + rng.uniform(1e-6, 1e-3, n)
    rhs = rng.normal(size=(n, 3))
    start = 0
    for c in counts:  # kinematic root vertex: identity row, no coupling
        diag[start], upper[start], rhs[start] = 1.0, 0.0, 0.0
        if c > 1:
            lower[start + 1] = 0.0
        start += c
    s_start, s_count, v_strand = _fields(counts)
    sols = {}
    for method in ("thomas", "pcr"):
        solver = TridiagonalSolver(s_start, s_count, v_strand, counts, method=method, use_shared=False)
        fl, fd, fu = (ti.field(ti.f32, n) for _ in range(3))
        fr = ti.Vector.field(3, ti.f32, n)
        for f, v in ((fl, lower), (fd, diag), (fu, upper), (fr, rhs)):
            f.from_numpy(v.astype(np.float32))
        solver.solve(fl, fd, fu, fr)
        sols[method] = fr.to_numpy().astype(np.float64)
    expected = _dense_solve(counts, lower, diag, upper, rhs)
    scale = np.max(np.abs(expected))
    # Condition numbers up to ~7e4: single precision gives about 1e-3 relative accuracy.
    assert np.max(np.abs(sols["thomas"] - expected)) / scale < 2e-3
    assert np.max(np.abs(sols["pcr"] - expected)) / scale < 2e-3
    assert np.max(np.abs(sols["thomas"] - sols["pcr"])) / scale < 2e-3


def test_block_packing_keeps_strands_whole():
    counts = np.array([10, 20, 30, 5, 100, 1, 64])
    starts, sizes = _pack_blocks(counts, 64)
    assert sizes.sum() == counts.sum()
    assert np.all(sizes <= 100)
    boundaries = set(np.concatenate([[0], np.cumsum(counts)]).tolist())
    for s, z in zip(starts, sizes):
        assert s in boundaries and s + z in boundaries
        assert z <= 64 or z == 100  # a strand longer than the block gets a block of its own
