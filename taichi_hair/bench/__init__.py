"""Speed-against-accuracy studies: ``taichi-hair bench pareto`` and ``taichi-hair bench stability``."""
