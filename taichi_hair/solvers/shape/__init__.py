"""SolverShape (Han & Harada, the origin of AMD TressFX): :mod:`.solver` (the step), :mod:`.constraints`
(its Taichi kernels: integration, shape and length constraints, collisions)."""
