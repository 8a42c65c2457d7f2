"""MTD push-out: separate each touching pair along its normal, shared by inverse mass.

The seed moves both bodies apart along the collision normal by the MTD ("push vector"). Here the
displacement is split by inverse mass, so a concrete body (inverse mass 0) takes none and a light
body moves more than a heavy one: push_a = -n d w_a / (w_a + w_b), push_b = +n d w_b / (w_a + w_b).

Modes (WorldSettings.position_correction): FULL pushes the whole MTD depth (the seed); PARTIAL
pushes correction * (depth - slop), leaving a little overlap so resting contacts stay in touch
(less jitter), with the slop capped at 5 % of the thinner body's thickness; NONE pushes nothing.

Pairs are pushed one after another in (a, b) order (Gauss-Seidel), each seeing the positions left
by the pairs before it. The contact points, which lie on the incident body, move with it.
"""

from __future__ import annotations

import numba

from isaac.engine import kernel_cache  # noqa: F401  (first: keys the kernels' numba cache)

FULL = 0
PARTIAL = 1
NONE = 2
# largest share of the thinner body's thickness left as slop by PARTIAL
SLOP_SHARE = 0.05


@numba.njit(cache=True, nogil=True, _nrt=False)  # (no reference counts: see driver)
def push_out(
    rows,
    c_a,
    c_b,
    c_feature,
    c_slot,
    c_point,
    c_normal,
    c_pair_depth,
    inv_mass,
    thickness,
    position,
    mode,
    slop,
    correction,
    iterations,
    c_push_a,
    c_push_b,
    start,
):
    """Push each pair apart (on its slot-0 row) in `iterations` passes; positions in place.

    The depth a pair still has after earlier pushes in this stage is its MTD depth minus how far
    the pushes have already moved b away from a along n: d = d0 - ((x_b - x_b0) - (x_a - x_a0)) . n
    (exact for the translations the push applies), so later passes only push what is left and a
    stack's push propagates through it. One pass is the seed's push.
    Writes push_a / push_b (m, world) per row, the total over the passes (zero on slot > 0 rows),
    and moves every row's point with its incident body (feature // 4096 == 0: the reference face
    is a's, the point is on b). start: (n, 2) scratch (the positions before the pushes).
    """
    if rows == 0:
        return
    for i in range(position.shape[0]):
        start[i, 0] = position[i, 0]
        start[i, 1] = position[i, 1]
    for k in range(rows):
        c_push_a[k, 0] = 0.0
        c_push_a[k, 1] = 0.0
        c_push_b[k, 0] = 0.0
        c_push_b[k, 1] = 0.0
    for _ in range(iterations):
        for k in range(rows):
            if c_slot[k] != 0:
                continue
            a = c_a[k]
            b = c_b[k]
            w = inv_mass[a] + inv_mass[b]
            if w <= 0.0:
                continue
            nx = c_normal[k, 0]
            ny = c_normal[k, 1]
            moved = (position[b, 0] - start[b, 0] - position[a, 0] + start[a, 0]) * nx + (
                position[b, 1] - start[b, 1] - position[a, 1] + start[a, 1]
            ) * ny
            d = c_pair_depth[k] - moved
            if mode == PARTIAL:
                # the slop never exceeds a small share of the thinner body (a 1 mm body or a
                # 1 cm sliver must not be left half-sunk by a 5 mm slop)
                pair_slop = min(slop, SLOP_SHARE * min(thickness[a], thickness[b]))
                d = correction * (d - pair_slop)
            elif mode == NONE:
                d = 0.0
            if d <= 0.0:
                continue
            share_a = d * inv_mass[a] / w
            share_b = d * inv_mass[b] / w
            position[a, 0] -= nx * share_a
            position[a, 1] -= ny * share_a
            position[b, 0] += nx * share_b
            position[b, 1] += ny * share_b
            c_push_a[k, 0] -= nx * share_a
            c_push_a[k, 1] -= ny * share_a
            c_push_b[k, 0] += nx * share_b
            c_push_b[k, 1] += ny * share_b
    # the points belong to the incident body (b when a's face is the reference)
    first = 0
    for k in range(rows):
        if c_slot[k] == 0:
            first = k
        if c_feature[k] // 4096 == 0:
            c_point[k, 0] += c_push_b[first, 0]
            c_point[k, 1] += c_push_b[first, 1]
        else:
            c_point[k, 0] += c_push_a[first, 0]
            c_point[k, 1] += c_push_a[first, 1]
