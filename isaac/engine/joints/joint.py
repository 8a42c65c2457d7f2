"""The joint table and the per-joint loops of each phase, which dispatch on the joint's kind
(Box2D v3's joint.c: b2PrepareJointsTask, b2WarmStartJoint, b2SolveJoint, b2GetJointReaction;
each kind's arithmetic in its own module beside this one).

The phases, each a loop over the joints that calls the kind's function (inlined):
1. `prepare_joints`: the world anchor arms r = R(angle) local, the separation, and the kind's
   axes, effective masses, limits' margins and springs' soft coefficients, from the poses
   after the push-out; the accumulated impulses loaded (warm starting) or zeroed;
2. `warm_start_joints`: those impulses applied first (as contacts' are);
3. `solve_joint_velocities`: one Gauss-Seidel pass over the joints, between the contact passes
   (each velocity iteration: the contacts' pass, then the joints'), accumulating impulses;
4. `correct_joint_positions`, after integration (Box2D 2.3's non-linear Gauss-Seidel,
   b2Joint::SolvePositionConstraints): `iterations` passes moving the bodies back onto their
   rigid constraints, each correction capped, then each joint's remaining error;
5. `keep_joint_impulses` (the next sub-step's warm start) and `write_joint_rows` (a step's
   `isaac.engine.records.JointRows`).
A joint whose two bodies do not both exist does nothing.

The joint table (Joints) holds the scene's joints as arrays; the scratch `jt` (m, WIDTH) one row
per joint, its columns named in `isaac.engine.joints.shared`; the accumulated impulses are
columns J0 .. JU (the warm start carry, `JOINT_IMPULSES` of them).
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from isaac.engine import kernel_cache  # noqa: F401  (first: keys the kernels' numba cache)
from isaac.engine.geometry import sin_cos
from isaac.engine.joints.distance import (
    correct_distance,
    distance_error,
    distance_reaction,
    prepare_distance,
    solve_distance,
    warm_start_distance,
)
from isaac.engine.joints.prismatic import (
    correct_prismatic,
    prepare_prismatic,
    prismatic_error,
    prismatic_reaction,
    solve_prismatic,
    warm_start_prismatic,
)
from isaac.engine.joints.revolute import (
    correct_revolute,
    point_error,
    point_reaction,
    prepare_revolute,
    solve_revolute,
    warm_start_point,
)
from isaac.engine.joints.shared import (
    DX,
    DY,
    J0,
    JL,
    JM,
    JOINT_IMPULSES,
    JU,
    KA,
    ON,
    RAX,
    RAY,
    RBX,
    RBY,
    WIDTH,
    inv_or_zero,
    turned,
    wrap,
)
from isaac.engine.joints.weld import correct_weld, prepare_weld, solve_weld, weld_error

REVOLUTE = 0
DISTANCE = 1
WELD = 2
PRISMATIC = 3
KIND_CODES = {"revolute": REVOLUTE, "distance": DISTANCE, "weld": WELD, "prismatic": PRISMATIC}


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


# The per-joint loops below are compiled without reference counting (`_nrt=False`: they
# allocate nothing and return no array; isaac.engine.joints.shared says what it saves); the
# kernels that allocate (`_rotations`' table) call them.


@numba.njit(cache=True, nogil=True)
def prepare_joints(J, jt, position, angle, exists, inv_mass, inv_inertia, h, warm, warm_starting):
    """Fill the scratch rows for this sub-step (poses after the push-out) and load the
    accumulated impulses: `warm` (m, JOINT_IMPULSES), last sub-step's, when warm_starting
    (else they start from zero)."""
    rot = _rotations(J, angle, exists)
    _prepare_rows(
        J, jt, rot, position, angle, exists, inv_mass, inv_inertia, h, warm, warm_starting
    )


@numba.njit(cache=True, nogil=True, _nrt=False)
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
        rax, ray = turned(local_a[k, 0], local_a[k, 1], sa, ca)
        rbx, rby = turned(local_b[k, 0], local_b[k, 1], sb, cb)
        t[RAX] = rax
        t[RAY] = ray
        t[RBX] = rbx
        t[RBY] = rby
        ma = inv_mass[a]
        ia = inv_inertia[a]
        mb = inv_mass[b]
        ib = inv_inertia[b]
        t[KA] = inv_or_zero(ia + ib)
        dx = position[b, 0] + rbx - position[a, 0] - rax
        dy = position[b, 1] + rby - position[a, 1] - ray
        t[DX] = dx
        t[DY] = dy
        masses = (ma, ia, mb, ib)
        arms = (rax, ray, rbx, rby)
        kind = J.kind[k]
        if kind == REVOLUTE or kind == WELD:
            q = wrap(angle[b] - angle[a] - J.reference_angle[k])
            if kind == REVOLUTE:
                prepare_revolute(J, k, t, q, masses, arms)
            else:
                prepare_weld(J, k, t, h, q, masses, arms)
        elif kind == DISTANCE:
            prepare_distance(J, k, t, h, dx, dy, masses, arms)
        else:
            prepare_prismatic(J, k, t, dx, dy, sa, ca, masses, arms)
        if warm_starting:
            for c in range(JOINT_IMPULSES):
                t[J0 + c] = warm[k, c]


@numba.njit(cache=True, nogil=True, _nrt=False)
def warm_start_joints(J, jt, v, inv):
    """Apply every active joint's loaded impulses (last sub-step's) to the velocities v (n, 3)
    (inverse masses and inertias inv (n, 2))."""
    for k in range(J.kind.shape[0]):
        t = jt[k]
        if t[ON] == 0.0:
            continue
        a = J.a[k]
        b = J.b[k]
        kind = J.kind[k]
        if kind == REVOLUTE or kind == WELD:
            warm_start_point(t, v, inv, a, b)
        elif kind == DISTANCE:
            warm_start_distance(t, v, inv, a, b)
        else:
            warm_start_prismatic(t, v, inv, a, b)


@numba.njit(cache=True, nogil=True, _nrt=False)
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
        if kind == REVOLUTE:
            solve_revolute(J, k, t, v, inv, a, b, h, inv_h)
        elif kind == WELD:
            solve_weld(J, k, t, v, inv, a, b, h, inv_h)
        elif kind == DISTANCE:
            solve_distance(J, k, t, v, inv, a, b, h, inv_h)
        else:
            solve_prismatic(J, k, t, v, inv, a, b, h, inv_h)


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


@numba.njit(cache=True, nogil=True, _nrt=False)
def _correct_passes(J, position, angle, exists, inv_mass, inv_inertia, iterations):
    """`correct_joint_positions`' passes."""
    for _ in range(iterations):
        for k in range(J.kind.shape[0]):
            a = J.a[k]
            b = J.b[k]
            if not (exists[a] and exists[b]):
                continue
            kind = J.kind[k]
            if kind == REVOLUTE:
                correct_revolute(J, k, a, b, position, angle, inv_mass, inv_inertia)
            elif kind == WELD:
                correct_weld(J, k, a, b, position, angle, inv_mass, inv_inertia)
            elif kind == DISTANCE:
                correct_distance(J, k, a, b, position, angle, inv_mass, inv_inertia)
            else:
                correct_prismatic(J, k, a, b, position, angle, inv_mass, inv_inertia)


@numba.njit(cache=True, nogil=True, _nrt=False)
def _errors(J, rot, position, angle, exists, error):
    """`correct_joint_positions`' remaining errors, with the bodies' (sin, cos) `rot`."""
    local_a = J.local_a
    local_b = J.local_b
    for k in range(J.kind.shape[0]):
        a = J.a[k]
        b = J.b[k]
        error[k, 0] = 0.0
        error[k, 1] = 0.0
        if not (exists[a] and exists[b]):
            continue
        sa, ca = _sin_cos_of(rot, angle, a)
        sb, cb = _sin_cos_of(rot, angle, b)
        rax, ray = turned(local_a[k, 0], local_a[k, 1], sa, ca)
        rbx, rby = turned(local_b[k, 0], local_b[k, 1], sb, cb)
        dx = position[b, 0] + rbx - position[a, 0] - rax
        dy = position[b, 1] + rby - position[a, 1] - ray
        kind = J.kind[k]
        if kind == REVOLUTE:
            error[k, 0], error[k, 1] = point_error(dx, dy)
        elif kind == DISTANCE:
            error[k, 0], error[k, 1] = distance_error(J, k, dx, dy)
        else:
            q = wrap(angle[b] - angle[a] - J.reference_angle[k])
            if kind == WELD:
                error[k, 0], error[k, 1] = weld_error(J, k, dx, dy, q)
            else:
                error[k, 0], error[k, 1] = prismatic_error(J, k, dx, dy, q, sa, ca)


@numba.njit(cache=True, nogil=True, _nrt=False)
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


@numba.njit(cache=True, nogil=True, _nrt=False)
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
        rax, ray = turned(J.local_a[k, 0], J.local_a[k, 1], sa, ca)
        rbx, rby = turned(J.local_b[k, 0], J.local_b[k, 1], sb, cb)
        anchor_a[k, 0] = position[a, 0] + rax
        anchor_a[k, 1] = position[a, 1] + ray
        anchor_b[k, 0] = position[b, 0] + rbx
        anchor_b[k, 1] = position[b, 1] + rby
        kind = J.kind[k]
        if kind == REVOLUTE or kind == WELD:
            linear[k, 0], linear[k, 1], angular[k] = point_reaction(t)
        elif kind == DISTANCE:
            linear[k, 0], linear[k, 1], angular[k] = distance_reaction(t)
        else:
            linear[k, 0], linear[k, 1], angular[k] = prismatic_reaction(t)
