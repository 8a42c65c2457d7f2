"""What leaves the step: plain, immutable records of arrays.

Conventions used by every field below (and by the log format, docs/log-format.md):
- SI units: m, kg, s, rad. World frame: x right, y up. Angles counter-clockwise.
- Bodies are indexed 0..n-1 in scene order (generators already expanded).
- A contact row is one contact *point* between bodies ``a < b``. ``normal`` is a unit vector that
  points from body a towards body b. ``depth`` is the point's own penetration and
  ``pair_depth`` the pair's MTD depth (m, >= 0; negative only for a speculative contact, where it
  is minus the gap). The impulse ``j`` (N·s, >= 0) was applied as
  ``-j * normal`` to a and ``+j * normal`` to b at ``point``; ``tangent_impulse`` (N·s, signed,
  along ``tangent = (-normal_y, normal_x)``) likewise ``-jt * tangent`` to a and ``+jt * tangent``
to b.
- ``push_a`` / ``push_b`` are the displacements (m, world) the MTD push-out applied to a and b for
  this row's pair; a pair's push is stored on its first point (``slot == 0``) only, so summing the
  rows gives what was applied.
- Every array is a private copy: a record never changes after it is made.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from isaac.engine.counts import count

CONTACT_FIELDS = (
    "substep",
    "a",
    "b",
    "feature",
    "slot",
    "point",
    "normal",
    "depth",
    "pair_depth",
    "push_a",
    "push_b",
    "impulse",
    "tangent_impulse",
    "restitution",
)


@dataclass(frozen=True, eq=False)
class Contacts:
    """Every contact point of one step, ordered by (substep, a, b, slot).

    substep: (m,) int32, sub-step index within the step (0 when the scene has no sub-steps).
    a, b: (m,) int32 body indices, a < b.
    feature: (m,) int32 contact feature id: ``((ref_side * 64 + ref_edge) * 64 + inc_edge)`` where
        ref_side is 0 when the reference face belongs to a, 1 when to b. It keys warm starting and
        the axis hysteresis between steps.
    slot: (m,) int32, 0 or 1: which point of the pair's manifold (only 0 with one-point contacts).
    point: (m, 2) world contact point (m) on the incident body's surface after the push-out.
    normal: (m, 2) unit normal, from a towards b.
    depth: (m,) this point's own penetration before the push-out (m): how far the point lies
        behind the reference face along ``normal`` (negative: the gap of a speculative point).
    pair_depth: (m,) the pair's MTD depth before the push-out (m): the minimum overlap of the two
        bodies along ``normal`` found by SAT, the same on every row of a pair, what the push-out
        resolves. It can exceed ``depth`` (a face-face point at the middle of the overlapping
        segment lies less deep than the deepest vertex) or differ in sign from it.
    push_a, push_b: (m, 2) push-out displacement applied to a and b (m, world); zero when slot > 0.
    impulse: (m,) normal impulse j >= 0 (N·s).
    tangent_impulse: (m,) friction impulse along the tangent (N·s); 0 when friction is off.
    restitution: (m,) the restitution e used for this contact (after the pair rule and threshold).
    """

    substep: np.ndarray
    a: np.ndarray
    b: np.ndarray
    feature: np.ndarray
    slot: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    depth: np.ndarray
    pair_depth: np.ndarray
    push_a: np.ndarray
    push_b: np.ndarray
    impulse: np.ndarray
    tangent_impulse: np.ndarray
    restitution: np.ndarray

    def __len__(self) -> int:
        return int(self.a.shape[0])

    @staticmethod
    def concatenate(parts: list[Contacts]) -> Contacts:
        """One Contacts of several parts' rows (sub-steps, or steps), in order."""
        if len(parts) == 1:
            return parts[0]
        return Contacts(*(np.concatenate([getattr(p, f) for p in parts]) for f in CONTACT_FIELDS))

    @staticmethod
    def empty() -> Contacts:
        i = np.zeros(0, dtype=np.int32)
        f = np.zeros(0, dtype=np.float64)
        v = np.zeros((0, 2), dtype=np.float64)
        return Contacts(i, i, i, i, i, v, v, f, f, v, v, f, f, f)


JOINT_FIELDS = (
    "anchor_a",
    "anchor_b",
    "linear_impulse",
    "angular_impulse",
    "motor_impulse",
    "limit_impulse",
    "error",
    "impulses",
)


@dataclass(frozen=True, eq=False)
class JointRows:
    """Every joint of one step (row k: the scene's joint k), at the step's end.

    anchor_a, anchor_b: (m, 2) each body's anchor (m, world).
    linear_impulse: (m, 2) the constraint's impulse on b (N s, world; a takes minus it):
        revolute and weld, the anchors' point impulse; distance, along the axis a -> b;
        prismatic, along the axis's normal.
    angular_impulse: (m,) the constraint's angular impulse on b (N m s, counter-clockwise; a
        takes minus it): weld and prismatic (their locked rotation), 0 otherwise.
    motor_impulse: (m,) the motor's impulse on b (N m s revolute, N s prismatic), 0 without.
    limit_impulse: (m,) the limits' impulse on b: lower limit's less upper limit's (N m s, N s).
    error: (m, 2) what is left of the constraint after the step's position correction: the
        anchors' distance off it (m) and the rotation off it (rad; weld and prismatic).
    impulses: (m, JOINT_IMPULSES) the solver's accumulated impulses of the step's last
        sub-step (isaac.engine.joints, columns J0 .. JU), which the next step warm-starts from;
        the fields above are made from them.
    A joint whose bodies do not both exist has all zeros. Impulses are the last sub-step's.
    """

    anchor_a: np.ndarray
    anchor_b: np.ndarray
    linear_impulse: np.ndarray
    angular_impulse: np.ndarray
    motor_impulse: np.ndarray
    limit_impulse: np.ndarray
    error: np.ndarray
    impulses: np.ndarray

    def __len__(self) -> int:
        return int(self.anchor_a.shape[0])

    @staticmethod
    def empty(m: int = 0) -> JointRows:
        v = np.zeros((m, 2))
        f = np.zeros(m)
        return JointRows(v, v.copy(), v.copy(), f, f.copy(), f.copy(), v.copy(), np.zeros((m, 6)))


@dataclass(frozen=True, eq=False)
class StepRecord:
    """The state after step ``step`` and the contacts found while taking it.

    step: index of the state; step 0 is the initial state (no contacts), step k the state after
        k calls of ``Simulation.step``.
    time: ``step * dt`` (s), computed from the index, never accumulated.
    position: (n, 2) world position of each body's centre of mass (m).
    angle: (n,) rotation of each body (rad, counter-clockwise), wrapped to [-pi, pi].
    velocity: (n, 2) linear velocity of the centre of mass (m/s, world).
    angular_velocity: (n,) angular velocity (rad/s, counter-clockwise positive).
    exists: (n,) bool, whether each body is in the scene at ``time`` (the seed's Exist).
    contacts: the contacts resolved while advancing from step-1 to step.
    joints: the joints at the end of that step (`JointRows`), or None for a scene without
        joints.
    """

    step: int
    time: float
    position: np.ndarray
    angle: np.ndarray
    velocity: np.ndarray
    angular_velocity: np.ndarray
    exists: np.ndarray
    contacts: Contacts
    joints: JointRows | None = None


def state_hash(record: StepRecord) -> str:
    """sha256 (hex) of the exact bits of the body state after the step.

    Covers position, angle, velocity, angular velocity and existence, as little-endian float64 /
    uint8 in body order. Two runs agree bit for bit exactly when their hashes agree.
    """
    h = hashlib.sha256()
    # hashed through the buffer protocol: the same bytes as .tobytes(), without copying them
    for arr in (record.position, record.angle, record.velocity, record.angular_velocity):
        h.update(np.ascontiguousarray(arr, dtype="<f8"))
    h.update(np.ascontiguousarray(record.exists, dtype=np.uint8))
    return h.hexdigest()


class StepBatch:
    """The records of consecutive steps, as the compiled driver wrote them: read-only arrays
    indexed by the step's place in the batch (0 .. steps - 1).

    first: the state index of the batch's first record (its step). position (steps, n, 2),
    angle (steps, n), velocity (steps, n, 2), angular_velocity (steps, n), exists (steps, n):
    the state after each step (units and frames as in `StepRecord`). offsets (steps + 1,): the
    contact rows of step s are rows offsets[s] .. offsets[s + 1] of the row arrays, which
    `contacts_of(s)` hands out as a `Contacts`. `record(s)` is step s as a `StepRecord`
    (views, no copies: a batch's arrays are its own and never written again).
    """

    def __init__(self, first: int, dt: float, arrays: tuple, steps: int) -> None:
        """arrays: `isaac.engine.driver.Batch`'s fields, in order."""
        for a in arrays:
            a.flags.writeable = False
        self.first = first
        self.dt = dt
        self.steps = steps
        (self.position, self.angle, self.velocity, self.angular_velocity, self.exists) = (
            a[:steps] for a in arrays[:5]
        )
        self.offsets = arrays[5][: steps + 1]
        end = 6 + len(CONTACT_FIELDS)
        self._rows = arrays[6:end]
        joint_arrays = arrays[end:]
        # (steps, m, ...) per joint field; None for a scene without joints
        self._joints = (
            tuple(a[:steps] for a in joint_arrays)
            if joint_arrays and joint_arrays[0].shape[1]
            else None
        )

    def __len__(self) -> int:
        return self.steps

    @staticmethod
    def of_places(first: int, dt: float, arrays: tuple, at: int, steps: int) -> StepBatch:
        """The batch of places at .. at + steps - 1 of a batch's arrays (`Batch`'s fields, the
        first step's rows from offsets[at]): views, with the offsets counted from its own first
        row, which its row arrays start at."""
        if at == 0:
            return StepBatch(first, dt, arrays, steps)
        offsets = arrays[5][at : at + steps + 1]
        lo, hi = int(offsets[0]), int(offsets[-1])
        end = 6 + len(CONTACT_FIELDS)
        return StepBatch(
            first, dt,
            (
                *(a[at : at + steps] for a in arrays[:5]), offsets - lo,
                *(a[lo:hi] for a in arrays[6:end]), *(a[at : at + steps] for a in arrays[end:]),
            ),
            steps,
        )  # fmt: skip

    def _place(self, s) -> int:
        """s as a place of this batch: an int 0 .. steps - 1 (numpy integers too); TypeError
        or ValueError else (a negative place read the last step's arrays under another
        step's index)."""
        if type(s) is int and 0 <= s < self.steps:  # the common case, first
            return s
        s = count(s, "a batch's place")
        if s >= self.steps:
            raise ValueError(f"place {s} is past the batch's last (it holds {self.steps} steps)")
        return s

    def contacts_of(self, s: int) -> Contacts:
        """The contact rows of step s (a place 0 .. steps - 1), views."""
        s = self._place(s)
        lo, hi = int(self.offsets[s]), int(self.offsets[s + 1])
        return Contacts(*(a[lo:hi] for a in self._rows))

    @property
    def row_arrays(self) -> tuple:
        """The row arrays as the driver wrote them (`CONTACT_FIELDS` order); only rows
        offsets[0] .. offsets[-1] are the batch's (what a compiled consumer indexes with the
        offsets)."""
        return self._rows

    def joints_of(self, s: int) -> JointRows | None:
        """The joints at the end of step s (views), or None for a scene without joints."""
        s = self._place(s)
        if self._joints is None:
            return None
        return JointRows(*(a[s] for a in self._joints))

    def all_contacts(self) -> Contacts:
        """The contact rows of every step of the batch, in step order (views)."""
        lo, hi = int(self.offsets[0]), int(self.offsets[-1])
        return Contacts(*(a[lo:hi] for a in self._rows))

    def record(self, s: int) -> StepRecord:
        """Step s as a `StepRecord` whose arrays are views of this batch, made when first read
        (a record of a 2-body step cost 5 us made eagerly, more than the step); s: a place
        0 .. steps - 1."""
        return _BatchRecord.of(self, self._place(s))

    @staticmethod
    def of_records(records: list[StepRecord], dt: float) -> StepBatch:
        """A batch holding these consecutive records (copies)."""
        counts = [len(r.contacts) for r in records]
        offsets = np.zeros(len(records) + 1, dtype=np.int64)
        offsets[1:] = np.cumsum(counts)
        state = [
            np.stack([getattr(r, f) for r in records])
            for f in ("position", "angle", "velocity", "angular_velocity", "exists")
        ]
        # copies, even of one record's rows (`Contacts.concatenate` hands one part back as it
        # is): the batch makes its arrays read-only, and the record's rows are the ones the
        # staged path's next step reads (a read-only array is another type to numba, and
        # collide_pairs, match_previous and the solver compiled again for it, 6.7 s)
        rows = Contacts(
            *(np.concatenate([getattr(r.contacts, f) for r in records]) for f in CONTACT_FIELDS)
        )
        joints = ()
        if records[0].joints is not None:
            joints = tuple(np.stack([getattr(r.joints, f) for r in records]) for f in JOINT_FIELDS)
        return StepBatch(
            records[0].step, dt,
            (*state, offsets, *(getattr(rows, f) for f in CONTACT_FIELDS), *joints),
            len(records),
        )  # fmt: skip


class _BatchRecord(StepRecord):
    """A `StepRecord` of one step of a `StepBatch`: the same fields, read from the batch on
    first use (functools.cached_property writes the instance's __dict__, which a frozen
    dataclass allows)."""

    def __new__(cls, *args, **fields):
        # only `dataclasses.replace` calls the class, to make its copy as type(record)(**fields):
        # a plain StepRecord
        return StepRecord(*args, **fields)

    @staticmethod
    def of(batch: StepBatch, s: int) -> _BatchRecord:
        """Step s of the batch (made without calling the class: 0.3 us a record less)."""
        record = object.__new__(_BatchRecord)
        step = batch.first + s
        record.__dict__.update(_batch=batch, _s=s, step=step, time=step * batch.dt)
        return record

    def __repr__(self) -> str:
        return "StepRecord" + super().__repr__()[len("_BatchRecord") :]

    def __reduce__(self):  # pickled (e.g. sent to another process) as a plain StepRecord
        return StepRecord, tuple(getattr(self, f) for f in StepRecord.__dataclass_fields__)

    @cached_property
    def position(self) -> np.ndarray:
        return self._batch.position[self._s]

    @cached_property
    def angle(self) -> np.ndarray:
        return self._batch.angle[self._s]

    @cached_property
    def velocity(self) -> np.ndarray:
        return self._batch.velocity[self._s]

    @cached_property
    def angular_velocity(self) -> np.ndarray:
        return self._batch.angular_velocity[self._s]

    @cached_property
    def exists(self) -> np.ndarray:
        return self._batch.exists[self._s]

    @cached_property
    def contacts(self) -> Contacts:
        return self._batch.contacts_of(self._s)

    @cached_property
    def joints(self) -> JointRows | None:
        return self._batch.joints_of(self._s)
