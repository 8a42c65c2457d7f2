"""The arrays a Rerun recording draws, computed by compiled kernels over whole batches of steps
(recorder.rerun_writer buffers them and sends them column-wise, ``send_columns``).

A 500-body pile's batch of 100 steps is 500,000 outline vertices and 120,000 contact rows; the
numpy version of these passes (complex multiply-adds, concatenations, casts, a stable sort for
the push arrows) took 140-200 us per step, as much as a third of the step it records. Here each
output is written once, straight into the batch's float32 buffers, from the steps' own arrays:
a `StepBatch`'s (all its steps in one call, `draw_steps`) or one step's (a writer process's
shared-memory frame, a batch of one), so no float64 copy of a step is kept.
Rerun stores float32: each value is computed in float64 and rounded once.

Outputs per step, in the `Buffers` bundle, each appended after what the batch holds already:
- outlines: the moving bodies that exist, in body order, each a closed strip (its vertices,
  then vertex 0 again);
- contact rows: the point, the normal drawn ``normal_length`` m long, the impulse ``j n`` at
  ``impulse_scale`` m per N s;
- push arrows: at the contact point, the non-zero push-outs of body a (row order), then of
  body b, drawn ``push_scale`` times their length;
- joints whose two bodies exist, in joint order: the world anchors of a and of b, from the
  step's poses and each joint's body-frame anchors (the engine's `JointRows.anchor_a/_b` are
  the same sums; for a revolute joint they coincide, the pivot).
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from recorder import kernel_cache  # noqa: F401  (first: keys the kernels' numba cache)
from recorder.pack import _stat_sums, step_state

# the columns of Buffers.per_step and the cursors of Buffers.at
STRIPS, ROWS, PUSHES, JOINTS = 0, 1, 2, 3  # per_step: strips, contact rows, push arrows, joints
AT_POINTS, AT_STRIPS, AT_ROWS, AT_PUSHES, AT_JOINTS, AT_STEPS = range(6)


class Drawing(NamedTuple):
    """What a run draws that does not change from step to step.

    local: (n, V, 2) m, each body's drawn vertices in its frame (recorder.shapes.drawn_shapes);
    counts: (n,) int64 vertices per body; moving: (n,) bool, drawn each step (not concrete);
    joint_a, joint_b: (m,) int64 each joint's bodies; local_a, local_b: (m, 2) m, its anchors
    in a's and b's frames; scales: (3,) float64 normal_length (m), impulse_scale (m per N s),
    push_scale (a push-out arrow's drawn length over its own).
    """

    local: np.ndarray
    counts: np.ndarray
    moving: np.ndarray
    joint_a: np.ndarray
    joint_b: np.ndarray
    local_a: np.ndarray
    local_b: np.ndarray
    scales: np.ndarray


class Buffers(NamedTuple):
    """The open batch's float32 outputs (m) and counts, filled by `draw_steps`.

    strips (P, 2): outline points, strip after strip; strip_len (Q,) int32: points per strip;
    points, normals, impulses (R, 2): per contact row; push_pt, push_v (2R, 2): push arrows;
    joints (J, 2): per joint drawn, its anchor on a then its anchor on b; per_step (B, 4) int64:
    each step's strips, rows, push arrows and joints (STRIPS .. JOINTS); at (6,) int64: the next
    free place in each (AT_POINTS .. AT_STEPS).
    """

    strips: np.ndarray
    strip_len: np.ndarray
    points: np.ndarray
    normals: np.ndarray
    impulses: np.ndarray
    push_pt: np.ndarray
    push_v: np.ndarray
    joints: np.ndarray
    per_step: np.ndarray
    at: np.ndarray


@numba.njit(cache=True, nogil=True)
def _outline(angle, position, local, nv, out, w):
    """A closed world outline into out[w:], vertex = position + R(angle) @ local (CCW)."""
    c = np.cos(angle)
    sn = np.sin(angle)
    px = position[0]
    py = position[1]
    for v in range(nv):
        lx = local[v, 0]
        ly = local[v, 1]
        out[w + v, 0] = np.float32(px + (lx * c - ly * sn))
        out[w + v, 1] = np.float32(py + (lx * sn + ly * c))
    out[w + nv, 0] = out[w, 0]  # closed: vertex 0 again (the same float32 values)
    out[w + nv, 1] = out[w, 1]
    return w + nv + 1


@numba.njit(cache=True, nogil=True)
def step_outlines(angle, position, idx, local, counts, out, at):
    """Closed world outlines (float32, m) of bodies ``idx`` at one step, written to ``out[at:]``
    one after the other (body idx[0]'s counts + 1 vertices, then idx[1]'s, ...); returns the
    row after the last one written. angle (n,) rad, position (n, 2) m, local (n, V, 2) m,
    counts (n,)."""
    w = at
    for j in range(idx.size):
        body = idx[j]
        w = _outline(angle[body], position[body], local[body], counts[body], out, w)
    return w


@numba.njit(cache=True, nogil=True)
def _anchor(angle, position, local):
    """A body-frame point (m) in the world: position + R(angle) @ local."""
    c = np.cos(angle)
    sn = np.sin(angle)
    return (
        position[0] + (local[0] * c - local[1] * sn),
        position[1] + (local[0] * sn + local[1] * c),
    )


@numba.njit(cache=True, nogil=True)
def draw_steps(angle, position, exists, offsets, point, normal, impulse, push_a, push_b, d, out):
    """Append what steps 0 .. S - 1 draw to ``out`` (`Buffers`; room for them is the caller's).

    angle (S, n) rad, position (S, n, 2) m, exists (S, n) bool: the state after each step;
    offsets (S + 1,): step s's contact rows are rows offsets[s] .. offsets[s + 1] of point
    (m, 2) m, normal (unit, a to b), impulse (N s), push_a and push_b (m); d: `Drawing`.
    """
    at = out.at
    normal_length = d.scales[0]
    impulse_scale = d.scales[1]
    push_scale = d.scales[2]
    for s in range(angle.shape[0]):
        k = at[AT_STEPS]
        # outlines: the moving bodies that exist, in body order
        w = at[AT_POINTS]
        q = at[AT_STRIPS]
        for body in range(d.moving.shape[0]):
            if d.moving[body] and exists[s, body]:
                nv = d.counts[body]
                w = _outline(angle[s, body], position[s, body], d.local[body], nv, out.strips, w)
                out.strip_len[q] = nv + 1
                q += 1
        out.per_step[k, STRIPS] = q - at[AT_STRIPS]
        at[AT_POINTS] = w
        at[AT_STRIPS] = q
        # contact rows
        r = at[AT_ROWS]
        lo = offsets[s]
        hi = offsets[s + 1]
        for i in range(lo, hi):
            nx = normal[i, 0]
            ny = normal[i, 1]
            j = impulse[i] * impulse_scale
            out.points[r, 0] = np.float32(point[i, 0])
            out.points[r, 1] = np.float32(point[i, 1])
            out.normals[r, 0] = np.float32(nx * normal_length)
            out.normals[r, 1] = np.float32(ny * normal_length)
            out.impulses[r, 0] = np.float32(nx * j)
            out.impulses[r, 1] = np.float32(ny * j)
            r += 1
        # push arrows: a's non-zero pushes, then b's
        p = at[AT_PUSHES]
        for side in range(2):
            push = push_a if side == 0 else push_b
            for i in range(lo, hi):
                x = push[i, 0]
                y = push[i, 1]
                if x != 0.0 or y != 0.0:
                    out.push_pt[p, 0] = out.points[at[AT_ROWS] + i - lo, 0]
                    out.push_pt[p, 1] = out.points[at[AT_ROWS] + i - lo, 1]
                    out.push_v[p, 0] = np.float32(x * push_scale)
                    out.push_v[p, 1] = np.float32(y * push_scale)
                    p += 1
        out.per_step[k, ROWS] = r - at[AT_ROWS]
        out.per_step[k, PUSHES] = p - at[AT_PUSHES]
        at[AT_ROWS] = r
        at[AT_PUSHES] = p
        # joints whose bodies both exist: anchor on a, anchor on b
        g = at[AT_JOINTS]
        drawn = 0
        for jt in range(d.joint_a.shape[0]):
            a = d.joint_a[jt]
            b = d.joint_b[jt]
            if not (exists[s, a] and exists[s, b]):
                continue
            ax, ay = _anchor(angle[s, a], position[s, a], d.local_a[jt])
            bx, by = _anchor(angle[s, b], position[s, b], d.local_b[jt])
            out.joints[g, 0] = np.float32(ax)
            out.joints[g, 1] = np.float32(ay)
            out.joints[g + 1, 0] = np.float32(bx)
            out.joints[g + 1, 1] = np.float32(by)
            g += 2
            drawn += 1
        out.per_step[k, JOINTS] = drawn
        at[AT_JOINTS] = g
        at[AT_STEPS] = k + 1


@numba.njit(cache=True, nogil=True)
def _finite_rows(src, lo, hi):
    ok = True
    for i in range(lo, hi):
        for c in range(src.shape[1]):
            ok &= np.isfinite(src[i, c])
    return ok


@numba.njit(cache=True, nogil=True)
def _finite_values(src, lo, hi):
    ok = True
    for i in range(lo, hi):
        ok &= np.isfinite(src[i])
    return ok


@numba.njit(cache=True, nogil=True)
def batch_stats(model, gravity, state, offsets, rows, out):
    """Each step's nine `/stats` values (recorder.rerun_writer.STAT_NAMES order, as
    `recorder.stats.compute_stats` has them, the same kernel for the sums) into out (S, 9),
    checking every float of the step on the way. Returns the first step holding a NaN or an
    infinity (its stats and those after it not written), or S.

    A `isaac.engine.records.StepBatch`'s bundles (`recorder.pack`): state, the (S, n, ...)
    arrays after each step; rows, the contact rows, step s's at offsets[s] .. offsets[s + 1];
    model (mass kg, inertia kg m^2, concrete); gravity (gx, gy) m/s^2.
    """
    position, angle, velocity, angular_velocity, _ = state
    (_, _, _, _, _, point, normal, depth, pair_depth, push_a, push_b, impulse, tangent_impulse,
     restitution) = rows  # fmt: skip
    steps = angle.shape[0]
    for s in range(steps):
        lo = offsets[s]
        hi = offsets[s + 1]
        n = angle.shape[1]
        ok = _finite_rows(position[s], 0, n) and _finite_values(angle[s], 0, n)
        ok = ok and _finite_rows(velocity[s], 0, n) and _finite_values(angular_velocity[s], 0, n)
        ok = ok and _finite_rows(point, lo, hi) and _finite_rows(normal, lo, hi)
        ok = ok and _finite_values(depth, lo, hi) and _finite_values(pair_depth, lo, hi)
        ok = ok and _finite_rows(push_a, lo, hi) and _finite_rows(push_b, lo, hi)
        ok = ok and _finite_values(impulse, lo, hi) and _finite_values(tangent_impulse, lo, hi)
        ok = ok and _finite_values(restitution, lo, hi)
        if not ok:
            return s
        ke, pe, px, py, ang, max_depth, max_impulse = _stat_sums(
            model, gravity, step_state(state, s), depth[lo:hi], impulse[lo:hi]
        )
        out[s, 0] = ke
        out[s, 1] = pe
        out[s, 2] = ke + pe
        out[s, 3] = px
        out[s, 4] = py
        out[s, 5] = ang
        out[s, 6] = hi - lo
        out[s, 7] = max_depth
        out[s, 8] = max_impulse
    return steps
