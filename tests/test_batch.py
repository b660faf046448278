"""Batches on Dask distributed (issue 18): the spec's runs and sweeps, each run exactly a ``simulate`` run
(frames bit for bit), failures recorded by name without stopping the others, finished runs skipped on a
rerun, and runs whose worker was killed resumed from their checkpoints."""

import csv
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from taichi_hair.scene.batch import read_batch
from taichi_hair.scene.file import SceneError

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
KNOWN = {"strands", "frames", "seed", "iterations", "substeps", "checkpoint_every", "hair_hair", "fps"}


def _spec(tmp_path, text):
    p = tmp_path / "spec.toml"
    p.write_text(text)
    return p


# --------------------------------------------------------------------------- the spec (no Dask)
def test_a_sweep_is_the_cross_product_over_each_named_run(tmp_path):
    """2 named runs x (3 seeds x 2 frictions) = 12 runs; defaults from [batch], a run's own keys over them,
    dotted sweep keys as scene-file sets, names joined from the values."""
    scene = tmp_path / "s.toml"
    scene.write_text("")
    p = _spec(tmp_path, f"""
[batch]
scene = "{scene.name}"
frames = 6
set = {{ "solver.iterations" = 7 }}

[[runs]]
name = "a"
strands = 10

[[runs]]
name = "b"
strands = 20
frames = 3

[sweep]
seed = [0, 1, 2]
"solver.contacts.friction" = [0.1, 0.3]
""")
    runs = read_batch(p, KNOWN)
    assert len(runs) == 12 and len({r.name for r in runs}) == 12
    first = runs[0]
    assert first.name == "a_seed-0_friction-0.1" and first.scene == str(scene)
    assert first.options == {"frames": 6, "strands": 10, "seed": 0}
    assert first.sets == {"solver.iterations": 7, "solver.contacts.friction": 0.1}
    last = runs[-1]
    assert last.name == "b_seed-2_friction-0.3" and last.options == {"frames": 3, "strands": 20, "seed": 2}


@pytest.mark.parametrize("text,message", [
    ('[batch]\nframes = 3\n[[runs]]\nname = "a"', "'scene' is required"),
    ('[batch]\nscene = "hang"\n[[runs]]\nname = "a"\nstrandz = 3', "unknown simulate option 'strandz'"),
    ('[batch]\nscene = "hang"\n[[runs]]\nname = "a"\nout = "x"', "'out' is decided by the batch"),
    ('[batch]\nscene = "hang"\n[[runs]]\nname = "a"\n[[runs]]\nname = "a"', "two runs are named 'a'"),
    ('[batch]\nscene = "hang"\n[[runs]]\nname = "../up"', "'name' must be a folder-safe name"),
    ('[batch]\nscene = "hang"\n[sweep]\nseed = 3', "seed must be a non-empty list"),
    ('[batch]\nscene = "hang"', "no runs"),
    ('[batch]\nscene = "hang"\n[sweep]\nseed = [' + ",".join(map(str, range(200))) + ']\nframes = ['
     + ",".join(map(str, range(1, 101))) + "]", "makes 20,000 runs"),
    ('[batches]\nscene = "hang"', "unknown table 'batches'"),
])
def test_a_bad_spec_is_one_line_naming_the_file_and_key(tmp_path, text, message):
    p = _spec(tmp_path, text)
    with pytest.raises(SceneError) as e:
        read_batch(p, KNOWN)
    assert message in str(e.value) and str(p) in str(e.value) and "\n" not in str(e.value)


def test_simulate_set_changes_a_scene_file_key_and_refuses_a_path_through_a_value(tmp_path):
    from taichi_hair.scene.file import apply_sets, parse_set

    data = {"solver": {"contacts": {"friction": 0.2}}, "colliders": [{"friction": 0.2}]}
    out = apply_sets(data, dict([parse_set("solver.contacts.friction=0.3"), parse_set("colliders.0.friction=0.5"),
                                 parse_set('groom.path="a b.tfx"')]), "s.toml")
    assert out["solver"]["contacts"]["friction"] == 0.3 and out["colliders"][0]["friction"] == 0.5
    assert out["groom"]["path"] == "a b.tfx" and data["solver"]["contacts"]["friction"] == 0.2  # a copy
    with pytest.raises(SceneError, match="solver.contacts.friction is a value, not a table"):
        apply_sets(data, {"solver.contacts.friction.x": 1}, "s.toml")
    with pytest.raises(SceneError, match="name an entry"):
        apply_sets(data, {"colliders.friction": 1}, "s.toml")


# --------------------------------------------------------------------------- on Dask
def _batch(*args, **kw):
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-m", "taichi_hair.cli", "batch", *map(str, args)], env=env,
                          capture_output=True, text=True, timeout=600, **kw)


@pytest.mark.slow
def test_a_batch_runs_each_run_as_simulate_would_records_failures_and_skips_finished_runs(tmp_path):
    pytest.importorskip("distributed")
    from taichi_hair.cli.main import main

    spec = _spec(tmp_path, """
[batch]
scene = "hang"
strands = 3
frames = 2

[[runs]]
name = "good"
seed = 1

[[runs]]
name = "bad"
iterations = 0

[[runs]]
name = "other"
seed = 2
""")
    out = tmp_path / "out"
    proc = _batch(spec, "--out", out, "--workers", "1", "--quiet")
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "failed: bad: SolverADMMConfig.iterations must be an integer >= 1, got 0" in proc.stderr
    with open(out / "batch.csv") as fh:
        rows = {r["name"]: r for r in csv.DictReader(fh)}
    assert rows["good"]["status"] == rows["other"]["status"] == "done" and rows["bad"]["status"] == "failed"
    assert float(rows["good"]["strain_p99_max"]) < 0.01 and int(rows["good"]["frames"]) == 2
    # The groom's drift and shape distance at the end (hanging strands on a body): shape distance <= drift, vertex by vertex.
    assert 0.0 <= float(rows["good"]["shape_distance_p90_last_m"]) <= float(rows["good"]["drift_p90_last_m"])
    meta = json.loads((out / "batch.json").read_text())
    assert [r["name"] for r in meta["runs"]] == ["good", "bad", "other"]
    # the same run through simulate: the same frames, bit for bit
    direct = tmp_path / "direct"
    assert main(["simulate", "hang", "--strands", "3", "--frames", "2", "--seed", "1", "--out", str(direct),
                 "--quiet"]) == 0
    a = np.load(direct / "frames.npz")["positions"]
    b = np.load(out / "good" / "frames.npz")["positions"]
    assert a.shape == b.shape and np.array_equal(a, b)
    # a rerun skips the finished runs and tries the failed one again
    proc = _batch(spec, "--out", out, "--workers", "1", "--quiet")
    assert proc.returncode == 1 and "3 runs, 2 finished earlier, 1 to run" in proc.stdout, proc.stdout


def test_a_pack_steps_its_runs_as_one_model_with_each_runs_own_frames_bit_for_bit(tmp_path, monkeypatch):
    """Three hang runs with other seeds, strand counts and lengths in one task (cli/simulate_pack.py): one
    Model, one solver, one compilation; each run's frames, per-frame quality columns, summary quality and
    model choice are those of the same simulate run alone (bit for bit: nothing couples strands without
    contacts).  The pack (369 vertices) is over the size from which "auto" takes the lanes, set to 300 here, and its
    runs (82-164) are under it: the pack keeps their strand schedule (``pack_schedule``).  Runs with other solver
    settings are not packed: each runs alone, still right."""
    from taichi_hair import lanes
    from taichi_hair.cli.batch import run_argv, run_pack_task, simulate_actions
    from taichi_hair.cli.main import main
    from taichi_hair.scene.batch import BatchRun

    monkeypatch.setattr(lanes, "AUTO_LANES_VERTICES", 300)

    acts = simulate_actions()
    out = str(tmp_path / "out")
    runs = [BatchRun("a", "hang", dict(strands=3, frames=3, seed=0)),
            BatchRun("b", "hang", dict(strands=4, frames=3, seed=1)),
            BatchRun("c", "hang", dict(strands=2, frames=3, seed=2, length=0.15))]
    argvs = [run_argv(r, out, acts) for r in runs]
    res = run_pack_task([r.name for r in runs], argvs)
    assert [r["exit_code"] for r in res] == [0, 0, 0] and all(r["packed_with"] == ["a", "b", "c"] for r in res), res
    for r, argv in zip(runs, argvs):
        solo = str(tmp_path / f"solo_{r.name}")
        assert main([solo if a == os.path.join(out, r.name) else a for a in argv]) == 0
        a, b = np.load(os.path.join(solo, "frames.npz")), np.load(os.path.join(out, r.name, "frames.npz"))
        assert sorted(a.files) == sorted(b.files)
        for k in a.files:
            assert np.array_equal(a[k], b[k]), (r.name, k)
        with open(os.path.join(solo, "stats.csv")) as fa, open(os.path.join(out, r.name, "stats.csv")) as fb:
            ra, rb = list(csv.DictReader(fa)), list(csv.DictReader(fb))
        assert [{k: v for k, v in x.items() if k != "ms"} for x in ra] == [{k: v for k, v in x.items() if k != "ms"}
                                                                          for x in rb]
        sa = json.loads(open(os.path.join(solo, "summary.json")).read())
        sb = json.loads(open(os.path.join(out, r.name, "summary.json")).read())
        assert sa["quality"] == sb["quality"] and sa["model"] == sb["model"] and sb["model"]["schedule"] == "strand"
        assert sb["vertices"] < 300 < sum(json.loads(open(os.path.join(out, n.name, "summary.json")).read())["vertices"]
                                          for n in runs)
        assert sb["pack"]["runs"] == ["a", "b", "c"] and sb["strands"] == r.options["strands"]
        assert os.path.isfile(os.path.join(out, r.name, "batch_done.json"))
    # Other iteration counts: other solver settings, so no pack; each run alone (its own frames still right).
    other = [BatchRun("d", "hang", dict(strands=2, frames=2, seed=0, iterations=5)),
             BatchRun("e", "hang", dict(strands=2, frames=2, seed=0, iterations=10))]
    res = run_pack_task(["d", "e"], [run_argv(r, out, acts) for r in other])
    assert [r["exit_code"] for r in res] == [0, 0] and not any(r.get("packed_with") for r in res), res
    log = open(os.path.join(out, "d", "batch.log")).read()
    assert "note: not packed (PackRefused: " in log and "other solver settings" in log, log


def test_a_pack_takes_its_runs_own_schedule_and_refuses_the_lanes_or_runs_that_disagree(monkeypatch):
    """``cli.simulate_pack.pack_schedule``: "auto" resolves per run (``lanes.auto_schedule``), not on the pack's size;
    runs that would take the lanes alone, or different schedules, are not packed (the lanes group strands by eight
    across runs); an explicit schedule is kept."""
    from taichi_hair import SolverADMMConfig, lanes
    from taichi_hair.cli.simulate_pack import PackRefused, pack_schedule

    monkeypatch.setattr(lanes, "AUTO_LANES_VERTICES", 1000)
    assert pack_schedule(SolverADMMConfig(), [400, 900]) == "strand"
    assert pack_schedule(SolverADMMConfig(schedule="stage"), [400, 5000]) == "stage"
    with pytest.raises(PackRefused, match="lanes schedule steps strands in groups of eight"):
        pack_schedule(SolverADMMConfig(), [1000, 2000])
    with pytest.raises(PackRefused, match="alone the runs take the schedules"):
        pack_schedule(SolverADMMConfig(), [400, 2000])


def test_runs_that_differ_only_in_their_grooms_share_a_pack():
    """pack_groups: seed / strands / length / groom.* / material.* keys leave runs in one group; any other
    option or key makes another; a group is cut into packs that spread the runs over the workers."""
    from taichi_hair.cli.batch import pack_groups
    from taichi_hair.scene.batch import BatchRun

    runs = [BatchRun(f"s{k}", "hang", dict(frames=4, seed=k, strands=3 + k)) for k in range(4)]
    runs += [BatchRun("i5", "hang", dict(frames=4, seed=0, iterations=5)),
             BatchRun("m1", "x.toml", {}, {"material.youngs_modulus": 1e9}),
             BatchRun("m2", "x.toml", {}, {"material.youngs_modulus": 2e9, "groom.seed": 3}),
             BatchRun("f1", "x.toml", {}, {"solver.contacts.friction": 0.1})]
    names = [r.name for r in runs]
    tasks = pack_groups(runs, names, workers=1, pack=0)
    assert tasks == [["s0", "s1", "s2", "s3"], ["i5"], ["m1", "m2"], ["f1"]]
    assert pack_groups(runs, names, workers=4, pack=0)[:2] == [["s0", "s1"], ["s2", "s3"]]  # 8 runs / 4
    assert all(len(t) == 1 for t in pack_groups(runs, names, workers=1, pack=1))


def _descendants(pid):
    import psutil

    return psutil.Process(pid).children(recursive=True)


@pytest.mark.slow
def test_a_killed_worker_and_a_killed_batch_resume_from_their_checkpoints(tmp_path):
    """A 240-frame run checkpointed every 5 frames.  (1) Its worker process is SIGKILLed mid-run: Dask's nanny
    starts a new worker, the task is retried and resumes from the checkpoint; the batch finishes with the run
    done.  (2) The whole batch is SIGKILLed mid-run; the same command again resumes it.  Both give the frames
    of an uninterrupted simulate run, bit for bit."""
    pytest.importorskip("distributed")
    import psutil

    from taichi_hair.cli.main import main

    spec = _spec(tmp_path, """
[batch]
scene = "hang"
strands = 3
frames = 240
checkpoint_every = 5

[[runs]]
name = "long"
""")
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))

    def start(out):
        return subprocess.Popen([sys.executable, "-m", "taichi_hair.cli", "batch", str(spec), "--out", str(out),
                                 "--workers", "1", "--quiet"], env=env, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True, start_new_session=True)

    def wait_for_checkpoint(proc, out):
        ck = out / "long" / "checkpoint.npz"
        end = time.time() + 300
        while not ck.exists():
            assert proc.poll() is None and time.time() < end, proc.communicate()
            time.sleep(0.05)

    direct = tmp_path / "direct"
    assert main(["simulate", "hang", "--strands", "3", "--frames", "240", "--checkpoint-every", "5",
                 "--out", str(direct), "--quiet"]) == 0
    want = np.load(direct / "frames.npz")["positions"]

    # (1) the worker killed
    out1 = tmp_path / "out1"
    proc = start(out1)
    wait_for_checkpoint(proc, out1)
    # the worker: the process the nanny (inside the batch process) spawned; not multiprocessing's resource tracker
    workers = [p for p in _descendants(proc.pid) if "spawn_main" in " ".join(p.cmdline())]
    assert workers, [p.cmdline() for p in _descendants(proc.pid)]
    for p in workers:
        p.send_signal(signal.SIGKILL)
    stdout, stderr = proc.communicate(timeout=600)
    assert proc.returncode == 0, stdout + stderr
    summary = json.loads((out1 / "long" / "summary.json").read_text())
    assert summary["resumed_from_frame"] is not None and summary["resumed_from_frame"] > 0, summary
    assert np.array_equal(np.load(out1 / "long" / "frames.npz")["positions"], want)

    # (2) the whole batch killed, then the same command again
    out2 = tmp_path / "out2"
    proc = start(out2)
    wait_for_checkpoint(proc, out2)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.communicate(timeout=60)
    for p in psutil.process_iter(["cmdline"]):  # nothing of the killed batch is left running
        assert str(out2) not in " ".join(p.info["cmdline"] or []), p.info
    proc = _batch(spec, "--out", out2, "--workers", "1", "--quiet")
    assert proc.returncode == 0 and "1 runs, 0 finished earlier, 1 to run" in proc.stdout, proc.stdout + proc.stderr
    summary = json.loads((out2 / "long" / "summary.json").read_text())
    assert summary["resumed_from_frame"] is not None and summary["resumed_from_frame"] > 0, summary
    assert np.array_equal(np.load(out2 / "long" / "frames.npz")["positions"], want)


@pytest.mark.slow
def test_a_batch_runs_on_an_existing_cluster_through_its_scheduler_address(tmp_path, monkeypatch):
    """--scheduler tcp://...: a cluster started apart (here a LocalCluster of this test process, one worker)
    runs the same runs; the frames equal those of a LocalCluster batch, bit for bit."""
    pytest.importorskip("distributed")
    import logging

    from distributed import LocalCluster

    spec = _spec(tmp_path, '[batch]\nscene = "hang"\nstrands = 3\nframes = 2\n[sweep]\nseed = [0, 1]\n')
    monkeypatch.setenv("PYTHONPATH", ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))  # for the workers
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None,
                      silence_logs=logging.ERROR) as cluster:
        proc = _batch(spec, "--out", tmp_path / "remote", "--scheduler", cluster.scheduler_address, "--quiet")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    proc = _batch(spec, "--out", tmp_path / "local", "--workers", "1", "--quiet")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    for name in ("sweep_seed-0", "sweep_seed-1"):
        a = np.load(tmp_path / "remote" / name / "frames.npz")["positions"]
        b = np.load(tmp_path / "local" / name / "frames.npz")["positions"]
        assert np.array_equal(a, b)
