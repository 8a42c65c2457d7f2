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


@numba.njit(cache=True)
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


# columns of the per-row table built once per solve (m, 1/kg, 1/(kg m^2), m/s)
NX, NY, RAX, RAY, RBX, RBY, RNA, RNB, RTA, RTB = 0, 1, 2, 3, 4, 5, 6, 7, 8, 9
IMA, IMB, IIA, IIB, KN, MN, KT, MT, TARGET, MU = 10, 11, 12, 13, 14, 15, 16, 17, 18, 19
# two-point manifolds (on the slot-0 row): 1.0 when solved as a block, K12, inverse of K
BLOCK, K12, NM11, NM12, NM22 = 20, 21, 22, 23, 24
COLUMNS = 25
# a manifold is solved as a 2x2 block only while K is well conditioned (Box2D's
# b2_maxConditionNumber): k11^2 < MAX_CONDITION * det(K); otherwise point by point
MAX_CONDITION = 1000.0


@numba.njit(cache=True)
def solve_contacts(rows, c_a, c_b, c_slot, c_point, c_normal, c_depth, c_previous,
                   position, velocity, angular_velocity, inv_mass, inv_inertia,
                   restitution, friction, restitution_rule, friction_rule, restitution_threshold,
                   friction_on, seed_solver, iterations, warm_starting, h,
                   prev_impulse, prev_tangent, c_impulse, c_tangent, c_restitution):
    """Resolve every contact row; writes the impulses applied (N s) and the restitution used.

    Velocities are worked on as a packed copy (vx, vy, w) per body and written back at the end.
    """
    n = velocity.shape[0]
    v = np.empty((n, 3))
    for i in range(n):
        v[i, 0] = velocity[i, 0]
        v[i, 1] = velocity[i, 1]
        v[i, 2] = angular_velocity[i]
    rc = np.empty((rows, COLUMNS))
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
        ima = inv_mass[a]
        imb = inv_mass[b]
        iia = inv_inertia[a]
        iib = inv_inertia[b]
        # the seed's denominator: 1/m_a + 1/m_b + (r_ap x n)^2 / I_a + (r_bp x n)^2 / I_b
        kn = ima + imb + rna * rna * iia + rnb * rnb * iib
        kt = ima + imb + rta * rta * iia + rtb * rtb * iib
        rc[k, NX] = nx
        rc[k, NY] = ny
        rc[k, RAX] = rax
        rc[k, RAY] = ray
        rc[k, RBX] = rbx
        rc[k, RBY] = rby
        rc[k, RNA] = rna
        rc[k, RNB] = rnb
        rc[k, RTA] = rta
        rc[k, RTB] = rtb
        rc[k, IMA] = ima
        rc[k, IMB] = imb
        rc[k, IIA] = iia
        rc[k, IIB] = iib
        rc[k, KN] = kn
        rc[k, MN] = 1.0 / kn if kn > 0.0 else 0.0
        rc[k, KT] = kt
        rc[k, MT] = 1.0 / kt if kt > 0.0 else 0.0
        rc[k, MU] = combine(friction_rule, friction[a], friction[b]) if friction_on else 0.0
        # v_ab . n: normal velocity of b's point relative to a's, (w x r) . n = w (r x n)
        vn0 = ((v[b, 0] - v[a, 0]) * nx + (v[b, 1] - v[a, 1]) * ny
               + v[b, 2] * rnb - v[a, 2] * rna)
        gap = -c_depth[k]
        hits = vn0 < 0.0 if gap <= 0.0 else vn0 * h < -gap
        e = 0.0
        if hits and -vn0 >= restitution_threshold:
            e = combine(restitution_rule, restitution[a], restitution[b])
        c_restitution[k] = e
        if gap <= 0.0:
            rc[k, TARGET] = -e * vn0
        elif hits:
            rc[k, TARGET] = max(-gap / h, -e * vn0)
        else:
            rc[k, TARGET] = -gap / h
        c_impulse[k] = 0.0
        c_tangent[k] = 0.0
        rc[k, BLOCK] = 0.0

    # two-point manifolds: the 2x2 effective mass K of both points, for the block solver
    for k in range(rows - 1):
        if c_slot[k] == 0 and c_slot[k + 1] == 1:
            k11 = rc[k, KN]
            k22 = rc[k + 1, KN]
            k12 = (rc[k, IMA] + rc[k, IMB] + rc[k, RNA] * rc[k + 1, RNA] * rc[k, IIA]
                   + rc[k, RNB] * rc[k + 1, RNB] * rc[k, IIB])
            det = k11 * k22 - k12 * k12
            if k11 * k11 < MAX_CONDITION * det:
                rc[k, BLOCK] = 1.0
                rc[k, K12] = k12
                rc[k, NM11] = k22 / det
                rc[k, NM12] = -k12 / det
                rc[k, NM22] = k11 / det

    if seed_solver:
        _seed_pass(rows, c_a, c_b, c_depth, rc, v, c_restitution, c_impulse, c_tangent)
    else:
        if warm_starting:
            for k in range(rows):
                p = c_previous[k]
                if p >= 0:
                    c_impulse[k] = prev_impulse[p]
                    c_tangent[k] = prev_tangent[p] if rc[k, MU] > 0.0 else 0.0
                    _apply(c_a[k], c_b[k], k, c_impulse[k], c_tangent[k], rc, v)
        for _ in range(iterations):
            _sequential_pass(rows, c_a, c_b, rc, v, c_impulse, c_tangent)

    for i in range(n):
        velocity[i, 0] = v[i, 0]
        velocity[i, 1] = v[i, 1]
        angular_velocity[i] = v[i, 2]


@numba.njit(cache=True)
def _apply(a, b, k, jn, jt, rc, v):
    """Apply normal impulse jn and tangent impulse jt (N s) of row k: -P to a, +P to b."""
    nx = rc[k, NX]
    ny = rc[k, NY]
    px = jn * nx - jt * ny
    py = jn * ny + jt * nx
    v[a, 0] -= px * rc[k, IMA]
    v[a, 1] -= py * rc[k, IMA]
    v[a, 2] -= (jn * rc[k, RNA] + jt * rc[k, RTA]) * rc[k, IIA]
    v[b, 0] += px * rc[k, IMB]
    v[b, 1] += py * rc[k, IMB]
    v[b, 2] += (jn * rc[k, RNB] + jt * rc[k, RTB]) * rc[k, IIB]


@numba.njit(cache=True)
def _seed_pass(rows, c_a, c_b, c_depth, rc, v, c_restitution, c_impulse, c_tangent):
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
        _apply(a, b, k, j, 0.0, rc, v)
        c_impulse[k] = j
        if rc[k, MU] > 0.0 and rc[k, KT] > 0.0:
            vt = (-(v[b, 0] - v[a, 0]) * rc[k, NY] + (v[b, 1] - v[a, 1]) * rc[k, NX]
                  + v[b, 2] * rc[k, RTB] - v[a, 2] * rc[k, RTA])
            limit = rc[k, MU] * j
            jt = min(max(-vt / rc[k, KT], -limit), limit)
            _apply(a, b, k, 0.0, jt, rc, v)
            c_tangent[k] = jt


@numba.njit(cache=True)
def _sequential_pass(rows, c_a, c_b, rc, v, c_impulse, c_tangent):
    """One Gauss-Seidel pass of accumulated, clamped impulses.

    Per manifold, friction first (non-penetration matters more, so it is solved last), then the
    normal impulses: point by point (Box2D-Lite's ApplyImpulse), or for a well-conditioned
    two-point manifold both at once as a 2x2 linear complementarity problem (Box2D's block
    solver), which makes resting stacks converge in far fewer iterations.
    """
    k = 0
    while k < rows:
        if rc[k, BLOCK] == 1.0:
            _friction(c_a[k], c_b[k], k, rc, v, c_impulse, c_tangent)
            _friction(c_a[k], c_b[k], k + 1, rc, v, c_impulse, c_tangent)
            _block_normal(c_a[k], c_b[k], k, rc, v, c_impulse)
            k += 2
        else:
            _friction(c_a[k], c_b[k], k, rc, v, c_impulse, c_tangent)
            _normal(c_a[k], c_b[k], k, rc, v, c_impulse)
            k += 1


@numba.njit(cache=True)
def _normal(a, b, k, rc, v, c_impulse):
    """Accumulated normal impulse of one point, clamped to >= 0."""
    nx = rc[k, NX]
    ny = rc[k, NY]
    rna = rc[k, RNA]
    rnb = rc[k, RNB]
    # (v_b + w_b x r_b - v_a - w_a x r_a) . n, using (w x r) . n = w (r x n)
    vn = (v[b, 0] - v[a, 0]) * nx + (v[b, 1] - v[a, 1]) * ny + v[b, 2] * rnb - v[a, 2] * rna
    old = c_impulse[k]
    new = max(old + (rc[k, TARGET] - vn) * rc[k, MN], 0.0)
    c_impulse[k] = new
    dj = new - old
    v[a, 0] -= dj * nx * rc[k, IMA]
    v[a, 1] -= dj * ny * rc[k, IMA]
    v[a, 2] -= dj * rna * rc[k, IIA]
    v[b, 0] += dj * nx * rc[k, IMB]
    v[b, 1] += dj * ny * rc[k, IMB]
    v[b, 2] += dj * rnb * rc[k, IIB]


@numba.njit(cache=True)
def _friction(a, b, k, rc, v, c_impulse, c_tangent):
    """Accumulated tangent impulse of one point, clamped to |jt| <= mu j (Coulomb)."""
    mu = rc[k, MU]
    if mu <= 0.0:
        return
    nx = rc[k, NX]
    ny = rc[k, NY]
    rta = rc[k, RTA]
    rtb = rc[k, RTB]
    # tangent t = (-n_y, n_x)
    vt = -(v[b, 0] - v[a, 0]) * ny + (v[b, 1] - v[a, 1]) * nx + v[b, 2] * rtb - v[a, 2] * rta
    limit = mu * c_impulse[k]
    old = c_tangent[k]
    new = min(max(old - vt * rc[k, MT], -limit), limit)
    c_tangent[k] = new
    dt = new - old
    v[a, 0] += dt * ny * rc[k, IMA]
    v[a, 1] -= dt * nx * rc[k, IMA]
    v[a, 2] -= dt * rta * rc[k, IIA]
    v[b, 0] -= dt * ny * rc[k, IMB]
    v[b, 1] += dt * nx * rc[k, IMB]
    v[b, 2] += dt * rtb * rc[k, IIB]


@numba.njit(cache=True)
def _block_normal(a, b, k, rc, v, c_impulse):
    """Both normal impulses of a two-point manifold (rows k, k + 1) as one 2x2 LCP.

    Find x >= 0 with w = K x + b' >= 0 and x . w = 0, where b' = vn - target - K a and a the
    accumulated impulses: try both points active, then only the first, only the second, none
    (Box2D 2.x b2ContactSolver::SolveVelocityConstraints). If no case fits (degenerate), the
    impulses are left as they are.
    """
    nx = rc[k, NX]
    ny = rc[k, NY]
    rna1 = rc[k, RNA]
    rnb1 = rc[k, RNB]
    rna2 = rc[k + 1, RNA]
    rnb2 = rc[k + 1, RNB]
    k11 = rc[k, KN]
    k22 = rc[k + 1, KN]
    k12 = rc[k, K12]
    a1 = c_impulse[k]
    a2 = c_impulse[k + 1]
    dvx = v[b, 0] - v[a, 0]
    dvy = v[b, 1] - v[a, 1]
    vn1 = dvx * nx + dvy * ny + v[b, 2] * rnb1 - v[a, 2] * rna1
    vn2 = dvx * nx + dvy * ny + v[b, 2] * rnb2 - v[a, 2] * rna2
    b1 = vn1 - rc[k, TARGET] - (k11 * a1 + k12 * a2)
    b2 = vn2 - rc[k + 1, TARGET] - (k12 * a1 + k22 * a2)
    # both points active: x = -K^-1 b
    x1 = -(rc[k, NM11] * b1 + rc[k, NM12] * b2)
    x2 = -(rc[k, NM12] * b1 + rc[k, NM22] * b2)
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
                    return
    d1 = x1 - a1
    d2 = x2 - a2
    c_impulse[k] = x1
    c_impulse[k + 1] = x2
    px = (d1 + d2) * nx
    py = (d1 + d2) * ny
    v[a, 0] -= px * rc[k, IMA]
    v[a, 1] -= py * rc[k, IMA]
    v[a, 2] -= (d1 * rna1 + d2 * rna2) * rc[k, IIA]
    v[b, 0] += px * rc[k, IMB]
    v[b, 1] += py * rc[k, IMB]
    v[b, 2] += (d1 * rnb1 + d2 * rnb2) * rc[k, IIB]
