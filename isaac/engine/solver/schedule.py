"""The sequential solver's units in Gauss-Seidel order, cut into waves and groups of LANES
independent units (`schedule`), and their columns in the group table (`layout_table`)."""

from __future__ import annotations

import numba
import numpy as np

from isaac.engine import kernel_cache  # noqa: F401  (first: keys the kernels' numba cache)

# ---- the sequential solver: several units at a time ---------------------------------------------
#
# Every pass visits the solver's units (single points and two-point blocks) in one fixed
# Gauss-Seidel order (schedule). Units that share no moving body do not affect each other, so the
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


# a manifold is solved as a 2x2 block only while K is well conditioned (Box2D's
# b2_maxConditionNumber): k11^2 < MAX_CONDITION * det(K); otherwise point by point
MAX_CONDITION = 1000.0

# 4 lanes, one AVX2 register of float64: the lane loops compile to 4-wide vector code (with 8
# they came out 2-wide), and a group pads less (pile-100: 174 units in 54 groups of 8, 432
# lanes, or 65 groups of 4, 260 lanes); its passes took 20 instead of 28 us a sub-step, the same
# bits (each lane's arithmetic does not depend on the lane count)
LANES = 4
UNIT_BLOCK = 0  # a two-point manifold solved as a 2x2 block
UNIT_POINT = 1  # a single point
# The group table's columns, each LANES wide, by their offset in a group (column c * LANES): per
# row (a unit's first row, then ROW2 further on its second): normal, friction coefficient,
# r x t of a and b, 1 / k along the tangent, r x n of a and b, target normal velocity,
# accumulated normal and tangent impulses, and R_K: k along the normal (a block) or 1 / k (a
# point); then per unit: inverse masses and inertias, a block's K12 and K^-1, the velocities.
(R_NX, R_NY, R_MU, R_RTA, R_RTB, R_MT, R_RNA, R_RNB, R_TG, R_JN, R_JT, R_K, ROW2) = (
    c * LANES for c in range(13)
)
(IMA, IIA, IMB, IIB, G12, GM11, GM12, GM22, VAX, VAY, WA, VBX, VBY, WB) = (
    c * LANES for c in range(24, 38)
)
GROUP_COLUMNS = 38
GROUP_WIDTH = GROUP_COLUMNS * LANES
U_LANES = np.uint64(LANES)
U_2LANES = np.uint64(2 * LANES)


@numba.njit(cache=True, nogil=True, _nrt=False)
def schedule(
    rows, c_a, c_b, c_slot, c_point, c_normal, position, inv, n, block, unit, grounded, last, slot,
    count, first,
):  # fmt: skip
    """The solver's units in their Gauss-Seidel order, cut into waves; returns (units, waves,
    groups): how many units, waves and groups of at most LANES independent units of one kind
    (`group_lanes` then lays the groups out).

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
    Scratch it fills (int64, from the caller; nothing is allocated): block (rows,): 1 on the
    first row of a block; unit (rows,): each unit's first row in Gauss-Seidel order; grounded
    (rows,), last (n,); slot (rows,): each unit's 2 wave + kind; count, first (2 rows,): per
    (wave, kind) its units and its first group.
    determinism: the waves depend only on the rows, visited in index order.
    """
    units = 0
    n_grounded = 0
    skip = False
    for k in range(rows):
        block[k] = 0
        if skip:  # a block's second row
            skip = False
            continue
        a = c_a[k]
        b = c_b[k]
        # (a slot-0 row always starts a unit)
        if k + 1 < rows and c_slot[k] == 0 and c_slot[k + 1] == 1:
            # both points' r x n and k along the normal, as row_terms computes them
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
            k22 = inv[a2, 0] + inv[b2, 0] + rna2 * rna2 * inv[a2, 1] + rnb2 * rnb2 * inv[b2, 1]
            k12 = inv[a, 0] + inv[b, 0] + rna1 * rna2 * inv[a, 1] + rnb1 * rnb2 * inv[b, 1]
            det = k11 * k22 - k12 * k12
            if k11 * k11 < MAX_CONDITION * det:
                block[k] = 1
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
    for body in range(n):
        last[body] = 0
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
    for s in range(2 * waves):
        count[s] = 0
    for u in range(units):
        count[slot[u]] += 1
    groups = 0
    for s in range(2 * waves):
        first[s] = groups
        groups += (count[s] + LANES - 1) // LANES
    return units, waves, groups


@numba.njit(cache=True, nogil=True, _nrt=False)
def group_lanes(units, waves, unit, slot, count, first, kind, lane_row):
    """Each group's kind and each lane's first row (-1: padding), from `schedule`'s units and
    slots, into kind (groups,) and lane_row (groups LANES,)."""
    for i in range(lane_row.shape[0]):
        lane_row[i] = -1
    for s in range(2 * waves):
        count[s] = 0
    for u in range(units):
        s = slot[u]
        lane = first[s] * LANES + count[s]
        lane_row[lane] = unit[u]
        kind[lane // LANES] = s % 2
        count[s] += 1


@numba.njit(cache=True, nogil=True, _nrt=False)
def layout_table(
    t, kind, lane_row, rows, c_a, c_b, inv, where, successor, first, last, fixed, fixed_body
):
    """Where each row's columns go (where[k]: its column-0 position), each unit's inverse masses
    and inertias, padding lanes zeroed, and the velocity hand-on: each lane side's successor
    (the velocity columns of the next unit of the same moving body, the body's first unit for
    its last; a sink for concrete bodies and padding), each moving body's first velocity
    columns (first, -1 for a body without a unit), and the concrete bodies' velocity columns
    (fixed) and bodies (fixed_body). Scratch from the caller (nothing is allocated): where
    (rows,), successor (groups 2 LANES,) uint64, first and last (n,), fixed and fixed_body
    (groups 2 LANES,). Returns how many of fixed are used."""
    groups = kind.shape[0]
    n = inv.shape[0]
    sink = groups * GROUP_WIDTH  # three columns nothing reads
    for body in range(n):
        first[body] = -1
    # last[body]: the successor entry of a body's last unit so far
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
    return n_fixed
