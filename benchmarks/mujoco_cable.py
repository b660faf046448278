r"""MuJoCo baseline: time for a MuJoCo cable to bring one hair rod to rest.

This module is self-contained (MuJoCo, NumPy, SciPy; no taichi; the command line
alone writes its JSON through benchmarks/harness.py). It builds one
hair rod with MuJoCo's cable model (the ``mujoco.elasticity.cable`` engine
plugin on an explicit body chain, i.e. what ``<composite type="cable">``
generates, with a clamp that is correct at the root) and measures the wall time
MuJoCo needs to bring it from the straight horizontal state to its static
equilibrium under gravity (the heavy cantilever).

Run ``python benchmarks/mujoco_cable.py`` (``--help`` for options); figures go to
stdout and, as JSON with the harness's machine block, to
``benchmarks/results/mujoco_cable.json``.

The rod
-------
Naturally straight, L = 10 cm, 40 edges (41 vertices), circular section
R = 0.05 mm, rho = 1300 kg/m^3, E = 3 GPa, nu = 0.45 (G = E / (2 (1 + nu))),
g = 9.81 m/s^2 along -z, clamped horizontally at the root (position and
tangent +x fixed, material frame fixed), free at the tip.

    A = pi R^2 = 7.854e-9 m^2,  I = pi R^4 / 4 = 4.909e-18 m^4,
    EI = 1.4726e-8 N m^2,       q = rho g A = 1.0016e-4 N/m,
    Gamma = q L^3 / (E I) = 6.8016.

Gamma is NOT small: a 10 cm hair is floppy. Linear beam theory would give a tip
drop q L^4 / (8 E I) = 8.50 cm (85 % of the length), which is meaningless; the
heavy elastica (E I theta'' = -q (L - s) cos(theta), theta(0) = 0,
theta'(L) = 0, solved here with scipy's solve_bvp) gives a tip drop of
0.592775 L = 5.928 cm.  The linear figure is still printed for reference, and
the physics check compares MuJoCo with the elastica (and with the exact
equilibrium of the same 40-edge discretisation).  Linear theory is accurate
only for small Gamma, e.g. a 1 cm piece of the same hair (Gamma = 0.0068),
which the test in ``tests/test_mujoco_cable_baseline.py`` also checks.

Model (see ``build_cable_model``)
---------------------------------
* Units.  MuJoCo rejects moving bodies whose mass or inertia is below
  mjMINVAL = 1e-15 and clamps tiny pivots of the mass matrix; in SI the polar
  inertia of one 2.5 mm segment is 3.2e-17 kg m^2, so the SI model does not
  even compile.  The model is therefore written in millimetres, milligrams and
  seconds (all numbers O(1e-5..1e12), the polar inertia becomes 3.2e-5
  mg mm^2).  This is an exact change of units: time stays in seconds, and all
  results are converted back to SI.
* Bodies.  One body per edge, frame at the edge's first vertex, x axis along
  the edge, a ``cylinder`` geom of radius R from 0 to l = L/n along x with
  ``density`` = rho: mass rho A l per edge, exactly rho A per unit length with
  the uniform-segment inertia (no capsule hemispheres, which would add
  4R/(3l) = 2.7 % of spurious mass).  Total mass 1.0210e-6 kg.  Each body is
  attached to its parent by a ball joint at its first vertex (3 dofs).
* Elasticity.  ``mujoco.elasticity.cable`` with ``bend`` = E, ``twist`` = G,
  ``flat`` = true (straight rest shape).  The plugin takes the radius from
  the body's own geom (``size[0]`` of a cylinder/capsule) and uses
  I = pi r^4/4, J = pi r^4/2, so the geom size must be the physical radius
  (it is).  The moment at the joint between a body and its predecessor is
  -(E I) * omega / d, where omega is the rotation vector of the relative
  rotation and d the distance between the two body origins, i.e. the
  discrete-elastic-rod bending energy sum_k E I |phi_k|^2 / (2 d_k) with d_k
  the Voronoi length of the joint.
* Clamp.  ``<composite type="cable" initial="none">`` welds the whole first
  edge and puts the first elastic joint at vertex 1; with 40 edges that
  under-predicts the (linear) tip drop by 5 % (0.9506 = sum_{m=1}^{39} m^3 /
  (40^4 / 4), the root term is missing; measured 0.95062 with a composite
  cable on the 1 cm rod).  Here a massless, welded "clamp"
  body of length l/2 (from x = -l/2 to 0) carries the plugin too, and the first
  real edge hangs from it by a ball joint at the root vertex x = 0.  The root
  joint's Voronoi length is then l/2 (half an edge, as at the boundary of the
  continuous rod), its stiffness 2 E I / l, and the discrete cantilever is
  second-order accurate (trapezoidal rule: linear tip drop error
  +0.06 %, heavy elastica +0.05 % with 40 edges).  The clamp body has no dofs,
  so the root position and the full root frame (tangent +x, twist) are fixed.
* Damping.  Joint damping of joint k is set to c_k = tau * k_k where
  k_k = E I / d_k is the plugin's bending stiffness of that joint and tau
  (``damping``, seconds) a Kelvin-Voigt retardation time: the damping moment
  is tau E I dkappa/dt, a viscous bending stress that converges under mesh
  refinement (a uniform c would not).  MuJoCo applies the same coefficient
  to the three axes of a ball joint (twist included).  The integrators take
  joint damping implicitly (M + h D), while the plugin's elastic moments are
  explicit, so a heavily damped model is stable at large steps: the linear
  estimate for the stiffest joint is h k_k / c_k = h / tau < 2; measured,
  with gravity's geometric nonlinearity at Gamma = 6.8, about h / tau < 1.2
  (tuning table).
* Contacts are disabled (a lone rod; self-collision is not part of the
  benchmark).

Tuning (``python benchmarks/mujoco_cable.py --sweep``)
-----------------------------------------------------
Measured with MuJoCo 3.17.0, Python 3.11, one thread of a 2-core AMD EPYC VM
(150-210 us per step for nv = 120; the two dense 120x120 LDL factorisations
per step, of M and of M + h D, dominate).  Entries: steps until the tip stays
within 0.1 % of its final height, implicitfast integrator; ``x`` = blew up
(MuJoCo's bad-qacc reset); ``>`` = never settles within 20000 steps / 1000 s
(beyond the stable h/tau the large-step iteration just flails about, the
rotations being bounded).  All converged runs end at the same tip drop,
59.3063 mm (= the exact discrete equilibrium to ~1e-15).

    tau\h 0.001 0.003  0.01  0.02  0.03  0.05   0.1   0.2   0.3   0.5   0.6   0.7   0.8     1   1.2   1.5     2     3     5    10
    0.003      >  8013     x     x     x     x     x     x     x     x     x     x     x     x     x     x     x     x     x     x
    0.01    7120  2376   732     x     x     x     x     x     x     x     x     x     x     x     x     x     x     x     x     x
    0.03    2324   778   236   128    87    56     x     x     x     x     x     x     x     x     x     x     x     x     x     x
    0.05    1419   476   146    75    56    35     >     >     >     >     >     >     >     >     >     >     >     >     >     >
    0.1      749   253    79    42    29    22    14     >     >     >     >     >     >     >     >     >     >     >     >     >
    0.15     519   175    54    27    25    16    11     8     >     >     >     >     >     >     >     >     >     >     >     >
    0.3     1214   403   119    58    38    21     8     7     5     >     >     >     >     >     >     >     >     >     >     >
    0.5     2149   715   213   106    70    41    19     8     5    10    32     >     >     >     >     >     >     >     >     >
    1       4394  1463   438   218   145    86    42    20    13     6     4     4     4    12    46     >     >     >     >     >
    1.5     6617  2204   660   329   219   131    64    31    20    11     9     7     6     4     5    12     >     >     >     >
    2       8834  2944   882   440   293   175    87    42    28    16    13    11     9     6     5     4    12     >     >     >
    3          >  4420  1325   662   441   264   131    65    42    25    20    17    15    11     9     6     4    12     >     >
    10         >     >  4418  2208  1472   883   441   220   146    87    72    61    54    42    35    28    20    13     7     >

    integrator comparison at the chosen h = 0.7 s, tau = 1 s (median of 21):
    implicitfast h=0.7 tau=1.0: 4 steps, 0.597 ms (149 us/step)
    euler h=0.7 tau=1.0: 4 steps, 0.643 ms (161 us/step)
    discrete h=0.7 tau=1.0: 4 steps, 0.684 ms (171 us/step)
    implicit h=0.7 tau=1.0: 4 steps, 2.840 ms (710 us/step)
    (Euler and discrete take the same steps as implicitfast at every setting
    tried; implicit too, at ~5x the cost per step for the RNE derivatives.)

Reading: for tau >~ 0.3 s the inertia is negligible against h D, so
(M + h D) v+ = M v + h (f_grav(q) - K q) reduces to the relaxed fixed-point
(Picard) iteration q+ = q + (h / tau) K^-1 (f_grav(q) - K q): the step count
depends only on h / tau (best 0.6..0.8 -> 4 steps; above ~1.3 the iteration
diverges because gravity's geometric stiffness at Gamma = 6.8 makes it
non-contractive).  Smaller tau is underdamped (tau = 2 / omega_1 = 0.15 s
critically damps the first linear mode) and needs a timestep that resolves
the motion.  None of the integrators (implicitfast, implicit, Euler and the
3.13+ ``discrete``) folds the plugin's elastic forces into its implicit
metric -- only joint damping -- which is why the step counts are identical.

Chosen: implicitfast, h = 0.7 s, tau = 1.0 s (joint damping 5.9e-6 N m s/rad
inside, 1.18e-5 at the root): 4 steps, ~0.6-0.8 ms wall, mid-plateau of the
fastest region with a factor ~1.7 of margin to divergence (h/tau = 1.2 still
converges).  Steps stay at 4 for n_edges = 10..160 (the cost per step grows
~n^3 with the dense chain factorisation: 0.04, 0.17, 0.8, 4.7, 35 ms in all).

Caveat for comparisons: these settings turn MuJoCo into a quasi-static
relaxation solver (tau = 1 s is a honey-like viscosity; the 2.8 "simulated"
seconds are not physical time).  For a physically meaningful transient, the
"dynamic" reference that main() also reports uses tau = 2 / omega_1 (critical
damping of the first mode) and h = 0.01 s (~47 steps per period of that
mode): 54 steps, 0.54 s simulated, ~8-10 ms wall.
"""
from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
import time

import numpy as np

import mujoco

# Model units: millimetre, milligram, second (see module docstring).
LENGTH_UNIT = 1e-3  # metres per model length unit
MASS_UNIT = 1e-6  # kilograms per model mass unit
PLUGIN = "mujoco.elasticity.cable"

# Chosen defaults (fastest stable to rest; see the tuning table above).
DEFAULT_INTEGRATOR = "implicitfast"
DEFAULT_TIMESTEP = 0.7  # s
DEFAULT_DAMPING = 1.0  # s, Kelvin-Voigt time tau: c_k = tau * E I / d_k
# "dynamic" reference: tau = 2 / omega_1 (computed per rod), this timestep
DYNAMIC_TIMESTEP = 0.01  # s


# --------------------------------------------------------------------------
# rod constants and reference solutions
# --------------------------------------------------------------------------
def rod_constants(length=0.1, radius=5e-5, density=1300.0, young=3e9,
                  poisson=0.45, gravity=9.81):
    """Cross-section constants of the rod (SI)."""
    area = math.pi * radius ** 2
    inertia = math.pi * radius ** 4 / 4.0
    shear = young / (2.0 * (1.0 + poisson))
    ei = young * inertia
    q = density * gravity * area  # weight per unit length
    return {
        "area_m2": area,
        "second_moment_m4": inertia,
        "shear_modulus_pa": shear,
        "bending_stiffness_nm2": ei,
        "twist_stiffness_nm2": shear * 2.0 * inertia,
        "weight_per_length_n_per_m": q,
        "mass_per_length_kg_per_m": density * area,
        "gamma": q * length ** 3 / ei,
        "linear_theory_tip_drop_m": q * length ** 4 / (8.0 * ei),
        # first bending mode of the linear cantilever, rad/s
        "omega1_rad_s": 1.8751040687 ** 2 * math.sqrt(ei / (density * area * length ** 4)),
    }


def heavy_elastica_tip_drop(gamma, length=1.0):
    """Tip drop of the inextensible heavy cantilever (continuous elastica).

    E I theta'' = -q (L - s) cos(theta), theta(0) = 0, theta'(L) = 0 and
    tip drop = int_0^L sin(theta) ds; in s/L this depends only on
    gamma = q L^3 / (E I).
    """
    from scipy.integrate import solve_bvp

    def rhs(s, y):
        return np.vstack([y[1], -gamma * (1.0 - s) * np.cos(y[0]), np.sin(y[0])])

    def bc(ya, yb):
        return np.array([ya[0], yb[1], ya[2]])

    s = np.linspace(0.0, 1.0, 401)
    y = np.zeros((3, s.size))
    # start from a damped version of the linear solution (robust for large gamma)
    lin = gamma * (1.0 - (1.0 - s) ** 3) / 6.0
    y[0] = np.clip(lin, 0.0, 1.2)
    y[1] = np.gradient(y[0], s)
    y[2] = np.cumsum(np.sin(y[0])) * (s[1] - s[0])
    sol = solve_bvp(rhs, bc, s, y, tol=1e-10, max_nodes=200000)
    if sol.status != 0:
        raise RuntimeError("heavy elastica BVP did not converge: " + sol.message)
    return float(sol.y[2, -1]) * length


def discrete_chain_tip_drop(n_edges, gamma, length=1.0):
    """Exact static tip drop of the same discretisation as the MuJoCo model.

    n rigid uniform segments of length l = L/n hanging from rotational springs
    of stiffness E I / d_k at the vertices k = 0..n-1 (d_0 = l/2 at the clamp,
    d_k = l inside); planar large-rotation equilibrium solved with Newton
    (scipy.optimize.root).  Lengths in units of L, E I = 1, q = gamma.
    """
    from scipy.optimize import root

    n = int(n_edges)
    l = 1.0 / n
    k = np.full(n, 1.0 / l)
    k[0] = 1.0 / (0.5 * l)

    def residual(phi):
        th = np.cumsum(phi)
        c = np.cos(th)
        xv = np.concatenate([[0.0], np.cumsum(l * c)])  # vertex abscissae
        xc = xv[:-1] + 0.5 * l * c  # segment centres
        # moment of the weight of segments k..n-1 about vertex k
        wsum = np.cumsum((xc)[::-1])[::-1]  # sum_{j>=k} xc_j
        count = n - np.arange(n)
        moment = gamma * l * (wsum - count * xv[:-1])
        return k * phi - moment

    phi0 = np.zeros(n)
    sol = root(residual, phi0, method="hybr", tol=1e-14)
    if np.max(np.abs(residual(sol.x))) > 1e-9:
        raise RuntimeError("discrete chain equilibrium did not converge")
    th = np.cumsum(sol.x)
    return float(np.sum(l * np.sin(th))) * length


# --------------------------------------------------------------------------
# model
# --------------------------------------------------------------------------
def _f(x):
    return repr(float(x))


# MJCF spelling of the integrator keywords
_MJCF_INTEGRATOR = {"euler": "Euler", "rk4": "RK4", "implicit": "implicit",
                    "implicitfast": "implicitfast", "discrete": "discrete"}


def cable_xml(n_edges=40, length=0.1, radius=5e-5, density=1300.0, young=3e9,
              poisson=0.45, gravity=9.81, timestep=None, damping=None,
              integrator=None):
    """MJCF text of the clamped cable (model units mm, mg, s)."""
    timestep = DEFAULT_TIMESTEP if timestep is None else float(timestep)
    damping = DEFAULT_DAMPING if damping is None else float(damping)
    integrator = DEFAULT_INTEGRATOR if integrator is None else str(integrator)
    integrator = _MJCF_INTEGRATOR.get(integrator.lower(), integrator)
    n = int(n_edges)
    if n < 2:
        raise ValueError("need at least 2 edges")

    lu, mu = LENGTH_UNIT, MASS_UNIT
    stress_unit = mu / lu  # Pa per model stress unit (mg / (mm s^2))
    l = length / n / lu  # edge length, mm
    r = radius / lu
    rho = density / (mu / lu ** 3)
    young_m = young / stress_unit
    shear_m = young_m / (2.0 * (1.0 + poisson))
    g = gravity / lu
    ei_m = young_m * math.pi * r ** 4 / 4.0  # bending stiffness in model units
    # joint damping c_k = tau * E I / d_k  (d_0 = l/2 at the clamp, l inside)
    c_root = damping * ei_m / (0.5 * l)
    c_in = damping * ei_m / l

    out = []
    out.append('<mujoco model="hair_cable">')
    out.append('<compiler angle="radian"/>')
    out.append(
        f'<option timestep="{_f(timestep)}" gravity="0 0 {_f(-g)}" '
        f'integrator="{integrator}"><flag contact="disable"/></option>')
    out.append(
        '<custom>'
        f'<numeric name="length_unit" data="{_f(lu)}"/>'
        f'<numeric name="mass_unit" data="{_f(mu)}"/>'
        f'<numeric name="n_edges" data="{n}"/>'
        f'<numeric name="rod_length" data="{_f(length)}"/>'
        f'<numeric name="radius" data="{_f(radius)}"/>'
        f'<numeric name="density" data="{_f(density)}"/>'
        f'<numeric name="young" data="{_f(young)}"/>'
        f'<numeric name="poisson" data="{_f(poisson)}"/>'
        f'<numeric name="gravity" data="{_f(gravity)}"/>'
        f'<numeric name="damping_time" data="{_f(damping)}"/>'
        '</custom>')
    out.append(
        f'<extension><plugin plugin="{PLUGIN}"><instance name="rod">'
        f'<config key="bend" value="{_f(young_m)}"/>'
        f'<config key="twist" value="{_f(shear_m)}"/>'
        '<config key="flat" value="true"/>'
        '<config key="vmax" value="0"/>'
        '</instance></plugin></extension>')
    out.append('<worldbody>')
    # Welded clamp: half an edge behind the root vertex; carries the plugin so
    # that the root joint gets the boundary Voronoi length l/2.
    out.append(
        f'<body name="clamp" pos="{_f(-0.5 * l)} 0 0"><plugin instance="rod"/>'
        f'<geom name="clamp" type="cylinder" size="{_f(r)}" '
        f'fromto="0 0 0 {_f(0.5 * l)} 0 0" density="0" contype="0" conaffinity="0"/>')
    for i in range(n):
        pos = 0.5 * l if i == 0 else l
        c = c_root if i == 0 else c_in
        out.append(
            f'<body name="e{i}" pos="{_f(pos)} 0 0"><plugin instance="rod"/>'
            f'<joint name="v{i}" type="ball" damping="{_f(c)}"/>'
            f'<geom type="cylinder" size="{_f(r)}" fromto="0 0 0 {_f(l)} 0 0" '
            f'density="{_f(rho)}" contype="0" conaffinity="0"/>')
    out.append(f'<site name="tip" pos="{_f(l)} 0 0"/>')
    out.append('</body>' * (n + 1))
    out.append('</worldbody></mujoco>')
    return "".join(out)


def build_cable_model(n_edges=40, length=0.1, radius=5e-5, density=1300.0,
                      young=3e9, poisson=0.45, gravity=9.81, timestep=None,
                      damping=None, integrator=None):
    """Compile the clamped hair cable; returns a ``mujoco.MjModel``.

    Arguments are SI (``timestep`` in s).  ``damping`` is the Kelvin-Voigt
    retardation time tau in seconds: joint k gets damping tau * E I / d_k
    [N m s / rad] (see module docstring).  ``None`` picks the tuned defaults
    DEFAULT_TIMESTEP, DEFAULT_DAMPING, DEFAULT_INTEGRATOR.
    """
    xml = cable_xml(n_edges=n_edges, length=length, radius=radius,
                    density=density, young=young, poisson=poisson,
                    gravity=gravity, timestep=timestep, damping=damping,
                    integrator=integrator)
    return mujoco.MjModel.from_xml_string(xml)


def _numeric(model, name):
    return float(model.numeric(name).data[0])


def model_params(model):
    """Rod parameters (SI) stored in a model built by build_cable_model."""
    names = ["length_unit", "mass_unit", "n_edges", "rod_length", "radius",
             "density", "young", "poisson", "gravity", "damping_time"]
    return {k: _numeric(model, k) for k in names}


def tip_height_m(model, data):
    """Tip height (SI metres) relative to the clamp (z = 0)."""
    return float(data.site("tip").xpos[2]) * _numeric(model, "length_unit")


# --------------------------------------------------------------------------
# time to rest
# --------------------------------------------------------------------------
def _integrator_name(model):
    return mujoco.mjtIntegrator(model.opt.integrator).name.replace("mjINT_", "").lower()


def time_to_rest(model=None, rel_tol=1e-3, max_sim_time=1000.0,
                 max_steps=100000, vel_tol=1e-7, repeats=21, **build_kwargs):
    """Wall time for MuJoCo to bring the rod to rest from the straight state.

    Pass 1 (untimed) steps the model from the initial straight state until it
    is at rest -- tip speed below ``vel_tol`` m/s and every joint angular
    speed below ``vel_tol`` / (rod length) rad/s, held for at least 100
    steps and 1 % of the steps so far -- the tip height then is the final
    equilibrium tip height z_f.  RuntimeError if that does not happen within
    ``max_sim_time`` simulated seconds or ``max_steps`` steps, and
    FloatingPointError if the simulation blows up.  The tip height
    after every step is recorded; the settle step N is the first step after
    which |z - z_f| <= rel_tol |z_f| for all later recorded steps.

    Pass 2 (timed) resets to the initial state and runs exactly N steps with a
    single ``mujoco.mj_step(model, data, N)`` call (MuJoCo is deterministic,
    so this is the same trajectory; the settle tolerance is re-checked at the
    end).  It is repeated ``repeats`` times; ``wall_s`` is the median.
    Model compilation, MjData allocation and resets are excluded.  For
    reference ``wall_s_stepwise`` times a Python loop that steps one step at a
    time and checks the tip after each step (what a naive script would do).

    If ``model`` is None it is built with ``build_cable_model(**build_kwargs)``
    and the build is timed (``compile_s``); otherwise ``compile_s`` is None
    (a given model must come from ``build_cable_model``: units, rod data and
    the "tip" site are read from it).

    Returns a dict: wall_s, compile_s, steps, sim_time_s, final_tip_drop_m,
    linear_theory_tip_drop_m, timestep, integrator, plus wall_s_min,
    wall_s_stepwise, wall_s_per_step, heavy-elastica and same-discretisation
    reference drops with relative differences, gamma, damping, mass, nv.
    """
    compile_s = None
    if model is None:
        t0 = time.perf_counter()
        model = build_cable_model(**build_kwargs)
        compile_s = time.perf_counter() - t0
    elif build_kwargs:
        raise TypeError("build arguments given together with a model")

    p = model_params(model)
    lu = p["length_unit"]
    rod_len = p["rod_length"]
    dt = float(model.opt.timestep)
    data = mujoco.MjData(model)
    tip_id = model.site("tip").id

    # ---- pass 1: run to rest, record the tip height after every step
    mujoco.mj_resetData(model, data)
    max_steps = min(int(max_steps), int(math.ceil(max_sim_time / dt)))
    chunk = 1
    zs = np.empty(max_steps)
    tip_vel = np.zeros(6)
    quiet = 0
    at_rest = False
    steps_done = 0
    qvel_lim = vel_tol / rod_len  # rad/s
    while steps_done < max_steps:
        mujoco.mj_step(model, data, chunk)
        zs[steps_done] = data.site_xpos[tip_id, 2] * lu
        steps_done += 1
        # MuJoCo resets mjData by itself when qacc becomes NaN/huge (and
        # warns); treat that, or non-finite state, as a blow-up
        if (data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number
                or not np.all(np.isfinite(data.qpos))):
            raise FloatingPointError(
                f"simulation blew up at t = {data.time:.6g} s (dt = {dt}, "
                f"integrator {_integrator_name(model)}, tau = {p['damping_time']})")
        mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_SITE, tip_id,
                                 tip_vel, 0)
        speed = float(np.linalg.norm(tip_vel[3:])) * lu
        if speed < vel_tol and float(np.max(np.abs(data.qvel))) < qvel_lim:
            quiet += 1
        else:
            quiet = 0
        if quiet >= max(100, int(0.01 * steps_done)):
            at_rest = True
            break
    if not at_rest:
        raise RuntimeError(
            f"not at rest after {steps_done} steps ({steps_done * dt:g} s; "
            f"dt = {dt}, tau = {p['damping_time']})")
    zs = zs[:steps_done]
    z_final = float(zs[-1])
    tol = rel_tol * abs(z_final)
    outside = np.nonzero(np.abs(zs - z_final) > tol)[0]
    settle_steps = int(outside[-1]) + 2 if outside.size else 1
    if settle_steps > steps_done:
        raise AssertionError("settle step beyond the recorded trajectory")

    # ---- pass 2: timed, from the initial state, exactly settle_steps steps
    walls = []
    for _ in range(max(1, int(repeats))):
        mujoco.mj_resetData(model, data)
        t0 = time.perf_counter()
        mujoco.mj_step(model, data, settle_steps)
        walls.append(time.perf_counter() - t0)
        z_end = data.site_xpos[tip_id, 2] * lu
        if abs(z_end - z_final) > tol * (1 + 1e-9):
            raise RuntimeError("timed pass did not reproduce the recorded trajectory")
    wall_s = statistics.median(walls)

    # ---- reference: naive python loop stepping and checking each step
    mujoco.mj_resetData(model, data)
    n_ok = 0
    t0 = time.perf_counter()
    while True:
        mujoco.mj_step(model, data)
        n_ok += 1
        if n_ok >= settle_steps and abs(data.site_xpos[tip_id, 2] * lu - z_final) <= tol:
            break
    wall_stepwise = time.perf_counter() - t0

    consts = rod_constants(length=rod_len, radius=p["radius"],
                           density=p["density"], young=p["young"],
                           poisson=p["poisson"], gravity=p["gravity"])
    n_edges = int(round(p["n_edges"]))
    elastica = heavy_elastica_tip_drop(consts["gamma"], rod_len)
    discrete = discrete_chain_tip_drop(n_edges, consts["gamma"], rod_len)
    drop = -z_final
    lin = consts["linear_theory_tip_drop_m"]
    return {
        "wall_s": wall_s,
        "wall_s_min": min(walls),
        "wall_s_stepwise": wall_stepwise,
        "wall_s_per_step": wall_s / settle_steps,
        "compile_s": compile_s,
        "steps": settle_steps,
        "sim_time_s": settle_steps * dt,
        "rel_tol": rel_tol,
        "at_rest": at_rest,
        "rest_check_steps": steps_done,
        "rest_check_sim_time_s": steps_done * dt,
        "final_tip_drop_m": drop,
        "linear_theory_tip_drop_m": lin,
        "rel_diff_vs_linear_theory": drop / lin - 1.0,
        "heavy_elastica_tip_drop_m": elastica,
        "rel_diff_vs_heavy_elastica": drop / elastica - 1.0,
        "discrete_chain_tip_drop_m": discrete,
        "rel_diff_vs_discrete_chain": drop / discrete - 1.0,
        "gamma": consts["gamma"],
        "timestep": dt,
        "integrator": _integrator_name(model),
        "damping_time_s": p["damping_time"],
        "joint_damping_nms": p["damping_time"] * consts["bending_stiffness_nm2"]
        / (rod_len / n_edges),
        "n_edges": n_edges,
        "nv": int(model.nv),
        "total_mass_kg": float(np.sum(model.body_mass)) * p["mass_unit"],
        "expected_mass_kg": consts["mass_per_length_kg_per_m"] * rod_len,
    }


# --------------------------------------------------------------------------
# tuning sweep
# --------------------------------------------------------------------------
SWEEP_TIMESTEPS = (0.001, 0.003, 0.01, 0.02, 0.03, 0.05, 0.1, 0.2, 0.3, 0.5,
                   0.6, 0.7, 0.8, 1.0, 1.2, 1.5, 2.0, 3.0, 5.0, 10.0)
SWEEP_DAMPINGS = (0.003, 0.01, 0.03, 0.05, 0.1, 0.15, 0.3, 0.5, 1.0, 1.5, 2.0,
                  3.0, 10.0)


def sweep(integrator="implicitfast", timesteps=SWEEP_TIMESTEPS,
          dampings=SWEEP_DAMPINGS, rel_tol=1e-3, repeats=3, max_steps=20000,
          verbose=True):
    """Steps/wall time to rest over a (damping time, timestep) grid.

    Returns a list of row dicts; status "ok", "unstable" (blow-up),
    "not at rest" (not settled within max_steps steps) or "wrong equilibrium".
    """
    rows = []
    for tau in dampings:
        for dt in timesteps:
            row = {"integrator": integrator, "timestep": dt,
                   "damping_time_s": tau, "steps": None, "wall_s": None}
            try:
                r = time_to_rest(rel_tol=rel_tol, repeats=repeats,
                                 max_steps=max_steps, timestep=dt,
                                 damping=tau, integrator=integrator)
                ok = abs(r["rel_diff_vs_discrete_chain"]) < 1e-4
                row.update(steps=r["steps"], sim_time_s=r["sim_time_s"],
                           wall_s=r["wall_s"], drop=r["final_tip_drop_m"],
                           status="ok" if ok else "wrong equilibrium")
            except FloatingPointError:
                row["status"] = "unstable"
            except RuntimeError:
                row["status"] = "not at rest"
            rows.append(row)
            if verbose:
                print(_row_str(row), flush=True)
    return rows


def _row_str(row):
    head = (f"{row['integrator']:>12s} dt={row['timestep']:<6g} "
            f"tau={row['damping_time_s']:<6g}")
    if row.get("steps") is None:
        return f"{head} {row['status']}"
    return (f"{head} steps={row['steps']:<6d} sim={row['sim_time_s']:<8.4g} "
            f"wall={row['wall_s'] * 1e3:9.3f} ms "
            f"drop={row['drop'] * 1e3:.4f} mm {row['status']}")


def sweep_table(rows):
    """Format sweep rows as a tau x timestep table of step counts."""
    dts = sorted({r["timestep"] for r in rows})
    taus = sorted({r["damping_time_s"] for r in rows})
    cell = {(r["damping_time_s"], r["timestep"]): r for r in rows}
    mark = {"unstable": "x", "not at rest": ">", "skipped": ".",
            "wrong equilibrium": "?"}
    lines = ["tau\\h " + " ".join(f"{dt:>5g}" for dt in dts)]
    for tau in taus:
        out = []
        for dt in dts:
            r = cell.get((tau, dt))
            if r is None:
                out.append(f"{'.':>5s}")
            elif r["status"] == "ok":
                out.append(f"{r['steps']:>5d}")
            else:
                out.append(f"{mark.get(r['status'], '?'):>5s}")
        lines.append(f"{tau:<6g} " + " ".join(out))
    return "\n".join(lines)


def compare_integrators(timestep=None, damping=None, repeats=21,
                        integrators=("implicitfast", "euler", "discrete",
                                     "implicit")):
    """Steps and wall time to rest of each integrator at one setting."""
    rows = []
    for integ in integrators:
        if integ == "discrete" and not hasattr(mujoco.mjtIntegrator,
                                               "mjINT_DISCRETE"):
            continue
        r = time_to_rest(timestep=timestep, damping=damping, integrator=integ,
                         repeats=repeats)
        rows.append({k: r[k] for k in ("integrator", "timestep",
                                        "damping_time_s", "steps", "wall_s",
                                        "wall_s_per_step")})
    return rows


# --------------------------------------------------------------------------
# command line
# --------------------------------------------------------------------------
def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=os.path.join("benchmarks", "results",
                                                  "mujoco_cable.json"))
    ap.add_argument("--n-edges", type=int, default=40)
    ap.add_argument("--timestep", type=float, default=None)
    ap.add_argument("--damping", type=float, default=None,
                    help="Kelvin-Voigt time tau [s]; joint damping = tau*EI/d_k")
    ap.add_argument("--integrator", default=None,
                    help="euler | implicit | implicitfast (default %s)"
                    % DEFAULT_INTEGRATOR)
    ap.add_argument("--rel-tol", type=float, default=1e-3)
    ap.add_argument("--repeats", type=int, default=21)
    ap.add_argument("--no-dynamic", action="store_true",
                    help="skip the 'dynamic' reference run (tau = 2/omega_1, "
                    "h = %g s)" % DYNAMIC_TIMESTEP)
    ap.add_argument("--sweep", action="store_true",
                    help="run the tuning sweep instead of the single benchmark")
    args = ap.parse_args(argv)
    from harness import Bench  # benchmarks/harness.py (the script's folder is on sys.path)

    bench = Bench("mujoco_cable", argv, script=__file__)

    if args.sweep:
        rows = sweep(integrator=args.integrator or DEFAULT_INTEGRATOR)
        print(sweep_table(rows))
        for r in compare_integrators(timestep=args.timestep,
                                     damping=args.damping):
            print(f"{r['integrator']:>12s} h={r['timestep']} tau={r['damping_time_s']}: "
                  f"{r['steps']} steps, {r['wall_s'] * 1e3:.3f} ms "
                  f"({r['wall_s_per_step'] * 1e6:.0f} us/step)")
        return 0

    res = time_to_rest(rel_tol=args.rel_tol, repeats=args.repeats,
                       n_edges=args.n_edges, timestep=args.timestep,
                       damping=args.damping, integrator=args.integrator)
    if not args.no_dynamic:
        # physically meaningful transient for reference: critical damping of
        # the first linear cantilever mode, timestep resolving that mode
        tau_dyn = 2.0 / rod_constants()["omega1_rad_s"]
        dyn = time_to_rest(rel_tol=args.rel_tol, repeats=args.repeats,
                           n_edges=args.n_edges, timestep=DYNAMIC_TIMESTEP,
                           damping=tau_dyn, integrator=args.integrator)
        res["dynamic_reference"] = {
            k: dyn[k] for k in ("wall_s", "wall_s_min", "steps", "sim_time_s",
                                "timestep", "integrator", "damping_time_s",
                                "joint_damping_nms", "final_tip_drop_m")}
    res["mujoco_version"] = mujoco.__version__

    mm = 1e3
    print(f"MuJoCo {mujoco.__version__} cable ({PLUGIN}), {res['n_edges']} edges, "
          f"nv = {res['nv']}, integrator {res['integrator']}, dt = {res['timestep']} s, "
          f"tau = {res['damping_time_s']} s (joint damping "
          f"{res['joint_damping_nms']:.3e} N m s/rad)")
    print(f"  Gamma = rho g A L^3 / (E I)        = {res['gamma']:.4f}")
    print(f"  mass                              = {res['total_mass_kg']:.6e} kg "
          f"(rho A L = {res['expected_mass_kg']:.6e})")
    print(f"  compile                           = {res['compile_s'] * mm:.2f} ms")
    print(f"  time to rest (tip within {res['rel_tol']:.1%} of final): "
          f"{res['steps']} steps, {res['sim_time_s']:.4g} s simulated")
    print(f"  wall to rest (median of {args.repeats}) = {res['wall_s'] * mm:.3f} ms "
          f"(min {res['wall_s_min'] * mm:.3f} ms, "
          f"{res['wall_s_per_step'] * 1e6:.1f} us/step; "
          f"python step-by-step loop {res['wall_s_stepwise'] * mm:.3f} ms)")
    print(f"  final tip drop                    = {res['final_tip_drop_m'] * mm:.4f} mm")
    print(f"  heavy elastica tip drop           = {res['heavy_elastica_tip_drop_m'] * mm:.4f} mm "
          f"(rel diff {res['rel_diff_vs_heavy_elastica']:+.3%})")
    print(f"  same-discretisation exact drop    = {res['discrete_chain_tip_drop_m'] * mm:.4f} mm "
          f"(rel diff {res['rel_diff_vs_discrete_chain']:+.2e})")
    print(f"  linear theory rho g A L^4/(8 E I) = {res['linear_theory_tip_drop_m'] * mm:.4f} mm "
          f"(rel diff {res['rel_diff_vs_linear_theory']:+.1%}; not valid at this Gamma)")

    if "dynamic_reference" in res:
        d = res["dynamic_reference"]
        print(f"  dynamic reference (tau = 2/omega_1 = {d['damping_time_s']:.4f} s, "
              f"dt = {d['timestep']} s): {d['steps']} steps, "
              f"{d['sim_time_s']:.4g} s simulated, wall {d['wall_s'] * mm:.3f} ms")

    bench.write(args.out, res)
    print(f"  written {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
