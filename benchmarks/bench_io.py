"""Groom file I/O throughput: save and load of a generated groom in every writable format.

    python benchmarks/bench_io.py                      # 100k strands x 32 vertices, then 100k tiny strands
    python benchmarks/bench_io.py --strands 10000 --formats hair ply
    python benchmarks/bench_io.py --cases tiny         # 100k strands of 2 to 4 vertices only

Two grooms: ``large`` (``--strands`` x ``--vertices``) and ``tiny`` (``--tiny-strands`` strands of 2 to 4
vertices, 4 for binary TressFX, which needs one count): with tiny records the per-strand work of a reader
or writer shows instead of its per-byte work.

For each format: the file size, the best of ``--repeat`` wall times of
``save_groom`` and ``load_groom`` (ms), throughput in MB/s of file bytes and in
strands/s, and a bit-for-bit check of the loaded points.  USD is loaded both
the default way (usd-core in a child process, which includes its ~0.5 s start)
and in-process (``isolate=False``).  Prints a table and
writes ``benchmarks/results/io.json``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
import warnings

import numpy as np

from harness import Bench, results_path, timed  # benchmarks/harness.py (the script's folder is on sys.path)
from taichi_hair.io import Groom, load_groom, save_groom

# (label, format, extension, writer options, reader options)
CASES = [
    ("hair", "hair", ".hair", {}, {}),
    ("data", "data", ".data", {}, {}),
    ("ply-binary", "ply", ".ply", {}, {}),
    ("ply-ascii", "ply", ".ply", {"ascii": True}, {}),
    ("obj", "obj", ".obj", {}, {}),
    ("tfx-v4", "tfx", ".tfx", {"version": 4.0}, {}),
    ("tfx-v3", "tfx", ".tfx", {"version": 3.0}, {}),
    ("tfx-v2-ascii", "tfx", ".tfx", {"version": 2.0}, {}),
    ("usdc", "usd", ".usdc", {}, {}),  # the default read: usd-core in a child process
    ("usdc-inproc", "usd", ".usdc", {}, {"isolate": False}),
    ("usda", "usd", ".usda", {}, {}),
    ("thair", "thair", ".thair.npz", {}, {}),
]


def make_groom(strands: int, vertices: int, seed: int = 0) -> Groom:
    """Strands of 20 cm from roots on a 10 cm sphere, with a small random walk (float32, metres)."""
    rng = np.random.default_rng(seed)
    roots = rng.normal(size=(strands, 3))
    roots /= np.linalg.norm(roots, axis=1, keepdims=True)
    step = 0.2 / (vertices - 1)
    walk = roots[:, None, :] * step + rng.normal(scale=0.2 * step, size=(strands, vertices, 3))
    walk[:, 0] = roots * 0.1
    pts = np.cumsum(walk, axis=1).reshape(-1, 3).astype(np.float32)
    offsets = np.arange(strands + 1, dtype=np.int64) * vertices
    return Groom(points=pts, strand_offsets=offsets, units="m").validate()


def make_tiny_groom(strands: int, uniform: bool = False, seed: int = 1) -> Groom:
    """Strands of 2 to 4 vertices (4 each with ``uniform``), 2 mm edges from roots on a 10 cm sphere."""
    rng = np.random.default_rng(seed)
    counts = np.full(strands, 4) if uniform else rng.integers(2, 5, size=strands)
    off = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    roots = rng.normal(size=(strands, 3))
    roots /= np.linalg.norm(roots, axis=1, keepdims=True)
    k = np.arange(int(off[-1])) - np.repeat(off[:-1], counts)  # vertex index within its strand
    pts = np.repeat(roots, counts, axis=0) * (0.1 + 0.002 * k[:, None])
    pts += rng.normal(scale=1e-4, size=pts.shape) * (k[:, None] > 0)
    return Groom(points=pts.astype(np.float32), strand_offsets=off, units="m").validate()


def best_time(fn, repeat: int) -> float:
    """The fastest of ``repeat`` calls (file I/O compiles nothing: no separate first call)."""
    return timed(fn, repeat, each=True, first=False, sync=lambda: None)["run_min_s"]


def run_case(groom: Groom, uniform: Groom, formats, repeat: int, have_usd: bool, tmp: str, case: str) -> list:
    """One row per format: file size, best save and load times, MB/s, strands/s, bit-exact check."""
    rows = []
    for label, fmt, ext, opts, load_opts in CASES:
        if formats and label not in formats:
            continue
        if fmt == "usd" and not have_usd:
            print(f"{label}: skipped (usd-core not installed)")
            continue
        g = uniform if label in ("tfx-v3", "tfx-v4") else groom
        text = label in ("ply-ascii", "obj", "tfx-v2-ascii", "usda")
        reps = 1 if text else repeat
        path = os.path.join(tmp, "groom" + ext)
        t_save = best_time(lambda: save_groom(g, path, format=fmt, **opts), reps)
        size = os.path.getsize(path)
        loaded = []

        def load():
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                loaded[:] = [load_groom(path, format=fmt, **load_opts)]

        t_load = best_time(load, reps)
        out = loaded[0]
        exact = bool(np.array_equal(out.points.view(np.uint32), g.points.view(np.uint32))
                     and np.array_equal(out.strand_offsets, g.strand_offsets))
        mb, ns = size / 1e6, g.strand_count
        rows.append(dict(case=case, format=label, strands=ns, vertices=g.vertex_count, file_mb=mb,
                         save_ms=1e3 * t_save, load_ms=1e3 * t_load, save_mb_s=mb / t_save, load_mb_s=mb / t_load,
                         save_strands_s=ns / t_save, load_strands_s=ns / t_load, repeat=reps, bit_exact=exact))
        os.remove(path)
        r = rows[-1]
        print(f"{case:>5} {label:>13}: {mb:8.1f} MB  save {r['save_ms']:9.1f} ms {r['save_mb_s']:8.1f} MB/s  "
              f"load {r['load_ms']:9.1f} ms {r['load_mb_s']:8.1f} MB/s  exact {exact}", flush=True)
    return rows


def print_table(title: str, rows: list) -> None:
    print()
    print(title)
    print(f"{'format':>13} {'file MB':>8} {'save ms':>9} {'save MB/s':>9} {'save strands/s':>14} "
          f"{'load ms':>9} {'load MB/s':>9} {'load strands/s':>14} {'exact':>5}")
    for r in rows:
        print(f"{r['format']:>13} {r['file_mb']:8.1f} {r['save_ms']:9.1f} {r['save_mb_s']:9.1f} "
              f"{r['save_strands_s']:14.3g} {r['load_ms']:9.1f} {r['load_mb_s']:9.1f} {r['load_strands_s']:14.3g} "
              f"{str(r['bit_exact']):>5}")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--strands", type=int, default=100_000)
    p.add_argument("--vertices", type=int, default=32, help="vertices per strand")
    p.add_argument("--tiny-strands", type=int, default=100_000, help="strands of the tiny case (2-4 vertices)")
    p.add_argument("--cases", nargs="*", default=["large", "tiny"], choices=["large", "tiny"])
    p.add_argument("--repeat", type=int, default=3, help="best of this many runs (text formats: 1)")
    p.add_argument("--formats", nargs="*", default=None, help="labels to run (default: all)")
    p.add_argument("--out", default=results_path("io.json"))
    p.add_argument("--tmp", default=None, help="folder for the files (default: a fresh temporary folder)")
    args = p.parse_args(argv)
    bench = Bench("io", argv)
    try:
        from pxr import Usd

        usd_version = ".".join(str(v) for v in Usd.GetVersion())
    except ImportError:
        usd_version = None
    tmp = tempfile.mkdtemp(prefix="bench_io_", dir=args.tmp)
    rows, tiny_rows = [], []
    try:
        if "large" in args.cases:
            g = make_groom(args.strands, args.vertices)
            rows = run_case(g, g, args.formats, args.repeat, usd_version is not None, tmp, "large")
        if "tiny" in args.cases:
            rows_t = run_case(make_tiny_groom(args.tiny_strands), make_tiny_groom(args.tiny_strands, uniform=True),
                              args.formats, args.repeat, usd_version is not None, tmp, "tiny")
            tiny_rows = rows_t
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    if rows:
        print_table(f"groom: {args.strands} strands x {args.vertices} vertices ({args.strands * args.vertices} "
                    f"points, float32); best of {args.repeat} (text formats: 1)", rows)
    if tiny_rows:
        print_table(f"tiny records: {args.tiny_strands} strands of 2 to 4 vertices (binary TressFX: 4), float32; "
                    f"best of {args.repeat} (text formats: 1)", tiny_rows)
    result = dict(strands=args.strands, vertices_per_strand=args.vertices, tiny_strands=args.tiny_strands,
                  repeat=args.repeat, numpy=np.__version__, usd_core=usd_version,
                  time=time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), rows=rows, tiny_rows=tiny_rows)
    bench.write(args.out, result)
    print(f"wrote {args.out}")
    return 0 if all(r["bit_exact"] for r in rows + tiny_rows) else 1


if __name__ == "__main__":
    sys.exit(main())
