"""The compiled driver: whole steps, many per call, without returning to Python.

`run_steps_sequential` and `run_steps_seed` advance the world by k steps (every sub-step of
each: geometry, broad phase, narrow phase, push-out, impulses, integration; existence changes
at their times; the divergence check after each step). They call the same stage kernels, in
the same order, as `isaac.engine.step.substep`, so every path gives the same bits. Two drivers,
one per solver, so that a run compiles only the solver it uses (numba types every branch of a
function, and the sequential solver is most of the compile time); and `run_steps_sequential_joints`
for a scene with joints, so that every other scene's driver never types, compiles or links the
joints' kernels (nor the solver's joint passes: `solve_sequential` on joints None), a third of
the driver's code and its first compile (the default scene's first run: bench/README.md).

Arguments are named bundles of arrays (`Bodies`, `Pose`, `Scratch`, `Carry`, `Settings`,
`Batch`), crossed into compiled code once per call: their cost is paid per batch of steps,
not per stage (and little even then: see below).

When a step finds more candidate pairs than the scratch holds, or more contact rows than the
batch has room for, the call puts that step's starting state back and returns, saying how
much room it needs (`NEED_PAIRS`, `NEED_ROWS`, and `NEED_TABLE` when the sequential solver's
scratch is too small); the caller grows the buffers and calls again from that step, so it is
computed afresh from its starting state. Buffer sizes never change a result (tests compare a
run that grew mid-batch with one sized generously from the start).

Reference counts. numba counts the references to an array with an atomic update (an NRT_incref
and an NRT_decref, each some 10-20 ns here) whenever a function names an array and then calls
another kernel while the name lives, or has more than one way out (an early return, a guard
around its body): a bundle's field read (`work.pair_a`), a tuple unpacked, an argument. So the
driver names every array once, at the top of a call, and calls the stage kernels with those
names inside the loop (a bundle's field read inside the loop cost two updates a read, about 170
reads a sub-step: most of a small scene's step, head-on 4.7 us a step before); and the kernels
that allocate nothing and return no array (geometry, broad and narrow phase, push-out,
integration, the divergence check, the helpers below) are compiled with numba's `_nrt=False`,
without reference counting at all (push_out with 2 rows: 213 -> 104 ns a call). The sub-step
also skips the narrow phase, push-out and solver when there is nothing for them (no pairs, no
rows): they would do nothing, and a call still paid its counts.

Python crosses into a driver with one object (`isaac.engine.driver_kit`'s call kit: the
bundles that live as long as the buffers, the pose and the batch; a pointer to unbox, where
their arrays as tuples cost 16 us a call on pile-100, and three objects 1.6 against 0.7 us).
Inside, the bundles are plain tuples of their fields (numba types a plain tuple through its
fast path, a namedtuple through a slow one: 4.1 against 2.4 us for twelve arrays).

`run_steps_sequential_timed` and `run_steps_seed_timed` are the same drivers with a clock read
(`isaac.engine.clock`) between the stages, adding each stage's time up in an array
(`isaac run --profile`); compiled apart, so the plain drivers carry no clock read. The clock
only reads the time: the timed drivers give the same bits.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from isaac.engine import kernel_cache  # noqa: F401  (first: keys the kernels' numba cache)
from isaac.engine.broad_phase import find_pairs, speculative_reach
from isaac.engine.clock import monotonic_ns
from isaac.engine.driver_kit import BatchCall, KitFields, make_call_kit, make_kit
from isaac.engine.geometry import transform
from isaac.engine.integrate import (
    DIVERGED_ANGLE,
    DIVERGED_POSITION,
    DIVERGED_SPEED,
    add_gravity,
    advance_positions,
    first_diverged,
)
from isaac.engine.joints import (
    JOINT_IMPULSES,
    Joints,
    correct_joint_positions,
    keep_joint_impulses,
    prepare_joints,
    write_joint_rows,
)
from isaac.engine.narrow_phase import collide_pairs, match_previous
from isaac.engine.push_out import push_out
from isaac.engine.records import CONTACT_FIELDS, StepBatch, StepRecord
from isaac.engine.solver.seed import solve_seed
from isaac.engine.solver.sequential import grown_scratch, solve_sequential
from isaac.engine.step_slots import StepSlot


class Bodies(NamedTuple):
    """What never changes during a run, per body (from `isaac.engine.world.Model`)."""

    vertices_local: np.ndarray  # (n, V, 2) m, body frame
    normals_local: np.ndarray  # (n, V, 2) unit, body frame
    vertex_count: np.ndarray  # (n,) int64
    radius: np.ndarray  # (n,) m, the seed's MaxDist
    thickness: np.ndarray  # (n,) m
    inv_mass: np.ndarray  # (n,) 1/kg, 0 for concrete bodies
    inv_inertia: np.ndarray  # (n,) 1/(kg m^2)
    restitution: np.ndarray  # (n,)
    friction: np.ndarray  # (n,)
    movable: np.ndarray  # (n,) bool, not concrete
    enters_at: np.ndarray  # (n,) s
    leaves_at: np.ndarray  # (n,) s, inf when never
    category: np.ndarray  # (n,) int64, the collision filter (isaac.collision_filter)
    mask: np.ndarray  # (n,) int64
    group: np.ndarray  # (n,) int64
    sweeps: np.ndarray  # (n,) bool, False: the filter keeps it from every other body
    no_collide: np.ndarray  # (p,) int64 sorted keys a * n + b of pairs joints keep apart
    joints: tuple  # `isaac.engine.joints.Joints`'s fields (m rows; none: m = 0)
    joint_waves: tuple  # the same in the position passes' order (`joints.in_waves`)


class Pose(NamedTuple):
    """The evolving state, updated in place (`isaac.engine.world.State`'s arrays)."""

    position: np.ndarray  # (n, 2) m, world
    angle: np.ndarray  # (n,) rad, counter-clockwise, wrapped to [-pi, pi]
    velocity: np.ndarray  # (n, 2) m/s
    angular_velocity: np.ndarray  # (n,) rad/s
    exists: np.ndarray  # (n,) bool


class Scratch(NamedTuple):
    """A sub-step's working arrays: world geometry, candidate pairs and contact rows (the field
    meanings of `isaac.engine.records.Contacts`)."""

    vertices: np.ndarray  # (n, V, 2) m, world
    normals: np.ndarray  # (n, V, 2)
    aabb: np.ndarray  # (n, 4) m
    expand: np.ndarray  # (n,) m, speculative reach
    pair_a: np.ndarray  # (pairs,) int64
    pair_b: np.ndarray
    pair_spare: np.ndarray  # the broad phase's scratch (`find_pairs`)
    sweep_index: np.ndarray
    sweep_key: np.ndarray
    sweep_table: np.ndarray
    push_start: np.ndarray  # (n, 2) m, push-out's scratch
    a: np.ndarray  # (2 pairs,) int32
    b: np.ndarray
    feature: np.ndarray
    slot: np.ndarray
    point: np.ndarray  # (2 pairs, 2) m
    normal: np.ndarray
    depth: np.ndarray  # m
    pair_depth: np.ndarray
    previous: np.ndarray  # int64
    push_a: np.ndarray  # (2 pairs, 2) m
    push_b: np.ndarray
    impulse: np.ndarray  # N s
    tangent: np.ndarray
    restitution: np.ndarray
    joint_scratch: np.ndarray  # (m, isaac.engine.joints.WIDTH)
    joint_error: np.ndarray  # (m, 2) m, rad: what the position pass left


class Carry(NamedTuple):
    """The last sub-step's contacts, which the next one reads (axis hysteresis, warm starting):
    `isaac.engine.step.ContactCache`'s arrays at some capacity; the first `count` are valid."""

    key: np.ndarray  # int64 a * n + b, ascending
    feature: np.ndarray  # int32
    slot: np.ndarray  # int32
    impulse: np.ndarray  # N s
    tangent: np.ndarray
    joint: np.ndarray  # (m, JOINT_IMPULSES) the joints' accumulated impulses (always all valid)


class Settings(NamedTuple):
    """`isaac.engine.step.StepSettings` as the driver reads it (plain numbers)."""

    gx: float  # m/s^2
    gy: float
    h: float  # s, sub-step
    dt: float  # s, step
    substeps: int
    explicit: bool
    iterations: int
    warm_starting: bool
    two_points: bool
    correction_mode: int
    slop: float
    correction: float
    position_iterations: int
    restitution_rule: int
    restitution_threshold: float
    friction_on: bool
    friction_rule: int
    gravity_dv: np.ndarray  # (2,) m/s
    look_ahead: float
    gravity_reach: float
    hysteresis: bool
    timed: bool
    filtered: bool  # whether any body has a collision filter (else none is tested)


class Batch(NamedTuple):
    """What each step of a call produced (when asked to record): the state after step s at
    [s], and the contact rows of step s (every sub-step, in order) at rows[offsets[s]:
    offsets[s + 1]]. Row fields as in `isaac.engine.records.Contacts`."""

    position: np.ndarray  # (k, n, 2)
    angle: np.ndarray  # (k, n)
    velocity: np.ndarray  # (k, n, 2)
    angular_velocity: np.ndarray  # (k, n)
    exists: np.ndarray  # (k, n) bool
    offsets: np.ndarray  # (k + 1,) int64
    substep: np.ndarray  # (rows,) int32
    a: np.ndarray
    b: np.ndarray
    feature: np.ndarray
    slot: np.ndarray
    point: np.ndarray  # (rows, 2)
    normal: np.ndarray
    depth: np.ndarray  # m, the point's own penetration
    pair_depth: np.ndarray  # m, the pair's MTD depth
    push_a: np.ndarray
    push_b: np.ndarray
    impulse: np.ndarray
    tangent: np.ndarray
    restitution: np.ndarray
    # the joints at the end of step s at [s] (`isaac.engine.records.JointRows`' fields)
    joint_anchor_a: np.ndarray  # (k, m, 2)
    joint_anchor_b: np.ndarray
    joint_linear: np.ndarray  # (k, m, 2)
    joint_angular: np.ndarray  # (k, m)
    joint_motor: np.ndarray
    joint_limit: np.ndarray
    joint_error: np.ndarray  # (k, m, 2)
    joint_impulses: np.ndarray  # (k, m, JOINT_IMPULSES)


# the Batch fields that hold contact rows (grown when a step makes more rows)
ROW_FIELDS = slice(6, 6 + len(CONTACT_FIELDS))

# what a call ended with (the first value it returns)
DONE = 0  # every step asked for was taken
DIVERGED = 1  # a step diverged: it was undone, and `body`, `field` say where
NEED_PAIRS = 2  # a step found more candidate pairs than the scratch holds: undone
NEED_ROWS = 3  # a step made more contact rows than the batch holds: undone
NEED_TABLE = 4  # the sequential solver's scratch (`Workspace.solver_table`) is too small: undone

# what the timed driver (`isaac run --profile`) adds up, in clock[1 + stage] (ns; clock[0]: the
# whole call): the stages of `isaac.engine.step`, and the driver's own work (saving each step's
# start to undo it, carrying contacts to the next sub-step, existence and the divergence check,
# copying states and rows into the batch)
STAGES = (
    "geometry",
    "broad phase",
    "narrow phase",
    "push-out",
    "impulses",
    "integration",
    "driver",
)
GEOMETRY, BROAD_PHASE, NARROW_PHASE, PUSH_OUT, IMPULSES, INTEGRATION, DRIVER = range(len(STAGES))


@numba.njit(cache=True, nogil=True, inline="always")
def _lap(clock, stage, since):
    """Add the time since `since` (ns) to a stage's total; returns now."""
    now = monotonic_ns()
    clock[1 + stage] += now - since
    return now


# The small helpers below take bundles as plain tuples and name their fields inside (no
# reference counting: see the module docstring).


@numba.njit(cache=True, nogil=True, _nrt=False)  # (no reference counts: see driver)
def carry_over(work, rows, n, carry):
    """This sub-step's rows as the next one's Carry (it has the scratch's row capacity);
    returns the count. The key is `isaac.engine.step.ContactCache`'s: a * n + b."""
    w = Scratch(*work)
    c = Carry(*carry)
    for k in range(rows):
        c.key[k] = np.int64(w.a[k]) * n + w.b[k]
        c.feature[k] = w.feature[k]
        c.slot[k] = w.slot[k]
        c.impulse[k] = w.impulse[k]
        c.tangent[k] = w.tangent[k]
    return rows


@numba.njit(cache=True, nogil=True, _nrt=False)  # (no reference counts: see driver)
def keep_rows(batch, at, work, rows, substep):
    """Append a sub-step's contact rows to the batch at row `at`; returns the new end, or -1
    (nothing written) when they do not fit."""
    b = Batch(*batch)
    w = Scratch(*work)
    fits = at + rows <= b.a.shape[0]
    for k in range(rows if fits else 0):
        q = at + k
        b.substep[q] = substep
        b.a[q] = w.a[k]
        b.b[q] = w.b[k]
        b.feature[q] = w.feature[k]
        b.slot[q] = w.slot[k]
        b.point[q, 0] = w.point[k, 0]
        b.point[q, 1] = w.point[k, 1]
        b.normal[q, 0] = w.normal[k, 0]
        b.normal[q, 1] = w.normal[k, 1]
        b.depth[q] = w.depth[k]
        b.pair_depth[q] = w.pair_depth[k]
        b.push_a[q, 0] = w.push_a[k, 0]
        b.push_a[q, 1] = w.push_a[k, 1]
        b.push_b[q, 0] = w.push_b[k, 0]
        b.push_b[q, 1] = w.push_b[k, 1]
        b.impulse[q] = w.impulse[k]
        b.tangent[q] = w.tangent[k]
        b.restitution[q] = w.restitution[k]
    return at + rows if fits else -1


@numba.njit(cache=True, nogil=True, _nrt=False)  # (no reference counts: see driver)
def _set_existence(enters_at, leaves_at, exists, time):
    """Which bodies exist at `time` (s): enters_at <= time < leaves_at."""
    for i in range(exists.shape[0]):
        exists[i] = enters_at[i] <= time and time < leaves_at[i]


# (element loops, not slice assignments: numba's broadcasting setitem made these few lines
# cost 12 s of LLVM time to compile)
@numba.njit(cache=True, nogil=True, _nrt=False)  # (no reference counts: see driver)
def _keep_state(batch, s, pose, at):
    b = Batch(*batch)
    p = Pose(*pose)
    for i in range(p.position.shape[0]):
        b.position[s, i, 0] = p.position[i, 0]
        b.position[s, i, 1] = p.position[i, 1]
        b.angle[s, i] = p.angle[i]
        b.velocity[s, i, 0] = p.velocity[i, 0]
        b.velocity[s, i, 1] = p.velocity[i, 1]
        b.angular_velocity[s, i] = p.angular_velocity[i]
        b.exists[s, i] = p.exists[i]
    b.offsets[s + 1] = at


@numba.njit(cache=True, nogil=True)
def _keep_joints(batch, s, joints, pose, jt, error):
    b = Batch(*batch)
    p = Pose(*pose)
    write_joint_rows(
        joints,
        jt,
        p.position,
        p.angle,
        p.exists,
        error,
        b.joint_anchor_a[s],
        b.joint_anchor_b[s],
        b.joint_linear[s],
        b.joint_angular[s],
        b.joint_motor[s],
        b.joint_limit[s],
        b.joint_impulses[s],
        b.joint_error[s],
    )


@numba.njit(cache=True, nogil=True, _nrt=False)  # (no reference counts: see driver)
def _copy_pose(pose, into):
    p = Pose(*pose)
    q = Pose(*into)
    for i in range(p.position.shape[0]):
        q.position[i, 0] = p.position[i, 0]
        q.position[i, 1] = p.position[i, 1]
        q.angle[i] = p.angle[i]
        q.velocity[i, 0] = p.velocity[i, 0]
        q.velocity[i, 1] = p.velocity[i, 1]
        q.angular_velocity[i] = p.angular_velocity[i]
        q.exists[i] = p.exists[i]


@numba.njit(cache=True, nogil=True, _nrt=False)  # (no reference counts: see driver)
def _copy_carry(carry, into, count):
    c = Carry(*carry)
    d = Carry(*into)
    for k in range(count):
        d.key[k] = c.key[k]
        d.feature[k] = c.feature[k]
        d.slot[k] = c.slot[k]
        d.impulse[k] = c.impulse[k]
        d.tangent[k] = c.tangent[k]
    for k in range(c.joint.shape[0]):
        for m in range(c.joint.shape[1]):
            d.joint[k, m] = c.joint[k, m]


@numba.njit(cache=True, nogil=True, inline="always")
def _run_steps(
    seed, timed, jointed, bodies, cfg, pose, work, carry, saved_pose, saved_carry, batch, table,
    start, carried, first, k, record, clock,
):  # fmt: skip
    """The body of every driver (inlined into each, so that the constants `seed`, `timed` and
    `jointed` prune the solver a driver does not use, the clock reads of an untimed one and the
    joints' kernels of a scene without joints, before numba compiles it). The sub-step is
    `isaac.engine.step.substep`'s, stage for stage."""
    began = monotonic_ns() if timed else 0
    lap = began
    # every array a stage takes is named here, once a call, never inside the loop (a bundle's
    # field read there costs two atomic reference-count updates a read; see the module docstring)
    (
        vertices_local, normals_local, vertex_count, radius, thickness, inv_mass, inv_inertia,
        restitution, friction, movable, enters_at, leaves_at, category, mask, group, sweeps,
        no_collide, joint_fields, joint_wave_fields,
    ) = bodies  # fmt: skip
    position, angle, velocity, angular_velocity, exists = pose
    (
        vertices, normals, aabb, expand, pair_a, pair_b, pair_spare, sweep_index, sweep_key,
        sweep_table, push_start, c_a, c_b, c_feature, c_slot, c_point, c_normal, c_depth,
        c_pair_depth, c_previous, push_a, push_b, c_impulse, c_tangent, c_restitution,
        joint_scratch, joint_error,
    ) = work  # fmt: skip
    prev_key, prev_feature, prev_slot, prev_impulse, prev_tangent, joint_carry = carry
    joints = Joints(*joint_fields)
    joint_waves = Joints(*joint_wave_fields)
    gravity_dv = cfg.gravity_dv
    n = position.shape[0]
    n_joints = joint_scratch.shape[0]  # (0 whenever not `jointed`)
    no_error = np.empty((0, 2))  # what a sub-step whose joint errors are not logged gets
    at = Batch(*batch).offsets[start] if record else 0
    last_carried = carried
    for s in range(k):
        _copy_pose(pose, saved_pose)
        _copy_carry(carry, saved_carry, carried)
        step_carried = carried
        need = 0
        status = DONE
        if timed:
            lap = _lap(clock, DRIVER, lap)
        for index in range(cfg.substeps):
            # 1. geometry
            transform(
                position, angle, exists, vertices_local, normals_local, vertex_count, radius,
                vertices, normals, aabb,
            )  # fmt: skip
            if timed:
                lap = _lap(clock, GEOMETRY, lap)
            # 2. broad phase (when the pairs do not fit the scratch nothing has moved yet)
            speculative_reach(
                velocity, angular_velocity, radius, cfg.look_ahead, cfg.gravity_reach, expand
            )
            pairs = find_pairs(
                position, radius, aabb, expand, movable, exists, sweeps, cfg.filtered, category,
                mask, group, no_collide, pair_a, pair_b, pair_spare, sweep_index, sweep_key,
                sweep_table,
            )  # fmt: skip
            if timed:
                lap = _lap(clock, BROAD_PHASE, lap)
            if pairs > pair_a.shape[0]:
                status = NEED_PAIRS
                need = pairs
                break
            # 3. narrow phase (and which previous contact each row continues, for warm
            # starting); 4. push-out. (Not called without pairs, or rows: they would do
            # nothing, and a call costs the reference counts of its arrays.)
            rows = 0
            if pairs > 0:
                rows = collide_pairs(
                    pair_a, pair_b, pairs, vertices, normals, vertex_count, radius, velocity,
                    angular_velocity, cfg.look_ahead, cfg.gravity_reach, cfg.two_points,
                    cfg.hysteresis, prev_key[:carried], prev_feature[:carried], c_a, c_b,
                    c_feature, c_slot, c_point, c_normal, c_depth, c_pair_depth,
                )  # fmt: skip
            if rows > 0:
                match_previous(
                    rows, c_a, c_b, c_feature, c_slot, n, prev_key[:carried],
                    prev_feature[:carried], prev_slot[:carried], c_previous,
                )  # fmt: skip
            if timed:
                lap = _lap(clock, NARROW_PHASE, lap)
            if rows > 0:
                push_out(
                    rows, c_a, c_b, c_feature, c_slot, c_point, c_normal, c_pair_depth, inv_mass,
                    thickness, position, cfg.correction_mode, cfg.slop, cfg.correction,
                    cfg.position_iterations, push_a, push_b, push_start,
                )  # fmt: skip
            if timed:
                lap = _lap(clock, PUSH_OUT, lap)
            # 5. impulses (semi-implicit Euler: gravity first, so contacts see it), with the
            # joints
            if not cfg.explicit:
                add_gravity(velocity, movable, exists, cfg.gx, cfg.gy, cfg.h)
            if jointed and n_joints:
                prepare_joints(
                    joints, joint_scratch, position, angle, exists, inv_mass, inv_inertia, cfg.h,
                    joint_carry, cfg.warm_starting,
                )  # fmt: skip
            if seed and rows > 0:  # (without rows both solvers return at once)
                solve_seed(
                    rows, c_a, c_b, c_feature, c_slot, c_point, c_normal, c_depth, position,
                    velocity, angular_velocity, inv_mass, inv_inertia, gravity_dv, restitution,
                    friction, cfg.restitution_rule, cfg.friction_rule,
                    cfg.restitution_threshold, cfg.friction_on, cfg.h, c_impulse, c_tangent,
                    c_restitution, push_a, push_b,
                )  # fmt: skip
            elif not seed:
                # (the previous impulses whole: rows name their previous row by index)
                if jointed:
                    if rows > 0 or n_joints > 0:
                        need = solve_sequential(
                            rows, c_a, c_b, c_feature, c_slot, c_point, c_normal, c_depth,
                            c_previous, position, velocity, angular_velocity, inv_mass,
                            inv_inertia, gravity_dv, restitution, friction, cfg.restitution_rule,
                            cfg.friction_rule, cfg.restitution_threshold, cfg.friction_on,
                            cfg.iterations, cfg.warm_starting, cfg.h, prev_impulse, prev_tangent,
                            c_impulse, c_tangent, c_restitution, push_a, push_b, table,
                            joint_fields, joint_scratch,
                        )  # fmt: skip
                elif rows > 0:
                    # the solver's specialisation without the joints' code (solve_sequential)
                    need = solve_sequential(
                        rows, c_a, c_b, c_feature, c_slot, c_point, c_normal, c_depth, c_previous,
                        position, velocity, angular_velocity, inv_mass, inv_inertia, gravity_dv,
                        restitution, friction, cfg.restitution_rule, cfg.friction_rule,
                        cfg.restitution_threshold, cfg.friction_on, cfg.iterations,
                        cfg.warm_starting, cfg.h, prev_impulse, prev_tangent, c_impulse,
                        c_tangent, c_restitution, push_a, push_b, table, None, None,
                    )  # fmt: skip
                if need > 0:
                    status = NEED_TABLE
                    break
            if timed:
                lap = _lap(clock, IMPULSES, lap)
            # 6. integration (the seed's explicit Euler: gravity last), then the joints'
            # position pass
            advance_positions(position, angle, velocity, angular_velocity, movable, exists, cfg.h)
            if cfg.explicit:
                add_gravity(velocity, movable, exists, cfg.gx, cfg.gy, cfg.h)
            if jointed and n_joints:
                # the errors are computed only where they are logged: a recorded step's last
                # sub-step (`Stepper.redo_last` takes `advance`'s last step again to record it)
                logged = record and index == cfg.substeps - 1
                correct_joint_positions(
                    joints, joint_waves, position, angle, exists, inv_mass, inv_inertia,
                    cfg.position_iterations, joint_error if logged else no_error,
                )  # fmt: skip
            if timed:
                lap = _lap(clock, INTEGRATION, lap)
            # this sub-step's contacts are what the next one reads
            carried = carry_over(work, rows, n, carry)
            if jointed and n_joints:
                keep_joint_impulses(joint_scratch, joint_carry)
            if record:
                end = keep_rows(batch, at, work, rows, index)
                if end < 0:
                    status = NEED_ROWS
                    need = at + rows
                    break
                at = end
            if timed:
                lap = _lap(clock, DRIVER, lap)
        body = -1
        field = -1
        if status == DONE:
            # existence from time = step * dt (never a running sum), then the divergence check
            if cfg.timed:
                _set_existence(enters_at, leaves_at, exists, (first + s + 1) * cfg.dt)
            body, field = first_diverged(
                position, angle, velocity, angular_velocity, exists, DIVERGED_POSITION,
                DIVERGED_SPEED, DIVERGED_ANGLE,
            )  # fmt: skip
            if body >= 0:
                status = DIVERGED
        if status != DONE:
            _copy_pose(saved_pose, pose)
            _copy_carry(saved_carry, carry, step_carried)
            if timed:
                lap = _lap(clock, DRIVER, lap)
                clock[0] += lap - began
            return status, s, step_carried, body, field, need, step_carried
        if record:
            _keep_state(batch, start + s, pose, at)
            if jointed and n_joints:
                _keep_joints(batch, start + s, joints, pose, joint_scratch, joint_error)
        last_carried = step_carried
        if timed:
            lap = _lap(clock, DRIVER, lap)
    if timed:
        clock[0] += monotonic_ns() - began
    return DONE, k, carried, -1, -1, 0, last_carried


@numba.njit(cache=True, nogil=True)
def run_steps_sequential(call, start, carried, first, k, record):
    """Advance the pose by up to k steps from state index `first` with the sequential solver,
    writing the batch from index `start` when `record`.

    call: a call kit (`isaac.engine.driver_kit.make_call_kit`): the driver's kit (the bundles
    that live as long as the buffers: `Bodies`, `Settings`, `Scratch`, `Carry`, the `Pose` and
    `Carry` a step is undone to, the solver's table, the clock that only the timed drivers
    write), the pose (the `Pose` fields, a plain tuple) and the batch (the `Batch` fields);
    carried: how many Carry rows are valid. A scene without joints only
    (`run_steps_sequential_joints` otherwise): this driver never types, compiles or links the
    joints' kernels nor the solver's joint passes. Returns (status, steps taken, carried, body,
    field, rows or scratch entries needed, carried at the start of the last step): status
    DONE, or DIVERGED / NEED_PAIRS / NEED_ROWS / NEED_TABLE with the step that did it undone
    (body, field: `first_diverged`'s). On return the kit's `saved_pose` / `saved_carry` hold
    the start of the last step taken (or undone), which `Stepper.redo_last` computes again to
    record it."""
    kit = call.driver
    return _run_steps(
        False, False, False, kit.bodies, Settings(*kit.settings), call.pose, kit.scratch,
        kit.carry, kit.saved_pose, kit.saved_carry, call.arrays, kit.table, start, carried,
        first, k, record, kit.clock,
    )  # fmt: skip


@numba.njit(cache=True, nogil=True)
def run_steps_seed(call, start, carried, first, k, record):
    """`run_steps_sequential` with the seed's single-pass solver."""
    kit = call.driver
    return _run_steps(
        True, False, False, kit.bodies, Settings(*kit.settings), call.pose, kit.scratch,
        kit.carry, kit.saved_pose, kit.saved_carry, call.arrays, kit.table, start, carried,
        first, k, record, kit.clock,
    )  # fmt: skip


@numba.njit(cache=True, nogil=True)
def run_steps_sequential_timed(call, start, carried, first, k, record):
    """`run_steps_sequential` that also adds each stage's time to `clock` (ns: clock[0] the
    whole call, clock[1 + i] stage STAGES[i]); the same bits."""
    kit = call.driver
    return _run_steps(
        False, True, False, kit.bodies, Settings(*kit.settings), call.pose, kit.scratch,
        kit.carry, kit.saved_pose, kit.saved_carry, call.arrays, kit.table, start, carried,
        first, k, record, kit.clock,
    )  # fmt: skip


@numba.njit(cache=True, nogil=True)
def run_steps_seed_timed(call, start, carried, first, k, record):
    """`run_steps_seed` that also adds each stage's time to `clock`, as
    `run_steps_sequential_timed` does."""
    kit = call.driver
    return _run_steps(
        True, True, False, kit.bodies, Settings(*kit.settings), call.pose, kit.scratch,
        kit.carry, kit.saved_pose, kit.saved_carry, call.arrays, kit.table, start, carried,
        first, k, record, kit.clock,
    )  # fmt: skip


@numba.njit(cache=True, nogil=True)
def run_steps_sequential_joints(call, start, carried, first, k, record):
    """`run_steps_sequential` for a scene with joints: the joints' kernels and the solver's
    joint passes (the seed's solver has no joint rows: a scene with joints cannot choose it)."""
    kit = call.driver
    return _run_steps(
        False, False, True, kit.bodies, Settings(*kit.settings), call.pose, kit.scratch,
        kit.carry, kit.saved_pose, kit.saved_carry, call.arrays, kit.table, start, carried,
        first, k, record, kit.clock,
    )  # fmt: skip


@numba.njit(cache=True, nogil=True)
def run_steps_sequential_joints_timed(call, start, carried, first, k, record):
    """`run_steps_sequential_joints` that also adds each stage's time to `clock`, as
    `run_steps_sequential_timed` does."""
    kit = call.driver
    return _run_steps(
        False, True, True, kit.bodies, Settings(*kit.settings), call.pose, kit.scratch,
        kit.carry, kit.saved_pose, kit.saved_carry, call.arrays, kit.table, start, carried,
        first, k, record, kit.clock,
    )  # fmt: skip


def driver_kernel(seed_solver: bool, jointed: bool, timed: bool):
    """The driver a simulation calls: by its solver (the seed's or the sequential one), whether
    its scene has joints (a driver without the joints' code for every other scene), and whether
    it is timed (`isaac run --profile`)."""
    if jointed:
        return run_steps_sequential_joints_timed if timed else run_steps_sequential_joints
    if timed:
        return run_steps_seed_timed if seed_solver else run_steps_sequential_timed
    return run_steps_seed if seed_solver else run_steps_sequential


class Stepper:
    """One simulation's handle on the compiled driver: its bundles, built once, and the loop
    that grows a buffer and calls again when a step did not fit (Python, once per call or
    growth, never per stage)."""

    def __init__(self, model, settings, dt: float, work, *, timed: bool = False) -> None:
        """model: `isaac.engine.world.Model`; settings: `isaac.engine.step.StepSettings`;
        dt: the step (s); work: the simulation's `isaac.engine.step.Workspace`; timed: call the
        timed driver, which adds each stage's time up (`stage_seconds`)."""
        self.n = model.n_bodies
        self.dt = float(dt)
        self.work = work
        self.bodies = tuple(
            Bodies(
                model.vertices_local,
                model.normals_local,
                model.vertex_count,
                model.radius,
                model.thickness,
                model.inv_mass,
                model.inv_inertia,
                model.restitution,
                model.friction,
                work.movable,
                model.enters_at,
                model.leaves_at,
                model.category,
                model.mask,
                model.group,
                model.sweeps,
                model.no_collide,
                tuple(model.joints),
                tuple(model.joint_waves),
            )
        )
        s = settings
        self.settings = tuple(
            Settings(
                float(s.gx), float(s.gy), float(s.h), float(dt), int(s.substeps),
                bool(s.explicit), int(s.iterations), bool(s.warm_starting), bool(s.two_points),
                int(s.correction_mode), float(s.slop), float(s.correction),
                int(s.position_iterations), int(s.restitution_rule),
                float(s.restitution_threshold), bool(s.friction_on), int(s.friction_rule),
                np.asarray(s.gravity_dv, dtype=np.float64), float(s.look_ahead),
                float(s.gravity_reach), bool(s.hysteresis), bool(model.timed),
                bool(model.filtered),
            )
        )  # fmt: skip
        jointed = model.joints.kind.shape[0] > 0
        if s.seed_solver and jointed:
            raise ValueError(
                "the seed's solver has no joint rows: a scene with joints cannot use it"
            )
        self.kernel = driver_kernel(bool(s.seed_solver), jointed, timed)
        self.clock = np.zeros(1 + len(STAGES), dtype=np.int64)  # ns (the timed driver's)
        self.substeps = int(s.substeps)
        self._sized_for = -1
        self.kit = None  # the driver's kit (`isaac.engine.driver_kit`), made at the first call
        self._kit_table = None  # the solver's table the kit holds
        self.carried = 0
        self._last_start = None  # (state index, carried) of the saved pose and carry, or None
        self._empty_saved()
        self._fit()
        # what an unrecorded call writes nothing into, with its call kit
        self._empty_call = BatchCall(self.new_batch(0, 0))
        self._slots: list[StepSlot] = []  # the most recently used last
        self._held = None  # the last slot `_held_slot` made
        self._rows_per_step = 4 * self.n  # first guess at a batch's contact rows per step
        # called before compiled code gets a state whose arrays or step index it has not had
        # (`BatchCall.kit`; `Simulation` sets its check of the state's arrays)
        self.check_state = None

    def _fit(self) -> None:
        """(Re)build the scratch and carry tuples for the workspace's current capacity, and
        the kit when they or the solver's table (which the staged path grows too) changed."""
        w = self.work
        rows = w.a.shape[0]
        if rows == self._sized_for:
            return
        self.scratch = tuple(
            Scratch(
                w.vertices, w.normals, w.aabb, w.expand, w.pair_a, w.pair_b, w.pair_spare,
                w.sweep_index, w.sweep_key, w.sweep_table, w.push_start, w.a, w.b,
                w.feature, w.slot, w.point, w.normal, w.depth, w.pair_depth, w.previous,
                w.push_a, w.push_b, w.impulse, w.tangent, w.restitution, w.joint_scratch,
                w.joint_error,
            )
        )  # fmt: skip
        old = getattr(self, "carry", None)
        self._last_start = None  # the saved carry is rebuilt
        joints = w.joint_scratch.shape[0]
        self.carry = _carry_arrays(rows, joints)
        self.saved_carry = _carry_arrays(rows, joints)
        if old is not None:  # the valid rows go on (the workspace only grows past them)
            m = min(self.carried, rows)
            for new, kept in zip(self.carry[:-1], old[:-1]):
                new[:m] = kept[:m]
            self.carry[-1][:] = old[-1]
        self._sized_for = rows
        self.kit = None  # made again at the next call (`_current_kit`)

    def _current_kit(self):
        """The kit of the current buffers: made again after `_fit` rebuilt them or the solver's
        table was replaced (grown here, or by the staged path)."""
        if self.kit is None or self._kit_table is not self.work.solver_table:
            self.kit = self._kit(self.carry, self.saved_pose, self.saved_carry, self.clock)
            self._kit_table = self.work.solver_table
        return self.kit

    def _kit(self, carry, saved_pose, saved_carry, clock):
        return make_kit(
            KitFields(
                self.bodies, self.settings, self.scratch, carry, saved_pose, saved_carry,
                self.work.solver_table, clock,
            )
        )  # fmt: skip

    def set_carry(self, cache) -> None:
        """Take the `isaac.engine.step.ContactCache` the next step reads."""
        m = cache.key.shape[0]
        if m > self.work.a.shape[0]:
            self.work.grow((m + 1) // 2)
            self._fit()
        for into, values in zip(
            self.carry, (cache.key, cache.feature, cache.slot, cache.impulse, cache.tangent)
        ):
            into[:m] = values
        self.carry[-1][:] = cache.joints
        self.carried = m

    def cache_arrays(self, *, copy: bool = True) -> tuple:
        """The valid Carry rows: (key, feature, slot, impulse, tangent, joints); copies, or
        views for a reader that writes nothing and is done before the next call."""
        m = self.carried
        if not copy:
            return (*(a[:m] for a in self.carry[:-1]), self.carry[-1])
        return (*(a[:m].copy() for a in self.carry[:-1]), self.carry[-1].copy())

    def new_batch(self, k: int, rows: int | None = None) -> tuple:
        """A batch's arrays (`Batch`'s fields) with room for k steps and `rows` contact rows
        (default: the rows a step had lately, k times), the offsets zeroed."""
        batch = tuple(np.empty(shape, dtype) for shape, dtype in self.batch_layout(k, rows))
        batch[5][:] = 0
        return batch

    def batch_layout(self, k: int, rows: int | None = None) -> tuple:
        """The (shape, dtype) of each of `new_batch`'s arrays, in `Batch` order."""
        n = self.n
        m = self.work.joint_scratch.shape[0]
        rows = max(16, self._rows_per_step * k if rows is None else rows)
        f, i32 = _F64, _I32
        return (
            ((k, n, 2), f), ((k, n), f), ((k, n, 2), f), ((k, n), f), ((k, n), _BOOL),
            ((k + 1,), _I64),
            ((rows,), i32), ((rows,), i32), ((rows,), i32), ((rows,), i32), ((rows,), i32),
            ((rows, 2), f), ((rows, 2), f), ((rows,), f), ((rows,), f), ((rows, 2), f),
            ((rows, 2), f), ((rows,), f), ((rows,), f), ((rows,), f),
            ((k, m, 2), f), ((k, m, 2), f), ((k, m, 2), f), ((k, m), f), ((k, m), f),
            ((k, m), f), ((k, m, 2), f), ((k, m, JOINT_IMPULSES), f),
        )  # fmt: skip

    def recorded(self, state, k: int) -> tuple[StepBatch | None, int, int]:
        """Advance `state` by up to k steps, recorded into a `StepSlot` (`Simulation.run` and
        `batches`). Returns (the batch of the steps taken, or None when the first diverged and
        was undone; body or -1; field code).

        Why slots: a batch's arrays made afresh come from the kernel as pages it zeroes on first
        write (pile-100 `run` 86-88 us a step against 73-75 in reused arrays), and reusing a
        batch of tuples cost 12-20 us of Python a call (28 reference counts, 56 write flags, a
        `StepBatch`). A slot is reused once its reference counts say nothing holds it, and the
        most recently used free one is taken: the one still in the cache (pile-100 `run`, 16
        steps a batch: 69-70 us a step against 75-79 cycling through three). When none is
        free, the batch goes in the places after the last one handed out (`_held_slot`)."""
        slot, at = self._slot_for(k)
        taken, body, field, arrays = self.run(state, k, slot.arrays, slot.call, start=at)
        if not taken:
            return None, body, field
        first = state.step - taken + 1
        if self._used(slot, arrays, at + taken) is None:  # its rows outgrew the slot
            return StepBatch.of_places(first, self.dt, arrays, at, taken), body, field
        return slot.batch(first, taken, at), body, field

    def one_step(self, state) -> tuple[StepRecord | None, int, int]:
        """Advance `state` by one step, recorded into a slot (`Simulation.step()`). Returns
        (the step's record, or None when it diverged and was undone; body or -1; field code).

        The common case is one driver call and no more: the kit is current (`_current_kit`'s
        and `_fit`'s checks) and the step fits the buffers. A step that does not fit, or
        diverges, is undone by the driver, and `run`'s loop takes it again in the same place
        (growing the buffer, or stopping at the same body). (Without `run`'s loop a small
        scene's `step()` takes 0.3 us less, of about 5.3: head-on and off-centre, in-process
        A/B.)"""
        slot, at = self._slot_for(1)
        self._fit()  # `Simulation.detect` may have grown the workspace
        if self._call(state, slot.call, at, 1, True)[0] == DONE:
            arrays = slot.arrays
        else:
            taken, body, field, arrays = self.run(state, 1, slot.arrays, slot.call, start=at)
            if not taken:
                return None, body, field
        if self._used(slot, arrays, at + 1) is None:  # its rows outgrew the slot
            return StepBatch.of_places(state.step, self.dt, arrays, at, 1).record(0), -1, -1
        return slot.record(state.step, at), -1, -1

    def _slot_for(self, k: int) -> tuple[StepSlot, int]:
        """Where `recorded` writes k steps: (slot, the first step's place in it). The most
        recently used slot with room for k that nothing holds, else `_held_slot`'s."""
        for slot in reversed(self._slots):
            if slot.steps >= k and slot.free():
                return slot, 0
        return self._held_slot(k)

    def _held_slot(self, k: int) -> tuple[StepSlot, int]:
        """Where k steps go when no slot is free: (slot, the first step's place in it).

        The places after the last record or batch handed out from the last slot made here,
        while it has room: a caller that keeps everything (`[sim.step() for _ in range(n)]`,
        `list(sim.run(n))`) holds every slot, and a slot made a step cost 43 us (head-on
        `step()` 61 us against 4.8; `run` 4.6 against 2.0). What was handed out is the places
        before them, which are never written again. Else a new slot, with room for k rounded up
        to a power of two (a run's batches come in few sizes: a bench's warm-up `run(60)` then
        serves its timed `run(240)`'s batches of 64), or for twice the steps of the last one
        while everything handed out from that one is still held (up to `_APPEND_BYTES`): a
        caller that keeps one record or batch in two, three or ten pins at most about twice
        what it keeps."""
        held, steps = self._held, 1 << (k - 1).bit_length()
        if held is not None:
            if held.next_place + k <= held.steps:
                return held, held.next_place
            if held.records_held() >= held.handed:
                room = max(1, _APPEND_BYTES // held.bytes_per_step())
                steps = max(steps, min(2 * held.steps, 1 << (room.bit_length() - 1)))
        self._held = self._new_slot(steps)
        return self._held, 0

    def _used(self, slot: StepSlot, arrays: tuple, end: int) -> StepSlot | None:
        """After a call that recorded into `arrays`, `slot`'s or grown ones, up to place `end`:
        the slot as the most recently used, or dropped (None) when its rows were outgrown
        (later slots have room for the rows seen); the rows a step had, for the next slot's
        size. (A slot `one_step` fills may have left the list: it goes back in.)"""
        if not self._slots or self._slots[-1] is not slot or arrays is not slot.arrays:
            if slot in self._slots:
                self._slots.remove(slot)
            if arrays is slot.arrays:
                self._slots.append(slot)
                del self._slots[:-SPARE_BATCHES]
            else:
                slot.next_place = slot.steps  # (the grown arrays share its state arrays)
                slot = None
        if end:  # (a slot's rows start at row 0)
            self._rows_per_step = max(4, -(-int(arrays[5][end]) // end))
        return slot

    def _new_slot(self, steps: int) -> StepSlot:
        # room for the rows the last call's steps had, and half a step's more: the rows of a
        # pile come and go from step to step (a slot they outgrow is made again), and a batch of
        # many steps evens them out
        rows = max(16, self._rows_per_step * steps + self._rows_per_step // 2)
        slot = StepSlot(self.batch_layout(steps, rows), self.dt, BatchCall)
        self._slots.append(slot)
        del self._slots[:-SPARE_BATCHES]
        return slot

    def run(
        self, state, k: int, batch: tuple | None, call: BatchCall | None = None, start: int = 0
    ) -> tuple[int, int, int, tuple | None]:
        """Advance `state` (an `isaac.engine.world.State`) by up to k steps, recording into
        `batch` when it is given (from `new_batch(k)`; call: its `BatchCall` when the caller
        holds one, a `StepSlot`'s; start: the batch's place of the first step). Returns (steps
        taken, diverged body or -1, field code, the batch, possibly grown, or None). The loop
        grows a buffer and calls again when a step did not fit."""
        self._fit()  # `Simulation.detect` may have grown the workspace
        record = batch is not None
        if batch is None:
            call = self._empty_call
        elif call is None:
            call = BatchCall(batch)
        self._last_start = None
        taken = 0
        while True:
            status, done, body, field, need = self._call(
                state, call, start + taken, k - taken, record
            )
            taken += done
            if status == NEED_PAIRS:
                self.work.grow(need)
                self._fit()
            elif status == NEED_ROWS:
                batch = _grown_rows(batch, need)
                call = BatchCall(batch)
            elif status == NEED_TABLE:
                self.work.solver_table = grown_scratch(self.work.solver_table, need)
            else:
                return taken, body, field, batch if record else None

    def _call(self, state, call: BatchCall, start: int, k: int, record: bool):
        """One driver call of up to k steps from `state`, writing its batch (`call`'s) from
        index `start` when `record`; `state.step`, the carried rows and the start of the last
        step taken follow it. Returns (status, steps taken, body, field, needed)."""
        check = self.check_state
        try:
            step = state.step
        except AttributeError:  # (not a State: the check says so)
            step = None
        if type(step) is not int and check is not None:
            check()
            step = state.step
        status, done, carried, body, field, need, last_carried = self.kernel(
            call.kit(self._current_kit(), state, check), start, self.carried, step, k, record
        )
        self.carried = carried
        state.step += done
        if done and status == DONE:
            self._last_start = (state.step - 1, last_carried)
        return status, done, body, field, need

    def stage_seconds(self) -> dict[str, float]:
        """Seconds the timed driver spent in each of STAGES, and in all its calls ("total"),
        since this stepper was made (zeros when it is not timed)."""
        seconds = {stage: 1e-9 * int(self.clock[1 + i]) for i, stage in enumerate(STAGES)}
        seconds["total"] = 1e-9 * int(self.clock[0])
        return seconds

    def redo_last(self, state) -> tuple | None:
        """The batch (one step) of the last step the last `run` took, computed again from its
        starting state, which the driver left in the saved pose and carry: `Simulation.advance`
        records nothing, and pays for the last step's contacts only when they are asked for.
        None when that start is gone (nothing was taken, or the buffers changed since).
        Checks that the step lands on `state` bit for bit."""
        if self._last_start is None:
            return None
        first, carried = self._last_start
        pose = tuple(a.copy() for a in self.saved_pose)
        carry = tuple(a.copy() for a in self.saved_carry)
        spare_pose = tuple(np.empty_like(a) for a in pose)
        spare_carry = tuple(np.empty_like(a) for a in carry)
        batch = self.new_batch(1)
        while True:
            # (a step taken again is not the run's time: a clock of its own)
            kit = self._kit(carry, spare_pose, spare_carry, np.zeros_like(self.clock))
            status, _, _, _, _, need, _ = self.kernel(
                make_call_kit(batch, kit, pose), 0, carried, first, 1, True
            )
            if status == NEED_ROWS:
                batch = _grown_rows(batch, need)
                continue
            if status == NEED_TABLE:
                self.work.solver_table = grown_scratch(self.work.solver_table, need)
                continue
            break
        now = (state.position, state.angle, state.velocity, state.angular_velocity, state.exists)
        if status != DONE or not all(np.array_equal(a, b) for a, b in zip(pose, now)):
            raise RuntimeError("the last step, computed again, did not land on the same state")
        return batch

    def _empty_saved(self) -> None:
        n = self.n
        self.saved_pose = (
            np.empty((n, 2)), np.empty(n), np.empty((n, 2)), np.empty(n),
            np.empty(n, dtype=bool),
        )  # fmt: skip


def _carry_arrays(rows: int, joints: int) -> tuple:
    return (
        np.zeros(rows, dtype=np.int64),
        np.zeros(rows, dtype=np.int32),
        np.zeros(rows, dtype=np.int32),
        np.zeros(rows),
        np.zeros(rows),
        np.zeros((joints, JOINT_IMPULSES)),
    )


_F64, _I32, _I64, _BOOL = (np.dtype(t) for t in (np.float64, np.int32, np.int64, np.bool_))

# the slots a stepper keeps (`recorded`): a caller holds the last one or two while the next is
# written (the simulation its last record, a generator its batch)
SPARE_BATCHES = 3
# bytes of a slot `_held_slot` makes for a caller that keeps everything: what is left unused of
# the last is at most this (pile-100: 64 steps, pile-2000: 8, pile-10000: 1)
_APPEND_BYTES = 4 << 20


def _grown_rows(batch: tuple, needed: int) -> tuple:
    """The batch with room for at least `needed` contact rows (doubling), rows kept."""
    b = Batch(*batch)
    size = max(needed, 2 * b.a.shape[0])
    fields = list(batch)
    for i in range(ROW_FIELDS.start, ROW_FIELDS.stop):
        old = fields[i]
        new = np.empty((size, *old.shape[1:]), dtype=old.dtype)
        new[: old.shape[0]] = old
        fields[i] = new
    return tuple(fields)
