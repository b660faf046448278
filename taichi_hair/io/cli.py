"""``taichi-hair convert`` and ``taichi-hair info``: groom files from the command line.

Wire into the main parser with ``register(subparsers)``; each command is a
function of the parsed arguments returning an exit code.  Bad files raise
:class:`GroomFormatError` (a ``ValueError``), which the main CLI prints as one line.

    taichi-hair convert ponytail/back.tfx back.hair --scale 0.01
    taichi-hair info back.hair
"""

from __future__ import annotations

import json
import math
import os
import sys
import warnings

import numpy as np

from . import FORMAT_NAMES, WRITERS, format_from_extension, load_groom, save_groom
from .groom import Groom


def groom_stats(groom: Groom) -> dict:
    """Summary statistics: counts, strand lengths, bounding box, discrete curvature.

    Curvature is the turning angle between consecutive edges at each interior
    vertex divided by its Voronoi length (half the two edges) [rad / length unit].
    """
    pts = groom.points.astype(np.float64)
    off = groom.strand_offsets
    lengths = groom.lengths()
    e = np.diff(pts, axis=0)
    le = np.linalg.norm(e, axis=1)
    # Interior vertex j (global) has edges j-1 and j; both must lie inside the same strand.
    interior = np.ones(groom.vertex_count, dtype=bool)
    interior[off[:-1]] = False
    interior[off[1:] - 1] = False
    j = np.nonzero(interior)[0]
    a, b = e[j - 1], e[j]
    la, lb = le[j - 1], le[j]
    ok = (la > 0) & (lb > 0)
    cosang = np.einsum("ij,ij->i", a[ok], b[ok]) / (la[ok] * lb[ok])
    angle = np.arccos(np.clip(cosang, -1.0, 1.0))
    kappa = angle / (0.5 * (la[ok] + lb[ok]))
    counts = groom.strand_vertex_counts()
    out = {
        "strands": groom.strand_count,
        "vertices": groom.vertex_count,
        "vertices_per_strand": {"min": int(counts.min()), "max": int(counts.max())},
        "dtype": str(groom.points.dtype),
        "units": groom.units,
        "length": {"min": float(lengths.min()), "median": float(np.median(lengths)), "max": float(lengths.max()),
                   "total": float(lengths.sum())},
        "bbox": {"min": pts.min(axis=0).tolist(), "max": pts.max(axis=0).tolist()},
        "edge_length": {"min": float(le[~_joins(groom)].min()) if groom.vertex_count > 1 else 0.0,
                        "mean": float(le[~_joins(groom)].mean()) if groom.vertex_count > 1 else 0.0},
        "turning_angle_deg": {"mean": float(np.degrees(angle.mean())) if angle.size else 0.0,
                              "max": float(np.degrees(angle.max())) if angle.size else 0.0},
        "curvature_per_unit": {"mean": float(kappa.mean()) if kappa.size else 0.0,
                               "max": float(kappa.max()) if kappa.size else 0.0},
        "attributes": [k for k in ("radius", "color", "region", "guide", "rest_points", "pinned", "point_frames")
                       if getattr(groom, k) is not None],
        "params": groom.params,
    }
    if groom.pinned is not None:
        out["pinned_vertices"] = int(groom.pinned.sum())
    if groom.point_frames is not None:
        out["frames"] = int(groom.point_frames.shape[0])
    return out


def _joins(groom: Groom) -> np.ndarray:
    """Mask over np.diff(points) of the fake edges joining one strand's tip to the next root."""
    m = np.zeros(max(groom.vertex_count - 1, 0), dtype=bool)
    m[groom.strand_offsets[1:-1] - 1] = True
    return m


def format_stats(path: str, s: dict) -> str:
    u = s["units"] or "file units"
    lo, hi = s["bbox"]["min"], s["bbox"]["max"]
    lines = [
        f"{path}",
        f"  strands {s['strands']}, vertices {s['vertices']} ({s['vertices_per_strand']['min']} to "
        f"{s['vertices_per_strand']['max']} per strand), {s['dtype']}, units: {u}",
        f"  strand length [{u}]: min {s['length']['min']:.6g}, median {s['length']['median']:.6g}, "
        f"max {s['length']['max']:.6g}, total {s['length']['total']:.6g}",
        f"  bounding box [{u}]: ({lo[0]:.6g}, {lo[1]:.6g}, {lo[2]:.6g}) to ({hi[0]:.6g}, {hi[1]:.6g}, {hi[2]:.6g})",
        f"  edge length [{u}]: min {s['edge_length']['min']:.6g}, mean {s['edge_length']['mean']:.6g}",
        f"  turning angle per vertex [deg]: mean {s['turning_angle_deg']['mean']:.4g}, "
        f"max {s['turning_angle_deg']['max']:.4g}",
        f"  curvature [rad / {u}]: mean {s['curvature_per_unit']['mean']:.6g}, "
        f"max {s['curvature_per_unit']['max']:.6g}",
        f"  attributes: {', '.join(s['attributes']) or 'none'}",
    ]
    if "pinned_vertices" in s:
        lines.append(f"  pinned vertices: {s['pinned_vertices']}")
    if "frames" in s:
        lines.append(f"  animation frames: {s['frames']}")
    if s["params"]:
        lines.append(f"  params: {json.dumps(s['params'], sort_keys=True)[:400]}")
    return "\n".join(lines)


def _scale(value: str) -> float:
    try:
        f = float(value)
    except ValueError:
        raise ValueError(f"--scale must be a number, got {value!r}") from None
    if not (math.isfinite(f) and f > 0):
        raise ValueError(f"--scale must be a finite positive number, got {value!r}")
    return f


def _is_result(path) -> bool:
    """A folder that ``simulate`` wrote, or a frames.npz (positions of every frame)."""
    path = os.fspath(path)
    if os.path.isdir(path):
        return True
    if path.lower().endswith(".npz") and not path.lower().endswith(".thair.npz") and os.path.isfile(path):
        try:
            with np.load(path) as probe:
                return "positions" in probe.files
        except (OSError, ValueError):
            return False
    return False


def _load(path, fmt, scale) -> Groom:
    """load_groom with its warnings printed as one ``warning:`` line each, and a missing
    optional dependency (usd-core) reported as a ValueError so the main CLI prints one line."""
    if fmt is None and _is_result(path):  # a simulate folder or its frames.npz: every frame, the last as points
        from .result import load_result

        res = load_result(path)
        groom = res.groom(res.frame_count - 1)
        groom.point_frames = np.ascontiguousarray(res.positions)
        groom.frame_times = np.arange(res.frame_count, dtype=np.float64)
        if res.fps:
            groom.params = {"fps": res.fps, "usd_time_codes_per_second": res.fps}
        return groom.scaled(scale, units="m") if scale is not None else groom
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            groom = load_groom(path, format=fmt, scale=scale)
        except ImportError as exc:
            raise ValueError(str(exc)) from None
    for w in caught:
        print(f"warning: {w.message}", file=sys.stderr)
    return groom


def cmd_convert(args) -> int:
    if args.to_format is None and format_from_extension(args.output) not in WRITERS:
        raise ValueError(f"cannot tell the output format from {args.output!r}; pass --to, one of "
                         f"{', '.join(WRITERS)}")
    groom = _load(args.input, args.from_format, args.scale)
    options = {}
    if args.ascii:
        options["ascii"] = True
    os.makedirs(os.path.dirname(os.path.abspath(args.output)), exist_ok=True)
    try:
        save_groom(groom, args.output, format=args.to_format, **options)
    except ImportError as exc:
        raise ValueError(str(exc)) from None
    print(f"wrote {args.output}: {groom.strand_count} strands, {groom.vertex_count} vertices")
    return 0


def cmd_info(args) -> int:
    groom = _load(args.file, args.from_format, args.scale)
    stats = groom_stats(groom)
    if args.json:
        print(json.dumps(stats, indent=2))
    else:
        print(format_stats(args.file, stats))
    return 0


def register(subparsers) -> None:
    """Add ``convert`` and ``info`` to an argparse subparsers object."""
    c = subparsers.add_parser("convert", help="convert a groom file between formats",
                              description=f"Formats: {', '.join(FORMAT_NAMES)} (writable: {', '.join(WRITERS)}).")
    c.add_argument("input", metavar="IN", help="input groom file")
    c.add_argument("output", metavar="OUT", help="output file (format from its extension unless --to)")
    c.add_argument("--scale", type=_scale, default=None, help="factor from the input's units to metres (0.01 for cm)")
    c.add_argument("--from", dest="from_format", default=None, help="input format (default: detected)")
    c.add_argument("--to", dest="to_format", default=None, help="output format (default: from OUT's extension)")
    c.add_argument("--ascii", action="store_true", help="ASCII output where the format has both (PLY)")
    c.set_defaults(func=cmd_convert)

    i = subparsers.add_parser("info", help="print a groom file's strand statistics")
    i.add_argument("file", metavar="FILE", help="groom file")
    i.add_argument("--from", dest="from_format", default=None, help="format (default: detected)")
    i.add_argument("--scale", type=_scale, default=None, help="factor from the file's units to metres")
    i.add_argument("--json", action="store_true", help="print the statistics as JSON")
    i.set_defaults(func=cmd_info)


def main(argv=None) -> int:
    """Stand-alone entry (``python -m taichi_hair.io.cli``) until the main CLI wires ``register`` in."""
    import argparse

    p = argparse.ArgumentParser(prog="taichi-hair-io")
    register(p.add_subparsers(dest="command", required=True))
    args = p.parse_args(argv)
    try:
        return args.func(args)
    except (ValueError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
