"""The prismatic joint (a slider): b moves along an axis u fixed in a, the relative rotation
locked; a motor and translation limits along u.

Formulas: Box2D 2.3's b2PrismaticJoint (b2_prismatic_joint.cpp; Catto, "Modeling and Solving
Constraints", GDC 2009): with d the anchors' separation b - a, the arms along u are
a1 = (d + r_a) x u (a's: from its centre to b's anchor) and a2 = r_b x u, along the normal
p = perp(u) s1 = (d + r_a) x p and s2 = r_b x p. The normal and the rotation are solved
together, their 2x2 effective mass
K = [[1/m_a + 1/m_b + s1^2 / I_a + s2^2 / I_b, s1 / I_a + s2 / I_b], [., 1/I_a + 1/I_b]]
inverted once (`_normal_mass`); the motor and the one-sided limits along u use the axial mass
1 / (1/m_a + 1/m_b + a1^2 / I_a + a2^2 / I_b) (KAX). Position
(b2PrismaticJoint::SolvePositionConstraints, without its 3x3 limit block): the normal and the
rotation by K (capped at MAX_LINEAR_CORRECTION and MAX_ANGULAR_CORRECTION), then the limit it
is past.
Scratch columns: the arms, UX / UY the axis and PX / PY its normal (world), A1, A2, S1, S2, KAX,
K11 .. K22 the inverse of K, CL / CU the limits' margins; impulses J0 (normal), J1 (rotation),
JM (motor), JL / JU (limits).
"""

from __future__ import annotations

import numba

from isaac.engine import kernel_cache  # noqa: F401  (first: keys the kernels' numba cache)
from isaac.engine.geometry import sin_cos
from isaac.engine.joints.shared import (
    A1,
    A2,
    CL,
    CU,
    J0,
    J1,
    JL,
    JM,
    JU,
    K11,
    K12,
    K22,
    KAX,
    MAX_ANGULAR_CORRECTION,
    MAX_LINEAR_CORRECTION,
    PX,
    PY,
    S1,
    S2,
    UX,
    UY,
    apply,
    apply_along,
    axial_mass,
    clamp,
    inverse_2x2,
    motor,
    move,
    move_along,
    one_sided,
    separation,
    turned,
    wrap,
)


@numba.njit(cache=True, nogil=True, inline="always")
def _crosses(dx, dy, rax, ray, rbx, rby, ux, uy):
    """(d + r_a) x u and r_b x u (m) of the separation d = (dx, dy) and the arms."""
    return (dx + rax) * uy - (dy + ray) * ux, rbx * uy - rby * ux


@numba.njit(cache=True, nogil=True, inline="always")
def _normal_mass(ma, ia, mb, ib, s1, s2):
    """The inverse of K (the module docstring)."""
    k22 = ia + ib
    if k22 == 0.0:
        k22 = 1.0  # two bodies that cannot turn: the rotation row is idle
    return inverse_2x2(ma + mb + ia * s1 * s1 + ib * s2 * s2, ia * s1 + ib * s2, k22)


@numba.njit(cache=True, nogil=True, inline="always")
def prepare_prismatic(J, k, t, dx, dy, sa, ca, masses, arms):
    """Joint k's scratch row t: its axis (a's frame) turned by a's (sin, cos) (sa, ca), its
    anchors' separation (dx, dy) (m, world), its bodies' inverse masses and inertias and its
    arms (as `prepare_revolute`)."""
    ma, ia, mb, ib = masses
    rax, ray, rbx, rby = arms
    ux, uy = turned(J.axis[k, 0], J.axis[k, 1], sa, ca)
    px = -uy
    py = ux
    t[UX] = ux
    t[UY] = uy
    t[PX] = px
    t[PY] = py
    a1, a2 = _crosses(dx, dy, rax, ray, rbx, rby, ux, uy)
    s1, s2 = _crosses(dx, dy, rax, ray, rbx, rby, px, py)
    t[A1] = a1
    t[A2] = a2
    t[S1] = s1
    t[S2] = s2
    t[KAX] = axial_mass(ma, ia, mb, ib, a1, a2)
    t[K11], t[K12], t[K22] = _normal_mass(ma, ia, mb, ib, s1, s2)
    translation = ux * dx + uy * dy
    t[CL] = translation - J.lower[k]
    t[CU] = J.upper[k] - translation


@numba.njit(cache=True, nogil=True, inline="always")
def _along(ux, uy, a1, a2, v, a, b):
    """The relative velocity (m/s) along the unit vector (ux, uy) of arms a1, a2 (b's less
    a's)."""
    return ux * (v[b, 0] - v[a, 0]) + uy * (v[b, 1] - v[a, 1]) + a2 * v[b, 2] - a1 * v[a, 2]


@numba.njit(cache=True, nogil=True, inline="always")
def solve_prismatic(J, k, t, v, inv, a, b, h, inv_h):
    """One velocity pass of prismatic joint k: the motor and the limits along the axis, then
    the normal and the rotation together."""
    ux = t[UX]
    uy = t[UY]
    a1 = t[A1]
    a2 = t[A2]
    if J.has_motor[k]:
        cdot = _along(ux, uy, a1, a2, v, a, b)
        d = motor(t, t[KAX], cdot - J.motor_speed[k], J.max_motor[k], h)
        apply_along(v, inv, a, b, d, ux, uy, a1, a2)
    if J.has_limit[k]:
        d = one_sided(t, JL, _along(ux, uy, a1, a2, v, a, b), t[CL], inv_h, t[KAX])
        apply_along(v, inv, a, b, d, ux, uy, a1, a2)
        d = -one_sided(t, JU, -_along(ux, uy, a1, a2, v, a, b), t[CU], inv_h, t[KAX])
        apply_along(v, inv, a, b, d, ux, uy, a1, a2)
    px = t[PX]
    py = t[PY]
    s1 = t[S1]
    s2 = t[S2]
    c1 = _along(px, py, s1, s2, v, a, b)  # along the normal
    c2 = v[b, 2] - v[a, 2]
    i1 = -(t[K11] * c1 + t[K12] * c2)
    i2 = -(t[K12] * c1 + t[K22] * c2)
    t[J0] += i1
    t[J1] += i2
    apply(v, inv, a, b, i1 * px, i1 * py, i1 * s1 + i2, i1 * s2 + i2)


@numba.njit(cache=True, nogil=True, inline="always")
def warm_start_prismatic(t, v, inv, a, b):
    """The loaded impulses applied: normal J0 and rotation J1, axial JM + JL - JU."""
    j0 = t[J0]
    j1 = t[J1]
    axial = t[JM] + t[JL] - t[JU]
    apply(
        v, inv, a, b,
        j0 * t[PX] + axial * t[UX],
        j0 * t[PY] + axial * t[UY],
        j0 * t[S1] + j1 + axial * t[A1],
        j0 * t[S2] + j1 + axial * t[A2],
    )  # fmt: skip


@numba.njit(cache=True, nogil=True, inline="always")
def correct_prismatic(J, k, a, b, position, angle, inv_mass, inv_inertia):
    """Position pass of prismatic joint k: the normal and the rotation, then the limit."""
    ma = inv_mass[a]
    ia = inv_inertia[a]
    mb = inv_mass[b]
    ib = inv_inertia[b]
    rax, ray, rbx, rby, dx, dy = separation(J, k, a, b, position, angle)
    s, co = sin_cos(angle[a])
    ux, uy = turned(J.axis[k, 0], J.axis[k, 1], s, co)
    px = -uy
    py = ux
    s1, s2 = _crosses(dx, dy, rax, ray, rbx, rby, px, py)
    c1 = clamp(px * dx + py * dy, MAX_LINEAR_CORRECTION)
    c2 = clamp(wrap(angle[b] - angle[a] - J.reference_angle[k]), MAX_ANGULAR_CORRECTION)
    k11, k12, k22 = _normal_mass(ma, ia, mb, ib, s1, s2)
    i1 = -(k11 * c1 + k12 * c2)
    i2 = -(k12 * c1 + k22 * c2)
    move(
        position, angle, inv_mass, inv_inertia, a, b, i1 * px, i1 * py,
        i1 * s1 + i2, i1 * s2 + i2,
    )  # fmt: skip
    if J.has_limit[k]:
        rax, ray, rbx, rby, dx, dy = separation(J, k, a, b, position, angle)
        translation = ux * dx + uy * dy
        c = 0.0
        if translation < J.lower[k]:
            c = translation - J.lower[k]
        elif translation > J.upper[k]:
            c = translation - J.upper[k]
        if c != 0.0:
            a1, a2 = _crosses(dx, dy, rax, ray, rbx, rby, ux, uy)
            move_along(c, ux, uy, a1, a2, a, b, position, angle, inv_mass, inv_inertia)


@numba.njit(cache=True, nogil=True, inline="always")
def prismatic_error(J, k, dx, dy, q, sa, ca):
    """Prismatic joint k's remaining error: its anchors' separation (dx, dy) off the axis (m)
    (turned by a's (sin, cos) (sa, ca)) and its rotation q off the reference (rad)."""
    ux, uy = turned(J.axis[k, 0], J.axis[k, 1], sa, ca)
    return abs(-uy * dx + ux * dy), q


@numba.njit(cache=True, nogil=True, inline="always")
def prismatic_reaction(t):
    """A prismatic joint's reported impulses: linear J0 p (N s), angular J1 (N m s)."""
    return t[J0] * t[PX], t[J0] * t[PY], t[J1]
