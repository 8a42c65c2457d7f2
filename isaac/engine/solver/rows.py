"""What both solvers compute per contact row: lever arms, effective masses, the target normal
velocity and restitution (`row_terms`), and the bounce-back of speculative rows that bounce."""

from __future__ import annotations

import numba

from isaac.engine import kernel_cache  # noqa: F401  (first: keys the kernels' numba cache)
from isaac.engine.solver.mixing import combine

# (row_terms takes scalars only: an inlined helper that takes arrays costs an atomic reference
# count update per array and call, several times the arithmetic here.)


@numba.njit(cache=True, nogil=True, inline="always")
def row_terms(
    nx,
    ny,
    px,
    py,
    xa,
    ya,
    xb,
    yb,
    ima,
    iia,
    imb,
    iib,
    vax,
    vay,
    wa,
    vbx,
    vby,
    wb,
    depth,
    restitution_a,
    restitution_b,
    gdx,
    gdy,
    restitution_rule,
    restitution_threshold,
    h,
):
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


@numba.njit(cache=True, nogil=True, _nrt=False)
def apply_bounce_back(
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
):
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
