"""Anderson acceleration of the ADMM iterations, strand by strand (issue 12, item 5).

Why.  One ADMM iteration of Algorithm 1 is a fixed-point map u <- G(u) of the iterate
u = (x, lambda_y, theta) (positions, scaled elasticity duals, twists).  On hair its slowest mode is the
strand turning about its root (the cantilever's first bending mode): the penalty W_y |Bx - y|^2
holds every edge *vector* where the last local step put it, so a rotation crosses the strand a
little per iteration.  Measured on the stability atlas' rods (dt = 1/96 s, state 0.3 s into the
fall, ``benchmarks/probes/admm_convergence.py``): error of the step against a 3,000-iteration solve
after 10 / 50 iterations 2-20 % / 1-8 % at w0 = 1; per-iteration rate 0.95-0.99 for every weight
rule tried (w0 = 0.1-3, per-strand, inertia-scaled), with three Gauss-Newton passes in the local
step (no change), heavy-ball momentum on x (unstable above beta = 0.2), or duals stored in the pair
frame (no change).  The weights are not the lever; the iteration is.  Anderson acceleration (Walker
& Ni 2011; for ADMM in simulation, Zhang et al. 2019, "Accelerating ADMM for efficient simulation
and optimization") extrapolates from the last ``window`` iterates, and turned the rods' settling at
10 iterations per step from 0.02-6.6 % of L after 2 s to 0.02-0.5 % (BENCHMARKS.md, issue 12).

What.  Type-II Anderson mixing per strand, at the end of each iteration (after the twist step (g)), of
u = (x, lambda_y, theta * l_rest): theta times the edge's rest length, the displacement of turning an edge
by theta, so that the least squares weighs positions, duals and twists alike.  The strand's frames are then
rebuilt from the mixed x and theta, so that the next iteration's local step sees consistent frames:

    f_k = G(u_k) - u_k,   dF_j = f_{j+1} - f_j,   dG_j = G(u_{j+1}) - G(u_j)   (last ``window`` j)
    gamma = argmin |f_k - dF gamma|^2      (normal equations in float64, Tikhonov 1e-10 trace)
    u_{k+1} = G(u_k) - dG gamma

The fixed point is unchanged (at convergence f = 0 and gamma = 0 for a full-rank dF), so the
accelerated solver computes the same backward-Euler (or BDF2) step, only in fewer iterations.
Safeguard: when a strand's residual |f_k| grows past ``ANDERSON_RESTART`` times the last one, or the
least-squares weights are not finite, the strand's history is dropped and the plain iterate G(u_k)
taken (a restart, as Zhang et al. 2019 do when the energy rises).  The history starts empty at every
step.  The paper has no acceleration (it suggests momentum for slow quasistatic convergence);
``SolverADMMConfig.anderson_window = 0`` is the paper's plain iteration.  (Until 2026-12 theta was left
out of u and got its Newton step from the mixed x; putting it in did not change what follows.)

Where it runs by default (``SolverADMMConfig.anderson_window = None``, :func:`anderson_auto_window`): in the
dynamic mode with backward Euler, on grooms whose twist unknowns are dropped (naturally straight round rods,
``frames.twist_choice``), without contacts and with >= ``ANDERSON_MIN_ITERATIONS`` iterations per step.
Elsewhere the plain iteration runs unless a window is given, because of what was measured there:

* Twist solved (naturally curved rods): on the bend-twist validation (64 curved rods, 50 iterations per
  step; ``benchmarks/probes/anderson_bend_twist.py``, which runs ``validation.bend_twist.run_bend_twist``
  with the window forced) the plain iteration's 50 and 200 iterations per step agree (largest vertex speed
  after 100 / 200 / 300 steps 4.82 / 2.26 / 1.05 and 4.82 / 2.24 / 1.02 m/s) while window 5 gives 1.92 / 0.79
  / 1.24 (50 iterations, theta mixed; 1.20 / 1.13 / 1.18 with theta not mixed): the mixed iteration computes
  another motion.  What one step shows (``benchmarks/probes/anderson_one_step.py``: 60 plain steps, then one
  step from the same state with each method, against 3,000 plain iterations): the six worst rods are the
  1.6-4.5 m ones with 120 edges, near their twist-bend buckling, where the plain iteration converges very
  slowly (3,000 and 6,000 iterations still differ by 5 mm) and Anderson's iterate wanders along the nearly
  flat direction instead of converging: 4.3 / 15.6 / 25.7 cm from the reference after 50 / 200 / 1,000 mixed
  iterations (plain 50: 1.4 cm).  A residual-monotone restart (``ANDERSON_RESTART`` = 1) and a cap of the
  extrapolation at 2 or 10 times the plain step did not make it converge (3-12 cm after 1,000); nor did Zhang
  et al.'s revert (2026-12-04, a scratch patch: a mixed iterate whose |f| is not below the last accepted one is
  replaced by the last accepted plain iterate and the history restarts there; 4.0 / 4.0 / 35 cm after 50 / 200 /
  1,000 iterations, plain 50: 1.5 cm).  The
  residual |f| is a poor measure of the error where the map's rate is ~1; a safeguard on the step's
  objective (Zhang et al. 2019 check an energy) is the next thing to try.  Twist-free rods have no
  twist-bend coupling; there every measurement (atlas, Pareto cantilever, settling) went the plain
  iteration's way or better.
* The quasistatic mode: the energy is no longer monotone (a scratch copy of
  ``tests/test_solver.py::test_quasistatic_energy_decreases_monotonically`` with window 5, 6 cm rod: it rose
  by up to half the total drop on the way, reaching rest in half the steps).
* BDF2: on the Pareto cantilever at 10 iterations per step the mixed BDF2 run ended 57 % off (plain BDF2
  2.4 %); BDF2's extrapolated predictor amplifies unconverged steps (BENCHMARKS.md).

Round-off: the restart and the noise floor are branches, so two implementations that differ only in
round-off (Thomas and PCR, CPU and GPU) can take different branches and end up to the iteration's
convergence error apart (four 5-11 cm rods, 20 steps: 1.8e-4 m; the plain iteration: < 1e-6 m).  The tests
compare implementations on the plain iteration.

Cost: per vertex and iteration, one pass writing the newest differences and the Gram sums
(``window`` x ``window`` dot products of 10-vectors), one mixing pass and, on mixed strands, a second
frame pass; ~0.45 kB of history per vertex at window 5.
"""

import taichi as ti

vec10 = ti.types.vector(10, float)

#: A strand's Anderson history is dropped when its fixed-point residual grows by more than this
#: factor in one iteration [-].
ANDERSON_RESTART = 4.0
#: No mixing while a strand's residual |f| is below this times |u|: the differences of float32 iterates
#: are then mostly round-off, and mixing them kept settled rods jittering at ~1e-3 of their length [-].
ANDERSON_NOISE_FLOOR = 1e-5
#: Fewest iterations per step with which the mixing runs; below, the plain iteration [-].  Measured on
#: the Pareto cantilever (1-30 cm rods, >= 16 edges, dt = 1/96 s, window 5, 1.5 s;
#: ``benchmarks/probes/anderson_cantilever.py``, BENCHMARKS.md issue 12): with 5 iterations the 2-4 cm
#: rods (0.6-1.25 mm edges) swing up through a cross-step mode of the warm-started duals that the plain
#: iteration damps only slowly (the 3.9 cm rod's tip swings -11 to +7 mm after 1.5 s about its converged
#: sag of 1.9 mm, which converged steps reach within 0.15 s); with 8 the 2 cm rod ends 3x further off than
#: plain; with 10 and 30 every rod ends as close or closer (at 10: max tip error 0.04-4.0 % of L against
#: 0.04-25.6 %).  Mixing only early in a short step (the last 2-3 iterations plain), damped mixing, mixing
#: x only and a stricter restart did not remove it; without warm-started duals it is stable but biased.
ANDERSON_MIN_ITERATIONS = 10
#: The window of ``SolverADMMConfig.anderson_window = None`` (auto) where it runs (module doc) [-].
ANDERSON_DEFAULT_WINDOW = 5
#: Tikhonov term of the least-squares normal equations, relative to their trace [-].
ANDERSON_REGULARISATION = 1e-10


def anderson_auto_window(window: int | None, dynamic: bool, twist_free: bool, bdf2: bool) -> tuple[int, str]:
    """The window a solver uses for ``SolverADMMConfig.anderson_window`` (``window``), and why it is 0 when
    it is: a given integer as it is; None (auto) ``ANDERSON_DEFAULT_WINDOW`` in the dynamic mode with
    backward Euler on twist-free rods, else 0 (module doc, "Where it runs by default")."""
    if window is not None:
        return int(window), "SolverADMMConfig.anderson_window = 0"
    if not dynamic:
        return 0, "the quasistatic mode (the plain iteration lowers the energy monotonically)"
    if bdf2:
        return 0, "BDF2 (measured to amplify unconverged mixed steps)"
    if not twist_free:
        return 0, "the twist is solved (curved rods: measured to converge elsewhere when mixed)"
    return ANDERSON_DEFAULT_WINDOW, ""


class AndersonBuffers:
    """History of the Anderson mixing.  Allocated by SolverADMM when ``anderson_window`` > 0.

    ``window`` differences per vertex; shapes (vertex_count,), (vertex_count, window) or (strand_count,).
    """

    def __init__(self, vertex_count: int, strand_count: int, window: int):
        n, m = vertex_count, max(int(window), 1)
        self.window = int(window)
        #: The current iterate u_k = (x [m], lambda_y [m]) before the iteration's plain step.
        self.vertex_anderson_iterate = ti.field(vec10, n)
        #: G(u_{k-1}) and f_{k-1} = G(u_{k-1}) - u_{k-1} of the last iteration [m].
        self.vertex_anderson_value = ti.field(vec10, n)
        self.vertex_anderson_residual = ti.field(vec10, n)
        #: Ring of the last ``window`` differences dG_j and dF_j [m].
        self.vertex_anderson_dvalue = ti.field(vec10, (n, m))
        self.vertex_anderson_dresidual = ti.field(vec10, (n, m))
        #: Per strand: number of stored differences (<= window) [-], slot of the next one [-],
        #: iterations since the last (re)start [-] and the last residual norm |f| [m].
        self.strand_anderson_count = ti.field(ti.i32, strand_count)
        self.strand_anderson_slot = ti.field(ti.i32, strand_count)
        self.strand_anderson_age = ti.field(ti.i32, strand_count)
        self.strand_anderson_residual = ti.field(ti.f64, strand_count)
        #: Per-strand scratch of the least-squares solve: Gram matrix dF^T dF (lower triangle, then its
        #: Cholesky factor), right-hand side dF^T f and weights gamma [m^2, m^2, -].
        self.strand_anderson_gram = ti.field(ti.f64, (strand_count, m, m))
        self.strand_anderson_rhs = ti.field(ti.f64, (strand_count, m))
        self.strand_anderson_gamma = ti.field(ti.f64, (strand_count, m))


@ti.func
def pack_iterate(edge: ti.template(), x: ti.template(), theta: ti.template(), buf: ti.template(),
                 i: ti.i32) -> vec10:
    """u at vertex i: its position [m], the scaled duals of pair i [m] and the twist of edge i times the
    edge's rest length [rad m], the displacement scale of turning an edge by theta, so that the least
    squares weighs the three alike (ghost edges and pairs carry zeros that never change)."""
    p = x[i]
    d = buf.pair_dual[i]
    return vec10(p[0], p[1], p[2], d[0], d[1], d[2], d[3], d[4], d[5], theta[i] * edge.edge_rest_length[i])


@ti.func
def anderson_begin_strand(s: ti.i32, start: ti.i32, m: ti.i32, edge: ti.template(), x: ti.template(),
                          theta: ti.template(), buf: ti.template(), aa: ti.template()):
    """Start strand s's history for a new step: u_0 = (x, lambda_y, theta) as they are now."""
    for k in range(m):
        i = start + k
        aa.vertex_anderson_iterate[i] = pack_iterate(edge, x, theta, buf, i)
    aa.strand_anderson_count[s] = 0
    aa.strand_anderson_slot[s] = 0
    aa.strand_anderson_age[s] = 0
    aa.strand_anderson_residual[s] = 0.0


@ti.func
def anderson_mix_strand(s: ti.i32, start: ti.i32, m: ti.i32, vertex: ti.template(), edge: ti.template(),
                        x: ti.template(), theta: ti.template(), buf: ti.template(), aa: ti.template(),
                        window: ti.template(), last: ti.i32) -> ti.i32:
    """Replace strand s's plain iterate G(u_k) (now in x, lambda_y and theta) by the Anderson mix (module
    doc); ``last`` != 0 on the step's last iteration, which keeps the plain iterate.  Returns 1 when the
    strand was mixed: its frames must then be rebuilt from the mixed x and theta.

    Loops over the history run at run time over per-strand scratch (few instructions to compile)."""
    age = aa.strand_anderson_age[s]
    slot = aa.strand_anderson_slot[s]
    # Pass 1: f_k, |f_k|, |u|, and the newest differences into the ring (from the second iteration on).
    fn2 = ti.f64(0.0)
    un2 = ti.f64(0.0)
    for k in range(m):
        i = start + k
        g = pack_iterate(edge, x, theta, buf, i)
        f = g - aa.vertex_anderson_iterate[i]
        fn2 += ti.cast(f.dot(f), ti.f64)
        un2 += ti.cast(g.dot(g), ti.f64)
        if age > 0:
            aa.vertex_anderson_dvalue[i, slot] = g - aa.vertex_anderson_value[i]
            aa.vertex_anderson_dresidual[i, slot] = f - aa.vertex_anderson_residual[i]
        aa.vertex_anderson_value[i] = g
        aa.vertex_anderson_residual[i] = f
    fn = ti.sqrt(fn2)
    count = aa.strand_anderson_count[s]
    if age > 0:
        count = ti.min(count + 1, window)
        slot = (slot + 1) % window
    restart = age > 0 and fn > ANDERSON_RESTART * aa.strand_anderson_residual[s]
    # Below the noise floor the differences are round-off: plain iterations there.
    quiet = fn2 < ANDERSON_NOISE_FLOOR * ANDERSON_NOISE_FLOOR * un2
    mixed = False
    if count > 0 and not restart and not quiet and last == 0:
        # Pass 2: normal equations (dF^T dF) gamma = dF^T f over the strand, float64 (lower triangle).
        for a in range(count):
            aa.strand_anderson_rhs[s, a] = 0.0
            for b in range(a + 1):
                aa.strand_anderson_gram[s, a, b] = 0.0
        for k in range(m):
            i = start + k
            f = aa.vertex_anderson_residual[i]
            for a in range(count):
                da = aa.vertex_anderson_dresidual[i, a]
                aa.strand_anderson_rhs[s, a] += ti.cast(da.dot(f), ti.f64)
                for b in range(a + 1):
                    aa.strand_anderson_gram[s, a, b] += ti.cast(da.dot(aa.vertex_anderson_dresidual[i, b]), ti.f64)
        trace = ti.f64(0.0)
        for a in range(count):
            trace += aa.strand_anderson_gram[s, a, a]
        reg = ANDERSON_REGULARISATION * trace + 1e-300
        # In-place Cholesky of the lower triangle, then the two triangular solves into strand_anderson_gamma.
        ok = True
        for a in range(count):
            d = aa.strand_anderson_gram[s, a, a] + reg
            for c in range(a):
                d -= aa.strand_anderson_gram[s, a, c] * aa.strand_anderson_gram[s, a, c]
            if d <= 0.0:
                ok = False
                d = 1.0
            la = ti.sqrt(d)
            aa.strand_anderson_gram[s, a, a] = la
            for b in range(a + 1, count):
                v = aa.strand_anderson_gram[s, b, a]
                for c in range(a):
                    v -= aa.strand_anderson_gram[s, b, c] * aa.strand_anderson_gram[s, a, c]
                aa.strand_anderson_gram[s, b, a] = v / la
        for a in range(count):
            v = aa.strand_anderson_rhs[s, a]
            for c in range(a):
                v -= aa.strand_anderson_gram[s, a, c] * aa.strand_anderson_gamma[s, c]
            aa.strand_anderson_gamma[s, a] = v / aa.strand_anderson_gram[s, a, a]
        for a2 in range(count):
            a = count - 1 - a2
            v = aa.strand_anderson_gamma[s, a]
            for c in range(a + 1, count):
                v -= aa.strand_anderson_gram[s, c, a] * aa.strand_anderson_gamma[s, c]
            v /= aa.strand_anderson_gram[s, a, a]
            aa.strand_anderson_gamma[s, a] = v
            if not (ti.abs(v) < 1e30):
                ok = False
        if ok:
            mixed = True
        else:
            restart = True
    if restart:
        count = 0
        slot = 0
        age = 0
    # Pass 3: u_{k+1} = G(u_k) - dG gamma (or the plain G(u_k)); it is the next iteration's u_k.
    for k in range(m):
        i = start + k
        u = aa.vertex_anderson_value[i]
        if mixed:
            for a in range(count):
                u -= ti.cast(aa.strand_anderson_gamma[s, a], float) * aa.vertex_anderson_dvalue[i, a]
            if vertex.vertex_is_fixed[i] == 0:
                x[i] = ti.math.vec3(u[0], u[1], u[2])
            else:
                p = x[i]
                u[0] = p[0]
                u[1] = p[1]
                u[2] = p[2]
            buf.pair_dual[i] = ti.types.vector(6, float)(u[3], u[4], u[5], u[6], u[7], u[8])
            r = edge.edge_rest_length[i]
            if edge.edge_is_fixed[i] == 0 and r > 0.0:
                theta[i] = u[9] / r
            else:
                u[9] = theta[i] * r
        aa.vertex_anderson_iterate[i] = u
    aa.strand_anderson_count[s] = count
    aa.strand_anderson_slot[s] = slot
    aa.strand_anderson_age[s] = age + 1
    aa.strand_anderson_residual[s] = fn
    return ti.i32(1) if mixed else ti.i32(0)


@ti.kernel
def anderson_begin(strand: ti.template(), edge: ti.template(), x: ti.template(), theta: ti.template(),
                   buf: ti.template(), aa: ti.template()):
    """Stage schedule: :func:`anderson_begin_strand` for every strand."""
    for s in strand.strand_vertex_start:
        anderson_begin_strand(s, strand.strand_vertex_start[s], strand.strand_vertex_count[s], edge, x, theta, buf,
                              aa)


@ti.kernel
def anderson_mix(strand: ti.template(), vertex: ti.template(), edge: ti.template(), x: ti.template(),
                 theta: ti.template(), buf: ti.template(), aa: ti.template(), window: ti.template(), last: ti.i32):
    """Stage schedule: :func:`anderson_mix_strand` for every strand (after the twist step); the caller
    rebuilds the frames."""
    for s in strand.strand_vertex_start:
        anderson_mix_strand(s, strand.strand_vertex_start[s], strand.strand_vertex_count[s], vertex, edge, x, theta,
                            buf, aa, window, last)
