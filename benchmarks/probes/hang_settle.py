"""Does the hang scene come to rest?  (issue 12 item 5: "a dynamic run of the hang scene ... settles within 1 %
of its equilibrium in 2 s of simulated time").

Run from the repository root:
    python3 benchmarks/probes/hang_settle.py [STRANDS] [DURATION_S] [drag=RATE_PER_S] [W0 ...]

The built-in hang scene's groom (taichi_hair.scene.builtin.build_hang) with the sphere held still (no nod), its
default material (no strain-rate damping, no air drag: backward Euler's own damping only), dynamic ADMM at
dt = 1/96 s and 10 iterations (optional air drag: a velocity relaxation rate, as the stability atlas),
released from the groom as built.  The reference is the same Model's
equilibrium (quasistatic ADMM, w0 = 1, 3,000 steps of 10 iterations).  Prints, per w0, the largest and the
median tip distance to the equilibrium after DURATION_S (default 2), relative to the strand length.
A diagnostic, not a benchmark.
"""

import sys

import numpy as np


def parse(argv):
    """(strands, duration, drag, w0s) from the command line's words."""
    strands = int(argv[0]) if len(argv) > 0 else 30
    duration = float(argv[1]) if len(argv) > 1 else 2.0
    drag = float(next((a[5:] for a in argv[2:] if a.startswith("drag=")), 0.0))
    w0s = [float(a) for a in argv[2:] if not a.startswith("drag=")] or [25.0, 5.0, 1.0]
    return strands, duration, drag, w0s


def run(strands: int, duration: float, drag: float, w0s) -> None:
    from taichi_hair import SolverADMM, SolverADMMConfig
    from taichi_hair.scene.builtin import HangScene, build_hang

    scene = HangScene(strands=strands)
    model = build_hang(scene)
    h = model.host
    tips = h["strand_vertex_start"] + h["strand_vertex_count"] - 1
    length = np.array([h["edge_rest_length"][s:s + c - 1].sum()
                       for s, c in zip(h["strand_vertex_start"], h["strand_vertex_count"])])
    st, ct = model.state(), model.control()
    qs = SolverADMM(model, SolverADMMConfig(mode="quasistatic", w0=1.0, iterations=10))
    for _ in range(3000):
        qs.step(st, ct, 1.0)
    x_eq = st.positions().astype(np.float64)
    qs.step(st, ct, 1.0)
    print(f"{strands} strands; equilibrium tip drift in its last step / L: max "
          f"{(np.linalg.norm(st.positions()[tips] - x_eq[tips], axis=1) / length).max():.1e}")
    dt = 1 / 96
    for w0 in w0s:
        rho_a = model.materials[0].density * model.materials[0].area
        solver = SolverADMM(model, SolverADMMConfig(iterations=10, w0=w0, air_viscosity=drag * rho_a))
        model.reset_state(st)
        for _ in range(int(round(duration / dt))):
            solver.step(st, ct, dt)
        err = np.linalg.norm(st.positions()[tips] - x_eq[tips], axis=1) / length
        print(f"w0 = {w0:5g}, drag {drag} /s: after {duration} s tip distance to equilibrium / L: max {err.max():.2e}, "
              f"median {np.median(err):.2e}", flush=True)


def main(argv=None) -> int:
    args = parse(sys.argv[1:] if argv is None else list(argv))
    import taichi as ti

    import taichi_hair

    taichi_hair.init(arch=ti.cpu, log_level=ti.WARN)
    run(*args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
