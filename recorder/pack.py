"""Copy a step record into a writer process's shared-memory ring, checking it on the way.

The parent's whole share of recording a step (see recorder.writer_process) is this copy, so it
is one compiled pass: every array is copied into its block of the frame (the layout of
`recorder.writer_process.frame_layout`), and every float is checked for NaN and infinity while
it passes, which is the recorder's never-write-NaN check. Only the parent imports this module
(the writer processes start without numba).
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def _f8(ring, at, src):
    """Copy float64 `src` (any shape, C order) to ring[at:]; True if every value is finite."""
    flat = src.ravel()
    finite = True
    for i in range(flat.size):
        x = flat[i]
        ring[at + i] = x
        finite &= np.isfinite(x)
    return finite


@numba.njit(cache=True, nogil=True)
def _i4(ring, at, src):
    for i in range(src.size):
        ring[at + i] = src[i]


@numba.njit(cache=True, nogil=True)
def pack_frame(ring_f8, ring_i4, ring_u8, base, head_bytes, row_bytes, n, m, position, angle,
               velocity, angular_velocity, exists, substep, a, b, feature, slot, point, normal,
               depth, push_a, push_b, impulse, tangent_impulse, restitution):
    """Copy the record's arrays into the frame at byte ``base`` of the ring (``ring_*`` are three
    views of one buffer), after its ``head_bytes`` header, in `writer_process` field order:
    field k has ``row_bytes[k]`` bytes per row, n rows for the 5 body fields, m for the 13
    contact fields, each block padded to 8 bytes (`writer_process.frame_blocks`' rule).

    Returns -1, or the index (in that order) of the first float field holding a NaN or an
    infinity; the frame is then incomplete and must not be sent.
    """
    offsets = np.empty(18, dtype=np.int64)
    at = head_bytes
    for k in range(18):
        offsets[k] = at
        at += (row_bytes[k] * (n if k < 5 else m) + 7) // 8 * 8
    ok = np.ones(18, dtype=np.bool_)
    ok[0] = _f8(ring_f8, (base + offsets[0]) // 8, position)
    ok[1] = _f8(ring_f8, (base + offsets[1]) // 8, angle)
    ok[2] = _f8(ring_f8, (base + offsets[2]) // 8, velocity)
    ok[3] = _f8(ring_f8, (base + offsets[3]) // 8, angular_velocity)
    at = base + offsets[4]
    for i in range(exists.size):
        ring_u8[at + i] = exists[i]
    _i4(ring_i4, (base + offsets[5]) // 4, substep)
    _i4(ring_i4, (base + offsets[6]) // 4, a)
    _i4(ring_i4, (base + offsets[7]) // 4, b)
    _i4(ring_i4, (base + offsets[8]) // 4, feature)
    _i4(ring_i4, (base + offsets[9]) // 4, slot)
    ok[10] = _f8(ring_f8, (base + offsets[10]) // 8, point)
    ok[11] = _f8(ring_f8, (base + offsets[11]) // 8, normal)
    ok[12] = _f8(ring_f8, (base + offsets[12]) // 8, depth)
    ok[13] = _f8(ring_f8, (base + offsets[13]) // 8, push_a)
    ok[14] = _f8(ring_f8, (base + offsets[14]) // 8, push_b)
    ok[15] = _f8(ring_f8, (base + offsets[15]) // 8, impulse)
    ok[16] = _f8(ring_f8, (base + offsets[16]) // 8, tangent_impulse)
    ok[17] = _f8(ring_f8, (base + offsets[17]) // 8, restitution)
    for k in range(18):
        if not ok[k]:
            return k
    return -1
