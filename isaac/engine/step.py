"""The step: one function that lists the stages in order.

Order of a step (each of `substeps` sub-steps of h = dt / substeps runs all of it):

1. geometry      world vertices, edge normals and boxes at the current pose
2. broad phase   candidate pairs: MaxDist circles and boxes, sort-and-sweep (broad_phase.py)
3. narrow phase  SAT: normal, MTD depth, contact points (narrow_phase.py)
4. push-out      separate each pair along the normal by the MTD, by inverse mass (push_out.py)
5. impulses      the seed's formula, or the sequential solver (impulse.py)
6. integration   positions and angles; gravity (integrate.py)

This is the seed's order (impulses, then integration with gravity) with the seed's implicit
detection made explicit. One departure, chosen by `integrator`: semi-implicit Euler puts gravity
into the velocities *before* the impulses (between 4 and 5), so a resting contact cancels gravity
in the same step instead of letting bodies sink for a step; the seed's explicit Euler keeps
gravity last. Existence (the seed's Exist) is evaluated from time = step * dt, never from a running
sum of dt: a body takes part in a step when it exists at the step's start.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from isaac.engine.broad_phase import SWEEP_INDEX_ROWS, find_pairs, speculative_reach
from isaac.engine.geometry import transform
from isaac.engine.integrate import add_gravity, advance_positions
from isaac.engine.joints import (
    JOINT_IMPULSES,
    correct_joint_positions,
    keep_joint_impulses,
    prepare_joints,
    write_joint_rows,
)
from isaac.engine.joints import WIDTH as JOINT_WIDTH
from isaac.engine.narrow_phase import collide_pairs, match_previous
from isaac.engine.push_out import FULL, NONE, PARTIAL, push_out
from isaac.engine.records import Contacts, JointRows
from isaac.engine.solver import RULE_CODES, solve_contacts
from isaac.engine.solver.schedule import GROUP_WIDTH, LANES
from isaac.engine.world import Model, State
from isaac.scene import WorldSettings

_CORRECTION = {"full": FULL, "partial": PARTIAL, "none": NONE}


@dataclass(frozen=True)
class StepSettings:
    """WorldSettings turned into the plain numbers the compiled kernels take."""

    gx: float
    gy: float
    h: float  # sub-step length (s)
    substeps: int
    explicit: bool
    seed_solver: bool
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
    gravity_dv: np.ndarray  # (2,) m/s gravity adds before the impulses (semi-implicit), else 0
    look_ahead: float  # s; 0 without ccd
    gravity_reach: float  # m a body can gain from gravity in one sub-step
    hysteresis: bool

    @staticmethod
    def of(world: WorldSettings) -> StepSettings:
        h = world.dt / world.substeps
        # determinism: sqrt of written-out products (IEEE exact rounding), not libm's hypot
        gx, gy = float(world.gravity[0]), float(world.gravity[1])
        g = math.sqrt(gx * gx + gy * gy)
        speculative = world.ccd == "speculative"
        return StepSettings(
            gx=float(world.gravity[0]),
            gy=float(world.gravity[1]),
            h=h,
            substeps=int(world.substeps),
            explicit=world.integrator == "explicit",
            seed_solver=world.solver == "seed",
            iterations=1 if world.solver == "seed" else int(world.iterations),
            warm_starting=bool(world.warm_starting) and world.solver != "seed",
            two_points=world.contact_points == 2,
            correction_mode=_CORRECTION[world.position_correction],
            slop=float(world.slop),
            correction=float(world.correction),
            position_iterations=int(world.position_iterations),
            restitution_rule=RULE_CODES[world.restitution_rule],
            restitution_threshold=float(world.restitution_threshold),
            friction_on=bool(world.friction),
            friction_rule=RULE_CODES[world.friction_rule],
            gravity_dv=(
                np.zeros(2)
                if world.integrator == "explicit"
                else np.array([world.gravity[0] * h, world.gravity[1] * h])
            ),
            look_ahead=h if speculative else 0.0,
            gravity_reach=g * h * h if speculative else 0.0,
            hysteresis=bool(world.axis_hysteresis),
        )


class Workspace:
    """Scratch arrays reused from step to step (grown when a step finds more pairs)."""

    def __init__(self, model: Model, pair_capacity: int = 256) -> None:
        n, width = model.vertices_local.shape[:2]
        self.vertices = np.zeros((n, width, 2))
        self.normals = np.zeros((n, width, 2))
        self.aabb = np.zeros((n, 4))
        self.expand = np.zeros(n)
        self.movable = ~model.concrete
        # the broad phase's and push-out's scratch (per body: a step allocates none of it)
        self.sweep_index = np.zeros((SWEEP_INDEX_ROWS, n + 1), dtype=np.int64)
        self.sweep_key = np.zeros(n)
        self.sweep_table = np.zeros((n, 8))
        self.push_start = np.zeros((n, 2))
        # the impulse solver's scratch, grown as it needs; made here with room for a few groups
        # (twice what they need, as the solver grows it), so that the first contact of a run
        # does not pay for it (head-on: 5-7 us in that step)
        self.solver_table = np.zeros(2 * (GROUP_WIDTH * min(n, 8) + 3 * LANES))
        m = model.joints.kind.shape[0]
        self.joint_scratch = np.zeros((m, JOINT_WIDTH))  # isaac.engine.joints' rows
        self.joint_error = np.zeros((m, 2))  # what the position pass left (m, rad)
        self._allocate(pair_capacity)

    def _allocate(self, pairs: int) -> None:
        self.pair_a = np.zeros(pairs, dtype=np.int64)
        self.pair_b = np.zeros(pairs, dtype=np.int64)
        self.pair_spare = np.zeros(pairs, dtype=np.int64)
        rows = 2 * pairs
        self.a = np.zeros(rows, dtype=np.int32)
        self.b = np.zeros(rows, dtype=np.int32)
        self.feature = np.zeros(rows, dtype=np.int32)
        self.slot = np.zeros(rows, dtype=np.int32)
        self.point = np.zeros((rows, 2))
        self.normal = np.zeros((rows, 2))
        self.depth = np.zeros(rows)
        self.pair_depth = np.zeros(rows)
        self.previous = np.zeros(rows, dtype=np.int64)
        self.push_a = np.zeros((rows, 2))
        self.push_b = np.zeros((rows, 2))
        self.impulse = np.zeros(rows)
        self.tangent = np.zeros(rows)
        self.restitution = np.zeros(rows)

    def grow(self, pairs: int) -> None:
        self._allocate(max(pairs, 2 * self.pair_a.shape[0]))

    def contacts(self, rows: int, substep: int) -> Contacts:
        """Private copies of the first `rows` contact rows."""
        return Contacts(
            substep=np.full(rows, substep, dtype=np.int32),
            a=self.a[:rows].copy(),
            b=self.b[:rows].copy(),
            feature=self.feature[:rows].copy(),
            slot=self.slot[:rows].copy(),
            point=self.point[:rows].copy(),
            normal=self.normal[:rows].copy(),
            depth=self.depth[:rows].copy(),
            pair_depth=self.pair_depth[:rows].copy(),
            push_a=self.push_a[:rows].copy(),
            push_b=self.push_b[:rows].copy(),
            impulse=self.impulse[:rows].copy(),
            tangent_impulse=self.tangent[:rows].copy(),
            restitution=self.restitution[:rows].copy(),
        )


@dataclass(frozen=True, eq=False)
class ContactCache:
    """Last sub-step's contacts, keyed for axis hysteresis and warm starting.

    key: (m,) int64 a * n + b, ascending; the other arrays are the matching Contacts fields.
    joints: (joints, JOINT_IMPULSES) the joints' accumulated impulses of the last sub-step
        (`JointRows.impulses`), which the next one warm-starts from.
    """

    key: np.ndarray
    feature: np.ndarray
    slot: np.ndarray
    impulse: np.ndarray
    tangent: np.ndarray
    joints: np.ndarray

    @staticmethod
    def of(contacts: Contacts, n_bodies: int, joints: np.ndarray) -> ContactCache:
        c = contacts
        if len(c) and c.substep[-1] != c.substep[0]:
            last = c.substep == c.substep[-1]
            c = Contacts(**{f: getattr(c, f)[last] for f in Contacts.__dataclass_fields__})
        key = c.a.astype(np.int64) * n_bodies + c.b
        return ContactCache(key, c.feature, c.slot, c.impulse, c.tangent_impulse, joints)


def detect(
    model: Model, cfg: StepSettings, state: State, work: Workspace, cache: ContactCache
) -> int:
    """Stages 1-3: find the contacts at the current pose; returns the number of rows in `work`."""
    # 1. geometry
    transform(
        state.position,
        state.angle,
        state.exists,
        model.vertices_local,
        model.normals_local,
        model.vertex_count,
        model.radius,
        work.vertices,
        work.normals,
        work.aabb,
    )
    # 2. broad phase (grow the buffers and look again when they were too small)
    speculative_reach(
        state.velocity,
        state.angular_velocity,
        model.radius,
        cfg.look_ahead,
        cfg.gravity_reach,
        work.expand,
    )
    while True:
        pairs = find_pairs(
            state.position,
            model.radius,
            work.aabb,
            work.expand,
            work.movable,
            state.exists,
            model.sweeps,
            model.filtered,
            model.category,
            model.mask,
            model.group,
            model.no_collide,
            work.pair_a,
            work.pair_b,
            work.pair_spare,
            work.sweep_index,
            work.sweep_key,
            work.sweep_table,
        )
        if pairs <= work.pair_a.shape[0]:
            break
        work.grow(pairs)
    # 3. narrow phase (and which previous contact each row continues, for warm starting)
    rows = collide_pairs(
        work.pair_a,
        work.pair_b,
        pairs,
        work.vertices,
        work.normals,
        model.vertex_count,
        model.radius,
        state.velocity,
        state.angular_velocity,
        cfg.look_ahead,
        cfg.gravity_reach,
        cfg.two_points,
        cfg.hysteresis,
        cache.key,
        cache.feature,
        work.a,
        work.b,
        work.feature,
        work.slot,
        work.point,
        work.normal,
        work.depth,
        work.pair_depth,
    )
    match_previous(
        rows,
        work.a,
        work.b,
        work.feature,
        work.slot,
        model.n_bodies,
        cache.key,
        cache.feature,
        cache.slot,
        work.previous,
    )
    return rows


def resolve(
    model: Model, cfg: StepSettings, state: State, work: Workspace, cache: ContactCache, rows: int
) -> None:
    """Stage 5: the impulses of the first `rows` contact rows of `work` (velocities in place)."""
    work.solver_table = solve_contacts(
        rows,
        work.a,
        work.b,
        work.feature,
        work.slot,
        work.point,
        work.normal,
        work.depth,
        work.previous,
        state.position,
        state.velocity,
        state.angular_velocity,
        model.inv_mass,
        model.inv_inertia,
        cfg.gravity_dv,
        model.restitution,
        model.friction,
        cfg.restitution_rule,
        cfg.friction_rule,
        cfg.restitution_threshold,
        cfg.friction_on,
        cfg.seed_solver,
        cfg.iterations,
        cfg.warm_starting,
        cfg.h,
        cache.impulse,
        cache.tangent,
        work.impulse,
        work.tangent,
        work.restitution,
        work.push_a,
        work.push_b,
        work.solver_table,
        tuple(model.joints),  # a plain tuple, as the driver passes it: one compiled solver
        work.joint_scratch,
    )


def substep(
    model: Model,
    cfg: StepSettings,
    state: State,
    work: Workspace,
    cache: ContactCache,
    index: int,
    solve: bool = True,
) -> Contacts:
    """Advance the state by one sub-step of cfg.h seconds; return the contacts resolved.

    solve: False skips the impulses (stage 5); only `isaac.engine.compile_ahead` does, to compile
    the other stages while another process compiles the solver.
    """
    rows = detect(model, cfg, state, work, cache)
    # 4. push-out
    push_out(
        rows,
        work.a,
        work.b,
        work.feature,
        work.slot,
        work.point,
        work.normal,
        work.pair_depth,
        model.inv_mass,
        model.thickness,
        state.position,
        cfg.correction_mode,
        cfg.slop,
        cfg.correction,
        cfg.position_iterations,
        work.push_a,
        work.push_b,
        work.push_start,
    )
    # 5. impulses (semi-implicit Euler: gravity first, so contacts see it), with the joints
    if not cfg.explicit:
        add_gravity(state.velocity, work.movable, state.exists, cfg.gx, cfg.gy, cfg.h)
    joints = work.joint_scratch.shape[0] > 0
    if joints:
        _prepare_joints(model, state, work, cfg.h, cache.joints, cfg.warm_starting)
    if solve:
        resolve(model, cfg, state, work, cache, rows)
    # 6. integration (the seed's explicit Euler: gravity last), then the joints' position pass
    advance_positions(
        state.position,
        state.angle,
        state.velocity,
        state.angular_velocity,
        work.movable,
        state.exists,
        cfg.h,
    )
    if cfg.explicit:
        add_gravity(state.velocity, work.movable, state.exists, cfg.gx, cfg.gy, cfg.h)
    if joints:
        correct_joint_positions(
            model.joints,
            model.joint_waves,
            state.position,
            state.angle,
            state.exists,
            model.inv_mass,
            model.inv_inertia,
            cfg.position_iterations,
            work.joint_error,
        )
    return work.contacts(rows, index)


def _prepare_joints(model, state, work, h: float, warm: np.ndarray, warm_starting: bool) -> None:
    """`prepare_joints` on the workspace's joint rows at the current pose (h: the sub-step, s)."""
    prepare_joints(
        model.joints,
        work.joint_scratch,
        state.position,
        state.angle,
        state.exists,
        model.inv_mass,
        model.inv_inertia,
        h,
        warm,
        warm_starting,
    )


def joint_rows(model: Model, state: State, work: Workspace) -> JointRows | None:
    """The joints at the end of the step just taken (private copies), or None without joints."""
    m = work.joint_scratch.shape[0]
    if m == 0:
        return None
    rows = JointRows.empty(m)
    write_joint_rows(
        model.joints,
        work.joint_scratch,
        state.position,
        state.angle,
        state.exists,
        work.joint_error,
        rows.anchor_a,
        rows.anchor_b,
        rows.linear_impulse,
        rows.angular_impulse,
        rows.motor_impulse,
        rows.limit_impulse,
        rows.impulses,
        rows.error,
    )
    return rows


def initial_joint_rows(model: Model, state: State, work: Workspace) -> JointRows | None:
    """The joints at a state no step has made (step 0): anchors and errors, no impulse."""
    m = work.joint_scratch.shape[0]
    if m == 0:
        return None
    _prepare_joints(model, state, work, 1.0, np.zeros((m, JOINT_IMPULSES)), False)
    work.joint_error[:] = 0.0
    return joint_rows(model, state, work)


def joint_carry(work: Workspace) -> np.ndarray:
    """The accumulated joint impulses the next sub-step warm-starts from."""
    carry = np.zeros((work.joint_scratch.shape[0], JOINT_IMPULSES))
    keep_joint_impulses(work.joint_scratch, carry)
    return carry


def step(
    model: Model,
    cfg: StepSettings,
    dt: float,
    state: State,
    work: Workspace,
    cache: ContactCache,
    solve: bool = True,
) -> tuple[Contacts, ContactCache]:
    """Advance `state` in place from step k to k + 1; return its contacts and the new cache.

    solve: as in `substep` (always True outside `isaac.engine.compile_ahead`)."""
    parts = []
    for index in range(cfg.substeps):
        contacts = substep(model, cfg, state, work, cache, index, solve)
        cache = ContactCache.of(contacts, model.n_bodies, joint_carry(work))
        parts.append(contacts)
    state.step += 1
    if model.timed:
        time = state.step * dt
        state.exists[:] = (model.enters_at <= time) & (time < model.leaves_at)
    return Contacts.concatenate(parts), cache
