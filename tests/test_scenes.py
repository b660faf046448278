"""TOML scene files (taichi_hair.scene.file) and the shipped scenes.

The command-line runs are subprocesses, as a user runs them.  The hairball scene runs (and is resumed) in
``tests/test_cli.py``, to keep each file's time down (Taichi compiles the kernels in every run).
"""

import glob
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest

from taichi_hair.rotation import euler_to_matrix, quat_from_matrix_np, quat_slerp_np, quat_to_matrix_np
from taichi_hair.scene.file import SceneError, load_scene

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = os.path.join(ROOT, "assets", "scenes")
SHIPPED = sorted(glob.glob(os.path.join(SCENES, "*.toml")))
SMALL = ["--strands", "12", "--frames", "2"]


def run_cli(*args, timeout=600):
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-m", "taichi_hair.cli", *args], capture_output=True, text=True,
                          timeout=timeout, env=env, cwd=ROOT)


def write(tmp_path, text, name="s.toml"):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


# --------------------------------------------------------------------------- parsing (no kernels)
def test_shipped_scenes_parse():
    names = {os.path.basename(p) for p in SHIPPED}
    assert {"head_turn.toml", "hairball.toml", "ponytail.toml"} <= names
    head = load_scene(os.path.join(SCENES, "head_turn.toml"))
    assert head.groom.strand_count == 300 and head.solver == "admm" and head.frames == 72
    assert type(head.colliders[0]).__name__ == "MeshCollider" and head.colliders[0].watertight
    assert head.solver_config.contacts is not None
    pony = load_scene(os.path.join(SCENES, "ponytail.toml"))
    assert pony.groom.strand_count == 255 and pony.groom.vertex_count == 255 * 16  # tail.tfx
    assert 0.15 < np.median(pony.groom.lengths()) < 0.4  # metres after scale = 0.0035
    assert len(pony.colliders) == 3
    assert pony.solver_config.contacts is not None and pony.solver_config.contacts.hair_hair
    ball = load_scene(os.path.join(SCENES, "hairball.toml"), {"strands": 7, "frames": 3, "iterations": 4})
    assert ball.groom.strand_count == 7 and ball.frames == 3 and ball.solver_config.iterations == 4
    assert np.allclose(np.linalg.norm(ball.groom.points[ball.groom.strand_offsets[:-1]], axis=1), 0.0905,
                       atol=1e-3)


def test_errors_name_file_table_and_key(tmp_path):
    groom = '[groom]\ngenerator = "straight"\nsurface = "sphere"\nstrands = 3\n'
    cases = [
        (groom + "[scene]\nframez = 3\n", r"\[scene\].*unknown key 'framez'"),
        (groom + "[scene]\nframes = 0\n", r"\[scene\] frames: must be >= 1"),
        (groom + "[scene]\nfps = \"fast\"\n", r"\[scene\] fps: expected a finite number"),
        ("[groom]\ngenerator = \"frizzy\"\n", r"\[groom\] generator: must be one of straight, wavy, curly"),
        ("[groom]\nfile = \"nowhere.hair\"\n", r"\[groom\] file: no such file"),
        ('[groom]\ngenerator = "wavy"\nlenght = 0.1\n', r"\[groom\].*unknown key 'lenght'"),
        ('[groom]\ngenerator = "wavy"\nlength = -1.0\n', r"\[groom\].*GeneratorConfig.length"),
        (groom + "[material]\nyoungs_modulus_bend = -3.0\n", r"\[material\].*RodMaterial.youngs_modulus_bend"),
        (groom + "[solver]\ntype = \"magic\"\n", r"\[solver\] type: must be one of admm, shape, xpbd"),
        (groom + "[solver]\niterations = 0\n", r"\[solver\].*SolverADMMConfig.iterations"),
        (groom + "[solver.contacts]\nfriction = -1.0\n", r"\[solver.contacts\].*ContactConfig.friction"),
        (groom + "[[colliders]]\ntype = \"cube\"\n", r"\[colliders 0\] type: must be one of"),
        (groom + "[[colliders]]\ntype = \"sphere\"\nradius = 0.1\ncolour = 1\n",
         r"\[colliders 0\].*unknown key 'colour'"),
        (groom + "[[colliders]]\ntype = \"sphere\"\nbody = 3\n", r"\[colliders 0\] body: 3 is not a body"),
        (groom + "[[bodies]]\npreset = \"spin\"\n", r"\[bodies 0\] preset: must be one of"),
        (groom + "[[bodies]]\nkeys = [{time = 1.0}, {time = 0.5}]\n", r"\[bodies 0.keys\[1\]\] time: times must"),
        (groom + "[[bodies]]\nkeys = [{time = 0.0, euler = [0, 1]}]\n", r"\[bodies 0.keys\[0\]\] euler: expected"),
        (groom + "[extras]\na = 1\n", r"unknown table or key 'extras'"),
        (groom + "[solver]\ntype = \"xpbd\"\n[[colliders]]\ntype = \"plane\"\n", r"\"xpbd\" has no collisions"),
        ("[scene]\nframes = 3\n", r"missing table \[groom\]"),
        ("[groom\n", r"not valid TOML"),
    ]
    for text, pattern in cases:
        p = write(tmp_path, text)
        with pytest.raises(SceneError, match=pattern) as info:
            load_scene(p)
        assert str(info.value).startswith(p) and "\n" not in str(info.value), str(info.value)


def test_file_groom_units_subsampling_and_radius(tmp_path):
    from taichi_hair.io import Groom, save_groom

    polys = [np.c_[np.zeros(5), -np.linspace(0, 10, 5), np.full(5, float(s))] for s in range(10)]
    save_groom(Groom.from_polylines(polys, radius=np.linspace(1, 2, 10) * 1e-3), tmp_path / "g.hair")
    s = load_scene(write(tmp_path, '[groom]\nfile = "g.hair"\nunits = "cm"\nstrands = 4\n'))
    assert s.groom.strand_count == 4 and np.allclose(s.groom.lengths(), 0.1)
    assert np.allclose(s.groom.points[s.groom.strand_offsets[:-1], 2], [0.0, 0.03, 0.06, 0.09])
    with pytest.raises(SceneError, match="give 'scale' or 'units', not both"):
        load_scene(write(tmp_path, '[groom]\nfile = "g.hair"\nunits = "cm"\nscale = 0.01\n'))
    with pytest.raises(SceneError, match="--length applies to generated grooms"):
        load_scene(write(tmp_path, '[groom]\nfile = "g.hair"\n'), {"length": 0.2})


def test_keyframes_slerp_smooth_linear_and_pivot(tmp_path):
    text = ('[groom]\ngenerator = "straight"\nsurface = "sphere"\nstrands = 2\n'
            '[[bodies]]\ninterpolation = "linear"\npivot = [0.0, 0.1, 0.0]\n'
            'keys = [{time = 0.0}, {time = 1.0, euler = [0, 90, 0], translation = [0.2, 0, 0]}]\n'
            '[[bodies]]\nkeys = [{time = 0.0}, {time = 1.0, quaternion = [0.0, 1.0, 0.0, 0.0]}]\n')
    s = load_scene(write(tmp_path, text))
    assert s.body_count == 2
    (R, T), _ = s.body_transforms(0.5)
    assert np.allclose(R, euler_to_matrix((0, 45, 0)), atol=1e-12)  # slerp halfway: 45 degrees
    pivot = np.array([0.0, 0.1, 0.0])
    assert np.allclose(R @ pivot + T, pivot + [0.1, 0, 0])  # the pivot only translates
    (R1, _), _ = s.body_transforms(2.0)  # held after the last key
    assert np.allclose(R1, euler_to_matrix((0, 90, 0)))
    # Smooth (default): a 180 degree turn about x eases in: a quarter of the way in time is less than a quarter
    # of the angle (smoothstep(0.25) = 0.15625), and it is symmetric about the middle.
    _, (Rs, _) = s.body_transforms(0.25)
    assert math.isclose(math.degrees(math.acos(Rs[1, 1])), 180 * 0.15625, rel_tol=1e-9)
    # The file's quaternion is (w, x, y, z) (a turn about x above); the description (the checkpoint
    # fingerprint) keeps that order, the Keyframe holds taichi_hair.rotation's (x, y, z, w).
    assert s.bodies[1].description["keys"][1][1] == [0.0, 1.0, 0.0, 0.0]
    assert np.array_equal(s.bodies[1].keys[1].rotation, [1.0, 0.0, 0.0, 0.0])
    q = quat_from_matrix_np(euler_to_matrix((10, 20, 30)))
    assert np.allclose(quat_to_matrix_np(q), euler_to_matrix((10, 20, 30)))
    assert np.allclose(quat_slerp_np([0, 0, 0, 1], q, 1.0), q)


def test_presets_head_turn_and_nod_reach_their_amplitude(tmp_path):
    text = ('[groom]\ngenerator = "straight"\nsurface = "sphere"\nstrands = 2\n'
            '[[bodies]]\npreset = "head_turn"\namplitude = 30.0\nperiod = 2.0\nstart = 0.5\n'
            '[[bodies]]\npreset = "nod"\n[[bodies]]\npreset = "hairball"\n')
    s = load_scene(write(tmp_path, text))

    def yaw(t):
        R = s.body_transforms(t)[0][0]
        return math.degrees(math.atan2(R[0, 2], R[0, 0]))

    assert yaw(0.0) == 0.0 and yaw(0.5) == 0.0
    assert math.isclose(yaw(1.0), 30.0, abs_tol=1e-9) and math.isclose(yaw(2.0), -30.0, abs_tol=1e-9)
    assert abs(yaw(2.5)) < 1e-9
    R_nod = s.body_transforms(0.25 + 1.5 / 4)[1][0]
    assert math.isclose(math.degrees(math.atan2(R_nod[2, 1], R_nod[1, 1])), 15.0, abs_tol=1e-9)
    from taichi_hair.scene.builtin import hairball_rotation

    assert np.array_equal(s.body_transforms(1.3)[2][0], hairball_rotation(1.3))


# --------------------------------------------------------------------------- shipped scenes, headless
@pytest.mark.parametrize("name", ["head_turn", "ponytail"])
def test_shipped_scene_runs_headless(tmp_path, name):
    path = os.path.join(SCENES, f"{name}.toml")
    extra = [] if name == "ponytail" else ["--vertices-per-strand", "16"]
    out = {"head_turn": tmp_path / "ht.usda", "ponytail": tmp_path / "pt.thair.npz"}[name]
    proc = run_cli("simulate", path, *SMALL, *extra, "--out", str(out), "--quiet")
    assert proc.returncode == 0, proc.stderr
    over = {"strands": 12, "frames": 2}
    if extra:
        over["vertices_per_strand"] = 16
    scene = load_scene(path, over)
    from taichi_hair.io import load_groom

    g = load_groom(out)  # USD time samples, or the native format with every frame
    pos = g.point_frames
    assert np.array_equal(g.frame_times, [0.0, 1.0, 2.0])
    summary = json.loads(open(str(out) + ".summary.json").read())
    assert pos.shape == (3, 12 * 16, 3) and np.all(np.isfinite(pos))
    assert summary["frames"] == 2 and summary["diverged"] is None
    # Roots (first two vertices of each strand) follow body 0's transform at the end of frame 2.
    R, T = scene.body_transforms(2 / scene.fps)[0]
    roots = scene.groom.points[scene.groom.strand_offsets[:-1]]
    got = pos[2][np.arange(12) * 16]
    np.testing.assert_allclose(got, roots @ R.T + T, atol=2e-6)
    # Hair moved, and no vertex is inside a sphere collider by more than a hair radius.
    assert np.max(np.abs(pos[2] - pos[0])) > 1e-5
    for c in scene.colliders:
        if hasattr(c, "center"):
            centre = R @ c.center + T
            assert np.linalg.norm(pos[2] - centre, axis=1).min() > c.radius - 1e-4


def test_shape_and_xpbd_solver_tables(tmp_path):
    from taichi_hair.solvers.shape.solver import SolverShapeConfig
    from taichi_hair.solvers.xpbd.solver import SolverXPBDConfig

    groom = '[groom]\ngenerator = "straight"\nsurface = "sphere"\nstrands = 3\n'
    s = load_scene(write(tmp_path, groom + '[solver]\ntype = "shape"\nmethod = 1\n[solver.region]\n'
                                           'global_stiffness = 0.4\n[[colliders]]\ntype = "sphere"\nbody = 0\n'))
    assert isinstance(s.solver_config, SolverShapeConfig) and s.solver_config.method == 1
    assert s.solver_config.regions[0].global_stiffness == 0.4 and len(s.colliders) == 1
    # Every collider kind is accepted (SolverShape takes the colliders of taichi_hair.contact.colliders).
    s = load_scene(write(tmp_path, groom + '[solver]\ntype = "shape"\n[[colliders]]\ntype = "plane"\n'))
    assert type(s.colliders[0]).__name__ == "PlaneCollider" and not hasattr(s.solver_config, "colliders")
    with pytest.raises(SceneError, match=r"\[solver.region\].*ShapeRegion.damping"):
        load_scene(write(tmp_path, groom + '[solver]\ntype = "shape"\n[solver.region]\ndamping = 2.0\n'))
    # ``simulate --schedule`` (an ADMM launch schedule) is refused for another solver, and set for ADMM.
    with pytest.raises(SceneError, match=r'--schedule applies to type = "admm", not \'shape\''):
        load_scene(write(tmp_path, groom + '[solver]\ntype = "shape"\n'), {"schedule": "lanes"})
    assert load_scene(write(tmp_path, groom), {"schedule": "lanes"}).solver_config.schedule == "lanes"
    s = load_scene(write(tmp_path, groom + '[solver]\ntype = "xpbd"\nsubsteps = 30\n'), {"iterations": 2})
    assert isinstance(s.solver_config, SolverXPBDConfig) and s.solver_config.substeps == 30
    assert s.solver_config.iterations == 2


def test_shape_scene_with_a_mesh_collider_keeps_the_hair_out_of_the_head(tmp_path):
    """A "shape" scene with the head mesh as collider on a turning body: after every step of half a
    second no free vertex is inside the head by the reference signed distance (the generator's own
    96^3 SDF of assets/head.obj, another grid than the collider's 64^3), within 0.1 mm; without the
    collider, the same hair sinks centimetres into the head (so the check can fail)."""
    from taichi_hair.groom.generators import load_head

    head = os.path.join(ROOT, "assets", "head.obj")
    text = ('[scene]\nfps = 24.0\nsubsteps = 4\n'
            '[groom]\ngenerator = "straight"\nsurface = "head"\nstrands = 30\nlength = 0.2\n'
            'vertices_per_strand = 12\nseed = 3\n'
            '[solver]\ntype = "shape"\n[solver.region]\nglobal_stiffness = 0.0\nlocal_stiffness = 0.1\n'
            'length_iterations = 4\n'
            f'[[colliders]]\ntype = "mesh"\nfile = "{head}"\nbody = 0\nfriction = 0.3\nresolution = 64\n'
            '[[bodies]]\npreset = "head_turn"\namplitude = 40.0\nperiod = 1.0\nstart = 0.0\n')
    path = write(tmp_path, text)
    reference = load_head().sdf
    deepest = {}
    for with_head in (True, False):
        scene = load_scene(path)
        if not with_head:
            scene.colliders = []
        model = scene.build_model()
        solver = scene.make_solver(model)
        assert (solver.colliders is not None) == with_head
        state, control = model.state(), model.control()
        free = model.host["vertex_is_fixed"] == 0
        dt = 1.0 / (scene.fps * scene.substeps)
        worst = np.inf
        for k in range(1, 49):
            for b, (R, T) in enumerate(scene.body_transforms(k * dt)):
                control.set_body_transform(b, R, T)
            solver.step(state, control, dt)
            R, T = scene.body_transforms(k * dt)[0]
            x = state.positions().astype(np.float64)[free]
            worst = min(worst, float(reference((x - T) @ R).min()))  # head (body) frame: R^T (x - T)
        deepest[with_head] = worst
        assert np.max(np.abs(x - model.host["vertex_rest_position"][free])) > 0.02  # the hair moved
        if with_head:  # and it rests on the collider's own SDF a hair radius out, within 0.1 mm
            hair = min(m.radius for m in model.materials)
            assert solver.colliders.distance_numpy(x, control).min() > hair - 1e-4
    assert deepest[True] > -1e-4, deepest
    assert deepest[False] < -1e-2, deepest


def test_progress_lines_when_not_a_terminal():
    import io

    from taichi_hair.progress import Progress, format_seconds

    buf = io.StringIO()
    bar = Progress(10, initial=4, stream=buf, interval=1e9)
    for f in range(5, 11):
        bar.update(f, contacts=f * 3)
    bar.close()
    lines = buf.getvalue().splitlines()
    assert len(lines) == 2  # the first update, then the last (interval not reached in between)
    assert lines[0].startswith("frames 5/10 [") and "contacts 15" in lines[0] and "eta" in lines[0]
    assert lines[1].startswith("frames 10/10 [" + "#" * 24 + "] 100%") and "contacts 30" in lines[1]
    assert format_seconds(3725) == "1:02:05" and format_seconds(65) == "1:05"
    quiet = io.StringIO()
    Progress(3, stream=quiet, enabled=False).update(3)
    assert quiet.getvalue() == ""


def _hair_sized_groom(unit: float):
    """20 strands of 20 cm with roots spread over a 20 cm square, in a file unit (1 m = 1 / unit)."""
    from taichi_hair.io import Groom

    polys = [np.c_[np.full(5, 0.2 * (s % 5) / 4), -np.linspace(0, 0.2, 5), np.full(5, 0.2 * (s // 5) / 3)] / unit
             for s in range(20)]
    return Groom.from_polylines(polys)


@pytest.mark.parametrize("unit, name, factor", [(0.01, "cm", "0.01"), (0.001, "mm", "0.001")])
def test_scene_file_groom_in_cm_or_mm_read_as_metres_warns_with_the_unit(tmp_path, unit, name, factor):
    # A 20 cm groom saved in centimetres (lengths 20) or millimetres (200) and read as metres: the warning
    # names the unit and the factor (for millimetres the old hint said 0.01, 10x off), and the scene's
    # own keys to fix it; with the unit given, no unit warning.
    import warnings

    from taichi_hair.io import UnitsWarning, save_groom

    save_groom(_hair_sized_groom(unit), tmp_path / "g.hair")
    with pytest.warns(UnitsWarning, match=rf'g\.hair.*set units = "{name}" \(or scale = {factor}\) in \[groom\]'):
        load_scene(write(tmp_path, '[groom]\nfile = "g.hair"\n'))
    with warnings.catch_warnings():
        warnings.simplefilter("error", UnitsWarning)
        s = load_scene(write(tmp_path, f'[groom]\nfile = "g.hair"\nunits = "{name}"\n'))
    assert np.allclose(s.groom.lengths(), 0.2, rtol=1e-6)
    if name == "mm":  # a scale that leaves the groom 100x too large (20 m) is caught, with the total factor
        with pytest.warns(UnitsWarning, match=r"read with scale 0\.1\).*set scale = 0\.001 in \[groom\]"):
            load_scene(write(tmp_path, '[groom]\nfile = "g.hair"\nscale = 0.1\n'))
