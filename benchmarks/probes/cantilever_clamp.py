"""Which clamp the boundary Voronoi rescaling amounts to: the 10 cm cantilever's tip drop with and without
SolverADMMConfig.voronoi_rescaling, against the heavy elastica clamped at the root vertex and at half an edge.
``python3 benchmarks/probes/cantilever_clamp.py`` (output in benchmarks/results/validation/cantilever_clamp.txt)."""
import sys
import time


def main(argv=None) -> int:
    import taichi as ti

    import taichi_hair

    taichi_hair.init(arch=ti.cpu, default_fp=ti.f32, offline_cache=True, log_level=ti.WARN)
    from taichi_hair.validation.cantilever import clamp_convention_tip_drops

    t = time.perf_counter()
    r = clamp_convention_tip_drops(0.1)
    print(r.table())
    print(f"quasistatic ADMM, w0 = 0.2, f32, CPU; iterations (on, off) {r.iterations}, "
          f"stop at a relative change < 1e-6 per 250 iterations; {time.perf_counter() - t:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
