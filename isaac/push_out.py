"""MTD push-out: separate each touching pair along its normal, shared by inverse mass.

The seed moves both bodies apart along the collision normal by the MTD ("push vector"). Here the
displacement is split by inverse mass, so a concrete body (inverse mass 0) takes none and a light
body moves more than a heavy one: push_a = -n d w_a / (w_a + w_b), push_b = +n d w_b / (w_a + w_b).

Modes (WorldSettings.position_correction): FULL pushes the whole MTD depth (the seed); PARTIAL
pushes correction * (depth - slop), leaving a little overlap so resting contacts stay in touch
(less jitter); NONE pushes nothing.

Pairs are pushed one after another in (a, b) order (Gauss-Seidel), each seeing the positions left
by the pairs before it. The contact points, which lie on the incident body, move with it.
"""

from __future__ import annotations

import numba

FULL = 0
PARTIAL = 1
NONE = 2


@numba.njit(cache=True)
def push_out(rows, c_a, c_b, c_feature, c_slot, c_point, c_normal, c_pair_depth, inv_mass,
             position, mode, slop, correction, c_push_a, c_push_b):
    """Apply the push of each pair (on its slot-0 row) to `position` in place.

    Writes push_a / push_b (m, world) per row (zero on slot > 0 rows) and moves every row's point
    with its incident body (feature // 4096 == 0: the reference face is a's, the point is on b).
    """
    pa_x = 0.0
    pa_y = 0.0
    pb_x = 0.0
    pb_y = 0.0
    for k in range(rows):
        a = c_a[k]
        b = c_b[k]
        if c_slot[k] == 0:
            pa_x = 0.0
            pa_y = 0.0
            pb_x = 0.0
            pb_y = 0.0
            d = c_pair_depth[k]
            if mode == PARTIAL:
                d = correction * (d - slop)
            elif mode == NONE:
                d = 0.0
            w = inv_mass[a] + inv_mass[b]
            if d > 0.0 and w > 0.0:
                nx = c_normal[k, 0]
                ny = c_normal[k, 1]
                share_a = d * inv_mass[a] / w
                share_b = d * inv_mass[b] / w
                pa_x = -nx * share_a
                pa_y = -ny * share_a
                pb_x = nx * share_b
                pb_y = ny * share_b
                position[a, 0] += pa_x
                position[a, 1] += pa_y
                position[b, 0] += pb_x
                position[b, 1] += pb_y
            c_push_a[k, 0] = pa_x
            c_push_a[k, 1] = pa_y
            c_push_b[k, 0] = pb_x
            c_push_b[k, 1] = pb_y
        else:
            c_push_a[k, 0] = 0.0
            c_push_a[k, 1] = 0.0
            c_push_b[k, 0] = 0.0
            c_push_b[k, 1] = 0.0
        # the point belongs to the incident body (b when a's face is the reference)
        if c_feature[k] // 4096 == 0:
            c_point[k, 0] += pb_x
            c_point[k, 1] += pb_y
        else:
            c_point[k, 0] += pa_x
            c_point[k, 1] += pa_y
