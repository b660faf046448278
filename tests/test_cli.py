"""The command line, run as a user would (subprocesses, headless)."""

import csv
import json
import os
import subprocess
import sys

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def run_cli(*args, timeout=600):
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-m", "taichi_hair.cli", *args], capture_output=True, text=True,
                          timeout=timeout, env=env, cwd=ROOT)


def test_simulate_hang_writes_frames_and_statistics(tmp_path):
    out = tmp_path / "hang"
    proc = run_cli("simulate", "hang", "--strands", "24", "--frames", "6", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    assert "frame" in proc.stdout and "max stretch %" in proc.stdout
    data = np.load(out / "frames.npz")
    pos = data["positions"]
    assert pos.shape[0] == 7 and np.all(np.isfinite(pos))
    starts, counts = data["strand_vertex_start"], data["strand_vertex_count"]
    assert len(starts) == 24 and pos.shape[1] == int(counts.sum())
    # Strands hang: every tip ends below its root, and the motion is non-trivial.
    tips = starts + counts - 1
    assert np.all(pos[-1, tips, 1] < pos[-1, starts, 1])
    assert np.max(np.abs(pos[-1] - pos[0])) > 1e-3
    with open(out / "stats.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 6 and float(rows[-1]["max_stretch_percent"]) < 1.0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["frames"] == 6 and summary["diverged"] is None
    assert summary["model"]["schedule"] == "strand"  # the CPU default under 50,000 vertices (lanes.auto_schedule)


def test_validate_cantilever_small_sweep(tmp_path):
    out = tmp_path / "val"
    proc = run_cli("validate", "cantilever", "--count", "5", "--out", str(out), "--quiet")
    assert proc.returncode == 0, proc.stderr
    with open(out / "cantilever.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0].keys()) == ["length_m", "gamma", "h_over_w", "h_over_w_reference", "rel_error"]
    assert len(rows) == 5
    errors = np.array([float(r["rel_error"]) for r in rows])
    assert np.all(np.abs(errors) < 0.02), errors
    gammas = np.array([float(r["gamma"]) for r in rows])
    assert gammas.min() < 1e-3 and gammas.max() > 1e4
    assert (out / "cantilever.png").stat().st_size > 10000


def test_bad_arguments_give_one_line_errors(tmp_path):
    proc = run_cli("simulate", "hang", "--strands", "0", "--out", str(tmp_path / "x"))
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines()[-1].startswith("error: HangScene.strands")
    proc = run_cli("simulate", "nowhere", "--out", str(tmp_path / "x"))
    assert proc.returncode == 2 and "unknown scene" in proc.stderr


def test_simulate_hairball_runs_with_contacts_and_reports_them(tmp_path):
    out = tmp_path / "hairball"
    proc = run_cli("simulate", "hairball", "--strands", "40", "--length", "0.1", "--frames", "3", "--profile",
                   "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    assert "contacts" in proc.stdout and "stage breakdown" in proc.stdout
    summary = json.loads((out / "summary.json").read_text())
    assert summary["frames"] == 3 and summary["diverged"] is None
    assert summary["max_penetration_m"] < 3.7e-5  # less than one hair radius
    assert "projection" in summary["stage_ms_per_step"] and "detection" in summary["stage_ms_per_step"]
    data = np.load(out / "frames.npz")
    pos = data["positions"]
    assert np.all(np.isfinite(pos))
    # each frame's contact states (render --color contact): 0 free, 1 sticking, 2 sliding; frame 0 before any step
    cst = data["vertex_contact_state"]
    assert cst.shape == pos.shape[:2] and set(np.unique(cst)) <= {0, 1, 2} and not cst[0].any()
    # Roots stay on the ball (radius 9 cm) and no vertex ends inside it by more than the hair radius.
    assert np.linalg.norm(pos[-1], axis=1).min() > 0.09 - 1e-4


def test_unknown_scene_is_one_line_error(tmp_path):
    proc = run_cli("simulate", "nope", "--out", str(tmp_path))
    assert proc.returncode == 2 and "unknown scene" in proc.stderr and "Traceback" not in proc.stderr


HAIRBALL_TOML = os.path.join(ROOT, "assets", "scenes", "hairball.toml")


def test_scene_file_resume_equals_an_uninterrupted_run_bit_for_bit(tmp_path):
    """The shipped hairball scene (12 short strands, 6 fps so that contacts and the ball's turn start within
    5 frames), run straight for 5 frames, or for 2 frames then resumed to 5 from its end-of-run checkpoint.
    The resumed run's ``--profile`` figures are per step of its own 3 frames (they divided by all 5 frames'
    steps before: 0.6x the true figure)."""
    args = ["simulate", HAIRBALL_TOML, "--strands", "12", "--length", "0.15", "--vertices-per-strand", "16",
            "--fps", "6", "--checkpoint-every", "3", "--quiet"]
    split, straight = tmp_path / "split", tmp_path / "straight"
    proc = run_cli(*args, "--frames", "2", "--out", str(split))
    assert proc.returncode == 0, proc.stderr
    # The interrupted run alone: a folder of per-frame files, finite, roots on the ball, nothing inside it.
    pos = np.load(split / "frames.npz")["positions"]
    assert pos.shape == (3, 192, 3) and np.all(np.isfinite(pos))
    from taichi_hair.io import load_groom

    frame2 = load_groom(split / "frames" / "frame_00002.thair.npz")
    assert np.array_equal(frame2.points, pos[2]) and frame2.strand_count == 12
    assert np.linalg.norm(pos[2], axis=1).min() > 0.09 - 1e-4
    proc = run_cli(*args, "--frames", "5", "--out", str(split), "--resume", "--profile")
    assert proc.returncode == 0, proc.stderr
    proc = run_cli(*args, "--frames", "5", "--out", str(straight))
    assert proc.returncode == 0, proc.stderr
    a = np.load(straight / "frames.npz")["positions"]
    b = np.load(split / "frames.npz")["positions"]
    assert a.shape == b.shape == (6, 192, 3)
    assert np.array_equal(a, b)
    assert len(list((split / "frames").glob("frame_*.thair.npz"))) == 6
    summary = json.loads((split / "summary.json").read_text())
    assert summary["resumed_from_frame"] == 2 and summary["frames"] == 5 and summary["diverged"] is None
    assert summary["stage_steps"] == 3 * summary["substeps"] and summary["stage_ms_per_step"]["iterations"] > 0
    with open(split / "stats.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [int(r["frame"]) for r in rows] == [1, 2, 3, 4, 5]
    assert sum(int(r["contacts"]) for r in rows[2:]) > 0  # the resumed part has contacts
    # A checkpoint made for other settings is refused with one line, before anything compiles.
    proc = run_cli(*args, "--frames", "6", "--seed", "5", "--out", str(split), "--resume")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert "made for a different scene or settings (differs in scene.groom" in proc.stderr.strip().splitlines()[-1]


def test_bdf2_resume_equals_an_uninterrupted_run_bit_for_bit(tmp_path):
    """The same hairball with ``--integrator bdf2``: the checkpoint carries the BDF2 history (x_{n-1}, v_{n-1},
    theta_{n-1}, omega_{n-1}, kappa_{n-1}), so the resumed run is the straight one, bit for bit; and the
    history changes the motion (the run differs from backward Euler's)."""
    args = ["simulate", HAIRBALL_TOML, "--strands", "12", "--length", "0.15", "--vertices-per-strand", "16",
            "--fps", "6", "--checkpoint-every", "3", "--quiet", "--integrator", "bdf2"]
    split, straight = tmp_path / "split", tmp_path / "straight"
    for extra, out in ((["--frames", "2"], split), (["--frames", "4", "--resume"], split), (["--frames", "4"], straight)):
        proc = run_cli(*args, *extra, "--out", str(out))
        assert proc.returncode == 0, proc.stderr
    a = np.load(straight / "frames.npz")["positions"]
    b = np.load(split / "frames.npz")["positions"]
    assert a.shape == b.shape == (5, 192, 3) and np.all(np.isfinite(a))
    assert np.array_equal(a, b)
    be = tmp_path / "be"
    proc = run_cli(*args[:-2], "--frames", "4", "--out", str(be))
    assert proc.returncode == 0, proc.stderr
    assert not np.array_equal(np.load(be / "frames.npz")["positions"], a)


def test_scene_file_errors_are_one_line(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('[groom]\ngenerator = "wavy"\nlenght = 0.1\n')
    proc = run_cli("simulate", str(bad), "--out", str(tmp_path / "o"))
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    line = proc.stderr.strip().splitlines()[-1]
    assert line.startswith(f"error: {bad}: [groom]") and "unknown key 'lenght'" in line
    proc = run_cli("simulate", HAIRBALL_TOML, "--out", str(tmp_path / "o"), "--frame-format", "tfxmesh")
    assert proc.returncode == 2 and "read-only" in proc.stderr
    proc = run_cli("simulate", "hang", "--vertices-per-strand", "8", "--out", str(tmp_path / "o"))
    assert proc.returncode == 2 and "TOML scenes" in proc.stderr
    # An absurd w0 overflows the float32 weights: one line naming the field, no frames written.
    proc = run_cli("simulate", HAIRBALL_TOML, "--strands", "4", "--frames", "1", "--set", "solver.w0=1e300",
                   "--out", str(tmp_path / "w0"))
    assert proc.returncode == 2 and "Traceback" not in proc.stderr and "overflow" not in proc.stderr
    assert proc.stderr.strip().splitlines()[-1].startswith("error: SolverADMMConfig.w0 = 1e+300 makes the elasticity")
    assert not (tmp_path / "w0").exists()


def test_the_command_line_switches_numpy_huge_page_advice_off_unless_the_environment_sets_it(monkeypatch):
    """cli.common.no_numpy_huge_pages (applied with ti.init by the command line and the grooming app): NumPy's
    madvise of huge pages goes off, except where the user set NUMPY_MADVISE_HUGEPAGE (then NumPy is left as
    told).  Why it matters (a 29 MB array into new memory: 62-69 ms with the advice, 13-15 ms without, on the
    VM) is in its docstring; this checks the switch, not the speed."""
    from numpy._core import multiarray

    from taichi_hair.cli.common import NUMPY_HUGE_PAGES_ENV, no_numpy_huge_pages

    before = multiarray._get_madvise_hugepage()
    try:
        multiarray._set_madvise_hugepage(True)
        monkeypatch.setenv(NUMPY_HUGE_PAGES_ENV, "1")
        assert no_numpy_huge_pages() is False and multiarray._get_madvise_hugepage() is True
        monkeypatch.delenv(NUMPY_HUGE_PAGES_ENV)
        assert no_numpy_huge_pages() is True and multiarray._get_madvise_hugepage() is False
    finally:
        multiarray._set_madvise_hugepage(before)



def test_the_command_line_keeps_freed_memory_for_the_next_arrays_and_the_environment_can_say_no(tmp_path):
    """cli.common.keep_freed_memory (applied with ti.init by the command line and the grooming app): glibc keeps the
    memory NumPy frees.  In a fresh process, ten 8 MB arrays made, touched and dropped three times: the third
    round's minor page faults are ~every page (80 MB / 4 KiB = 19,531; measured 19,499) with glibc's defaults and
    none with the switch (measured 0; bound: under 5 %).  TAICHI_HAIR_STOCK_MALLOC=1 leaves glibc as it is."""
    import os
    import subprocess
    import sys

    code = ("import resource, sys\nimport numpy as np\n"
            "from taichi_hair.cli.common import keep_freed_memory, no_numpy_huge_pages\n"
            "no_numpy_huge_pages()\napplied = keep_freed_memory()\n"
            "def round_():\n    a = [np.ones(1_000_000) for _ in range(10)]\n    del a\n"
            "round_(); round_()\nf0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt\nround_()\n"
            "print(applied, resource.getrusage(resource.RUSAGE_SELF).ru_minflt - f0)\n")
    out = {}
    for name, extra in (("keep", {}), ("stock", {"TAICHI_HAIR_STOCK_MALLOC": "1"})):
        env = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_")} | extra
        r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
        assert r.returncode == 0, r.stderr[-2000:]
        applied, faults = r.stdout.split()[-2:]
        out[name] = (applied == "True", int(faults))
    pages = 10 * 8_000_000 // 4096
    assert out["keep"][0] and out["keep"][1] < 0.05 * pages
    assert not out["stock"][0] and out["stock"][1] > 0.5 * pages

def test_the_tests_run_under_taichi_hair_init_options(tmp_path):
    """conftest starts Taichi through ``taichi_hair.init``, as the command line does: opt_level 0
    (``TAICHI_INIT_OPTIONS``: Taichi's CFG optimization and whole-kernel CSE off), the precision as given."""
    import taichi as ti

    import taichi_hair as th

    cfg = ti.lang.impl.current_cfg()
    assert th.TAICHI_INIT_OPTIONS == {"opt_level": 0}
    assert cfg.opt_level == 0 and cfg.default_fp == ti.f32
    # The kernel cache's size: the environment's where set (conftest: 2 GiB - 1), else 1 GiB, else the call's.
    assert cfg.offline_cache_max_size_of_files == int(os.environ["TI_OFFLINE_CACHE_MAX_SIZE_OF_FILES"]) == 2**31 - 1
    code = ("import taichi as ti, taichi_hair as th\n"
            "th.init(arch=ti.cpu, log_level=ti.ERROR)\n"
            "a = ti.lang.impl.current_cfg().offline_cache_max_size_of_files\n"
            "th.init(arch=ti.cpu, log_level=ti.ERROR, offline_cache_max_size_of_files=5 << 20)\n"
            "print(a, ti.lang.impl.current_cfg().offline_cache_max_size_of_files)\n")
    env = {k: v for k, v in os.environ.items() if k != "TI_OFFLINE_CACHE_MAX_SIZE_OF_FILES"}
    env["PYTHONPATH"] = ROOT + os.pathsep + env.get("PYTHONPATH", "")
    # A cache folder of its own: with 5 MiB allowed, Taichi would trim the suite's cache (measured: 1.03 GB -> 0.35 GB).
    env["TI_OFFLINE_CACHE_FILE_PATH"] = str(tmp_path / "ticache")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.split()[-2:] == [str(th.OFFLINE_CACHE_BYTES), str(5 << 20)] and th.OFFLINE_CACHE_BYTES == 1 << 30


def test_lighter_kernel_positions_change_no_bit_and_keep_file_and_line_in_compile_errors(tmp_path):
    """cli.common.lighter_kernel_positions (a cheaper Taichi frontend, applied after ti.init): the same run with
    Taichi's own position messages (TAICHI_HAIR_STOCK_POSITIONS=1) gives the same frames, bit for bit; and a
    kernel that fails to compile still names its file, line and code."""
    frames = []
    for stock in ("1", "0"):
        out = tmp_path / f"stock{stock}"
        env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""),
                   TAICHI_HAIR_STOCK_POSITIONS=stock)
        proc = subprocess.run([sys.executable, "-m", "taichi_hair.cli", "simulate", "hang", "--strands", "4",
                               "--frames", "3", "--quiet", "--out", str(out)], capture_output=True, text=True,
                              timeout=600, env=env, cwd=ROOT)
        assert proc.returncode == 0, proc.stderr
        frames.append(np.load(out / "frames.npz")["positions"])
    assert np.array_equal(frames[0], frames[1])
    bad = tmp_path / "bad_kernel.py"
    bad.write_text("import taichi as ti\nfrom taichi_hair.cli.common import lighter_kernel_positions\n"
                   "ti.init(arch=ti.cpu)\nassert lighter_kernel_positions()\nf = ti.field(float, 4)\n\n"
                   "@ti.kernel\ndef k():\n    for i in f:\n        f[i] = undefined_name + 1.0\n\nk()\n")
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""),
               TAICHI_HAIR_STOCK_POSITIONS="0")
    proc = subprocess.run([sys.executable, str(bad)], capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode != 0
    assert f'File "{bad}", line 10, in k' in proc.stderr and "undefined_name + 1.0" in proc.stderr, proc.stderr[-2000:]


def _module_from(path, text: str, name: str):
    import importlib.util

    path.write_text(text)
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


KERNEL_SOURCE = """import taichi as ti

out = ti.field(float, 3)


@ti.func
def twice(v):
    return 2.0 * v{extra}


@ti.kernel
def fill():
    for i in out:
        out[i] = twice(twice(float(i)))
"""


def test_kernel_sources_are_read_once_and_are_the_sources_inspect_reads(tmp_path):
    """taichi_hair.init memoizes Taichi's source reading (``memoize_kernel_sources``): what its frontend gets is what
    ``inspect`` gives (lines and first line number, a fresh list each call), a redefined function is read anew, the
    kernel built from it computes 4 i (twice, inlined twice), and a compile error still names its file and line."""
    import inspect

    import taichi as ti
    from taichi.lang import kernel_impl

    import taichi_hair

    assert taichi_hair.memoize_kernel_sources()  # (applied by the session's taichi_hair.init already)
    assert hasattr(kernel_impl.getsourcelines, "__wrapped__")
    mod = _module_from(tmp_path / "kernels_a.py", KERNEL_SOURCE.format(extra=""), "kernels_a")
    f = mod.twice.func.func
    first = kernel_impl.getsourcelines(f)
    assert first == inspect.getsourcelines(f) and first[1] == 6  # (the decorator's line)
    first[0].append("mutated")
    assert kernel_impl.getsourcelines(f) == inspect.getsourcelines(f)  # (a copy each time)
    assert inspect.getsourcefile(f) == str(tmp_path / "kernels_a.py")
    mod.fill()
    assert np.array_equal(mod.out.to_numpy(), [0.0, 4.0, 8.0])
    # The same name redefined in another file, with another body: read anew.
    mod_b = _module_from(tmp_path / "kernels_b.py", KERNEL_SOURCE.format(extra=" + 1.0"), "kernels_b")
    g = mod_b.twice.func.func
    assert kernel_impl.getsourcelines(g) == inspect.getsourcelines(g) != first
    mod_b.fill()
    assert np.array_equal(mod_b.out.to_numpy(), [3.0, 7.0, 11.0])  # 2 (2 i + 1) + 1
    bad = _module_from(tmp_path / "kernels_c.py", KERNEL_SOURCE.format(extra=" + undefined_name"), "kernels_c")
    with pytest.raises(Exception) as err:
        bad.fill()
    assert "kernels_c.py" in str(err.value) and "line 8" in str(err.value), str(err.value)
    assert ti.lang.impl.current_cfg().opt_level == 0


def test_file_outputs_with_the_same_stem_keep_their_own_sidecars(tmp_path):
    """x.usda and x.thair.npz once shared x.summary.json / x.stats.csv / x.bodies.npz and overwrote each other's:
    the sidecars are named after the whole file name."""
    for out, strands in (("x.usda", "3"), ("x.thair.npz", "5")):
        proc = run_cli("simulate", "hang", "--strands", strands, "--frames", "1", "--quiet", "--out", str(tmp_path / out))
        assert proc.returncode == 0, proc.stderr
    for out, strands in (("x.usda", 3), ("x.thair.npz", 5)):
        summary = json.loads((tmp_path / f"{out}.summary.json").read_text())
        assert summary["strands"] == strands and summary["output"].endswith(out)
        assert (tmp_path / f"{out}.stats.csv").is_file() and (tmp_path / f"{out}.bodies.npz").is_file()
    assert not (tmp_path / "x.summary.json").exists()


SOFT_SCENE = """
[scene]
frames = 3
fps = 24.0
substeps = 2

[groom]
generator = "straight"
surface = "sphere"
sphere_radius = 0.05
strands = 4
length = 0.3
vertices_per_strand = 9

[material]
youngs_modulus_stretch = 2e3   # [Pa]: a millionth of hair's, so the strands stretch under their weight

[solver.contacts]
hair_hair = false
# A soft material keeps its stretch only with "before": the default "rest" makes the end-of-step correction
# hold hair's rest lengths on every edge (measured: with it the p99 strain stayed under the 5 % of --strict).
correction_lengths = "before"

[[colliders]]
type = "sphere"
radius = 0.05
body = 0
"""


def test_simulate_strict_fails_on_a_stretched_run_and_reports_quality(tmp_path):
    # Hanging 30 cm strands with E_s = 2 kPa: the weight below the root, rho g L = 1300 * 9.81 * 0.3 = 3.8 kPa,
    # is above E_s, so the p99 strain passes 5 % within the 3 frames (measured: 62 % at frame 3).
    scene = tmp_path / "soft.toml"
    scene.write_text(SOFT_SCENE)
    proc = run_cli("simulate", str(scene), "--out", str(tmp_path / "o"), "--strict", "--checkpoint-every", "0",
                   "--quiet")
    err = proc.stderr.strip().splitlines()
    assert proc.returncode == 3, proc.stderr
    assert "Traceback" not in proc.stderr
    assert err[-1].startswith("error: --strict: p99 edge strain reached") and "worst strand" in err[-1]
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    q = summary["quality"]
    assert q["strain_p99_max"] > 0.05 and q["vertices_inside_max"] == 0 and q["came_to_rest"] is False
    # Not at rest: vertices above 1 cm/s are counted, and the p99 speed is at most the fastest vertex's.
    assert q["last_frame_vertices_above_rest_speed"] > 0
    assert q["last_frame_speed_p99_m_s"] <= q["last_frame_max_speed_m_s"] * (1 + 1e-6)
    # Each vertex lies on the authored polylines' own course at its authored position, so the shape distance (to the
    # nearest point of the polylines, both ways) is at most the drift (to that one point), percentile by percentile.
    assert 0 <= q["shape_distance_p90_last_m"] <= q["drift_p90_last_m"] * (1 + 1e-9)
    with open(tmp_path / "o" / "stats.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 3 and float(rows[-1]["strain_p99"]) == q["strain_p99_max"]
    # The largest move over the last frame, as a speed: the column of the last row, and not 0 for strands still falling.
    assert float(rows[-1]["max_frame_speed"]) == q["last_frame_max_move_speed_m_s"] > 0.0
    assert "body_penetration_max_m" in rows[0] and "vertices_inside" in rows[0]
