"""Sag-free rest pose (issue 14): how well each groom holds its authored shape, authored vs sag-free.

    python3 benchmarks/bench_rest_pose.py [--frames N] [--strands 300] [--grooms straight,wavy,curly,ponytail]
        [--motion still|head_turn] [--contacts all|body] [--iterations N] [--amplitude DEG] [--air-viscosity XI]
        [--friction MU] [--body-friction MU] [--weight-time paper|step|hair-step] [--rest-poses authored,sag-free]
        [--arch cpu|cuda] [--out benchmarks/results/rest_pose.json]

For every groom: the scene (``assets/scenes/head_turn.toml`` with the generator style swapped, or
``assets/scenes/ponytail.toml``) with its body still (``--motion still``) or turning, hair-hair and body contacts
on at the scene's settings, simulated ``--frames`` frames (default 48 = 2 s with the body still; 240 = 10 s under the head turn,
whose 2 s cycle starts at 0.25 s, so the groom has 7.75 s to settle) twice through ``taichi-hair simulate``:
with ``--rest-pose authored`` and ``--rest-pose sag-free``.  Printed and written: the time of the rest
pose solve, the strands it holds, and the p90 / max vertex drift from the authored shape at the end and over the
run (the runs' own ``summary.json``: ``quality.drift_*``), the strain and the wall time of each run.

The head-turn study (BENCHMARKS.md, issue 14) varies what the return depends on: the ADMM iterations per
substep, the turn's amplitude, air drag (``[solver] air_viscosity``, 1e-4 Pa s in both scenes) and the hair-hair
and body friction.
``--rest-poses sag-free`` skips the authored runs.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile

from harness import ROOT, Bench

SCENES = {"ponytail": os.path.join(ROOT, "assets", "scenes", "ponytail.toml")}
HEAD = os.path.join(ROOT, "assets", "scenes", "head_turn.toml")


def without_hair_contacts(src: str) -> str:
    """The scene without its [solver.contacts] table (hair-hair contacts off; body colliders stay)."""
    if "[solver.contacts]" not in src:
        return src
    a = src.index("[solver.contacts]")
    b = src.index("\n[", a + 1)
    return src[:a] + src[b + 1:]


def scene_text(groom: str, motion: str) -> str:
    """The TOML of one groom's scene, paths absolute, with the body still or turning."""
    if groom == "ponytail":
        src = open(SCENES["ponytail"]).read().replace('"../ponytail/tail.tfx"',
                                                       json.dumps(os.path.join(ROOT, "assets", "ponytail", "tail.tfx")))
        bodies = src.index("[[bodies]]")
        body = '[[bodies]]\npreset = "still"\n' if motion == "still" else \
            '[[bodies]]\npreset = "head_turn"\namplitude = 40.0\nperiod = 2.0\nstart = 0.25\npivot = [0.0, 0.2, 0.0]\n'
        return src[:bodies] + body
    src = open(HEAD).read().replace('generator = "wavy"', f'generator = "{groom}"')
    src = src.replace('file = "../head.obj"', f'file = {json.dumps(os.path.join(ROOT, "assets", "head.obj"))}')
    if motion == "still":
        src = src[:src.index("[[bodies]]")] + '[[bodies]]\npreset = "still"\n'
    return src


def with_body_friction(text: str, mu: float) -> str:
    """``text`` with every ``[[colliders]]`` table's friction set to ``mu`` (the line replaced, or added where
    the table has none: the ponytail's spheres take the default)."""
    parts = text.split("\n[[colliders]]\n")
    for k in range(1, len(parts)):
        lines = parts[k].split("\n")
        end = next((j for j, ln in enumerate(lines) if ln.startswith("[")), len(lines))
        hit = [j for j in range(end) if lines[j].startswith("friction =")]
        if hit:
            lines[hit[0]] = f"friction = {float(mu)!r}"
        else:
            lines.insert(0, f"friction = {float(mu)!r}")
        parts[k] = "\n".join(lines)
    if len(parts) == 1:
        raise ValueError("the scene has no [[colliders]] table")
    return "\n[[colliders]]\n".join(parts)


def run(groom: str, rest_pose: str, args, work: str) -> dict:
    path = os.path.join(work, f"{groom}_{args.motion}.toml")
    text = scene_text(groom, args.motion).replace("[groom]\n", "[groom]\nrest_pose_check = true\n", 1)
    if args.iterations is not None:
        assert "\niterations = 10\n" in text, "the scene's [solver] iterations line moved"
        text = text.replace("\niterations = 10\n", f"\niterations = {args.iterations}\n", 1)
    if args.amplitude is not None:
        assert "\namplitude = 40.0" in text, "the scene's head_turn amplitude line moved"
        text = text.replace("\namplitude = 40.0", f"\namplitude = {float(args.amplitude)!r}", 1)
    if args.air_viscosity is not None:
        assert "\nair_viscosity = 1.0e-4" in text, "the scene's air_viscosity line moved"
        text = text.replace("\nair_viscosity = 1.0e-4", f"\nair_viscosity = {float(args.air_viscosity)!r}", 1)
    if args.friction is not None:
        assert "[solver.contacts]" in text and "\nfriction = 0.2\n" in text, "the scene's hair-hair friction line moved"
        text = text.replace("\nfriction = 0.2\n", f"\nfriction = {float(args.friction)!r}\n", 1)
    if args.body_friction is not None:
        text = with_body_friction(text, args.body_friction)
    if args.weight_time is not None:
        assert "\n[solver.contacts]" in text, "the scene has no [solver.contacts] table"
        a = text.index("\n", text.index("\n[solver.contacts]") + 1)  # the table's line may carry a comment
        text = text[:a + 1] + f"weight_time = {json.dumps(args.weight_time)}\n" + text[a + 1:]
    if args.contacts == "body":
        text = without_hair_contacts(text)
    with open(path, "w") as fh:
        fh.write(text)
    out = os.path.join(work, f"{groom}_{rest_pose}")
    cmd = [sys.executable, "-m", "taichi_hair.cli", "simulate", path, "--rest-pose", rest_pose, "--frames",
           str(args.frames), "--out", out, "--quiet", "--arch", args.arch]
    if groom != "ponytail":
        cmd += ["--strands", str(args.strands)]
    p = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
    if p.returncode != 0:
        return dict(error=(p.stderr or p.stdout)[-600:], returncode=p.returncode)
    with open(os.path.join(out, "summary.json")) as fh:
        s = json.load(fh)
    q = s["quality"]
    row = dict(strands=s["strands"], vertices=s["vertices"], ms_per_frame=s["ms_per_frame"],
               drift_p90_last_mm=1e3 * q["drift_p90_last_m"], drift_p90_max_mm=1e3 * q["drift_p90_max_m"],
               drift_max_mm=1e3 * q["drift_max_m"], strain_p99_max=q["strain_p99_max"], strain_max=q["strain_max"],
               came_to_rest=q["came_to_rest"], shape_distance_p90_last_mm=1e3 * q.get("shape_distance_p90_last_m", float("nan")),
               vertices_above_rest_speed=q.get("last_frame_vertices_above_rest_speed"))
    if "rest_pose" in s:
        r = s["rest_pose"]
        row.update(rest_pose_seconds=r["seconds"], strands_held=r["strands_held"],
                   largest_rest_turn=r["largest_rest_turn"], unstable=r.get("unstable_count"))
        # The drift over the strands the solve holds and finds stable (check_stability), from the frames.
        import numpy as np

        with np.load(os.path.join(out, "frames.npz")) as z:
            key = "positions" if "positions" in z.files else z.files[0]
            frames = z[key]
        x0, x1 = frames[0].astype(np.float64), frames[-1].astype(np.float64)
        counts = np.asarray(s.get("strand_vertex_counts") or [], np.int64)
        if counts.size == 0:
            counts = np.full(s["strands"], s["vertices"] // s["strands"])
        strand = np.repeat(np.arange(counts.size), counts)
        bad = {d["strand"] for d in r["not_held"]} | {d["strand"] for d in r.get("unstable", [])}
        if r["not_held_count"] <= len(r["not_held"]) and r.get("unstable_count", 0) <= len(r.get("unstable", [])):
            ok = ~np.isin(strand, sorted(bad))
            d = np.linalg.norm(x1 - x0, axis=1)[ok]
            row.update(held_stable_strands=int(counts.size - len(bad)),
                       held_stable_drift_p90_last_mm=1e3 * float(np.percentile(d, 90)) if d.size else None)
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=None, help="frames to simulate (default: 48 still, 240 head_turn)")
    ap.add_argument("--strands", type=int, default=300)
    ap.add_argument("--grooms", default="straight,wavy,curly,ponytail")
    ap.add_argument("--motion", choices=("still", "head_turn"), default="still")
    ap.add_argument("--contacts", choices=("all", "body"), default="all",
                    help="all: the scene's hair-hair and body contacts; body: hair-hair contacts off")
    ap.add_argument("--iterations", type=int, default=None,
                    help="ADMM iterations per substep instead of the scene's 10 (the head turn's return depends on it)")
    ap.add_argument("--amplitude", type=float, default=None, help="head_turn: peak angle [deg] instead of 40")
    ap.add_argument("--air-viscosity", type=float, default=None,
                    help="[solver] air_viscosity xi [Pa s] instead of the scenes' 1e-4 (0: no air)")
    ap.add_argument("--friction", type=float, default=None, help="hair-hair friction instead of the scene's 0.2")
    ap.add_argument("--body-friction", type=float, default=None,
                    help="every collider's friction instead of the scene's (added where a collider table has none)")
    ap.add_argument("--weight-time", choices=("paper", "step", "hair-step"), default=None,
                    help="ContactConfig.weight_time of the hair-hair and body contacts (default: the scene's, hair-step)")
    ap.add_argument("--rest-poses", default="authored,sag-free", help="which runs: authored, sag-free or both")
    ap.add_argument("--arch", default="cpu", help="Taichi arch of the simulate runs: cpu (default), cuda, gpu, vulkan")
    ap.add_argument("--out", default=os.path.join(ROOT, "benchmarks", "results", "rest_pose.json"))
    args = ap.parse_args(argv)
    poses = [p for p in args.rest_poses.split(",") if p]
    if not poses or any(p not in ("authored", "sag-free") for p in poses):
        ap.error(f"--rest-poses takes authored and/or sag-free, got {args.rest_poses!r}")
    if args.frames is None:
        args.frames = 240 if args.motion == "head_turn" else 48
    bench = Bench("rest_pose", argv)
    rows = {}
    with tempfile.TemporaryDirectory() as work:
        for groom in args.grooms.split(","):
            rows[groom] = {rp: run(groom, rp, args, work) for rp in poses}
            if poses == ["sag-free"] and "error" not in rows[groom]["sag-free"]:
                b = rows[groom]["sag-free"]
                print(f"{groom:9s} {b['strands']:4d} strands, sag-free: p90 drift at the end {b['drift_p90_last_mm']:8.3f} mm, "
                      f"largest p90 over the run {b['drift_p90_max_mm']:.1f} mm; shape distance p90 at the end "
                      f"{b['shape_distance_p90_last_mm']:.3f} mm; at rest {b['came_to_rest']} "
                      f"({b['vertices_above_rest_speed']} vertices above 1 cm/s); "
                      f"{b['ms_per_frame']:.0f} ms/frame", flush=True)
                continue
            if len(poses) < 2:
                print(f"{groom}: {rows[groom]}")
                continue
            a, b = rows[groom]["authored"], rows[groom]["sag-free"]
            if "error" in a or "error" in b:
                print(f"{groom}: failed: {a.get('error') or b.get('error')}")
                continue
            ratio = b["drift_p90_last_mm"] / max(a["drift_p90_last_mm"], 1e-12)
            rows[groom]["ratio_p90_last"] = ratio
            print(f"{groom:9s} {a['strands']:4d} strands: p90 drift at the end authored {a['drift_p90_last_mm']:8.3f} mm, "
                  f"sag-free {b['drift_p90_last_mm']:8.3f} mm ({100 * ratio:5.1f} %); max {a['drift_max_mm']:.1f} / "
                  f"{b['drift_max_mm']:.1f} mm; held {b.get('strands_held')}/{b['strands']} "
                  f"(solve {b.get('rest_pose_seconds', float('nan')):.2f} s); p99 strain {100 * b['strain_p99_max']:.3f} %; "
                  f"{b['ms_per_frame']:.0f} ms/frame; held and stable: {b.get('held_stable_strands')} strands, "
                  f"p90 drift {b.get('held_stable_drift_p90_last_mm', float('nan')):.3f} mm", flush=True)
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    bench.write(args.out, dict(frames=args.frames, motion=args.motion, contacts=args.contacts,
                               iterations=args.iterations or 10, amplitude=args.amplitude or 40.0,
                               air_viscosity=args.air_viscosity, friction=args.friction,
                               body_friction=args.body_friction, weight_time=args.weight_time, arch=args.arch,
                               grooms=rows))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
