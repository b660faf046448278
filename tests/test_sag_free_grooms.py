"""Sag-free grooms hold their authored shape under gravity with hair-hair and body contacts (issue 14, item 3).

Run as a user would: ``taichi-hair simulate`` on the head-turn scene with the head still, a generated straight
groom, once as authored and once with ``--rest-pose sag-free``.  The drift is measured here from the written
frames (independent of the run's own summary): the distance of every non-root vertex from its position at
frame 0, after 2 s.
"""

import os
import subprocess
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "benchmarks"))


def _drift_p90(out) -> float:
    with np.load(os.path.join(out, "frames.npz")) as z:
        pos, starts = z["positions"].astype(np.float64), z["strand_vertex_start"]
    free = np.ones(pos.shape[1], bool)
    free[starts] = False
    return float(np.percentile(np.linalg.norm(pos[-1] - pos[0], axis=1)[free], 90))


def _run_both(tmp_path, text: str, frames: int, extra=()) -> dict:
    """p90 drift of the scene run as authored and sag-free through the CLI, from the written frames [m]."""
    scene = tmp_path / "scene.toml"
    scene.write_text(text)
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    drift = {}
    for rest_pose in ("authored", "sag-free"):
        out = tmp_path / rest_pose
        proc = subprocess.run([sys.executable, "-m", "taichi_hair.cli", "simulate", str(scene), "--rest-pose",
                               rest_pose, "--frames", str(frames), "--out", str(out), "--quiet", *extra],
                              capture_output=True, text=True, timeout=600, env=env, cwd=ROOT)
        assert proc.returncode == 0, proc.stderr[-2000:]
        drift[rest_pose] = _drift_p90(out)
    return drift


def test_a_generated_groom_solved_sag_free_holds_within_1_mm_with_contacts_while_the_authored_one_sags(tmp_path):
    # Claim (issue 14 item 3, at a test's size: 60 strands x 16 vertices instead of 300 x 24): after 2 s (48
    # frames, 4 substeps, 10 ADMM iterations, hair-hair friction 0.2, head mesh friction 0.3, head still), the
    # p90 vertex drift of the sag-free groom is <= 1 mm and <= 10 % of the authored groom's.  Measured at this
    # size: 0.033 mm against 15.1 mm.  The 4 strands the solve reports as not held fall, and stay under p90.
    from bench_rest_pose import scene_text

    text = scene_text("straight", "still").replace("strands = 300", "strands = 60")
    text = text.replace("vertices_per_strand = 24", "vertices_per_strand = 16")
    drift = _run_both(tmp_path, text, 48)
    assert drift["authored"] > 5e-3, drift  # the authored groom does sag (the claim below is not vacuous)
    assert drift["sag-free"] <= 1e-3, drift
    assert drift["sag-free"] <= 0.1 * drift["authored"], drift


def test_the_shipped_ponytail_solved_sag_free_holds_within_1_mm_with_contacts_while_the_authored_one_sags(tmp_path):
    # Claim (issue 14 item 3, the shipped ponytail: assets/scenes/ponytail.toml, 255 TressFX strands x 16
    # vertices, r = 110 um, hair-hair friction 0.2, the three head spheres, head still): after 2 s (48 frames)
    # the p90 drift of the sag-free tail is <= 1 mm and <= 10 % of the authored tail's.  Measured 2026-12-05:
    # 0.047 mm against 57 mm.  It needs ContactConfig.keep_rest_overlaps (default): the tail's strands are
    # authored closer than two radii, and pushing them apart moved the sag-free tail by 1.3 mm p90.
    from bench_rest_pose import scene_text

    drift = _run_both(tmp_path, scene_text("ponytail", "still"), 48)
    assert drift["authored"] > 20e-3, drift  # the authored tail does fall
    assert drift["sag-free"] <= 1e-3, drift
    assert drift["sag-free"] <= 0.1 * drift["authored"], drift


def test_a_sag_free_groom_returns_within_1_mm_of_its_authored_shape_after_a_10_degree_head_turn(tmp_path):
    # Claim (issue 14 item 3, the head turn, at a test's size: 60 wavy strands x 16 vertices on assets/head.obj,
    # hair-hair friction 0.2, head friction 0.3, air drag 1e-4 Pa s as the shipped scene, 10 ADMM iterations):
    # the head turns 10 degrees and back (one 2 s cycle from 0.25 s); 5 s after the turn (168 frames) the p90
    # drift from the authored shape is <= 1 mm, and the turn did carry the groom (p90 > 5 mm on the way, in the
    # world frame the drift is measured in: the head is back at its start pose after the cycle).
    # Measured at this size: 0.036 mm at the end, 22.6 mm largest.  At 300 x 24 (BENCHMARKS.md, issue 14):
    # straight 0.04, wavy 0.75, curly 1.08 mm (still settling).  Not claimed:
    # the 40 degree turn of the shipped scene, which reorders strands (2-7 mm stay; BENCHMARKS.md).
    from bench_rest_pose import scene_text

    text = scene_text("wavy", "head_turn").replace("strands = 300", "strands = 60")
    text = text.replace("vertices_per_strand = 24", "vertices_per_strand = 16")
    assert "\namplitude = 40.0" in text
    text = text.replace("\namplitude = 40.0", "\namplitude = 10.0", 1)
    scene = tmp_path / "scene.toml"
    scene.write_text(text)
    out = tmp_path / "turn"
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.run([sys.executable, "-m", "taichi_hair.cli", "simulate", str(scene), "--rest-pose", "sag-free",
                           "--frames", "168", "--out", str(out), "--quiet"],
                          capture_output=True, text=True, timeout=900, env=env, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-2000:]
    with np.load(os.path.join(out, "frames.npz")) as z:
        pos, starts = z["positions"].astype(np.float64), z["strand_vertex_start"]
    free = np.ones(pos.shape[1], bool)
    free[starts] = False
    p90 = np.percentile(np.linalg.norm(pos - pos[0], axis=2)[:, free], 90, axis=1)  # per frame [m]
    assert p90.max() > 5e-3, p90.max()  # the turn moves the groom (the claim below is not vacuous)
    assert p90[-1] <= 1e-3, p90[-1]
