"""taichi-hair: hair simulation on Taichi.

Discrete Elastic Rods integrated with the ADMM local-global solver of
Daviet 2023, "Interactive Hair Simulation on the GPU using ADMM".

Importing this package is light: it does not call ``ti.init``, open a window or
import plotting libraries.  The application (or the test session) chooses the
Taichi arch and the floating-point precision, e.g. ``ti.init(arch=ti.cpu)`` for
single precision or ``ti.init(arch=ti.cpu, default_fp=ti.f64)`` for double.

Typical use::

    import taichi as ti
    import taichi_hair as th
    ti.init(arch=ti.cpu)
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
]
__version__ = "0.1.0"
