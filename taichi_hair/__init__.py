"""taichi-hair: hair simulation on Taichi.

Discrete Elastic Rods integrated with the ADMM local-global solver of
Daviet 2023, "Interactive Hair Simulation on the GPU using ADMM".

Importing this package is light: it does not call ``ti.init``, open a window or
import plotting libraries.  The application (or the test session) chooses the
Taichi arch and the floating-point precision, e.g. ``ti.init(arch=ti.cpu)`` for
single precision or ``ti.init(arch=ti.cpu, default_fp=ti.f64)`` for double.
:func:`init` is ``ti.init`` with the compile options the project is measured with
(:data:`TAICHI_INIT_OPTIONS`: kernels compile 2-3x faster, run as fast).

Typical use::

    import taichi as ti
    import taichi_hair as th
    th.init(arch=ti.cpu)                # ti.init(arch=ti.cpu) works too, with slower kernel compilation
    builder = th.GroomBuilder()
    builder.add_strand(points, material=th.RodMaterial(), root="clamped")
    model = builder.finalize()
    state, control = model.state(), model.control()
    solver = th.SolverADMM(model, th.SolverADMMConfig(iterations=10))
    solver.step(state, control, dt=1 / 96)
"""

from .config import ContactConfig, RodMaterial, SolverADMMConfig
from .builder import GroomBuilder
from .model import Model
from .state import State, Control
from .solver_admm import SolverADMM
from .errors import SimulationDivergedError
from .contact.colliders import CapsuleCollider, ColliderSet, MeshCollider, PlaneCollider, SphereCollider
from .solvers.xpbd.solver import SolverXPBD, SolverXPBDConfig
from .groom.session import GroomingConfig, GroomingSession
from .solvers.shape.solver import ShapeRegion, SolverShape, SolverShapeConfig
from .groom.skinning import SkinningConfig, SkinningLBS, build_guides, compute_binding, error_colors, \
    interpolation_error, select_guides

__all__ = [
    "RodMaterial",
    "SolverADMMConfig",
    "GroomBuilder",
    "Model",
    "State",
    "Control",
    "SolverADMM",
    "SimulationDivergedError",
    "ContactConfig",
    "PlaneCollider",
    "SphereCollider",
    "CapsuleCollider",
    "MeshCollider",
    "ColliderSet",
    "SolverShape",
    "SolverXPBD",
    "SolverXPBDConfig",
    "GroomingConfig",
    "GroomingSession",
    "SolverShapeConfig",
    "ShapeRegion",
    "SkinningConfig",
    "SkinningLBS",
    "build_guides",
    "compute_binding",
    "select_guides",
    "interpolation_error",
    "error_colors",
    "init",
    "TAICHI_INIT_OPTIONS",
]
__version__ = "0.1.0"

#: ``ti.init`` keyword arguments the project runs, tests and measures with (:func:`init` applies them).
#:
#: ``opt_level=0`` switches off two of Taichi's own IR passes, its control-flow-graph optimization (store-to-load
#: forwarding, dead-store elimination) and its whole-kernel common-subexpression elimination; LLVM's optimizer
#: still runs in full.  Those passes grow faster than the kernels: on the 2-core VM (2026-12-07, cold cache) the
#: lanes schedule's first step took 27.6 s with them and 9.7 s without, and the grooming benchmark's cold first
#: frame (86,000 strands, sag-free) 58.6 s against 19.1-20.5 s in the same hour, while steps ran as fast (ADMM
#: 1,000 x 32, strand and lanes schedules, hairball 1,000 strands with contacts, grooming frame: within the VM's
#: noise, in alternated runs; BENCHMARKS.md, "Kernel compilation: Taichi's IR passes").  What changes: the machine code, hence the
#: rounding of some results (a run is bit-identical to itself, not to a run under ``ti.init``'s defaults).
TAICHI_INIT_OPTIONS = {"opt_level": 0}


def init(arch=None, **kwargs):
    """``ti.init(arch, **kwargs)`` with :data:`TAICHI_INIT_OPTIONS` where ``kwargs`` does not set them (the
    application's choice, called once per process as ``ti.init`` is; the package never calls it at import).
    ``arch=None`` is Taichi's own default (``TI_ARCH`` where set, else the CPU)."""
    import taichi as ti

    return ti.init(arch=arch, **{**TAICHI_INIT_OPTIONS, **kwargs})
