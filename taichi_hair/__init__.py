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
    "memoize_kernel_sources",
    "TAICHI_INIT_OPTIONS",
    "OFFLINE_CACHE_BYTES",
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


#: Taichi's offline kernel cache may hold this many bytes before it drops its least recently used quarter
#: (``offline_cache_max_size_of_files``; Taichi's own default is 100 MiB).  Taichi compiles a kernel for the sizes of
#: the fields it is given, so every groom size opened is a cold start and adds its own kernels: a grooming session's
#: 129 kernels took 5.6 MB (2,000 strands, measured 2026-12-07), and ``~/.cache/taichi`` on the 2-core VM stood at 96 %
#: of the 100 MiB after the sessions' runs of many sizes (past it, Taichi drops the least recently used quarter).
#: :func:`init` sets 1 GiB unless the call or ``TI_OFFLINE_CACHE_MAX_SIZE_OF_FILES`` sets another.
OFFLINE_CACHE_BYTES = 1 << 30


def init(arch=None, memoize_sources: bool = True, **kwargs):
    """``ti.init(arch, **kwargs)`` with :data:`TAICHI_INIT_OPTIONS` where ``kwargs`` does not set them (the
    application's choice, called once per process as ``ti.init`` is; the package never calls it at import).
    ``arch=None`` is Taichi's own default (``TI_ARCH`` where set, else the CPU).  ``memoize_sources``: first
    :func:`memoize_kernel_sources` (the same kernels, Taichi's frontend faster).  The offline kernel cache may grow
    to :data:`OFFLINE_CACHE_BYTES` unless ``kwargs`` or the environment says otherwise."""
    import os

    import taichi as ti

    if memoize_sources:
        memoize_kernel_sources()
    options = dict(TAICHI_INIT_OPTIONS)
    if not os.environ.get("TI_OFFLINE_CACHE_MAX_SIZE_OF_FILES"):
        options["offline_cache_max_size_of_files"] = OFFLINE_CACHE_BYTES
    return ti.init(arch=arch, **{**options, **kwargs})


def memoize_kernel_sources() -> bool:
    """Keep the source lines of each function Taichi 1.7's frontend reads, instead of reading them again each time;
    returns whether this Taichi has the function (else it is left as it is).  Once per process (a second call finds
    the memo in place); :func:`init` calls it.

    Taichi's frontend runs for every new kernel instance, even when the compiled kernel then comes from the offline
    cache, and each time it parses a kernel or inlines a ``ti.func`` it asks ``inspect`` for the function's source
    lines (``kernel_impl._get_tree_and_ctx``), which tokenizes the file's function again: 1,276 times in the
    grooming tool's first frame.  Kept per function object (``taichi.lang.kernel_impl.getsourcelines``, a fresh list
    each call); the AST is still parsed anew each time (Taichi annotates it).  The same source, so the same kernels
    and offline-cache keys.  A function redefined (a new object) is read anew; a file edited under a running process
    keeps the source its functions were first read with.  The other frontend saving, Taichi's position messages
    shortened, changes error messages and is the application's choice (``cli.common.lighter_kernel_positions``).
    Measured (BENCHMARKS.md, "Taichi's frontend: the sources read once"): the grooming session's first frame with a
    warm cache, 3,000 strands, 7.1-7.2 s -> 5.9-6.5 s (with the shortened messages, as the app runs) and
    10.7 -> 9.0 s (without)."""
    try:
        from taichi.lang import kernel_impl
    except ImportError:  # (another Taichi: left as it is)
        return False
    read = getattr(kernel_impl, "getsourcelines", None)
    if not callable(read):
        return False
    if hasattr(read, "__wrapped__"):  # (in place already)
        return True
    sources = {}

    def getsourcelines(obj):
        try:
            found = sources.get(obj)
        except TypeError:  # (not hashable: not kept)
            return read(obj)
        if found is None:
            found = sources[obj] = read(obj)
        return list(found[0]), found[1]

    getsourcelines.__wrapped__ = read
    kernel_impl.getsourcelines = getsourcelines
    return True
