"""The sequential-impulse solver: accumulated, clamped impulses, warm started, `iterations`
passes over the scheduled units."""

from __future__ import annotations

import numba
import numpy as np

from isaac.engine import kernel_cache  # noqa: F401  (first: keys the kernels' numba cache)
from isaac.engine.joints import Joints, solve_joint_velocities, warm_start_joints
from isaac.engine.solver.mixing import combine
from isaac.engine.solver.passes import run_passes
from isaac.engine.solver.rows import apply_bounce_back, row_terms
from isaac.engine.solver.schedule import (
    G12,
    GM11,
    GM12,
    GM22,
    GROUP_WIDTH,
    LANES,
    R_JN,
    R_JT,
    R_K,
    R_MT,
    R_MU,
    R_NX,
    R_NY,
    R_RNA,
    R_RNB,
    R_RTA,
    R_RTB,
    R_TG,
    ROW2,
    UNIT_BLOCK,
    group_lanes,
    layout_table,
    schedule,
)

# The solver's scratch: one float64 array the caller keeps from step to step (`table`), carved
# into every per-step array the solver uses, so that a step allocates nothing (an np.empty is an
# allocation and two reference-count updates; the solver took 22 a sub-step). Its fixed part
# (sized by rows and bodies): the velocities v (n, 3) and inverse masses (n, 2), bounce-back
# distances (rows,), warm-start impulses (rows, 4), then int64 columns (9 rows + 4 n, below);
# at FIXED_PART's end (a multiple of LANES) the group table (groups GROUP_WIDTH + 3 LANES, the
# last three LANES a sink) and the groups' int64 columns (groups (1 + 7 LANES)).


@numba.njit(cache=True, nogil=True, _nrt=False, inline="always")
def _fixed_part(rows, n):
    """float64 entries of the scratch before the group table, a multiple of LANES."""
    size = 5 * n + 5 * rows + 9 * rows + 4 * n
    return (size + LANES - 1) // LANES * LANES


@numba.njit(cache=True, nogil=True, _nrt=False, inline="always")
def _group_part(groups):
    """float64 entries of the group table and the groups' int64 columns."""
    return groups * GROUP_WIDTH + 3 * LANES + groups * (1 + 7 * LANES)


@numba.njit(cache=True, nogil=True, _nrt=False)
def solve_sequential(
    rows,
    c_a,
    c_b,
    c_feature,
    c_slot,
    c_point,
    c_normal,
    c_depth,
    c_previous,
    position,
    velocity,
    angular_velocity,
    inv_mass,
    inv_inertia,
    gravity_dv,
    restitution,
    friction,
    restitution_rule,
    friction_rule,
    restitution_threshold,
    friction_on,
    iterations,
    warm_starting,
    h,
    prev_impulse,
    prev_tangent,
    c_impulse,
    c_tangent,
    c_restitution,
    c_push_a,
    c_push_b,
    table,
    joints,
    jt,
):
    """solve_contacts with the sequential solver: accumulated, clamped impulses, warm started,
    `iterations` Gauss-Seidel passes over every unit.

    joints, jt: the joint table (`isaac.engine.joints.Joints`, a plain tuple) and its scratch
    rows, prepared for this sub-step (`prepare_joints`); with joints each iteration is the
    contacts' pass, then the joints' (their impulses accumulate in jt). Without joints
    (jt has no rows) the passes run as before, all at once. Both None for a scene without
    joints: numba prunes the `jt is None` branches on a None argument's type before typing, so
    that specialisation never compiles or links the joints' kernels (what a scene without
    joints pays at its first run); it computes what an empty joint table does, bit for bit.

    table: (m,) float64 scratch, kept by the caller (see above); the solver allocates nothing.
    Returns 0 when it solved, or, when `table` is too small, the size it needs (at least; the
    caller grows it and calls again): then it has changed nothing, no velocity, no row, so
    the call can simply be repeated, and results never depend on the scratch's size.

    Schedules the units, lays the group table of schedule's groups out and fills it with each
    row's terms, applies the warm-start impulses (last step's accumulated impulses of the same
    contact points, in row order), runs the passes, and writes the accumulated impulses to
    c_impulse / c_tangent. (Several small kernels rather than one: numba compiles them in a
    fraction of the time. _nrt=False: no reference counts, as the driver's stage kernels.)
    """
    if jt is None:  # (pruned on the argument's type: see the docstring)
        n_joints = 0
    else:
        n_joints = jt.shape[0]
    if rows == 0 and n_joints == 0:  # nothing to solve: the velocities stay as they are
        return 0
    n = velocity.shape[0]
    fixed_size = _fixed_part(rows, n)
    if table.shape[0] < fixed_size:  # (a first guess at the groups; a retry may ask more)
        return fixed_size + _group_part(rows // LANES + 1)
    v = table[: 3 * n].reshape((n, 3))  # the velocities (vx, vy, w), packed per body
    inv = table[3 * n : 5 * n].reshape((n, 2))  # and the inverse masses
    bounce_back = table[5 * n : 5 * n + rows]  # (1 + e u_b / u) g of rows that bounce (m)
    warm = table[5 * n + rows : 5 * n + 5 * rows].reshape((rows, 4))
    ints = table[5 * n + 5 * rows : 5 * n + 5 * rows + 9 * rows + 4 * n].view(np.int64)
    block = ints[:rows]
    unit = ints[rows : 2 * rows]
    grounded = ints[2 * rows : 3 * rows]
    slot = ints[3 * rows : 4 * rows]
    where = ints[4 * rows : 5 * rows]
    count = ints[5 * rows : 7 * rows]
    first_group = ints[7 * rows : 9 * rows]
    last = ints[9 * rows : 9 * rows + n]
    first = ints[9 * rows + n : 9 * rows + 2 * n]
    units_of = ints[9 * rows + 2 * n : 9 * rows + 3 * n]
    for i in range(n):
        inv[i, 0] = inv_mass[i]
        inv[i, 1] = inv_inertia[i]
    units, waves, groups = schedule(
        rows, c_a, c_b, c_slot, c_point, c_normal, position, inv, n, block, unit, grounded, last,
        slot, count, first_group,
    )  # fmt: skip
    need = fixed_size + _group_part(groups)
    if table.shape[0] < need:
        return need
    for i in range(n):
        v[i, 0] = velocity[i, 0]
        v[i, 1] = velocity[i, 1]
        v[i, 2] = angular_velocity[i]
    end = fixed_size + groups * GROUP_WIDTH + 3 * LANES
    t = table[fixed_size:end]
    kind = table[end : end + groups].view(np.int64)
    lane_row = table[end + groups : end + groups + groups * LANES].view(np.int64)
    at = end + groups + groups * LANES
    successor = table[at : at + groups * 2 * LANES].view(np.uint64)
    fixed = table[at + groups * 2 * LANES : at + groups * 4 * LANES].view(np.int64)
    fixed_body = table[at + groups * 4 * LANES : at + groups * 6 * LANES].view(np.int64)
    group_lanes(units, waves, unit, slot, count, first_group, kind, lane_row)
    n_fixed = layout_table(
        t, kind, lane_row, rows, c_a, c_b, inv, where, successor, first, last, fixed, fixed_body
    )
    fill_rows(
        t,
        where,
        block,
        rows,
        c_a,
        c_b,
        c_point,
        c_normal,
        c_depth,
        c_previous,
        position,
        v,
        inv,
        gravity_dv,
        restitution,
        friction,
        restitution_rule,
        friction_rule,
        restitution_threshold,
        friction_on,
        warm_starting,
        h,
        prev_impulse,
        prev_tangent,
        c_restitution,
        bounce_back,
        warm,
    )
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
    if jt is not None:
        if n_joints and warm_starting:
            warm_start_joints(Joints(*joints), jt, v, inv)
    # the velocities into each moving body's first unit and every unit side with a concrete body
    _to_first_units(t, first, v)
    for f in range(n_fixed):
        _put_velocity(t, fixed[f], v, fixed_body[f])

    if jt is None:
        run_passes(t, kind, successor, groups, iterations)
    elif n_joints == 0:
        run_passes(t, kind, successor, groups, iterations)
    else:
        J = Joints(*joints)
        # after each pass the velocities are back in each body's first unit (its successor);
        # handed between the units and v for the bodies that have a unit alone (`units`), not
        # for every body each iteration (the 100 x 100 joint grid has 10,000 bodies, no contact)
        units = units_of[: _bodies_with_units(first, units_of)]
        for _ in range(iterations):
            run_passes(t, kind, successor, groups, 1)
            _from_units(t, first, v, units)
            solve_joint_velocities(J, jt, v, inv, h)
            _to_units(t, first, v, units)

    # the velocities the passes handed back to each moving body's first unit, and every row's
    # accumulated impulses
    _from_first_units(t, first, v)
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
    apply_bounce_back(
        rows,
        c_a,
        c_b,
        c_feature,
        c_slot,
        c_point,
        c_normal,
        bounce_back,
        inv,
        position,
        c_push_a,
        c_push_b,
    )
    return 0


@numba.njit(cache=True, nogil=True, inline="always")
def _to_first_units(t, first, v):
    for body in range(v.shape[0]):
        if first[body] >= 0:
            _put_velocity(t, first[body], v, body)


@numba.njit(cache=True, nogil=True, inline="always")
def _from_first_units(t, first, v):
    for body in range(v.shape[0]):
        if first[body] >= 0:
            _get_velocity(t, first[body], v, body)


@numba.njit(cache=True, nogil=True, inline="always")
def _bodies_with_units(first, units):
    """The bodies (ascending) whose first unit `first` gives (>= 0), into units; how many."""
    count = 0
    for body in range(first.shape[0]):
        if first[body] >= 0:
            units[count] = body
            count += 1
    return count


@numba.njit(cache=True, nogil=True, inline="always")
def _to_units(t, first, v, units):
    """`_to_first_units` for the bodies `units` (`_bodies_with_units`)."""
    for u in range(units.shape[0]):
        _put_velocity(t, first[units[u]], v, units[u])


@numba.njit(cache=True, nogil=True, inline="always")
def _from_units(t, first, v, units):
    """`_from_first_units` for the bodies `units` (`_bodies_with_units`)."""
    for u in range(units.shape[0]):
        _get_velocity(t, first[units[u]], v, units[u])


@numba.njit(cache=True, nogil=True, inline="always")
def _put_velocity(t, at, v, body):
    """A body's (vx, vy, w) into a unit side's velocity columns at ``at`` of table t."""
    t[at] = v[body, 0]
    t[at + LANES] = v[body, 1]
    t[at + 2 * LANES] = v[body, 2]


@numba.njit(cache=True, nogil=True, inline="always")
def _get_velocity(t, at, v, body):
    """The velocity columns at ``at`` of table t back into a body's (vx, vy, w)."""
    v[body, 0] = t[at]
    v[body, 1] = t[at + LANES]
    v[body, 2] = t[at + 2 * LANES]


@numba.njit(cache=True, nogil=True, _nrt=False)
def fill_rows(
    t,
    where,
    block,
    rows,
    c_a,
    c_b,
    c_point,
    c_normal,
    c_depth,
    c_previous,
    position,
    v,
    inv,
    gravity_dv,
    restitution,
    friction,
    restitution_rule,
    friction_rule,
    restitution_threshold,
    friction_on,
    warm_starting,
    h,
    prev_impulse,
    prev_tangent,
    c_restitution,
    bounce_back,
    warm,
):
    """Each row's terms into its table columns, in row order, with a block's K12 and K^-1;
    the restitution used and the bounce-back distances; and the warm-start impulse (last
    step's accumulated impulses of the same contact point) as it will be applied, into warm
    (rows, 4): P = (px, py) and the torques r x P of a and b."""
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
        rna, rnb, rta, rtb, kn, kt, mt, target, e, bounce = row_terms(
            nx,
            ny,
            c_point[k, 0],
            c_point[k, 1],
            position[a, 0],
            position[a, 1],
            position[b, 0],
            position[b, 1],
            inv[a, 0],
            inv[a, 1],
            inv[b, 0],
            inv[b, 1],
            v[a, 0],
            v[a, 1],
            v[a, 2],
            v[b, 0],
            v[b, 1],
            v[b, 2],
            c_depth[k],
            restitution[a],
            restitution[b],
            gravity_dv[0],
            gravity_dv[1],
            restitution_rule,
            restitution_threshold,
            h,
        )
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


def grown_scratch(table: np.ndarray, need: int) -> np.ndarray:
    """A new solver scratch for one that was `need` entries too short (solve_sequential's
    answer): twice that, so that a growing scene seldom asks again. Its contents do not matter
    (the solver writes every entry it reads), zeros only for tidiness."""
    return np.zeros(max(2 * need, table.shape[0]))
