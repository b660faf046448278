"""Checkpoints you can trust, and memory bounded before allocation (issue 17 items 1 and 3).

A checkpoint records the project version and the SHA-256, dtype and shape of every member (and of its own
record).  ``--resume`` from one that is truncated, bit-flipped, lacks a member, was edited, holds a
non-finite value or has the wrong shapes is refused with one line naming the file and what is wrong, and
how to start over; nothing already written is touched.  A frame buffer too large for memory is streamed
through a file (the same frames, bit for bit); sizes that cannot fit are refused before anything is built;
a ``MemoryError`` anywhere is one line.
"""

import json
import os
import shutil
import zipfile

import numpy as np
import pytest

from taichi_hair.cli.main import main
from taichi_hair.scene.checkpoint import CheckpointError, read_checkpoint, write_checkpoint

RUN = ["simulate", "hang", "--strands", "3", "--checkpoint-every", "1", "--quiet"]


@pytest.fixture(scope="module")
def base_run(tmp_path_factory):
    """A finished 2-frame run of the hang scene with its checkpoint (frame 2)."""
    out = tmp_path_factory.mktemp("ckpt") / "hang"
    assert main(RUN + ["--frames", "2", "--out", str(out)]) == 0
    return out


def _copy(base_run, tmp_path):
    out = tmp_path / "hang"
    shutil.copytree(base_run, out)
    return out


def _rewrite(path, change):
    """Rewrite the checkpoint's zip with ``change(name, array) -> array or None (drop)``, keeping 'meta' as is:
    what a corruption or a hand edit does (the record no longer matches)."""
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    out = {}
    for k, a in arrays.items():
        b = a if k == "meta" else change(k, a)
        if b is not None:
            out[k] = b
    with open(path, "wb") as fh:
        np.savez(fh, **out)


def _resave(path, change):
    """Write a self-consistent checkpoint (fresh checksums) whose arrays went through ``change``."""
    ck = read_checkpoint(path)
    state = {k: change("state/" + k, v) for k, v in ck["state"].items()}
    solver = {k: change("solver/" + k, v) for k, v in ck["solver"].items()}
    write_checkpoint(str(path), state, solver, ck["frame"], change("frame_positions", ck["frame_positions"]),
                     ck["stats"], ck["fingerprint"])


def _truncate(p):
    data = p.read_bytes()
    p.write_bytes(data[: len(data) // 2])


def _flip_a_byte(p):
    data = bytearray(p.read_bytes())
    data[len(data) // 3] ^= 0x40  # inside the stored arrays (an uncompressed zip: caught by its CRC-32)
    p.write_bytes(bytes(data))


def _drop_a_member(p):
    _rewrite(p, lambda k, a: None if k == "state/vertex_velocity" else a)


def _shift_frames_5_m(p):
    _rewrite(p, lambda k, a: a + np.float32(5.0) if k == "frame_positions" else a)


def _nan_in_a_frame(p):
    def change(k, a):
        if k == "frame_positions":
            a = a.copy()
            a[1, 7, 1] = np.nan
        return a
    _resave(p, change)


def _state_10_rows_short(p):
    _resave(p, lambda k, a: a[:-10] if k == "state/vertex_position" else a)


def _not_a_zip(p):
    p.write_bytes(b"this is not a checkpoint\n" * 10)


CASES = [
    (_truncate, "not a readable checkpoint"),
    (_flip_a_byte, "not a readable checkpoint"),
    (_drop_a_member, "lacks the member 'state/vertex_velocity'"),
    (_shift_frames_5_m, "member 'frame_positions' fails its SHA-256 checksum"),
    (_nan_in_a_frame, "member 'frame_positions' holds 1 non-finite value(s)"),
    (_state_10_rows_short, "state/vertex_position has the shape"),
    (_not_a_zip, "not a readable checkpoint"),
]


@pytest.mark.parametrize("corrupt,reason", CASES, ids=[c.__name__.strip("_") for c, _ in CASES])
def test_a_bad_checkpoint_is_refused_in_one_line_and_nothing_is_lost(base_run, tmp_path, capsys, corrupt, reason):
    out = _copy(base_run, tmp_path)
    ckpt = out / "checkpoint.npz"
    frames_before = (out / "frames.npz").read_bytes()
    corrupt(ckpt)
    capsys.readouterr()
    rc = main(RUN + ["--frames", "4", "--out", str(out), "--resume"])
    err = capsys.readouterr().err.strip()
    assert rc == 2, err
    assert "\n" not in err and "Traceback" not in err, err
    assert str(ckpt) in err and reason in err and "to start from frame 0" in err, err
    # nothing lost: the frames already written are untouched, and no frame past 2 was written
    assert (out / "frames.npz").read_bytes() == frames_before
    assert not (out / "frames" / "frame_00003.thair.npz").exists()


def test_a_checkpoint_records_the_version_and_a_checksum_of_every_member(base_run):
    import taichi_hair

    with np.load(base_run / "checkpoint.npz") as z:
        meta = json.loads(str(z["meta"]))
        files = set(z.files) - {"meta"}
    assert meta["project_version"] == taichi_hair.__version__ and meta["version"] == 2
    assert set(meta["members"]) == files and all(len(m["sha256"]) == 64 for m in meta["members"].values())
    assert read_checkpoint(str(base_run / "checkpoint.npz"))["frame"] == 2


def test_an_edited_record_fails_its_own_checksum(base_run, tmp_path):
    """The record (frame, stats, fingerprint) is checksummed too: moving 'frame' back by hand is caught."""
    p = _copy(base_run, tmp_path) / "checkpoint.npz"
    with np.load(p) as z:
        arrays = {k: z[k] for k in z.files}
    meta = json.loads(str(arrays["meta"]))
    meta["frame"] = 1
    arrays["meta"] = np.array(json.dumps(meta))
    with open(p, "wb") as fh:
        np.savez(fh, **arrays)
    with pytest.raises(CheckpointError, match="'meta' fails its SHA-256 checksum"):
        read_checkpoint(str(p))


def test_a_sound_checkpoint_still_resumes(base_run, tmp_path):
    out = _copy(base_run, tmp_path)
    assert main(RUN + ["--frames", "3", "--out", str(out), "--resume"]) == 0
    assert np.load(out / "frames.npz")["positions"].shape[0] == 4
    assert zipfile.is_zipfile(out / "checkpoint.npz")


def test_state_load_and_solver_restore_check_shapes_before_loading_anything():
    """A snapshot 10 rows short raises ValueError naming the field, and the State keeps its values (before
    this check, Taichi's from_numpy read past the array's end)."""
    from taichi_hair import GroomBuilder, RodMaterial, SolverADMM

    b = GroomBuilder()
    b.add_strand(np.c_[np.zeros(20), -np.linspace(0, 0.1, 20), np.zeros(20)], RodMaterial())
    model = b.finalize()
    st = model.state()
    before = st.to_numpy()
    snap = {k: v.copy() for k, v in before.items()}
    snap["vertex_position"] = snap["vertex_position"][:-10] + 1.0
    snap["vertex_velocity"] = snap["vertex_velocity"] + 1.0
    with pytest.raises(ValueError, match=r"State.load: vertex_position has the shape \(10, 3\), expected \(20, 3\)"):
        st.load(snap)
    assert all(np.array_equal(st.to_numpy()[k], before[k]) for k in before)
    solver = SolverADMM(model)
    ck = solver.checkpoint()
    key = next(k for k, v in ck.items() if np.ndim(v) == 2)
    bad = dict(ck, **{key: ck[key][:-10]})
    with pytest.raises(ValueError, match=f"SolverADMM.restore: {key} has the shape"):
        solver.restore(bad)
    missing = {k: v for k, v in ck.items() if k != "step_count"}
    with pytest.raises(ValueError, match="lacks 'step_count'"):
        solver.restore(missing)


def test_a_frame_buffer_too_large_for_memory_is_streamed_with_the_same_frames(base_run, tmp_path, monkeypatch,
                                                                           capsys):
    """FRAME_BUFFER_FRACTION 0: every buffer counts as too large, so the run streams its frames through
    ``.frames.buffer.npy`` in the output folder; frames.npz is bit for bit the in-memory run's, and the
    buffer file is gone afterwards."""
    import taichi_hair.io.sizing as sizing

    monkeypatch.setattr(sizing, "FRAME_BUFFER_FRACTION", 0.0)
    out = tmp_path / "streamed"
    assert main(["simulate", "hang", "--strands", "3", "--frames", "2", "--out", str(out)]) == 0
    assert "streamed through" in capsys.readouterr().err
    a = np.load(base_run / "frames.npz")["positions"]
    b = np.load(out / "frames.npz")["positions"]
    assert a.shape == b.shape and np.array_equal(a, b)
    assert not [f for f in os.listdir(out) if f.startswith(".frames.buffer")]


def test_a_run_too_large_for_memory_or_disk_is_refused_before_anything_is_built(tmp_path, capsys):
    """10^8 frames of 1,000 strands (41,000 vertices): a 49 TB frame buffer, more than memory, so it would be
    streamed, and more than the disk holds: one line with the estimate, at once (no Taichi start-up)."""
    import time

    t = time.perf_counter()
    rc = main(["simulate", "hang", "--strands", "1000", "--frames", "100000000", "--out", str(tmp_path / "x")])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "\n" not in err and "Traceback" not in err, err
    assert "of disk in" in err and "TB" in err, err
    assert time.perf_counter() - t < 10.0
    assert not (tmp_path / "x").exists()


def test_memory_error_anywhere_is_one_line(tmp_path, capsys, monkeypatch):
    import taichi_hair.io.sizing as sizing

    def boom(*a, **k):
        raise MemoryError

    monkeypatch.setattr(sizing, "check_simulation", boom)
    rc = main(["simulate", "hang", "--strands", "3", "--frames", "1", "--out", str(tmp_path / "m")])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and err.startswith("error: out of memory (") and "\n" not in err, err


def test_the_builder_refuses_a_model_too_large_for_memory_before_allocating(monkeypatch):
    """available_memory patched to 10 MB: a 20,000-vertex Model (~24 MB at 1.2 kB per vertex) is refused by
    finalize() with the estimate, before Taichi allocates a field."""
    from taichi_hair import GroomBuilder, RodMaterial
    import taichi_hair.io.sizing as sizing

    monkeypatch.setattr(sizing, "available_memory", lambda: 10e6)
    b = GroomBuilder()
    pts = (np.zeros((1000, 20, 3)) + np.linspace(0, -0.1, 20)[None, :, None] * [0, 1, 0]).reshape(-1, 3)
    pts[:, 0] += np.repeat(np.arange(1000) * 1e-3, 20)
    b.add_strands(pts, np.arange(0, 20001, 20), RodMaterial())
    with pytest.raises(ValueError, match=r"GroomBuilder.finalize: a Model of 20,000 vertices needs an estimated 24"):
        b.finalize()
