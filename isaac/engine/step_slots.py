"""One-step batches that `Simulation.step()` records into, each used again once no record
holds it.

`step()` takes one driver call a step, and the record it returns must stay as it was, whatever
steps come after. A fresh batch a step (28 arrays), or `Stepper.reused_batch` (28 reference
counts to read and 56 write flags to turn), cost 12-20 us of Python a step on pile-100, a
quarter of its physics. A slot's 28 arrays are views of one block of memory, made once; the
record a step hands out reads them through the slot's `StepBatch` (read-only views). So two
reference counts say whether anything still holds the slot: the `StepBatch`'s (a record of
it) and the block's (any array taken from such a record, which numpy makes a view of the
block). A slot in use is never written; a new one is made instead.
"""

from __future__ import annotations

import sys

import numpy as np

from isaac.engine.records import StepBatch, StepRecord

_ALIGN = 64  # bytes: each array starts on a cache line (numba types a misaligned array apart)


class StepSlot:
    """A one-step batch whose arrays are views of one block (`Batch`'s fields, in order)."""

    def __init__(self, template: tuple, dt: float, kit_of) -> None:
        """template: a one-step batch (`Stepper.new_batch(1, rows)`) whose shapes and dtypes
        the slot's arrays take; dt: the step (s); kit_of: what makes the arrays' batch kit for
        the driver (`isaac.engine.driver_kit.make_batch_kit`)."""
        sizes = [-(-a.nbytes // _ALIGN) * _ALIGN for a in template]
        self._block = np.empty(max(1, sum(sizes)), dtype=np.uint8)
        arrays, at = [], 0
        for a, size in zip(template, sizes):
            arrays.append(self._block[at : at + a.nbytes].view(a.dtype).reshape(a.shape))
            at += size
        arrays[5][:] = 0  # the offsets: the step's rows start at row 0 (the driver writes [1])
        self.arrays = tuple(arrays)  # what the driver writes
        self.kit = kit_of(self.arrays)  # (made once: 6 us)
        self._batch = StepBatch(0, dt, tuple(a.view() for a in arrays), 1)  # read-only views
        self._idle = self._references()

    def _references(self) -> tuple[int, int]:
        return sys.getrefcount(self._batch), sys.getrefcount(self._block)

    def free(self) -> bool:
        """Whether nothing outside the slot holds its batch or any view of its block."""
        return self._references() == self._idle

    @property
    def rows(self) -> int:
        """How many contact rows the slot has room for."""
        return self.arrays[6].shape[0]

    def record(self, step: int) -> StepRecord:
        """The record of the step just written, as step `step` (its views are made when first
        read, as `StepBatch.record`'s)."""
        self._batch.first = step
        return self._batch.record(0)
