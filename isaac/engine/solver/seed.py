"""The seed's solver: one pass over the contacts in order, each contact's impulse by the seed's
formula from the velocities the previous ones left (Gauss-Seidel)."""

from __future__ import annotations

import numba
import numpy as np

from isaac.engine import kernel_cache  # noqa: F401  (first: keys the kernels' numba cache)
from isaac.engine.solver.mixing import combine
from isaac.engine.solver.rows import apply_bounce_back, row_terms

# Columns of the seed solver's per-row table.
NX, NY, RNA, RNB, RTA, RTB, MN, MT, TARGET, MU, KN, KT = range(12)
COLUMNS = 12


@numba.njit(cache=True, nogil=True)
def solve_seed(
    rows,
    c_a,
    c_b,
    c_feature,
    c_slot,
    c_point,
    c_normal,
    c_depth,
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
    h,
    c_impulse,
    c_tangent,
    c_restitution,
    c_push_a,
    c_push_b,
):
    """solve_contacts with the seed's solver (_seed_pass)."""
    if rows == 0:  # nothing to solve: the velocities stay as they are
        return
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
        vn = (
            (v[b, 0] - v[a, 0]) * rc[k, NX]
            + (v[b, 1] - v[a, 1]) * rc[k, NY]
            + v[b, 2] * rc[k, RNB]
            - v[a, 2] * rc[k, RNA]
        )
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
            vt = (
                -(v[b, 0] - v[a, 0]) * rc[k, NY]
                + (v[b, 1] - v[a, 1]) * rc[k, NX]
                + v[b, 2] * rc[k, RTB]
                - v[a, 2] * rc[k, RTA]
            )
            limit = rc[k, MU] * j
            jt = min(max(-vt / rc[k, KT], -limit), limit)
            _apply(a, b, k, 0.0, jt, rc, inv, v)
            c_tangent[k] = jt
