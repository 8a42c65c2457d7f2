"""Joints: revolute, distance, weld and prismatic constraints, solved with the contacts.

Each sub-step, inside the sequential solver (isaac.engine.solver.sequential):
1. `prepare_joints`: the world anchor arms r = R(angle) local, axes, effective masses, the
   limits' current values and the springs' soft coefficients, from the poses after the
   push-out;
2. `warm_start_joints`: last sub-step's accumulated impulses applied first (as contacts are);
3. `solve_joint_velocities`: one Gauss-Seidel pass over the joints, between the contact passes
   (each velocity iteration: the contacts' pass, then the joints'), accumulating impulses.
After integration, `correct_joint_positions` (Box2D 2.3's non-linear Gauss-Seidel, b2Joint::
SolvePositionConstraints) moves the bodies back onto their rigid constraints, `iterations`
passes, each joint's correction capped (MAX_LINEAR_CORRECTION, MAX_ANGULAR_CORRECTION), so the
state a step ends with keeps the chains together instead of letting them drift.

Velocity constraints (Box2D 2.3's joints, sign conventions: an impulse P is applied as -P to a
and +P to b at the anchors; v_a, w_a, v_b, w_b the bodies' velocities):
- revolute: the anchors' separation unchanged over the sub-step (`_end_separation`: each arm
  turned by h w; to first order the relative velocity v_b + w_b x r_b - v_a - w_a x r_a = 0;
  a 2x2 effective mass, of the arms the sub-step ends with when a body turns by more than
  SLOW_TURN, `_slow_turns`); a motor w_b - w_a = speed with |impulse| <= max_torque h; limits on the
  angle q = wrap(angle_b - angle_a - reference) as one-sided constraints (impulse >= 0) that let
  a limit still open by C close within the sub-step (C / h, as speculative contacts do).
- distance: along the unit axis u between the anchors: rigid (the length unchanged over the
  sub-step, as the revolute's separation), a spring of
  frequency f and damping ratio z (Catto's soft constraint: omega = 2 pi f, a1 = 2 z + h omega,
  a2 = h omega a1, bias rate omega / a1, mass scale a2 / (1 + a2), impulse scale 1 / (1 + a2)),
  and one-sided limits min_length / max_length.
- weld: the revolute's point constraint and w_b - w_a = 0, rigid or an angular spring.
- prismatic: along the axis's normal p and the relative rotation, both at once (2x2), a motor
  and limits along the axis u.
A joint whose two bodies do not both exist does nothing. Position errors are left to
`correct_joint_positions`, except for springs, which pull by their bias.

The joint table (Joints) holds the scene's joints as arrays; the scratch `jt` (m, WIDTH) one row
per joint, columns named below; the accumulated impulses are columns J0 .. JU (the warm start
carry, `JOINT_IMPULSES` of them).
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from isaac.engine import kernel_cache  # noqa: F401  (first: keys the kernels' numba cache)
from isaac.engine.geometry import sin_cos
from isaac.engine.integrate import PI, TWO_PI

REVOLUTE = 0
DISTANCE = 1
WELD = 2
PRISMATIC = 3
KIND_CODES = {"revolute": REVOLUTE, "distance": DISTANCE, "weld": WELD, "prismatic": PRISMATIC}

# Box2D 2.3's caps on one position correction (b2_maxLinearCorrection, b2_maxAngularCorrection)
MAX_LINEAR_CORRECTION = 0.2  # m
MAX_ANGULAR_CORRECTION = 8.0 / 180.0 * np.pi  # rad
# a body turning faster than this in a sub-step (rad) gets the joints' Newton step
# (`_slow_turns`); below it the bits are those of physics version 2
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


class Joints(NamedTuple):
    """The scene's joints as the compiled kernels take them (`isaac.scene.JointSpec`'s fields,
    one row per joint; "none" as flags)."""

    kind: np.ndarray  # (m,) int64, REVOLUTE .. PRISMATIC
    a: np.ndarray  # (m,) int64 body indices
    b: np.ndarray
    local_a: np.ndarray  # (m, 2) m, a's frame
    local_b: np.ndarray  # (m, 2) m, b's frame
    axis: np.ndarray  # (m, 2) unit, a's frame (prismatic)
    reference_angle: np.ndarray  # (m,) rad
    length: np.ndarray  # (m,) m (distance)
    rigid: np.ndarray  # (m,) bool: distance without spring or limits; weld without spring
    has_limit: np.ndarray  # (m,) bool
    lower: np.ndarray  # (m,) rad or m (distance: min length, -inf when none)
    upper: np.ndarray  # (m,) (distance: max length, +inf when none)
    spring: np.ndarray  # (m,) bool
    stiffness: np.ndarray  # (m,) Hz
    damping_ratio: np.ndarray  # (m,)
    has_motor: np.ndarray  # (m,) bool
    motor_speed: np.ndarray  # (m,) rad/s or m/s
    max_motor: np.ndarray  # (m,) N m or N


def joint_table(joints, n_bodies: int) -> tuple[Joints, np.ndarray]:
    """(Joints, no_collide) of a scene's JointSpecs: no_collide is the sorted int64 keys
    min * n + max of the body pairs that a joint keeps from colliding (collide_connected false),
    which the broad phase drops."""
    m = len(joints)
    if m == 0:
        # most scenes: the same empty columns without the 17 passes over no joints (a third of
        # building a 2-body scene's Simulation, which a sweep does for each of its runs)
        return _empty_table(), np.zeros(0, dtype=np.int64)

    def col(get, dtype=np.float64):
        return np.array([get(j) for j in joints], dtype=dtype).reshape(m)

    def pairs(get):
        return np.array([get(j) for j in joints], dtype=np.float64).reshape(m, 2)

    def given(j):  # the limits the scene gives (None: none on that side)
        return (j.min_length, j.max_length) if j.kind == "distance" else (j.lower, j.upper)

    def bound(value, none):
        return none if value is None else value

    has_limit = col(lambda j: given(j) != (None, None), bool)
    spring = col(lambda j: j.stiffness is not None and j.kind in ("distance", "weld"), bool)
    kind = col(lambda j: KIND_CODES[j.kind], np.int64)
    table = Joints(
        kind=kind,
        a=col(lambda j: j.a, np.int64),
        b=col(lambda j: j.b, np.int64),
        local_a=pairs(lambda j: j.local_a),
        local_b=pairs(lambda j: j.local_b),
        axis=pairs(lambda j: j.axis),
        reference_angle=col(lambda j: j.reference_angle),
        length=col(lambda j: j.length),
        # a distance joint with limits acts only at them; every other joint without a spring is
        # rigid
        rigid=col(lambda j: j.stiffness is None, bool) & ~(has_limit & (kind == DISTANCE)),
        has_limit=has_limit,
        lower=col(lambda j: bound(given(j)[0], -np.inf)),
        upper=col(lambda j: bound(given(j)[1], np.inf)),
        spring=spring,
        stiffness=col(lambda j: 0.0 if j.stiffness is None else j.stiffness),
        damping_ratio=col(lambda j: j.damping_ratio),
        has_motor=col(lambda j: j.motor_speed is not None, bool),
        motor_speed=col(lambda j: 0.0 if j.motor_speed is None else j.motor_speed),
        max_motor=col(lambda j: j.max_motor),
    )
    keys = sorted(
        {min(j.a, j.b) * n_bodies + max(j.a, j.b) for j in joints if not j.collide_connected}
    )
    return table, np.array(keys, dtype=np.int64)


# the columns of the (m, 2) fields and of the integer and boolean ones; the others are float64
_PAIRS = ("local_a", "local_b", "axis")
_TYPES = {"kind": np.int64, "a": np.int64, "b": np.int64, "rigid": bool, "has_limit": bool}
_TYPES.update(spring=bool, has_motor=bool)


def _empty_table() -> Joints:
    """The table of no joints: what `joint_table` builds for m = 0 (shapes, dtypes, layout)."""
    return Joints(
        *(
            np.zeros((0, 2) if f in _PAIRS else 0, dtype=_TYPES.get(f, np.float64))
            for f in Joints._fields
        )
    )


def in_waves(table: Joints, n_bodies: int) -> Joints:
    """The joint table reordered for the position passes, which visit it in this order: each
    joint's wave is one more than the last wave of a joint before it (in the scene's order)
    with a body in common, and the joints go wave by wave (stably).

    The same bits as the scene's order: a joint's correction reads and writes its two bodies'
    positions and angles alone, so two joints with no body in common commute exactly, and
    every body still sees the joints that move it in the scene's order (concrete bodies
    count too: a move by zero can still turn -0.0 into +0.0). Faster where consecutive joints
    of the scene's order share a body (each waiting on the last one's sin/cos and division):
    the 100 x 100 joint grid's joints fall into 396 waves of 50, and a pass takes 0.61 ms
    instead of 0.74 (a chain's joints stay in its order, one to a wave)."""
    m = table.kind.shape[0]
    if m == 0:  # no joints: nothing to reorder (and nothing to write in either)
        return table
    last = np.zeros(n_bodies, dtype=np.int64)
    wave = np.empty(m, dtype=np.int64)
    for k, (a, b) in enumerate(zip(table.a.tolist(), table.b.tolist())):
        wave[k] = max(last[a], last[b])
        last[a] = last[b] = wave[k] + 1
    order = np.argsort(wave, kind="stable")
    return Joints(*(np.ascontiguousarray(column[order]) for column in table))


@numba.njit(cache=True, nogil=True, inline="always")
def _wrap(angle):
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


# Speed: the helpers below take scalars (or the kernels' own array arguments), never the joint
# table or one of its arrays: each such argument cost a reference count update, 0.4-0.9 us a
# joint on the 100 x 100 joint grid (bench/joint_grid.py), more than the physics.
# NO_COUNTS: the per-joint loops are compiled without reference counting at all (numba's
# `_nrt=False`, as isaac.engine.driver's stage kernels): they allocate nothing and return no
# array, and with counting each row view (jt[k]) and each read of the table's arrays still cost
# atomic count updates, most of a loop's time (100 x 100 grid, with the other changes of that
# pass: a velocity pass 0.57 -> 0.33 ms, the warm start 0.76 -> 0.24 ms, bench/README.md). The
# kernels that allocate (`_rotations`' table) call them.


@numba.njit(cache=True, nogil=True, inline="always")
def _arm(lx, ly, angle):
    """The body-frame vector (lx, ly) (m) turned by the body's angle (rad): world frame."""
    s, c = sin_cos(angle)
    return _turned(lx, ly, s, c)


@numba.njit(cache=True, nogil=True, inline="always")
def _turned(lx, ly, s, c):
    """(lx, ly) turned by the angle whose (sin, cos) are (s, c)."""
    return c * lx - s * ly, s * lx + c * ly


@numba.njit(cache=True, nogil=True)
def _rotations(J, angle, exists):
    """(n, 2) sin and cos of every existing body's angle, or (0, 2) when the joints have fewer
    ends than there are bodies (then each end computes its own: the same bits, as sin_cos is
    a function of the angle alone). One sin_cos per body instead of one per joint end: the
    100 x 100 joint grid has 10,000 bodies and 39,586 ends."""
    n = angle.shape[0]
    if n > 2 * J.kind.shape[0]:
        return np.empty((0, 2))
    rot = np.empty((n, 2))
    for i in range(n):
        if exists[i]:
            rot[i, 0], rot[i, 1] = sin_cos(angle[i])
    return rot


@numba.njit(cache=True, nogil=True, inline="always")
def _sin_cos_of(rot, angle, i):
    """Body i's (sin, cos): from `_rotations`' table when it has one."""
    if rot.shape[0]:
        return rot[i, 0], rot[i, 1]
    return sin_cos(angle[i])


@numba.njit(cache=True, nogil=True, inline="always")
def _inverse_2x2(k11, k12, k22):
    det = k11 * k22 - k12 * k12
    if det != 0.0:
        det = 1.0 / det
    return det * k22, -det * k12, det * k11


@numba.njit(cache=True, nogil=True, inline="always")
def _point_mass(ma, ia, mb, ib, rax, ray, rbx, rby):
    """Inverse of the 2x2 effective mass of a point-to-point constraint."""
    k11 = ma + mb + ia * ray * ray + ib * rby * rby
    k12 = -ia * rax * ray - ib * rbx * rby
    k22 = ma + mb + ia * rax * rax + ib * rbx * rbx
    return _inverse_2x2(k11, k12, k22)


@numba.njit(cache=True, nogil=True, inline="always")
def _inv_or_zero(k):
    return 1.0 / k if k > 0.0 else 0.0


@numba.njit(cache=True, nogil=True)
def prepare_joints(J, jt, position, angle, exists, inv_mass, inv_inertia, h, warm, warm_starting):
    """Fill the scratch rows for this sub-step (poses after the push-out) and load the
    accumulated impulses: `warm` (m, JOINT_IMPULSES), last sub-step's, when warm_starting
    (else they start from zero)."""
    rot = _rotations(J, angle, exists)
    _prepare_rows(
        J, jt, rot, position, angle, exists, inv_mass, inv_inertia, h, warm, warm_starting
    )


@numba.njit(cache=True, nogil=True, _nrt=False)  # (no reference counts: see NO_COUNTS)
def _prepare_rows(
    J, jt, rot, position, angle, exists, inv_mass, inv_inertia, h, warm, warm_starting
):  # fmt: skip
    """`prepare_joints`' loop, with the bodies' (sin, cos) `rot` (`_rotations`)."""
    local_a = J.local_a
    local_b = J.local_b
    for k in range(J.kind.shape[0]):
        a = J.a[k]
        b = J.b[k]
        t = jt[k]
        for c in range(WIDTH):
            t[c] = 0.0
        if not (exists[a] and exists[b]):
            continue
        t[ON] = 1.0
        sa, ca = _sin_cos_of(rot, angle, a)
        sb, cb = _sin_cos_of(rot, angle, b)
        rax, ray = _turned(local_a[k, 0], local_a[k, 1], sa, ca)
        rbx, rby = _turned(local_b[k, 0], local_b[k, 1], sb, cb)
        t[RAX] = rax
        t[RAY] = ray
        t[RBX] = rbx
        t[RBY] = rby
        ma = inv_mass[a]
        ia = inv_inertia[a]
        mb = inv_mass[b]
        ib = inv_inertia[b]
        t[KA] = _inv_or_zero(ia + ib)
        dx = position[b, 0] + rbx - position[a, 0] - rax
        dy = position[b, 1] + rby - position[a, 1] - ray
        t[DX] = dx
        t[DY] = dy
        kind = J.kind[k]
        q = _wrap(angle[b] - angle[a] - J.reference_angle[k])
        c_now = 0.0  # the spring's stretch (m or rad)
        if kind == REVOLUTE or kind == WELD:
            t[K11], t[K12], t[K22] = _point_mass(ma, ia, mb, ib, rax, ray, rbx, rby)
            t[CL] = q - J.lower[k]
            t[CU] = J.upper[k] - q
            c_now = q
        elif kind == DISTANCE:
            d = np.sqrt(dx * dx + dy * dy)
            ux = 1.0
            uy = 0.0
            if d > 0.0:
                ux = dx / d
                uy = dy / d
            t[UX] = ux
            t[UY] = uy
            cra = rax * uy - ray * ux
            crb = rbx * uy - rby * ux
            t[KAX] = _inv_or_zero(ma + mb + ia * cra * cra + ib * crb * crb)
            t[CL] = d - J.lower[k]
            t[CU] = J.upper[k] - d
            c_now = d - J.length[k]
        else:  # PRISMATIC
            s, c = sin_cos(angle[a])
            ux = c * J.axis[k, 0] - s * J.axis[k, 1]
            uy = s * J.axis[k, 0] + c * J.axis[k, 1]
            px = -uy
            py = ux
            t[UX] = ux
            t[UY] = uy
            t[PX] = px
            t[PY] = py
            # arms of a: from a's centre to b's anchor (d + r_a); of b: r_b
            a1 = (dx + rax) * uy - (dy + ray) * ux
            a2 = rbx * uy - rby * ux
            s1 = (dx + rax) * py - (dy + ray) * px
            s2 = rbx * py - rby * px
            t[A1] = a1
            t[A2] = a2
            t[S1] = s1
            t[S2] = s2
            t[KAX] = _inv_or_zero(ma + mb + ia * a1 * a1 + ib * a2 * a2)
            k22 = ia + ib
            if k22 == 0.0:
                k22 = 1.0  # two bodies that cannot turn: the rotation row is idle
            t[K11], t[K12], t[K22] = _inverse_2x2(
                ma + mb + ia * s1 * s1 + ib * s2 * s2, ia * s1 + ib * s2, k22
            )
            translation = ux * dx + uy * dy
            t[CL] = translation - J.lower[k]
            t[CU] = J.upper[k] - translation
        if J.spring[k]:
            omega = TWO_PI * J.stiffness[k]
            a1s = 2.0 * J.damping_ratio[k] + h * omega
            a2s = h * omega * a1s
            a3s = 1.0 / (1.0 + a2s)
            t[BIAS] = omega / a1s * c_now
            t[MS] = a2s * a3s
            t[IS] = a3s
        if warm_starting:
            for c in range(JOINT_IMPULSES):
                t[J0 + c] = warm[k, c]


@numba.njit(cache=True, nogil=True, inline="always")
def _apply(v, inv, a, b, px, py, la, lb):
    """-P (and angular -la) to a, +P (and +lb) to b."""
    v[a, 0] -= px * inv[a, 0]
    v[a, 1] -= py * inv[a, 0]
    v[a, 2] -= la * inv[a, 1]
    v[b, 0] += px * inv[b, 0]
    v[b, 1] += py * inv[b, 0]
    v[b, 2] += lb * inv[b, 1]


@numba.njit(cache=True, nogil=True, inline="always")
def _push(kind, a, b, jt, k, v, inv, impulses):
    """Apply impulses (J0 .. JU layout) of joint k, of `kind` between bodies a and b, as the
    solve does, with its scratch row's arms."""
    rax = jt[k, RAX]
    ray = jt[k, RAY]
    rbx = jt[k, RBX]
    rby = jt[k, RBY]
    j0, j1, j2, jm, jl, ju = impulses
    if kind == REVOLUTE or kind == WELD:
        ang = jm + jl - ju + j2
        _apply(v, inv, a, b, j0, j1, rax * j1 - ray * j0 + ang, rbx * j1 - rby * j0 + ang)
    elif kind == DISTANCE:
        axial = j2 + jl - ju
        ux = jt[k, UX]
        uy = jt[k, UY]
        _apply(
            v,
            inv,
            a,
            b,
            axial * ux,
            axial * uy,
            axial * (rax * uy - ray * ux),
            axial * (rbx * uy - rby * ux),
        )
    else:
        axial = jm + jl - ju
        _apply(
            v,
            inv,
            a,
            b,
            j0 * jt[k, PX] + axial * jt[k, UX],
            j0 * jt[k, PY] + axial * jt[k, UY],
            j0 * jt[k, S1] + j1 + axial * jt[k, A1],
            j0 * jt[k, S2] + j1 + axial * jt[k, A2],
        )


@numba.njit(cache=True, nogil=True, _nrt=False)  # (no reference counts: see NO_COUNTS)
def warm_start_joints(J, jt, v, inv):
    """Apply every active joint's loaded impulses (last sub-step's) to the velocities."""
    for k in range(J.kind.shape[0]):
        t = jt[k]
        if t[ON] == 0.0:
            continue
        _push(J.kind[k], J.a[k], J.b[k], jt, k, v, inv, (t[J0], t[J1], t[J2], t[JM], t[JL], t[JU]))


@numba.njit(cache=True, nogil=True, inline="always")
def _one_sided(jt, k, col, cdot, c, inv_h, mass):
    """A limit's new accumulated impulse (>= 0) and its increment: a limit still open by c > 0
    may close within the sub-step (c / h), one reached or passed holds (position errors are
    the position pass's)."""
    if c == np.inf:  # no limit on this side
        return 0.0
    bias = c * inv_h if c > 0.0 else 0.0
    old = jt[k, col]
    new = max(old - mass * (cdot + bias), 0.0)
    jt[k, col] = new
    return new - old


@numba.njit(cache=True, nogil=True, inline="always")
def _end_separation(rax, ray, rbx, rby, v, a, b, h):
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
def _slow_turns(v, a, b, h):
    """Whether both bodies turn by at most SLOW_TURN (rad) in the sub-step of h at velocities
    v: then the end-of-step target is solved with the arms the sub-step starts with (the
    prepared effective mass). A faster turn takes a Newton step about the arms it ends with
    (`_end_arms`): with the starting arms, a link whipping round at h w of 1 rad or more
    (a 40-link chain at dt = 1/120 s) was pushed further round each iteration, and the chain
    blew up."""
    return abs(h * v[a, 2]) <= SLOW_TURN and abs(h * v[b, 2]) <= SLOW_TURN


@numba.njit(cache=True, nogil=True, inline="always")
def _end_arms(rax, ray, rbx, rby, v, a, b, h):
    """The arms (m, world) turned by the sub-step's turns h w (`_turn`), and the change of
    the anchors' separation over the sub-step, as `_end_separation`: the derivative of that
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


@numba.njit(cache=True, nogil=True, _nrt=False)  # (no reference counts: see NO_COUNTS)
def solve_joint_velocities(J, jt, v, inv, h):
    """One Gauss-Seidel pass over the joints (velocities v (n, 3): vx, vy, w; in place)."""
    inv_h = 1.0 / h
    for k in range(J.kind.shape[0]):
        t = jt[k]
        if t[ON] == 0.0:
            continue
        a = J.a[k]
        b = J.b[k]
        kind = J.kind[k]
        rax = t[RAX]
        ray = t[RAY]
        rbx = t[RBX]
        rby = t[RBY]
        if kind == REVOLUTE or kind == WELD:
            if kind == REVOLUTE and J.has_motor[k]:
                cdot = v[b, 2] - v[a, 2] - J.motor_speed[k]
                old = t[JM]
                most = J.max_motor[k] * h
                new = min(max(old - t[KA] * cdot, -most), most)
                t[JM] = new
                _apply(v, inv, a, b, 0.0, 0.0, new - old, new - old)
            if kind == REVOLUTE and J.has_limit[k]:
                d = _one_sided(jt, k, JL, v[b, 2] - v[a, 2], t[CL], inv_h, t[KA])
                _apply(v, inv, a, b, 0.0, 0.0, d, d)
                d = _one_sided(jt, k, JU, v[a, 2] - v[b, 2], t[CU], inv_h, t[KA])
                _apply(v, inv, a, b, 0.0, 0.0, -d, -d)
            if kind == WELD:
                cdot = v[b, 2] - v[a, 2]
                if J.spring[k]:
                    d = -t[MS] * t[KA] * (cdot + t[BIAS]) - t[IS] * t[J2]
                else:
                    d = -t[KA] * cdot
                t[J2] += d
                _apply(v, inv, a, b, 0.0, 0.0, d, d)
            # the anchors' separation at the end of the sub-step, at the velocities so far
            if _slow_turns(v, a, b, h):
                ex, ey = _end_separation(rax, ray, rbx, rby, v, a, b, h)
                ix = -(t[K11] * ex + t[K12] * ey) * inv_h
                iy = -(t[K12] * ex + t[K22] * ey) * inv_h
                t[J0] += ix
                t[J1] += iy
                _apply(v, inv, a, b, ix, iy, rax * iy - ray * ix, rbx * iy - rby * ix)
            else:  # a Newton step about the arms the sub-step ends with (`_end_arms`)
                pax, pay, pbx, pby, ex, ey = _end_arms(rax, ray, rbx, rby, v, a, b, h)
                k11, k12, k22 = _point_mass(
                    inv[a, 0], inv[a, 1], inv[b, 0], inv[b, 1], pax, pay, pbx, pby
                )
                ix = -(k11 * ex + k12 * ey) * inv_h
                iy = -(k12 * ex + k22 * ey) * inv_h
                t[J0] += ix
                t[J1] += iy
                _apply(v, inv, a, b, ix, iy, pax * iy - pay * ix, pbx * iy - pby * ix)
        elif kind == DISTANCE:
            ux = t[UX]
            uy = t[UY]
            cra = rax * uy - ray * ux
            crb = rbx * uy - rby * ux
            for part in range(3):
                # relative velocity of the anchors along u (b's less a's)
                cdot = ux * (v[b, 0] - v[b, 2] * rby - v[a, 0] + v[a, 2] * ray) + uy * (
                    v[b, 1] + v[b, 2] * rbx - v[a, 1] - v[a, 2] * rax
                )
                # the direction and arms the impulse acts along
                pux = ux
                puy = uy
                pcra = cra
                pcrb = crb
                if part == 0:
                    if J.spring[k]:
                        d = -t[MS] * t[KAX] * (cdot + t[BIAS]) - t[IS] * t[J2]
                    elif J.rigid[k] and _slow_turns(v, a, b, h):
                        # the length at the end of the sub-step, at the velocities so far
                        ex, ey = _end_separation(rax, ray, rbx, rby, v, a, b, h)
                        ex += t[DX]
                        ey += t[DY]
                        now = np.sqrt(t[DX] * t[DX] + t[DY] * t[DY])
                        d = -t[KAX] * (np.sqrt(ex * ex + ey * ey) - now) * inv_h
                    elif J.rigid[k]:
                        # a Newton step about the arms and axis the sub-step ends with
                        pax, pay, pbx, pby, ex, ey = _end_arms(rax, ray, rbx, rby, v, a, b, h)
                        ex += t[DX]
                        ey += t[DY]
                        end = np.sqrt(ex * ex + ey * ey)
                        if end > 0.0:
                            pux = ex / end
                            puy = ey / end
                        pcra = pax * puy - pay * pux
                        pcrb = pbx * puy - pby * pux
                        mass = _inv_or_zero(
                            inv[a, 0] + inv[b, 0] + inv[a, 1] * pcra * pcra
                            + inv[b, 1] * pcrb * pcrb
                        )  # fmt: skip
                        now = np.sqrt(t[DX] * t[DX] + t[DY] * t[DY])
                        d = -mass * (end - now) * inv_h
                    else:
                        continue
                    t[J2] += d
                elif not J.has_limit[k]:
                    break
                elif part == 1:
                    d = _one_sided(jt, k, JL, cdot, t[CL], inv_h, t[KAX])
                else:
                    d = -_one_sided(jt, k, JU, -cdot, t[CU], inv_h, t[KAX])
                _apply(v, inv, a, b, d * pux, d * puy, d * pcra, d * pcrb)
        else:  # PRISMATIC
            ux = t[UX]
            uy = t[UY]
            a1 = t[A1]
            a2 = t[A2]
            if J.has_motor[k] or J.has_limit[k]:
                for part in range(3):
                    cdot = (
                        ux * (v[b, 0] - v[a, 0]) + uy * (v[b, 1] - v[a, 1])
                        + a2 * v[b, 2] - a1 * v[a, 2]
                    )  # fmt: skip
                    if part == 0:
                        if not J.has_motor[k]:
                            continue
                        old = t[JM]
                        most = J.max_motor[k] * h
                        new = min(max(old - t[KAX] * (cdot - J.motor_speed[k]), -most), most)
                        t[JM] = new
                        d = new - old
                    elif not J.has_limit[k]:
                        break
                    elif part == 1:
                        d = _one_sided(jt, k, JL, cdot, t[CL], inv_h, t[KAX])
                    else:
                        d = -_one_sided(jt, k, JU, -cdot, t[CU], inv_h, t[KAX])
                    _apply(v, inv, a, b, d * ux, d * uy, d * a1, d * a2)
            px = t[PX]
            py = t[PY]
            s1 = t[S1]
            s2 = t[S2]
            c1 = px * (v[b, 0] - v[a, 0]) + py * (v[b, 1] - v[a, 1]) + s2 * v[b, 2] - s1 * v[a, 2]
            c2 = v[b, 2] - v[a, 2]
            i1 = -(t[K11] * c1 + t[K12] * c2)
            i2 = -(t[K12] * c1 + t[K22] * c2)
            t[J0] += i1
            t[J1] += i2
            _apply(v, inv, a, b, i1 * px, i1 * py, i1 * s1 + i2, i1 * s2 + i2)


@numba.njit(cache=True, nogil=True, inline="always")
def _clamp(x, most):
    return min(max(x, -most), most)


@numba.njit(cache=True, nogil=True)
def correct_joint_positions(
    J, waves, position, angle, exists, inv_mass, inv_inertia, iterations, error
):  # fmt: skip
    """After integration: `iterations` Gauss-Seidel passes that move each joint's bodies back
    onto its rigid constraints (positions and angles in place, angles wrapped), visiting the
    joints in the order of `waves` (the table `in_waves` reorders: the same bits as J's), and
    then each joint's remaining error into error (m, 2): the anchors' distance off the
    constraint (m) and the rotation off it (rad; weld and prismatic), 0 for what a joint leaves
    free.

    Per joint (Box2D 2.3's SolvePositionConstraints): revolute, its angle limits then the
    anchors together (2x2); weld, the rotation then the anchors; distance, the length (rigid)
    or the limit it is past; prismatic, the axis's normal and the rotation (2x2), then the
    limit it is past. Springs are not corrected: their stretch is their force. Each correction
    is capped at MAX_LINEAR_CORRECTION (m) and MAX_ANGULAR_CORRECTION (rad).

    An `error` of no rows asks for no errors: the compiled driver's sub-steps whose errors are
    not logged (every one but the last of a recorded step; 0.3 ms a sub-step on the 100 x 100
    joint grid)."""
    _correct_passes(waves, position, angle, exists, inv_mass, inv_inertia, iterations)
    if error.shape[0] == 0:
        return
    rot = _rotations(J, angle, exists)  # the final angles
    _errors(J, rot, position, angle, exists, error)


@numba.njit(cache=True, nogil=True, _nrt=False)  # (no reference counts: see NO_COUNTS)
def _correct_passes(J, position, angle, exists, inv_mass, inv_inertia, iterations):
    """`correct_joint_positions`' passes."""
    m = J.kind.shape[0]
    local_a = J.local_a
    local_b = J.local_b
    axis = J.axis
    for _ in range(iterations):
        for k in range(m):
            a = J.a[k]
            b = J.b[k]
            if not (exists[a] and exists[b]):
                continue
            _correct(
                J.kind[k], J.reference_angle[k], J.rigid[k], J.has_limit[k], J.lower[k],
                J.upper[k], J.length[k], axis[k, 0], axis[k, 1], local_a[k, 0], local_a[k, 1],
                local_b[k, 0], local_b[k, 1], a, b, position, angle, inv_mass, inv_inertia,
            )  # fmt: skip


@numba.njit(cache=True, nogil=True, _nrt=False)  # (no reference counts: see NO_COUNTS)
def _errors(J, rot, position, angle, exists, error):
    """`correct_joint_positions`' remaining errors, with the bodies' (sin, cos) `rot`."""
    m = J.kind.shape[0]
    local_a = J.local_a
    local_b = J.local_b
    axis = J.axis
    for k in range(m):
        a = J.a[k]
        b = J.b[k]
        error[k, 0] = 0.0
        error[k, 1] = 0.0
        if exists[a] and exists[b]:
            sa, ca = _sin_cos_of(rot, angle, a)
            sb, cb = _sin_cos_of(rot, angle, b)
            error[k, 0], error[k, 1] = _error(
                J.kind[k], J.reference_angle[k], J.rigid[k], J.spring[k], J.lower[k],
                J.upper[k], J.length[k], axis[k, 0], axis[k, 1], local_a[k, 0], local_a[k, 1],
                local_b[k, 0], local_b[k, 1], a, b, position, angle, sa, ca, sb, cb,
            )  # fmt: skip


@numba.njit(cache=True, nogil=True, inline="always")
def _separation(lax, lay, lbx, lby, a, b, position, angle):
    """The arms (m, world) of the anchors (lax, lay) in a's frame and (lbx, lby) in b's, and the
    anchors' separation b - a (m, world)."""
    rax, ray = _arm(lax, lay, angle[a])
    rbx, rby = _arm(lbx, lby, angle[b])
    dx = position[b, 0] + rbx - position[a, 0] - rax
    dy = position[b, 1] + rby - position[a, 1] - ray
    return rax, ray, rbx, rby, dx, dy


@numba.njit(cache=True, nogil=True, inline="always")
def _move(position, angle, inv_mass, inv_inertia, a, b, px, py, la, lb):
    position[a, 0] -= px * inv_mass[a]
    position[a, 1] -= py * inv_mass[a]
    angle[a] = _wrap(angle[a] - la * inv_inertia[a])
    position[b, 0] += px * inv_mass[b]
    position[b, 1] += py * inv_mass[b]
    angle[b] = _wrap(angle[b] + lb * inv_inertia[b])


@numba.njit(cache=True, nogil=True, inline="always")
def _correct(
    kind, reference, rigid, has_limit, lower, upper, length, axis_x, axis_y, lax, lay, lbx, lby,
    a, b, position, angle, inv_mass, inv_inertia,
):  # fmt: skip
    """One joint's position correction (`correct_joint_positions`), its table row as scalars."""
    ma = inv_mass[a]
    ia = inv_inertia[a]
    mb = inv_mass[b]
    ib = inv_inertia[b]
    if kind == REVOLUTE or kind == WELD:
        c = 0.0
        if kind == WELD and rigid:
            c = _wrap(angle[b] - angle[a] - reference)
        elif kind == REVOLUTE and has_limit:
            q = _wrap(angle[b] - angle[a] - reference)
            if q < lower:
                c = q - lower
            elif q > upper:
                c = q - upper
        if c != 0.0 and ia + ib > 0.0:
            lam = -_clamp(c, MAX_ANGULAR_CORRECTION) / (ia + ib)
            _move(position, angle, inv_mass, inv_inertia, a, b, 0.0, 0.0, lam, lam)
        rax, ray, rbx, rby, dx, dy = _separation(lax, lay, lbx, lby, a, b, position, angle)
        length = np.sqrt(dx * dx + dy * dy)
        if length > MAX_LINEAR_CORRECTION:  # capped, along the same direction
            scale = MAX_LINEAR_CORRECTION / length
            dx *= scale
            dy *= scale
        k11, k12, k22 = _point_mass(ma, ia, mb, ib, rax, ray, rbx, rby)
        px = -(k11 * dx + k12 * dy)
        py = -(k12 * dx + k22 * dy)
        _move(
            position, angle, inv_mass, inv_inertia, a, b, px, py,
            rax * py - ray * px, rbx * py - rby * px,
        )  # fmt: skip
    elif kind == DISTANCE:
        rax, ray, rbx, rby, dx, dy = _separation(lax, lay, lbx, lby, a, b, position, angle)
        d = np.sqrt(dx * dx + dy * dy)
        if d == 0.0:
            return
        c = 0.0
        if rigid:
            c = d - length
        elif d < lower:
            c = d - lower
        elif d > upper:
            c = d - upper
        if c == 0.0:
            return
        ux = dx / d
        uy = dy / d
        cra = rax * uy - ray * ux
        crb = rbx * uy - rby * ux
        mass = _inv_or_zero(ma + mb + ia * cra * cra + ib * crb * crb)
        lam = -mass * _clamp(c, MAX_LINEAR_CORRECTION)
        _move(
            position, angle, inv_mass, inv_inertia, a, b, lam * ux, lam * uy, lam * cra, lam * crb
        )
    else:  # PRISMATIC
        rax, ray, rbx, rby, dx, dy = _separation(lax, lay, lbx, lby, a, b, position, angle)
        s, co = sin_cos(angle[a])
        ux = co * axis_x - s * axis_y
        uy = s * axis_x + co * axis_y
        px = -uy
        py = ux
        s1 = (dx + rax) * py - (dy + ray) * px
        s2 = rbx * py - rby * px
        c1 = _clamp(px * dx + py * dy, MAX_LINEAR_CORRECTION)
        c2 = _clamp(_wrap(angle[b] - angle[a] - reference), MAX_ANGULAR_CORRECTION)
        k22 = ia + ib
        if k22 == 0.0:
            k22 = 1.0
        k11, k12, k22 = _inverse_2x2(ma + mb + ia * s1 * s1 + ib * s2 * s2, ia * s1 + ib * s2, k22)
        i1 = -(k11 * c1 + k12 * c2)
        i2 = -(k12 * c1 + k22 * c2)
        _move(
            position, angle, inv_mass, inv_inertia, a, b, i1 * px, i1 * py,
            i1 * s1 + i2, i1 * s2 + i2,
        )  # fmt: skip
        if has_limit:
            rax, ray, rbx, rby, dx, dy = _separation(lax, lay, lbx, lby, a, b, position, angle)
            translation = ux * dx + uy * dy
            c = 0.0
            if translation < lower:
                c = translation - lower
            elif translation > upper:
                c = translation - upper
            if c != 0.0:
                a1 = (dx + rax) * uy - (dy + ray) * ux
                a2 = rbx * uy - rby * ux
                mass = _inv_or_zero(ma + mb + ia * a1 * a1 + ib * a2 * a2)
                lam = -mass * _clamp(c, MAX_LINEAR_CORRECTION)
                _move(
                    position, angle, inv_mass, inv_inertia, a, b, lam * ux, lam * uy,
                    lam * a1, lam * a2,
                )  # fmt: skip


@numba.njit(cache=True, nogil=True, inline="always")
def _error(
    kind, reference, rigid, spring, lower, upper, length, axis_x, axis_y, lax, lay, lbx, lby, a,
    b, position, angle, sa, ca, sb, cb,
):  # fmt: skip
    """One joint's remaining error (`correct_joint_positions`), its table row as scalars and
    its bodies' (sin, cos) (sa, ca), (sb, cb)."""
    rax, ray = _turned(lax, lay, sa, ca)
    rbx, rby = _turned(lbx, lby, sb, cb)
    dx = position[b, 0] + rbx - position[a, 0] - rax
    dy = position[b, 1] + rby - position[a, 1] - ray
    if kind == REVOLUTE:
        return np.sqrt(dx * dx + dy * dy), 0.0
    q = _wrap(angle[b] - angle[a] - reference)
    if kind == WELD:
        return np.sqrt(dx * dx + dy * dy), 0.0 if spring else q
    if kind == DISTANCE:
        d = np.sqrt(dx * dx + dy * dy)
        if rigid:
            return abs(d - length), 0.0
        if d < lower:
            return lower - d, 0.0
        if d > upper:
            return d - upper, 0.0
        return 0.0, 0.0
    ux = ca * axis_x - sa * axis_y
    uy = sa * axis_x + ca * axis_y
    return abs(-uy * dx + ux * dy), q


@numba.njit(cache=True, nogil=True, _nrt=False)  # (no reference counts: see NO_COUNTS)
def keep_joint_impulses(jt, carry):
    """The accumulated impulses (J0 .. JU) into carry (m, JOINT_IMPULSES), for the next
    sub-step's warm start (zeros for an inactive joint)."""
    for k in range(jt.shape[0]):
        for c in range(JOINT_IMPULSES):
            carry[k, c] = jt[k, J0 + c]


@numba.njit(cache=True, nogil=True)
def write_joint_rows(
    J, jt, position, angle, exists, error, anchor_a, anchor_b, linear, angular, motor, limit,
    impulses, error_out,
):  # fmt: skip
    """One step's `isaac.engine.records.JointRows` fields (m, ...) from the last sub-step's
    scratch (impulses, axes) and the final poses (anchors), `error` from the position pass."""
    rot = _rotations(J, angle, exists)
    _write_rows(
        J, jt, rot, position, angle, exists, error, anchor_a, anchor_b, linear, angular, motor,
        limit, impulses, error_out,
    )  # fmt: skip


@numba.njit(cache=True, nogil=True, _nrt=False)  # (no reference counts: see NO_COUNTS)
def _write_rows(
    J, jt, rot, position, angle, exists, error, anchor_a, anchor_b, linear, angular, motor, limit,
    impulses, error_out,
):  # fmt: skip
    """`write_joint_rows`' loop, with the bodies' (sin, cos) `rot` (`_rotations`)."""
    for k in range(J.kind.shape[0]):
        t = jt[k]
        for c in range(JOINT_IMPULSES):
            impulses[k, c] = t[J0 + c]
        error_out[k, 0] = error[k, 0]
        error_out[k, 1] = error[k, 1]
        a = J.a[k]
        b = J.b[k]
        for c in range(2):
            anchor_a[k, c] = 0.0
            anchor_b[k, c] = 0.0
            linear[k, c] = 0.0
        angular[k] = 0.0
        motor[k] = t[JM]
        limit[k] = t[JL] - t[JU]
        if t[ON] == 0.0 or not (exists[a] and exists[b]):
            continue
        sa, ca = _sin_cos_of(rot, angle, a)
        sb, cb = _sin_cos_of(rot, angle, b)
        rax, ray = _turned(J.local_a[k, 0], J.local_a[k, 1], sa, ca)
        rbx, rby = _turned(J.local_b[k, 0], J.local_b[k, 1], sb, cb)
        anchor_a[k, 0] = position[a, 0] + rax
        anchor_a[k, 1] = position[a, 1] + ray
        anchor_b[k, 0] = position[b, 0] + rbx
        anchor_b[k, 1] = position[b, 1] + rby
        kind = J.kind[k]
        if kind == REVOLUTE or kind == WELD:
            linear[k, 0] = t[J0]
            linear[k, 1] = t[J1]
            angular[k] = t[J2]
        elif kind == DISTANCE:
            linear[k, 0] = t[J2] * t[UX]
            linear[k, 1] = t[J2] * t[UY]
        else:
            linear[k, 0] = t[J0] * t[PX]
            linear[k, 1] = t[J0] * t[PY]
            angular[k] = t[J1]
