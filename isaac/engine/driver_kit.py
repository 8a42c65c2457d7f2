"""The compiled driver's bundles as objects that cross into compiled code as pointers.

A driver call reads about 130 arrays that live as long as a `Stepper`'s buffers: the model's
(`Bodies`), the sub-step's scratch, the carried contacts, the copies that undo a step, the
solver's table and the profile clock. Handed over as tuples, numba's entry into compiled code
types each array and wraps it in a fresh reference-counted handle on every call: 16 us a call
on pile-100, more than a fifth of a step, which is why `Simulation.step()` once took the staged
path (eight smaller crossings, with their own Python) rather than a one-step driver call. A
`DriverKit` holds those handles, made once (`make_kit`), and a call unboxes it as one pointer.
A call's kit (`CallKit`, `make_call_kit`: 6 us to make) holds the driver's kit, the pose (the
state's 5 arrays) and the batch the call writes (28 arrays, some 3.5 us a call as a tuple), so
a call crosses with one object and five integers: 0.7 us, where the driver's kit, the pose and
a batch's kit as three arguments took 1.6 us (numba types each object argument in Python).
`BatchCall` keeps a batch's call kit and makes it again when the driver's kit or the pose it
holds was replaced.

Every field is replaced as a whole (a new kit) when a buffer grows, never written from Python.

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
class CallKitType(_FieldsType):
    """numba's type of a `CallKit`."""


class CallKit(structref.StructRefProxy):
    """What a driver call takes, held by compiled code: a `CallFields`."""


structref.define_boxing(DriverKitType, DriverKit)
structref.define_boxing(CallKitType, CallKit)


class CallFields(NamedTuple):
    """What a call's kit holds (the reference path's call kit itself)."""

    arrays: tuple  # the batch the call writes: `isaac.engine.driver.Batch`'s fields, in order
    driver: object  # the `DriverKit` (`make_kit`)
    pose: tuple  # the state's `isaac.engine.driver.Pose` fields, which the call advances


def _driver_kit(bodies, settings, scratch, carry, saved_pose, saved_carry, table, clock):
    """A `DriverKit` of these fields (compiled code only: typed by the overload below)."""


def _call_kit(arrays, driver, pose):
    """A `CallKit` of these fields (compiled code only: typed by the overload below)."""


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


@overload(_call_kit)
def _call_kit_typed(arrays, driver, pose):
    kit_type = CallKitType([("arrays", arrays), ("driver", driver), ("pose", pose)])

    def make(arrays, driver, pose):
        kit = structref.new(kit_type)
        kit.arrays = arrays
        kit.driver = driver
        kit.pose = pose
        return kit

    return make


@numba.njit(cache=True)
def _new_driver_kit(bodies, settings, scratch, carry, saved_pose, saved_carry, table, clock):
    return _driver_kit(bodies, settings, scratch, carry, saved_pose, saved_carry, table, clock)


@numba.njit(cache=True)
def _new_call_kit(arrays, driver, pose):
    return _call_kit(arrays, driver, pose)


def make_kit(fields: KitFields):
    """The kit a driver call takes: a `DriverKit` holding `fields`, or `fields` itself on the
    reference path (NUMBA_DISABLE_JIT=1)."""
    if numba.config.DISABLE_JIT:
        return fields
    return _new_driver_kit(*fields)


def make_call_kit(arrays: tuple, driver, pose: tuple):
    """What a driver call takes: a `CallKit` holding the batch it writes (`arrays`: `Batch`'s
    fields, in order), the driver's kit (`make_kit`) and the pose it advances (`Pose`'s
    fields, the state's arrays), or a `CallFields` on the reference path."""
    if numba.config.DISABLE_JIT:
        return CallFields(arrays, driver, pose)
    return _new_call_kit(arrays, driver, pose)


class BatchCall:
    """A batch's arrays and its call kit (`make_call_kit`), made again when the driver's kit or
    the pose it holds is not the one given (a buffer grew, or the state's arrays were replaced:
    `Simulation.resume`, or a user's assignment), else the same object, call after call.
    The kit is made again only after `check()` (given: `Simulation`'s check of the state's
    arrays, `isaac.engine.guards.check_state`) passes, so that arrays a caller assigned reach
    compiled code checked, at no cost to a call whose pose is the one before."""

    __slots__ = ("arrays", "_kit", "_driver", "_pose")

    def __init__(self, arrays: tuple) -> None:
        self.arrays = arrays
        self._kit = None
        self._driver = None
        self._pose = None

    def kit(self, driver, state, check=None):
        """The call kit of this batch with `driver` (a `DriverKit`) and `state`'s arrays (an
        `isaac.engine.world.State`); check: called first when those are not the kit's."""
        p = self._pose
        if (
            self._driver is not driver
            or p[0] is not state.position
            or p[1] is not state.angle
            or p[2] is not state.velocity
            or p[3] is not state.angular_velocity
            or p[4] is not state.exists
        ):
            if check is not None:
                check()
            s = state
            self._pose = (s.position, s.angle, s.velocity, s.angular_velocity, s.exists)
            self._driver = driver
            self._kit = make_call_kit(self.arrays, driver, self._pose)
        return self._kit
