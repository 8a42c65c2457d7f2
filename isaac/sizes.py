"""A byte count as a person reads it, the one way every message of ISAAC writes one."""

from __future__ import annotations


def byte_size(n: float) -> str:
    """``n`` bytes in binary units (KiB, MiB, GiB: powers of 1024, as the limits and chunk sizes
    they are compared with are defined), three significant digits, e.g. ``'3.05 MiB'``;
    below 1 KiB, ``'512 bytes'``."""
    for unit, shift in (("GiB", 30), ("MiB", 20), ("KiB", 10)):
        if n >= 1 << shift:
            return f"{n / (1 << shift):.3g} {unit}"
    return f"{int(n)} bytes"
