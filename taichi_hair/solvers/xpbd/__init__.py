"""SolverXPBD: :mod:`.solver` (the step), :mod:`.constraints` (its Taichi kernels; the quaternion algebra is
:mod:`taichi_hair.rotation`)."""
