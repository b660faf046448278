"""USD BasisCurves (``.usd``, ``.usda``, ``.usdc``) through ``usd-core`` (optional, imported lazily).

Written layout (one prim, default ``/Groom/Strands``)::

    BasisCurves  type = "linear"
      int[]     curveVertexCounts      (S,)
      point3f[] points                  (N,) default value, plus one time sample per frame of
                                        ``point_frames`` (at ``frame_times``) for an animated cache
      float[]   widths                  2 * radius, interpolation "uniform" (S) or "vertex" (N)
      primvars: point3f[] rest (vertex), int[] region (uniform), bool[] guide (uniform),
                bool[] pinned (vertex), color3f[] displayColor (uniform or vertex)
      customData: taichiHair:params (JSON string), taichiHair:units
    stage metadata metersPerUnit from ``units`` (m, cm, mm)

The reader concatenates every BasisCurves prim of the stage (an attribute is
kept only if every prim has it).  By default usd-core runs in a child process
(:mod:`._usd_extract`): on corrupt binary files it can crash or allocate
without bound, which becomes a GroomFormatError instead of taking the caller
down.  USD stores points as float32, so float32
grooms round-trip bit for bit; float64 ones are rounded to float32.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import tempfile
import warnings

import numpy as np

from ._util import atomic_path, file_size, finish, offsets_from_counts, parse_params, prepare_write
from . import _usd_extract
from .errors import GroomFormatError
from .groom import Groom

UNIT_METRES = {"m": 1.0, "cm": 0.01, "mm": 0.001}


def _pxr():
    try:
        from pxr import Sdf, Tf, Usd, UsdGeom, Vt
    except ImportError as exc:
        raise ImportError("USD support needs the optional package usd-core: pip install usd-core "
                          f"(or pip install 'taichi-hair[usd]'); import failed: {exc}") from None
    return Sdf, Tf, Usd, UsdGeom, Vt


# usd-core does not bound what it allocates for a corrupt crate (.usdc) file: a fuzzed file
# can make it reserve and touch many gigabytes.  During a read the process's address space
# may grow by at most this much plus USD_READ_BYTES_PER_FILE_BYTE times the file size
# (Linux; RLIMIT_AS), so such a file fails with an error instead of exhausting memory.
USD_READ_BASE_BYTES = 2 << 30
USD_READ_BYTES_PER_FILE_BYTE = 64


@contextlib.contextmanager
def limited_address_space(extra_bytes: int):
    """Cap the address space at its current size + ``extra_bytes`` for the duration (no-op where unsupported)."""
    try:
        import resource

        soft, hard = resource.getrlimit(resource.RLIMIT_AS)
        with open("/proc/self/statm") as fh:
            current = int(fh.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
    except (ImportError, OSError, ValueError, AttributeError):
        yield
        return
    limit = current + int(extra_bytes)
    if hard != resource.RLIM_INFINITY:
        limit = min(limit, hard)
    if soft != resource.RLIM_INFINITY and soft <= limit:
        yield  # already tighter
        return
    resource.setrlimit(resource.RLIMIT_AS, (limit, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


def read_usd(path, isolate: bool = True) -> Groom:
    """Read every BasisCurves prim of a USD stage.

    Args:
        isolate: run usd-core in a child process (default).  usd-core can crash
            or allocate without bound on a corrupt binary file; in a child that
            becomes a GroomFormatError.  ``isolate=False`` reads in this process
            (about 0.5 s faster per file) with only the address-space cap.
    """
    size = file_size(path)  # a missing path or a folder: GroomFormatError naming it
    if size == 0:
        raise GroomFormatError(path, "the file is empty")
    budget = USD_READ_BASE_BYTES + USD_READ_BYTES_PER_FILE_BYTE * size
    if isolate:
        meta, arrays = _extract_in_child(path, budget, size)
    else:
        _pxr()
        try:
            with limited_address_space(budget):
                meta, arrays = _usd_extract.extract(os.fspath(path))
        except _usd_extract.USDExtractError as exc:
            raise GroomFormatError(path, str(exc)) from None
        except Exception as exc:  # noqa: BLE001 - MemoryError under the cap, anything else USD raises
            raise GroomFormatError(path, f"USD could not read the stage ({type(exc).__name__}: "
                                         f"{_usd_extract._safe_str(exc)})") from None
    return _build_groom(path, meta, arrays)


def _extract_in_child(path, budget: int, size: int):
    timeout = 60.0 + size / 1e6  # a second per MB on top of a minute
    with tempfile.TemporaryDirectory() as d:
        out = os.path.join(d, "arrays.npz")
        cmd = [sys.executable, _usd_extract.__file__, os.path.abspath(os.fspath(path)), out, str(budget)]
        try:
            # One USD work thread and two malloc arenas: a small read gains nothing from threads,
            # and each extra thread's arena reserves 64 MB of the address-space budget.
            env = dict(os.environ, PXR_WORK_THREAD_LIMIT="1", MALLOC_ARENA_MAX="2")
            proc = subprocess.run(cmd, capture_output=True, timeout=timeout, env=env)
        except subprocess.TimeoutExpired:
            raise GroomFormatError(path, f"usd-core did not finish reading the file within {timeout:.0f} s") \
                from None
        err = proc.stderr.decode("utf-8", "replace")
        mine = [ln[len(_usd_extract.ERROR_PREFIX):] for ln in err.splitlines()
                if ln.startswith(_usd_extract.ERROR_PREFIX)]
        if proc.returncode == 4:
            raise ImportError("USD support needs the optional package usd-core: pip install usd-core "
                              f"(or pip install 'taichi-hair[usd]'); {mine[-1] if mine else ''}")
        if proc.returncode < 0:
            try:
                name = signal.Signals(-proc.returncode).name
            except ValueError:
                name = f"signal {-proc.returncode}"
            said = [ln.strip() for ln in err.splitlines() if ln.strip() and not ln.startswith("#")]
            said = f" (it said: {said[-1][:200]})" if said else ""
            raise GroomFormatError(path, f"usd-core crashed ({name}) while reading the file, in a child process"
                                         f"{said}; the file is corrupt or not a USD stage")
        if proc.returncode != 0:
            why = mine[-1] if mine else (err.strip().splitlines() or ["no message"])[-1][:300]
            raise GroomFormatError(path, why)
        try:
            with np.load(out, allow_pickle=False) as z:
                arrays = {k: z[k] for k in z.files}
            meta = json.loads(str(arrays.pop("__meta__")[()]))
        except (OSError, ValueError, KeyError) as exc:
            raise GroomFormatError(path, f"the USD reader process returned no data ({exc})") from None
    return meta, arrays


def _build_groom(path, meta: dict, arrays: dict) -> Groom:
    prims = meta["prims"]
    if not prims:
        raise GroomFormatError(path, "the stage has no BasisCurves prim")
    parts = [_check_prim(path, i, p, arrays) for i, p in enumerate(prims)]
    params: dict = {}
    units = ""
    for p in prims:
        if p["params"] is not None:
            params.update(parse_params(path, p["params"], f"{p['path']}: customData taichiHair:params",
                                       objects_only=False))
        units = p["units"] or units
    mpu = meta.get("meters_per_unit")
    if not units and mpu is not None:
        units = next((u for u, v in UNIT_METRES.items() if abs(mpu - v) <= 1e-9 * v), "")
        if not units:
            params["usd_meters_per_unit"] = float(mpu)
    if prims[0]["type"] != "linear":
        params["usd_curve_type"] = prims[0]["type"]
    if len(prims) > 1:
        params["usd_prims"] = [p["path"] for p in prims]
    if any(p["frames"] is not None for p in parts):
        params["usd_time_codes_per_second"] = float(meta["time_codes_per_second"])

    def cat(key):
        vals = [p[key] for p in parts]
        if any(v is None for v in vals):
            if any(v is not None for v in vals):
                warnings.warn(f"{os.fspath(path)}: '{key}' is authored on some BasisCurves prims only; dropped",
                              stacklevel=4)
            return None
        if len({v.shape[0] == p["counts"].size for v, p in zip(vals, parts)}) > 1:
            warnings.warn(f"{os.fspath(path)}: '{key}' is per strand on some prims and per vertex on others; "
                          f"dropped", stacklevel=4)
            return None
        return np.concatenate(vals)

    frames = times = None
    if all(p["frames"] is not None for p in parts):
        t0 = parts[0]["times"]
        if all(np.array_equal(p["times"], t0) for p in parts):
            frames = np.concatenate([p["frames"] for p in parts], axis=1)
            times = t0
    counts = np.concatenate([p["counts"] for p in parts])
    g = Groom(points=cat("points"), strand_offsets=offsets_from_counts(counts), radius=cat("radius"),
              color=cat("color"), region=cat("region"), guide=cat("guide"), rest_points=cat("rest"),
              rest_twist=cat("restTwist"),
              pinned=cat("pinned"), point_frames=frames, frame_times=times, params=params, units=units)
    return finish(g, path)


def _check_prim(path, i: int, prim: dict, arrays: dict) -> dict:
    where = prim["path"]
    counts = arrays[f"{i}.counts"].reshape(-1)
    if counts.size == 0:
        raise GroomFormatError(path, f"{where}: curveVertexCounts is empty")
    if counts.min() < 2:
        s = int(np.argmin(counts))
        raise GroomFormatError(path, f"{where}: curveVertexCounts[{s}] is {int(counts[s])}; a strand needs at "
                                     f"least 2 points", strand=s)
    n, ns = int(counts.sum()), counts.size
    frames = times = None
    if f"{i}.times" in arrays:
        times = arrays[f"{i}.times"]
        frames = [arrays[f"{i}.frame{k}"] for k in range(times.size)]
        if any(f.shape != (n, 3) for f in frames):
            raise GroomFormatError(path, f"{where}: a time sample of points does not hold {n} points (the sum of "
                                         f"curveVertexCounts)")
        frames = np.stack(frames) if frames else None
    points = arrays.get(f"{i}.points")
    if points is None:
        if frames is None:
            raise GroomFormatError(path, f"{where}: no points")
        points = frames[0].copy()
    if points.shape[0] != n:
        raise GroomFormatError(path, f"{where}: points has {points.shape[0]} entries but curveVertexCounts sums to "
                                     f"{n}")

    def sized(key, what, allowed, width=None):
        v = arrays.get(key)
        if v is None:
            return None
        if width:
            if v.size % width:
                raise GroomFormatError(path, f"{where}: {what} has {v.size} values, not a multiple of {width}")
            v = v.reshape(-1, width)
        if v.shape[0] not in allowed:
            raise GroomFormatError(path, f"{where}: {what} has {v.shape[0]} entries; expected "
                                         f"{' or '.join(str(a) for a in allowed)}")
        return v

    w = arrays.get(f"{i}.widths")
    radius = None
    if w is not None:
        w = w.reshape(-1)
        if w.shape[0] == 1:  # constant interpolation
            w = np.full(ns, w[0], np.float32)
        arrays[f"{i}.widths"] = w
        radius = sized(f"{i}.widths", "widths", (ns, n))
        radius = radius * np.float32(0.5)
    return dict(counts=counts, points=points, frames=frames, times=times, radius=radius,
                rest=sized(f"{i}.pv.rest", "primvars:rest", (n,), 3),
                restTwist=sized(f"{i}.pv.restTwist", "primvars:restTwist", (n,)),
                color=sized(f"{i}.pv.displayColor", "primvars:displayColor", (ns, n), 3),
                region=sized(f"{i}.pv.region", "primvars:region", (ns,)),
                guide=sized(f"{i}.pv.guide", "primvars:guide", (ns,)),
                pinned=sized(f"{i}.pv.pinned", "primvars:pinned", (n,)))


def write_usd(groom: Groom, path, prim_path: str = "/Groom/Strands") -> None:
    g = prepare_write(groom, "write_usd")
    Sdf, Tf, Usd, UsdGeom, Vt = _pxr()
    ext = os.path.splitext(os.fspath(path))[1].lower()
    if ext not in (".usd", ".usda", ".usdc"):
        raise ValueError(f"write_usd: the file name must end in .usd, .usda or .usdc, got {os.fspath(path)!r}")
    stage = Usd.Stage.CreateInMemory()
    if g.units in UNIT_METRES:
        UsdGeom.SetStageMetersPerUnit(stage, UNIT_METRES[g.units])
    curves = UsdGeom.BasisCurves.Define(stage, prim_path)
    stage.SetDefaultPrim(stage.GetPrimAtPath(Sdf.Path(prim_path).GetPrefixes()[0]))
    curves.CreateTypeAttr(UsdGeom.Tokens.linear)
    curves.CreateCurveVertexCountsAttr(Vt.IntArray.FromNumpy(g.strand_vertex_counts().astype(np.int32)))
    pattr = curves.CreatePointsAttr()
    pattr.Set(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(g.points, dtype=np.float32)))
    if g.point_frames is not None:
        for f, t in enumerate(g.frame_times):
            pattr.Set(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(g.point_frames[f], dtype=np.float32)),
                      Usd.TimeCode(float(t)))
        stage.SetStartTimeCode(float(g.frame_times[0]))
        stage.SetEndTimeCode(float(g.frame_times[-1]))
        tps = g.params.get("usd_time_codes_per_second")
        if isinstance(tps, (int, float)) and tps > 0:
            stage.SetTimeCodesPerSecond(float(tps))
    ns, n = g.strand_count, g.vertex_count
    interp = {ns: UsdGeom.Tokens.uniform, n: UsdGeom.Tokens.vertex}
    if g.radius is not None:
        curves.CreateWidthsAttr(Vt.FloatArray.FromNumpy((g.radius.astype(np.float32) * np.float32(2.0))))
        curves.SetWidthsInterpolation(interp[g.radius.shape[0]])
    pv = UsdGeom.PrimvarsAPI(curves)
    T = Sdf.ValueTypeNames
    if g.rest_points is not None:
        pv.CreatePrimvar("rest", T.Point3fArray, UsdGeom.Tokens.vertex).Set(
            Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(g.rest_points, dtype=np.float32)))
    if g.rest_twist is not None:
        pv.CreatePrimvar("restTwist", T.DoubleArray, UsdGeom.Tokens.vertex).Set(
            Vt.DoubleArray.FromNumpy(np.ascontiguousarray(g.rest_twist, dtype=np.float64)))
    if g.color is not None:
        pv.CreatePrimvar("displayColor", T.Color3fArray, interp[g.color.shape[0]]).Set(
            Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(g.color, dtype=np.float32)))
    if g.region is not None:
        pv.CreatePrimvar("region", T.IntArray, UsdGeom.Tokens.uniform).Set(
            Vt.IntArray.FromNumpy(g.region.astype(np.int32)))
    if g.guide is not None:
        pv.CreatePrimvar("guide", T.BoolArray, UsdGeom.Tokens.uniform).Set(Vt.BoolArray(g.guide.tolist()))
    if g.pinned is not None:
        pv.CreatePrimvar("pinned", T.BoolArray, UsdGeom.Tokens.vertex).Set(Vt.BoolArray(g.pinned.tolist()))
    prim = curves.GetPrim()
    if g.params:
        prim.SetCustomDataByKey("taichiHair:params", json.dumps(g.params, allow_nan=False))
    if g.units:
        prim.SetCustomDataByKey("taichiHair:units", g.units)
    with atomic_path(path, suffix=ext) as tmp:
        if not stage.GetRootLayer().Export(tmp):
            raise OSError(f"write_usd: USD could not write {tmp}")
