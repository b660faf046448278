"""SolverXPBD: :mod:`.solver` (the step), :mod:`.constraints` (its Taichi kernels, quaternions)."""
