"""The contact impulses carried from one quasistatic step to the next (the quasistatic fight).

Every detection makes the contacts anew, and the step's first ADMM iterations started from zero contact forces: a
groom at rest (moving 0.04 mm per step) sank 60 um into its neighbours in each step's iterations (~1,100 contacts
deeper than 10 um on the grooming benchmark's 8,600 guides) for the end-of-step correction to push out again.
Here, in the quasistatic mode, :func:`keep_impulses` records each contact's impulse r = r~ / D_hat after the step's
iterations, and :func:`warm_impulses` gives a hair pair of the next detection the impulse of the pair with the same
two edges, r~ = r D_hat, and every contact vertex the collision dual
of those impulses, lambda_z = W_z^-1 H^T D_hat^-1 r~, so that the z-step still starts at x
(``projection.begin_projection``).  The local solves project each carried impulse into its new friction cone at the
first sweep, and release it where the pair separates.  Measured (scratch ``/tmp/p/s21/warm.py``, 6 steps of the still
groom): contacts deeper than 10 um after the iterations 1,167 -> 53, crossed 281 -> 40, the correction 15 -> 10
sweeps.  Carrying the per-vertex dual instead diverged (BENCHMARKS.md): it cannot be released contact by contact.
Dynamic runs start from zero as the paper does.  Body contacts start from zero too: carried on the grooming comb
(a body that moves every step) they halved the friction drag of a tooth slid over held strands (0.41 against 1.1 mm
on ``tests/test_grooming.py``'s comb, whose claim is > 0.5 mm), and the fight is between hairs.
"""

import taichi as ti

from .narrow import entry_coefficient

vec3 = ti.math.vec3


@ti.kernel
def keep_impulses(con: ti.template(), warm: ti.template()):
    """Record every contact's key and impulse r = r~ / D_hat, and the CSR of the contacts by first vertex."""
    nc = ti.min(con.contact_count[None], con.capacity)
    warm.warm_count[None] = nc
    for c in range(nc):
        warm.warm_key_a[c] = con.contact_vertex[c][0]
        warm.warm_key_b[c] = con.contact_vertex[c][2]  # (-1 on a body contact: never a hair pair's key)
        dh = con.contact_delassus[c]
        warm.warm_impulse[c] = con.contact_accumulated[c] / dh if dh > 0.0 else vec3(0.0)
    n = warm.warm_start.shape[0] - 1
    ti.loop_config(serialize=True)
    for _ in range(1):
        for i in range(n + 1):
            warm.warm_start[i] = 0
        for c in range(nc):
            warm.warm_start[warm.warm_key_a[c] + 1] += 1
        for i in range(n):
            warm.warm_start[i + 1] += warm.warm_start[i]
        for c in range(nc):  # (fill, moving each start to its end ...)
            a = warm.warm_key_a[c]
            warm.warm_order[warm.warm_start[a]] = c
            warm.warm_start[a] += 1
        for j in range(n):  # (... and back)
            warm.warm_start[n - j] = warm.warm_start[n - j - 1]
        warm.warm_start[0] = 0


@ti.kernel
def warm_impulses(con: ti.template(), warm: ti.template()):
    """r~_c = r D_hat_c from the recorded contact with c's key (after ``narrow.build_adjacency``), then
    lambda_z = W_z^-1 H^T D_hat^-1 r~ on every contact vertex."""
    nc = ti.min(con.contact_count[None], con.capacity)
    for c in range(nc):
        if con.contact_collider[c] < 0:  # (hair pairs only: see the module's note on bodies)
            a = con.contact_vertex[c][0]
            b = con.contact_vertex[c][2]
            for j in range(warm.warm_start[a], warm.warm_start[a + 1]):
                o = warm.warm_order[j]
                if warm.warm_key_b[o] == b:
                    con.contact_accumulated[c] = warm.warm_impulse[o] * con.contact_delassus[c]
    duals_of_impulses(con)


@ti.func
def duals_of_impulses(con: ti.template()):
    """lambda_z = W_z^-1 H^T D_hat^-1 r~ on every contact vertex: the pushes of the contacts' impulses r~ (so that the
    z-step still starts at x, ``projection.begin_projection``)."""
    for k in range(con.active_vertex_count[None]):
        i = con.active_vertex[k]
        iw = con.vertex_contact_inv_weight[i]
        lam = vec3(0.0)
        if iw > 0.0:
            for e in range(con.vertex_contact_start[i], con.vertex_contact_start[i + 1]):
                c = con.vertex_contact_list[e]
                lam += (iw * entry_coefficient(con, i, c)) * con.contact_accumulated[c]
        con.vertex_contact_dual[i] = lam
