"""Helpers shared by the ``taichi-hair`` sub-commands (no Taichi import at module load)."""

from __future__ import annotations

import os

import numpy as np


class CLIError(Exception):
    """A user-facing error: printed as one line, exit code 2."""


def _init_taichi(arch: str, precision: str):
    import taichi as ti

    archs = {"cpu": ti.cpu, "cuda": ti.cuda, "gpu": ti.gpu, "vulkan": ti.vulkan}
    if arch not in archs:
        raise CLIError(f"--arch must be one of {sorted(archs)}, got {arch!r}")
    fp = {"f32": ti.f32, "f64": ti.f64}[precision]
    ti.init(arch=archs[arch], default_fp=fp, log_level=ti.WARN)
    used = str(ti.lang.impl.current_cfg().arch).split(".")[-1]
    return ti, used


def _atomic_savez(path: str, **arrays):
    tmp = path + ".tmp.npz"
    np.savez_compressed(tmp, **arrays)
    os.replace(tmp, path)


def _add_common(p):
    p.add_argument("--arch", default="cpu", help="Taichi arch: cpu (default), cuda, gpu, vulkan")
    p.add_argument("--precision", default="f32", choices=["f32", "f64"], help="floating point precision")
    p.add_argument("--quiet", action="store_true", help="print only the summary")


