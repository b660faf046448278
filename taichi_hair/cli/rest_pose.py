"""``taichi-hair rest-pose``: solve a groom's sag-free rest pose and write it beside the authored shape.

    taichi-hair rest-pose assets/ponytail/tail.tfx --scale 0.0035 --out out/tail_sag_free.thair.npz
    taichi-hair rest-pose groom.usd --units cm --body head.obj --out groom_sag_free.usd

The groom's shape x* stays its ``points``; the solved rest pose is written as the *rest curve*
(``rest_points``, USD's ``rest`` primvar, and ``rest_twist``, USD ``restTwist``: the shape each strand relaxes
to without gravity, :mod:`taichi_hair.solvers.rest_curve`), with ``params["rest_pose"]`` saying what was
solved.  Any writable format takes the output; the native ``.thair.npz`` and USD keep the rest curve and its
twist (so ``[groom] rest_pose = "file"`` in a scene, or ``simulate --rest-pose file``, reads it back).
With ``--body`` the roots are checked to sit on the mesh and no vertex to start inside it (reported by
strand).  Strands that cannot be held (:mod:`taichi_hair.solvers.rest_pose`), or that the builder refuses
(a zero-length edge, too few vertices), keep their authored rest pose and are named; the rest are solved.
Exit status: 0 solved (some strands may be named), 2 bad input.
"""

from __future__ import annotations

import json
import os
import sys
import time

import numpy as np

from .common import CLIError, _init_taichi

#: A root farther than this from the body's surface is reported as not on the body [m].
ROOT_TOLERANCE_M = 2.0e-3


def _model_of(groom, material_kw: dict):
    """Model of every strand the builder accepts, and [(strand, why)] for the others (kept out)."""
    from ..builder import GroomBuilder
    from ..config import RodMaterial

    b = GroomBuilder()
    kept, refused = [], []
    radius = groom.radius
    for s in range(groom.strand_count):
        kw = dict(material_kw)
        if radius is not None and "radius" not in kw:
            a, e = groom.strand_offsets[s], groom.strand_offsets[s + 1]
            kw["radius"] = float(np.mean(radius[a:e]) if radius.shape[0] == groom.vertex_count else radius[s])
        try:
            b.add_strand(groom.strand(s).astype(np.float64), RodMaterial(**kw))
        except ValueError as exc:
            refused.append((s, str(exc).replace(f"strand {b.strand_count}: ", "")))
            continue
        kept.append(s)
    if not kept:
        raise CLIError(f"no strand of the groom can be built (strand {refused[0][0]}: {refused[0][1]})")
    return b.finalize(), np.array(kept), refused


def _body_report(groom, mesh_path: str) -> list:
    """Lines naming strands whose root is off the body or that start inside it."""
    import trimesh

    from ..contact.mesh_query import TriangleMeshQuery

    try:
        mesh = trimesh.load(mesh_path, force="mesh", process=False)
    except Exception as exc:  # noqa: BLE001 - trimesh raises many kinds for a bad file
        raise CLIError(f"{mesh_path}: cannot read the body mesh ({type(exc).__name__}: {exc})") from None
    if len(mesh.faces) == 0:
        raise CLIError(f"{mesh_path}: the body mesh has no triangles")
    q = TriangleMeshQuery(np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64))
    off = groom.strand_offsets
    roots = groom.points[off[:-1]].astype(np.float64)
    d = q.unsigned_distance(roots)
    lines = []
    far = np.nonzero(d > ROOT_TOLERANCE_M)[0]
    if far.size:
        s = int(far[np.argmax(d[far])])
        lines.append(f"roots more than {1e3 * ROOT_TOLERANCE_M:g} mm from the body: {far.size} of "
                     f"{len(roots)} strands (farthest: strand {s}, {1e3 * d[s]:.1f} mm); their rest pose is solved "
                     "as if clamped where they are")
    free = np.ones(groom.vertex_count, bool)
    free[off[:-1]] = False
    free[np.minimum(off[:-1] + 1, off[1:] - 1)] = False
    idx = np.nonzero(free)[0]
    inside = idx[q.winding_number(groom.points[idx].astype(np.float64)) >= 0.5]
    if inside.size:
        strand = np.searchsorted(off, inside, side="right") - 1
        bad = np.unique(strand)
        lines.append(f"vertices inside the body at the start: {bad.size} strands (first: strand {int(bad[0])}; "
                     f"{inside.size} vertices in all); contacts will push them out, away from the authored shape")
    return lines


def cmd_rest_pose(args) -> int:
    from ..io import load_groom, save_groom, units_warning
    from ..scene.setup import UNITS as UNIT_METRES

    if not os.path.exists(args.groom):
        raise CLIError(f"{args.groom}: no such file")
    if args.scale is not None and args.units is not None:
        raise CLIError("give --scale or --units, not both")
    if args.units is not None and args.units not in UNIT_METRES:
        raise CLIError(f"--units must be one of {', '.join(UNIT_METRES)}, got {args.units!r}")
    scale = args.scale if args.scale is not None else UNIT_METRES[args.units] if args.units else None
    g = load_groom(args.groom, scale=scale)
    msg = units_warning(g, args.groom, applied_scale=scale)
    if msg:
        print(f"warning: {msg}", file=sys.stderr)
    if args.body and not os.path.exists(args.body):
        raise CLIError(f"{args.body}: no such file")
    _init_taichi(args.arch, "f32")
    from ..config import SolverADMMConfig
    from ..solvers.rest_curve import rest_curve
    from ..solvers.rest_pose import RestPoseConfig, apply_rest_pose, solve_rest_pose

    t0 = time.perf_counter()
    material = {}
    if args.youngs_modulus is not None:
        material["youngs_modulus_bend"] = args.youngs_modulus
    if args.radius is not None:
        material["radius"] = args.radius
    model, kept, refused = _model_of(g, material)
    t_build = time.perf_counter() - t0
    res = solve_rest_pose(model, SolverADMMConfig(), gravity=tuple(args.gravity),
                          config=RestPoseConfig(max_rest_change=args.max_rest_change))
    apply_rest_pose(model, res)
    if not args.no_check:
        from ..solvers.rest_pose import check_stability

        check_stability(model, res, SolverADMMConfig(), gravity=tuple(args.gravity), progress=True)
    xr, tw = rest_curve(model, res.pair_rest_strain, res.edge_rest_length)
    rest = g.points.astype(np.float64).copy()
    twist = np.zeros(g.vertex_count)
    off = g.strand_offsets
    src = np.concatenate([np.arange(off[s], off[s + 1]) for s in kept])
    rest[src] = xr
    twist[src] = tw
    if g.rest_points is not None:
        print("note: the file's own rest_points are replaced by the solved rest curve", file=sys.stderr)
    unheld = [(int(kept[s]), why) for s, why in res.unheld] + refused
    unheld.sort()
    params = dict(g.params)
    params["rest_pose"] = dict(kind="sag-free", solver="admm", strain_measure=res.measure,
                               gravity=list(map(float, args.gravity)), held=res.held_count,
                               strands=g.strand_count, not_held=[s for s, _ in unheld][:1000],
                               unstable=[int(kept[s]) for s, _ in res.unstable][:1000],
                               largest_rest_turn=float(res.strand_rest_turn.max()))
    from dataclasses import replace

    out = replace(g, rest_points=rest.astype(g.points.dtype), rest_twist=twist, params=params)
    save_groom(out, args.out)
    body_lines = _body_report(g, args.body) if args.body else []
    print(f"{args.groom}: {g.strand_count} strands, {g.vertex_count} vertices (model {t_build:.2f} s)")
    print(res.summary().replace(f"{res.held_count}/{model.strand_count}",
                                f"{res.held_count}/{g.strand_count}"))
    for s, why in unheld[:args.list]:
        print(f"  strand {s}: {why}")
    if len(unheld) > args.list:
        print(f"  ... {len(unheld) - args.list} more (all in {args.out}'s params['rest_pose']['not_held'])")
    for s, why in res.unstable[:args.list]:
        print(f"  strand {int(kept[s])} (held, unstable): {why}")
    for line in body_lines:
        print(f"warning: {line}", file=sys.stderr)
    print(f"wrote {args.out} (points: the authored shape; rest_points, rest_twist: the sag-free rest curve)")
    if args.report:
        with open(args.report, "w") as fh:
            json.dump(dict(groom=args.groom, out=args.out, strands=g.strand_count, held=res.held_count,
                           seconds=res.seconds, largest_rest_turn=float(res.strand_rest_turn.max()),
                           not_held=[dict(strand=s, why=w) for s, w in unheld],
                           unstable=[dict(strand=int(kept[s]), why=w) for s, w in res.unstable], body=body_lines),
                      fh, indent=1)
    return 0


def register(sub) -> None:
    p = sub.add_parser("rest-pose", help="solve a groom's sag-free rest pose (the shape it holds under gravity)",
                       description=__doc__.split("\n\n")[0])
    p.add_argument("groom", help="groom file (any format taichi-hair reads)")
    p.add_argument("--out", required=True, help="groom file to write (.thair.npz or .usd keep the rest curve)")
    p.add_argument("--units", default=None, help="the file's length unit: m, cm, mm or in")
    p.add_argument("--scale", type=float, default=None, help="file units to metres (instead of --units)")
    p.add_argument("--body", default=None, help="body mesh the roots sit on (checked: roots on it, none inside)")
    p.add_argument("--gravity", type=float, nargs=3, default=(0.0, -9.81, 0.0), metavar=("X", "Y", "Z"),
                   help="gravity in the groom's frame [m/s^2] (default 0 -9.81 0)")
    p.add_argument("--radius", type=float, default=None, help="fibre radius [m] (default: the file's, else 37 um)")
    p.add_argument("--youngs-modulus", type=float, default=None, help="bending Young's modulus [Pa] (default 3e9)")
    p.add_argument("--max-rest-change", type=float, default=1.0,
                   help="largest change of a rest strain |kappa_bar - kappa| a held strand may need (default 1.0, "
                        "about 60 degrees per vertex)")
    p.add_argument("--no-check", action="store_true",
                   help="skip the stability check (a 2 s dynamic run without contacts that finds the held strands "
                        "whose equilibrium is unstable)")
    p.add_argument("--list", type=int, default=10, help="strands not held to name on stdout (default 10)")
    p.add_argument("--report", default=None, help="also write a JSON report here")
    p.add_argument("--arch", default="cpu", help="Taichi arch: cpu (default), cuda, gpu, vulkan")
    p.set_defaults(func=cmd_rest_pose)
