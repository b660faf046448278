"""``taichi-hair simulate GROOM_FILE``: a groom file with its body in one set of units and axes, without a
scene file (:mod:`taichi_hair.scene.groom_file`).

The fixture is a centimetre, z-up groom on a centimetre, z-up sphere mesh: the layout of CT2Hair's and
Blender's exports.  Read with ``units = cm`` and ``up = z`` it must land in metres, y-up, with its roots on
the body, exactly as the scene file with the same keys reads it.
"""

import json
import os
import subprocess
import sys
import warnings

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RADIUS_CM = 9.0


def run_cli(*args, timeout=600):
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-m", "taichi_hair.cli", *args], capture_output=True, text=True,
                          timeout=timeout, env=env, cwd=ROOT)


def z_up(p):
    """y-up (x, y, z) -> the file's z-up (x, -z, y): the inverse of the reader's (x, y, z) -> (x, z, -y)."""
    return np.stack([p[:, 0], -p[:, 2], p[:, 1]], axis=1)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A 12-strand groom (.tfx) and its body as PLY and TressFX .tfxmesh, all in cm, z-up."""
    import trimesh

    from taichi_hair.io import Groom, save_groom

    d = tmp_path_factory.mktemp("groomfile")
    rng = np.random.default_rng(3)
    polys = []
    for _ in range(12):  # roots on the upper cap (y-up), strands 6 cm along the normal, 8 vertices
        n = rng.normal(size=3)
        n[1] = abs(n[1]) + 0.8
        n /= np.linalg.norm(n)
        polys.append(z_up((RADIUS_CM + np.linspace(0.0, 6.0, 8))[:, None] * n[None, :]))
    save_groom(Groom.from_polylines(polys, units="cm"), d / "groom.tfx")
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=RADIUS_CM)
    v = z_up(np.asarray(sphere.vertices))
    trimesh.Trimesh(vertices=v, faces=sphere.faces, process=False).export(d / "body.ply")
    nrm = v / np.linalg.norm(v, axis=1)[:, None]
    rows = [f"{i} {a[0]:.9g} {a[1]:.9g} {a[2]:.9g} {b[0]:.6f} {b[1]:.6f} {b[2]:.6f} 0 0 0 0 1 0 0 0"
            for i, (a, b) in enumerate(zip(v, nrm))]
    tris = [f"{i} {f[0]} {f[1]} {f[2]}" for i, f in enumerate(sphere.faces)]
    (d / "body.tfxmesh").write_text("numOfBones 1\n0 head\nnumOfVertices %d\n%s\nnumOfTriangles %d\n%s\n"
                                    % (len(rows), "\n".join(rows), len(tris), "\n".join(tris)))
    return d


def test_a_cm_z_up_groom_is_read_in_metres_and_y_up(files):
    """points = R (0.01 p_file), R: (x, y, z) -> (x, z, -y); the roots then lie on the 9 cm sphere
    (|root| = 0.09 m to the file's 9-digit precision, bound 1e-6 m)."""
    from taichi_hair.io import load_groom
    from taichi_hair.scene.groom_file import scene_from_groom_file

    scene = scene_from_groom_file(str(files / "groom.tfx"), units="cm", up="z")
    p = np.asarray(load_groom(str(files / "groom.tfx"), scale=0.01).points, np.float64)
    expect = np.stack([p[:, 0], p[:, 2], -p[:, 1]], axis=1)
    np.testing.assert_allclose(scene.groom.points, expect, rtol=0, atol=1e-7)
    roots = np.asarray(scene.groom.points, np.float64)[scene.groom.strand_offsets[:-1]]
    assert np.all(roots[:, 1] > 0)  # on the upper cap: up is +y
    np.testing.assert_allclose(np.linalg.norm(roots, axis=1), RADIUS_CM / 100, atol=1e-6)


def test_the_groom_file_scene_is_the_scene_file_with_the_same_keys(files, tmp_path):
    """Same groom bits, same body SDF, same body transform at t = 0.6 s, same description (so a checkpoint
    of one resumes the other)."""
    from taichi_hair.scene.file import load_scene
    from taichi_hair.scene.groom_file import scene_from_groom_file

    a = scene_from_groom_file(str(files / "groom.tfx"), units="cm", up="z", body=str(files / "body.ply"),
                              animation="nod")
    pivot = a.bodies[0].pivot
    toml = tmp_path / "same.toml"
    toml.write_text(f'''[scene]\nname = "groom"\n[groom]\nfile = "{files / "groom.tfx"}"\nunits = "cm"\nup = "z"
[[colliders]]\ntype = "mesh"\nfile = "{files / "body.ply"}"\nunits = "cm"\nup = "z"\nbody = 0
[[bodies]]\npreset = "nod"\npivot = [{pivot[0]!r}, {pivot[1]!r}, {pivot[2]!r}]\n''')
    b = load_scene(str(toml))
    assert np.array_equal(a.groom.points, b.groom.points)
    assert np.array_equal(a.colliders[0].sdf, b.colliders[0].sdf)
    for (ra, ta), (rb, tb) in zip(a.body_transforms(0.6), b.body_transforms(0.6)):
        assert np.array_equal(ra, rb) and np.array_equal(ta, tb) and not np.allclose(ra, np.eye(3))
    da, db = json.loads(json.dumps(a.description)), json.loads(json.dumps(b.description))
    da["groom"].pop("points_sha1"), db["groom"].pop("points_sha1")
    assert da == db


def test_nod_turns_about_the_neck_the_lowest_point_of_the_body(files):
    """Pivot = (centre x, lowest y, centre z) of the body's box: (0, -0.09, 0) m for the sphere, within
    one SDF voxel (0.18 m x 1.3 / 64 = 3.7 mm) of the analytic point."""
    from taichi_hair.scene.groom_file import scene_from_groom_file

    s = scene_from_groom_file(str(files / "groom.tfx"), units="cm", up="z", body=str(files / "body.ply"),
                              animation="turn")
    np.testing.assert_allclose(s.bodies[0].pivot, [0.0, -0.09, 0.0], atol=3.7e-3)
    assert s.bodies[0].description["preset"] == "head_turn"


def test_a_tfxmesh_body_gives_the_sdf_of_the_same_mesh_as_ply(files):
    """The .tfxmesh holds the PLY's triangles (vertices to 9 digits): SDFs agree to 1e-6 m."""
    from taichi_hair.scene.groom_file import scene_from_groom_file

    kw = dict(units="cm", up="z")
    a = scene_from_groom_file(str(files / "groom.tfx"), body=str(files / "body.ply"), **kw)
    b = scene_from_groom_file(str(files / "groom.tfx"), body=str(files / "body.tfxmesh"), **kw)
    assert b.colliders[0].source.endswith("body.tfxmesh")
    np.testing.assert_allclose(a.colliders[0].sdf, b.colliders[0].sdf, atol=1e-6)


def test_a_body_in_other_units_than_the_hair_warns_instead_of_running_without_contacts(files):
    """The body read in metres (100x the hair's size): no root lies near it, a one-line warning says so."""
    from taichi_hair.scene.groom_file import scene_from_groom_file

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scene_from_groom_file(str(files / "groom.tfx"), units="cm", up="z", body=str(files / "body.ply"),
                              body_units="m")
    text = [str(w.message) for w in caught if "no strand root lies near a collider's surface" in str(w.message)]
    assert len(text) == 1 and "\n" not in text[0] and "units and the up axis" in text[0]


@pytest.mark.parametrize("args, message", [
    (["--animation", "wobble"], "--animation must be one of still, nod, turn"),
    (["--body", "nope.obj"], "nope.obj: no such body mesh"),
    (["--body", "README.md"], "not a body mesh this reads"),
])
def test_bad_groom_file_options_are_one_line_errors(files, args, message):
    proc = run_cli("simulate", str(files / "groom.tfx"), "--units", "cm", "--out", "/tmp/never", *args)
    assert proc.returncode == 2 and message in proc.stderr and "Traceback" not in proc.stderr
    assert not os.path.exists("/tmp/never")


def test_groom_file_options_on_a_scene_file_are_refused():
    proc = run_cli("simulate", "assets/scenes/ponytail.toml", "--units", "cm", "--out", "/tmp/never")
    assert proc.returncode == 2 and "--units applies to a groom file" in proc.stderr


def test_simulate_a_groom_file_on_its_nodding_body_writes_the_posed_body(files, tmp_path):
    """3 frames at 8 fps (the nod starts at 0.25 s): the run ends at rest-level quality (p99 strain
    < 1 %, no vertex inside the body), the frames carry the body's transforms and mesh, and the roots follow
    the body: root(t) = R(t) root(0) + T(t) to f32 rounding (1e-6 m)."""
    out = tmp_path / "o"
    proc = run_cli("simulate", str(files / "groom.tfx"), "--units", "cm", "--up", "z", "--body",
                   str(files / "body.tfxmesh"), "--animation", "nod", "--frames", "3", "--fps", "8", "--out",
                   str(out))
    assert proc.returncode == 0, proc.stderr
    data = np.load(out / "frames.npz")
    pos, R, T = data["positions"], data["body_rotation"], data["body_translation"]
    assert R.shape == (4, 1, 3, 3) and T.shape == (4, 1, 3)
    assert not np.allclose(R[3, 0], np.eye(3))
    roots = data["strand_vertex_start"]
    np.testing.assert_allclose(pos[3][roots], pos[0][roots] @ R[3, 0].T + T[3, 0], atol=1e-6)
    assert data["collider_0_faces"].shape[1] == 3 and int(data["collider_0_body"]) == 0
    q = json.loads((out / "summary.json").read_text())["quality"]
    assert q["strain_p99_max"] < 0.01 and q["vertices_inside_max"] == 0, q


def test_a_usd_body_is_read_in_world_space_with_its_stage_units_and_up_axis(tmp_path):
    """A cube of 2 units (6 quads, fanned into 12 triangles) under an Xform translated by 10 units along z,
    in a stage with metersPerUnit 0.01 and upAxis Z: read in metres and y-up, (x, y, z) -> (x, z, -y), it
    spans x, z in [-0.01, 0.01] and y in [0.09, 0.11], closed (watertight); the stage's units win over the
    scale passed (the groom's)."""
    pytest.importorskip("pxr")
    from pxr import Gf, Usd, UsdGeom

    from taichi_hair.scene.setup import load_body_mesh

    path = str(tmp_path / "cube.usda")
    st = Usd.Stage.CreateNew(path)
    UsdGeom.SetStageMetersPerUnit(st, 0.01)
    UsdGeom.SetStageUpAxis(st, UsdGeom.Tokens.z)
    x = UsdGeom.Xform.Define(st, "/World")
    x.AddTranslateOp().Set(Gf.Vec3d(0, 0, 10))
    m = UsdGeom.Mesh.Define(st, "/World/cube")
    corners = [(-1, -1, -1), (1, -1, -1), (1, 1, -1), (-1, 1, -1), (-1, -1, 1), (1, -1, 1), (1, 1, 1), (-1, 1, 1)]
    m.GetPointsAttr().Set([Gf.Vec3f(*map(float, c)) for c in corners])
    quads = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
    m.GetFaceVertexCountsAttr().Set([4] * 6)
    m.GetFaceVertexIndicesAttr().Set([i for q in quads for i in q])
    st.Save()
    mesh = load_body_mesh(path, scale=1.0, up="y")
    assert len(mesh.faces) == 12 and mesh.is_watertight
    np.testing.assert_allclose(mesh.bounds, [[-0.01, 0.09, -0.01], [0.01, 0.11, 0.01]], atol=1e-9)
    with pytest.raises(ValueError, match="no UsdGeom.Mesh"):
        empty = str(tmp_path / "empty.usda")
        Usd.Stage.CreateNew(empty).Save()
        load_body_mesh(empty)
