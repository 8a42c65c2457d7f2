"""A log's time stamps: ``log_time`` (ns) of a step from its index, exactly.

Its own module so that everything that stamps records (`recorder.mcap_writer`, the compiled
packer `recorder.mcap_pack`) shares one definition without importing each other.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np


class LogClock:
    """``log_time`` (ns) of a step from its index, in integer arithmetic.

    ``dt`` is turned into the exact rational value of its float64 bits, so
    ``log_time(k) = round(k * dt * 1e9)`` exactly (halves rounded up), never accumulated.
    """

    def __init__(self, dt: float) -> None:
        frac = Fraction(dt) * 1_000_000_000
        self.num = frac.numerator
        self.den = frac.denominator

    def __call__(self, step: int) -> int:
        return (2 * step * self.num + self.den) // (2 * self.den)

    def times(self, first: int, count: int) -> np.ndarray:
        """(count,) int64: the log times of steps first .. first + count - 1, each as
        ``self(step)`` computes it (Python integers in numpy's loops: the products pass 2^63)."""
        steps = np.arange(first, first + count, dtype=object)
        return ((2 * self.num * steps + self.den) // (2 * self.den)).astype(np.int64)
