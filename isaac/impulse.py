"""Collision impulses: the seed's single pass, or an iterative sequential-impulse solver.

The seed's impulse (from myphysicslab's collision derivation), for a contact point P with unit
normal n from a to b:

    j = -(1 + e) v_ab . n / (1/m_a + 1/m_b + (r_ap x n)^2 / I_a + (r_bp x n)^2 / I_b)

with r_ap = P - x_a, r_bp = P - x_b. Here v_ab . n is `vn`, the normal velocity of b's point
relative to a's, (v_b + w_b x r_bp - v_a - w_a x r_ap) . n, negative when they approach; the
denominator is `k_normal` (1/kg). j >= 0 is applied as -j n to a and +j n to b:
v_a -= j n / m_a, w_a -= (r_ap x j n) / I_a, v_b += j n / m_b, w_b += (r_bp x j n) / I_b.
The seed applies it only when the bodies approach (vn < 0).

- solver "seed": one pass over the contacts in order, each seeing the velocities the previous ones
  left (Gauss-Seidel), exactly the formula above.
- solver "sequential": `iterations` passes; each contact accumulates its impulse, clamped to stay
  >= 0 (contacts push, never pull), towards the target normal velocity -e vn0 (vn0 = normal
  velocity before solving). Warm starting applies last step's accumulated impulses first.
  This converges to the simultaneous solution of all contacts (stacks, two-point manifolds).
- restitution_threshold: a contact approaching slower than this does not bounce (e = 0).
- friction (Coulomb, optional): a tangent impulse along t = (-n_y, n_x), clamped to
  |jt| <= mu j, aiming at zero tangential velocity.
- speculative rows (depth < 0: a gap g = -depth still open) allow the bodies to close the gap in
  this step but not more: target normal velocity -g / h; when they would meet within this step
  the contact bounces now with the same formula (the bounce happens up to g early).
"""

from __future__ import annotations

import numba
import numpy as np


# pair restitution rules (WorldSettings.restitution_rule)
RULE_MAX = 0
RULE_MIN = 1
RULE_MEAN = 2
RULE_PRODUCT = 3
RULE_SQRT = 4  # geometric mean (friction's default)
RULE_CODES = {"max": RULE_MAX, "min": RULE_MIN, "mean": RULE_MEAN, "product": RULE_PRODUCT,
              "sqrt": RULE_SQRT}


@numba.njit(cache=True, nogil=True)
def combine(rule, x, y):
    """Mix two bodies' coefficients (restitution or friction) by a pair rule."""
    if rule == RULE_MAX:
        return max(x, y)
    if rule == RULE_MIN:
        return min(x, y)
    if rule == RULE_MEAN:
        return 0.5 * (x + y)
    if rule == RULE_PRODUCT:
        return x * y
    return np.sqrt(x * y)


# Columns of the per-row table built once per solve. It holds only what the iterations read
# (13 float64, 104 bytes a row) so that a large scene's table stays in cache across iterations;
# inverse masses are read from a packed per-body table instead.
NX, NY, RNA, RNB, RTA, RTB, MN, MT, TARGET, MU, KN, KT, BLOCK = range(13)
COLUMNS = 13
# per two-point manifold (on its slot-0 row): K12 and the inverse of K
K12, NM11, NM12, NM22 = range(4)
# a manifold is solved as a 2x2 block only while K is well conditioned (Box2D's
# b2_maxConditionNumber): k11^2 < MAX_CONDITION * det(K); otherwise point by point
MAX_CONDITION = 1000.0


@numba.njit(cache=True, nogil=True)
def solve_contacts(rows, c_a, c_b, c_feature, c_slot, c_point, c_normal, c_depth, c_previous,
                   position, velocity, angular_velocity, inv_mass, inv_inertia, gravity_dv,
                   restitution, friction, restitution_rule, friction_rule, restitution_threshold,
                   friction_on, seed_solver, iterations, warm_starting, h,
                   prev_impulse, prev_tangent, c_impulse, c_tangent, c_restitution,
                   c_push_a, c_push_b):
    """Resolve every contact row; writes the impulses applied (N s) and the restitution used.

    gravity_dv: (2,) velocity (m/s) gravity added to every moving body just before this solve
    (g h with semi-implicit Euler, zero with explicit). The bounce is computed from the approach
    velocity the bodies *arrived* with, without it: a resting body (arrived at 0) does not bounce
    off the gravity of its own step, and a falling body bounces back with the speed it hit with;
    reflecting the gravity increment too gained about 0.4 % of the energy per bounce.
    A speculative contact that meets within the step (gap g closed at speed u = -vn0, which
    includes this step's gravity since the impact comes after it) leaves with the bounce
    velocity e u and is moved back by (1 + e) g, shared by inverse mass: it ends the step e times
    as far from the surface as it would have sunk through it, the reflection at the surface, not
    in the air g above it. That displacement is added to the pair's push_a / push_b. (With
    semi-implicit Euler this keeps an e = 1 bounce's energy within 0.5 % over 60 s; reflecting
    the arrival velocity at the mirrored position lost 23 %.)
    Velocities are worked on as a packed copy (vx, vy, w) per body and written back at the end.
    """
    n = velocity.shape[0]
    v = np.empty((n, 3))
    inv = np.empty((n, 2))
    for i in range(n):
        v[i, 0] = velocity[i, 0]
        v[i, 1] = velocity[i, 1]
        v[i, 2] = angular_velocity[i]
        inv[i, 0] = inv_mass[i]
        inv[i, 1] = inv_inertia[i]
    rc = np.empty((rows, COLUMNS))
    bounce_back = np.zeros(rows)  # (1 + e u_b / u) g of speculative rows that bounce (m)
    for k in range(rows):
        a = c_a[k]
        b = c_b[k]
        nx = c_normal[k, 0]
        ny = c_normal[k, 1]
        rax = c_point[k, 0] - position[a, 0]
        ray = c_point[k, 1] - position[a, 1]
        rbx = c_point[k, 0] - position[b, 0]
        rby = c_point[k, 1] - position[b, 1]
        rna = rax * ny - ray * nx  # r_ap x n
        rnb = rbx * ny - rby * nx
        rta = rax * nx + ray * ny  # r_ap x t, t = (-n_y, n_x)
        rtb = rbx * nx + rby * ny
        ima = inv[a, 0]
        imb = inv[b, 0]
        iia = inv[a, 1]
        iib = inv[b, 1]
        # the seed's denominator: 1/m_a + 1/m_b + (r_ap x n)^2 / I_a + (r_bp x n)^2 / I_b
        kn = ima + imb + rna * rna * iia + rnb * rnb * iib
        kt = ima + imb + rta * rta * iia + rtb * rtb * iib
        rc[k, NX] = nx
        rc[k, NY] = ny
        rc[k, RNA] = rna
        rc[k, RNB] = rnb
        rc[k, RTA] = rta
        rc[k, RTB] = rtb
        rc[k, KN] = kn
        rc[k, MN] = 1.0 / kn if kn > 0.0 else 0.0
        rc[k, KT] = kt
        rc[k, MT] = 1.0 / kt if kt > 0.0 else 0.0
        rc[k, MU] = combine(friction_rule, friction[a], friction[b]) if friction_on else 0.0
        rc[k, BLOCK] = 0.0
        # v_ab . n: normal velocity of b's point relative to a's, (w x r) . n = w (r x n)
        vn0 = ((v[b, 0] - v[a, 0]) * nx + (v[b, 1] - v[a, 1]) * ny
               + v[b, 2] * rnb - v[a, 2] * rna)
        # the approach velocity the pair arrived with: without this step's gravity, which moved
        # each moving body by gravity_dv (no relative change between two moving bodies)
        moved = (1.0 if imb > 0.0 else 0.0) - (1.0 if ima > 0.0 else 0.0)
        arrived = vn0 - moved * (gravity_dv[0] * nx + gravity_dv[1] * ny)
        gap = -c_depth[k]
        hits = vn0 < 0.0 if gap <= 0.0 else vn0 * h < -gap
        e = 0.0
        if hits and arrived < 0.0 and -arrived >= restitution_threshold:
            e = combine(restitution_rule, restitution[a], restitution[b])
        c_restitution[k] = e
        if gap <= 0.0:
            rc[k, TARGET] = -e * arrived
        elif hits and e > 0.0:
            # it meets within this step, after this step's gravity: bounce with -e vn0 and
            # move back by (1 + e) g, to where the reflection at the surface puts it
            rc[k, TARGET] = -e * vn0
            bounce_back[k] = (1.0 + e) * gap
        else:
            rc[k, TARGET] = -gap / h
        c_impulse[k] = 0.0
        c_tangent[k] = 0.0

    if seed_solver:
        _seed_pass(rows, c_a, c_b, c_depth, rc, inv, v, c_restitution, c_impulse, c_tangent)
    else:
        # two-point manifolds: the 2x2 effective mass K of both points, for the block solver
        blk = np.empty((rows, 4))
        for k in range(rows - 1):
            if c_slot[k] == 0 and c_slot[k + 1] == 1:
                a = c_a[k]
                b = c_b[k]
                k11 = rc[k, KN]
                k22 = rc[k + 1, KN]
                k12 = (inv[a, 0] + inv[b, 0] + rc[k, RNA] * rc[k + 1, RNA] * inv[a, 1]
                       + rc[k, RNB] * rc[k + 1, RNB] * inv[b, 1])
                det = k11 * k22 - k12 * k12
                if k11 * k11 < MAX_CONDITION * det:
                    rc[k, BLOCK] = 1.0
                    blk[k, K12] = k12
                    blk[k, NM11] = k22 / det
                    blk[k, NM12] = -k12 / det
                    blk[k, NM22] = k11 / det
        if warm_starting:
            for k in range(rows):
                p = c_previous[k]
                if p >= 0:
                    c_impulse[k] = prev_impulse[p]
                    c_tangent[k] = prev_tangent[p] if rc[k, MU] > 0.0 else 0.0
                    _apply(c_a[k], c_b[k], k, c_impulse[k], c_tangent[k], rc, inv, v)
        # the solver's units (single points and two-point blocks, by their first row): contacts
        # between moving bodies first, contacts with concrete bodies last, so every pass ends
        # with the contacts that hold the world up satisfied (a blow on top of a stack no longer
        # leaves the bottom body moving into the floor after the last pass)
        starts = _solve_order(rows, c_a, c_b, rc, inv, n)
        units = starts.shape[0]
        for _ in range(iterations):
            _sequential_pass(starts, units, c_a, c_b, rc, blk, inv, v, c_impulse, c_tangent)

    for i in range(n):
        velocity[i, 0] = v[i, 0]
        velocity[i, 1] = v[i, 1]
        angular_velocity[i] = v[i, 2]
    _bounce_back(rows, c_a, c_b, c_feature, c_slot, c_point, c_normal, bounce_back, inv,
                 position, c_push_a, c_push_b)


@numba.njit(cache=True, nogil=True)
def _bounce_back(rows, c_a, c_b, c_feature, c_slot, c_point, c_normal, bounce_back, inv,
                 position, c_push_a, c_push_b):
    """Move each pair whose speculative contact bounced by its smallest bounce-back distance
    along the normal (a towards b, shared by inverse mass), recorded on its slot-0 row."""
    k = 0
    while k < rows:
        last = k
        while last + 1 < rows and c_slot[last + 1] != 0:
            last += 1
        d = 0.0
        for q in range(k, last + 1):
            if bounce_back[q] > 0.0 and (d == 0.0 or bounce_back[q] < d):
                d = bounce_back[q]
        a = c_a[k]
        b = c_b[k]
        w = inv[a, 0] + inv[b, 0]
        if d > 0.0 and w > 0.0:
            nx = c_normal[k, 0]
            ny = c_normal[k, 1]
            dax = nx * d * inv[a, 0] / w
            day = ny * d * inv[a, 0] / w
            dbx = -nx * d * inv[b, 0] / w
            dby = -ny * d * inv[b, 0] / w
            position[a, 0] += dax
            position[a, 1] += day
            position[b, 0] += dbx
            position[b, 1] += dby
            c_push_a[k, 0] += dax
            c_push_a[k, 1] += day
            c_push_b[k, 0] += dbx
            c_push_b[k, 1] += dby
            for q in range(k, last + 1):  # the points move with their incident body
                if c_feature[q] // 4096 == 0:
                    c_point[q, 0] += dbx
                    c_point[q, 1] += dby
                else:
                    c_point[q, 0] += dax
                    c_point[q, 1] += day
        k = last + 1


@numba.njit(cache=True, nogil=True, inline="always")
def _apply(a, b, k, jn, jt, rc, inv, v):
    """Apply normal impulse jn and tangent impulse jt (N s) of row k: -P to a, +P to b."""
    nx = rc[k, NX]
    ny = rc[k, NY]
    px = jn * nx - jt * ny
    py = jn * ny + jt * nx
    v[a, 0] -= px * inv[a, 0]
    v[a, 1] -= py * inv[a, 0]
    v[a, 2] -= (jn * rc[k, RNA] + jt * rc[k, RTA]) * inv[a, 1]
    v[b, 0] += px * inv[b, 0]
    v[b, 1] += py * inv[b, 0]
    v[b, 2] += (jn * rc[k, RNB] + jt * rc[k, RTB]) * inv[b, 1]


@numba.njit(cache=True, nogil=True)
def _seed_pass(rows, c_a, c_b, c_depth, rc, inv, v, c_restitution, c_impulse, c_tangent):
    """The seed: one pass, each contact's impulse from the velocities the previous ones left."""
    for k in range(rows):
        if rc[k, KN] <= 0.0:
            continue
        a = c_a[k]
        b = c_b[k]
        vn = ((v[b, 0] - v[a, 0]) * rc[k, NX] + (v[b, 1] - v[a, 1]) * rc[k, NY]
              + v[b, 2] * rc[k, RNB] - v[a, 2] * rc[k, RNA])
        if c_depth[k] >= 0.0:
            if vn >= 0.0:
                continue  # not approaching: the seed applies nothing
            j = -(1.0 + c_restitution[k]) * vn / rc[k, KN]  # the seed's formula, literally
        else:
            if vn >= rc[k, TARGET]:
                continue
            j = (rc[k, TARGET] - vn) / rc[k, KN]
        _apply(a, b, k, j, 0.0, rc, inv, v)
        c_impulse[k] = j
        if rc[k, MU] > 0.0 and rc[k, KT] > 0.0:
            vt = (-(v[b, 0] - v[a, 0]) * rc[k, NY] + (v[b, 1] - v[a, 1]) * rc[k, NX]
                  + v[b, 2] * rc[k, RTB] - v[a, 2] * rc[k, RTA])
            limit = rc[k, MU] * j
            jt = min(max(-vt / rc[k, KT], -limit), limit)
            _apply(a, b, k, 0.0, jt, rc, inv, v)
            c_tangent[k] = jt


@numba.njit(cache=True, nogil=True)
def _solve_order(rows, c_a, c_b, rc, inv, n):
    """The order the solver visits its units (single points and two-point blocks, by their
    first row) in every pass.

    The Gauss-Seidel order is: contacts between moving bodies first, contacts with concrete
    bodies last, each group in (a, b) order, so every pass ends with the contacts that hold the
    world up satisfied (a blow on top of a thin stack no longer leaves the bottom body moving
    into the floor).

    The units are then scheduled in waves without changing a single bit of the result: a unit's
    wave is one more than the last wave that touched either of its moving bodies, and units are
    visited wave by wave. Every unit still comes after each earlier unit it shares a body with
    (the order of two units that share no moving body does not change what either computes), but
    consecutive units now touch different bodies, so the processor overlaps them instead of
    waiting for each unit's velocity stores. Concrete bodies never change velocity (their
    inverse mass and inertia are 0) and do not tie units together.
    determinism: the waves depend only on the rows, visited in index order.
    """
    unit = np.empty(rows, dtype=np.int64)
    units = 0
    for grounded in range(2):
        k = 0
        while k < rows:
            touches_concrete = inv[c_a[k], 0] == 0.0 or inv[c_b[k], 0] == 0.0
            if touches_concrete == (grounded == 1):
                unit[units] = k
                units += 1
            k += 2 if rc[k, BLOCK] == 1.0 else 1
    last = np.zeros(n, dtype=np.int64)
    wave = np.empty(units, dtype=np.int64)
    waves = 0
    for u in range(units):
        k = unit[u]
        a = c_a[k]
        b = c_b[k]
        moving_a = inv[a, 0] > 0.0 or inv[a, 1] > 0.0
        moving_b = inv[b, 0] > 0.0 or inv[b, 1] > 0.0
        w = 0
        if moving_a:
            w = last[a]
        if moving_b:
            w = max(w, last[b])
        wave[u] = w
        if moving_a:
            last[a] = w + 1
        if moving_b:
            last[b] = w + 1
        waves = max(waves, w + 1)
    # stable counting sort by wave
    count = np.zeros(waves + 1, dtype=np.int64)
    for u in range(units):
        count[wave[u] + 1] += 1
    for w in range(waves):
        count[w + 1] += count[w]
    order = np.empty(units, dtype=np.int64)
    for u in range(units):
        order[count[wave[u]]] = unit[u]
        count[wave[u]] += 1
    return order


@numba.njit(cache=True, nogil=True)
def _sequential_pass(starts, units, c_a, c_b, rc, blk, inv, v, c_impulse, c_tangent):
    """One Gauss-Seidel pass of accumulated, clamped impulses.

    Per manifold, friction first (non-penetration matters more, so it is solved last), then the
    normal impulses: point by point (Box2D-Lite's ApplyImpulse), or for a well-conditioned
    two-point manifold both at once as a 2x2 linear complementarity problem (Box2D's block
    solver), which makes resting stacks converge in far fewer iterations. The two bodies'
    velocities are loaded once per manifold into locals and stored once.
    """
    for u in range(units):
        k = starts[u]
        a = c_a[k]
        b = c_b[k]
        ima = inv[a, 0]
        iia = inv[a, 1]
        imb = inv[b, 0]
        iib = inv[b, 1]
        vax = v[a, 0]
        vay = v[a, 1]
        wa = v[a, 2]
        vbx = v[b, 0]
        vby = v[b, 1]
        wb = v[b, 2]
        last = k + 1 if rc[k, BLOCK] == 1.0 else k
        for q in range(k, last + 1):
            mu = rc[q, MU]
            if mu > 0.0:
                nx = rc[q, NX]
                ny = rc[q, NY]
                rta = rc[q, RTA]
                rtb = rc[q, RTB]
                # tangent t = (-n_y, n_x); Coulomb: |jt| <= mu j
                vt = -(vbx - vax) * ny + (vby - vay) * nx + wb * rtb - wa * rta
                limit = mu * c_impulse[q]
                old = c_tangent[q]
                new = min(max(old - vt * rc[q, MT], -limit), limit)
                c_tangent[q] = new
                dt = new - old
                vax += dt * ny * ima
                vay -= dt * nx * ima
                wa -= dt * rta * iia
                vbx -= dt * ny * imb
                vby += dt * nx * imb
                wb += dt * rtb * iib
        nx = rc[k, NX]
        ny = rc[k, NY]
        if last == k:
            rna = rc[k, RNA]
            rnb = rc[k, RNB]
            # (v_b + w_b x r_b - v_a - w_a x r_a) . n, using (w x r) . n = w (r x n)
            vn = (vbx - vax) * nx + (vby - vay) * ny + wb * rnb - wa * rna
            old = c_impulse[k]
            new = max(old + (rc[k, TARGET] - vn) * rc[k, MN], 0.0)
            c_impulse[k] = new
            dj = new - old
            vax -= dj * nx * ima
            vay -= dj * ny * ima
            wa -= dj * rna * iia
            vbx += dj * nx * imb
            vby += dj * ny * imb
            wb += dj * rnb * iib
        else:
            d1, d2 = _block_normal(k, rc, blk, c_impulse, vax, vay, wa, vbx, vby, wb)
            px = (d1 + d2) * nx
            py = (d1 + d2) * ny
            vax -= px * ima
            vay -= py * ima
            wa -= (d1 * rc[k, RNA] + d2 * rc[k + 1, RNA]) * iia
            vbx += px * imb
            vby += py * imb
            wb += (d1 * rc[k, RNB] + d2 * rc[k + 1, RNB]) * iib
        v[a, 0] = vax
        v[a, 1] = vay
        v[a, 2] = wa
        v[b, 0] = vbx
        v[b, 1] = vby
        v[b, 2] = wb


@numba.njit(cache=True, nogil=True, inline="always")
def _block_normal(k, rc, blk, c_impulse, vax, vay, wa, vbx, vby, wb):
    """Both normal impulses of a two-point manifold (rows k, k + 1) as one 2x2 LCP.

    Find x >= 0 with w = K x + b' >= 0 and x . w = 0, where b' = vn - target - K a and a the
    accumulated impulses: try both points active, then only the first, only the second, none
    (Box2D 2.x b2ContactSolver::SolveVelocityConstraints). Stores the new accumulated impulses
    and returns their increments (N s); if no case fits (degenerate) nothing changes.
    """
    nx = rc[k, NX]
    ny = rc[k, NY]
    k11 = rc[k, KN]
    k22 = rc[k + 1, KN]
    k12 = blk[k, K12]
    a1 = c_impulse[k]
    a2 = c_impulse[k + 1]
    dvx = vbx - vax
    dvy = vby - vay
    vn1 = dvx * nx + dvy * ny + wb * rc[k, RNB] - wa * rc[k, RNA]
    vn2 = dvx * nx + dvy * ny + wb * rc[k + 1, RNB] - wa * rc[k + 1, RNA]
    b1 = vn1 - rc[k, TARGET] - (k11 * a1 + k12 * a2)
    b2 = vn2 - rc[k + 1, TARGET] - (k12 * a1 + k22 * a2)
    # both points active: x = -K^-1 b
    x1 = -(blk[k, NM11] * b1 + blk[k, NM12] * b2)
    x2 = -(blk[k, NM12] * b1 + blk[k, NM22] * b2)
    if not (x1 >= 0.0 and x2 >= 0.0):
        # only the first point active
        x1 = -b1 / k11
        x2 = 0.0
        if not (x1 >= 0.0 and k12 * x1 + b2 >= 0.0):
            # only the second point active
            x1 = 0.0
            x2 = -b2 / k22
            if not (x2 >= 0.0 and k12 * x2 + b1 >= 0.0):
                # neither
                x1 = 0.0
                x2 = 0.0
                if not (b1 >= 0.0 and b2 >= 0.0):
                    return 0.0, 0.0
    c_impulse[k] = x1
    c_impulse[k + 1] = x2
    return x1 - a1, x2 - a2
