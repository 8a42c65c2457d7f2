"""Narrow phase: Separating Axis Theorem over both polygons' edge normals, with contact points.

(Pairs with a circle go to isaac.engine.circles.)

For each candidate pair (a, b) this finds:
- the minimum translation distance (MTD): the edge normal of a or b along which the polygons
  overlap least (the seed's method). For convex polygons the overlap along a's edge normal n_i is
  minus the *separation* s_i = min over b's vertices v of n_i . (v - a_i), so the MTD axis is the
  face with the largest separation; a positive separation on any face is a separating axis.
  This fixes the seed pseudo-code, which compared `max < x` for the minimum and projected b's
  vertices with a's vertex index.
- the normal: unit, from a towards b (a's outward face normal, or minus b's).
- the contact point(s), by clipping the incident edge (the edge of the other body most opposed to
  the reference face) against the side planes of the reference face (Box2D-Lite / Ericson 5.x):
  a vertex-face contact gives the penetrating vertex; nearly parallel edges (face-face) give the
  middle of the overlapping segment, so a symmetric head-on hit produces no spin. With two-point
  manifolds both clipped points are kept. Points lie on the incident body's surface.

Axis hysteresis: when the pair touched in the previous step and that step's reference face is
still within a small tolerance of the best face, it is kept, so near-ties (a box resting on a
box: a's top and b's bottom overlap equally) do not flip the normal from step to step.

Speculative contacts (ccd): with a margin > 0, pairs closer than the distance they can close in
one step produce contacts with negative depth (minus the gap); the solver lets them close the gap
but not pass through.
"""

from __future__ import annotations

import numba
import numpy as np

from isaac.engine import kernel_cache  # noqa: F401  (first: keys the kernels' numba cache)
from isaac.engine.circles import round_contact

# Two clipped points count as one face-face contact when their depths differ by less than this
# fraction of their distance (edges within about 1e-3 rad of parallel).
PARALLEL_TOLERANCE = 1e-3
# Hysteresis: keep last step's face while its separation is within this fraction of the depth
# plus this fraction of the smaller body's radius of the best face.
HYSTERESIS_RELATIVE = 0.02
HYSTERESIS_ABSOLUTE = 1e-4


# Bodies are addressed by index into the (n, V, 2) world arrays rather than by slicing a view per
# body: a view costs reference counting on every pair, which was half the narrow phase's time.


@numba.njit(cache=True, nogil=True, inline="always")
def face_separation(vertices, normals, r, edge, i, count_i):
    """Separation (m) of body i from face `edge` of body r: min over i's vertices."""
    nx = normals[r, edge, 0]
    ny = normals[r, edge, 1]
    ox = vertices[r, edge, 0]
    oy = vertices[r, edge, 1]
    best = np.inf
    for j in range(count_i):
        s = nx * (vertices[i, j, 0] - ox) + ny * (vertices[i, j, 1] - oy)
        if s < best:
            best = s
    return best


@numba.njit(cache=True, nogil=True, inline="always")
def max_separation(vertices, normals, r, count_r, i, count_i):
    """Largest face separation of body r against body i, and its face index.

    All faces are always visited: an early exit at the first separating axis made the loop
    twice as slow (it can no longer be unrolled, and the exit branch is unpredictable).
    determinism: strict '>' keeps the lowest face index on exact ties.
    """
    best = -np.inf
    best_edge = 0
    for k in range(count_r):
        s = face_separation(vertices, normals, r, k, i, count_i)
        if s > best:
            best = s
            best_edge = k
    return best, best_edge


@numba.njit(cache=True, nogil=True, inline="always")
def _emit(
    row,
    a,
    b,
    feature,
    slot,
    px,
    py,
    nx,
    ny,
    depth,
    pair_depth,
    c_a,
    c_b,
    c_feature,
    c_slot,
    c_point,
    c_normal,
    c_depth,
    c_pair_depth,
):
    """Write one contact row."""
    c_a[row] = a
    c_b[row] = b
    c_feature[row] = feature
    c_slot[row] = slot
    c_point[row, 0] = px
    c_point[row, 1] = py
    c_normal[row, 0] = nx
    c_normal[row, 1] = ny
    c_depth[row] = depth
    c_pair_depth[row] = pair_depth


@numba.njit(cache=True, nogil=True, _nrt=False)  # (no reference counts: see driver)
def collide_pairs(
    pair_a,
    pair_b,
    n_pairs,
    vertices,
    normals,
    vertex_count,
    radius,
    velocity,
    angular_velocity,
    margin_time,
    margin_extra,
    two_points,
    hysteresis,
    prev_key,
    prev_feature,
    c_a,
    c_b,
    c_feature,
    c_slot,
    c_point,
    c_normal,
    c_depth,
    c_pair_depth,
):
    """Contacts of every candidate pair, written row by row in pair order; returns the row count.

    margin_time: time (s) over which speculative contacts look ahead (0 turns ccd off);
    margin_extra: extra speculative distance (m), e.g. what gravity adds in one step.
    A pair's speculative margin is margin_time * (|v_b - v_a| + |w_a| r_a + |w_b| r_b) + extra.
    Rows: c_depth is the penetration of that point (m; negative = gap of a speculative point) and
    c_pair_depth the pair's MTD depth, used by the push-out. prev_key (the previous rows'
    a * n + b) is ascending, like the pairs, so one forward walk finds every pair's previous
    rows (for axis hysteresis); match_previous pairs rows for warm starting afterwards.
    """
    n = vertex_count.shape[0]
    n_prev = prev_key.shape[0]
    q = 0
    rows = 0
    for p in range(n_pairs):
        a = pair_a[p]
        b = pair_b[p]
        key = a * n + b
        while q < n_prev and prev_key[q] < key:
            q += 1
        prev = q if q < n_prev and prev_key[q] == key else -1
        ca = vertex_count[a]
        cb = vertex_count[b]
        margin = 0.0
        if margin_time > 0.0:
            dvx = velocity[b, 0] - velocity[a, 0]
            dvy = velocity[b, 1] - velocity[a, 1]
            margin = (
                margin_time
                * (
                    np.sqrt(dvx * dvx + dvy * dvy)
                    + abs(angular_velocity[a]) * radius[a]
                    + abs(angular_velocity[b]) * radius[b]
                )
                + margin_extra
            )
        if ca == 1 or cb == 1:  # a circle (a scene of polygons never takes this branch)
            touching, px, py, nx, ny, depth, feature = round_contact(
                vertices, normals, vertex_count, radius, a, b, margin
            )
            if touching:
                _emit(
                    rows,
                    a,
                    b,
                    feature,
                    0,
                    px,
                    py,
                    nx,
                    ny,
                    depth,
                    depth,
                    c_a,
                    c_b,
                    c_feature,
                    c_slot,
                    c_point,
                    c_normal,
                    c_depth,
                    c_pair_depth,
                )
                rows += 1
            continue
        sep_a, edge_a = max_separation(vertices, normals, a, ca, b, cb)
        if sep_a > margin:
            continue
        sep_b, edge_b = max_separation(vertices, normals, b, cb, a, ca)
        if sep_b > margin:
            continue

        # reference face: the MTD axis, with hysteresis against near-ties
        ref_side = 0
        ref_edge = edge_a
        ref_sep = sep_a
        if hysteresis:
            best = max(sep_a, sep_b)
            tol = HYSTERESIS_RELATIVE * abs(best) + HYSTERESIS_ABSOLUTE * min(radius[a], radius[b])
            if sep_b > sep_a + tol:
                ref_side = 1
                ref_edge = edge_b
                ref_sep = sep_b
            if prev >= 0:
                f = prev_feature[prev]
                side = f // 4096
                edge = (f // 64) % 64
                owner, other, other_count = (a, b, cb) if side == 0 else (b, a, ca)
                if edge < vertex_count[owner]:
                    s_prev = face_separation(vertices, normals, owner, edge, other, other_count)
                    if s_prev >= best - tol:
                        ref_side = side
                        ref_edge = edge
                        ref_sep = s_prev
        elif sep_b > sep_a:
            ref_side = 1
            ref_edge = edge_b
            ref_sep = sep_b

        if ref_side == 0:
            r = a
            cr = ca
            i = b
            ci = cb
        else:
            r = b
            cr = cb
            i = a
            ci = ca
        nx = normals[r, ref_edge, 0]
        ny = normals[r, ref_edge, 1]
        r1x = vertices[r, ref_edge, 0]
        r1y = vertices[r, ref_edge, 1]
        e2 = ref_edge + 1
        if e2 == cr:
            e2 = 0
        r2x = vertices[r, e2, 0]
        r2y = vertices[r, e2, 1]

        # incident edge: the edge of the other polygon whose normal is most opposed to n
        inc_edge = 0
        most = np.inf
        for k in range(ci):
            d = normals[i, k, 0] * nx + normals[i, k, 1] * ny
            if d < most:
                most = d
                inc_edge = k
        k2 = inc_edge + 1
        if k2 == ci:
            k2 = 0
        p1x = vertices[i, inc_edge, 0]
        p1y = vertices[i, inc_edge, 1]
        p2x = vertices[i, k2, 0]
        p2y = vertices[i, k2, 1]

        # clip the incident segment to the reference face's side planes t.p >= t.r1, t.p <= t.r2
        tx = r2x - r1x
        ty = r2y - r1y
        ok = True
        for plane in range(2):
            if plane == 0:
                sx = -tx
                sy = -ty
                off = -(tx * r1x + ty * r1y)
            else:
                sx = tx
                sy = ty
                off = tx * r2x + ty * r2y
            d1 = sx * p1x + sy * p1y - off
            d2 = sx * p2x + sy * p2y - off
            if d1 > 0.0 and d2 > 0.0:
                ok = False
                break
            if d1 > 0.0:
                w = d1 / (d1 - d2)
                p1x = p1x + w * (p2x - p1x)
                p1y = p1y + w * (p2y - p1y)
            elif d2 > 0.0:
                w = d2 / (d2 - d1)
                p2x = p2x + w * (p1x - p2x)
                p2y = p2y + w * (p1y - p2y)
        if ok:
            s1 = nx * (p1x - r1x) + ny * (p1y - r1y)
            s2 = nx * (p2x - r1x) + ny * (p2y - r1y)
        else:
            # degenerate clip (cannot happen for a true overlap; kept for robustness):
            # the deepest vertex of the incident polygon
            s1 = np.inf
            for k in range(ci):
                s = nx * (vertices[i, k, 0] - r1x) + ny * (vertices[i, k, 1] - r1y)
                if s < s1:
                    s1 = s
                    p1x = vertices[i, k, 0]
                    p1y = vertices[i, k, 1]
            p2x = p1x
            p2y = p1y
            s2 = np.inf
        keep1 = s1 <= margin
        keep2 = s2 <= margin
        if not keep1 and not keep2:
            continue

        if ref_side == 0:
            outx = nx
            outy = ny
        else:
            outx = -nx
            outy = -ny
        feature = (ref_side * 64 + ref_edge) * 64 + inc_edge
        pair_depth = -ref_sep
        if two_points:
            slot = 0
            if keep1:
                _emit(
                    rows,
                    a,
                    b,
                    feature,
                    0,
                    p1x,
                    p1y,
                    outx,
                    outy,
                    -s1,
                    pair_depth,
                    c_a,
                    c_b,
                    c_feature,
                    c_slot,
                    c_point,
                    c_normal,
                    c_depth,
                    c_pair_depth,
                )
                rows += 1
                slot = 1
            if keep2:
                _emit(
                    rows,
                    a,
                    b,
                    feature,
                    slot,
                    p2x,
                    p2y,
                    outx,
                    outy,
                    -s2,
                    pair_depth,
                    c_a,
                    c_b,
                    c_feature,
                    c_slot,
                    c_point,
                    c_normal,
                    c_depth,
                    c_pair_depth,
                )
                rows += 1
        else:
            if keep1 and keep2:
                dx = p2x - p1x
                dy = p2y - p1y
                if abs(s1 - s2) <= PARALLEL_TOLERANCE * np.sqrt(dx * dx + dy * dy):
                    px = 0.5 * (p1x + p2x)
                    py = 0.5 * (p1y + p2y)
                elif s2 < s1:
                    px = p2x
                    py = p2y
                else:
                    px = p1x
                    py = p1y
            elif keep1:
                px = p1x
                py = p1y
            else:
                px = p2x
                py = p2y
            _emit(
                rows,
                a,
                b,
                feature,
                0,
                px,
                py,
                outx,
                outy,
                pair_depth,
                pair_depth,
                c_a,
                c_b,
                c_feature,
                c_slot,
                c_point,
                c_normal,
                c_depth,
                c_pair_depth,
            )
            rows += 1
    return rows


@numba.njit(cache=True, nogil=True, _nrt=False)  # (no reference counts: see driver)
def match_previous(
    rows, c_a, c_b, c_feature, c_slot, n, prev_key, prev_feature, prev_slot, c_previous
):
    """For each row, the previous step's row with the same pair, feature and slot (the same
    contact point, whose impulse warm-starts this one), or -1.

    Both row lists are sorted by pair key a * n + b, so one forward walk matches them. (Done
    here rather than inside collide_pairs: reading the previous rows there made the whole
    narrow-phase loop 40 % slower.)
    """
    n_prev = prev_key.shape[0]
    q = 0
    for k in range(rows):
        key = c_a[k] * n + c_b[k]
        while q < n_prev and prev_key[q] < key:
            q += 1
        found = -1
        p = q
        while p < n_prev and prev_key[p] == key:
            if prev_feature[p] == c_feature[k] and prev_slot[p] == c_slot[k]:
                found = p
                break
            p += 1
        c_previous[k] = found
