"""The checks at the engine's Python boundary: what a caller hands a `Simulation` (a count of
steps, a record to resume from, the state's arrays) is checked here before any of it reaches
compiled code, which trusts its input (a record of 3 bodies resumed into a scene of 2 wrote
past its arrays' ends).

- `count` (from `isaac.engine.counts`, where `StepBatch` takes it too): a number of steps or a
  batch size: an int (numpy integers too, not bool) >= a floor.
- `check_state`: the arrays of an `isaac.engine.world.State` (replaced by a caller between
  steps): each of the shape, dtype and layout the kernels were compiled for, and finite.
- `checked_record`: a `StepRecord` to resume from, against the simulation's model: its step,
  time, body, contact and joint counts, dtypes and ranges; private copies of what it holds.

Every failure is a TypeError (not the kind of object asked for) or an `isaac.errors.StateError`
(a ValueError) naming the field and what differs. docs/physics.md, "The Python API's guards".
"""

from __future__ import annotations

import math

import numpy as np

from isaac.engine.counts import count
from isaac.engine.joints import JOINT_IMPULSES
from isaac.engine.records import CONTACT_FIELDS, JOINT_FIELDS, Contacts, JointRows, StepRecord
from isaac.engine.world import State
from isaac.errors import StateError

# the state's arrays: (field, trailing shape, dtype) in `State` order
STATE_FIELDS = (
    ("position", (2,), np.dtype(np.float64)),
    ("angle", (), np.dtype(np.float64)),
    ("velocity", (2,), np.dtype(np.float64)),
    ("angular_velocity", (), np.dtype(np.float64)),
    ("exists", (), np.dtype(np.bool_)),
)
_CONTACT_INTS = frozenset(("substep", "a", "b", "feature", "slot"))
_CONTACT_PAIRS = frozenset(("point", "normal", "push_a", "push_b"))
# what the next step reads of a record's contacts (the warm start): finite, where the other
# fields are only handed out again (a format-1 log's pair_depth is NaN)
_CONTACT_READ = ("impulse", "tangent_impulse")
_JOINT_WIDTH = {"anchor_a": 2, "anchor_b": 2, "linear_impulse": 2, "error": 2}
_JOINT_WIDTH["impulses"] = JOINT_IMPULSES
# a contact's feature id, ((side * 64 + edge) * 64 + edge): below 2 * 64 * 64
FEATURES = 2 * 64 * 64


def check_state(state, names: tuple[str, ...]) -> None:
    """Check a simulation's `State` before compiled code advances it in place: a `State` whose
    step is an int >= 0 and whose arrays are (n, 2) or (n,) float64 (exists: bool), C-contiguous,
    writeable and finite, for the n bodies named `names`. A numpy integer step is made a Python
    int."""
    n = len(names)
    if not isinstance(state, State):
        raise TypeError(f"sim.state must be an isaac.engine.world.State, got {_kind(state)}")
    state.step = count(state.step, "sim.state.step")
    for name, tail, dtype in STATE_FIELDS:
        a = getattr(state, name)
        where = f"sim.state.{name}"
        if not isinstance(a, np.ndarray):
            raise TypeError(f"{where} must be a numpy array, got {_kind(a)}")
        _shaped(a, (n, *tail), where, n)
        if a.dtype != dtype:
            raise StateError(f"{where} has dtype {a.dtype}; the engine's is {dtype}")
        if not a.flags.c_contiguous or not a.flags.writeable:
            raise StateError(
                f"{where} is {'not C-contiguous' if a.flags.writeable else 'read-only'}; "
                f"assign a copy (np.array(x, dtype=np.{dtype.name}))"
            )
        if dtype.kind == "f":
            _finite(a, where, names)


def checked_record(record, model, dt: float, substeps: int):
    """(state, contacts, joints): private copies of what `record` holds, checked against the
    model (`isaac.engine.world.Model`) of a scene with step dt (s) and `substeps` sub-steps.

    Refused: another kind of object (TypeError); a step that is not an int >= 0, a time that
    is not step * dt, another body count, existence that the scene's enters_at / leaves_at
    do not give at that time, arrays of another shape or dtype, non-finite state or impulses,
    contact rows naming bodies outside the scene or not in (substep, a, b, slot) order, and
    another joint count (StateError). A record without joints (None) starts the joints cold."""
    if not isinstance(record, StepRecord):
        raise TypeError(f"a record to resume from must be a StepRecord, got {_kind(record)}")
    n = model.n_bodies
    step = count(record.step, "the record's step")
    arrays = []
    for name, tail, dtype in STATE_FIELDS:
        a = _array(getattr(record, name), f"the record's {name}", (n, *tail), dtype.kind, n)
        if dtype.kind == "f":
            _finite(a, f"the record's {name}", model.names)
        arrays.append(np.array(a, dtype=dtype))
    t = step * dt
    if not isinstance(record.time, (int, float, np.floating, np.integer)) or not math.isclose(
        float(record.time), t, rel_tol=1e-9, abs_tol=0.0
    ):
        raise StateError(
            f"the record's time is {record.time!r} s at step {step}; the scene's is "
            f"{t!r} s (step * dt, dt {dt!r} s): a record of another scene?"
        )
    exists = (model.enters_at <= t) & (t < model.leaves_at)
    if not np.array_equal(arrays[-1], exists):
        i = int(np.flatnonzero(arrays[-1] != exists)[0])
        raise StateError(
            f"the record's body {model.names[i]!r} (index {i}) "
            f"{'exists' if arrays[-1][i] else 'does not exist'} at step {step} (t = {t!r} s); "
            f"in the scene it {'does' if exists[i] else 'does not'} (enters_at "
            f"{model.enters_at[i]!r} s, leaves_at {model.leaves_at[i]!r} s): a record of "
            "another scene?"
        )
    state = State(step, *arrays)
    contacts = _checked_contacts(record.contacts, n, substeps)
    joints = _checked_joints(record.joints, model.joints.kind.shape[0])
    return state, contacts, joints


def _checked_contacts(contacts, n: int, substeps: int) -> Contacts:
    if not isinstance(contacts, Contacts):
        raise TypeError(f"the record's contacts must be a Contacts, got {_kind(contacts)}")
    m = np.shape(contacts.a)[0] if np.ndim(contacts.a) else -1
    raw = {}
    for name in CONTACT_FIELDS:
        tail = (2,) if name in _CONTACT_PAIRS else ()
        kind = "i" if name in _CONTACT_INTS else "f"
        raw[name] = _array(
            getattr(contacts, name), f"the record's contacts.{name}", (m, *tail), kind
        )
    for name in _CONTACT_READ:
        _finite(raw[name], f"the record's contacts.{name}", None)
    # ranges checked before the int32 copies are made (which would wrap a value past 2^31)
    _within(raw["a"], 0, n - 1, "a", f"the scene has {n} bodies")
    _within(raw["b"], 0, n - 1, "b", f"the scene has {n} bodies")
    _within(raw["substep"], 0, substeps - 1, "substep", f"the scene has {substeps} sub-steps")
    _within(raw["slot"], 0, 1, "slot", "a pair has at most 2 points")
    _within(raw["feature"], 0, FEATURES - 1, "feature", "a feature id is below 8192")
    rows = {
        name: np.array(a, dtype=np.int32 if name in _CONTACT_INTS else np.float64)
        for name, a in raw.items()
    }
    a, b, substep, slot = rows["a"], rows["b"], rows["substep"], rows["slot"]
    if m:
        # the next step walks the last sub-step's rows by ascending key a * n + b
        key = ((substep.astype(np.int64) * n + a) * n + b) * 2 + slot
        wrong = np.flatnonzero((a >= b) | np.r_[False, key[1:] <= key[:-1]])
        if wrong.size:
            r = int(wrong[0])
            raise StateError(
                f"the record's contact row {r} (bodies {a[r]} and {b[r]}, sub-step "
                f"{substep[r]}, slot {slot[r]}) is not after the one before it in "
                "(substep, a, b, slot) order with a < b"
            )
    return Contacts(**rows)


def _checked_joints(joints, m: int) -> JointRows | None:
    if joints is None:
        return None
    if not isinstance(joints, JointRows):
        raise TypeError(f"the record's joints must be JointRows or None, got {_kind(joints)}")
    got = np.shape(joints.impulses)[0] if np.ndim(joints.impulses) else -1
    if got != m:
        raise StateError(f"the record has {got} joints, the scene has {m}")
    rows = {}
    for name in JOINT_FIELDS:
        width = _JOINT_WIDTH.get(name)
        where = f"the record's joints.{name}"
        a = _array(getattr(joints, name), where, (m,) if width is None else (m, width), "f")
        _finite(a, where, None)
        rows[name] = np.array(a, dtype=np.float64)
    return JointRows(**rows)


def _array(value, where: str, shape: tuple, kind: str, n: int | None = None) -> np.ndarray:
    """`value` as an array of `shape` whose dtype is of `kind` ("f": real floating, also
    accepting integers; "i": integer; "b": bool)."""
    if not isinstance(value, np.ndarray):
        raise TypeError(f"{where} must be a numpy array, got {_kind(value)}")
    _shaped(value, shape, where, n)
    ok = {"f": "fiu", "i": "iu", "b": "b"}[kind]
    if value.dtype.kind not in ok:
        raise StateError(f"{where} has dtype {value.dtype}; it must be {_KINDS[kind]}")
    return value


_KINDS = {"f": "a float dtype", "i": "an integer dtype", "b": "bool"}


def _shaped(a: np.ndarray, shape: tuple, where: str, n: int | None) -> None:
    if a.shape == shape:
        return
    if n is not None and a.ndim == len(shape) and a.ndim and a.shape[1:] == shape[1:]:
        raise StateError(f"{where} holds {a.shape[0]} bodies; the scene has {n}")
    raise StateError(f"{where} has shape {a.shape}; it must be {shape}")


def _finite(a: np.ndarray, where: str, names) -> None:
    bad = ~np.isfinite(a)
    if bad.any():
        i = int(np.flatnonzero(bad.reshape(a.shape[0], -1).any(axis=1))[0])
        which = f"body {names[i]!r} (index {i})" if names is not None else f"row {i}"
        raise StateError(f"{where} of {which} is not finite ({a[i]})")


def _within(a: np.ndarray, lo: int, hi: int, name: str, why: str) -> None:
    if a.size and (int(a.min()) < lo or int(a.max()) > hi):
        r = int(np.flatnonzero((a < lo) | (a > hi))[0])
        raise StateError(
            f"the record's contact row {r} has {name} {int(a[r])}, outside {lo}..{hi} ({why})"
        )


def _kind(value) -> str:
    return type(value).__name__
