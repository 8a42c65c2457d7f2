"""The arrays a Rerun step draws, computed by compiled kernels as each step arrives
(recorder.rerun_writer buffers them and sends a batch of steps at once).

A 500-body pile's batch of 100 steps is 500,000 outline vertices and 120,000 contact rows; the
numpy version of these passes (complex multiply-adds, concatenations, casts, a stable sort for
the push arrows) took 140-200 us per step, as much as a third of the step it records. Here each
output is written once, straight into the batch's float32 buffers, from the step's own arrays
(in the Rerun writer process: the shared-memory frame), so no float64 copy of the step is kept.
Rerun stores float32: each value is computed in float64 and rounded once.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def step_outlines(angle, position, idx, local, counts, out, at):
    """Closed world outlines (float32, m) of bodies ``idx`` at one step, written to ``out[at:]``
    one after the other: body idx[0]'s counts + 1 vertices (vertex 0 repeated last), then
    idx[1]'s, ...; returns the row after the last one written.

    angle (n,) rad, position (n, 2) m, local (n, V, 2) body-frame vertices (m), counts (n,)
    vertices per body; vertex = position + R(angle) @ local, counter-clockwise rotation.
    """
    w = at
    for j in range(idx.size):
        body = idx[j]
        c = np.cos(angle[body])
        sn = np.sin(angle[body])
        px = position[body, 0]
        py = position[body, 1]
        nv = counts[body]
        for v in range(nv):
            lx = local[body, v, 0]
            ly = local[body, v, 1]
            out[w + v, 0] = np.float32(px + (lx * c - ly * sn))
            out[w + v, 1] = np.float32(py + (lx * sn + ly * c))
        out[w + nv, 0] = out[w, 0]  # closed: vertex 0 again (the same float32 values)
        out[w + nv, 1] = out[w, 1]
        w += nv + 1
    return w


@numba.njit(cache=True, nogil=True)
def step_contacts(
    point,
    normal,
    impulse,
    push_a,
    push_b,
    normal_length,
    impulse_scale,
    points,
    normals,
    impulses,
    at,
    push_pt,
    push_v,
    push_at,
):
    """A step's contact points and arrows (float32, m), written from row ``at`` of points,
    normals and impulses and from row ``push_at`` of push_pt and push_v; returns the row after
    the last push arrow written.

    normals are ``normal_length`` long, impulses ``j * n`` at ``impulse_scale`` m per N s;
    push arrows start at the contact point: the non-zero pushes of body a, then those of b.
    """
    m = point.shape[0]
    for i in range(m):
        nx = normal[i, 0]
        ny = normal[i, 1]
        j = impulse[i] * impulse_scale
        points[at + i, 0] = np.float32(point[i, 0])
        points[at + i, 1] = np.float32(point[i, 1])
        normals[at + i, 0] = np.float32(nx * normal_length)
        normals[at + i, 1] = np.float32(ny * normal_length)
        impulses[at + i, 0] = np.float32(nx * j)
        impulses[at + i, 1] = np.float32(ny * j)
    w = push_at
    for side in range(2):
        push = push_a if side == 0 else push_b
        for i in range(m):
            x = push[i, 0]
            y = push[i, 1]
            if x != 0.0 or y != 0.0:
                push_pt[w, 0] = points[at + i, 0]
                push_pt[w, 1] = points[at + i, 1]
                push_v[w, 0] = np.float32(x)
                push_v[w, 1] = np.float32(y)
                w += 1
    return w


@numba.njit(cache=True, nogil=True)
def step_arrays(
    angle,
    position,
    idx,
    local,
    counts,
    strips,
    strip_at,
    point,
    normal,
    impulse,
    push_a,
    push_b,
    normal_length,
    impulse_scale,
    points,
    normals,
    impulses,
    row_at,
    push_pt,
    push_v,
    push_at,
):
    """`step_outlines` and `step_contacts` of one step in one call (one dispatch per step);
    returns the next free rows of strips and of the push arrows."""
    strip_end = step_outlines(angle, position, idx, local, counts, strips, strip_at)
    push_end = step_contacts(
        point,
        normal,
        impulse,
        push_a,
        push_b,
        normal_length,
        impulse_scale,
        points,
        normals,
        impulses,
        row_at,
        push_pt,
        push_v,
        push_at,
    )
    return strip_end, push_end
