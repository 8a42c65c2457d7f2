"""The weld joint: the revolute's point constraint and the relative rotation locked
(w_b - w_a = 0), rigid or an angular spring.

Formulas: Box2D 2.3's b2WeldJoint (b2_weld_joint.cpp): the point as the revolute's
(`isaac.engine.joints.revolute.solve_point`), the rotation by its angular effective mass
1 / (1/I_a + 1/I_b) (KA); a soft weld's rotation is Catto's soft constraint ("Soft
Constraints", GDC 2011; `isaac.engine.joints.shared.soften`) on the stretch
q = wrap(angle_b - angle_a - reference). Position (b2WeldJoint::SolvePositionConstraints, rigid
only; a spring's stretch is its torque): the rotation (capped at MAX_ANGULAR_CORRECTION), then
the anchors.
Scratch columns: the revolute's arms and point mass, KA, a spring's BIAS / MS / IS; impulses
J0, J1 (point), J2 (rotation).
"""

from __future__ import annotations

import numba
import numpy as np

from isaac.engine import kernel_cache  # noqa: F401  (first: keys the kernels' numba cache)
from isaac.engine.joints.revolute import correct_point, point_mass, solve_point
from isaac.engine.joints.shared import J2, K11, K12, K22, KA, apply, soft_impulse, soften, wrap


@numba.njit(cache=True, nogil=True, inline="always")
def prepare_weld(J, k, t, h, q, masses, arms):
    """Joint k's scratch row t from its angle q off the reference (rad), its bodies' inverse
    masses and inertias and its arms (as `prepare_revolute`), h the sub-step (s)."""
    ma, ia, mb, ib = masses
    rax, ray, rbx, rby = arms
    t[K11], t[K12], t[K22] = point_mass(ma, ia, mb, ib, rax, ray, rbx, rby)
    if J.spring[k]:
        soften(t, J.stiffness[k], J.damping_ratio[k], h, q)


@numba.njit(cache=True, nogil=True, inline="always")
def solve_weld(J, k, t, v, inv, a, b, h, inv_h):
    """One velocity pass of weld joint k: the rotation (rigid or soft), then the point."""
    cdot = v[b, 2] - v[a, 2]
    if J.spring[k]:
        d = soft_impulse(t, t[KA], cdot)
    else:
        d = -t[KA] * cdot
    t[J2] += d
    apply(v, inv, a, b, 0.0, 0.0, d, d)
    solve_point(t, v, inv, a, b, h, inv_h)


@numba.njit(cache=True, nogil=True, inline="always")
def correct_weld(J, k, a, b, position, angle, inv_mass, inv_inertia):
    """Position pass of weld joint k: a rigid weld's rotation, then the anchors."""
    c = 0.0
    if J.rigid[k]:
        c = wrap(angle[b] - angle[a] - J.reference_angle[k])
    correct_point(c, J, k, a, b, position, angle, inv_mass, inv_inertia)


@numba.njit(cache=True, nogil=True, inline="always")
def weld_error(J, k, dx, dy, q):
    """Weld joint k's remaining error: the anchors' distance (m) for their separation
    (dx, dy) and, rigid, its rotation q off the reference (rad)."""
    return np.sqrt(dx * dx + dy * dy), 0.0 if J.spring[k] else q
