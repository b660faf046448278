"""Cantilever validation (Daviet 2023 Sec. 5.1; Romero et al. 2021).

Naturally straight hair rods of lengths 0.5 cm to 128 cm are clamped
horizontally and left to sag under gravity, all in one quasistatic ADMM
simulation.  The aspect ratio H/W of each equilibrium centerline (H: vertical
drop root-to-tip, W: horizontal extent root-to-tip) is compared with the heavy
elastica (:mod:`taichi_hair.validation.elastica`, solved independently with
scipy) at the same Gamma = rho g A L^3 / (E I).

Discretisation: 2.5 mm per edge and at least 16 edges per rod (the paper's),
roots (vertices 0 and 1) clamped, boundary Voronoi rescaling on.

Choice written down: the paper runs 5,000 quasistatic iterations with its
constraint weight w0 = 25.  In this implementation the quasistatic ADMM
converges slowly at w0 = 25 (the penalty is 25x the local bending stiffness,
far above the stiffness of the rods' low bending modes), so the validation
uses a smaller w0 (default 0.2) and iterates until H/W stops changing; the
w0 sweep of ``benchmarks/cantilever_convergence.py`` records the trade-off.
The converged answer does not depend on w0 (ADMM's fixed point is the
equilibrium of the discrete model), only the number of iterations does.
w0 is always passed explicitly (the SolverADMMConfig default may change).

Accuracy: the bound is 2 % (max |rel error| over the 100 rods); the 1 % aim
is missed, and where and why is written down here.  Where: at Gamma < 1,
i.e. the rods shorter than ~5.3 cm, which have the minimum of 16 edges
(L <= 4 cm) or just above it: -1.81 % from 0.5 cm to 4 cm, decreasing to
-1.07 % at 5.3 cm (``benchmarks/results/cantilever/cantilever.csv``).  Why:
it is the discrete model's own small-deflection error, not the solver's:
the exact tip drop of the discrete clamped rod
(:func:`discrete_linear_tip_deflection`, closed form) is 0.98193 of the
continuum's at 16 edges, i.e. -1.807 %, which the simulation reproduces to
1e-5.  The error is O(h^2) (-0.30 % at 40 edges); 1 % needs 22 edges or more,
finer than the paper's 2.5 mm / 16-edge resolution used here.

Clamp convention (measured, ``benchmarks/probes/cantilever_clamp.py``,
:func:`clamp_convention_tip_drops`): vertices 0 and 1 are held, so edge 0 is
rigid.  Plain Voronoi lengths integrate the bending of vertex 1 over
[h/2, 3h/2] only: the rod is then an elastica clamped half an edge out, of
free length L - h/2.  The rescaling v_1* = e_0 + e_1/2 integrates it over
[0, 3h/2]: the rod is an elastica clamped at the root vertex, of free
length L (the tip-side mirror matters little: the moment vanishes at the
tip).  10 cm rod, 40 edges, Gamma = 6.80, tip drop:

    ====================  =========  ==============  ============
    (f32, converged)      drop [mm]  vs root vertex  vs half edge
    ====================  =========  ==============  ============
    elastica, root vertex   59.2775
    elastica, half edge     57.3957
    rescaling on            59.1287      -0.25 %        +3.02 %
    rescaling off           57.3867      -3.19 %        -0.02 %
    ====================  =========  ==============  ============

(small-deflection closed form of the discrete model at 40 edges: -0.30 %
against the root vertex with rescaling, -0.03 % against the half edge
without.)
"""

from __future__ import annotations

import csv
import os
import time
from dataclasses import dataclass, field

import numpy as np

from .elasticity_params import HAIR
from .elastica import cantilever_gamma, heavy_elastica_h_over_w

EDGE_LENGTH = 2.5e-3
MIN_EDGES = 16


def default_lengths(count: int = 100) -> np.ndarray:
    """Log-spaced rod lengths from 0.5 cm to 128 cm [m]."""
    return np.geomspace(0.005, 1.28, count)


def rod_vertex_count(length: float) -> int:
    return max(MIN_EDGES, int(round(length / EDGE_LENGTH))) + 1


@dataclass
class CantileverResult:
    lengths: np.ndarray
    gammas: np.ndarray
    h_over_w: np.ndarray
    reference: np.ndarray
    iterations: int
    seconds: float
    history: list = field(default_factory=list)  # (iterations, max |rel error|)

    @property
    def rel_error(self) -> np.ndarray:
        return self.h_over_w / self.reference - 1.0

    @property
    def max_abs_rel_error(self) -> float:
        return float(np.max(np.abs(self.rel_error)))


def build_cantilever_model(lengths):
    """One clamped, horizontal (+x) rod per length; gravity will be -y."""
    from ..builder import GroomBuilder
    from ..config import RodMaterial

    b = GroomBuilder()
    mat = RodMaterial(**HAIR)
    for i, L in enumerate(lengths):
        n = rod_vertex_count(L)
        # All roots at the origin: no contacts here, and small coordinates keep f32 precise.
        pts = np.c_[np.linspace(0.0, L, n), np.zeros(n), np.zeros(n)]
        b.add_strand(pts, mat, root_director=(0.0, 0.0, 1.0))
    return b.finalize()


def aspect_ratios(model, state) -> np.ndarray:
    """H/W root-to-tip for every strand (gravity along -y, rods along +x)."""
    x = state.vertex_position.to_numpy().astype(np.float64)
    starts = model.host["strand_vertex_start"]
    tips = starts + model.host["strand_vertex_count"] - 1
    H = x[starts, 1] - x[tips, 1]
    W = np.hypot(x[tips, 0] - x[starts, 0], x[tips, 2] - x[starts, 2])
    return H / W


def run_cantilever(lengths=None, w0: float = 0.2, max_iterations: int = 20000, chunk: int = 250,
                   tolerance: float = 5e-5, strain_measure: str = "korner", voronoi_rescaling: bool = True,
                   progress=None) -> CantileverResult:
    """Run the sweep until H/W changes by less than ``tolerance`` (relative) over one chunk.

    Args:
        lengths: rod lengths [m]; default :func:`default_lengths`.
        w0: ADMM weight scale (see the module docstring).
        max_iterations: stop after this many ADMM iterations in any case.
        chunk: iterations between convergence checks.
        tolerance: relative change of every H/W over one chunk below which we stop.
        progress: optional callable(iterations, max_change, max_error) for progress display.
    """
    from ..config import SolverADMMConfig
    from ..solver_admm import SolverADMM

    lengths = default_lengths() if lengths is None else np.asarray(lengths, dtype=np.float64)
    gammas = np.array([cantilever_gamma(L, HAIR["radius"], HAIR["density"], HAIR["youngs_modulus_bend"])
                       for L in lengths])
    reference = heavy_elastica_h_over_w(gammas)
    model = build_cantilever_model(lengths)
    state, control = model.state(), model.control()
    control.gravity = (0.0, -9.81, 0.0)
    cfg = SolverADMMConfig(iterations=chunk, mode="quasistatic", w0=w0, strain_measure=strain_measure,
                           voronoi_rescaling=voronoi_rescaling)
    solver = SolverADMM(model, cfg)
    prev = aspect_ratios(model, state)
    history = []
    t0 = time.perf_counter()
    it = 0
    while it < max_iterations:
        solver.step(state, control, 1.0)
        it += chunk
        hw = aspect_ratios(model, state)
        change = float(np.max(np.abs(hw - prev) / np.maximum(np.abs(hw), 1e-30)))
        err = float(np.max(np.abs(hw / reference - 1.0)))
        history.append((it, err, change))
        if progress is not None:
            progress(it, change, err)
        prev = hw
        if change < tolerance:
            break
    seconds = time.perf_counter() - t0
    return CantileverResult(lengths, gammas, prev, reference, it, seconds, history)


def write_outputs(result: CantileverResult, out_dir: str) -> tuple[str, str]:
    """Write ``cantilever.csv`` and ``cantilever.png`` into ``out_dir``; return their paths."""
    os.makedirs(out_dir, exist_ok=True)
    csv_path = os.path.join(out_dir, "cantilever.csv")
    tmp = csv_path + ".tmp"
    with open(tmp, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["length_m", "gamma", "h_over_w", "h_over_w_reference", "rel_error"])
        for L, g, hw, ref, e in zip(result.lengths, result.gammas, result.h_over_w, result.reference,
                                    result.rel_error):
            w.writerow([f"{L:.6g}", f"{g:.6g}", f"{hw:.8g}", f"{ref:.8g}", f"{e:.6g}"])
    os.replace(tmp, csv_path)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .elastica import heavy_elastica_h_over_w as ref_curve

    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(7, 7), sharex=True, gridspec_kw={"height_ratios": [3, 1.3]})
    g = np.geomspace(result.gammas.min() / 2, result.gammas.max() * 2, 300)
    ax.loglog(g, ref_curve(g), "k-", lw=1.2, label="heavy elastica (scipy reference)")
    ax.loglog(result.gammas, result.h_over_w, "o", ms=4, mfc="none", color="C3", label="taichi-hair ADMM (f32)")
    ax.set_ylabel("H / W")
    ax.set_title("Cantilever: 2.5 mm edges, >= 16 edges, quasistatic ADMM")
    ax.legend()
    ax.grid(True, which="both", alpha=0.3)
    ax2.semilogx(result.gammas, 100 * result.rel_error, "o-", ms=3, color="C3", label="simulation vs elastica")
    # The discrete model's own small-deflection answer (closed form): what a converged
    # simulation must give for small Gamma, whatever the solver.
    small = result.gammas < 0.3
    if np.any(small):
        disc = [8.0 * discrete_linear_tip_deflection(rod_vertex_count(L) - 1) - 1.0 for L in result.lengths[small]]
        ax2.semilogx(result.gammas[small], 100 * np.array(disc), "k--", lw=1,
                     label="exact discrete model, small deflection")
    ax2.legend(fontsize=8, loc="lower right")
    ax2.axhspan(-2, 2, color="0.9", zorder=0)
    ax2.axhline(0, color="k", lw=0.8)
    ax2.set_xlabel("Gamma = rho g A L^3 / (E I)")
    ax2.set_ylabel("rel. error [%]")
    ax2.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    png_path = os.path.join(out_dir, "cantilever.png")
    fig.savefig(png_path + ".tmp.png", dpi=120)
    plt.close(fig)
    os.replace(png_path + ".tmp.png", png_path)
    return csv_path, png_path


def discrete_linear_tip_deflection(edge_count: int, voronoi_rescaling: bool = True) -> float:
    """Exact small-deflection tip drop of the discrete clamped rod, in units of q L^4 / (E I).

    Uniform edges h = L/N, vertices 0 and 1 clamped, hinges at vertices
    1..N-1 with bending stiffness E I / v_k (v_k = h, or 1.5 h at the second and
    penultimate vertices with rescaling), lumped loads q h (q h / 2 at the
    tip).  Hinge k turns by M_k v_k / (E I), M_k the moment of the loads
    beyond it, and the tip drops by sum_k phi_k (s_N - s_k).  The continuum
    value is 1/8; the difference is the discretisation error of the model
    itself, which a converged simulation must reproduce.
    """
    N = int(edge_count)
    h = 1.0 / N
    s = np.arange(N + 1) * h
    F = np.full(N + 1, h)
    F[-1] = h / 2
    v = np.full(N + 1, h)
    if voronoi_rescaling:
        v[1] = 1.5 * h
        v[N - 1] = 1.5 * h if N > 2 else 2.0 * h
    total = 0.0
    for k in range(1, N):
        M = float(np.sum(F[k + 1:] * (s[k + 1:] - s[k])))
        total += M * v[k] * (s[N] - s[k])
    return total


@dataclass
class ClampConventionResult:
    """Tip drop of one clamped rod, with and without the boundary Voronoi rescaling, against the elastica
    clamped at the root vertex (free length L) and at half an edge (free length L - h/2)."""
    length: float
    edge_count: int
    gamma: float
    drop_rescaled: float          # simulated tip drop [m], SolverADMMConfig.voronoi_rescaling = True
    drop_plain: float             # idem, False
    drop_root_vertex: float       # elastica clamped at vertex 0 [m]
    drop_half_edge: float         # elastica clamped at s = h/2 [m]
    iterations: tuple             # ADMM iterations run (rescaled, plain)

    def table(self) -> str:
        rows = [f"tip drop of the {100 * self.length:g} cm rod ({self.edge_count} edges, Gamma = {self.gamma:.3f})",
                f"{'':24} {'drop [mm]':>10} {'vs root vertex':>15} {'vs half edge':>13}",
                f"{'elastica, root vertex':24} {1e3 * self.drop_root_vertex:10.4f}",
                f"{'elastica, half edge':24} {1e3 * self.drop_half_edge:10.4f}"]
        for name, d in (("sim, rescaling on", self.drop_rescaled), ("sim, rescaling off", self.drop_plain)):
            rows.append(f"{name:24} {1e3 * d:10.4f} {100 * (d / self.drop_root_vertex - 1):+14.2f}% "
                        f"{100 * (d / self.drop_half_edge - 1):+12.2f}%")
        return "\n".join(rows)


def clamp_convention_tip_drops(length: float = 0.1, w0: float = 0.2, max_iterations: int = 20000,
                               chunk: int = 250, tolerance: float = 1e-6) -> ClampConventionResult:
    """Which clamp the boundary Voronoi rescaling amounts to (see the module docstring), measured.

    One rod of ``length`` (edges of EDGE_LENGTH), one Model, two states, two quasistatic solvers (rescaling
    on / off), each iterated until the tip drop changes by less than ``tolerance`` (relative) over ``chunk``
    iterations.  The elastica clamped at half an edge is the heavy elastica of free length
    L' = L - h/2 (Gamma' = Gamma (L'/L)^3) behind a rigid horizontal stub of h/2, so its drop is
    L' H/L(Gamma').
    """
    from ..config import SolverADMMConfig
    from ..solver_admm import SolverADMM
    from .elastica import solve_heavy_elastica

    model = build_cantilever_model([length])
    n_edges = rod_vertex_count(length) - 1
    h = length / n_edges
    gamma = cantilever_gamma(length, HAIR["radius"], HAIR["density"], HAIR["youngs_modulus_bend"])
    short = length - 0.5 * h
    gamma_short = gamma * (short / length) ** 3
    drop_root = length * solve_heavy_elastica(gamma).height
    drop_half = short * solve_heavy_elastica(gamma_short).height
    drops, its = [], []
    for rescale in (True, False):
        state, control = model.state(), model.control()
        control.gravity = (0.0, -9.81, 0.0)
        solver = SolverADMM(model, SolverADMMConfig(iterations=chunk, mode="quasistatic", w0=w0,
                                                    voronoi_rescaling=rescale))
        prev, it = 0.0, 0
        while it < max_iterations:
            solver.step(state, control, 1.0)
            it += chunk
            x = state.vertex_position.to_numpy().astype(np.float64)
            drop = float(x[0, 1] - x[-1, 1])
            if abs(drop - prev) < tolerance * abs(drop):
                break
            prev = drop
        drops.append(drop)
        its.append(it)
    return ClampConventionResult(length, n_edges, gamma, drops[0], drops[1], drop_root, drop_half, tuple(its))


def format_summary(result: CantileverResult) -> str:
    e = result.rel_error
    i = int(np.argmax(np.abs(e)))
    return (f"cantilever: {len(result.lengths)} rods, {result.iterations} ADMM iterations in {result.seconds:.1f} s; "
            f"max |rel error| {100 * abs(e[i]):.2f}% at L = {100 * result.lengths[i]:.2f} cm "
            f"(Gamma = {result.gammas[i]:.3g}); mean |rel error| {100 * float(np.mean(np.abs(e))):.2f}%")
