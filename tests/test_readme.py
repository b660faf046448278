"""The README's examples run on a clean clone, in the README's order, at a small size.

Every ``taichi-hair`` line of every ```bash block is run as the README writes it, with these reductions
(so the whole file runs in a few minutes): ``--strands`` at most 12 (added where absent), ``--frames`` 2
for simulate (and ``0:2`` for render, ``--frame`` at most 2), ``--count`` 2, ``--turntable`` 2,
render and groom images 64 x 48, variants with 1 action and 1 frame; ``out/...`` paths go to a temporary
folder.  Lines that cannot run here are parsed, not run, with the reason:

* ``taichi-hair groom`` without ``--offscreen`` opens the window (needs a display);
* ``validate`` and ``bench`` take minutes at any size the commands offer; their own tests run them small
  (tests/test_validation*.py, tests/test_bench*.py).

The ```python blocks run as one script in a child process (they continue each other).
"""

import os
import re
import shlex
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
README = os.path.join(ROOT, "README.md")
NOT_RUN = {"validate": "minutes at any size; tests/test_validation*.py run it small",
           "bench": "minutes at any size; tests/test_bench*.py run it small"}


def blocks(kind: str) -> list:
    text = open(README).read()
    return re.findall(r"```" + kind + r"\n(.*?)```", text, flags=re.S)


def commands() -> list:
    out = []
    for b in blocks("bash"):
        for line in b.splitlines():
            line = line.split("  #")[0].split(" # ")[0].strip()
            if "taichi-hair " not in line:
                continue
            out.append(line[line.index("taichi-hair "):])
    return out


def _set(argv, flag, value, add=True):
    if flag in argv:
        argv[argv.index(flag) + 1] = value
    elif add:
        argv += [flag, value]


def reduce(argv: list, tmp: str) -> list:
    """The README's command at a small size, its out/ paths under ``tmp``."""
    argv = [os.path.join(tmp, a) if a.startswith("out/") else a for a in argv]
    cmd = argv[0]
    if "--strands" in argv:
        i = argv.index("--strands") + 1
        argv[i] = str(min(int(argv[i]), 12))
    if cmd == "simulate":
        _set(argv, "--frames", "2")
        if "--strands" not in argv:
            argv += ["--strands", "12"]
        argv.append("--quiet")
    elif cmd == "render":
        _set(argv, "--frames", "0:2", add=False)
        if "--frame" in argv:  # the frames kept: 0, 1, 2
            i = argv.index("--frame") + 1
            argv[i] = str(min(int(argv[i]), 2))
        _set(argv, "--turntable", "2", add=False)
        _set(argv, "--size", "64", add=False)
        if "--size" not in argv:
            argv += ["--size", "64", "48"]
        argv.append("--quiet")
    elif cmd == "groom":
        argv += ["--strands", "12", "--size", "64", "48", "--iterations", "3"]
    elif cmd == "batch":
        _set(argv, "--workers", "1")
        argv.append("--quiet")
    elif cmd == "variants":
        _set(argv, "--count", "2")
        argv += ["--actions", "1", "--frames", "1", "--thumbnail", "32", "32", "--strands", "12"]
    return argv


def test_the_readme_names_commands_and_every_file_they_read_ships():
    cmds = commands()
    assert len(cmds) >= 20, cmds
    for c in cmds:
        for a in shlex.split(c):
            if a.startswith(("assets/", "benchmarks/")):
                assert os.path.exists(os.path.join(ROOT, a)), (c, a)


def test_every_readme_command_runs_at_a_small_size(tmp_path):
    from taichi_hair.cli.main import build_parser

    parser = build_parser()
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    ran = 0
    for line in commands():
        argv = shlex.split(line)[1:]
        parser.parse_args(argv)  # every line parses, run or not
        if argv[0] in NOT_RUN or (argv[0] == "groom" and "--offscreen" not in argv):
            continue
        if argv[0] == "batch" and "--scheduler" in argv:  # needs a cluster: tests/test_batch.py starts one
            continue
        small = reduce(argv, str(tmp_path))
        proc = subprocess.run([sys.executable, "-m", "taichi_hair.cli", *small], cwd=ROOT, env=env,
                              capture_output=True, text=True, timeout=900)
        assert proc.returncode == 0, (line, small, proc.stderr[-2000:])
        assert "Traceback" not in proc.stderr, (line, proc.stderr[-2000:])
        ran += 1
    assert ran >= 15


def test_the_readme_python_blocks_run_in_order(tmp_path):
    code = "\n".join(blocks("python"))
    assert "th.init(arch=ti.cpu)" in code
    script = tmp_path / "readme.py"
    script.write_text(code)
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.run([sys.executable, str(script)], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=900)
    assert proc.returncode == 0, proc.stderr[-3000:]


if __name__ == "__main__":  # pragma: no cover - print what would run
    for c in commands():
        print(c)
    pytest.main([__file__])
