"""Batches the driver records into (`Simulation.step()`, `run`, `batches`), each used again
once nothing holds it.

A batch handed out must stay as it was, whatever steps come after. A fresh batch a call (28
arrays, whose pages the kernel zeroes on first write), or a reused batch of plain arrays (28
reference counts to read, 56 write flags to turn, a `StepBatch` to make), cost 12-20 us of
Python a call on pile-100: a quarter of a step for `step()`. A slot's 28 arrays are views of one
block of memory, made once, with what hands them to the driver (a `BatchCall`) and the
`StepBatch` of read-only views that hands them out. So two reference counts say whether
anything still holds the slot: the `StepBatch`'s (the batch, or a record of it) and the
block's (any array taken from them, which numpy makes a view of the block). A slot in use is
never written where it handed something out: another is taken or made, or the next steps go in
the places after the last record or batch it handed out (`Stepper._held_slot`: a caller that
keeps everything holds every slot).
"""

from __future__ import annotations

import sys

import numpy as np

from isaac.engine.records import StepBatch, StepRecord, _BatchRecord

_ALIGN = 64  # bytes: each array starts on a cache line (numba types a misaligned array apart)


class StepSlot:
    """A batch whose arrays are views of one block (`isaac.engine.driver.Batch`'s fields, in
    order)."""

    def __init__(self, layout: tuple, dt: float, call_of) -> None:
        """layout: the (shape, dtype) of each of the slot's arrays
        (`Stepper.batch_layout(steps)`); dt: the step (s); call_of: what hands the arrays to
        the driver (`isaac.engine.driver_kit.BatchCall`)."""
        sizes = [-(-_nbytes(shape, dtype) // _ALIGN) * _ALIGN for shape, dtype in layout]
        self._block = np.empty(max(1, sum(sizes)), np.uint8)
        arrays, at = [], 0
        for (shape, dtype), size in zip(layout, sizes):
            # (one constructor a view: a slice, a view and a reshape cost twice as much)
            arrays.append(np.ndarray(shape, dtype, self._block, at))
            at += size
        arrays[5][:] = 0  # the offsets: a call's rows start at row 0 (the driver writes [1:])
        self.arrays = tuple(arrays)  # what the driver writes
        self.call = call_of(self.arrays)  # (its kit made at the first call: 6 us)
        self.steps = self.arrays[0].shape[0]  # room for this many steps
        self._views = tuple(a.view() for a in arrays)  # (StepBatch makes them read-only)
        self._batch = StepBatch(0, dt, self._views, self.steps)
        self._dt = dt
        b = self._batch
        # what the batch hands out as it is, not as a new view: its arrays and their tuples
        self._handed = (
            b.position, b.angle, b.velocity, b.angular_velocity, b.exists, b.offsets, b._rows,
            *b._rows, *(b._joints or ()),
        )  # fmt: skip
        del b  # (the counts below are the slot's own references alone)
        self._idle = self._references()
        self._idle_handed = self._handed_references()
        self._lent = False  # whether the batch itself went out (`batch`), not only a record
        # the place the next steps may go in while the slot is held (`Stepper._held_slot`):
        # after the last record or batch handed out from here (a slot lent whole: none)
        self.next_place = self.steps
        self.handed = 0  # records and batches handed out since a step was recorded in place 0

    def _references(self) -> tuple[int, int]:
        return sys.getrefcount(self._batch), sys.getrefcount(self._block)

    def _handed_references(self) -> list[int]:
        return [sys.getrefcount(a) for a in self._handed]

    def free(self) -> bool:
        """Whether nothing outside the slot holds its batch, an array or tuple the batch hands
        out as it is (`position`, `row_arrays`, ...; checked only once the batch itself went
        out), or any view of its block (whatever else a batch or a record hands out)."""
        if self._references() != self._idle:
            return False
        return not self._lent or self._handed_references() == self._idle_handed

    def batch(self, first: int, steps: int, at: int = 0) -> StepBatch:
        """The batch of the `steps` steps just written from place `at`, the first of them step
        `first`: the slot's own `StepBatch` when they fill it, else one over new views of the
        block's places (which holds the slot's batch, so that `records_held` counts it)."""
        self._handing(at, at + steps)
        if at == 0 and steps == self.steps:
            self._lent = True
            self._batch.first = first
            return self._batch
        part = StepBatch.of_places(first, self._dt, tuple(a.view() for a in self._views), at, steps)
        part._slot_batch = self._batch
        return part

    def record(self, step: int, at: int) -> StepRecord:
        """The record of the step just written at place `at`, as step `step` (its arrays are
        views made when first read, which hold the block; the batch itself stays in the slot)."""
        self._handing(at, at + 1)
        self._lent = False
        self._batch.first = step - at
        return _BatchRecord.of(self._batch, at)  # (a place just written: not checked again)

    def _handing(self, at: int, end: int) -> None:
        """Places at .. end - 1 go out: the next steps may go after them, never in them."""
        self.handed = self.handed + 1 if at else 1
        self.next_place = end

    def records_held(self) -> int:
        """How many records and batches of this slot's places something holds (each holds the
        slot's batch)."""
        return sys.getrefcount(self._batch) - self._idle[0]

    def bytes_per_step(self) -> int:
        return -(-self._block.nbytes // self.steps)


def _nbytes(shape: tuple, dtype: np.dtype) -> int:
    size = dtype.itemsize
    for extent in shape:
        size *= extent
    return size
