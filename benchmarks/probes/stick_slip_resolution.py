"""Stick-slip: median onset error over mu in 0.1-0.3 and the simulated mu_c against the heavy elastica, for
reduced substep / iteration counts (what the tests can afford): ``python3 benchmarks/probes/stick_slip_resolution.py``.
Each configuration: mu in 0.1..0.3 step 0.05 plus 0.01 steps over the reference mu_c +- 0.02, pushed to 0.36 L.
Optional arguments: SUBSTEPSxITERATIONS ... (default 240x150 120x150 240x60)."""
import sys
import time

import numpy as np

DEFAULT_CONFIGS = [(240, 150), (120, 150), (240, 60)]


def run(configs) -> None:
    from taichi_hair.validation.stick_slip import reference_curve, run_stick_slip, stick_slip_gamma

    _, _, mu_c, _ = reference_curve(stick_slip_gamma(0.1), 0.36)
    mus = np.round(np.r_[np.arange(0.1, 0.301, 0.05), np.round(mu_c, 2) + np.arange(-0.02, 0.021, 0.01)], 4)
    for substeps, iterations in configs:
        t = time.perf_counter()
        r = run_stick_slip(mus=mus, substeps=substeps, max_displacement=0.36, iterations=iterations)
        mc, hw = r.mu_critical
        print(f"substeps {substeps} (step {0.36 / substeps:.4f} L) x {iterations} iterations: "
              f"median |err| {100 * r.median_abs_error():.2f}%, errors "
              + " ".join(f"{m:.2f}:{100 * e:+.1f}%" for m, e in zip(r.mus, r.rel_error) if np.isfinite(e))
              + f"; slid {[float(m) for m, c in zip(r.mus, r.critical) if np.isfinite(c)]}; mu_c {mc:.3f} +- {hw:.3f} "
              f"(reference {r.mu_critical_reference:.4f}); {time.perf_counter() - t:.0f} s", flush=True)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    configs = [(int(a), int(b)) for a, b in (c.split("x") for c in argv)] or DEFAULT_CONFIGS
    import taichi as ti

    import taichi_hair

    taichi_hair.init(arch=ti.cpu, default_fp=ti.f32, offline_cache=True, log_level=ti.WARN)
    run(configs)
    return 0


if __name__ == "__main__":
    sys.exit(main())
