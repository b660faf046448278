"""The on-disk cache of voxel SDFs (taichi_hair/contact/sdf_cache.py): the same bits as mesh2sdf, robust to
a damaged cache file, and off when asked."""

import os

import numpy as np
import pytest


@pytest.fixture()
def sphere():
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=4, radius=0.8)  # 5,120 triangles: above MIN_CACHED_FACES
    return np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)


def test_cached_grid_is_mesh2sdf_bit_for_bit_and_is_read_back(sphere, tmp_path, monkeypatch):
    import mesh2sdf

    from taichi_hair.contact import sdf_cache

    monkeypatch.setenv("TAICHI_HAIR_CACHE_DIR", str(tmp_path))
    v, f = sphere
    assert len(f) >= sdf_cache.MIN_CACHED_FACES
    fresh = mesh2sdf.compute(v, f, 32, fix=False, level=2.0 / 32)
    first = sdf_cache.mesh_sdf_grid(v, f, 32, 2.0 / 32)
    files = os.listdir(tmp_path / "sdf")
    assert len(files) == 1 and files[0].endswith(".npy")
    second = sdf_cache.mesh_sdf_grid(v, f, 32, 2.0 / 32)
    assert first.dtype == second.dtype == fresh.dtype
    assert np.array_equal(first, fresh) and np.array_equal(second, fresh)
    # A different resolution or mesh is another entry.
    sdf_cache.mesh_sdf_grid(v * 0.9, f, 32, 2.0 / 32)
    assert len(os.listdir(tmp_path / "sdf")) == 2


def test_damaged_cache_file_is_computed_again_and_replaced(sphere, tmp_path, monkeypatch):
    from taichi_hair.contact import sdf_cache

    monkeypatch.setenv("TAICHI_HAIR_CACHE_DIR", str(tmp_path))
    v, f = sphere
    good = sdf_cache.mesh_sdf_grid(v, f, 24, 2.0 / 24)
    (path,) = list((tmp_path / "sdf").iterdir())
    for junk in (b"", b"not an npy file", path.read_bytes()[:100]):
        path.write_bytes(junk)
        assert np.array_equal(sdf_cache.mesh_sdf_grid(v, f, 24, 2.0 / 24), good)
        assert np.array_equal(np.load(path), good)  # replaced by a good file


def test_cache_off_and_small_meshes_write_nothing(sphere, tmp_path, monkeypatch):
    import trimesh

    from taichi_hair.contact import sdf_cache

    v, f = sphere
    monkeypatch.setenv("TAICHI_HAIR_CACHE_DIR", "off")
    assert sdf_cache.cache_dir() is None
    sdf_cache.mesh_sdf_grid(v, f, 16, 2.0 / 16)
    monkeypatch.setenv("TAICHI_HAIR_CACHE_DIR", str(tmp_path))
    small = trimesh.creation.icosphere(subdivisions=2)  # 320 triangles
    sdf_cache.mesh_sdf_grid(np.asarray(small.vertices), np.asarray(small.faces, np.int64), 16, 2.0 / 16)
    assert not (tmp_path / "sdf").exists()
