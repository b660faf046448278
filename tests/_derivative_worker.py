"""Finite-difference checks of the strain measures, run in double precision.

Invoked as ``python tests/_derivative_worker.py`` by ``test_strains.py``; prints
one JSON object with the largest relative errors of each check.  Everything
here calls the production ``ti.func`` s of :mod:`taichi_hair.strains`.
"""

import json
import math
import os
import sys

import numpy as np
import taichi as ti

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import taichi_hair  # noqa: E402
taichi_hair.init(arch=ti.cpu, default_fp=ti.f64, log_level=ti.WARN)

from taichi_hair import strains as S  # noqa: E402
from taichi_hair.frames import wrap_angle  # noqa: E402

vec3 = ti.math.vec3
N_CASES = 24
P = 8  # parameters: e_a (3), e_b (3), theta_a, theta_b

# Base configuration per case: edges, frames (m1 per edge), rest strain, stiffness.
base_e = ti.Vector.field(3, float, (N_CASES, 2))
base_m1 = ti.Vector.field(3, float, (N_CASES, 2))
rest_kappa = ti.Vector.field(3, float, N_CASES)
stiff = ti.Vector.field(3, float, N_CASES)
params = ti.field(float, (N_CASES, P))  # perturbation applied to the base
out_kappa = ti.Vector.field(3, float, N_CASES)
out_energy = ti.field(float, N_CASES)
out_jac = ti.Matrix.field(3, 6, float, N_CASES)
out_dth = ti.Vector.field(3, float, (N_CASES, 5))
out_grad = ti.field(float, (N_CASES, P))
out_hess = ti.field(float, (N_CASES, 6, 6))


@ti.func
def frames_at(c: int, measure: ti.template()):
    """Material frames and strain after perturbing edges and twists by params[c]."""
    ea0, eb0 = base_e[c, 0], base_e[c, 1]
    ta0, tb0 = ea0.normalized(), eb0.normalized()
    ea = ea0 + vec3(params[c, 0], params[c, 1], params[c, 2])
    eb = eb0 + vec3(params[c, 3], params[c, 4], params[c, 5])
    ta, tb = ea.normalized(), eb.normalized()
    m1a, m2a = S.transported_material_frame(base_m1[c, 0], ta0, ta, params[c, 6])
    m1b, m2b = S.transported_material_frame(base_m1[c, 1], tb0, tb, params[c, 7])
    # Bergou twist: total material twist angle, continuous from the base configuration.
    m1a0 = base_m1[c, 0]
    ang0 = S.signed_angle(S.parallel_transport(m1a0, ta0, tb0), base_m1[c, 1], tb0)
    ang = S.signed_angle(S.parallel_transport(m1a, ta, tb), m1b, tb)
    twist = ang0 + wrap_angle(ang - ang0)
    kappa = S.pair_kappa(measure, m1a, m2a, ta, m1b, m2b, tb, twist)
    return ea, eb, m1a, m2a, ta, m1b, m2b, tb, kappa


@ti.kernel
def evaluate(measure: ti.template()):
    for c in range(N_CASES):
        ea, eb, m1a, m2a, ta, m1b, m2b, tb, kappa = frames_at(c, measure)
        out_kappa[c] = kappa
        la, lb = base_e[c, 0].norm(), base_e[c, 1].norm()
        eps_a, ga = S.stretch_strain(measure, ea, la)
        eps_b, gb = S.stretch_strain(measure, eb, lb)
        ks = 1e3
        out_energy[c] = S.bend_energy(kappa, rest_kappa[c], stiff[c]) + S.stretch_energy(eps_a, ks) + \
            S.stretch_energy(eps_b, ks)
        J = S.pair_edge_jacobian(measure, m1a, m2a, ta, ea.norm(), m1b, m2b, tb, eb.norm())
        out_jac[c] = J
        d = S.pair_twist_derivatives(measure, kappa, m1a, m2a, ta, m1b, m2b, tb)
        for k in ti.static(range(5)):
            out_dth[c, k] = d[k]
        # Analytic gradient of the energy in (e_a, e_b, theta_a, theta_b).
        gk = stiff[c] * (kappa - rest_kappa[c])
        g6 = J.transpose() @ gk
        for r in ti.static(range(3)):
            out_grad[c, r] = g6[r] + ks * eps_a * ga[r]
            out_grad[c, r + 3] = g6[r + 3] + ks * eps_b * gb[r]
        out_grad[c, 6] = gk.dot(d[0])
        out_grad[c, 7] = gk.dot(d[1])
        # Gauss-Newton Hessian of the edge block (what the local step uses).
        for r, q in ti.static(ti.ndrange(6, 6)):
            h = 0.0
            for a in ti.static(range(3)):
                h += J[a, r] * stiff[c][a] * J[a, q]
            out_hess[c, r, q] = h
        for r, q in ti.static(ti.ndrange(3, 3)):
            out_hess[c, r, q] += ks * ga[r] * ga[q]
            out_hess[c, r + 3, q + 3] += ks * gb[r] * gb[q]


def setup(rng, at_rest: bool):
    for c in range(N_CASES):
        ea = rng.normal(size=3)
        ea /= np.linalg.norm(ea)
        # Turning angle up to ~100 degrees, varied edge lengths.
        axis = np.cross(ea, rng.normal(size=3))
        axis /= np.linalg.norm(axis)
        phi = rng.uniform(0.05, 1.8)
        eb = ea * math.cos(phi) + np.cross(axis, ea) * math.sin(phi)
        la, lb = rng.uniform(0.5, 2.0, size=2)
        ta, tb = ea.copy(), eb.copy()
        d = np.cross(ta, rng.normal(size=3))
        d /= np.linalg.norm(d)
        th_a, th_b = rng.uniform(-1, 1, size=2)
        # Frame b: transport of frame a then an extra twist, so twist strain is non-zero.
        b = np.cross(ta, tb)
        cc = np.dot(ta, tb)
        db = cc * d + np.cross(b, d) + np.dot(b, d) / (1 + cc) * b
        d2a = np.cross(ta, d)
        m1a = math.cos(th_a) * d + math.sin(th_a) * d2a
        d2b = np.cross(tb, db)
        m1b = math.cos(th_b) * db + math.sin(th_b) * d2b
        base_e[c, 0] = (ea * la).tolist()
        base_e[c, 1] = (eb * lb).tolist()
        base_m1[c, 0] = m1a.tolist()
        base_m1[c, 1] = m1b.tolist()
        stiff[c] = rng.uniform(0.5, 2.0, size=3).tolist()
    params.fill(0.0)


def run_checks(measure: int, at_rest: bool, seed: int) -> dict:
    rng = np.random.default_rng(seed)
    setup(rng, at_rest)
    evaluate(measure)
    kappa0 = out_kappa.to_numpy()
    if at_rest:
        rest_kappa.from_numpy(kappa0)
    else:
        rest_kappa.from_numpy(kappa0 + rng.normal(scale=0.3, size=kappa0.shape))
    evaluate(measure)
    J = out_jac.to_numpy()
    dth = out_dth.to_numpy()
    grad = out_grad.to_numpy()
    hess = out_hess.to_numpy()
    h = 1e-6
    fd_jac = np.zeros((N_CASES, 3, P))
    fd_grad = np.zeros((N_CASES, P))
    fd_k2 = np.zeros((N_CASES, 3, 3))  # d2 kappa / dtheta (aa, bb, ab)
    fd_hess = np.zeros((N_CASES, 6, 6))
    p0 = np.zeros((N_CASES, P))

    def eval_at(p):
        params.from_numpy(p)
        evaluate(measure)
        return out_kappa.to_numpy(), out_energy.to_numpy()

    for k in range(P):
        dp = np.zeros((N_CASES, P))
        dp[:, k] = h
        kp, ep = eval_at(p0 + dp)
        km, em = eval_at(p0 - dp)
        fd_jac[:, :, k] = (kp - km) / (2 * h)
        fd_grad[:, k] = (ep - em) / (2 * h)
    # Second twist derivatives of kappa.
    hh = 1e-4
    k0, e0 = eval_at(p0)
    for idx, (a, b) in enumerate([(6, 6), (7, 7), (6, 7)]):
        def at(sa, sb):
            p = p0.copy()
            p[:, a] += sa * hh
            p[:, b] += sb * hh
            return eval_at(p)[0]
        if a == b:
            fd_k2[:, :, idx] = (at(1, 0) - 2 * k0 + at(-1, 0)) / hh**2
        else:
            fd_k2[:, :, idx] = (at(1, 1) - at(1, -1) - at(-1, 1) + at(-1, -1)) / (4 * hh**2)
    # Energy Hessian in the edges (for the Gauss-Newton comparison at rest).
    for r in range(6):
        for q in range(6):
            def e_at(sr, sq):
                p = p0.copy()
                p[:, r] += sr * hh
                p[:, q] += sq * hh
                return eval_at(p)[1]
            fd_hess[:, r, q] = (e_at(1, 1) - e_at(1, -1) - e_at(-1, 1) + e_at(-1, -1)) / (4 * hh**2)

    def rel(a, b):
        return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-30))

    an_k2 = np.stack([dth[:, 2], dth[:, 3], dth[:, 4]], axis=-1)
    return {
        "edge_jacobian": rel(J, fd_jac[:, :, :6]),
        "twist_jacobian": rel(np.stack([dth[:, 0], dth[:, 1]], -1), fd_jac[:, :, 6:]),
        "twist_second": rel(an_k2, fd_k2),
        "energy_gradient": rel(grad, fd_grad),
        "gauss_newton_hessian": rel(hess, fd_hess),
    }


if __name__ == "__main__":
    res = {}
    for name, measure in (("korner", S.KORNER), ("bergou", S.BERGOU)):
        res[name] = run_checks(measure, at_rest=False, seed=1)
        res[name + "_at_rest"] = run_checks(measure, at_rest=True, seed=2)
    print(json.dumps(res))
