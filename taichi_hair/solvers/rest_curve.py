"""A rest pose as a curve: the rest shape a groom's strands would take without gravity, and back.

:func:`~taichi_hair.solvers.rest_pose.solve_rest_pose` gives rest strains kappa_bar (the Model stores the
rest moments mu = S (kappa(x*) - kappa_bar)).  Files carry shapes, so a solved rest pose is written as the
*rest curve*: the polyline (and twist of its material frame) whose strains are kappa_bar, with the
authored root edge.  That is the meaning of USD's ``rest`` primvar (Groom.rest_points): the shape a strand
relaxes to; ``points`` stays the authored shape x*.  The twist of the rest curve's material frame about its
space-parallel reference frame is a per-vertex angle (Groom.params cannot hold arrays: the writers store it
as ``rest_twist``, a per-vertex attribute, where the format has one; without it the rest curve's frames
are its Bishop frames, exact when kappa_bar has no twist component).

Reconstruction (Korner strain, the default): kappa_bar_i = 2 v_i for the unit quaternion (w_i, v_i) of the
rotation R_i = F_{i-1}^T F_i between adjacent material frames, so F_i = F_{i-1} R(w_i, v_i) with
w_i = sqrt(1 - |v_i|^2), starting from the authored root frame F_0, and x_{i+1} = x_i + e_bar_i t_i.
Reading back (:func:`moments_from_rest_curve`): kappa of the rest curve's frames, mu = S (kappa(x*) -
kappa_rest).  Both directions are float64 and round-trip to round-off (tested).  The Bergou strain has no
such closed-form frame rotation: rest curves are written for Korner only.
"""

from __future__ import annotations

import numpy as np

from ..model import pair_voronoi_length
from .rest_pose import _dot, pair_strain_jacobians, rest_frames


def _quaternion_matrix(w: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotation matrices (k, 3, 3) of unit quaternions (w, v): (w^2 - v.v) I + 2 v v^T + 2 w [v]x."""
    k = w.shape[0]
    R = (w * w - _dot(v, v))[:, None, None] * np.eye(3)[None] + 2.0 * v[:, :, None] * v[:, None, :]
    vx = np.zeros((k, 3, 3))
    vx[:, 0, 1], vx[:, 0, 2], vx[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    vx[:, 1, 0], vx[:, 2, 0], vx[:, 2, 1] = v[:, 2], -v[:, 1], v[:, 0]
    return R + 2.0 * w[:, None, None] * vx


def rest_curve(model, rest_strain: np.ndarray, rest_length: np.ndarray | None = None):
    """The rest curve of every strand for Korner rest strains ``rest_strain`` (vertex_count, 3) [-].

    Returns (points (n, 3) [m], twist (n,) [rad]): the rest polyline with the authored root edge, and the
    angle of its material frame from its space-parallel reference frame (the builder's ``twist``)."""
    from ..builder import space_parallel_directors

    h = model.host
    m1, m2, t, e, _ = rest_frames(h)
    x = np.asarray(h["vertex_rest_position"], np.float64).copy()
    le = np.asarray(h["edge_rest_length"] if rest_length is None else rest_length, np.float64)
    kb = np.asarray(rest_strain, np.float64)
    starts, counts = h["strand_vertex_start"], h["strand_vertex_count"]
    F1, F2, F3 = m1.copy(), m2.copy(), t.copy()
    for j in range(1, int(counts.max()) - 1):
        idx = starts[counts - 1 > j] + j              # pair j of each strand long enough; its edge b = j
        v = 0.5 * kb[idx]
        nv = np.linalg.norm(v, axis=1)
        if np.any(nv > 1.0 + 1e-12):
            raise ValueError(f"rest curve: vertex {int(idx[np.argmax(nv)])}: |kappa_bar| = {2 * nv.max():.4g} > 2 has "
                             "no Korner rotation")
        v = v / np.maximum(nv, 1.0)[:, None]
        w = np.sqrt(np.maximum(1.0 - _dot(v, v), 0.0))
        R = _quaternion_matrix(w, v)
        a = idx - 1
        # [d1_b d2_b t_b] = [d1_a d2_a t_a] R  (R_kl = d_k^a . d_l^b)
        Fa = np.stack([F1[a], F2[a], F3[a]], axis=2)   # columns d1, d2, t
        Fb = np.matmul(Fa, R)
        F1[idx], F2[idx], F3[idx] = Fb[:, :, 0], Fb[:, :, 1], Fb[:, :, 2]
        x[idx + 1] = x[idx] + le[idx][:, None] * F3[idx]
    tangent = np.where((le > 0)[:, None], F3, 0.0)
    ref = space_parallel_directors(tangent, starts, counts, np.asarray(h["strand_root_director"], np.float64))
    twist = np.arctan2(_dot(np.cross(ref, F1), tangent), _dot(ref, F1))
    twist[le <= 0] = 0.0
    twist[starts] = np.asarray(h["edge_rest_twist"], np.float64)[starts]
    return x, twist


def moments_from_rest_curve(model, rest_points: np.ndarray, rest_twist: np.ndarray | None = None,
                            solver_config=None) -> np.ndarray:
    """Rest moments mu = S (kappa(x*) - kappa_rest) that make ``rest_points`` (with ``rest_twist``, zero when
    None) the rest shape of the Model's strands, whose authored shape x* stays the initial one [J], (n, 3).

    The root edge of the rest curve must be the authored one (vertices 0 and 1 of a clamped strand are
    kinematic); rest lengths are the Model's (``rest_points`` give shape, not length)."""
    from ..builder import space_parallel_directors
    from ..config import SolverADMMConfig

    scfg = solver_config or SolverADMMConfig()
    h = model.host
    n = model.vertex_count
    xr = np.asarray(rest_points, np.float64)
    if xr.shape != (n, 3) or not np.all(np.isfinite(xr)):
        raise ValueError(f"rest curve: 'rest_points' must be a finite ({n}, 3) array, got {xr.shape}")
    starts, counts = h["strand_vertex_start"], h["strand_vertex_count"]
    local = h["vertex_local_index"]
    ghost = local == counts[h["vertex_strand"]] - 1
    e = np.zeros((n, 3))
    e[:-1] = xr[1:] - xr[:-1]
    e[ghost] = 0.0
    le = np.linalg.norm(e, axis=1)
    bad = np.nonzero(~ghost & (le <= 0.0))[0]
    if bad.size:
        s = int(h["vertex_strand"][bad[0]])
        raise ValueError(f"strand {s}: field 'rest_points' has a zero-length edge at vertex {int(local[bad[0]])}")
    t = np.where(~ghost[:, None], e / np.where(le > 0, le, 1.0)[:, None], 0.0)
    d1 = space_parallel_directors(t, starts, counts, np.asarray(h["strand_root_director"], np.float64))
    th = np.zeros(n) if rest_twist is None else np.asarray(rest_twist, np.float64).reshape(n)
    d2 = np.cross(t, d1)
    c, s_ = np.cos(th)[:, None], np.sin(th)[:, None]
    r1, r2 = c * d1 + s_ * d2, -s_ * d1 + c * d2
    active = h["pair_is_active"].astype(bool)
    ip = np.nonzero(active)[0]
    a = ip - 1
    k_rest = np.zeros((n, 3))
    k_rest[ip] = pair_strain_jacobians(scfg.strain_measure, r1[a], r2[a], t[a], le[a], r1[ip], r2[ip], t[ip], le[ip],
                                       twist=th[ip] - th[a])[0]
    m1, m2, ta, ea, la = rest_frames(h)
    tha = np.asarray(h["edge_rest_twist"], np.float64)
    nla = np.linalg.norm(ea, axis=1)
    k_auth = np.zeros((n, 3))
    k_auth[ip] = pair_strain_jacobians(scfg.strain_measure, m1[a], m2[a], ta[a], nla[a], m1[ip], m2[ip], ta[ip],
                                       nla[ip], twist=tha[ip] - tha[a])[0]
    vstar = pair_voronoi_length(h, scfg.voronoi_rescaling)
    S = np.where(active[:, None], np.asarray(h["pair_bending_modulus"], np.float64) / vstar[:, None], 0.0)
    mu = S * (k_auth - k_rest)
    clamped = (h["strand_body"] >= 0)[h["vertex_strand"]]
    return np.where((active & clamped)[:, None], mu, 0.0)


def rest_pose_from_curve(model, rest_points: np.ndarray, rest_twist: np.ndarray | None = None, solver_config=None,
                         gravity=(0.0, -9.81, 0.0)):
    """A :class:`~taichi_hair.solvers.rest_pose.RestPoseResult` for a rest curve read from a file (the rest
    moments of :func:`moments_from_rest_curve`, the Model's rest lengths), with its equilibrium residual
    under ``gravity`` (small when the file was solved for this material and gravity); apply it with
    :func:`~taichi_hair.solvers.rest_pose.apply_rest_pose`."""
    import time

    from ..config import SolverADMMConfig
    from .rest_pose import RestPoseResult, _pair_jacobians, equilibrium_residual

    t0 = time.perf_counter()
    scfg = solver_config or SolverADMMConfig()
    h = model.host
    mu = moments_from_rest_curve(model, rest_points, rest_twist, scfg)
    residual = equilibrium_residual(model, scfg, gravity, moments=mu)
    strand_of = h["vertex_strand"]
    active = h["pair_is_active"].astype(bool)
    vstar = pair_voronoi_length(h, scfg.voronoi_rescaling)
    S = np.where(active[:, None], np.asarray(h["pair_bending_modulus"], np.float64) / vstar[:, None], 0.0)
    kappa = _pair_jacobians(h, scfg.strain_measure)[0]
    kbar = kappa - np.where(S > 0, mu / np.where(S > 0, S, 1.0), 0.0)
    turn = np.zeros(model.strand_count)
    np.maximum.at(turn, strand_of, np.where(active, np.linalg.norm(kbar, axis=1), 0.0))
    unheld = [(int(s), "its root is free (no equilibrium under gravity)") for s in np.nonzero(h["strand_body"] < 0)[0]]
    return RestPoseResult(pair_rest_moment=mu, pair_rest_strain=kbar,
                          edge_rest_length=np.asarray(h["edge_rest_length"], np.float64).copy(), strand_rest_turn=turn,
                          strand_residual=residual, unheld=unheld, measure=scfg.strain_measure,
                          seconds=time.perf_counter() - t0)
