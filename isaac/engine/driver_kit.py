"""The compiled driver's bundles as objects that cross into compiled code as pointers.

A driver call reads about 130 arrays that live as long as a `Stepper`'s buffers: the model's
(`Bodies`), the sub-step's scratch, the carried contacts, the copies that undo a step, the
solver's table and the profile clock. Handed over as tuples, numba's entry into compiled code
types each array and wraps it in a fresh reference-counted handle on every call: 16 us a call
on pile-100, more than a fifth of a step, which is why `Simulation.step()` once took the staged
path (eight smaller crossings, with their own Python) rather than a one-step driver call. A
`DriverKit` holds those handles, made once (`make_kit`), and a call unboxes it as one pointer.
A batch's 28 arrays go the same way (`BatchKit`, `make_batch_kit`: 6 us to make, once a batch
or a `StepSlot`, against some 3.5 us a call as a tuple). A call with both and the pose (a
tuple of 5 arrays) crosses in 2.7 us.

Every field is replaced as a whole (a new kit) when a buffer grows, never written from Python.
The pose stays a separate argument: `Simulation.resume` replaces `State`'s arrays.

With NUMBA_DISABLE_JIT=1 there is no compiled code to cross into: a kit is a plain named tuple
with the same fields, which the drivers, then plain Python, read alike.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np
from numba.core import types
from numba.experimental import structref
from numba.extending import overload

from isaac.engine import kernel_cache  # noqa: F401  (first: keys the kernels' numba cache)


class KitFields(NamedTuple):
    """What a kit holds (the reference path's kit itself). Every field as `isaac.engine.driver`
    names it: plain tuples of the `Bodies`, `Settings`, `Scratch`, `Carry` and `Pose` bundles'
    fields, in order."""

    bodies: tuple
    settings: tuple
    scratch: tuple
    carry: tuple
    saved_pose: tuple  # the pose and carry a step that must be undone goes back to
    saved_carry: tuple
    table: np.ndarray  # the sequential solver's scratch (`Workspace.solver_table`)
    clock: np.ndarray  # (1 + len(STAGES),) int64 ns, which only the timed drivers write


class _FieldsType(types.StructRef):
    """A kit's numba type: one per set of field types (as the driver's signature was one per
    set of argument types)."""

    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


@structref.register
class DriverKitType(_FieldsType):
    """numba's type of a `DriverKit`."""


class DriverKit(structref.StructRefProxy):
    """A `KitFields` held by compiled code (its fields are read inside compiled code only)."""


@structref.register
class BatchKitType(_FieldsType):
    """numba's type of a `BatchKit`."""


class BatchKit(structref.StructRefProxy):
    """A batch (`isaac.engine.driver.Batch`'s fields as a plain tuple, `arrays`) held by
    compiled code: 28 arrays that would cost some 3.5 us a call to hand over as a tuple."""


structref.define_boxing(DriverKitType, DriverKit)
structref.define_boxing(BatchKitType, BatchKit)


class BatchFields(NamedTuple):
    """What a batch kit holds (the reference path's batch kit itself)."""

    arrays: tuple


def _driver_kit(bodies, settings, scratch, carry, saved_pose, saved_carry, table, clock):
    """A `DriverKit` of these fields (compiled code only: typed by the overload below)."""


def _batch_kit(arrays):
    """A `BatchKit` of a batch's arrays (compiled code only: typed by the overload below)."""


# The kit's type is made from the argument types while numba types the call, so the compiled
# constructors dispatch on plain tuples (numba's fast path), not on a type passed in (its slow
# path: 140 us a call).
@overload(_driver_kit)
def _driver_kit_typed(bodies, settings, scratch, carry, saved_pose, saved_carry, table, clock):
    kit_type = DriverKitType(
        [
            ("bodies", bodies), ("settings", settings), ("scratch", scratch), ("carry", carry),
            ("saved_pose", saved_pose), ("saved_carry", saved_carry), ("table", table),
            ("clock", clock),
        ]
    )  # fmt: skip

    def make(bodies, settings, scratch, carry, saved_pose, saved_carry, table, clock):
        kit = structref.new(kit_type)
        kit.bodies = bodies
        kit.settings = settings
        kit.scratch = scratch
        kit.carry = carry
        kit.saved_pose = saved_pose
        kit.saved_carry = saved_carry
        kit.table = table
        kit.clock = clock
        return kit

    return make


@overload(_batch_kit)
def _batch_kit_typed(arrays):
    kit_type = BatchKitType([("arrays", arrays)])

    def make(arrays):
        kit = structref.new(kit_type)
        kit.arrays = arrays
        return kit

    return make


@numba.njit(cache=True)
def _new_driver_kit(bodies, settings, scratch, carry, saved_pose, saved_carry, table, clock):
    return _driver_kit(bodies, settings, scratch, carry, saved_pose, saved_carry, table, clock)


@numba.njit(cache=True)
def _new_batch_kit(arrays):
    return _batch_kit(arrays)


def make_kit(fields: KitFields):
    """The kit a driver call takes: a `DriverKit` holding `fields`, or `fields` itself on the
    reference path (NUMBA_DISABLE_JIT=1)."""
    if numba.config.DISABLE_JIT:
        return fields
    return _new_driver_kit(*fields)


def make_batch_kit(arrays: tuple):
    """The batch a driver call takes: a `BatchKit` holding `arrays` (`Batch`'s fields, in
    order), or a `BatchFields` on the reference path."""
    if numba.config.DISABLE_JIT:
        return BatchFields(arrays)
    return _new_batch_kit(arrays)
