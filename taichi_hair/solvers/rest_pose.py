"""Sag-free rest pose ("inverse statics", issue 14): rest strains that make the authored shape an equilibrium.

A groom file carries a shape x*, not a rest state; read as authored (rest = x*) every strand sags under
gravity.  Here we solve for the rest quantities of the simulated model (DER + ADMM, Daviet 2023 Sec. 4.1)
so that x* is a static equilibrium under gravity.

The discrete statics, exactly those of the simulated model
------------------------------------------------------------
The elastic energy of a strand is E = sum_pairs 1/2 (kappa_i - kappa_bar_i)^T S_i (kappa_i - kappa_bar_i)
+ sum_edges 1/2 k_j eps_j^2 with S_i = E_b K / v_i* (the solver's ``pair_bend_stiffness``) and
kappa_i(e_{i-1}, e_i, theta) the solver's strain measure.  Write mu_i = S_i (kappa_i - kappa_bar_i) (the
pair's bending moment [J], components on its material frame) and G_j = dE/de_j (the force of edge j [N]).
With e_j = x_{j+1} - x_j, dE/dx_i = G_{i-1} - G_i, so the equilibrium of every free vertex,
-dE/dx_i + f_i = 0 (f_i the weight m_i g, plus contact forces), gives tip to root

    G_{m-2} = f_{m-1},   G_{j-1} = G_j + f_j:   G_j = sum_{i > j} f_i   (the load carried beyond edge j),

and G_j = k_j eps_j d eps_j/de_j + J_{b,j}^T mu_j + J_{a,j+1}^T mu_{j+1}, J the strain Jacobians of
:mod:`taichi_hair.strains` (edge b of pair j and edge a of pair j+1 are both e_j).  Both bending terms are
perpendicular to the edge (the strains do not depend on edge lengths), so

* the tangential part of G_j is the tension: it sets the rest length (eps_j(|e_j*|, e_bar_j) such that
  k eps deps/de . t = G_j . t; ~1e-6 of the length for hair, more for soft test materials);
* its perpendicular part and the twist balance of edge j, dkappa_j/dtheta_b . mu_j +
  dkappa_{j+1}/dtheta_a . mu_{j+1} = 0, are three equations for mu_j once mu_{j+1} is known.

So the moments follow from the tip to the root, one 3x3 solve per pair (NumPy, float64, all strands at
once), and kappa_bar_i = kappa_i(x*) - S_i^-1 mu_i.  With the twist kept (SolverADMM solves it whenever a
rest moment is set: a curved rest shape couples twist and bending) the balance is exact for the solver's
energy, not a continuum approximation; the test pins it against the solver's own forces and against the
hand-computed moment of a horizontal strand.

What is stored: the moments mu (``Model.host["pair_rest_moment"]``, [J]), not kappa_bar, because mu is
what the statics fix and kappa_bar = kappa(x*) - mu / S follows from the solver's stiffness (with or without
the boundary Voronoi rescaling); the strain measure the moments were solved for is stored beside them
(``rest_pose_measure``) and SolverADMM refuses another.

Choices where the problem is silent (written down here and in the README):

* **Contacts carry nothing at rest.**  Every strand holds its own weight; contact forces at x* are zero
  (inside every Coulomb cone), so x* stays an equilibrium with hair-hair and body contacts switched on,
  and contacts act only against a disturbance.  It is the rule with no choice left to make; its price is
  that a strand lying horizontally needs a large rest curvature: 30 cm of human hair held horizontally
  needs a rest turn of ~1.4 rad per 2.5 mm edge at the root (the strand is reported as not held), and
  a TressFX ponytail tied 4 cm from the head (assets/ponytail, 1.9 cm edges) holds only 60 of its 255
  strands with 50 um hair: a real tail is carried by its neighbours.  ``ponytail.toml`` models each guide
  as the wisp of 5 hairs TressFX draws around it (r = 110 um, a bonded wisp's bending stiffness), and then
  all 255 are held.  Strands authored closer than two radii keep that distance in contact
  (``ContactConfig.keep_rest_overlaps``), so the packed tail is not pushed apart either.
* **A strand is "held"** when no rest strain moves more than ``max_rest_change`` from the authored one
  (|kappa_bar_i - kappa_i(x*)|, about 60 degrees per vertex by default), every rest turn |kappa_bar_i|
  stays below ``max_rest_turn`` (Korner's strain is 2 sin(phi/2): it cannot exceed 2), and the residual of
  the statics is below ``residual_tolerance`` of the strand's weight.  A strand not held keeps its
  authored rest pose and is reported by index with its turns; the rest of the groom is solved.
* Free-root strands have no equilibrium under gravity: they keep their authored rest pose (reported).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..model import pair_voronoi_length

#: Host keys the rest pose adds to ``Model.host``.
MOMENT_KEY = "pair_rest_moment"
MEASURE_KEY = "rest_pose_measure"


@dataclass
class RestPoseConfig:
    """How :func:`solve_rest_pose` solves.

    Attributes:
        max_rest_change: largest change |kappa_bar - kappa(x*)| of a pair's rest strain for the strand to
            count as held [-] (the Korner strain is 2 sin(phi/2) of the turn phi between two edges' frames:
            1.0 is a change of about 60 degrees per vertex, already a hairpin at the groom's resolution).
        max_rest_turn: largest |kappa_bar| [-]: Korner's strain cannot pass 2 (a full reversal); 1.9 keeps
            the rest curve constructible with margin.
        residual_tolerance: largest force residual of a vertex, relative to the strand's weight, for the
            strand to count as held [-].
        rest_lengths: also solve the rest lengths (the tension's stretch); False keeps the authored lengths.
        support_for: with a body support (``solve_rest_pose(support=...)``), which strands it may carry:
            ``"unheld"`` those that cannot hold their own weight, ``"all"`` every strand that touches it.
    """

    max_rest_change: float = 1.0
    max_rest_turn: float = 1.9
    residual_tolerance: float = 1.0e-6
    rest_lengths: bool = True
    support_for: str = "unheld"

    def __post_init__(self):
        if not (0.0 < self.max_rest_turn <= 2.0):
            raise ValueError(f"RestPoseConfig.max_rest_turn must be in (0, 2], got {self.max_rest_turn!r}")
        if not (self.max_rest_change > 0.0):
            raise ValueError(f"RestPoseConfig.max_rest_change must be > 0, got {self.max_rest_change!r}")
        if self.support_for not in ("unheld", "all"):
            raise ValueError(f"RestPoseConfig.support_for must be 'unheld' or 'all', got {self.support_for!r}")
        if not (self.residual_tolerance > 0.0):
            raise ValueError(f"RestPoseConfig.residual_tolerance must be > 0, got {self.residual_tolerance!r}")


@dataclass
class RestPoseResult:
    """What :func:`solve_rest_pose` found.  Arrays have shape (vertex_count, ...) or (strand_count,)."""

    #: Rest bending moment mu_i of every pair [J] (zero on strands not held and on inactive pairs).
    pair_rest_moment: np.ndarray
    #: Rest strain kappa_bar_i for the stiffness of the config solved for [-].
    pair_rest_strain: np.ndarray
    #: Rest length of every edge [m] (the authored one where not solved).
    edge_rest_length: np.ndarray
    #: Largest |kappa_bar_i| of each strand [-].
    strand_rest_turn: np.ndarray
    #: Largest vertex force residual of each strand over its weight [-] (NaN where not solved).
    strand_residual: np.ndarray
    #: Strands that keep their authored rest pose, with the reason: [(strand, message)].
    unheld: list = field(default_factory=list)
    #: Contact forces the body carries at x* (vertex_count, 3) [N] (None without a support; zero on strands
    #: not held).
    vertex_support_force: np.ndarray | None = None
    #: Held strands whose support uses all the friction somewhere (|f_t| = mu f_n): they stay up by friction.
    friction_limited: list = field(default_factory=list)
    #: Largest vertex drift of each strand in :func:`check_stability`'s run [m] (None until it ran).
    strand_stability_drift: np.ndarray | None = None
    #: Strands held (an equilibrium) but unstable, from :func:`check_stability`: [(strand, message)].
    unstable: list = field(default_factory=list)
    #: Strain measure the moments were solved for ("korner" or "bergou").
    measure: str = "korner"
    seconds: float = 0.0

    @property
    def held_count(self) -> int:
        return int(self.strand_rest_turn.shape[0]) - len(self.unheld)

    def summary(self) -> str:
        ns = self.strand_rest_turn.shape[0]
        ok = np.isfinite(self.strand_residual)
        res = float(np.nanmax(self.strand_residual)) if ok.any() else float("nan")
        line = (f"rest pose: {self.held_count}/{ns} strands sag-free, largest rest turn "
                f"{float(self.strand_rest_turn.max()):.3g}, largest residual {res:.2e} of the weight, "
                f"{self.seconds:.2f} s")
        if self.unheld:
            s, why = self.unheld[0]
            more = f" (and {len(self.unheld) - 1} more)" if len(self.unheld) > 1 else ""
            line += f"; strand {s} keeps its authored rest pose: {why}{more}"
        if self.unstable:
            s, why = self.unstable[0]
            line += f"; {len(self.unstable)} held strands are unstable equilibria (strand {s}: {why})"
        return line


# --------------------------------------------------------------------------- strains in NumPy (float64)
def _cross_matrix(v: np.ndarray) -> np.ndarray:
    """[v]x for a (k, 3) array: (k, 3, 3)."""
    z = np.zeros(v.shape[0])
    return np.stack([np.stack([z, -v[:, 2], v[:, 1]], 1), np.stack([v[:, 2], z, -v[:, 0]], 1),
                     np.stack([-v[:, 1], v[:, 0], z], 1)], 1)


def _dot(a, b):
    return np.sum(a * b, axis=-1)


def rest_frames(host: dict):
    """Material frames (m1, m2, t) and lengths of every edge at the authored shape, float64, (n, 3) each.

    The same frames the solver builds at rest (``Model.reset_state``): space-parallel reference directors
    ``edge_rest_director`` turned by the rest twist ``edge_rest_twist`` about the tangent.
    """
    x = np.asarray(host["vertex_rest_position"], np.float64)
    t = np.asarray(host["edge_rest_tangent"], np.float64)
    d1 = np.asarray(host["edge_rest_director"], np.float64)
    th = np.asarray(host["edge_rest_twist"], np.float64)
    d2 = np.cross(t, d1)
    c, s = np.cos(th)[:, None], np.sin(th)[:, None]
    m1 = c * d1 + s * d2
    m2 = -s * d1 + c * d2
    e = np.zeros_like(x)
    e[:-1] = x[1:] - x[:-1]
    length = np.asarray(host["edge_rest_length"], np.float64)
    return m1, m2, t, e, length


def pair_strain_jacobians(measure: str, m1a, m2a, ta, la, m1b, m2b, tb, lb, twist=None):
    """Strain kappa (k, 3), edge Jacobians J_a, J_b (k, 3, 3) and twist derivatives dk/dtheta_a, dk/dtheta_b
    (k, 3) of k edge pairs: NumPy float64 twins of :mod:`taichi_hair.strains` (tested against them)."""
    if measure == "korner":
        r11, r22, r33 = _dot(m1a, m1b), _dot(m2a, m2b), _dot(ta, tb)
        w = 0.5 * np.sqrt(np.maximum(1.0 + r11 + r22 + r33, 1e-24))
        v = np.stack([_dot(ta, m2b) - _dot(m2a, tb), _dot(m1a, tb) - _dot(ta, m1b),
                      _dot(m2a, m1b) - _dot(m1a, m2b)], 1) / (4.0 * w[:, None])
        kappa = 2.0 * v
        vx = _cross_matrix(v)
        eye = np.eye(3)[None]
        Aa = np.stack([-m2a, m1a, np.zeros_like(m1a)], 1) / la[:, None, None]
        Ab = np.stack([-m2b, m1b, np.zeros_like(m1b)], 1) / lb[:, None, None]
        Ja = -np.matmul(w[:, None, None] * eye - vx, Aa)
        Jb = np.matmul(w[:, None, None] * eye + vx, Ab)
        dk_da = np.stack([v[:, 1], -v[:, 0], -w], 1)
        dk_db = np.stack([v[:, 1], -v[:, 0], w], 1)
        return kappa, Ja, Jb, dk_da, dk_db
    if measure != "bergou":
        raise ValueError(f"strain measure must be 'korner' or 'bergou', got {measure!r}")
    chi = 1.0 + _dot(ta, tb)
    kb = 2.0 * np.cross(ta, tb) / chi[:, None]
    tt = (ta + tb) / chi[:, None]
    d1t = (m1a + m1b) / chi[:, None]
    d2t = (m2a + m2b) / chi[:, None]
    k1 = 0.5 * _dot(kb, m1a + m1b)
    k2 = 0.5 * _dot(kb, m2a + m2b)
    k3 = np.zeros_like(k1) if twist is None else twist
    kappa = np.stack([k1, k2, k3], 1)
    Ja = np.stack([-k1[:, None] * tt + np.cross(tb, d1t), -k2[:, None] * tt + np.cross(tb, d2t), 0.5 * kb],
                  1) / la[:, None, None]
    Jb = np.stack([-k1[:, None] * tt - np.cross(ta, d1t), -k2[:, None] * tt - np.cross(ta, d2t), 0.5 * kb],
                  1) / lb[:, None, None]
    dk_da = np.stack([0.5 * _dot(kb, m2a), -0.5 * _dot(kb, m1a), -np.ones_like(k1)], 1)
    dk_db = np.stack([0.5 * _dot(kb, m2b), -0.5 * _dot(kb, m1b), np.ones_like(k1)], 1)
    return kappa, Ja, Jb, dk_da, dk_db


def _rest_length_for_tension(measure: str, n: np.ndarray, tension: np.ndarray, ea: np.ndarray) -> np.ndarray:
    """Rest length e_bar with which an edge of length n carries ``tension`` [N] (ea = E_s A [N]).

    Linear strain: T = E_s A (n / e_bar - 1).  Hyperelastic (Korner): eps = (r^2 - 1) / 2 with r = n / e_bar,
    T = k eps deps/de . t = E_s A r (r^2 - 1) / 2, solved for r by Newton from r = 1 + T / E_s A.
    """
    tau = tension / ea
    r = 1.0 + tau
    if measure == "korner":
        for _ in range(8):
            f = 0.5 * r * (r * r - 1.0) - tau
            r = r - f / (1.5 * r * r - 0.5)
    return n / r


def _edge_loads(h: dict, force: np.ndarray) -> np.ndarray:
    """G_j = sum_{k = j+1}^{tip} f_k for every edge slot j (0 on ghost slots) [N]: a reversed cumulative
    sum over the flat array, less what lies beyond the strand's tip."""
    n = force.shape[0]
    starts, counts = h["strand_vertex_start"], h["strand_vertex_count"]
    strand_of = h["vertex_strand"]
    csum = np.cumsum(force[::-1], axis=0)[::-1]        # csum[i] = sum_{k >= i} f_k
    end = starts + counts                               # one past each strand's tip
    after_tip = np.zeros((starts.shape[0], 3))
    inside = end < n
    after_tip[inside] = csum[end[inside]]
    nxt = np.zeros((n, 3))
    nxt[:-1] = csum[1:]
    G = nxt - after_tip[strand_of]
    G[h["vertex_local_index"] == counts[strand_of] - 1] = 0.0
    return G


def _pair_jacobians(h: dict, measure: str):
    """Strains kappa, edge Jacobians J_a, J_b and twist derivatives of every active pair at the authored
    shape x* (pair i: edges i-1, i), zero elsewhere; shapes (n, 3), (n, 3, 3), (n, 3, 3), (n, 3), (n, 3)."""
    n = h["vertex_strand"].shape[0]
    m1, m2, t, e, _ = rest_frames(h)
    nlen = np.linalg.norm(e, axis=1)
    ip = np.nonzero(h["pair_is_active"])[0]
    kappa, dka, dkb = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3))
    Ja, Jb = np.zeros((n, 3, 3)), np.zeros((n, 3, 3))
    a = ip - 1
    th = np.asarray(h["edge_rest_twist"], np.float64)
    kappa[ip], Ja[ip], Jb[ip], dka[ip], dkb[ip] = pair_strain_jacobians(
        measure, m1[a], m2[a], t[a], nlen[a], m1[ip], m2[ip], t[ip], nlen[ip], twist=th[ip] - th[a])
    return kappa, Ja, Jb, dka, dkb


def equilibrium_residual(model, solver_config=None, gravity=(0.0, -9.81, 0.0), moments=None) -> np.ndarray:
    """How far the authored shape is from an equilibrium of the Model as it is (its rest moments, zero for an
    authored rest pose): per strand, the largest unbalanced force of a vertex (bending and twist; the tension
    is carried by the stretch) over the strand's weight [-], NaN for free strands.  About 1 for an authored
    rest pose under gravity (nothing holds the weight), round-off for a solved sag-free one.  ``moments``: other
    rest moments than the Model's (n, 3) [J] (a rest curve read from a file, before it is applied)."""
    from ..config import SolverADMMConfig

    scfg = solver_config or SolverADMMConfig()
    h = model.host
    g = np.asarray(gravity, np.float64).reshape(3)
    force = np.asarray(h["vertex_mass"], np.float64)[:, None] * g[None, :]
    G = _edge_loads(h, force)
    kappa, Ja, Jb, dka, dkb = _pair_jacobians(h, scfg.strain_measure)
    t = np.asarray(h["edge_rest_tangent"], np.float64)
    mu = h.get(MOMENT_KEY) if moments is None else moments
    mu = np.zeros((model.vertex_count, 3)) if mu is None else np.asarray(mu, np.float64)
    local = h["vertex_local_index"]
    strand_of = h["vertex_strand"]
    ghost = local == h["strand_vertex_count"][strand_of] - 1
    resid = _statics_residual(h, G, mu, Ja, Jb, dka, dkb, t, h["pair_is_active"].astype(bool), ghost, local)
    ns = model.strand_count
    weight = np.maximum(np.bincount(strand_of, weights=np.linalg.norm(force, axis=1), minlength=ns), 1e-300)
    r = np.zeros(ns)
    np.maximum.at(r, strand_of, resid)
    out = r / weight
    out[h["strand_body"] < 0] = np.nan
    return out


# --------------------------------------------------------------------------- the solve
def _tip_to_root_moments(h, G, t, Ja, Jb, dka, dkb, solve_s) -> np.ndarray:
    """The moments mu (vertex_count, 3) [J] that balance the edge loads G of the strands ``solve_s``, tip to root:
    edge j (local m-2 down to 1) fixes mu_j from G_j and mu_{j+1} (module docstring).  Linear in G."""
    local = h["vertex_local_index"]
    starts, counts = h["strand_vertex_start"], h["strand_vertex_count"]
    count_v = counts[h["vertex_strand"]]
    mu = np.zeros((G.shape[0], 3))
    max_local = int(counts[solve_s].max()) if solve_s.any() else 0
    for j in range(max_local - 2, 0, -1):
        sel = solve_s & (counts - 2 >= j)
        idx = starts[sel] + j                              # edge j of each strand = pair j's edge b
        P = G[idx].copy()
        tau = np.zeros(idx.size)
        has_next = local[idx] + 1 <= count_v[idx] - 2       # pair j+1 exists
        nx = idx[has_next] + 1
        P[has_next] -= np.einsum("kij,ki->kj", Ja[nx], mu[nx])
        tau[has_next] -= _dot(dka[nx], mu[nx])
        P -= _dot(P, t[idx])[:, None] * t[idx]              # the tension went to the rest length
        # [J_b^T ; dk_db^T] mu = [P ; tau]: 4 equations of rank 3, by the normal equations.
        A = np.concatenate([np.transpose(Jb[idx], (0, 2, 1)), dkb[idx][:, None, :]], axis=1)   # (k, 4, 3)
        rhs = np.concatenate([P, tau[:, None]], axis=1)
        AtA = np.einsum("kri,krj->kij", A, A)
        Atb = np.einsum("kri,kr->ki", A, rhs)
        mu[idx] = np.linalg.solve(AtA, Atb[..., None])[..., 0]
    return mu


def solve_rest_pose(model, solver_config=None, gravity=(0.0, -9.81, 0.0), config: RestPoseConfig | None = None,
                    external_force=None, strands=None, support=None, support_iterations: int = 2000) -> RestPoseResult:
    """Rest moments that make the Model's authored shape a static equilibrium (see the module docstring).

    Args:
        model: the :class:`~taichi_hair.model.Model` (its authored rest shape is x*).
        solver_config: the :class:`~taichi_hair.config.SolverADMMConfig` the groom will be simulated with
            (strain measure and Voronoi rescaling); default ``SolverADMMConfig()``.
        gravity: acceleration of gravity in the frame the groom is authored in [m/s^2].
        config: a :class:`RestPoseConfig`.
        external_force: optional (vertex_count, 3) further static loads on the vertices [N] (e.g. contact
            forces), added to the weights.
        strands: optional indices of the strands to solve (the others keep what the Model has).
        support: optional :class:`~taichi_hair.solvers.rest_support.ContactSupport`: vertices the body may push
            on at x*, with normals and friction; for the strands that cannot hold their own weight the body
            then carries what the rule of :mod:`~taichi_hair.solvers.rest_support` gives it (contact forces
            in the Coulomb cones); strands that can keep contacts carrying nothing.
        support_iterations: iterations of that cone program [-].

    Returns:
        a :class:`RestPoseResult`; apply it with :func:`apply_rest_pose`.
    """
    from ..config import SolverADMMConfig

    t_start = time.perf_counter()
    if support is not None and support.vertex.size and (config or RestPoseConfig()).support_for == "unheld":
        # The body carries only strands that cannot hold themselves: a strand held without support keeps its
        # own rest pose (contacts carry nothing for it), since the simulated contacts hold a static load
        # less exactly than the rest pose does (an earlier version of benchmarks/probes/rest_pose_support.py,
        # with only its 5 short strands over a 5 cm sphere, 2 s: without support p90 drift 0.02 mm, with
        # support wherever it lowers the rest change 1.8 mm).
        bare = solve_rest_pose(model, solver_config, gravity, config, external_force, strands)
        need = np.zeros(model.strand_count, bool)
        need[[s for s, _ in bare.unheld]] = True
        from .rest_support import ContactSupport

        keep = need[model.host["vertex_strand"][support.vertex]]
        support = ContactSupport(support.vertex[keep], support.normal[keep], support.friction[keep])
    cfg = config or RestPoseConfig()
    scfg = solver_config or SolverADMMConfig()
    measure = str(scfg.strain_measure)
    h = model.host
    n, ns = model.vertex_count, model.strand_count
    g = np.asarray(gravity, np.float64).reshape(3)
    if not np.all(np.isfinite(g)):
        raise ValueError(f"solve_rest_pose: gravity must be finite, got {tuple(gravity)}")
    local = h["vertex_local_index"]
    strand_of = h["vertex_strand"]
    starts = h["strand_vertex_start"]
    counts = h["strand_vertex_count"]
    count_v = counts[strand_of]
    active = h["pair_is_active"].astype(bool)
    clamped_s = h["strand_body"] >= 0
    selected = np.zeros(ns, bool)
    selected[np.arange(ns) if strands is None else np.asarray(strands, np.int64)] = True
    solve_s = selected & clamped_s
    unheld = [(int(s), "its root is free (no equilibrium under gravity)")
              for s in np.nonzero(selected & ~clamped_s)[0]]

    force = np.asarray(h["vertex_mass"], np.float64)[:, None] * g[None, :]
    if external_force is not None:
        ext = np.asarray(external_force, np.float64)
        if ext.shape != (n, 3) or not np.all(np.isfinite(ext)):
            raise ValueError(f"solve_rest_pose: external_force must be a finite ({n}, 3) array")
        force = force + ext
    ghost = local == count_v - 1
    m1, m2, t, e, length = rest_frames(h)
    kappa, Ja, Jb, dka, dkb = _pair_jacobians(h, measure)
    load = force                                    # weights and given loads (the residual's scale)
    support_force = np.zeros((n, 3))
    friction_limited = np.zeros(ns, bool)
    if support is not None:
        # The body's share (rest_support.py): the smallest change of rest strain with forces in the cones.
        from .rest_support import support_forces

        vstar0 = pair_voronoi_length(h, scfg.voronoi_rescaling, np.asarray(h["edge_rest_length"], np.float64))
        S0 = np.where(active[:, None], np.asarray(h["pair_bending_modulus"], np.float64) / vstar0[:, None], 0.0)

        def moments_of(f):
            return _tip_to_root_moments(h, _edge_loads(h, f), t, Ja, Jb, dka, dkb, solve_s)

        support_force, friction_limited = support_forces(h, support, moments_of(force), moments_of, S0, solve_s,
                                                         support_iterations)
        force = force + support_force
    G = _edge_loads(h, force)
    nlen = np.linalg.norm(e, axis=1)
    # Rest lengths from the tensions (free edges: local 1 .. m-2; the clamped root edge keeps its own).
    rest_len = np.asarray(h["edge_rest_length"], np.float64).copy()
    free_edge = (local >= 1) & ~ghost & solve_s[strand_of]
    if cfg.rest_lengths:
        ea = np.asarray(h["edge_stretch_stiffness"], np.float64) / np.maximum(rest_len, 1e-300)  # E_s A [N]
        tension = _dot(G, t)
        fe = np.nonzero(free_edge)[0]
        rest_len[fe] = _rest_length_for_tension(measure, nlen[fe], tension[fe], ea[fe])
    # The solver's bending stiffness S_i = E_b K / v_i* with these rest lengths (model.pair_voronoi_length).
    vstar = pair_voronoi_length(h, scfg.voronoi_rescaling, rest_len)
    S = np.where(active[:, None], np.asarray(h["pair_bending_modulus"], np.float64) / vstar[:, None], 0.0)

    # Tip to root: edge j (local m-2 down to 1) fixes mu_j from G_j and mu_{j+1}.
    mu = _tip_to_root_moments(h, G, t, Ja, Jb, dka, dkb, solve_s)

    # kappa_bar = kappa - mu / S, and the statics' residual with the solved moments.
    safe = np.where(S > 0.0, S, 1.0)
    kbar = np.where(S > 0.0, kappa - mu / safe, kappa)
    resid = _statics_residual(h, G, mu, Ja, Jb, dka, dkb, t, active, ghost, local)
    weight = np.maximum(np.bincount(strand_of, weights=np.linalg.norm(load, axis=1), minlength=ns), 1e-300)
    strand_res = np.full(ns, np.nan)
    r = np.zeros(ns)
    np.maximum.at(r, strand_of, resid)
    strand_res[solve_s] = r[solve_s] / weight[solve_s]
    turn = np.zeros(ns)
    solved_pair = active & solve_s[strand_of]
    np.maximum.at(turn, strand_of, np.where(solved_pair, np.linalg.norm(kbar, axis=1), 0.0))
    change = np.zeros(ns)
    np.maximum.at(change, strand_of, np.where(solved_pair, np.linalg.norm(kbar - kappa, axis=1), 0.0))
    for s in np.nonzero(solve_s)[0]:
        why = None
        if not np.isfinite(strand_res[s]) or not np.isfinite(turn[s]):
            why = "the statics have no finite solution"
        elif turn[s] > cfg.max_rest_turn or change[s] > cfg.max_rest_change:
            why = (f"it would need a rest turn of {turn[s]:.3g} (max_rest_turn {cfg.max_rest_turn:g}), "
                   f"{change[s]:.3g} from its authored turn (max_rest_change {cfg.max_rest_change:g}), to hold its "
                   "own weight" + (" with the body's support (friction at its limit)" if friction_limited[s] else
                                   " with the body's support" if np.any(support_force[starts[s]:starts[s] + counts[s]])
                                   else ""))
        elif strand_res[s] > cfg.residual_tolerance:
            why = f"residual {strand_res[s]:.2e} of its weight > {cfg.residual_tolerance:g}"
        if why is not None:
            unheld.append((int(s), why))
    unheld.sort()
    # Strands not held keep the Model's rest pose: zero moment, authored strains and lengths.
    keep = np.zeros(ns, bool)
    keep[[s for s, _ in unheld]] = True
    keep |= ~selected
    kv = keep[strand_of]
    old_mu = h.get(MOMENT_KEY)
    mu[kv] = 0.0 if old_mu is None else np.asarray(old_mu, np.float64)[kv]
    kbar[kv] = kappa[kv] - np.where(S[kv] > 0.0, mu[kv] / safe[kv], 0.0)
    rest_len[kv] = np.asarray(h["edge_rest_length"], np.float64)[kv]
    support_force[kv] = 0.0
    return RestPoseResult(pair_rest_moment=mu, pair_rest_strain=kbar, edge_rest_length=rest_len,
                          vertex_support_force=support_force if support is not None else None,
                          friction_limited=[int(s) for s in np.nonzero(friction_limited & ~keep)[0]],
                          strand_rest_turn=turn, strand_residual=strand_res, unheld=unheld, measure=measure,
                          seconds=time.perf_counter() - t_start)


def _statics_residual(h, G, mu, Ja, Jb, dka, dkb, t, active, ghost, local):
    """|G_j - tension_j t_j - J_{b,j}^T mu_j - J_{a,j+1}^T mu_{j+1}| + |twist balance| / |e| per edge [N]."""
    n = G.shape[0]
    bend = np.zeros((n, 3))
    torque = np.zeros(n)
    ip = np.nonzero(active)[0]
    bend[ip] += np.einsum("kij,ki->kj", Jb[ip], mu[ip])            # pair i on its edge b = i
    torque[ip] += _dot(dkb[ip], mu[ip])
    bend[ip - 1] += np.einsum("kij,ki->kj", Ja[ip], mu[ip])        # pair i on its edge a = i - 1
    torque[ip - 1] += _dot(dka[ip], mu[ip])
    perp = G - _dot(G, t)[:, None] * t
    res = np.linalg.norm(perp - bend, axis=1)
    free = (local >= 1) & ~ghost
    le = np.maximum(np.asarray(h["edge_rest_length"], np.float64), 1e-300)
    res = res + np.abs(torque) / le
    return np.where(free, res, 0.0)


def apply_rest_pose(model, result: RestPoseResult) -> None:
    """Write a solved rest pose into the Model in place (``Model.update``; solvers built on it must call
    ``refresh_model()``): the rest moments and the measure they were solved for, and the rest lengths with
    the stretch stiffness E_s A e_bar that follows from them.  Masses stay those of the authored lengths."""
    h = dict(model.host)
    old = np.asarray(h["edge_rest_length"], np.float64)
    le = result.edge_rest_length
    ratio = np.where(old > 0.0, le / np.where(old > 0.0, old, 1.0), 1.0)
    h["edge_stretch_stiffness"] = np.asarray(h["edge_stretch_stiffness"], np.float64) * ratio
    h["edge_rest_length"] = le.copy()
    h[MOMENT_KEY] = result.pair_rest_moment.copy()
    h[MEASURE_KEY] = str(result.measure)
    model.update(h)


def clear_rest_pose(model) -> None:
    """Back to the authored rest pose (no rest moments); rest lengths are left as they are."""
    h = dict(model.host)
    h.pop(MOMENT_KEY, None)
    h.pop(MEASURE_KEY, None)
    model.update(h)


def _tipping_perturbation(h: dict, x0: np.ndarray, free: np.ndarray, tip: float, seed: int) -> np.ndarray:
    """Displacements (vertex_count, 3) [m] that turn every strand's free part rigidly about its last clamped
    vertex by a small angle about a random axis (seeded), the tip moving by ``tip`` [m]: the way an unstable
    strand falls (it tips over about its root), with no stretch."""
    rng = np.random.default_rng(seed)
    starts = h["strand_vertex_start"]
    axes = rng.normal(size=(starts.size, 3))
    axes /= np.maximum(np.linalg.norm(axes, axis=1), 1e-300)[:, None]
    strand = h["vertex_strand"]
    # Pivot: the last clamped vertex of each strand (the root when only it is clamped).
    pivot_index = starts.copy()
    fixed_idx = np.nonzero(~free)[0]
    np.maximum.at(pivot_index, strand[fixed_idx], fixed_idx)
    arm = x0 - x0[pivot_index[strand]]
    reach = np.zeros(starts.size)
    np.maximum.at(reach, strand, np.where(free, np.linalg.norm(arm, axis=1), 0.0))
    angle = tip / np.maximum(reach, 1e-300)
    d = np.cross(axes[strand], arm) * angle[strand][:, None]
    return np.where(free[:, None], d, 0.0)


def check_stability(model, result: RestPoseResult, solver_config=None, gravity=(0.0, -9.81, 0.0),
                    seconds: float = 2.0, dt: float = 1.0 / 96.0, tolerance: float = 1.0e-3,
                    perturbation: float = 1.0e-4, seed: int = 0, progress: bool = False) -> RestPoseResult:
    """Which held strands are *unstable* equilibria, by the simulated model itself: a dynamic run of the Model
    (its rest pose applied, :func:`apply_rest_pose`) without contacts, from x* with every strand tipped rigidly
    about its root so that its tip moves by ``perturbation`` [m] (random axis, seeded) and the duals primed; a
    held strand any of whose vertices drifts more than ``tolerance`` [m] within ``seconds`` is listed in
    ``result.unstable`` (the result is returned, filled).  A strand is flagged when its fall grows 10x
    (tolerance / perturbation) within 2 s: growth rates above ~1.2 /s.

    The defaults, measured on the 300-strand straight groom on assets/head.obj (276 held;
    ``benchmarks/probes/rest_pose_stability.py`` for the tipping; the jitter, the earlier perturbation, with
    scratch scripts at commit 0e514de): a 1 um random jitter of every vertex for 1 s (the earlier default)
    flagged 9 strands; 2 s: 31; 4 s: 49; a 0.1 mm jitter for 1 s: 33, for 4 s: 56; the tipping perturbation
    of 0.1 mm for 1 s: 29, for 2 s (now): 47.  The instabilities grow slowly (rates down to ~1 /s), so a
    longer run finds more: the check is a lower bound on the unstable strands, not a proof of stability.

    Why a run and not a formula: the moments are fixed by the statics, so the Hessian at x* and with it the
    stability do not depend on the rest shape chosen: no rest pose holds a strand whose equilibrium is
    unstable (a straight upright strand above its self-weight buckling length, tested), and only support
    (hair on hair, the scalp) holds such strands.  The run also catches the solver's own trouble: before the
    prestress weight of ``SolverADMM`` (``PRESTRESS_WEIGHT``) it flagged 203 of the hang scene's 300 sag-free
    strands, which were the ADMM iteration diverging at w0 = 1, not physics; with it, none.
    ``progress``: a progress bar on stderr (the command line's)."""
    from dataclasses import replace

    from ..config import Mode, SolverADMMConfig
    from ..solver_admm import SolverADMM

    scfg = replace(solver_config or SolverADMMConfig(), contacts=None, mode=Mode.DYNAMIC)
    solver = SolverADMM(model, scfg)
    state, control = model.state(), model.control()
    control.gravity = tuple(float(g) for g in gravity)
    h = model.host
    x0 = np.asarray(h["vertex_rest_position"], np.float64)
    free = np.asarray(h["vertex_is_fixed"]) == 0
    x = x0 + _tipping_perturbation(h, x0, free, perturbation, seed)
    state.vertex_position.from_numpy(x.astype(state.vertex_position.to_numpy().dtype))
    solver.prime_duals(state, control, dt)
    strand = h["vertex_strand"]
    drift = np.zeros(model.strand_count)
    steps = max(1, int(round(seconds / dt)))
    from ..progress import Progress

    bar = Progress(total=steps, label="stability steps", enabled=progress)
    for k in range(steps):
        solver.step(state, control, dt)
        d = np.linalg.norm(state.vertex_position.to_numpy().astype(np.float64) - x0, axis=1)
        np.maximum.at(drift, strand, d)
        bar.update(k + 1)
    bar.close()
    unheld = {s for s, _ in result.unheld}
    result.strand_stability_drift = drift
    result.unstable = [(int(s), f"it drifts {1e3 * drift[s]:.1f} mm within {seconds:g} s without contacts "
                                f"(> {1e3 * tolerance:g} mm): an unstable equilibrium")
                       for s in np.nonzero(drift > tolerance)[0] if int(s) not in unheld]
    return result
