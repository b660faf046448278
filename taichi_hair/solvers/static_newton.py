"""A direct static solve for few rods: Gauss-Newton on the rod's energy, all iterations in one launch (issue 15, item 3).

The quasistatic ADMM (``SolverADMMConfig(mode="quasistatic")``) reaches an equilibrium by hundreds of
local-global iterations on a single rod (its low bending modes contract slowly), and each Python call costs
more than an iteration.  For a scene of few rods without contacts this module minimises the same discrete
energy directly:

    E(x) = sum_pairs 1/2 S_i |t_{i-1} - t_i|^2 + sum_edges 1/2 k_j eps_j^2 - sum_vertices m_v g . x_v

with S_i = E_b K_11 / v_i* the solver's ``pair_bend_stiffness`` (the bending Voronoi length v_i* with the
config's ``voronoi_rescaling``), k_j = E_s A e_j the edge's stretch stiffness and eps_j = (|e_j|^2 -
e_j^2) / (2 e_j^2) (the Korner measure).  The bending term is the Korner strain's exactly: with the twist
dropped (naturally straight, round strands, :func:`taichi_hair.frames.twist_choice`) the material frames are
parallel-transported along the centerline, the strain kappa = 2 v of the rotation q = (w, v) between adjacent
frames has no twist component, and |kappa|^2 = 4 sin^2(phi / 2) = 2 (1 - t_{i-1} . t_i) = |t_{i-1} - t_i|^2.
So the minimiser is the ADMM's equilibrium, not an approximation of it.

How (per strand, strands in parallel, every iteration inside one kernel launch):

* Gauss-Newton: bending as the least-squares residual r_i = sqrt(S_i) (t_{i-1} - t_i), Hessian J^T S J
  with dt/de = (I - t t^T) / |e| (the term r . d2r left out is of the size of the turn per pair); stretching
  with its exact Hessian k (e e^T / e_rest^4 + max(eps, 0) I / e_rest^2) (positive semi-definite);
* the banded system (3 unknowns per vertex, half-bandwidth 8: a pair couples three vertices) factored by a
  banded Cholesky in float64, fixed vertices as identity rows;
* a backtracking (Armijo) line search on E in float64, so every accepted step lowers the energy;
* stop when the largest vertex move of a step is below ``tolerance`` [m] or after ``max_iterations``.

Scope (checked at construction, a one-line ValueError otherwise): the Korner strain measure, strands whose
twist can be dropped, no sag-free rest moments, no contacts (the caller's choice: contacts are not
modelled here).  Float64 fields whatever ``ti.init``'s default precision: the stretch-to-bending stiffness
ratio (~1e4 per edge, ~1e10 between a long rod's stretch and its lowest bending mode) is past single
precision.  Memory: 9 float64 band entries and 5 other float64 values per unknown.

Used by :func:`taichi_hair.solvers.equilibrium.equilibrium` when the scene qualifies and by
``benchmarks/bench_admm.py``'s rod-to-rest comparison with MuJoCo.
"""


from dataclasses import dataclass

import numpy as np
import taichi as ti

vec3d = ti.types.vector(3, ti.f64)
mat3d = ti.types.matrix(3, 3, ti.f64)

#: Half-bandwidth of the system in unknowns: a bending pair couples vertices i-1 and i+1 (3 x 2 + 2).
BAND = 8


@dataclass
class StaticNewtonConfig:
    """Settings of :class:`SolverStaticNewton`.

    Attributes:
        max_iterations: Gauss-Newton iterations at most per strand [-].
        tolerance: stop when the largest vertex move of an iteration is below this [m].
        line_search_steps: halvings of the step at most in the line search [-].
    """

    max_iterations: int = 200
    tolerance: float = 1.0e-10
    line_search_steps: int = 40

    def __post_init__(self):
        if not (isinstance(self.max_iterations, int) and self.max_iterations >= 1):
            raise ValueError(f"StaticNewtonConfig.max_iterations must be an integer >= 1, got {self.max_iterations!r}")
        if not (np.isfinite(self.tolerance) and self.tolerance > 0):
            raise ValueError(f"StaticNewtonConfig.tolerance must be a finite length > 0 [m], got {self.tolerance!r}")
        if not (isinstance(self.line_search_steps, int) and 1 <= self.line_search_steps <= 200):
            raise ValueError("StaticNewtonConfig.line_search_steps must be an integer in [1, 200], "
                             f"got {self.line_search_steps!r}")


@dataclass
class StaticNewtonResult:
    """What :meth:`SolverStaticNewton.solve` did, per strand (arrays of shape (strand_count,))."""

    iterations: np.ndarray     # Gauss-Newton iterations [-]
    converged: np.ndarray      # the last move was below the tolerance [bool]
    last_move: np.ndarray      # largest vertex move of the last iteration [m]
    previous_move: np.ndarray  # the same for the iteration before (0 after one iteration) [m]
    energy: np.ndarray         # E at the end [J]

    @property
    def all_converged(self) -> bool:
        return bool(np.all(self.converged))

    def estimated_distance(self) -> float:
        """Largest estimated distance left to the equilibrium [m]: the geometric tail d r / (1 - r) of the last
        move d with the contraction rate r = d / d_previous the last two iterations show (Gauss-Newton converges
        linearly: the term it leaves out of the Hessian is of the size of the turn per pair); inf where the last
        move did not contract."""
        d, p = self.last_move, self.previous_move
        with np.errstate(divide="ignore", invalid="ignore"):
            r = np.where(p > 0.0, d / p, 0.0)
            tail = np.where(d == 0.0, 0.0, np.where(r < 1.0, d * r / (1.0 - r), np.inf))
        return float(np.max(tail)) if tail.size else 0.0


def static_newton_eligibility(model, solver_config=None) -> tuple[bool, str]:
    """Whether :class:`SolverStaticNewton` models ``model`` with ``solver_config`` exactly, and why not."""
    from ..config import SolverADMMConfig, StrainMeasure
    from ..frames import twist_choice

    cfg = solver_config or SolverADMMConfig()
    if cfg.strain_measure != StrainMeasure.KORNER:
        return False, "the static Newton solve models the Korner strain measure only"
    h = model.host
    moment = h.get("pair_rest_moment")
    if moment is not None and np.any(np.asarray(moment) != 0.0):
        return False, "the groom has a sag-free rest pose (rest moments): its twist is solved"
    ok, why = twist_choice(h, _rest_kappa(h))
    return ok, why


def _rest_kappa(h: dict) -> np.ndarray:
    """Bending magnitude |t_{i-1} - t_i| (components 0, 1) and rest twist (component 2) of every pair, from the
    rest frames (host, float64): enough for :func:`~taichi_hair.frames.twist_choice`'s straightness test."""
    t = np.asarray(h["edge_rest_tangent"], np.float64)
    d = np.asarray(h["edge_rest_director"], np.float64)
    tw = np.asarray(h["edge_rest_twist"], np.float64)
    m1 = np.cos(tw)[:, None] * d + np.sin(tw)[:, None] * np.cross(t, d)
    k = np.zeros((t.shape[0], 3))
    k[1:, 0] = np.linalg.norm(t[1:] - t[:-1], axis=1)
    k[1:, 2] = np.arctan2(np.einsum("ij,ij->i", np.cross(m1[:-1], m1[1:]), t[1:]), np.einsum("ij,ij->i", m1[:-1], m1[1:]))
    return np.where(np.asarray(h["pair_is_active"]).astype(bool)[:, None], k, 0.0)


@ti.data_oriented
class SolverStaticNewton:
    """Static equilibrium of few rods without contacts (see the module docstring).

    Args:
        model: the finalized :class:`~taichi_hair.model.Model`.
        solver_config: the :class:`~taichi_hair.config.SolverADMMConfig` whose discretisation to use (strain
            measure, Voronoi rescaling); default ``SolverADMMConfig()``.
        config: a :class:`StaticNewtonConfig`.

    Raises:
        ValueError: when the model is outside the scope (:func:`static_newton_eligibility`).
    """

    def __init__(self, model, solver_config=None, config: StaticNewtonConfig | None = None):
        from ..config import SolverADMMConfig

        self.model = model
        self.solver_config = solver_config or SolverADMMConfig()
        self.config = config or StaticNewtonConfig()
        ok, why = static_newton_eligibility(model, self.solver_config)
        if not ok:
            raise ValueError(f"SolverStaticNewton: {why}")
        h = model.host
        n, ns = model.vertex_count, model.strand_count
        active = np.asarray(h["pair_is_active"]).astype(bool)
        vstar = model.pair_voronoi_length(self.solver_config.voronoi_rescaling)
        bend = np.where(active, np.asarray(h["pair_bending_modulus"], np.float64)[:, 0] / vstar, 0.0)
        # Per vertex [SI]: bending stiffness S_i of pair i (0 where inactive), stretch stiffness and rest length
        # of edge i (0 on the ghost edge after a strand's tip), mass, fixed flag.
        self.pair_stiffness = ti.field(ti.f64, n)
        self.edge_stiffness = ti.field(ti.f64, n)
        self.edge_length = ti.field(ti.f64, n)
        self.vertex_mass = ti.field(ti.f64, n)
        self.vertex_fixed = ti.field(ti.i32, n)
        self.strand_start = ti.field(ti.i32, ns)
        self.strand_count = ti.field(ti.i32, ns)
        # Work arrays: positions and trial positions (n, 3) [m], the band of the lower Cholesky factor
        # (3n, BAND + 1): band[j, k] = A[j, j - k], right-hand side -grad E and the step (3n).
        self.x = ti.Vector.field(3, ti.f64, n)
        self.x_trial = ti.Vector.field(3, ti.f64, n)
        self.band = ti.field(ti.f64, (3 * n, BAND + 1))
        self.rhs = ti.field(ti.f64, 3 * n)
        self.step = ti.field(ti.f64, 3 * n)

        self.pair_stiffness.from_numpy(bend)
        self.edge_stiffness.from_numpy(np.asarray(h["edge_stretch_stiffness"], np.float64))
        self.edge_length.from_numpy(np.asarray(h["edge_rest_length"], np.float64))
        self.vertex_mass.from_numpy(np.asarray(h["vertex_mass"], np.float64))
        self.vertex_fixed.from_numpy(np.asarray(h["vertex_is_fixed"], np.int32))
        self.strand_start.from_numpy(np.asarray(h["strand_vertex_start"], np.int32))
        self.strand_count.from_numpy(np.asarray(h["strand_vertex_count"], np.int32))

    # ------------------------------------------------------------------ the energy and its model
    @ti.func
    def _energy(self, a: ti.i32, m: ti.i32, X: ti.template(), g: vec3d) -> ti.f64:
        """E of the strand with vertices a .. a + m - 1 at positions X [J]."""
        E = ti.cast(0.0, ti.f64)
        for k in range(m - 1):
            j = a + k
            le = self.edge_length[j]
            if le > 0.0:
                e = X[j + 1] - X[j]
                eps = 0.5 * (e.dot(e) / (le * le) - 1.0)
                E += 0.5 * self.edge_stiffness[j] * eps * eps
        for k in range(1, m - 1):
            i = a + k
            S = self.pair_stiffness[i]
            if S > 0.0:
                d = (X[i] - X[i - 1]).normalized() - (X[i + 1] - X[i]).normalized()
                E += 0.5 * S * d.dot(d)
        for k in range(m):
            v = a + k
            if self.vertex_fixed[v] == 0:
                E -= self.vertex_mass[v] * g.dot(X[v])
        return E

    @ti.func
    def _add_block(self, u: ti.i32, v: ti.i32, B: mat3d):
        """A[3u + r, 3v + c] += B[r, c] on the lower triangle (u >= v), unless u or v is fixed."""
        if self.vertex_fixed[u] == 0 and self.vertex_fixed[v] == 0:
            for r, c in ti.static(ti.ndrange(3, 3)):
                row = 3 * u + r
                col = 3 * v + c
                if row >= col:
                    self.band[row, row - col] += B[r, c]

    @ti.func
    def _add_gradient(self, v: ti.i32, f: vec3d):
        """rhs[3v .. 3v + 2] -= f (rhs is -grad E), unless v is fixed."""
        if self.vertex_fixed[v] == 0:
            for r in ti.static(range(3)):
                self.rhs[3 * v + r] -= f[r]

    @ti.func
    def _assemble(self, a: ti.i32, m: ti.i32, g: vec3d):
        """The Gauss-Newton matrix (band) and -grad E (rhs) of the strand at self.x."""
        for j in range(3 * a, 3 * (a + m)):
            self.rhs[j] = 0.0
            for k in ti.static(range(BAND + 1)):
                self.band[j, k] = 0.0
        eye = ti.Matrix.identity(ti.f64, 3)
        for k in range(m - 1):  # stretching of edge j = (j, j + 1)
            j = a + k
            le = self.edge_length[j]
            if le > 0.0:
                e = self.x[j + 1] - self.x[j]
                inv = 1.0 / (le * le)
                eps = 0.5 * (e.dot(e) * inv - 1.0)
                ks = self.edge_stiffness[j]
                f = ks * eps * inv * e  # dE/de
                H = ks * (inv * inv * e.outer_product(e) + ti.max(eps, 0.0) * inv * eye)
                self._add_gradient(j, -f)
                self._add_gradient(j + 1, f)
                self._add_block(j, j, H)
                self._add_block(j + 1, j + 1, H)
                self._add_block(j + 1, j, -H)
        for k in range(1, m - 1):  # bending of pair i = (i - 1, i, i + 1)
            i = a + k
            S = self.pair_stiffness[i]
            if S > 0.0:
                ea = self.x[i] - self.x[i - 1]
                eb = self.x[i + 1] - self.x[i]
                la, lb = ea.norm(), eb.norm()
                ta, tb = ea / la, eb / lb
                Pa = (eye - ta.outer_product(ta)) / la
                Pb = (eye - tb.outer_product(tb)) / lb
                r = ta - tb
                ga = S * (Pa @ r)      # dE/de_a
                gb = -S * (Pb @ r)     # dE/de_b
                Haa = S * (Pa @ Pa)
                Hab = -S * (Pa @ Pb)
                Hbb = S * (Pb @ Pb)
                # Vertices (i - 1, i, i + 1): e_a = x_i - x_{i-1}, e_b = x_{i+1} - x_i.
                self._add_gradient(i - 1, -ga)
                self._add_gradient(i, ga - gb)
                self._add_gradient(i + 1, gb)
                self._add_block(i - 1, i - 1, Haa)
                self._add_block(i, i - 1, -Haa + Hab.transpose())
                self._add_block(i, i, Haa - Hab - Hab.transpose() + Hbb)
                self._add_block(i + 1, i - 1, -Hab.transpose())
                self._add_block(i + 1, i, Hab.transpose() - Hbb)
                self._add_block(i + 1, i + 1, Hbb)
        for k in range(m):  # gravity, and identity rows for fixed vertices
            v = a + k
            if self.vertex_fixed[v] == 0:
                self._add_gradient(v, -self.vertex_mass[v] * g)
            else:
                for r in ti.static(range(3)):
                    self.band[3 * v + r, 0] = 1.0

    @ti.func
    def _factor_and_solve(self, a: ti.i32, m: ti.i32):
        """Banded Cholesky A = L L^T in place (band), then step = A^-1 rhs."""
        j0, j1 = 3 * a, 3 * (a + m)
        for j in range(j0, j1):
            lo = ti.max(j0, j - BAND)
            d = self.band[j, 0]
            for k in range(lo, j):
                d -= self.band[j, j - k] * self.band[j, j - k]
            d = ti.sqrt(ti.max(d, 1e-300))
            self.band[j, 0] = d
            for i in range(j + 1, ti.min(j1, j + BAND + 1)):
                s = self.band[i, i - j]
                for k in range(ti.max(lo, i - BAND), j):
                    s -= self.band[i, i - k] * self.band[j, j - k]
                self.band[i, i - j] = s / d
        for j in range(j0, j1):  # L y = rhs
            s = self.rhs[j]
            for k in range(ti.max(j0, j - BAND), j):
                s -= self.band[j, j - k] * self.step[k]
            self.step[j] = s / self.band[j, 0]
        for jj in range(j1 - j0):  # L^T step = y
            j = j1 - 1 - jj
            s = self.step[j]
            for i in range(j + 1, ti.min(j1, j + BAND + 1)):
                s -= self.band[i, i - j] * self.step[i]
            self.step[j] = s / self.band[j, 0]

    @ti.func
    def _stepped(self, v: ti.i32, alpha: ti.f64) -> vec3d:
        return alpha * vec3d(self.step[3 * v], self.step[3 * v + 1], self.step[3 * v + 2])

    @ti.func
    def _retract(self, a: ti.i32, m: ti.i32, alpha: ti.f64):
        """x_trial = the step alpha * step applied edge by edge from the root: each free vertex follows its
        predecessor along the stepped edge's direction, at the edge's length changed to first order only
        (|e| + t . de).  A rotation of an edge then keeps its length, where the linear step x + alpha * step
        would lengthen it by |de|^2 / (2 |e|) and the line search would cut a large rotation to a small one
        (measured on the 10 cm cantilever: 0.5 mm per iteration, 200 iterations without this)."""
        for k in range(m):
            v = a + k
            dv = self._stepped(v, alpha)
            if self.vertex_fixed[v] != 0:
                self.x_trial[v] = self.x[v]
            elif k == 0:
                self.x_trial[v] = self.x[v] + dv
            else:
                e = self.x[v] - self.x[v - 1]
                de = dv - self._stepped(v - 1, alpha)
                le = e.norm()
                length = le + (e / le).dot(de)
                self.x_trial[v] = self.x_trial[v - 1] + (e + de).normalized() * length

    @ti.kernel
    def _solve(self, serial: ti.template(), io: ti.types.ndarray(dtype=ti.f64, ndim=1)):
        """Every Gauss-Newton iteration of every strand, in one launch.  ``io`` packs everything that goes in
        and out (one array argument: each further argument costs ~10 us of launch on the 2-core VM, more than
        an iteration): positions (3n) [m] in and out, then per strand (5 ns) iterations, converged (0 / 1),
        last and previous moves [m] and energy [J] out, then max_iterations, tolerance [m], line_search_steps and g (3)
        [m/s^2] in.  ``serial`` (compile-time) runs the strands one after the other: for a few strands the
        thread pool's start (~70 us) would cost more than the strands themselves."""
        n3 = 3 * self.x.shape[0]
        ns = self.strand_start.shape[0]
        p0 = n3 + 5 * ns
        max_iterations = ti.cast(io[p0], ti.i32)
        tolerance = io[p0 + 1]
        line_search_steps = ti.cast(io[p0 + 2], ti.i32)
        g = vec3d(io[p0 + 3], io[p0 + 4], io[p0 + 5])
        if ti.static(serial):
            ti.loop_config(serialize=True)
        for s in range(ns):
            a, m = self.strand_start[s], self.strand_count[s]
            for k in range(m):
                v = a + k
                self.x[v] = vec3d(io[3 * v], io[3 * v + 1], io[3 * v + 2])
            E = self._energy(a, m, self.x, g)
            it, conv, move, previous = 0, 0, ti.cast(0.0, ti.f64), ti.cast(0.0, ti.f64)
            while it < max_iterations and conv == 0:
                self._assemble(a, m, g)
                self._factor_and_solve(a, m)
                slope = ti.cast(0.0, ti.f64)  # grad E . step < 0
                for j in range(3 * a, 3 * (a + m)):
                    slope -= self.rhs[j] * self.step[j]
                alpha = ti.cast(1.0, ti.f64)
                accepted = 0
                Et = E
                for _ in range(line_search_steps):
                    if accepted == 0:
                        self._retract(a, m, alpha)
                        Et = self._energy(a, m, self.x_trial, g)
                        if Et <= E + 1.0e-4 * alpha * slope:
                            accepted = 1
                        else:
                            alpha *= 0.5
                previous = move
                move = 0.0
                if accepted == 1:
                    for k in range(m):
                        v = a + k
                        move = ti.max(move, (self.x_trial[v] - self.x[v]).norm())
                        self.x[v] = self.x_trial[v]
                    E = Et
                it += 1
                if move < tolerance:
                    conv = 1  # a step below the tolerance, or none the line search accepts (at round-off)
            for k in range(m):
                for r in ti.static(range(3)):
                    io[3 * (a + k) + r] = self.x[a + k][r]
            io[n3 + 5 * s] = it
            io[n3 + 5 * s + 1] = conv
            io[n3 + 5 * s + 2] = move
            io[n3 + 5 * s + 3] = previous
            io[n3 + 5 * s + 4] = E

    #: Strands up to which the strands are solved one after the other (no thread pool).
    SERIAL_STRANDS = 8

    # ------------------------------------------------------------------ public
    def solve(self, state, control) -> StaticNewtonResult:
        """Move ``state`` to the static equilibrium under ``control.gravity`` (from its current positions;
        fixed vertices stay where the state has them); velocities are zeroed.  The frames of the state are
        left as they were: a following solver step recomputes them from the positions (twist-free strands)."""
        x0 = state.vertex_position.to_numpy().astype(np.float64)
        x, result = self.solve_to(x0, control.gravity)
        state.vertex_position.from_numpy(x.astype(x0.dtype if state.vertex_position.dtype == ti.f64 else np.float32))
        state.vertex_velocity.fill(0.0)
        return result

    def solve_to(self, x0: np.ndarray, gravity) -> tuple:
        """The equilibrium from positions ``x0`` (vertex_count, 3) [m], without a State: (positions (float64,
        a new array), :class:`StaticNewtonResult`).  One kernel launch, no field transfers: the form to time."""
        x = np.asarray(x0, np.float64)
        if x.shape != (self.model.vertex_count, 3):
            raise ValueError(f"SolverStaticNewton: positions must have shape ({self.model.vertex_count}, 3), "
                             f"got {x.shape}")
        if not np.all(np.isfinite(x)):
            raise ValueError("SolverStaticNewton: the positions are not finite")
        n, ns, c = self.model.vertex_count, self.model.strand_count, self.config
        io = np.empty(3 * n + 5 * ns + 6)
        io[:3 * n] = x.reshape(-1)
        io[3 * n + 5 * ns:] = (c.max_iterations, c.tolerance, c.line_search_steps, *[float(v) for v in gravity])
        self._solve(ns <= self.SERIAL_STRANDS, io)
        x = io[:3 * n].reshape(n, 3)
        out = io[3 * n:3 * n + 5 * ns].reshape(ns, 5)
        return x, StaticNewtonResult(out[:, 0].astype(np.int64), out[:, 1] > 0.5, out[:, 2].copy(), out[:, 3].copy(),
                                     out[:, 4].copy())
