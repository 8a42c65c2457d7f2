"""The revolute joint: the two anchors held together (a pin), a motor and angle limits; and its
point constraint, which the weld shares.

Formulas: Box2D 2.3's b2RevoluteJoint (b2_revolute_joint.cpp; Catto, "Modeling and Solving
Constraints", GDC 2009, for the point constraint's Jacobian and 2x2 effective mass):
- point: the anchors' separation unchanged over the sub-step (`end_separation`: each arm turned
  by h w; to first order the relative velocity v_b + w_b x r_b - v_a - w_a x r_a = 0), by
  the inverse (`point_mass`) of the 2x2 effective mass, with M = 1/m_a + 1/m_b,
  K = [[M + r_ay^2 / I_a + r_by^2 / I_b, -r_ax r_ay / I_a - r_bx r_by / I_b],
       [., M + r_ax^2 / I_a + r_bx^2 / I_b]];
  when a body turns by more than SLOW_TURN a Newton step about the arms the sub-step ends
  with (`end_arms`);
- motor: w_b - w_a = speed, |impulse| <= max_torque h (`isaac.engine.joints.shared.motor`);
- limits: on q = wrap(angle_b - angle_a - reference) as one-sided constraints (impulse >= 0)
  that let a limit still open by C close within the sub-step (C / h, as speculative contacts
  do);
- position (b2RevoluteJoint::SolvePositionConstraints): the limit it is past (capped at
  MAX_ANGULAR_CORRECTION), then the anchors together by the 2x2 mass (the separation capped at
  MAX_LINEAR_CORRECTION).
Scratch columns: arms RAX .. RBY, K11 .. K22 the inverse point mass, KA the angular one, CL / CU
the limits' margins, impulses J0, J1 (point), JM (motor), JL / JU (limits).
"""

from __future__ import annotations

import numba
import numpy as np

from isaac.engine import kernel_cache  # noqa: F401  (first: keys the kernels' numba cache)
from isaac.engine.joints.shared import (
    CL,
    CU,
    J0,
    J1,
    J2,
    JL,
    JM,
    JU,
    K11,
    K12,
    K22,
    KA,
    MAX_ANGULAR_CORRECTION,
    MAX_LINEAR_CORRECTION,
    RAX,
    RAY,
    RBX,
    RBY,
    apply,
    clamp,
    end_arms,
    end_separation,
    inverse_2x2,
    motor,
    move,
    one_sided,
    separation,
    slow_turns,
    wrap,
)


@numba.njit(cache=True, nogil=True, inline="always")
def point_mass(ma, ia, mb, ib, rax, ray, rbx, rby):
    """Inverse of the 2x2 effective mass of a point-to-point constraint."""
    k11 = ma + mb + ia * ray * ray + ib * rby * rby
    k12 = -ia * rax * ray - ib * rbx * rby
    k22 = ma + mb + ia * rax * rax + ib * rbx * rbx
    return inverse_2x2(k11, k12, k22)


@numba.njit(cache=True, nogil=True, inline="always")
def prepare_revolute(J, k, t, q, masses, arms):
    """Joint k's scratch row t from its angle q off the reference (rad), its bodies' inverse
    masses and inertias (1/m_a, 1/I_a, 1/m_b, 1/I_b) and its arms (r_a, r_b) (m, world)."""
    ma, ia, mb, ib = masses
    rax, ray, rbx, rby = arms
    t[K11], t[K12], t[K22] = point_mass(ma, ia, mb, ib, rax, ray, rbx, rby)
    t[CL] = q - J.lower[k]
    t[CU] = J.upper[k] - q


@numba.njit(cache=True, nogil=True, inline="always")
def solve_point(t, v, inv, a, b, h, inv_h):
    """The point constraint's impulse (J0, J1): the anchors' separation at the end of the
    sub-step, at the velocities so far, back to what it is."""
    rax = t[RAX]
    ray = t[RAY]
    rbx = t[RBX]
    rby = t[RBY]
    if slow_turns(v, a, b, h):
        ex, ey = end_separation(rax, ray, rbx, rby, v, a, b, h)
        k11 = t[K11]
        k12 = t[K12]
        k22 = t[K22]
    else:  # a Newton step about the arms the sub-step ends with (`end_arms`)
        rax, ray, rbx, rby, ex, ey = end_arms(rax, ray, rbx, rby, v, a, b, h)
        k11, k12, k22 = point_mass(inv[a, 0], inv[a, 1], inv[b, 0], inv[b, 1], rax, ray, rbx, rby)
    ix = -(k11 * ex + k12 * ey) * inv_h
    iy = -(k12 * ex + k22 * ey) * inv_h
    t[J0] += ix
    t[J1] += iy
    apply(v, inv, a, b, ix, iy, rax * iy - ray * ix, rbx * iy - rby * ix)


@numba.njit(cache=True, nogil=True, inline="always")
def solve_revolute(J, k, t, v, inv, a, b, h, inv_h):
    """One velocity pass of revolute joint k: the motor, the limits, then the point."""
    if J.has_motor[k]:
        d = motor(t, t[KA], v[b, 2] - v[a, 2] - J.motor_speed[k], J.max_motor[k], h)
        apply(v, inv, a, b, 0.0, 0.0, d, d)
    if J.has_limit[k]:
        d = one_sided(t, JL, v[b, 2] - v[a, 2], t[CL], inv_h, t[KA])
        apply(v, inv, a, b, 0.0, 0.0, d, d)
        d = one_sided(t, JU, v[a, 2] - v[b, 2], t[CU], inv_h, t[KA])
        apply(v, inv, a, b, 0.0, 0.0, -d, -d)
    solve_point(t, v, inv, a, b, h, inv_h)


@numba.njit(cache=True, nogil=True, inline="always")
def warm_start_point(t, v, inv, a, b):
    """The loaded impulses of a revolute or weld joint applied: the point's (J0, J1) at the
    arms, the rotation's (JM + JL - JU + J2) about them."""
    j0 = t[J0]
    j1 = t[J1]
    ang = t[JM] + t[JL] - t[JU] + t[J2]
    rax = t[RAX]
    ray = t[RAY]
    rbx = t[RBX]
    rby = t[RBY]
    apply(v, inv, a, b, j0, j1, rax * j1 - ray * j0 + ang, rbx * j1 - rby * j0 + ang)


@numba.njit(cache=True, nogil=True, inline="always")
def correct_point(c, J, k, a, b, position, angle, inv_mass, inv_inertia):
    """Position pass of revolute or weld joint k: its rotation error c (rad) first (capped),
    then its anchors together."""
    ma = inv_mass[a]
    ia = inv_inertia[a]
    mb = inv_mass[b]
    ib = inv_inertia[b]
    if c != 0.0 and ia + ib > 0.0:
        lam = -clamp(c, MAX_ANGULAR_CORRECTION) / (ia + ib)
        move(position, angle, inv_mass, inv_inertia, a, b, 0.0, 0.0, lam, lam)
    rax, ray, rbx, rby, dx, dy = separation(J, k, a, b, position, angle)
    length = np.sqrt(dx * dx + dy * dy)
    if length > MAX_LINEAR_CORRECTION:  # capped, along the same direction
        scale = MAX_LINEAR_CORRECTION / length
        dx *= scale
        dy *= scale
    k11, k12, k22 = point_mass(ma, ia, mb, ib, rax, ray, rbx, rby)
    px = -(k11 * dx + k12 * dy)
    py = -(k12 * dx + k22 * dy)
    move(
        position, angle, inv_mass, inv_inertia, a, b, px, py,
        rax * py - ray * px, rbx * py - rby * px,
    )  # fmt: skip


@numba.njit(cache=True, nogil=True, inline="always")
def correct_revolute(J, k, a, b, position, angle, inv_mass, inv_inertia):
    """Position pass of revolute joint k: the angle limit it is past, then the anchors."""
    c = 0.0
    if J.has_limit[k]:
        q = wrap(angle[b] - angle[a] - J.reference_angle[k])
        if q < J.lower[k]:
            c = q - J.lower[k]
        elif q > J.upper[k]:
            c = q - J.upper[k]
    correct_point(c, J, k, a, b, position, angle, inv_mass, inv_inertia)


@numba.njit(cache=True, nogil=True, inline="always")
def point_error(dx, dy):
    """A revolute joint's remaining error: the anchors' distance (m) for the separation
    (dx, dy) b - a, and no rotation error (it leaves the rotation free)."""
    return np.sqrt(dx * dx + dy * dy), 0.0


@numba.njit(cache=True, nogil=True, inline="always")
def point_reaction(t):
    """A revolute or weld joint's reported impulses: linear (J0, J1) (N s), angular J2."""
    return t[J0], t[J1], t[J2]
