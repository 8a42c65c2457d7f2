"""How many steps: the one check of a count a caller hands the engine (`advance`, `run`,
`batches`, a batch size, a batch's place), before compiled code counts with it."""

from __future__ import annotations

import numpy as np

# the largest count or step index: the kernels count steps in int64 (a step index and the steps
# still to take added up stay below 2^63)
LARGEST = 1 << 62


def count(value, what: str, *, minimum: int = 0) -> int:
    """`value` as an int in minimum .. LARGEST: a Python or numpy integer (not a bool);
    TypeError for anything else (1.5, "3", None), ValueError outside the range. `what` names
    it in the message ("steps")."""
    if type(value) is int and minimum <= value <= LARGEST:  # the common case, first
        return value
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{what} must be an int >= {minimum}, got {value!r}")
    if not minimum <= value <= LARGEST:
        raise ValueError(f"{what} must be an int from {minimum} to 2^62, got {value}")
    return int(value)
