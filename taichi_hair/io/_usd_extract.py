"""Raw array extraction from a USD stage's BasisCurves, runnable as a child process.

usd-core can crash (SIGSEGV) or allocate without bound on a corrupt crate
(``.usdc``) file, which no in-process check can stop.  So by default
:func:`taichi_hair.io.usd.read_usd` runs this file as a script in a child
process, with an address-space limit, and builds the Groom (with all of its
checks) from the arrays it writes.  This module imports only NumPy and pxr, so
the child starts in about half a second.

    python _usd_extract.py IN.usd OUT.npz EXTRA_ADDRESS_SPACE_BYTES

Exit codes: 0 written; 3 USD reported an error (message on stderr after
``ERROR_PREFIX``); 4 usd-core is not installed.
"""

from __future__ import annotations

import sys

if __name__ == "__main__":  # run as a script: keep this folder's modules (ply.py...) from shadowing others
    import os as _os

    _here = _os.path.dirname(_os.path.abspath(__file__))
    sys.path[:] = [p for p in sys.path if _os.path.abspath(p or ".") != _here]

import json
import os
import tempfile

import numpy as np

ERROR_PREFIX = "TAICHI_HAIR_USD_ERROR: "
PRIMVARS = {"rest": np.float32, "restTwist": np.float64, "displayColor": np.float32, "region": np.int64, "guide": bool,
            "pinned": bool}


class USDExtractError(Exception):
    """USD could not open or read the stage."""


def _safe_str(exc: BaseException) -> str:
    try:
        lines = str(exc).strip().splitlines()
    except Exception:  # noqa: BLE001 - Tf.ErrorException.__str__ fails on messages with bad UTF-8
        return "(the USD error message is not valid UTF-8)"
    return lines[-1][:300] if lines else "no message"


def _open(path: str, Usd):
    if os.path.splitext(path)[1].lower() in (".usd", ".usda", ".usdc", ".usdz"):
        return Usd.Stage.Open(path, Usd.Stage.LoadAll), None
    # USD picks its parser by extension: open a misnamed file through a link with the right one.
    with open(path, "rb") as fh:
        magic = fh.read(8)
    ext = ".usdc" if magic.startswith(b"PXR-USDC") else ".usdz" if magic.startswith(b"PK") else ".usda"
    d = tempfile.TemporaryDirectory()
    link = os.path.join(d.name, "stage" + ext)
    os.symlink(os.path.abspath(path), link)
    return Usd.Stage.Open(link, Usd.Stage.LoadAll), d


def _array(value, dtype, what: str) -> np.ndarray:
    try:
        return np.array(value if value is not None else [], dtype=dtype)
    except (TypeError, ValueError, OverflowError) as exc:
        raise USDExtractError(f"{what} is not a numeric array ({exc})") from None


def extract(path: str):
    """(meta, arrays) of every BasisCurves prim: plain JSON and NumPy arrays, nothing checked yet.

    ``arrays`` keys are ``"<prim index>.<name>"``: counts, points (the default
    value), times and frame<k> (time samples of points), widths, pv.<primvar>.
    """
    from pxr import Usd, UsdGeom

    try:
        stage, keep = _open(os.fspath(path), Usd)
    except Exception as exc:  # noqa: BLE001 - Tf.ErrorException, UnicodeDecodeError...
        raise USDExtractError(f"USD could not open the stage ({type(exc).__name__}: {_safe_str(exc)})") from None
    if stage is None:
        raise USDExtractError("USD could not open the stage")
    meta = {"prims": [], "meters_per_unit": None, "time_codes_per_second": float(stage.GetTimeCodesPerSecond())}
    if stage.HasAuthoredMetadata("metersPerUnit"):
        meta["meters_per_unit"] = float(UsdGeom.GetStageMetersPerUnit(stage))
    arrays = {}
    prims = [p for p in stage.Traverse() if p.IsA(UsdGeom.BasisCurves)]
    for i, prim in enumerate(prims):
        c = UsdGeom.BasisCurves(prim)
        where = str(prim.GetPath())
        arrays[f"{i}.counts"] = _array(c.GetCurveVertexCountsAttr().Get(), np.int64, f"{where}.curveVertexCounts")
        pattr = c.GetPointsAttr()
        default = pattr.Get(Usd.TimeCode.Default())
        if default is not None:
            arrays[f"{i}.points"] = _array(default, np.float32, f"{where}.points").reshape(-1, 3)
        samples = list(pattr.GetTimeSamples())
        if samples:
            arrays[f"{i}.times"] = np.array(samples, dtype=np.float64)
            for k, t in enumerate(samples):
                arrays[f"{i}.frame{k}"] = _array(pattr.Get(t), np.float32, f"{where}.points at {t}").reshape(-1, 3)
        widths = c.GetWidthsAttr().Get()
        if widths is not None and len(widths):
            arrays[f"{i}.widths"] = _array(widths, np.float32, f"{where}.widths")
        pv = UsdGeom.PrimvarsAPI(c)
        for name, dtype in PRIMVARS.items():
            p = pv.GetPrimvar(name)
            if p and p.HasAuthoredValue():
                v = p.ComputeFlattened()
                if v is not None:
                    arrays[f"{i}.pv.{name}"] = _array(v, dtype, f"{where}.primvars:{name}")
        params = prim.GetCustomDataByKey("taichiHair:params")  # a namespaced key: nested dictionaries
        units = prim.GetCustomDataByKey("taichiHair:units")
        meta["prims"].append({"path": where, "type": str(c.GetTypeAttr().Get() or "linear"),
                              "params": params if isinstance(params, str) else None,
                              "units": units if isinstance(units, str) else None})
    del keep
    return meta, arrays


def _limit_address_space(extra: int) -> None:
    """Cap the address space at its current size (pxr loaded) + ``extra`` bytes."""
    try:
        import resource

        soft, hard = resource.getrlimit(resource.RLIMIT_AS)
        with open("/proc/self/statm") as fh:
            limit = int(fh.read().split()[0]) * os.sysconf("SC_PAGE_SIZE") + extra
        if hard != resource.RLIM_INFINITY:
            limit = min(limit, hard)
        if soft == resource.RLIM_INFINITY or soft > limit:
            resource.setrlimit(resource.RLIMIT_AS, (limit, hard))
    except (ImportError, OSError, ValueError, AttributeError):
        pass


def _warm_up() -> None:
    """Load USD's plugins and start its thread pool before the cap, so the cap bounds what the file costs.

    Without this the first stage USD opens maps about 0.4-0.6 GB of plugins, pools and
    per-thread malloc arenas inside the budget, and how much depends on the machine's
    core count and load.
    """
    try:
        from pxr import Usd, UsdGeom

        stage = Usd.Stage.CreateInMemory("warm.usda")
        UsdGeom.BasisCurves.Define(stage, "/warm")
        del stage
    except Exception:  # noqa: BLE001 - a failure here shows again, with its message, on the real read
        pass


def main(argv) -> int:
    src, dst, limit = argv[1], argv[2], int(argv[3])
    try:
        import pxr  # noqa: F401
    except ImportError as exc:
        print(f"{ERROR_PREFIX}usd-core is not installed ({exc})", file=sys.stderr)
        return 4
    _warm_up()
    _limit_address_space(limit)
    try:
        meta, arrays = extract(src)
        arrays["__meta__"] = np.array(json.dumps(meta))
        with open(dst, "wb") as fh:
            np.savez(fh, **arrays)
    except USDExtractError as exc:
        print(f"{ERROR_PREFIX}{exc}", file=sys.stderr)
        return 3
    except Exception as exc:  # noqa: BLE001 - MemoryError under the limit, anything USD raises
        print(f"{ERROR_PREFIX}USD could not read the stage ({type(exc).__name__}: {_safe_str(exc)})",
              file=sys.stderr)
        return 3
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
