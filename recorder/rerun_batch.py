"""The arrays of a batch of Rerun steps, in compiled passes (recorder.rerun_writer sends them).

A 500-body pile's batch of 100 steps is 500,000 outline vertices and 120,000 contact rows; the
numpy version of these passes (complex multiply-adds, concatenations, casts, a stable sort for
the push arrows) took 140-200 us per step, as much as a third of the step it records. Here each
output is written once, in step order. Rerun stores float32: each value is computed in float64
and rounded once.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def outlines(angle, position, idx, local, counts):
    """Closed world outlines (float32, m) of bodies ``idx`` over R steps, one after the other:
    per step, body idx[0]'s counts + 1 vertices (vertex 0 repeated last), then idx[1]'s, ...

    angle (R, n) rad, position (R, n, 2) m, local (n, V, 2) body-frame vertices (m), counts (n,)
    vertices per body; vertex = position + R(angle) @ local, counter-clockwise rotation.
    Returns the (points, 2) array.
    """
    steps = angle.shape[0]
    per_step = 0
    for j in range(idx.size):
        per_step += counts[idx[j]] + 1
    out = np.empty((steps * per_step, 2), dtype=np.float32)
    w = 0
    for s in range(steps):
        for j in range(idx.size):
            body = idx[j]
            c = np.cos(angle[s, body])
            sn = np.sin(angle[s, body])
            px = position[s, body, 0]
            py = position[s, body, 1]
            nv = counts[body]
            for v in range(nv + 1):
                lx = local[body, v % nv, 0]
                ly = local[body, v % nv, 1]
                out[w, 0] = np.float32(px + (lx * c - ly * sn))
                out[w, 1] = np.float32(py + (lx * sn + ly * c))
                w += 1
    return out


@numba.njit(cache=True, nogil=True)
def contact_arrows(counts, point, normal, impulse, push_a, push_b, normal_length,
                   impulse_scale):
    """Contact points and arrows of a batch (float32, m), rows in step order.

    counts (B,) contact rows per step; the other inputs are the steps' rows concatenated.
    Returns points, normal vectors (``normal_length`` long), impulse vectors (``j * n`` at
    ``impulse_scale`` m per N s), push origins and vectors (per step: the non-zero pushes of
    body a, then those of body b) and the number of push arrows per step.
    """
    m = point.shape[0]
    points = np.empty((m, 2), dtype=np.float32)
    normals = np.empty((m, 2), dtype=np.float32)
    impulses = np.empty((m, 2), dtype=np.float32)
    pushed = 0
    for i in range(m):
        for d in range(2):
            points[i, d] = np.float32(point[i, d])
            normals[i, d] = np.float32(normal[i, d] * normal_length)
            impulses[i, d] = np.float32(normal[i, d] * (impulse[i] * impulse_scale))
        if push_a[i, 0] != 0.0 or push_a[i, 1] != 0.0:
            pushed += 1
        if push_b[i, 0] != 0.0 or push_b[i, 1] != 0.0:
            pushed += 1
    push_pt = np.empty((pushed, 2), dtype=np.float32)
    push_v = np.empty((pushed, 2), dtype=np.float32)
    push_counts = np.zeros(counts.size, dtype=np.int64)
    w = 0
    start = 0
    for s in range(counts.size):
        stop = start + counts[s]
        for side in range(2):
            push = push_a if side == 0 else push_b
            for i in range(start, stop):
                if push[i, 0] != 0.0 or push[i, 1] != 0.0:
                    push_pt[w, 0] = points[i, 0]
                    push_pt[w, 1] = points[i, 1]
                    push_v[w, 0] = np.float32(push[i, 0])
                    push_v[w, 1] = np.float32(push[i, 1])
                    w += 1
                    push_counts[s] += 1
        start = stop
    return points, normals, impulses, push_pt, push_v, push_counts
