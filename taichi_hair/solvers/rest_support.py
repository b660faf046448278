"""Support by the body in the sag-free rest pose (issue 14, item 1): contact forces inside Coulomb cones.

Where a strand lies on the body at its authored shape x*, the body can carry part of its weight, and the
rest pose then needs a smaller change of rest shape.  The statics stay exactly those of
:mod:`taichi_hair.solvers.rest_pose` (the moments mu are linear in the vertex loads); the contact forces are
extra loads f_c on the supported vertices, chosen by the rule

    minimise   1/2 sum_pairs |(mu_i(f) - 0) / S_i|^2    (the change of rest strain, |kappa_bar - kappa(x*)|^2)
    subject to f_c in the Coulomb cone of vertex c:  |f_c - (f_c . n_c) n_c| <= mu_c (f_c . n_c)

the smallest change of rest shape (the issue's first suggestion).  A vertex is supported when the caller says
so (:class:`ContactSupport`: vertices, outward unit normals, friction); tension and compression along the
strand go to the rest lengths and cost nothing here, so a load along an edge is never taken by friction.

How: mu(f) = mu_0 + A f, with A's columns the moments of unit loads at each supported vertex (one tip-to-root
solve per column, all strands at once); per strand the problem is a small convex cone program
(3 x supported vertices unknowns), solved by accelerated projected gradient (FISTA with adaptive restart,
Beck & Teboulle 2009; O'Donoghue & Candes 2015) with the exact projection onto each second-order cone, all
strands in one batch (NumPy, float64).  The optimum is approximate to the iteration count; the statics
are not: the forces found are applied as loads and the moments solved exactly for them.

Memory: one (vertex_count, 3) array per unit-load column (3 x the most supported vertices of a strand).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class ContactSupport:
    """Vertices the body may push on at x* (indices into the Model's vertices), their outward unit normals
    (k, 3) and the friction coefficient (a scalar or (k,)) [-]."""

    vertex: np.ndarray
    normal: np.ndarray
    friction: np.ndarray | float = 0.0

    def __post_init__(self):
        self.vertex = np.asarray(self.vertex, np.int64).reshape(-1)
        self.normal = np.asarray(self.normal, np.float64).reshape(-1, 3)
        k = self.vertex.size
        if self.normal.shape[0] != k:
            raise ValueError(f"ContactSupport: {k} vertices but {self.normal.shape[0]} normals")
        length = np.linalg.norm(self.normal, axis=1)
        if not np.all(np.isfinite(length)) or np.any(length < 1e-12):
            raise ValueError("ContactSupport: every normal must be finite and non-zero")
        self.normal = self.normal / length[:, None]
        self.friction = np.broadcast_to(np.asarray(self.friction, np.float64), (k,)).copy()
        if not np.all(np.isfinite(self.friction)) or np.any(self.friction < 0):
            raise ValueError("ContactSupport: friction must be finite and >= 0")
        if np.unique(self.vertex).size != k:
            raise ValueError("ContactSupport: a vertex is listed twice")


def project_cones(f: np.ndarray, n: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """Euclidean projection of forces f (..., 3) onto the cones {|f_t| <= mu f_n} about unit normals n."""
    fn = np.einsum("...i,...i->...", f, n)
    ft = f - fn[..., None] * n
    t = np.linalg.norm(ft, axis=-1)
    inside = t <= mu * fn
    polar = mu * t <= -fn
    scale = (fn + mu * t) / (1.0 + mu * mu)
    safe_t = np.where(t > 0.0, t, 1.0)
    proj = scale[..., None] * (n + (mu / safe_t)[..., None] * ft)
    out = np.where(inside[..., None], f, np.where(polar[..., None], 0.0, proj))
    return out


def support_forces(h: dict, support: ContactSupport, weight_moments: np.ndarray, moments_of, S: np.ndarray,
                   solve_s: np.ndarray, iterations: int = 2000):
    """Contact forces (vertex_count, 3) [N] of the rule in the module docstring, and per strand whether the
    friction limit is reached somewhere (bool, (strand_count,)).

    ``weight_moments``: the moments mu_0 of the loads without support (vertex_count, 3) [J];
    ``moments_of(G)``: the tip-to-root moments of vertex loads (a function of a (vertex_count, 3) load);
    ``S``: the pairs' bending stiffness (vertex_count, 3) [J] (0 on inactive pairs); ``solve_s``: the strands
    solved (bool, (strand_count,)); unsupported strands and strands not solved get no force."""
    n = weight_moments.shape[0]
    ns = solve_s.shape[0]
    strand_of = h["vertex_strand"]
    forces = np.zeros((n, 3))
    friction_limited = np.zeros(ns, bool)
    keep = solve_s[strand_of[support.vertex]] & (h["vertex_is_fixed"][support.vertex] == 0)
    vert, nrm, fr = support.vertex[keep], support.normal[keep], support.friction[keep]
    if vert.size == 0:
        return forces, friction_limited
    # Slot q of each supported vertex within its strand (0, 1, ...), the most slots Q.
    order = np.lexsort((vert, strand_of[vert]))
    vert, nrm, fr = vert[order], nrm[order], fr[order]
    vs = strand_of[vert]
    first = np.r_[0, np.nonzero(np.diff(vs))[0] + 1]
    slot = np.arange(vert.size) - np.repeat(first, np.diff(np.r_[first, vert.size]))
    Q = int(slot.max()) + 1
    strands = np.unique(vs)
    row = np.searchsorted(strands, vs)            # batch row of each supported vertex
    B = strands.size
    # Per strand: the pairs' rows (vertex slots of the strand) and the weights 1 / S^2.
    starts, counts = h["strand_vertex_start"], h["strand_vertex_count"]
    M = int(counts[strands].max())
    pair_idx = starts[strands][:, None] + np.arange(M)[None, :]
    pair_ok = np.arange(M)[None, :] < counts[strands][:, None]
    pair_idx = np.where(pair_ok, pair_idx, 0)
    W = np.where(S > 0.0, 1.0 / np.where(S > 0.0, S, 1.0) ** 2, 0.0)[pair_idx] * pair_ok[..., None]  # (B, M, 3)
    mu0 = weight_moments[pair_idx] * pair_ok[..., None]                                           # (B, M, 3)
    # Columns of A: the moments of a unit load e_d at the q-th supported vertex of every strand at once.
    A = np.zeros((B, M, 3, Q, 3))
    for q in range(Q):
        at = slot == q
        for d in range(3):
            load = np.zeros((n, 3))
            load[vert[at], d] = 1.0
            A[:, :, :, q, d] = moments_of(load)[pair_idx] * pair_ok[..., None]
    A = A.reshape(B, 3 * M, 3 * Q)
    Wf = W.reshape(B, 3 * M)
    r0 = mu0.reshape(B, 3 * M)
    H = np.einsum("bri,br,brj->bij", A, Wf, A)
    # Cones per slot (padding slots: a zero cone, the force stays 0).
    normal = np.zeros((B, Q, 3))
    normal[..., 1] = 1.0
    mu_f = np.zeros((B, Q))
    active = np.zeros((B, Q), bool)
    normal[row, slot] = nrm
    mu_f[row, slot] = fr
    active[row, slot] = True
    # Isotropic Jacobi scaling per vertex (the cones are invariant under it, so the projection stays exact):
    # a load near the root moves few moments and one near the tip many.  Alone it did not fix the slow
    # convergence (floor test: forces still 1.7 % off after 2,000 iterations); the start below did.
    diag = np.einsum("bii->bi", H).reshape(B, Q, 3).mean(axis=2)
    scale = np.where(active & (diag > 0.0), 1.0 / np.sqrt(np.where(diag > 0.0, diag, 1.0)), 0.0)
    sc = np.repeat(scale, 3, axis=1)                                   # (B, 3Q)
    As = A * sc[:, None, :]
    L = np.maximum(np.linalg.eigvalsh(H * sc[:, :, None] * sc[:, None, :])[:, -1], 1e-300)

    def project(f):
        p = project_cones(f.reshape(B, Q, 3), normal, mu_f)
        return (p * active[..., None]).reshape(B, 3 * Q)

    # In the residual form (the moments r = mu_0 + A f themselves), not f^T H f + b^T f: the optimum is often
    # r = 0 exactly (a strand lying on the floor), where the expanded form loses the digits that matter.
    def residual(u):
        return r0 + np.einsum("bri,bi->br", As, u)

    def objective(u):
        r = residual(u)
        return 0.5 * np.einsum("br,br,br->b", r, Wf, r)

    # FISTA on the scaled unknowns u = f / scale, with adaptive restart, from the projection of the
    # unconstrained least-squares optimum (minimum norm: no force along an edge, where the rest length takes
    # the load; exact when it lies in the cones, e.g. a strand lying on a floor, where the plain start left
    # the forces 1-2 % off after 2,000 iterations: the scaled problem's condition number is ~2.5e5 there).
    sw = np.sqrt(Wf)
    u = project(-np.einsum("bir,br->bi", np.linalg.pinv(As * sw[..., None], rcond=1e-10), sw * r0))
    y, tk = u.copy(), np.ones(B)
    last = objective(u)
    for _ in range(int(iterations)):
        grad = np.einsum("bri,br->bi", As, Wf * residual(y))
        u_new = project(y - grad / L[:, None])
        t_new = 0.5 * (1.0 + np.sqrt(1.0 + 4.0 * tk * tk))
        obj = objective(u_new)
        restart = obj > last                      # momentum off where the objective rose
        mom = np.where(restart, 0.0, (tk - 1.0) / t_new)
        y = u_new + mom[:, None] * (u_new - u)
        tk = np.where(restart, 1.0, t_new)
        u, last = u_new, obj
    f = u * sc
    fq = f.reshape(B, Q, 3)
    forces[vert] = fq[row, slot]
    fn = np.einsum("ki,ki->k", forces[vert], nrm)
    ft = np.linalg.norm(forces[vert] - fn[:, None] * nrm, axis=1)
    limited = (fn > 0.0) & (ft >= 0.999 * fr * fn) & (fr * fn > 0.0)
    friction_limited[np.unique(vs[limited])] = True
    return forces, friction_limited


def _signed_distance_and_normal(collider, p: np.ndarray, within: float = np.inf):
    """Signed distance (k,) [m] and outward unit normal (k, 3) of points p (k, 3) to one collider, in its
    body frame (exact geometry: for a mesh the distance to its triangles, the normal from central
    differences of that distance, the sign from the generalized winding number; for a mesh the normal only
    where |distance| <= ``within`` [m], zero elsewhere, and the distance +inf where a bound shows it is beyond
    ``within``)."""
    from ..contact.colliders import CapsuleCollider, MeshCollider, PlaneCollider, SphereCollider

    if isinstance(collider, PlaneCollider):
        n = np.asarray(collider.normal, np.float64)
        return (p - np.asarray(collider.point)) @ n, np.tile(n, (len(p), 1))
    if isinstance(collider, SphereCollider):
        r = p - np.asarray(collider.center)
        d = np.linalg.norm(r, axis=1)
        return d - collider.radius, r / np.maximum(d, 1e-300)[:, None]
    if isinstance(collider, CapsuleCollider):
        a, b = np.asarray(collider.p0), np.asarray(collider.p1)
        ab = b - a
        s = np.clip((p - a) @ ab / max(float(ab @ ab), 1e-300), 0.0, 1.0)
        r = p - (a + s[:, None] * ab)
        d = np.linalg.norm(r, axis=1)
        return d - collider.radius, r / np.maximum(d, 1e-300)[:, None]
    if isinstance(collider, MeshCollider):
        query = collider.triangle_query
        d = np.full(len(p), np.inf)
        cand = np.arange(len(p))
        if np.isfinite(within):
            # Only points that may lie within ``within`` of the surface get the exact (slow) distance: any point
            # of a triangle is within its longest edge of one of its vertices, so |d| >= (distance to the
            # nearest mesh vertex) - (longest edge).  Points beyond are returned at +inf (never a support).
            # Measured on the 8,600-guide groom (benchmarks/bench_rest_pose_solve.py): the exact distance of
            # every free vertex took 25 s.
            from scipy.spatial import cKDTree

            v, f = np.asarray(query.vertices, np.float64), np.asarray(query.faces)
            edge = max(float(np.max(np.linalg.norm(v[f] - v[np.roll(f, 1, axis=1)], axis=2))), 0.0)
            lower = cKDTree(v).query(p)[0] - edge
            cand = np.nonzero(lower <= within)[0]
        d[cand] = query.signed_distance(p[cand])
        near = np.nonzero(np.abs(d) <= within)[0]
        q, step = p[near], 1e-5
        grad = np.stack([(query.unsigned_distance(q + step * e) - query.unsigned_distance(q - step * e)) / (2 * step)
                         for e in np.eye(3)], axis=1)
        grad *= np.where(d[near] < 0.0, -1.0, 1.0)[:, None]
        normal = np.zeros((len(p), 3))
        normal[near] = grad / np.maximum(np.linalg.norm(grad, axis=1), 1e-300)[:, None]
        return d, normal
    raise ValueError(f"support_from_colliders: no support from a {type(collider).__name__}")


def support_from_colliders(model, colliders, reach: float = 5e-4) -> ContactSupport:
    """The free vertices of the Model's authored shape within ``reach`` [m] of a collider's surface (outside
    it, distance from the fibre's surface, i.e. centre distance minus the strand's radius), with the
    collider's outward normal and friction: the body may push on them (:func:`support_forces`).  Colliders
    are taken in the frame the groom is authored in (their body frame); the nearest collider wins.

    The reach, 0.5 mm by default, is a choice: a vertex that close leans on the body after a drift the
    size of the reach, the sag-free target's scale (issue 14: 1 mm)."""
    if not (np.isfinite(reach) and reach >= 0):
        raise ValueError(f"support_from_colliders: reach must be a finite number >= 0, got {reach!r}")
    h = model.host
    x = np.asarray(h["vertex_rest_position"], np.float64)
    free = np.nonzero(np.asarray(h["vertex_is_fixed"]) == 0)[0]
    radius = np.array([m.radius for m in model.materials], np.float64)[np.asarray(h["vertex_strand"])[free]]
    best = np.full(free.size, np.inf)
    normal = np.zeros((free.size, 3))
    friction = np.zeros(free.size)
    for c in colliders:
        d, n = _signed_distance_and_normal(c, x[free], within=reach + float(radius.max(initial=0.0)))
        gap = d - radius
        take = (gap >= -radius) & (gap <= reach) & (gap < best)
        best[take], normal[take], friction[take] = gap[take], n[take], float(c.friction)
    sel = np.isfinite(best)
    return ContactSupport(vertex=free[sel], normal=normal[sel], friction=friction[sel])
