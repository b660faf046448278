"""Solvers other than the main ADMM one (which lives at the top: :mod:`taichi_hair.solver_admm`), and
drivers that step any solver.

* :mod:`.shape`: :class:`SolverShape`, Han & Harada's TressFX-style solver (Verlet, global and local
  shape constraints, edge lengths);
* :mod:`.xpbd`: :class:`SolverXPBD`, extended position-based dynamics on Cosserat rods (a baseline);
* :mod:`.equilibrium`: quasistatic stepping to an equilibrium.
"""
