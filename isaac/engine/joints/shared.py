"""What the joint kinds share: the scratch row's columns, the caps and thresholds, and the
arithmetic more than one kind does (arms, effective masses, an impulse applied to two bodies, a
position move, one-sided limits, a motor, Catto's soft constraint, the end-of-sub-step
separation of two anchors).

The impulse convention (Box2D 2.3's joints, b2_joint.h): an impulse P is applied as -P to a and
+P to b at the anchors, so a constraint's velocity error cdot is b's velocity less a's.

The soft constraint (Catto, "Soft Constraints", GDC 2011; Box2D 2.3's b2DistanceJoint::
InitVelocityConstraints with frequency f (Hz) and damping ratio z): omega = 2 pi f,
a1 = 2 z + h omega, a2 = h omega a1, bias velocity omega / a1 C (C the stretch), mass scale
a2 / (1 + a2), impulse scale 1 / (1 + a2); the impulse is
-mass_scale m (cdot + bias) - impulse_scale (the impulse accumulated so far).

Speed: the helpers take scalars (or the kernels' own array arguments), never the joint table
or one of its arrays: each such argument cost a reference count update, 0.4-0.9 us a joint on
the 100 x 100 joint grid (bench/joint_grid.py), more than the physics. They are inlined into
the per-joint loops of `isaac.engine.joints.joint`, which are compiled without reference
counting at all (numba's `_nrt=False`, as isaac.engine.driver's stage kernels, NO_COUNTS
there): with counting, each row view (jt[k]) and each read of the table's arrays still cost
atomic count updates, most of a loop's time (bench/README.md).
"""

from __future__ import annotations

import numba
import numpy as np

from isaac.engine import kernel_cache  # noqa: F401  (first: keys the kernels' numba cache)
from isaac.engine.geometry import sin_cos
from isaac.engine.integrate import PI, TWO_PI

# Box2D 2.3's caps on one position correction (b2_maxLinearCorrection, b2_maxAngularCorrection)
MAX_LINEAR_CORRECTION = 0.2  # m
MAX_ANGULAR_CORRECTION = 8.0 / 180.0 * np.pi  # rad
# a body turning faster than this in a sub-step (rad) gets the joints' Newton step
# (`slow_turns`); below it the bits are those of physics version 2
SLOW_TURN = 0.05

# scratch columns: what a revolute joint's velocity pass reads first (arms, effective mass, on,
# impulses: the first two 64-byte lines of its row), the rest after; J0 .. JU stay adjacent
RAX, RAY, RBX, RBY = 0, 1, 2, 3  # world anchor arms (m)
K11, K12, K22 = 4, 5, 6  # inverse of the 2x2 effective mass (point, or prismatic normal+angle)
ON = 7  # 1.0 when both bodies exist
J0, J1, J2, JM, JL, JU = 8, 9, 10, 11, 12, 13  # accumulated impulses
KA = 14  # 1 / angular effective mass (motor, limits, weld)
CL, CU = 15, 16  # how far inside the lower / upper limit (m or rad; < 0: beyond it)
UX, UY = 17, 18  # distance: unit axis a -> b; prismatic: the slide axis (world)
PX, PY = 19, 20  # prismatic: the axis's normal
KAX = 21  # 1 / effective mass along the axis (distance, prismatic)
BIAS, MS, IS = 22, 23, 24  # a spring's bias velocity and soft mass / impulse scales
A1, A2, S1, S2 = 25, 26, 27, 28  # prismatic: (d + r_a) x u, r_b x u, (d + r_a) x p, r_b x p
DX, DY = 29, 30  # the anchors' separation b - a (m, world) after the push-out
WIDTH = 32  # (one spare column: a row is four whole 64-byte lines)
JOINT_IMPULSES = 6  # J0 .. JU: point x / normal, point y / rotation, axial / angular, motor,
# lower limit, upper limit (N s, or N m s for rotations)


@numba.njit(cache=True, nogil=True, inline="always")
def wrap(angle):
    """Into [-pi, pi] by whole turns (isaac.engine.world.wrap_angle's rule); a non-finite
    angle is left as it is (the divergence check stops the run)."""
    if not abs(angle) < 1e9:  # diverged (or not finite): the step's divergence check stops it
        return angle
    if abs(angle) > 4.0 * PI:  # far out (a whipping chain's tip): whole turns at once
        angle -= TWO_PI * np.floor((angle + PI) / TWO_PI)
    while angle > PI:
        angle -= TWO_PI
    while angle < -PI:
        angle += TWO_PI
    return angle


@numba.njit(cache=True, nogil=True, inline="always")
def turned(lx, ly, s, c):
    """(lx, ly) turned by the angle whose (sin, cos) are (s, c)."""
    return c * lx - s * ly, s * lx + c * ly


@numba.njit(cache=True, nogil=True, inline="always")
def separation(J, k, a, b, position, angle):
    """The arms (m, world) of joint k's anchors on its bodies a and b (the table J's local_a,
    local_b) at their poses, and the anchors' separation b - a (m, world)."""
    s, c = sin_cos(angle[a])
    rax, ray = turned(J.local_a[k, 0], J.local_a[k, 1], s, c)
    s, c = sin_cos(angle[b])
    rbx, rby = turned(J.local_b[k, 0], J.local_b[k, 1], s, c)
    dx = position[b, 0] + rbx - position[a, 0] - rax
    dy = position[b, 1] + rby - position[a, 1] - ray
    return rax, ray, rbx, rby, dx, dy


@numba.njit(cache=True, nogil=True, inline="always")
def inverse_2x2(k11, k12, k22):
    """The inverse of the symmetric 2x2 matrix [[k11, k12], [k12, k22]] (zeros if singular)."""
    det = k11 * k22 - k12 * k12
    if det != 0.0:
        det = 1.0 / det
    return det * k22, -det * k12, det * k11


@numba.njit(cache=True, nogil=True, inline="always")
def inv_or_zero(k):
    return 1.0 / k if k > 0.0 else 0.0


@numba.njit(cache=True, nogil=True, inline="always")
def axial_mass(ma, ia, mb, ib, ca, cb):
    """1 / effective mass (kg) along a unit axis u whose arms' cross products with u are ca, cb
    (m): 1 / (1/m_a + 1/m_b + (ca)^2 / I_a + (cb)^2 / I_b), 0 when nothing can move."""
    return inv_or_zero(ma + mb + ia * ca * ca + ib * cb * cb)


@numba.njit(cache=True, nogil=True, inline="always")
def clamp(x, most):
    return min(max(x, -most), most)


@numba.njit(cache=True, nogil=True, inline="always")
def apply(v, inv, a, b, px, py, la, lb):
    """-P (and angular -la) to a, +P (and +lb) to b: velocities v (n, 3), inverse mass and
    inertia inv (n, 2)."""
    v[a, 0] -= px * inv[a, 0]
    v[a, 1] -= py * inv[a, 0]
    v[a, 2] -= la * inv[a, 1]
    v[b, 0] += px * inv[b, 0]
    v[b, 1] += py * inv[b, 0]
    v[b, 2] += lb * inv[b, 1]


@numba.njit(cache=True, nogil=True, inline="always")
def apply_along(v, inv, a, b, d, ux, uy, ca, cb):
    """An impulse d (N s) along the unit axis (ux, uy), its arms' cross products ca, cb."""
    apply(v, inv, a, b, d * ux, d * uy, d * ca, d * cb)


@numba.njit(cache=True, nogil=True, inline="always")
def move(position, angle, inv_mass, inv_inertia, a, b, px, py, la, lb):
    """The position pass's `apply`: -P (and -la) to a's pose, +P (and +lb) to b's, the
    angles wrapped."""
    position[a, 0] -= px * inv_mass[a]
    position[a, 1] -= py * inv_mass[a]
    angle[a] = wrap(angle[a] - la * inv_inertia[a])
    position[b, 0] += px * inv_mass[b]
    position[b, 1] += py * inv_mass[b]
    angle[b] = wrap(angle[b] + lb * inv_inertia[b])


@numba.njit(cache=True, nogil=True, inline="always")
def move_along(c, ux, uy, ca, cb, a, b, position, angle, inv_mass, inv_inertia):
    """One position correction of an error c (m) along the unit axis (ux, uy), capped at
    MAX_LINEAR_CORRECTION, its arms' cross products ca, cb (distance, prismatic limits)."""
    mass = axial_mass(inv_mass[a], inv_inertia[a], inv_mass[b], inv_inertia[b], ca, cb)
    lam = -mass * clamp(c, MAX_LINEAR_CORRECTION)
    move(position, angle, inv_mass, inv_inertia, a, b, lam * ux, lam * uy, lam * ca, lam * cb)


@numba.njit(cache=True, nogil=True, inline="always")
def one_sided(t, col, cdot, c, inv_h, mass):
    """A limit's new accumulated impulse t[col] (>= 0) and its increment: a limit still open
    by c > 0 may close within the sub-step (c / h, as speculative contacts do), one reached or
    passed holds (position errors are the position pass's)."""
    if c == np.inf:  # no limit on this side
        return 0.0
    bias = c * inv_h if c > 0.0 else 0.0
    old = t[col]
    new = max(old - mass * (cdot + bias), 0.0)
    t[col] = new
    return new - old


@numba.njit(cache=True, nogil=True, inline="always")
def motor(t, mass, cdot, max_motor, h):
    """A motor's increment: its accumulated impulse t[JM] moved by -mass cdot (cdot: the
    speed error), clamped to |impulse| <= max_motor h."""
    old = t[JM]
    new = clamp(old - mass * cdot, max_motor * h)
    t[JM] = new
    return new - old


@numba.njit(cache=True, nogil=True, inline="always")
def soften(t, stiffness, damping_ratio, h, stretch):
    """A spring's soft coefficients (the module docstring) into t[BIAS], t[MS], t[IS]:
    stiffness (Hz), stretch C (m or rad), sub-step h (s)."""
    omega = TWO_PI * stiffness
    a1s = 2.0 * damping_ratio + h * omega
    a2s = h * omega * a1s
    a3s = 1.0 / (1.0 + a2s)
    t[BIAS] = omega / a1s * stretch
    t[MS] = a2s * a3s
    t[IS] = a3s


@numba.njit(cache=True, nogil=True, inline="always")
def soft_impulse(t, mass, cdot):
    """A spring's impulse increment on its accumulated t[J2] (the module docstring)."""
    return -t[MS] * mass * (cdot + t[BIAS]) - t[IS] * t[J2]


@numba.njit(cache=True, nogil=True, inline="always")
def slow_turns(v, a, b, h):
    """Whether both bodies turn by at most SLOW_TURN (rad) in the sub-step of h at velocities
    v: then the end-of-step target is solved with the arms the sub-step starts with (the
    prepared effective mass). A faster turn takes a Newton step about the arms it ends with
    (`end_arms`): with the starting arms, a link whipping round at h w of 1 rad or more
    (a 40-link chain at dt = 1/120 s) was pushed further round each iteration, and the chain
    blew up."""
    return abs(h * v[a, 2]) <= SLOW_TURN and abs(h * v[b, 2]) <= SLOW_TURN


@numba.njit(cache=True, nogil=True, inline="always")
def end_separation(rax, ray, rbx, rby, v, a, b, h):
    """How the anchors' separation b - a (m) changes over a sub-step of h at velocities v:
    each arm r turned by h w (`_turn`: r (1 - (h w)^2 / 2) + h w x r for small turns, exactly
    for large ones). The separation itself is left to the position pass: fed back here as
    well (Baumgarte at full strength), a 40-link chain blew up within a second."""
    hwa = h * v[a, 2]
    hwb = h * v[b, 2]
    ca, sa = _turn(hwa)
    cb, sb = _turn(hwb)
    ex = h * (v[b, 0] - v[a, 0]) + (rbx * cb - rby * sb) - (rax * ca - ray * sa)
    ey = h * (v[b, 1] - v[a, 1]) + (rby * cb + rbx * sb) - (ray * ca + rax * sa)
    return ex, ey


@numba.njit(cache=True, nogil=True, inline="always")
def end_arms(rax, ray, rbx, rby, v, a, b, h):
    """The arms (m, world) turned by the sub-step's turns h w (`_turn`), and the change of
    the anchors' separation over the sub-step, as `end_separation`: the derivative of that
    change by either body's velocities is the point constraint's Jacobian with these arms."""
    ca, sa = _turn(h * v[a, 2])
    cb, sb = _turn(h * v[b, 2])
    pax = rax + (rax * ca - ray * sa)
    pay = ray + (ray * ca + rax * sa)
    pbx = rbx + (rbx * cb - rby * sb)
    pby = rby + (rby * cb + rbx * sb)
    ex = h * (v[b, 0] - v[a, 0]) + (rbx * cb - rby * sb) - (rax * ca - ray * sa)
    ey = h * (v[b, 1] - v[a, 1]) + (rby * cb + rbx * sb) - (ray * ca + rax * sa)
    return pax, pay, pbx, pby, ex, ey


@numba.njit(cache=True, nogil=True, inline="always")
def _turn(x):
    """(cos x - 1, sin x) of a sub-step's turn x = h w (rad): to second order while |x| <= 0.05
    (error below x^3 / 6 = 2e-5 x), exactly (isaac.trig) beyond, where a whipping link's arm
    turns too far for the series."""
    if abs(x) <= 0.05:
        return -0.5 * x * x, x
    s, c = sin_cos(x)
    return c - 1.0, s
