"""An on-disk cache of voxel signed distance fields (issue 15 item 5: start-up).

Why.  ``mesh2sdf.compute`` takes 1.2-1.5 s for the shipped 6,376-triangle head at 64^3 on this 2-core VM
(measured 2026-12-03), and a grooming session or a head-turn scene computes two of them (the groom
generator's and the collider's) before the first frame, every start.  The result depends only on the mesh,
the resolution and the level, so it is kept on disk like Taichi's own kernel cache.

What.  :func:`mesh_sdf_grid` returns exactly what ``mesh2sdf.compute(vertices, faces, n, fix=False,
level=level)`` returns (same dtype, same bits: the cache stores the array as ``.npy``), keyed by the SHA-256
of the vertex and face bytes, n, level and mesh2sdf's version.  Meshes under ``MIN_CACHED_FACES`` triangles
are computed every time, so that the many small throwaway meshes of tests and scripts do not fill the cache.
They are not cheaper: mesh2sdf's time goes with the grid, not the mesh (measured 2026-12-03: a 320- and a
1,280-triangle sphere 0.90 / 0.93 s at 64^3, 6.3 / 7.0 s at 128^3).  A cache file that cannot be read or has the
wrong shape or dtype is computed again and replaced; writes go to a temporary file renamed into place, so a
killed run leaves no half file.  The folder is ``$TAICHI_HAIR_CACHE_DIR/sdf`` (default
``~/.cache/taichi-hair/sdf``); ``TAICHI_HAIR_CACHE_DIR=off`` switches the cache off.  A folder that cannot be
written is not an error: the grid is computed and used.
"""

from __future__ import annotations

import hashlib
import os
import tempfile

import numpy as np

#: Meshes with fewer triangles are not cached [-] (to keep small throwaway meshes out; module doc).
MIN_CACHED_FACES = 1000


def cache_dir() -> str | None:
    """The SDF cache folder, or None when ``TAICHI_HAIR_CACHE_DIR=off``."""
    root = os.environ.get("TAICHI_HAIR_CACHE_DIR")
    if root is not None and root.strip().lower() == "off":
        return None
    if not root:
        root = os.path.join(os.path.expanduser("~"), ".cache", "taichi-hair")
    return os.path.join(root, "sdf")


def _mesh2sdf_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("mesh2sdf")
    except PackageNotFoundError:
        return "unknown"


def _key(vertices: np.ndarray, faces: np.ndarray, n: int, level: float, version: str) -> str:
    h = hashlib.sha256()
    for a in (vertices, faces):
        h.update(str((a.dtype.str, a.shape)).encode())
        h.update(np.ascontiguousarray(a).tobytes())
    h.update(f"n={n} level={level!r} fix=False mesh2sdf={version}".encode())
    return h.hexdigest()


def mesh_sdf_grid(vertices: np.ndarray, faces: np.ndarray, n: int, level: float) -> np.ndarray:
    """``mesh2sdf.compute(vertices, faces, n, fix=False, level=level)``, from the cache when it holds it.

    Args:
        vertices: (V, 3) vertex positions in mesh2sdf's normalised cube [-1, 1]^3.
        faces: (F, 3) vertex indices.
        n: grid points per axis [-].
        level: mesh2sdf's iso level [normalised units].

    Returns:
        The (n, n, n) grid of signed distances [normalised units], as mesh2sdf computes it.
    """
    folder = cache_dir()
    if folder is None or len(faces) < MIN_CACHED_FACES:
        import mesh2sdf

        return mesh2sdf.compute(vertices, faces, n, fix=False, level=level)
    # Not ``import mesh2sdf`` before a cache hit: importing it takes ~1.3 s here (measured), as long as the lookup
    # saves; its version comes from the package metadata instead.
    version = _mesh2sdf_version()
    path = os.path.join(folder, _key(np.asarray(vertices), np.asarray(faces), n, level, version) + ".npy")
    try:
        grid = np.load(path, allow_pickle=False)
        if grid.shape == (n, n, n) and grid.dtype.kind == "f":
            return grid
    except (OSError, ValueError, EOFError):
        pass
    import mesh2sdf

    grid = mesh2sdf.compute(vertices, faces, n, fix=False, level=level)
    try:
        os.makedirs(folder, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=folder, suffix=".tmp")
    except OSError:
        return grid  # a read-only folder: the grid is still right, only not kept
    try:
        with os.fdopen(fd, "wb") as fh:
            np.save(fh, np.asarray(grid), allow_pickle=False)
        os.replace(tmp, path)
    except OSError:
        os.unlink(tmp)  # a full disk: no half file left behind
    return grid
