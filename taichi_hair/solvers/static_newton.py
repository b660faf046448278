"""A direct static solve for rods without contacts: Gauss-Newton on the rod's energy, all iterations in one launch.

Issue 15, item 3.  The quasistatic ADMM (``SolverADMMConfig(mode="quasistatic")``) reaches an equilibrium by
hundreds of local-global iterations on a single rod (its low bending modes contract slowly), and each Python
call costs more than an iteration.  Without contacts this module minimises the same discrete energy directly:

    E(x, theta) = sum_pairs 1/2 (kappa_i - kappa_bar_i)^T S_i (kappa_i - kappa_bar_i)
                + sum_edges 1/2 k_j eps_j^2 - sum_vertices m_v g . x_v

with S_i = E K / v_i* the solver's ``pair_bend_stiffness`` (bending Voronoi length v_i* with the config's
``voronoi_rescaling``), kappa_i the Korner strain of pair i (2 v of the rotation q = (w, v) between the two
edges' material frames), kappa_bar_i the rest strain (the rest shape's, minus mu_i / S_i for a sag-free rest
pose, as in :class:`~taichi_hair.solver_admm.SolverADMM`), k_j = E_s A e_j and eps_j = (|e_j|^2 - e_j^2) /
(2 e_j^2).  So its minimiser is the ADMM's equilibrium, not an approximation of it.  Two forms:

* **twist dropped** (naturally straight, round strands, :func:`taichi_hair.frames.twist_choice`): the frames
  are parallel-transported along the centerline, kappa has no twist, and |kappa|^2 = 4 sin^2(phi / 2) =
  2 (1 - t_{i-1} . t_i) = |t_{i-1} - t_i|^2: E depends on x alone, 3 unknowns per vertex;
* **twist solved** (curved, elliptic or prestressed strands): x and the edges' twist angles theta, 4 unknowns
  per vertex; the frames move by parallel transport of the reference director plus the twist (the
  ADMM's time-parallel convention), and kappa's Jacobians are those of :mod:`taichi_hair.strains`, in float64.

How (per strand, strands in parallel, every iteration inside one kernel launch):

* Gauss-Newton: bending as the least-squares residual sqrt(S_i) (kappa_i - kappa_bar_i) with Hessian J^T S J
  (the term (kappa - kappa_bar) . d2kappa left out makes the convergence linear: measured ~0.1 per iteration
  near the 10 cm rod's solution); stretching with its exact Hessian k (e e^T / e_rest^4 + max(eps, 0) I /
  e_rest^2) (positive semi-definite);
* the banded system (half-bandwidth 8 or 11 unknowns: a pair couples three vertices) factored by a banded
  Cholesky in float64, fixed vertices and fixed twists as identity rows;
* a step applied edge by edge from the root at first-order edge length (:meth:`SolverStaticNewton._retract`),
  then a backtracking (Armijo) line search on E in float64, so every accepted step lowers the energy;
* stop when the largest move of a step (vertex, or twist times edge length) is below ``tolerance`` [m].

Scope (checked at construction, a one-line ValueError otherwise): the Korner strain measure and no contacts
(the caller's choice: nothing here models them).  Float64 fields whatever ``ti.init``'s default precision:
the stretch-to-bending stiffness ratio (~1e4 per edge, ~1e10 between a long rod's stretch and its lowest
bending mode) is past single precision.  Memory: 12 float64 band entries and ~10 other values per unknown.

Used by :func:`taichi_hair.solvers.equilibrium.equilibrium` (``simulate --equilibrium``) where nothing touches,
and by ``benchmarks/bench_admm.py``'s rod-to-rest comparison with MuJoCo.
"""

import numpy as np
import taichi as ti

from .static_newton_config import StaticNewtonConfig, StaticNewtonResult, rest_strain, static_newton_eligibility

__all__ = ["SolverStaticNewton", "StaticNewtonConfig", "StaticNewtonResult", "static_newton_eligibility"]

vec3d = ti.types.vector(3, ti.f64)
mat3d = ti.types.matrix(3, 3, ti.f64)

#: Smallest field capacities [vertices], [strands] (see SolverStaticNewton.__init__).
MIN_VERTEX_CAPACITY, MIN_STRAND_CAPACITY = 1024, 64
#: Header of the kernel's io array: n, ns, max_iterations, tolerance, line_search_steps, g (3).
HEADER = 8


def _capacity(count: int, least: int) -> int:
    """The power of two >= count, at least ``least``."""
    return max(least, 1 << max(0, int(count) - 1).bit_length())


#: Band storage columns: the half-bandwidth in unknowns of the twist-solved form (4 x 2 + 3) plus the diagonal.
BAND_COLUMNS = 12


@ti.func
def _transport(u, t0, t1):
    """:func:`taichi_hair.strains.parallel_transport` in float64 (the half turn for a reversed tangent)."""
    b = t0.cross(t1)
    c = t0.dot(t1)
    out = u
    if c > -1.0 + 1e-12:
        out = c * u + b.cross(u) + (b.dot(u) / (1.0 + c)) * b
    else:
        a = u - u.dot(t0) * t0
        if a.norm() < 1e-300:
            a = t0.cross(vec3d(1.0, 0.0, 0.0)) if ti.abs(t0[0]) < 0.9 else t0.cross(vec3d(0.0, 1.0, 0.0))
        a = a.normalized()
        out = 2.0 * a.dot(u) * a - u
    return out


@ti.data_oriented
class SolverStaticNewton:
    """Static equilibrium of rods without contacts (see the module docstring).

    Args:
        model: the finalized :class:`~taichi_hair.model.Model`.
        solver_config: the :class:`~taichi_hair.config.SolverADMMConfig` whose discretisation to use (strain
            measure, Voronoi rescaling); default ``SolverADMMConfig()``.
        config: a :class:`StaticNewtonConfig`.

    Attributes:
        twist: whether the twist angles are unknowns (False: dropped, exactly; see the module docstring).

    Raises:
        ValueError: when the model is outside the scope (:func:`static_newton_eligibility`).
    """

    #: Strands up to which the strands are solved one after the other (no thread pool).
    SERIAL_STRANDS = 8

    def __init__(self, model, solver_config=None, config: StaticNewtonConfig | None = None):
        from ..config import SolverADMMConfig
        from ..frames import twist_choice

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
        bend = np.where(active[:, None], np.asarray(h["pair_bending_modulus"], np.float64) / vstar[:, None], 0.0)
        kbar = rest_strain(model, bend)
        moment = h.get("pair_rest_moment")
        prestressed = moment is not None and np.any(np.asarray(moment) != 0.0)
        self.twist = prestressed or not twist_choice(h, kbar)[0]
        #: Unknowns per vertex: x (3) and, with the twist, the angle of the edge that starts there.
        self.D = 4 if self.twist else 3
        self.band_width = 2 * self.D + (3 if self.twist else 2)  # half-bandwidth in unknowns
        ghost = np.asarray(h["edge_rest_length"]) <= 0.0
        pinned = np.zeros((n, self.D), np.int32)
        pinned[:, :3] = np.asarray(h["vertex_is_fixed"], np.int32)[:, None]
        if self.twist:
            pinned[:, 3] = ((np.asarray(h["edge_is_fixed"]) != 0) | ghost).astype(np.int32)
        # Taichi compiles a kernel for the shapes of the fields it reads, and its offline cache keys on them: the
        # fields are allocated at a capacity (vertices and strands rounded up to a power of two), so that grooms of
        # similar size share one compiled kernel (the twist form took ~30 s to compile for every new vertex count).
        cap_v, cap_s = _capacity(n, MIN_VERTEX_CAPACITY), _capacity(ns, MIN_STRAND_CAPACITY)
        # Per pair / edge / vertex [SI]: S_i (n, 3) (0 where inactive), kappa_bar_i (n, 3), stretch stiffness and
        # rest length of edge i (0 on the ghost edge after a strand's tip), mass; per unknown: pinned (0 / 1).
        self.pair_stiffness = ti.Vector.field(3, ti.f64, cap_v)
        self.pair_rest_kappa = ti.Vector.field(3, ti.f64, cap_v)
        self.edge_stiffness = ti.field(ti.f64, cap_v)
        self.edge_length = ti.field(ti.f64, cap_v)
        self.vertex_mass = ti.field(ti.f64, cap_v)
        self.dof_pinned = ti.field(ti.i32, self.D * cap_v)
        self.strand_start = ti.field(ti.i32, cap_s)
        self.strand_count = ti.field(ti.i32, cap_s)
        # Work arrays: positions, twists and edge frames (tangent, reference director) of the iterate and of the
        # trial [m, rad, -]; the material directors of the point being evaluated; the band of the lower Cholesky
        # factor (D n, BAND_COLUMNS): band[j, k] = A[j, j - k]; -grad E and the step (D n).
        self.x = ti.Vector.field(3, ti.f64, cap_v)
        self.x_trial = ti.Vector.field(3, ti.f64, cap_v)
        self.theta = ti.field(ti.f64, cap_v)
        self.theta_trial = ti.field(ti.f64, cap_v)
        self.edge_t = ti.Vector.field(3, ti.f64, cap_v)
        self.edge_ref = ti.Vector.field(3, ti.f64, cap_v)
        self.frame_t = ti.Vector.field(3, ti.f64, cap_v)
        self.frame_m1 = ti.Vector.field(3, ti.f64, cap_v)
        self.frame_m2 = ti.Vector.field(3, ti.f64, cap_v)
        self.band = ti.field(ti.f64, (self.D * cap_v, BAND_COLUMNS))
        self.rhs = ti.field(ti.f64, self.D * cap_v)
        self.step = ti.field(ti.f64, self.D * cap_v)

        def padded(a, cap):
            a = np.asarray(a)
            out = np.zeros((cap,) + a.shape[1:], a.dtype)
            out[:a.shape[0]] = a
            return out

        self.pair_stiffness.from_numpy(padded(bend, cap_v))
        self.pair_rest_kappa.from_numpy(padded(kbar, cap_v))
        self.edge_stiffness.from_numpy(padded(np.asarray(h["edge_stretch_stiffness"], np.float64), cap_v))
        self.edge_length.from_numpy(padded(np.asarray(h["edge_rest_length"], np.float64), cap_v))
        self.vertex_mass.from_numpy(padded(np.asarray(h["vertex_mass"], np.float64), cap_v))
        self.dof_pinned.from_numpy(padded(pinned, cap_v).reshape(-1))
        self.strand_start.from_numpy(padded(np.asarray(h["strand_vertex_start"], np.int32), cap_s))
        self.strand_count.from_numpy(padded(np.asarray(h["strand_vertex_count"], np.int32), cap_s))
        self._rest_frames = (np.asarray(h["edge_rest_tangent"], np.float64),
                             np.asarray(h["edge_rest_director"], np.float64),
                             np.asarray(h["edge_rest_twist"], np.float64))

    # ------------------------------------------------------------------ the energy at (X, TH)
    @ti.func
    def _frames(self, a: ti.i32, m: ti.i32, X: ti.template(), TH: ti.template()):
        """Tangents and material directors of the strand's edges at positions X and twists TH: the iterate's
        reference directors transported to the new tangents (with the twist: turned by TH)."""
        for k in range(m - 1):
            j = a + k
            if self.edge_length[j] > 0.0:
                t = (X[j + 1] - X[j]).normalized()
                self.frame_t[j] = t
                if ti.static(self.twist):
                    d1 = _transport(self.edge_ref[j], self.edge_t[j], t)
                    d1 = (d1 - d1.dot(t) * t).normalized()
                    c, s = ti.cos(TH[j]), ti.sin(TH[j])
                    m1 = c * d1 + s * t.cross(d1)
                    self.frame_m1[j] = m1
                    self.frame_m2[j] = t.cross(m1)

    @ti.func
    def _kappa(self, i: ti.i32):
        """Korner strain of pair i from the frames and its derivatives: kappa, w, v (q = (w, v))."""
        a = i - 1
        m1a, m2a, ta = self.frame_m1[a], self.frame_m2[a], self.frame_t[a]
        m1b, m2b, tb = self.frame_m1[i], self.frame_m2[i], self.frame_t[i]
        w = 0.5 * ti.sqrt(ti.max(1.0 + m1a.dot(m1b) + m2a.dot(m2b) + ta.dot(tb), 1e-12))
        v = vec3d(ta.dot(m2b) - m2a.dot(tb), m1a.dot(tb) - ta.dot(m1b), m2a.dot(m1b) - m1a.dot(m2b)) / (4.0 * w)
        return 2.0 * v, w, v

    @ti.func
    def _energy(self, a: ti.i32, m: ti.i32, X: ti.template(), TH: ti.template(), g: vec3d) -> ti.f64:
        """E of the strand with vertices a .. a + m - 1 at positions X (twists TH) [J]."""
        if ti.static(self.twist):
            self._frames(a, m, X, TH)
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
            if S[0] > 0.0:
                if ti.static(self.twist):
                    kappa, _w, _v = self._kappa(i)
                    r = kappa - self.pair_rest_kappa[i]
                    E += 0.5 * (S * r).dot(r)
                else:
                    d = (X[i] - X[i - 1]).normalized() - (X[i + 1] - X[i]).normalized()
                    E += 0.5 * S[0] * d.dot(d)
        for k in range(m):
            v = a + k
            if self.dof_pinned[self.D * v] == 0:
                E -= self.vertex_mass[v] * g.dot(X[v])
        return E

    # ------------------------------------------------------------------ the Gauss-Newton system at the iterate
    @ti.func
    def _add(self, p: ti.i32, q: ti.i32, value: ti.f64):
        """A[p, q] += value on the lower triangle (p >= q), unless p or q is pinned."""
        if p >= q and self.dof_pinned[p] == 0 and self.dof_pinned[q] == 0:
            self.band[p, p - q] += value

    @ti.func
    def _add_block(self, u: ti.i32, v: ti.i32, B: mat3d):
        """The position block (u, v) of A (vertices u >= v) += B, on the lower triangle, unless u or v is fixed."""
        D = ti.static(self.D)
        if self.dof_pinned[D * u] == 0 and self.dof_pinned[D * v] == 0:
            for r, c in ti.static(ti.ndrange(3, 3)):
                row, col = D * u + r, D * v + c
                if row >= col:
                    self.band[row, row - col] += B[r, c]

    @ti.func
    def _add_gradient(self, p: ti.i32, value: ti.f64):
        """rhs[p] -= value (rhs is -grad E), unless p is pinned."""
        if self.dof_pinned[p] == 0:
            self.rhs[p] -= value

    @ti.func
    def _assemble(self, a: ti.i32, m: ti.i32, g: vec3d):
        """The Gauss-Newton matrix (band) and -grad E (rhs) of the strand at the iterate (x, theta)."""
        D = ti.static(self.D)
        for j in range(D * a, D * (a + m)):
            self.rhs[j] = 0.0
            for k in ti.static(range(BAND_COLUMNS)):
                self.band[j, k] = 0.0
        if ti.static(self.twist):
            self._frames(a, m, self.x, self.theta)
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
                for r in ti.static(range(3)):
                    self._add_gradient(D * j + r, -f[r])
                    self._add_gradient(D * (j + 1) + r, f[r])
                self._add_block(j, j, H)
                self._add_block(j + 1, j + 1, H)
                self._add_block(j + 1, j, -H)
        for k in range(1, m - 1):  # bending (and twisting) of pair i = (i - 1, i, i + 1)
            i = a + k
            S = self.pair_stiffness[i]
            if S[0] > 0.0:
                ea = self.x[i] - self.x[i - 1]
                eb = self.x[i + 1] - self.x[i]
                la, lb = ea.norm(), eb.norm()
                Ja, Jb = mat3d(0.0), mat3d(0.0)
                r = vec3d(0.0)
                dk_da, dk_db = vec3d(0.0), vec3d(0.0)
                if ti.static(self.twist):
                    # strains.korner_edge_jacobian and korner_twist_derivatives, in float64.
                    kappa, w, v = self._kappa(i)
                    r = kappa - self.pair_rest_kappa[i]
                    vx = ti.Matrix([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]], ti.f64)
                    Aa = ti.Matrix.rows([-self.frame_m2[i - 1], self.frame_m1[i - 1], vec3d(0.0)]) / la
                    Ab = ti.Matrix.rows([-self.frame_m2[i], self.frame_m1[i], vec3d(0.0)]) / lb
                    Ja = -(w * eye - vx) @ Aa
                    Jb = (w * eye + vx) @ Ab
                    dk_db = vec3d(v[1], -v[0], w)
                    dk_da = vec3d(v[1], -v[0], -w)
                else:
                    # kappa ~ t_{i-1} - t_i (the same |.|^2), dt/de = (I - t t^T) / |e|.
                    ta, tb = ea / la, eb / lb
                    r = ta - tb
                    Ja = (eye - ta.outer_product(ta)) / la
                    Jb = -(eye - tb.outer_product(tb)) / lb
                # d r / d (x_{i-1}, x_i, x_{i+1}) = (-Ja, Ja - Jb, Jb) (e_a = x_i - x_{i-1}, e_b = x_{i+1} - x_i),
                # d r / d (theta_{i-1}, theta_i) = (dk_da, dk_db); gradient J^T S r, Gauss-Newton J^T S J by blocks.
                if ti.static(not self.twist):
                    S = vec3d(S[0], S[0], S[0])  # r = t_{i-1} - t_i is a world vector: one stiffness
                Sd = ti.Matrix([[S[0], 0.0, 0.0], [0.0, S[1], 0.0], [0.0, 0.0, S[2]]], ti.f64)
                SJa, SJb = Sd @ Ja, Sd @ Jb
                Sr = S * r
                ga, gb = Ja.transpose() @ Sr, Jb.transpose() @ Sr  # dE/de_a, dE/de_b
                Haa, Hab, Hbb = Ja.transpose() @ SJa, Ja.transpose() @ SJb, Jb.transpose() @ SJb
                for rr in ti.static(range(3)):
                    self._add_gradient(D * (i - 1) + rr, -ga[rr])
                    self._add_gradient(D * i + rr, ga[rr] - gb[rr])
                    self._add_gradient(D * (i + 1) + rr, gb[rr])
                self._add_block(i - 1, i - 1, Haa)
                self._add_block(i, i - 1, -Haa + Hab.transpose())
                self._add_block(i, i, Haa - Hab - Hab.transpose() + Hbb)
                self._add_block(i + 1, i - 1, -Hab.transpose())
                self._add_block(i + 1, i, Hab.transpose() - Hbb)
                self._add_block(i + 1, i + 1, Hbb)
                if ti.static(self.twist):
                    ta_dof, tb_dof = D * (i - 1) + 3, D * i + 3
                    Sa, Sb = S * dk_da, S * dk_db
                    self._add_gradient(ta_dof, dk_da.dot(Sr))
                    self._add_gradient(tb_dof, dk_db.dot(Sr))
                    self._add(ta_dof, ta_dof, dk_da.dot(Sa))
                    self._add(tb_dof, tb_dof, dk_db.dot(Sb))
                    self._add(tb_dof, ta_dof, dk_db.dot(Sa))
                    # Twist-position couplings: d^2 E / d theta d e = J_e^T S dk, to the vertices as above.
                    ca, cb = Ja.transpose() @ Sa, Jb.transpose() @ Sa   # theta_{i-1} with e_a, e_b
                    da, db = Ja.transpose() @ Sb, Jb.transpose() @ Sb   # theta_i with e_a, e_b
                    for rr in ti.static(range(3)):
                        for p, ua, ub in ti.static(((0, -1.0, 0.0), (1, 1.0, -1.0), (2, 0.0, 1.0))):
                            xdof = D * (i - 1 + p) + rr
                            va = ua * ca[rr] + ub * cb[rr]
                            vb = ua * da[rr] + ub * db[rr]
                            self._add(xdof, ta_dof, va)
                            self._add(ta_dof, xdof, va)
                            self._add(xdof, tb_dof, vb)
                            self._add(tb_dof, xdof, vb)
        for k in range(m):  # gravity
            v = a + k
            for r in ti.static(range(3)):
                self._add_gradient(D * v + r, -self.vertex_mass[v] * g[r])
        for j in range(D * a, D * (a + m)):  # identity rows for the pinned unknowns
            if self.dof_pinned[j] != 0:
                self.band[j, 0] = 1.0

    @ti.func
    def _factor_and_solve(self, a: ti.i32, m: ti.i32):
        """Banded Cholesky A = L L^T in place (band), then step = A^-1 rhs."""
        D, B = ti.static(self.D), ti.static(self.band_width)
        j0, j1 = D * a, D * (a + m)
        for j in range(j0, j1):
            lo = ti.max(j0, j - B)
            d = self.band[j, 0]
            for k in range(lo, j):
                d -= self.band[j, j - k] * self.band[j, j - k]
            d = ti.sqrt(ti.max(d, 1e-300))
            self.band[j, 0] = d
            for i in range(j + 1, ti.min(j1, j + B + 1)):
                s = self.band[i, i - j]
                for k in range(ti.max(lo, i - B), j):
                    s -= self.band[i, i - k] * self.band[j, j - k]
                self.band[i, i - j] = s / d
        for j in range(j0, j1):  # L y = rhs
            s = self.rhs[j]
            for k in range(ti.max(j0, j - B), j):
                s -= self.band[j, j - k] * self.step[k]
            self.step[j] = s / self.band[j, 0]
        for jj in range(j1 - j0):  # L^T step = y
            j = j1 - 1 - jj
            s = self.step[j]
            for i in range(j + 1, ti.min(j1, j + B + 1)):
                s -= self.band[i, i - j] * self.step[i]
            self.step[j] = s / self.band[j, 0]

    @ti.func
    def _stepped(self, v: ti.i32, alpha: ti.f64) -> vec3d:
        D = ti.static(self.D)
        return alpha * vec3d(self.step[D * v], self.step[D * v + 1], self.step[D * v + 2])

    @ti.func
    def _retract(self, a: ti.i32, m: ti.i32, alpha: ti.f64):
        """x_trial = the step alpha * step applied edge by edge from the root: each free vertex follows its
        predecessor along the stepped edge's direction, at the edge's length changed to first order only
        (|e| + t . de), and theta_trial = theta + alpha * dtheta.  A rotation of an edge then keeps its length,
        where the linear step x + alpha * step would lengthen it by |de|^2 / (2 |e|) and the line search would
        cut a large rotation to a small one (measured on the 10 cm cantilever: 0.5 mm per iteration, 200
        iterations without this; 11 with it)."""
        for k in range(m):
            v = a + k
            dv = self._stepped(v, alpha)
            if self.dof_pinned[self.D * v] != 0:
                self.x_trial[v] = self.x[v]
            elif k == 0:
                self.x_trial[v] = self.x[v] + dv
            else:
                e = self.x[v] - self.x[v - 1]
                de = dv - self._stepped(v - 1, alpha)
                le = e.norm()
                length = le + (e / le).dot(de)
                self.x_trial[v] = self.x_trial[v - 1] + (e + de).normalized() * length
            if ti.static(self.twist):
                self.theta_trial[v] = self.theta[v] + alpha * self.step[4 * v + 3]

    @ti.kernel
    def _solve(self, serial: ti.template(), io: ti.types.ndarray(dtype=ti.f64, ndim=1)):
        """Every Gauss-Newton iteration of every strand, in one launch.  ``io`` packs everything that goes in
        and out (one array argument: each further argument costs ~10 us of launch on the 2-core VM, more than
        an iteration): the HEADER (n, ns, max_iterations, tolerance [m], line_search_steps, g (3) [m/s^2]) in;
        positions (3n) [m], edge tangents (3n), reference directors (3n) and twists (n) [rad] in and out (the
        frames read and written with the twist only); per strand (5 ns) iterations, converged (0 / 1), last and
        previous moves [m] and energy [J] out.  ``serial`` (compile-time) runs the strands one after the other:
        for a few strands the thread pool's start (~70 us) would cost more than the strands themselves."""
        n = ti.cast(io[0], ti.i32)
        ns = ti.cast(io[1], ti.i32)
        max_iterations = ti.cast(io[2], ti.i32)
        tolerance = io[3]
        line_search_steps = ti.cast(io[4], ti.i32)
        g = vec3d(io[5], io[6], io[7])
        X0, T0, R0, TH0, O0 = HEADER, HEADER + 3 * n, HEADER + 6 * n, HEADER + 9 * n, HEADER + 10 * n
        if ti.static(serial):
            ti.loop_config(serialize=True)
        for s in range(ns):
            a, m = self.strand_start[s], self.strand_count[s]
            for k in range(m):
                v = a + k
                self.x[v] = vec3d(io[X0 + 3 * v], io[X0 + 3 * v + 1], io[X0 + 3 * v + 2])
                if ti.static(self.twist):
                    self.edge_t[v] = vec3d(io[T0 + 3 * v], io[T0 + 3 * v + 1], io[T0 + 3 * v + 2])
                    self.edge_ref[v] = vec3d(io[R0 + 3 * v], io[R0 + 3 * v + 1], io[R0 + 3 * v + 2])
                    self.theta[v] = io[TH0 + v]
            E = self._energy(a, m, self.x, self.theta, g)
            it, conv, move, previous = 0, 0, ti.cast(0.0, ti.f64), ti.cast(0.0, ti.f64)
            while it < max_iterations and conv == 0:
                self._assemble(a, m, g)
                self._factor_and_solve(a, m)
                slope = ti.cast(0.0, ti.f64)  # grad E . step < 0
                for j in range(self.D * a, self.D * (a + m)):
                    slope -= self.rhs[j] * self.step[j]
                alpha = ti.cast(1.0, ti.f64)
                accepted = 0
                Et = E
                for _ in range(line_search_steps):
                    if accepted == 0:
                        self._retract(a, m, alpha)
                        Et = self._energy(a, m, self.x_trial, self.theta_trial, g)
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
                        if ti.static(self.twist):
                            move = ti.max(move, ti.abs(self.theta_trial[v] - self.theta[v]) * self.edge_length[v])
                            self.theta[v] = self.theta_trial[v]
                    for k in range(m - 1 if ti.static(self.twist) else 0):  # the iterate's frames follow
                        j = a + k
                        if self.edge_length[j] > 0.0:
                            t = (self.x[j + 1] - self.x[j]).normalized()
                            d1 = _transport(self.edge_ref[j], self.edge_t[j], t)
                            self.edge_ref[j] = (d1 - d1.dot(t) * t).normalized()
                            self.edge_t[j] = t
                    E = Et
                it += 1
                if move < tolerance:
                    conv = 1  # a step below the tolerance, or none the line search accepts (at round-off)
            for k in range(m):
                v = a + k
                for r in ti.static(range(3)):
                    io[X0 + 3 * v + r] = self.x[v][r]
                if ti.static(self.twist):
                    for r in ti.static(range(3)):
                        io[T0 + 3 * v + r] = self.edge_t[v][r]
                        io[R0 + 3 * v + r] = self.edge_ref[v][r]
                    io[TH0 + v] = self.theta[v]
            io[O0 + 5 * s] = it
            io[O0 + 5 * s + 1] = conv
            io[O0 + 5 * s + 2] = move
            io[O0 + 5 * s + 3] = previous
            io[O0 + 5 * s + 4] = E

    # ------------------------------------------------------------------ public
    def solve(self, state, control) -> StaticNewtonResult:
        """Move ``state`` to the static equilibrium under ``control.gravity`` from its current positions, frames
        and twists (fixed vertices stay where the state has them); velocities are zeroed and, with the twist
        solved, the frames (tangents, reference and material directors, twists) written back consistent with the
        positions."""
        f = state.vertex_position.to_numpy().dtype
        frames = (state.edge_tangent.to_numpy(), state.edge_reference_director.to_numpy(), state.edge_twist.to_numpy())
        x, result, (t, ref, theta) = self._run(state.vertex_position.to_numpy(), control.gravity, frames)
        state.vertex_position.from_numpy(x.astype(f))
        state.vertex_velocity.fill(0.0)
        state.edge_angular_velocity.fill(0.0)
        if self.twist:
            state.edge_tangent.from_numpy(t.astype(f))
            state.edge_reference_director.from_numpy(ref.astype(f))
            state.edge_twist.from_numpy(theta.astype(f))
            m1 = np.cos(theta)[:, None] * ref + np.sin(theta)[:, None] * np.cross(t, ref)
            state.edge_material_d1.from_numpy(m1.astype(f))
            state.edge_material_d2.from_numpy(np.cross(t, m1).astype(f))
        # Twist dropped: the frames stay as they were; the solver's next step transports them to the new
        # tangents (frames.update_reference_frames, twist_free_strand), as after any step.
        return result

    def solve_to(self, x0: np.ndarray, gravity, frames=None) -> tuple:
        """The equilibrium from positions ``x0`` (vertex_count, 3) [m] without a State: (positions (float64, a
        new array), :class:`StaticNewtonResult`).  ``frames``: (tangents, reference directors, twists) of the
        edges to start from (default the Model's rest frames).  One kernel launch: the form to time."""
        x, result, _ = self._run(x0, gravity, frames)
        return x, result

    def _run(self, x0, gravity, frames):
        n, ns, c = self.model.vertex_count, self.model.strand_count, self.config
        x = np.asarray(x0, np.float64)
        if x.shape != (n, 3):
            raise ValueError(f"SolverStaticNewton: positions must have shape ({n}, 3), got {x.shape}")
        if not np.all(np.isfinite(x)):
            raise ValueError("SolverStaticNewton: the positions are not finite")
        t, ref, theta = self._rest_frames if frames is None else frames
        H = HEADER
        io = np.empty(H + 10 * n + 5 * ns)
        io[:H] = (n, ns, c.max_iterations, c.tolerance, c.line_search_steps, *[float(v) for v in gravity])
        io[H:H + 3 * n] = x.reshape(-1)
        io[H + 3 * n:H + 6 * n] = np.asarray(t, np.float64).reshape(-1)
        io[H + 6 * n:H + 9 * n] = np.asarray(ref, np.float64).reshape(-1)
        io[H + 9 * n:H + 10 * n] = np.asarray(theta, np.float64).reshape(-1)
        self._solve(ns <= self.SERIAL_STRANDS, io)
        out = io[H + 10 * n:].reshape(ns, 5)
        result = StaticNewtonResult(out[:, 0].astype(np.int64), out[:, 1] > 0.5, out[:, 2].copy(), out[:, 3].copy(),
                                    out[:, 4].copy())
        frames_out = (io[H + 3 * n:H + 6 * n].reshape(n, 3), io[H + 6 * n:H + 9 * n].reshape(n, 3),
                      io[H + 9 * n:H + 10 * n].copy())
        return io[H:H + 3 * n].reshape(n, 3).copy(), result, frames_out
