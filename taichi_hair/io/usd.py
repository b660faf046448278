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
kept only if every prim has it).  USD stores points as float32, so float32
grooms round-trip bit for bit; float64 ones are rounded to float32.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
import warnings

import numpy as np

from ._util import atomic_path, finish, offsets_from_counts, prepare_write
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


def _array(value, dtype, path, what) -> np.ndarray:
    try:
        return np.array(value, dtype=dtype)
    except (TypeError, ValueError) as exc:
        raise GroomFormatError(path, f"{what} is not a numeric array ({exc})") from None


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


def read_usd(path) -> Groom:
    if os.path.getsize(path) == 0:  # also raises the OSError for a missing file
        raise GroomFormatError(path, "the file is empty")
    Sdf, Tf, Usd, UsdGeom, Vt = _pxr()
    budget = USD_READ_BASE_BYTES + USD_READ_BYTES_PER_FILE_BYTE * os.path.getsize(path)
    try:
        with limited_address_space(budget):
            return _read_stage(path, Usd, UsdGeom)
    except GroomFormatError:
        raise
    except Exception as exc:  # noqa: BLE001 - pxr raises Tf.ErrorException, and for bad bytes
        # UnicodeDecodeError, IndexError, MemoryError...: every failure inside USD is a malformed file here.
        try:
            lines = str(exc).strip().splitlines()
        except Exception:  # noqa: BLE001 - Tf.ErrorException.__str__ fails on messages with bad UTF-8
            lines = ["(the USD error message is not valid UTF-8)"]
        raise GroomFormatError(path, f"USD could not read the stage ({type(exc).__name__}: "
                                     f"{lines[-1][:200] if lines else 'no message'})") from None


def _read_stage(path, Usd, UsdGeom) -> Groom:
    name = os.fspath(path)
    if os.path.splitext(name)[1].lower() in (".usd", ".usda", ".usdc", ".usdz"):
        return _read_open_stage(path, Usd.Stage.Open(name, Usd.Stage.LoadAll), Usd, UsdGeom)
    # USD picks its parser by extension: open a misnamed file through a link with the right one.
    with open(name, "rb") as fh:
        magic = fh.read(8)
    ext = ".usdc" if magic.startswith(b"PXR-USDC") else ".usdz" if magic.startswith(b"PK") else ".usda"
    with tempfile.TemporaryDirectory() as d:
        link = os.path.join(d, "stage" + ext)
        os.symlink(os.path.abspath(name), link)
        return _read_open_stage(path, Usd.Stage.Open(link, Usd.Stage.LoadAll), Usd, UsdGeom)


def _read_open_stage(path, stage, Usd, UsdGeom) -> Groom:
    if stage is None:
        raise GroomFormatError(path, "USD could not open the stage")
    prims = [p for p in stage.Traverse() if p.IsA(UsdGeom.BasisCurves)]
    if not prims:
        raise GroomFormatError(path, "the stage has no BasisCurves prim")
    parts = [_read_prim(UsdGeom.BasisCurves(p), path, UsdGeom, Usd) for p in prims]
    params: dict = {}
    units = ""
    for p in prims:
        text = p.GetCustomDataByKey("taichiHair:params")  # a namespaced key: nested dictionaries
        if text is not None:
            try:
                more = json.loads(text)
            except (TypeError, ValueError) as exc:
                raise GroomFormatError(path, f"{p.GetPath()}: customData taichiHair:params is not JSON ({exc})") \
                    from None
            if isinstance(more, dict):
                params.update(more)
        units = str(p.GetCustomDataByKey("taichiHair:units") or units)
    if not units and stage.HasAuthoredMetadata("metersPerUnit"):
        mpu = UsdGeom.GetStageMetersPerUnit(stage)
        units = next((u for u, v in UNIT_METRES.items() if abs(mpu - v) <= 1e-9 * v), "")
        if not units:
            params["usd_meters_per_unit"] = float(mpu)
    if parts[0]["type"] != "linear":
        params["usd_curve_type"] = parts[0]["type"]
    if len(prims) > 1:
        params["usd_prims"] = [str(p.GetPath()) for p in prims]
    if any(p["frames"] is not None for p in parts):
        params["usd_time_codes_per_second"] = float(stage.GetTimeCodesPerSecond())

    def cat(key):
        vals = [p[key] for p in parts]
        if any(v is None for v in vals):
            if any(v is not None for v in vals):
                warnings.warn(f"{os.fspath(path)}: '{key}' is authored on some BasisCurves prims only; dropped",
                              stacklevel=3)
            return None
        return np.concatenate(vals)

    counts = np.concatenate([p["counts"] for p in parts])
    frames = times = None
    if all(p["frames"] is not None for p in parts):
        t0 = parts[0]["times"]
        if all(np.array_equal(p["times"], t0) for p in parts):
            frames = np.concatenate([p["frames"] for p in parts], axis=1)
            times = t0
    radius = cat("radius") if len({p["radius"].shape[0] == p["counts"].size for p in parts
                                   if p["radius"] is not None}) <= 1 else None
    color = cat("color") if len({p["color"].shape[0] == p["counts"].size for p in parts
                                 if p["color"] is not None}) <= 1 else None
    g = Groom(points=cat("points"), strand_offsets=offsets_from_counts(counts), radius=radius, color=color,
              region=cat("region"), guide=cat("guide"), rest_points=cat("rest"), pinned=cat("pinned"),
              point_frames=frames, frame_times=times, params=params, units=units)
    return finish(g, path)


def _read_prim(curves, path, UsdGeom, Usd) -> dict:
    where = str(curves.GetPath())
    counts = _array(curves.GetCurveVertexCountsAttr().Get() or [], np.int64, path, f"{where}.curveVertexCounts")
    if counts.size == 0:
        raise GroomFormatError(path, f"{where}: curveVertexCounts is empty")
    if counts.min() < 2:
        s = int(np.argmin(counts))
        raise GroomFormatError(path, f"{where}: curveVertexCounts[{s}] is {int(counts[s])}; a strand needs at "
                                     f"least 2 points", strand=s)
    n = int(counts.sum())
    pattr = curves.GetPointsAttr()
    samples = list(pattr.GetTimeSamples())
    pts = pattr.Get(Usd.TimeCode.Default())
    frames = times = None
    if samples:
        frames = np.stack([_array(pattr.Get(t), np.float32, path, f"{where}.points") for t in samples]) \
            if all(len(pattr.Get(t) or []) == n for t in samples) else None
        if frames is None:
            raise GroomFormatError(path, f"{where}: a time sample of points does not hold {n} points "
                                         f"(the sum of curveVertexCounts)")
        times = np.array(samples, dtype=np.float64)
    if pts is None:
        if frames is None:
            raise GroomFormatError(path, f"{where}: no points")
        points = frames[0].copy()
    else:
        points = _array(pts, np.float32, path, f"{where}.points").reshape(-1, 3)
    if points.shape[0] != n:
        raise GroomFormatError(path, f"{where}: points has {points.shape[0]} entries but curveVertexCounts sums to "
                                     f"{n}")
    ns = counts.size

    def sized(value, what, allowed):
        if value is None:
            return None
        if value.shape[0] not in allowed:
            raise GroomFormatError(path, f"{where}: {what} has {value.shape[0]} entries; expected "
                                         f"{' or '.join(str(a) for a in allowed)}")
        return value

    radius = None
    wattr = curves.GetWidthsAttr()
    w = wattr.Get()
    if w is not None and len(w):
        w = _array(w, np.float32, path, f"{where}.widths")
        if w.shape[0] == 1:  # constant
            w = np.full(ns, w[0], np.float32)
        radius = sized(w * np.float32(0.5), "widths", (ns, n))
    pv = UsdGeom.PrimvarsAPI(curves)

    def primvar(name, dtype, allowed):
        p = pv.GetPrimvar(name)
        if not p or not p.HasAuthoredValue():
            return None
        v = p.ComputeFlattened()
        if v is None:
            return None
        return sized(_array(v, dtype, path, f"{where}.primvars:{name}"), f"primvars:{name}", allowed)

    rest = primvar("rest", np.float32, (n,))
    color = primvar("displayColor", np.float32, (ns, n))
    return dict(type=str(curves.GetTypeAttr().Get() or "linear"), counts=counts, points=points, frames=frames,
                times=times, radius=radius, rest=None if rest is None else rest.reshape(-1, 3),
                region=primvar("region", np.int64, (ns,)), guide=primvar("guide", bool, (ns,)),
                pinned=primvar("pinned", bool, (n,)), color=None if color is None else color.reshape(-1, 3))


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
