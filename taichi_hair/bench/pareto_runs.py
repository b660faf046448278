"""The runs of the speed-against-accuracy study (:mod:`taichi_hair.bench.pareto`): its scenes, the
method knobs of each point (:class:`RunSpec`, the default and f64 grids) and running them with the
timing and trajectory samples that the study scores.

The scenes, the reference and the grids are described in :mod:`taichi_hair.bench.pareto`.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass

import numpy as np

from ..validation.elasticity_params import GRAVITY, HAIR
from .methods import ADMM_VARIANTS, admm_config, is_admm

SCENES = ("cantilever", "swing", "groom")
#: Constraint weight scale w0 of each ADMM variant (the variants: :mod:`taichi_hair.bench.methods`).
ADMM_W0 = {name: v["w0"] for name, v in ADMM_VARIANTS.items()}
#: The reference: two f64 ADMM runs (coarse, fine) [s] and their iterations per step.
REFERENCE_DTS = (1 / 1920, 1 / 3840)
REFERENCE_ITERATIONS = 50
SAMPLE_INTERVAL = 1.0 / 48.0

# --------------------------------------------------------------------------- scenes
@dataclass
class Scene:
    name: str
    duration: float          # simulated time [s]
    drag_rate: float         # velocity relaxation rate of the damping [1/s]
    strand_lengths: np.ndarray  # [m]
    shake: bool = False


def _hair(**kw):
    from ..config import RodMaterial

    return RodMaterial(radius=HAIR["radius"], density=HAIR["density"], youngs_modulus_bend=HAIR["youngs_modulus_bend"],
                       poisson_ratio=HAIR["poisson_ratio"], **kw)


def cantilever_lengths() -> np.ndarray:
    return np.geomspace(0.01, 0.30, 6)


def build_scene(name: str, groom_strands: int = 192):
    """(Model, Scene) of one of :data:`SCENES`."""
    from ..builder import GroomBuilder

    b = GroomBuilder()
    mat = _hair()
    if name == "cantilever":
        lengths = cantilever_lengths()
        for i, L in enumerate(lengths):
            n = max(16, int(round(L / 2.5e-3))) + 1
            x = np.linspace(0.0, L, n)
            b.add_strand(np.c_[x, np.zeros(n), np.full(n, 0.01 * i)], mat, root_director=(0.0, 0.0, 1.0))
        return b.finalize(), Scene(name, 1.5, 8.0, lengths)
    if name == "swing":
        x = np.linspace(0.0, 0.40, 81)
        b.add_strand(np.c_[x, np.zeros(81), np.zeros(81)], mat, root_director=(0.0, 0.0, 1.0))
        return b.finalize(), Scene(name, 1.0, 0.5, np.array([0.40]))
    if name == "groom":
        k = np.arange(groom_strands) + 0.5
        y = k / groom_strands  # upper hemisphere, golden-angle spiral
        r = np.sqrt(1 - y * y)
        a = math.pi * (3 - math.sqrt(5)) * k
        normals = np.c_[r * np.cos(a), y, r * np.sin(a)]
        s = np.linspace(0.0, 0.20, 21)
        for nrm in normals:
            u = np.cross(nrm, [0.0, 0.0, 1.0] if abs(nrm[2]) < 0.9 else [1.0, 0.0, 0.0])
            u /= np.linalg.norm(u)
            pts = 0.09 * nrm + s[:, None] * nrm + 0.003 * np.sin(2 * math.pi * s / 0.04)[:, None] * u
            b.add_strand(pts, mat)
        model = b.finalize()
        le = model.host["edge_rest_length"]
        lengths = np.array([le[s0:s0 + c - 1].sum() for s0, c in model.strand_slices()])
        return model, Scene(name, 0.5, 0.5, lengths, shake=True)
    raise ValueError(f"scene must be one of {SCENES}, got {name!r}")


def shake_rotation(t: float) -> np.ndarray:
    """Head rotation about +y at time t [s]: 0.4 sin(2 pi 1.5 t) rad."""
    a = 0.4 * math.sin(2 * math.pi * 1.5 * t)
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


# --------------------------------------------------------------------------- method runs
@dataclass
class RunSpec:
    """One point: ``method`` (admm, admm_w1, admm_aa, admm_bdf2, admm_f64, admm_ref, shape, xpbd), dt [s] and its knobs."""

    method: str
    dt: float
    iterations: int = 0       # ADMM iterations / Shape local+length iterations
    substeps: int = 0         # XPBD substeps
    shape_method: int = 0     # SolverShape Method 1/2/3

    @property
    def family(self) -> str:
        return "admm" if is_admm(self.method) else self.method

    @property
    def label(self) -> str:
        if self.family == "admm":
            return f"dt=1/{1 / self.dt:.0f} it={self.iterations}"
        if self.method == "shape":
            return f"M{self.shape_method} dt=1/{1 / self.dt:.0f} it={self.iterations}"
        return f"dt=1/{1 / self.dt:.0f} sub={self.substeps}"


def default_specs(full: bool = False) -> list[RunSpec]:
    """The f32 sweep (admm_f64 and the reference run in the f64 worker)."""
    specs = []
    its = (2, 5, 10, 30, 100) if full else (5, 10, 30)
    for m in ("admm", "admm_w1", "admm_aa", "admm_bdf2"):
        for dt in ((1 / 48, 1 / 96, 1 / 384) if full else (1 / 96, 1 / 384)):
            specs += [RunSpec(m, dt, iterations=i) for i in its]
    for sm in (1, 2, 3):
        its = (2, 5, 10, 30) if full else (2, 10)
        specs += [RunSpec("shape", 1 / 96, iterations=i, shape_method=sm) for i in its]
    specs.append(RunSpec("shape", 1 / 384, iterations=10, shape_method=2))
    specs += [RunSpec("xpbd", 1 / 96, substeps=s) for s in ((5, 20, 80, 320) if full else (5, 20, 80))]
    return specs


def f64_specs(full: bool = False) -> list[RunSpec]:
    its = (5, 10, 30) if full else (10, 30)
    return [RunSpec("admm_ref", dt, iterations=REFERENCE_ITERATIONS) for dt in REFERENCE_DTS] + \
           [RunSpec("admm_f64", 1 / 96, iterations=i) for i in its]


def _make_solver(spec: RunSpec, model, scene: Scene):
    from ..solvers import make_solver

    rho_a = HAIR["density"] * math.pi * HAIR["radius"] ** 2
    if spec.family == "admm":
        return make_solver("admm", model, admm_config(spec.method, iterations=spec.iterations,
                                                      air_viscosity=scene.drag_rate * rho_a, check_finite=False))
    if spec.method == "shape":
        from ..solvers.shape.solver import ShapeRegion, SolverShapeConfig

        region = ShapeRegion(local_iterations=spec.iterations, length_iterations=spec.iterations,
                             damping=1.0 - math.exp(-scene.drag_rate * spec.dt))
        return make_solver("shape", model, SolverShapeConfig(method=spec.shape_method, regions=(region,),
                                                             air_drag=0.0, check_finite=False))
    if spec.method == "xpbd":
        from ..solvers.xpbd.solver import SolverXPBDConfig

        return make_solver("xpbd", model, SolverXPBDConfig(substeps=spec.substeps, damping=scene.drag_rate,
                                                           check_finite=False))
    raise ValueError(f"unknown method {spec.method!r}")


def _configure(solver, spec: RunSpec, scene: Scene) -> None:
    """Set the knobs of an existing solver (no recompilation)."""
    if spec.family == "admm":
        solver.config.iterations = spec.iterations
        solver.reset_duals()
    elif spec.method == "shape":
        solver.config.method = spec.shape_method
        r = solver.config.regions[0]
        r.local_iterations = r.length_iterations = spec.iterations
        r.damping = 1.0 - math.exp(-scene.drag_rate * spec.dt)
        solver.upload_regions()
    else:
        solver.config.substeps = spec.substeps


def _solver_key(spec: RunSpec):
    return ("admm", tuple(sorted(ADMM_VARIANTS[spec.method].items()))) if spec.family == "admm" else (spec.method, 0.0)


def run_specs(scene_name: str, specs, groom_strands: int = 192, progress=None):
    """Run every spec on one scene; returns a list of dicts with the trajectory samples and timing.

    Trajectories: positions every :data:`SAMPLE_INTERVAL` s, shape (samples, vertex_count, 3), float64.
    """
    model, scene = build_scene(scene_name, groom_strands)
    state, control = model.state(), model.control()
    control.gravity = (0.0, -GRAVITY, 0.0)
    solvers = {}
    out = []
    for spec in specs:
        key = _solver_key(spec)
        if key not in solvers:
            solvers[key] = _make_solver(spec, model, scene)
            solvers[key].step(state, control, spec.dt)  # compile outside the timing
        solver = solvers[key]
        # One warm-up step with these knobs (a kernel a knob selects compiles on first use), then reset.
        _configure(solver, spec, scene)
        solver.step(state, control, spec.dt)
        _configure(solver, spec, scene)
        model.reset_state(state)
        steps = int(round(scene.duration / spec.dt))
        per_sample = int(round(SAMPLE_INTERVAL / spec.dt))
        samples = []
        t0 = time.perf_counter()
        sim_time = 0.0
        for k in range(steps):
            if scene.shake:
                control.set_body_transform(0, shake_rotation((k + 1) * spec.dt), (0.0, 0.0, 0.0))
            solver.step(state, control, spec.dt)
            if (k + 1) % per_sample == 0:
                ti_sync()
                sim_time += time.perf_counter() - t0
                samples.append(state.vertex_position.to_numpy().astype(np.float64))
                t0 = time.perf_counter()
        ti_sync()
        sim_time += time.perf_counter() - t0
        if scene.shake:
            control.set_body_transform(0, np.eye(3), (0.0, 0.0, 0.0))
        traj = np.array(samples)
        out.append({"spec": asdict(spec), "seconds": sim_time, "vertex_count": model.vertex_count,
                    "trajectory": traj, "finite": bool(np.all(np.isfinite(traj)))})
        if progress is not None:
            progress(f"{scene_name}: {spec.method} {spec.label}: {sim_time:.2f} s")
    return out, model, scene


def ti_sync():
    import taichi as ti

    ti.sync()
