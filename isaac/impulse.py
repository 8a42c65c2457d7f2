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


# Columns of the seed solver's per-row table.
NX, NY, RNA, RNB, RTA, RTB, MN, MT, TARGET, MU, KN, KT = range(12)
COLUMNS = 12
# a manifold is solved as a 2x2 block only while K is well conditioned (Box2D's
# b2_maxConditionNumber): k11^2 < MAX_CONDITION * det(K); otherwise point by point
MAX_CONDITION = 1000.0


def solve_contacts(rows, c_a, c_b, c_feature, c_slot, c_point, c_normal, c_depth, c_previous,
                   position, velocity, angular_velocity, inv_mass, inv_inertia, gravity_dv,
                   restitution, friction, restitution_rule, friction_rule, restitution_threshold,
                   friction_on, seed_solver, iterations, warm_starting, h,
                   prev_impulse, prev_tangent, c_impulse, c_tangent, c_restitution,
                   c_push_a, c_push_b, table):
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
    table: (m,) float64 scratch for the sequential solver, kept by the caller from step to step
    (allocating its several hundred kB afresh every step cost more in page faults than the
    passes over it); returns it, or a larger replacement when it was too small.

    The two solvers are separate compiled kernels chosen here, so each is compiled only when a
    run first uses it.
    """
    if seed_solver:
        _solve_seed(rows, c_a, c_b, c_feature, c_slot, c_point, c_normal, c_depth, position,
                    velocity, angular_velocity, inv_mass, inv_inertia, gravity_dv, restitution,
                    friction, restitution_rule, friction_rule, restitution_threshold,
                    friction_on, h, c_impulse, c_tangent, c_restitution, c_push_a, c_push_b)
        return table
    return _solve_sequential(rows, c_a, c_b, c_feature, c_slot, c_point, c_normal, c_depth,
                             c_previous, position, velocity, angular_velocity, inv_mass,
                             inv_inertia, gravity_dv, restitution, friction, restitution_rule,
                             friction_rule, restitution_threshold, friction_on, iterations,
                             warm_starting, h, prev_impulse, prev_tangent, c_impulse,
                             c_tangent, c_restitution, c_push_a, c_push_b, table)


@numba.njit(cache=True, nogil=True)
def _solve_seed(rows, c_a, c_b, c_feature, c_slot, c_point, c_normal, c_depth, position,
                velocity, angular_velocity, inv_mass, inv_inertia, gravity_dv, restitution,
                friction, restitution_rule, friction_rule, restitution_threshold, friction_on, h,
                c_impulse, c_tangent, c_restitution, c_push_a, c_push_b):
    """solve_contacts with the seed's solver (_seed_pass)."""
    n = velocity.shape[0]
    v = np.empty((n, 3))  # the velocities (vx, vy, w) and inverse masses, packed per body
    inv = np.empty((n, 2))
    for i in range(n):
        v[i, 0] = velocity[i, 0]
        v[i, 1] = velocity[i, 1]
        v[i, 2] = angular_velocity[i]
        inv[i, 0] = inv_mass[i]
        inv[i, 1] = inv_inertia[i]
    bounce_back = np.zeros(rows)  # (1 + e u_b / u) g of speculative rows that bounce (m)
    rc = np.empty((rows, COLUMNS))
    for k in range(rows):
        a = c_a[k]
        b = c_b[k]
        nx = c_normal[k, 0]
        ny = c_normal[k, 1]
        rna, rnb, rta, rtb, kn, kt, mt, target, e, bounce = _row_terms(
            nx, ny, c_point[k, 0], c_point[k, 1], position[a, 0], position[a, 1],
            position[b, 0], position[b, 1], inv[a, 0], inv[a, 1], inv[b, 0], inv[b, 1],
            v[a, 0], v[a, 1], v[a, 2], v[b, 0], v[b, 1], v[b, 2], c_depth[k],
            restitution[a], restitution[b], gravity_dv[0], gravity_dv[1], restitution_rule,
            restitution_threshold, h)
        rc[k, NX] = nx
        rc[k, NY] = ny
        rc[k, RNA] = rna
        rc[k, RNB] = rnb
        rc[k, RTA] = rta
        rc[k, RTB] = rtb
        rc[k, KN] = kn
        rc[k, MN] = 1.0 / kn if kn > 0.0 else 0.0
        rc[k, KT] = kt
        rc[k, MT] = mt
        rc[k, MU] = combine(friction_rule, friction[a], friction[b]) if friction_on else 0.0
        rc[k, TARGET] = target
        c_restitution[k] = e
        bounce_back[k] = bounce
        c_impulse[k] = 0.0
        c_tangent[k] = 0.0
    _seed_pass(rows, c_a, c_b, c_depth, rc, inv, v, c_restitution, c_impulse, c_tangent)
    for i in range(n):
        velocity[i, 0] = v[i, 0]
        velocity[i, 1] = v[i, 1]
        angular_velocity[i] = v[i, 2]
    _bounce_back(rows, c_a, c_b, c_feature, c_slot, c_point, c_normal, bounce_back, inv,
                 position, c_push_a, c_push_b)


# (_row_terms takes scalars only: an inlined helper that takes arrays costs an atomic reference
# count update per array and call, several times the arithmetic here.)


@numba.njit(cache=True, nogil=True, inline="always")
def _row_terms(nx, ny, px, py, xa, ya, xb, yb, ima, iia, imb, iib, vax, vay, wa, vbx, vby, wb,
               depth, restitution_a, restitution_b, gdx, gdy, restitution_rule,
               restitution_threshold, h):
    """What the solver needs of one row: lever arms, k along the normal, k and 1/k along the
    tangent, target normal velocity, restitution used and the bounce-back distance (m; 0 unless
    a speculative row bounces)."""
    rax = px - xa
    ray = py - ya
    rbx = px - xb
    rby = py - yb
    rna = rax * ny - ray * nx  # r_ap x n
    rnb = rbx * ny - rby * nx
    rta = rax * nx + ray * ny  # r_ap x t, t = (-n_y, n_x)
    rtb = rbx * nx + rby * ny
    # the seed's denominator: 1/m_a + 1/m_b + (r_ap x n)^2 / I_a + (r_bp x n)^2 / I_b
    kn = ima + imb + rna * rna * iia + rnb * rnb * iib
    kt = ima + imb + rta * rta * iia + rtb * rtb * iib
    mt = 1.0 / kt if kt > 0.0 else 0.0
    # v_ab . n: normal velocity of b's point relative to a's, (w x r) . n = w (r x n)
    vn0 = (vbx - vax) * nx + (vby - vay) * ny + wb * rnb - wa * rna
    # the approach velocity the pair arrived with: without this step's gravity, which moved
    # each moving body by gravity_dv (no relative change between two moving bodies)
    moved = (1.0 if imb > 0.0 else 0.0) - (1.0 if ima > 0.0 else 0.0)
    arrived = vn0 - moved * (gdx * nx + gdy * ny)
    gap = -depth
    hits = vn0 < 0.0 if gap <= 0.0 else vn0 * h < -gap
    e = 0.0
    if hits and arrived < 0.0 and -arrived >= restitution_threshold:
        e = combine(restitution_rule, restitution_a, restitution_b)
    bounce = 0.0
    if gap <= 0.0:
        target = -e * arrived
    elif hits and e > 0.0:
        # it meets within this step, after this step's gravity: bounce with -e vn0 and
        # move back by (1 + e) g, to where the reflection at the surface puts it
        target = -e * vn0
        bounce = (1.0 + e) * gap
    else:
        target = -gap / h
    return rna, rnb, rta, rtb, kn, kt, mt, target, e, bounce


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


# ---- the sequential solver: several units at a time ---------------------------------------------
#
# Every pass visits the solver's units (single points and two-point blocks) in one fixed
# Gauss-Seidel order (_schedule). Units that share no moving body do not affect each other, so the
# order is cut into waves of mutually independent units, and each wave into groups of LANES units
# of one kind, which are computed side by side: the group table holds each column of a group's
# LANES units contiguously, and the per-unit code is a loop over the lanes that the compiler turns
# into vector instructions. Each lane performs exactly the floating-point operations of its unit,
# in the same order, so the results are the same bits as one unit at a time (the block's case
# analysis became selects between values that are computed either way).
#
# The two bodies' velocities are kept in the group table too (VAX..WB): after a group has been
# computed, each lane hands its bodies' new velocities straight to the velocity columns of the next
# unit that touches the same body (its successor), rather than to a per-body array that the next
# unit would gather from; a body's last unit hands them to its first unit, for the next pass.
# Concrete bodies (inverse mass and inertia 0) never change velocity: their columns hold their
# velocity throughout and what a lane computes for them is dropped (handed to a sink). Padding
# lanes (a group's unused lanes) compute zeros into the sink.

LANES = 8
UNIT_BLOCK = 0  # a two-point manifold solved as a 2x2 block
UNIT_POINT = 1  # a single point
# The group table's columns, each LANES wide, by their offset in a group (column c * LANES): per
# row (a unit's first row, then ROW2 further on its second): normal, friction coefficient,
# r x t of a and b, 1 / k along the tangent, r x n of a and b, target normal velocity,
# accumulated normal and tangent impulses, and R_K: k along the normal (a block) or 1 / k (a
# point); then per unit: inverse masses and inertias, a block's K12 and K^-1, the velocities.
(R_NX, R_NY, R_MU, R_RTA, R_RTB, R_MT, R_RNA, R_RNB, R_TG, R_JN, R_JT, R_K,
 ROW2) = (c * LANES for c in range(13))
(IMA, IIA, IMB, IIB, G12, GM11, GM12, GM22, VAX, VAY, WA, VBX, VBY,
 WB) = (c * LANES for c in range(24, 38))
GROUP_COLUMNS = 38
GROUP_WIDTH = GROUP_COLUMNS * LANES
U_LANES = np.uint64(LANES)
U_2LANES = np.uint64(2 * LANES)


@numba.njit(cache=True, nogil=True)
def _schedule(rows, c_a, c_b, c_slot, c_point, c_normal, position, inv, n):
    """The solver's units in their Gauss-Seidel order, cut into groups of at most LANES
    independent units of one kind.

    A unit is a two-point manifold whose 2x2 effective mass K is well conditioned (a block,
    by its first row), or a single row. The Gauss-Seidel order is: contacts between moving bodies
    first, contacts with concrete bodies last, each in (a, b) order, so every pass ends with the
    contacts that hold the world up satisfied (a blow on top of a thin stack no longer leaves the
    bottom body moving into the floor).

    The units are then scheduled in waves without changing a single bit of the result: a unit's
    wave is one more than the last wave that touched either of its moving bodies, and units are
    visited wave by wave. Every unit still comes after each earlier unit it shares a body with
    (the order of two units that share no moving body does not change what either computes).
    Concrete bodies never change velocity (their inverse mass and inertia are 0) and do not tie
    units together. Each wave's blocks, then its points, are cut into groups of LANES units.
    Returns (kind of each group, first row of each lane or -1 for padding, whether each row
    is the first row of a block).
    determinism: the waves depend only on the rows, visited in index order.
    """
    block = np.zeros(rows, dtype=np.bool_)  # the first row of a block
    unit = np.empty(rows, dtype=np.int64)  # units between moving bodies, then the others
    grounded = np.empty(rows, dtype=np.int64)  # units with a concrete body
    units = 0
    n_grounded = 0
    skip = False
    for k in range(rows):
        if skip:  # a block's second row
            skip = False
            continue
        a = c_a[k]
        b = c_b[k]
        # (a slot-0 row always starts a unit)
        if k + 1 < rows and c_slot[k] == 0 and c_slot[k + 1] == 1:
            # both points' r x n and k along the normal, as _row_terms computes them
            nx = c_normal[k, 0]
            ny = c_normal[k, 1]
            rna1 = (c_point[k, 0] - position[a, 0]) * ny - (c_point[k, 1] - position[a, 1]) * nx
            rnb1 = (c_point[k, 0] - position[b, 0]) * ny - (c_point[k, 1] - position[b, 1]) * nx
            k11 = inv[a, 0] + inv[b, 0] + rna1 * rna1 * inv[a, 1] + rnb1 * rnb1 * inv[b, 1]
            q = k + 1
            a2 = c_a[q]
            b2 = c_b[q]
            nx = c_normal[q, 0]
            ny = c_normal[q, 1]
            rna2 = (c_point[q, 0] - position[a2, 0]) * ny - (c_point[q, 1] - position[a2, 1]) * nx
            rnb2 = (c_point[q, 0] - position[b2, 0]) * ny - (c_point[q, 1] - position[b2, 1]) * nx
            k22 = (inv[a2, 0] + inv[b2, 0] + rna2 * rna2 * inv[a2, 1]
                   + rnb2 * rnb2 * inv[b2, 1])
            k12 = inv[a, 0] + inv[b, 0] + rna1 * rna2 * inv[a, 1] + rnb1 * rnb2 * inv[b, 1]
            det = k11 * k22 - k12 * k12
            if k11 * k11 < MAX_CONDITION * det:
                block[k] = True
                skip = True
        if inv[a, 0] == 0.0 or inv[b, 0] == 0.0:
            grounded[n_grounded] = k
            n_grounded += 1
        else:
            unit[units] = k
            units += 1
    for u in range(n_grounded):
        unit[units + u] = grounded[u]
    units += n_grounded
    last = np.zeros(n, dtype=np.int64)
    slot = np.empty(units, dtype=np.int64)  # 2 wave + kind
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
        if moving_a:
            last[a] = w + 1
        if moving_b:
            last[b] = w + 1
        waves = max(waves, w + 1)
        slot[u] = 2 * w + (UNIT_BLOCK if block[k] else UNIT_POINT)
    # groups per (wave, kind), in wave order, blocks before points
    count = np.zeros(2 * waves, dtype=np.int64)
    for u in range(units):
        count[slot[u]] += 1
    first = np.empty(2 * waves, dtype=np.int64)
    groups = 0
    for s in range(2 * waves):
        first[s] = groups
        groups += (count[s] + LANES - 1) // LANES
    kind = np.empty(groups, dtype=np.int64)
    lane_row = np.empty(groups * LANES, dtype=np.int64)
    lane_row[:] = -1
    count[:] = 0
    for u in range(units):
        s = slot[u]
        lane = first[s] * LANES + count[s]
        lane_row[lane] = unit[u]
        kind[lane // LANES] = s % 2
        count[s] += 1
    return kind, lane_row, block


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _passes(t, kind, successor, groups, iterations):
    """`iterations` Gauss-Seidel passes over the groups of table t; each group's lanes are
    computed side by side (the loops over the lanes are vectorised by the compiler), then hand
    their bodies' velocities on to their successors.

    Two-point blocks: per manifold, friction first (non-penetration matters more, so it is solved
    last), then both normal impulses at once as a 2x2 linear complementarity problem (Box2D's
    block solver): find x >= 0 with w = K x + b' >= 0 and x . w = 0, where b' = vn - target - K a
    and a the accumulated impulses: try both points active, then only the first, only the
    second, none (Box2D 2.x b2ContactSolver::SolveVelocityConstraints); if no case fits
    (degenerate) nothing changes. Every case is computed and the first that fits is selected,
    which gives the same bits as trying them in turn. Single points: friction, then the normal
    impulse (Box2D-Lite's ApplyImpulse), accumulated and clamped to stay >= 0.
    (Both are written out here rather than in inlined helpers, which cost seconds of compile
    time. error_model="numpy": k11, k22 > 0 in a block, and a division then needs no zero check,
    which would keep the loops from being vectorised.)
    """
    for _ in range(iterations):
        for g in range(groups):
            base = g * GROUP_WIDTH
            if kind[g] == UNIT_BLOCK:
                # two-point blocks
                for j in range(LANES):
                    at = base + j  # the lane's first row
                    at2 = at + ROW2  # its second
                    vax = t[at + VAX]
                    vay = t[at + VAY]
                    wa = t[at + WA]
                    vbx = t[at + VBX]
                    vby = t[at + VBY]
                    wb = t[at + WB]
                    ima = t[at + IMA]
                    iia = t[at + IIA]
                    imb = t[at + IMB]
                    iib = t[at + IIB]
                    # friction of each point; tangent t = (-n_y, n_x); Coulomb: |jt| <= mu j
                    mu = t[at + R_MU]
                    if mu > 0.0:
                        nx = t[at + R_NX]
                        ny = t[at + R_NY]
                        rta = t[at + R_RTA]
                        rtb = t[at + R_RTB]
                        vt = -(vbx - vax) * ny + (vby - vay) * nx + wb * rtb - wa * rta
                        limit = mu * t[at + R_JN]
                        old = t[at + R_JT]
                        new = min(max(old - vt * t[at + R_MT], -limit), limit)
                        t[at + R_JT] = new
                        dt = new - old
                        vax += dt * ny * ima
                        vay -= dt * nx * ima
                        wa -= dt * rta * iia
                        vbx -= dt * ny * imb
                        vby += dt * nx * imb
                        wb += dt * rtb * iib
                    # (the second point)
                    mu = t[at2 + R_MU]
                    if mu > 0.0:
                        nx = t[at2 + R_NX]
                        ny = t[at2 + R_NY]
                        rta = t[at2 + R_RTA]
                        rtb = t[at2 + R_RTB]
                        vt = -(vbx - vax) * ny + (vby - vay) * nx + wb * rtb - wa * rta
                        limit = mu * t[at2 + R_JN]
                        old = t[at2 + R_JT]
                        new = min(max(old - vt * t[at2 + R_MT], -limit), limit)
                        t[at2 + R_JT] = new
                        dt = new - old
                        vax += dt * ny * ima
                        vay -= dt * nx * ima
                        wa -= dt * rta * iia
                        vbx -= dt * ny * imb
                        vby += dt * nx * imb
                        wb += dt * rtb * iib
                    # both normal impulses (along the first point's normal)
                    nx = t[at + R_NX]
                    ny = t[at + R_NY]
                    rna1 = t[at + R_RNA]
                    rnb1 = t[at + R_RNB]
                    rna2 = t[at2 + R_RNA]
                    rnb2 = t[at2 + R_RNB]
                    k11 = t[at + R_K]
                    k22 = t[at2 + R_K]
                    k12 = t[at + G12]
                    a1 = t[at + R_JN]
                    a2 = t[at2 + R_JN]
                    dvx = vbx - vax
                    dvy = vby - vay
                    vn1 = dvx * nx + dvy * ny + wb * rnb1 - wa * rna1
                    vn2 = dvx * nx + dvy * ny + wb * rnb2 - wa * rna2
                    b1 = vn1 - t[at + R_TG] - (k11 * a1 + k12 * a2)
                    b2 = vn2 - t[at2 + R_TG] - (k12 * a1 + k22 * a2)
                    nm12 = t[at + GM12]
                    # both points active: x = -K^-1 b
                    x1 = -(t[at + GM11] * b1 + nm12 * b2)
                    x2 = -(nm12 * b1 + t[at + GM22] * b2)
                    # only the first point active; only the second
                    y1 = -b1 / k11
                    z2 = -b2 / k22
                    both = (x1 >= 0.0) & (x2 >= 0.0)
                    only1 = (y1 >= 0.0) & (k12 * y1 + b2 >= 0.0)
                    only2 = (z2 >= 0.0) & (k12 * z2 + b1 >= 0.0)
                    neither = (b1 >= 0.0) & (b2 >= 0.0)
                    n1 = x1 if both else (y1 if only1 else 0.0)
                    n2 = x2 if both else (0.0 if only1 else (z2 if only2 else 0.0))
                    fits = both | only1 | only2 | neither
                    d1 = n1 - a1 if fits else 0.0
                    d2 = n2 - a2 if fits else 0.0
                    t[at + R_JN] = n1 if fits else a1
                    t[at2 + R_JN] = n2 if fits else a2
                    px = (d1 + d2) * nx
                    py = (d1 + d2) * ny
                    t[at + VAX] = vax - px * ima
                    t[at + VAY] = vay - py * ima
                    t[at + WA] = wa - (d1 * rna1 + d2 * rna2) * iia
                    t[at + VBX] = vbx + px * imb
                    t[at + VBY] = vby + py * imb
                    t[at + WB] = wb + (d1 * rnb1 + d2 * rnb2) * iib
            else:
                # single points
                for j in range(LANES):
                    at = base + j
                    vax = t[at + VAX]
                    vay = t[at + VAY]
                    wa = t[at + WA]
                    vbx = t[at + VBX]
                    vby = t[at + VBY]
                    wb = t[at + WB]
                    ima = t[at + IMA]
                    iia = t[at + IIA]
                    imb = t[at + IMB]
                    iib = t[at + IIB]
                    nx = t[at + R_NX]
                    ny = t[at + R_NY]
                    mu = t[at + R_MU]
                    if mu > 0.0:
                        rta = t[at + R_RTA]
                        rtb = t[at + R_RTB]
                        vt = -(vbx - vax) * ny + (vby - vay) * nx + wb * rtb - wa * rta
                        limit = mu * t[at + R_JN]
                        old = t[at + R_JT]
                        new = min(max(old - vt * t[at + R_MT], -limit), limit)
                        t[at + R_JT] = new
                        dt = new - old
                        vax += dt * ny * ima
                        vay -= dt * nx * ima
                        wa -= dt * rta * iia
                        vbx -= dt * ny * imb
                        vby += dt * nx * imb
                        wb += dt * rtb * iib
                    rna = t[at + R_RNA]
                    rnb = t[at + R_RNB]
                    # (v_b + w_b x r_b - v_a - w_a x r_a) . n, using (w x r) . n = w (r x n)
                    vn = (vbx - vax) * nx + (vby - vay) * ny + wb * rnb - wa * rna
                    old = t[at + R_JN]
                    new = max(old + (t[at + R_TG] - vn) * t[at + R_K], 0.0)
                    t[at + R_JN] = new
                    dj = new - old
                    t[at + VAX] = vax - dj * nx * ima
                    t[at + VAY] = vay - dj * ny * ima
                    t[at + WA] = wa - dj * rna * iia
                    t[at + VBX] = vbx + dj * nx * imb
                    t[at + VBY] = vby + dj * ny * imb
                    t[at + WB] = wb + dj * rnb * iib
            # hand the velocities on (unsigned positions: no negative-index wrap-around)
            for j in range(LANES):
                at = base + VAX + j
                to = successor[g * 2 * LANES + j]
                t[to] = t[at]
                t[to + U_LANES] = t[at + LANES]
                t[to + U_2LANES] = t[at + 2 * LANES]
                at = base + VBX + j
                to = successor[g * 2 * LANES + LANES + j]
                t[to] = t[at]
                t[to + U_LANES] = t[at + LANES]
                t[to + U_2LANES] = t[at + 2 * LANES]


@numba.njit(cache=True, nogil=True)
def _solve_sequential(rows, c_a, c_b, c_feature, c_slot, c_point, c_normal, c_depth,
                      c_previous, position, velocity, angular_velocity, inv_mass, inv_inertia,
                      gravity_dv, restitution, friction, restitution_rule, friction_rule,
                      restitution_threshold, friction_on, iterations, warm_starting, h,
                      prev_impulse, prev_tangent, c_impulse, c_tangent, c_restitution, c_push_a,
                      c_push_b, table):
    """solve_contacts with the sequential solver: accumulated, clamped impulses, warm started,
    `iterations` Gauss-Seidel passes over every unit.

    Lays the group table of _schedule's groups out in `table` (or a larger one, returned) and
    fills it with each row's terms, applies the warm-start impulses (last step's accumulated
    impulses of the same contact points, in row order), runs the passes, and writes the
    accumulated impulses to c_impulse / c_tangent. (Several small kernels rather than one: numba
    compiles them in a fraction of the time.)
    """
    n = velocity.shape[0]
    v = np.empty((n, 3))  # the velocities (vx, vy, w) and inverse masses, packed per body
    inv = np.empty((n, 2))
    for i in range(n):
        v[i, 0] = velocity[i, 0]
        v[i, 1] = velocity[i, 1]
        v[i, 2] = angular_velocity[i]
        inv[i, 0] = inv_mass[i]
        inv[i, 1] = inv_inertia[i]
    kind, lane_row, block = _schedule(rows, c_a, c_b, c_slot, c_point, c_normal, position,
                                      inv, n)
    groups = kind.shape[0]
    if table.shape[0] < groups * GROUP_WIDTH + 3 * LANES:
        table = np.empty(2 * (groups * GROUP_WIDTH + 3 * LANES))
    where, successor, first, fixed, fixed_body = _layout(table, kind, lane_row, rows, c_a, c_b,
                                                         inv)
    bounce_back = np.zeros(rows)  # (1 + e u_b / u) g of speculative rows that bounce (m)
    warm = _fill_rows(table, where, block, rows, c_a, c_b, c_point, c_normal, c_depth,
                      c_previous, position, v, inv, gravity_dv, restitution, friction,
                      restitution_rule, friction_rule, restitution_threshold, friction_on,
                      warm_starting, h, prev_impulse, prev_tangent, c_restitution, bounce_back)
    t = table
    if warm_starting:
        # applied in row order: -P to a, +P to b
        for k in range(rows):
            if c_previous[k] < 0:
                continue
            a = c_a[k]
            b = c_b[k]
            px = warm[k, 0]
            py = warm[k, 1]
            v[a, 0] -= px * inv[a, 0]
            v[a, 1] -= py * inv[a, 0]
            v[a, 2] -= warm[k, 2] * inv[a, 1]
            v[b, 0] += px * inv[b, 0]
            v[b, 1] += py * inv[b, 0]
            v[b, 2] += warm[k, 3] * inv[b, 1]
    # the velocities into each moving body's first unit and every unit side with a concrete body
    for body in range(n):
        at = first[body]
        if at >= 0:
            t[at] = v[body, 0]
            t[at + LANES] = v[body, 1]
            t[at + 2 * LANES] = v[body, 2]
    for f in range(fixed.shape[0]):
        at = fixed[f]
        body = fixed_body[f]
        t[at] = v[body, 0]
        t[at + LANES] = v[body, 1]
        t[at + 2 * LANES] = v[body, 2]

    _passes(t, kind, successor, groups, iterations)

    # the velocities the passes handed back to each moving body's first unit, and every row's
    # accumulated impulses
    for body in range(n):
        at = first[body]
        if at >= 0:
            v[body, 0] = t[at]
            v[body, 1] = t[at + LANES]
            v[body, 2] = t[at + 2 * LANES]
    for g in range(groups):
        base = g * GROUP_WIDTH
        for j in range(LANES):
            k = lane_row[g * LANES + j]
            if k < 0:
                continue
            c_impulse[k] = t[base + R_JN + j]
            c_tangent[k] = t[base + R_JT + j]
            if kind[g] == UNIT_BLOCK:
                c_impulse[k + 1] = t[base + ROW2 + R_JN + j]
                c_tangent[k + 1] = t[base + ROW2 + R_JT + j]
    for i in range(n):
        velocity[i, 0] = v[i, 0]
        velocity[i, 1] = v[i, 1]
        angular_velocity[i] = v[i, 2]
    _bounce_back(rows, c_a, c_b, c_feature, c_slot, c_point, c_normal, bounce_back, inv,
                 position, c_push_a, c_push_b)
    return table


@numba.njit(cache=True, nogil=True)
def _layout(t, kind, lane_row, rows, c_a, c_b, inv):
    """Where each row's columns go (where[k]: its column-0 position), each unit's inverse masses
    and inertias, padding lanes zeroed, and the velocity hand-on: each lane side's successor
    (the velocity columns of the next unit of the same moving body, the body's first unit for
    its last; a sink for concrete bodies and padding), each moving body's first velocity
    columns, and the concrete bodies' velocity columns (and bodies)."""
    groups = kind.shape[0]
    n = inv.shape[0]
    sink = groups * GROUP_WIDTH  # three columns nothing reads
    successor = np.empty(groups * 2 * LANES, dtype=np.uint64)
    where = np.empty(rows, dtype=np.int64)
    first = np.full(n, -1, dtype=np.int64)
    last = np.empty(n, dtype=np.int64)  # the successor entry of a body's last unit so far
    fixed = np.empty(groups * 2 * LANES, dtype=np.int64)
    fixed_body = np.empty(groups * 2 * LANES, dtype=np.int64)
    n_fixed = 0
    for g in range(groups):
        base = g * GROUP_WIDTH
        for j in range(LANES):
            k = lane_row[g * LANES + j]
            if k < 0:
                for c in range(GROUP_COLUMNS):
                    t[base + c * LANES + j] = 0.0
                t[base + R_K + j] = 1.0
                t[base + ROW2 + R_K + j] = 1.0
                successor[g * 2 * LANES + j] = sink
                successor[g * 2 * LANES + LANES + j] = sink
                continue
            where[k] = base + j
            if kind[g] == UNIT_BLOCK:
                where[k + 1] = base + ROW2 + j
            for side in range(2):
                body = c_a[k] if side == 0 else c_b[k]
                im = inv[body, 0]
                ii = inv[body, 1]
                t[base + (IMB if side else IMA) + j] = im
                t[base + (IIB if side else IIA) + j] = ii
                at = base + (VBX if side else VAX) + j
                entry = g * 2 * LANES + side * LANES + j
                if im > 0.0 or ii > 0.0:
                    if first[body] < 0:
                        first[body] = at
                    else:
                        successor[last[body]] = at
                    last[body] = entry
                else:
                    successor[entry] = sink
                    fixed[n_fixed] = at
                    fixed_body[n_fixed] = body
                    n_fixed += 1
    for body in range(n):
        if first[body] >= 0:
            successor[last[body]] = first[body]  # the next pass
    return where, successor, first, fixed[:n_fixed], fixed_body[:n_fixed]


@numba.njit(cache=True, nogil=True)
def _fill_rows(t, where, block, rows, c_a, c_b, c_point, c_normal, c_depth, c_previous,
               position, v, inv, gravity_dv, restitution, friction, restitution_rule,
               friction_rule, restitution_threshold, friction_on, warm_starting, h,
               prev_impulse, prev_tangent, c_restitution, bounce_back):
    """Each row's terms into its table columns, in row order, with a block's K12 and K^-1;
    the restitution used and the bounce-back distances; and the warm-start impulse (last
    step's accumulated impulses of the same contact point) as it will be applied: returns
    (rows, 4) P = (px, py) and the torques r x P of a and b."""
    warm = np.empty((rows, 4))
    rna1 = 0.0
    rnb1 = 0.0
    kn1 = 0.0
    mu_a = -1  # the pair whose friction coefficient mu is
    mu_b = -1
    mu = 0.0
    for k in range(rows):
        a = c_a[k]
        b = c_b[k]
        nx = c_normal[k, 0]
        ny = c_normal[k, 1]
        rna, rnb, rta, rtb, kn, kt, mt, target, e, bounce = _row_terms(
            nx, ny, c_point[k, 0], c_point[k, 1], position[a, 0], position[a, 1],
            position[b, 0], position[b, 1], inv[a, 0], inv[a, 1], inv[b, 0], inv[b, 1],
            v[a, 0], v[a, 1], v[a, 2], v[b, 0], v[b, 1], v[b, 2], c_depth[k],
            restitution[a], restitution[b], gravity_dv[0], gravity_dv[1], restitution_rule,
            restitution_threshold, h)
        if a != mu_a or b != mu_b:  # (consecutive rows are often one pair's)
            mu = combine(friction_rule, friction[a], friction[b]) if friction_on else 0.0
            mu_a = a
            mu_b = b
        c_restitution[k] = e
        bounce_back[k] = bounce
        jn = 0.0
        jt = 0.0
        p = c_previous[k]
        if warm_starting and p >= 0:
            jn = prev_impulse[p]
            jt = prev_tangent[p] if mu > 0.0 else 0.0
        warm[k, 0] = jn * nx - jt * ny
        warm[k, 1] = jn * ny + jt * nx
        warm[k, 2] = jn * rna + jt * rta
        warm[k, 3] = jn * rnb + jt * rtb
        second = k > 0 and block[k - 1]
        at = where[k]
        t[at + R_NX] = nx
        t[at + R_NY] = ny
        t[at + R_MU] = mu
        t[at + R_RTA] = rta
        t[at + R_RTB] = rtb
        t[at + R_MT] = mt
        t[at + R_RNA] = rna
        t[at + R_RNB] = rnb
        t[at + R_TG] = target
        t[at + R_JN] = jn
        t[at + R_JT] = jt
        if block[k] or second:
            t[at + R_K] = kn
        else:
            t[at + R_K] = 1.0 / kn if kn > 0.0 else 0.0
        if second:
            # the block's 2x2 effective mass K of both points and its inverse
            a = c_a[k - 1]
            b = c_b[k - 1]
            k12 = inv[a, 0] + inv[b, 0] + rna1 * rna * inv[a, 1] + rnb1 * rnb * inv[b, 1]
            det = kn1 * kn - k12 * k12
            at = where[k - 1]
            t[at + G12] = k12
            t[at + GM11] = kn / det
            t[at + GM12] = -k12 / det
            t[at + GM22] = kn1 / det
        rna1 = rna
        rnb1 = rnb
        kn1 = kn
    return warm
