"""Speed against accuracy (issue 4, item 4): ``taichi-hair bench pareto --out DIR``.

Three scenes, every method over its knobs, cost against error, the Pareto front marked.

Scenes (hair of Daviet 2023 Fig. 2 unless stated; no contacts in any scene):

* ``cantilever``: 6 rods from 1 to 30 cm (2.5 mm edges, at least 16), clamped horizontally
  and released under gravity with a damping of 8 /s (velocity relaxation rate, the same for
  every method, see :mod:`taichi_hair.bench.stability`), 1.5 s simulated.  Error: the largest
  distance between a rod's tip and the heavy elastica's tip at the rod's Gamma, over the rod
  length (analytic reference, :mod:`taichi_hair.validation.elastica`).
* ``swing``: one 40 cm strand, 80 edges, released from horizontal, swinging for 1 s with a
  light damping of 0.5 /s.  Error: RMS over 48 sample times (every 1/48 s) and all vertices of
  |x - x_ref|, over the strand length.
* ``groom``: 192 wavy strands (20 cm, 20 edges, a 3 mm sine of 4 cm wavelength in their rest
  shape), rooted on the upper half of a 9 cm sphere and sticking out from it, under a head
  shake (rotation about the vertical, 0.4 sin(2 pi 1.5 t) rad), damping 0.5 /s, 0.5 s.  Error
  as for the swing.  There is no head collider: hair goes through the sphere in every method
  alike (the contact solvers differ between methods and are not what this chart measures).

Reference for ``swing`` and ``groom``: SolverADMM in double precision (its own process:
``ti.init`` precision is per process), w0 = 25, 50 iterations per step, run at dt = 1/1920 and
1/3840 s and Richardson-extrapolated (2 x_fine - x_coarse: backward Euler is first order in dt).
The difference between the two runs (the fine run's own first-order error) is written in
``pareto.json`` and drawn as a dotted line; the extrapolation removes most of it, but its
remaining error is not measured.  Choices measured on the swing (f64, ``/tmp`` scripts, figures
kept here): w0 = 1 is NOT usable for a reference: at 100 iterations and dt = 1/7680 s its
edges stretched by 2 % and its trajectory left the others by 20 % of L (the weight set from
bending becomes negligible against M/dt^2, and ADMM stalls); with w0 = 25 the runs at 1/960,
1/1920, 1/3840 s differ by 1.0 % and 0.59 % (first order), and 50 iterations differ from 100
by 0.12 % at 1/3840 s.

Methods and knobs (default grid; ``--full`` adds more):

* ``admm`` (w0 = 25, the paper's), ``admm_w1`` (w0 = 1, plain), ``admm_aa`` (w0 = 1,
  Anderson acceleration from 10 iterations: the default on these straight rods) and ``admm_bdf2`` (w0 = 1, BDF2, plain): dt in
  {1/96, 1/384} s x iterations in {5, 10, 30};  ``admm_f64``: w0 = 1 in double precision (the precision
  knob), dt = 1/96 s, iterations in {10, 30}, run in the reference's process.
* ``shape``: SolverShape Method 1, 2 and 3 (TressFX defaults for the shape stiffnesses) x
  local/length iterations in {2, 10} at dt = 1/96 s, and Method 2 with 10 iterations at 1/384 s.
* ``xpbd``: SolverXPBD, dt = 1/96 s, substeps in {5, 20, 80}, one sweep each.

Cost: wall seconds per simulated second per 1,000 vertices, on the arch in use, measured after a
warm-up step (kernel compilation excluded), one run each: on the shared 2-core VM figures move by
up to 2x with the load.  Error of a run with non-finite values: infinite (plotted at the top,
never on the front).

The measured data are copied to ``taichi_hair/bench/data/pareto_cpu.csv`` (with the machine in
``pareto_cpu.json``) so that the method choice of issue 4 item 6 can read them;
``taichi-hair bench pareto --out DIR --update-data`` re-measures and replaces them.

Findings, honestly (default grid, ``taichi-hair bench pareto --out benchmarks/results/pareto``, commit
c7c25fa, 2026-12-03 22:19-22:25 UTC, the current defaults (Anderson mixing on straight rods without contacts),
2-core VM, load 0.0 at the start, 364 s in all, 189 s of it the groom reference; the shipped
``data/pareto_cpu.csv`` is this run's ``pareto.csv``; costs are one run each and noisy by up to ~2x; errors at
10 iterations):

* ``cantilever`` (analytic error; straight rods, so the default mixes): ``admm_aa`` 0.25 % at dt = 1/96 s
  (0.13 % with 30 iterations, the best point), the plain w0 = 1 iteration 1.9 % (0.17 % at 1/384 s with
  30), BDF2 2.4 %, the paper's w0 = 25 52 % (it has not settled in 1.5 s).  SolverShape and XPBD are at
  best 76 % and 80 % of L off (no bending stiffness / too few substeps).
* ``swing`` (reference self-difference 0.57 %): BDF2 owns the front: 3.1 % at dt = 1/96 s, 0.57 % at
  1/384 s with 30 iterations, against backward Euler's 9.5 % (``admm_aa``) / 9.7 % (plain) and 4.2 % at
  1/384 s (its numerical damping of the swing, a time-step error that no iteration count removes), and
  XPBD's 2.7 % with 80 substeps per 1/96 s step.
* ``groom`` (wavy strands, so the twist is solved and the default runs plain; reference self-difference
  3.9 %, so errors below ~4 % cannot be told apart): SolverShape at the cheap end (51 %), plain ADMM at
  1/96 s with 5 iterations (16 %), then BDF2: 8.3 % at 1/96 s, 6.2 % at 1/384 s; backward Euler 16.2 %
  (plain) / 15.5 % (``admm_aa`` forced), XPBD 8.3 % with 80 substeps.
* The precision knob: ADMM in f64 gives the same errors as f32 at the same knobs (f32 is not the limit).
* The default integrator stays backward Euler: BDF2 is unstable with 2 iterations and, on uneven edges,
  with 10 iterations at dt = 1/96 s (:mod:`taichi_hair.bench.stability`); ``--max-error`` method choice
  may pick it for scenes without contacts, where it was measured.

Cost is per 1,000 vertices; the swing scene has 81 vertices, so its costs carry the per-step
Python and launch overhead (about 10x the per-vertex cost of the groom).

Code: the scenes, the method knobs and the timed runs are :mod:`taichi_hair.bench.pareto_runs`; the
measured points, the front, the CSV files and the choice from them :mod:`taichi_hair.bench.pareto_data`;
this module scores the runs (error measures, assembly into points), runs the f64 worker in its own
process, and writes the chart, the summary and the files (``cmd_pareto``).
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time

import numpy as np

from ..validation.elasticity_params import HAIR
from .pareto_data import DATA_DIR, Point, pareto_front, write_csv
from .pareto_runs import SCENES, RunSpec, default_specs, f64_specs, run_specs


# --------------------------------------------------------------------------- errors
def trajectory_error(traj: np.ndarray, ref: np.ndarray, strand_of_vertex: np.ndarray, lengths: np.ndarray) -> float:
    """RMS over samples and vertices of |x - x_ref| / (length of the vertex's strand) [-]."""
    if traj.shape != ref.shape:
        raise ValueError(f"trajectory shapes differ: {traj.shape} vs {ref.shape}")
    if not np.all(np.isfinite(traj)):
        return math.inf
    d = np.linalg.norm(traj - ref, axis=2) / lengths[strand_of_vertex][None, :]
    return float(np.sqrt(np.mean(d * d)))


def cantilever_error(final_positions: np.ndarray, model, lengths: np.ndarray) -> float:
    """Largest |tip - tip_elastica| / L over the rods (analytic reference) [-]."""
    from ..validation.elastica import cantilever_gamma, solve_heavy_elastica

    if not np.all(np.isfinite(final_positions)):
        return math.inf
    starts, counts = model.host["strand_vertex_start"], model.host["strand_vertex_count"]
    err = 0.0
    for s0, c, L in zip(starts, counts, lengths):
        sol = solve_heavy_elastica(cantilever_gamma(L, HAIR["radius"], HAIR["density"], HAIR["youngs_modulus_bend"]))
        tip = final_positions[s0 + c - 1] - final_positions[s0]
        ref = np.array([sol.width * L, -sol.height * L])
        err = max(err, float(np.hypot(tip[0] - ref[0], tip[1] - ref[1]) / L))
    return err


# --------------------------------------------------------------------------- worker (own process)
def _worker_main(argv) -> int:
    """``python -m taichi_hair.bench.pareto --worker PRECISION SCENES OUT.npz [--full] [--groom-strands N]``."""
    import pickle

    precision, scenes, out_path = argv[0], argv[1].split(","), argv[2]
    full = "--full" in argv
    strands = int(argv[argv.index("--groom-strands") + 1]) if "--groom-strands" in argv else 192
    import taichi as ti

    from .. import init

    init(arch=ti.cpu, default_fp=ti.f64 if precision == "f64" else ti.f32, log_level=ti.WARN)
    results = {}
    t0 = time.perf_counter()
    for sc in scenes:
        specs = f64_specs(full)
        if sc == "cantilever":
            specs = [s for s in specs if s.method != "admm_ref"]
        res, _, _ = run_specs(sc, specs, strands,
                              progress=lambda t: print(f"  [f64 worker {time.perf_counter() - t0:5.0f} s] {t}",
                                                       flush=True))
        results[sc] = res
    with open(out_path + ".tmp", "wb") as fh:
        pickle.dump(results, fh)
    os.replace(out_path + ".tmp", out_path)
    return 0


def run_f64_worker(scenes, out_path: str, full: bool = False, groom_strands: int = 192, quiet: bool = False):
    """Run the double-precision reference and ADMM f64 points in a subprocess; returns their results."""
    import pickle

    cmd = [sys.executable, "-m", "taichi_hair.bench.pareto", "--worker", "f64", ",".join(scenes), out_path,
           "--groom-strands", str(groom_strands)] + (["--full"] if full else [])
    proc = subprocess.run(cmd, stdout=None if not quiet else subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    if proc.returncode != 0:
        tail = (proc.stderr or "").strip().splitlines()[-1:] or ["no message"]
        raise RuntimeError(f"the f64 reference process failed (exit {proc.returncode}): {tail[0]}")
    with open(out_path, "rb") as fh:
        return pickle.load(fh)


# --------------------------------------------------------------------------- assembly

def assemble(scene_name: str, f32_results, f64_results, model, scene) -> tuple[list[Point], dict]:
    """Points with cost and error for one scene; info holds the reference's self-difference."""
    info = {}
    strand_of = model.host["vertex_strand"]
    ref = None
    if scene_name != "cantilever":
        refs = [r for r in f64_results if r["spec"]["method"] == "admm_ref"]
        fine = min(refs, key=lambda r: r["spec"]["dt"])
        coarse = max(refs, key=lambda r: r["spec"]["dt"])
        # Backward Euler is first order in dt: Richardson extrapolation of the two runs.
        ref = 2.0 * fine["trajectory"] - coarse["trajectory"]
        info["reference_self_error"] = trajectory_error(coarse["trajectory"], fine["trajectory"], strand_of,
                                                        scene.strand_lengths)
        info["reference_seconds"] = fine["seconds"] + coarse["seconds"]
    points = []
    for r, precision in [(r, "f32") for r in f32_results] + [(r, "f64") for r in f64_results
                                                                 if r["spec"]["method"] != "admm_ref"]:
        spec = RunSpec(**r["spec"])
        cost = r["seconds"] / scene.duration / (r["vertex_count"] / 1000.0)
        if scene_name == "cantilever":
            err = cantilever_error(r["trajectory"][-1], model, scene.strand_lengths)
        else:
            err = trajectory_error(r["trajectory"], ref, strand_of, scene.strand_lengths)
        points.append(Point(scene_name, spec.method, precision, spec.dt, spec.iterations, spec.substeps,
                            spec.shape_method, spec.label, cost, err))
    front = pareto_front([p.cost for p in points], [p.error for p in points])
    for p, f in zip(points, front):
        p.on_front = bool(f)
    return points, info


# --------------------------------------------------------------------------- outputs

COLORS = {"admm": "C3", "admm_w1": "C1", "admm_aa": "C6", "admm_bdf2": "C4", "admm_f64": "C5", "shape": "C0", "xpbd": "C2"}


def plot(points, infos: dict, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = list(dict.fromkeys(p.scene for p in points))
    fig, axes = plt.subplots(1, len(scenes), figsize=(5.2 * len(scenes), 4.6))
    axes = np.atleast_1d(axes)
    for ax, sc in zip(axes, scenes):
        ps = [p for p in points if p.scene == sc]
        finite = [p.error for p in ps if math.isfinite(p.error)]
        top = max(finite) * 3 if finite else 1.0
        for m in dict.fromkeys(p.method for p in ps):
            mp = sorted([p for p in ps if p.method == m], key=lambda p: p.cost)
            c = np.array([p.cost for p in mp])
            e = np.array([p.error if math.isfinite(p.error) else top for p in mp])
            own = pareto_front(c, [p.error for p in mp])
            ax.plot(c[own], e[own], "-", color=COLORS.get(m, "k"), lw=1.2)
            ax.plot(c, e, "o", color=COLORS.get(m, "k"), ms=4, mfc="none", label=m)
            bad = ~np.isfinite([p.error for p in mp])
            if bad.any():
                ax.plot(c[bad], e[bad], "x", color=COLORS.get(m, "k"), ms=7)
        fr = sorted([p for p in ps if p.on_front], key=lambda p: p.cost)
        ax.plot([p.cost for p in fr], [p.error for p in fr], "k--", lw=1, label="Pareto front (all methods)")
        ax.plot([p.cost for p in fr], [p.error for p in fr], "ks", ms=7, mfc="none")
        if "reference_self_error" in infos.get(sc, {}):
            ax.axhline(infos[sc]["reference_self_error"], color="0.5", ls=":", lw=1,
                       label="reference's fine run vs its coarse run")
        ax.set_xscale("log")
        ax.set_yscale("log")
        from matplotlib.ticker import NullFormatter

        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel("cost: wall s / simulated s / 1k vertices")
        ax.set_ylabel("error (cantilever: tip vs elastica / L; else RMS trajectory / L)")
        ax.set_title(sc, fontsize=10)
        ax.grid(True, which="both", alpha=0.25)
        ax.legend(fontsize=7)
    fig.suptitle("Speed against accuracy (x: non-finite, drawn at the top)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path + ".tmp.png", dpi=110)
    plt.close(fig)
    os.replace(path + ".tmp.png", path)


def format_summary(points, infos) -> str:
    lines = []
    for sc in dict.fromkeys(p.scene for p in points):
        ps = [p for p in points if p.scene == sc]
        fr = sorted([p for p in ps if p.on_front], key=lambda p: p.cost)
        extra = ""
        if "reference_self_error" in infos.get(sc, {}):
            extra = f" (reference self-difference {infos[sc]['reference_self_error']:.2e})"
        lines.append(f"{sc}: {len(ps)} points; Pareto front{extra}:")
        for p in fr:
            lines.append(f"    {p.method:9s} {p.precision} {p.label:28s} cost {p.cost:9.4g}  error {p.error:.3g}")
        for m in dict.fromkeys(p.method for p in ps):
            best = min((p for p in ps if p.method == m), key=lambda p: p.error)
            lines.append(f"  best {m:9s}: error {best.error:.3g} at cost {best.cost:.4g} ({best.label})")
    return "\n".join(lines)


# --------------------------------------------------------------------------- command
def cmd_pareto(args, methods) -> int:
    """``taichi-hair bench pareto``: f64 worker (reference, admm_f64), then the f32 sweep in this process."""
    from ..cli.common import CLIError, _init_taichi

    scenes = tuple(s.strip() for s in args.scenes.split(",") if s.strip())
    bad = [s for s in scenes if s not in SCENES]
    if not scenes or bad:
        raise CLIError(f"--scenes must be a comma-separated subset of {','.join(SCENES)}, got {args.scenes!r}")
    if args.groom_strands < 1:
        raise CLIError(f"--groom-strands must be >= 1, got {args.groom_strands}")
    if args.precision != "f32":
        raise CLIError("bench pareto runs its sweep in f32 and the reference in f64 itself; drop --precision")
    os.makedirs(args.out, exist_ok=True)
    t0 = time.perf_counter()
    load_at_start = os.getloadavg()  # the machine may be shared: costs scale with its load
    quiet = args.quiet

    def say(text):
        if not quiet:
            print(f"  [{time.perf_counter() - t0:6.0f} s] {text}", flush=True)

    if not quiet:
        print(f"pareto: scenes {', '.join(scenes)}; f64 reference process first, then the f32 sweep", flush=True)
    f64 = run_f64_worker(scenes, os.path.join(args.out, "f64_runs.pkl"), args.full, args.groom_strands, quiet)
    ti, arch = _init_taichi(args.arch, "f32")
    specs = [s for s in default_specs(args.full) if s.method in methods]
    points, infos = [], {}
    for sc in scenes:
        res, model, scene = run_specs(sc, specs, args.groom_strands, progress=say)
        f64_res = [r for r in f64[sc] if r["spec"]["method"] == "admm_ref" or r["spec"]["method"] in methods]
        pts, info = assemble(sc, res, f64_res, model, scene)
        points += pts
        infos[sc] = info
    os.remove(os.path.join(args.out, "f64_runs.pkl"))
    csv_path = os.path.join(args.out, "pareto.csv")
    write_csv(points, csv_path)
    png_path = os.path.join(args.out, "pareto.png")
    plot(points, infos, png_path)
    import platform

    meta = {"arch": arch, "machine": f"{platform.machine()}, {os.cpu_count()} CPUs, {platform.platform()}",
            "date_utc": time.strftime("%Y-%m-%d %H:%M", time.gmtime()),
            "load_average_at_start": [round(x, 2) for x in load_at_start],
            "full": bool(args.full), "groom_strands": args.groom_strands, "scenes": infos,
            "seconds": round(time.perf_counter() - t0, 1)}
    with open(os.path.join(args.out, "pareto.json"), "w") as fh:
        json.dump(meta, fh, indent=1)
    print(format_summary(points, infos))
    written = [csv_path, png_path, os.path.join(args.out, "pareto.json")]
    if args.update_data:
        os.makedirs(DATA_DIR, exist_ok=True)
        write_csv(points, os.path.join(DATA_DIR, "pareto_cpu.csv"))
        with open(os.path.join(DATA_DIR, "pareto_cpu.json"), "w") as fh:
            json.dump(meta, fh, indent=1)
        written.append(os.path.join(DATA_DIR, "pareto_cpu.csv"))
    print(f"wrote {', '.join(written)} in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--worker":
        sys.exit(_worker_main(sys.argv[2:]))
    print("usage: taichi-hair bench pareto --out DIR", file=sys.stderr)
    sys.exit(2)
