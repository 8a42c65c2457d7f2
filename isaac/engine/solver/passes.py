"""The sequential solver's Gauss-Seidel passes over the group table: single points, and two-point
manifolds as 2x2 blocks."""

from __future__ import annotations

import numba

from isaac.engine import kernel_cache  # noqa: F401  (first: keys the kernels' numba cache)
from isaac.engine.solver.schedule import (
    G12,
    GM11,
    GM12,
    GM22,
    GROUP_WIDTH,
    IIA,
    IIB,
    IMA,
    IMB,
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
    U_2LANES,
    U_LANES,
    UNIT_BLOCK,
    VAX,
    VAY,
    VBX,
    VBY,
    WA,
    WB,
)


@numba.njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def run_passes(t, kind, successor, groups, iterations):
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
