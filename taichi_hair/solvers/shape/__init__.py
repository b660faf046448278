"""SolverShape (Han & Harada, the origin of AMD TressFX): :mod:`.solver` (the step) and its Taichi kernels,
one module per job: :mod:`.integration` (Verlet, shock propagation, begin/end of step), :mod:`.constraints`
(frames, global and local shape constraints), :mod:`.lengths` (edge lengths, follow-the-leader) and
:mod:`.collisions` (collider projection)."""
