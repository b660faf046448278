"""Fuzzing the groom readers: truncated and corrupted files of every format.

Each reader must either return a valid Groom or raise GroomFormatError: never
another exception, a crash, a hang, or an allocation out of proportion to the
file (checked with tracemalloc, which sees NumPy's allocations).
"""

import os
import struct
import time
import tracemalloc
import warnings

import numpy as np
import pytest

from taichi_hair.io import Groom, GroomFormatError, load_groom, read_tfxmesh, save_groom

SEED = 20261125
# A reader may allocate a bounded multiple of the file size (index arrays, copies).
MEMORY_FACTOR = 64
MEMORY_SLACK = 4 << 20  # first-use imports inside NumPy / zipfile / pxr


def small_groom(rng, uniform=None):
    counts = np.full(12, uniform) if uniform else rng.integers(2, 12, size=12)
    polys = [np.cumsum(rng.normal(scale=0.01, size=(int(c), 3)), axis=0).astype(np.float32) for c in counts]
    g = Groom.from_polylines(polys)
    g.radius = rng.uniform(1e-5, 1e-4, size=g.vertex_count).astype(np.float32)
    g.region = rng.integers(0, 3, size=g.strand_count)
    g.guide = rng.random(g.strand_count) < 0.5
    g.pinned = rng.random(g.vertex_count) < 0.2
    g.rest_points = g.points + np.float32(0.001)
    return g.validate()


def ct2hair_bytes(rng):
    out = [struct.pack("<i", 6)]
    for _ in range(6):
        n = int(rng.integers(2, 8))
        out.append(struct.pack("<i", n))
        out.append(rng.normal(size=(n, 7)).astype("<f4").tobytes())
    return b"".join(out)


TFXMESH = (b"numOfBones 2\n0 root\n1 head\nnumOfVertices 4\n"
           b"0 0 0 0 0 0 1 0 1 0 0 1 0 0 0\n1 1 0 0 0 0 1 0 1 0 0 0.5 0.5 0 0\n"
           b"2 0 1 0 0 0 1 1 0 0 0 1 0 0 0\n3 1 1 0 0 0 1 1 0 0 0 1 0 0 0\n"
           b"numOfTriangles 2\n0 0 1 2\n1 1 3 2\n")


def make_samples(tmp_path):
    """(name, format, bytes, strict) for every readable format; strict: every truncation must fail."""
    rng = np.random.default_rng(SEED)
    g = small_groom(rng)
    g16 = small_groom(rng, uniform=4)
    g16.radius = g16.region = g16.guide = g16.rest_points = None
    g16.validate()
    specs = [("hair", "hair", g, {}, True), ("data", "data", g, {}, True), ("ply_bin", "ply", g, {}, True),
             ("ply_ascii", "ply", g, {"ascii": True}, False), ("obj", "obj", g, {}, False),
             ("tfx2", "tfx", g, {"version": 2.0}, False), ("tfx3", "tfx", g16, {"version": 3.0}, True),
             ("tfx4", "tfx", g16, {"version": 4.0}, True), ("thair", "thair", g, {}, True)]
    try:
        import pxr  # noqa: F401
        specs.append(("usda", "usd", g, {}, False))
        specs.append(("usdc", "usd", g, {}, False))
    except ImportError:
        pass
    out = []
    for name, fmt, groom, opts, strict in specs:
        ext = {"usd": "." + name, "thair": ".thair.npz"}.get(fmt, "." + fmt)
        p = tmp_path / f"sample_{name}{ext}"
        save_groom(groom, p, format=fmt, **opts)
        out.append((name, fmt, p.read_bytes(), strict, ext))
    out.append(("ct2hair", "ct2hair", ct2hair_bytes(rng), True, ".bin"))
    out.append(("tfxmesh", "tfxmesh", TFXMESH, False, ".tfxmesh"))
    return out


def mutations(data: bytes, rng, count: int):
    """Seeded truncations and corruptions of ``data``."""
    n = len(data)
    cuts = sorted(set(rng.integers(0, n, size=count // 2).tolist()) | {0, 1, 3, 4, 7, n - 1})
    for c in cuts:
        if 0 <= c < n:
            yield "truncate", data[:c]
    specials = [0, 1, 0x7FFFFFFF, 0x80000000, 0xFFFFFFFF, 0x7FC00000, 0x7F800000, 0xFFFF, 1 << 20]
    for _ in range(count - count // 2):
        b = bytearray(data)
        kind = int(rng.integers(0, 4))
        if kind == 0:  # flip a few random bytes
            for _ in range(int(rng.integers(1, 5))):
                b[int(rng.integers(0, n))] = int(rng.integers(0, 256))
        elif kind == 1 and n >= 4:  # an aligned 4-byte word (a count, an offset, a float) to an extreme value
            i = 4 * int(rng.integers(0, n // 4))
            b[i:i + 4] = struct.pack("<I", specials[int(rng.integers(0, len(specials)))])
        elif kind == 2:  # insert or delete a run of bytes
            i = int(rng.integers(0, n))
            if rng.random() < 0.5:
                del b[i:i + int(rng.integers(1, 16))]
            else:
                b[i:i] = bytes(rng.integers(0, 256, size=int(rng.integers(1, 16))).astype(np.uint8))
        else:  # a text-level corruption: digits to letters, minus signs, NaN
            i = int(rng.integers(0, n))
            token = [b"nan", b"-", b"x", b"-1", b"99999999999", b"\n", b" "][int(rng.integers(0, 7))]
            b[i:i + 1] = token
        yield "corrupt", bytes(b)


def _load(path, fmt, detect=False):
    if fmt == "tfxmesh":
        return read_tfxmesh(path)
    # USD in-process, for speed (a child process per case would take minutes): this seed's cases
    # are known not to crash usd-core; test_usd_crash_is_isolated covers the default, isolated path.
    options = {"isolate": False} if fmt == "usd" else {}
    return load_groom(path, format=None if detect else fmt, **options)


def check_case(path, fmt, data, strict_truncation, kind, detect=False):
    path.write_bytes(data)
    tracemalloc.reset_peak()
    base = tracemalloc.get_traced_memory()[0]
    t0 = time.perf_counter()
    outcome = "ok"
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = _load(path, fmt, detect)
    except GroomFormatError as exc:
        assert str(path) in str(exc), f"{fmt} {kind}: the message does not name the file: {exc}"
        outcome = "error"
    except Exception as exc:  # noqa: BLE001 - the point of the test
        pytest.fail(f"{fmt} {kind} ({len(data)} bytes): {type(exc).__name__}: {exc}")
    else:
        if isinstance(result, Groom):
            result.validate()
            assert np.all(np.isfinite(result.points))
    elapsed = time.perf_counter() - t0
    peak = tracemalloc.get_traced_memory()[1] - base
    assert elapsed < 2.0, f"{fmt} {kind}: took {elapsed:.2f} s"
    assert peak <= MEMORY_FACTOR * max(len(data), 1) + MEMORY_SLACK, \
        f"{fmt} {kind}: allocated {peak} bytes for a {len(data)}-byte file"
    if kind == "truncate" and strict_truncation:
        assert outcome == "error", f"{fmt}: a file truncated to {len(data)} bytes was accepted"
    return outcome


def test_fuzz_every_format(tmp_path):
    rng = np.random.default_rng(SEED)
    samples = make_samples(tmp_path)
    tracemalloc.start()
    tally = {}
    try:
        for name, fmt, data, strict, ext in samples:
            cases = 150 if fmt == "usd" else 400
            path = tmp_path / f"fuzz_{name}{ext}"
            errors = total = 0
            for kind, mutated in mutations(data, rng, cases):
                errors += check_case(path, fmt, mutated, strict, kind) == "error"
                total += 1
            # A tenth of the cases again through content detection, under a neutral extension.
            neutral = tmp_path / f"fuzz_{name}.unknown"
            for kind, mutated in mutations(data, rng, cases // 10):
                check_case(neutral, fmt, mutated, strict, kind, detect=True)
                total += 1
            tally[name] = (errors, total)
    finally:
        tracemalloc.stop()
    # Each sample was corrupted enough times that most cases must be rejected.
    for name, (errors, total) in tally.items():
        assert errors > total // 3, f"{name}: only {errors} of {total} mutated files were rejected"
    assert sum(t for _, t in tally.values()) >= 3000


HEADERS = [
    ("hair", lambda c: b"HAIR" + struct.pack("<4I", c, c, 3, 0) + bytes(108)),
    ("data", lambda c: struct.pack("<II", c, c)),
    ("ct2hair", lambda c: struct.pack("<II", c, c)),
    ("tfx", lambda c: struct.pack("<f4I", 3.0, c, c, 0, 0) + bytes(124) + struct.pack("<6I", 296, 0, 0, 0, 0, 0)
     + bytes(128)),
    ("tfx", lambda c: struct.pack("<f7I", 4.0, c, 16, 160, 0, 0, 0, 0) + bytes(128)),
    ("ply", lambda c: f"ply\nformat binary_little_endian 1.0\nelement vertex {c}\nproperty float x\n"
                      f"property float y\nproperty float z\nelement strand {c}\nproperty int segments\n"
                      f"end_header\n".encode()),
]


@pytest.mark.parametrize("fmt,header,count", [(f, h, c) for f, h in HEADERS for c in (0x7FFFFFFF, 0xFFFFFFFF)]
                         + [("ply", HEADERS[-1][1], 1 << 40)])
def test_huge_counts_fail_before_allocating(tmp_path, fmt, header, count):
    """Counts of 2^31 - 1, 2^32 - 1 (-1 as int32) and 2^40 in a 64-byte file: an error, no allocation."""
    data = header(count) + bytes(64)
    p = tmp_path / f"huge.{fmt}"
    tracemalloc.start()
    try:
        assert check_case(p, fmt, data, True, "corrupt") == "error"
        with pytest.raises(GroomFormatError, match="count|needs|more than|negative|expected"):
            load_groom(p, format=fmt)
    finally:
        tracemalloc.stop()


DATA = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "io")


@pytest.mark.parametrize("isolate", [True, False])
def test_usd_corrupt_crate_cannot_exhaust_memory(isolate):
    """A fuzzed .usdc (found by this fuzzer) on which usd-core alone grows to ~4 GB resident.

    read_usd caps the address space during the read (in the child, or in this
    process with isolate=False), so it fails with a clean error.
    """
    pytest.importorskip("pxr")
    import resource

    path = os.path.join(DATA, "fuzzed_huge_alloc.usdc")
    who = resource.RUSAGE_CHILDREN if isolate else resource.RUSAGE_SELF
    before = resource.getrusage(who).ru_maxrss  # KiB on Linux
    t0 = time.perf_counter()
    with pytest.raises(GroomFormatError, match="fuzzed_huge_alloc.usdc"):
        load_groom(path, format="usd", isolate=isolate)
    grown_mib = (resource.getrusage(who).ru_maxrss - before) / 1024
    assert grown_mib < 2500, f"the read grew the resident set by {grown_mib:.0f} MiB"
    assert time.perf_counter() - t0 < 10.0


def test_usd_crash_is_isolated():
    """A fuzzed .usdc (found by this fuzzer) on which usd-core 26.11 segfaults in Stage.Open.

    The default read runs usd-core in a child process, so the crash becomes a GroomFormatError.
    """
    pytest.importorskip("pxr")
    path = os.path.join(DATA, "fuzzed_segfault.usdc")
    with pytest.raises(GroomFormatError, match=r"fuzzed_segfault\.usdc: usd-core crashed \(SIGSEGV\)"):
        load_groom(path)


def test_usd_fuzz_through_the_isolated_reader(tmp_path):
    """A few mutated .usdc files through the default (child-process) reader."""
    pytest.importorskip("pxr")
    rng = np.random.default_rng(SEED + 1)
    g = small_groom(rng)
    save_groom(g, tmp_path / "s.usdc")
    data = (tmp_path / "s.usdc").read_bytes()
    p = tmp_path / "f.usdc"
    outcomes = []
    for kind, mutated in list(mutations(data, rng, 6))[::2]:
        p.write_bytes(mutated)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                load_groom(p).validate()
            outcomes.append("ok")
        except GroomFormatError as exc:
            assert str(p) in str(exc)
            outcomes.append("error")
    assert outcomes.count("error") >= len(outcomes) // 2
