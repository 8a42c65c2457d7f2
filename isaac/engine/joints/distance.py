"""The distance joint: along the unit axis u between the two anchors, a rigid rod (the length
unchanged over the sub-step, as the revolute's separation), a spring, and one-sided limits
min_length / max_length (a rope, a strut).

Formulas: Box2D 2.3's b2DistanceJoint (b2_distance_joint.cpp) and b2RopeJoint for the limits:
the axial effective mass 1 / (1/m_a + 1/m_b + (r_a x u)^2 / I_a + (r_b x u)^2 / I_b) (KAX); a
spring of frequency f and damping ratio z is Catto's soft constraint ("Soft Constraints", GDC
2011; `isaac.engine.joints.shared.soften`) on the stretch d - length. A rigid rod aims at the
length the sub-step ends with (`end_separation`), a Newton step about the end arms and axis
when a body turns by more than SLOW_TURN. Position (b2DistanceJoint::SolvePositionConstraints):
the length (rigid) or the limit it is past, capped at MAX_LINEAR_CORRECTION; springs are not
corrected.
Scratch columns: the arms, UX / UY the axis a -> b, KAX, CL / CU the limits' margins, a
spring's BIAS / MS / IS, DX / DY the separation; impulses J2 (rod or spring), JL / JU (limits).
"""

from __future__ import annotations

import numba
import numpy as np

from isaac.engine import kernel_cache  # noqa: F401  (first: keys the kernels' numba cache)
from isaac.engine.joints.shared import (
    CL,
    CU,
    DX,
    DY,
    J2,
    JL,
    JU,
    KAX,
    RAX,
    RAY,
    RBX,
    RBY,
    UX,
    UY,
    apply_along,
    axial_mass,
    end_arms,
    end_separation,
    move_along,
    one_sided,
    separation,
    slow_turns,
    soft_impulse,
    soften,
)


@numba.njit(cache=True, nogil=True, inline="always")
def prepare_distance(J, k, t, h, dx, dy, masses, arms):
    """Joint k's scratch row t from its anchors' separation (dx, dy) (m, world), its bodies'
    inverse masses and inertias and its arms (as `prepare_revolute`), h the sub-step (s)."""
    ma, ia, mb, ib = masses
    rax, ray, rbx, rby = arms
    d = np.sqrt(dx * dx + dy * dy)
    ux = 1.0
    uy = 0.0
    if d > 0.0:
        ux = dx / d
        uy = dy / d
    t[UX] = ux
    t[UY] = uy
    t[KAX] = axial_mass(ma, ia, mb, ib, rax * uy - ray * ux, rbx * uy - rby * ux)
    t[CL] = d - J.lower[k]
    t[CU] = J.upper[k] - d
    if J.spring[k]:
        soften(t, J.stiffness[k], J.damping_ratio[k], h, d - J.length[k])


@numba.njit(cache=True, nogil=True, inline="always")
def _along(ux, uy, rax, ray, rbx, rby, v, a, b):
    """The relative velocity (m/s) of the anchors along u (b's less a's)."""
    return ux * (v[b, 0] - v[b, 2] * rby - v[a, 0] + v[a, 2] * ray) + uy * (
        v[b, 1] + v[b, 2] * rbx - v[a, 1] - v[a, 2] * rax
    )


@numba.njit(cache=True, nogil=True, inline="always")
def solve_distance(J, k, t, v, inv, a, b, h, inv_h):
    """One velocity pass of distance joint k: the spring or the rod, then the limits."""
    rax = t[RAX]
    ray = t[RAY]
    rbx = t[RBX]
    rby = t[RBY]
    ux = t[UX]
    uy = t[UY]
    cra = rax * uy - ray * ux
    crb = rbx * uy - rby * ux
    if J.spring[k]:
        d = soft_impulse(t, t[KAX], _along(ux, uy, rax, ray, rbx, rby, v, a, b))
        t[J2] += d
        apply_along(v, inv, a, b, d, ux, uy, cra, crb)
    elif J.rigid[k] and slow_turns(v, a, b, h):
        # the length at the end of the sub-step, at the velocities so far
        ex, ey = end_separation(rax, ray, rbx, rby, v, a, b, h)
        ex += t[DX]
        ey += t[DY]
        now = np.sqrt(t[DX] * t[DX] + t[DY] * t[DY])
        d = -t[KAX] * (np.sqrt(ex * ex + ey * ey) - now) * inv_h
        t[J2] += d
        apply_along(v, inv, a, b, d, ux, uy, cra, crb)
    elif J.rigid[k]:
        # a Newton step about the arms and axis the sub-step ends with
        pax, pay, pbx, pby, ex, ey = end_arms(rax, ray, rbx, rby, v, a, b, h)
        ex += t[DX]
        ey += t[DY]
        end = np.sqrt(ex * ex + ey * ey)
        pux = ux
        puy = uy
        if end > 0.0:
            pux = ex / end
            puy = ey / end
        pcra = pax * puy - pay * pux
        pcrb = pbx * puy - pby * pux
        mass = axial_mass(inv[a, 0], inv[a, 1], inv[b, 0], inv[b, 1], pcra, pcrb)
        now = np.sqrt(t[DX] * t[DX] + t[DY] * t[DY])
        d = -mass * (end - now) * inv_h
        t[J2] += d
        apply_along(v, inv, a, b, d, pux, puy, pcra, pcrb)
    if J.has_limit[k]:
        cdot = _along(ux, uy, rax, ray, rbx, rby, v, a, b)
        d = one_sided(t, JL, cdot, t[CL], inv_h, t[KAX])
        apply_along(v, inv, a, b, d, ux, uy, cra, crb)
        cdot = _along(ux, uy, rax, ray, rbx, rby, v, a, b)
        d = -one_sided(t, JU, -cdot, t[CU], inv_h, t[KAX])
        apply_along(v, inv, a, b, d, ux, uy, cra, crb)


@numba.njit(cache=True, nogil=True, inline="always")
def warm_start_distance(t, v, inv, a, b):
    """The loaded axial impulses (J2 + JL - JU) applied along the axis."""
    axial = t[J2] + t[JL] - t[JU]
    ux = t[UX]
    uy = t[UY]
    apply_along(v, inv, a, b, axial, ux, uy, t[RAX] * uy - t[RAY] * ux, t[RBX] * uy - t[RBY] * ux)


@numba.njit(cache=True, nogil=True, inline="always")
def correct_distance(J, k, a, b, position, angle, inv_mass, inv_inertia):
    """Position pass of distance joint k: a rod's length, or the limit it is past."""
    rax, ray, rbx, rby, dx, dy = separation(J, k, a, b, position, angle)
    d = np.sqrt(dx * dx + dy * dy)
    if d == 0.0:
        return
    c = 0.0
    if J.rigid[k]:
        c = d - J.length[k]
    elif d < J.lower[k]:
        c = d - J.lower[k]
    elif d > J.upper[k]:
        c = d - J.upper[k]
    if c == 0.0:
        return
    ux = dx / d
    uy = dy / d
    cra = rax * uy - ray * ux
    crb = rbx * uy - rby * ux
    move_along(c, ux, uy, cra, crb, a, b, position, angle, inv_mass, inv_inertia)


@numba.njit(cache=True, nogil=True, inline="always")
def distance_error(J, k, dx, dy):
    """Distance joint k's remaining error (m): off its length (rod) or past a limit, for its
    anchors' separation (dx, dy)."""
    d = np.sqrt(dx * dx + dy * dy)
    if J.rigid[k]:
        return abs(d - J.length[k]), 0.0
    if d < J.lower[k]:
        return J.lower[k] - d, 0.0
    if d > J.upper[k]:
        return d - J.upper[k], 0.0
    return 0.0, 0.0


@numba.njit(cache=True, nogil=True, inline="always")
def distance_reaction(t):
    """A distance joint's reported linear impulse J2 u (N s) and no angular one."""
    return t[J2] * t[UX], t[J2] * t[UY], 0.0
