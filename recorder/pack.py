"""Encode a step record's `/bodies` and `/contacts` messages straight into a writer process's
shared-memory ring, checking every float on the way.

The simulating process's whole share of recording a step (see recorder.writer_process) is
writing the two protobuf messages exactly as `recorder.mcap_writer`'s `encode_bodies` and
`encode_contacts` do (tests compare the bytes), so the MCAP writer process hands them to the
mcap library as they are. One compiled call (`pack_frame`) writes every tag and length,
checks every float for NaN and infinity (the recorder's never-write-NaN check), computes the
`/stats` sums with `isaac.engine.diagnostics`' own kernel (`pack_layout`), copies each field's
values with memcpy and writes the frame's head; in Python it was 18 memcpys and a struct, about 15
us a step. Needs a little-endian machine (the caller checks).

Wire format (recorder.schema): a scalar field is its tag and a varint (uint) or 8 little-endian
bytes (double); a packed repeated field is its tag, the varint byte length and the raw
little-endian values (float64, fixed32 for the int32 indices, one byte per bool); an empty
repeated field is left out.
"""

from __future__ import annotations

import numba
import numpy as np
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic, overload

from isaac.engine.diagnostics import _sums
from isaac.engine.records import CONTACT_FIELDS as RECORD_CONTACT_FIELDS
from recorder import kernel_cache  # noqa: F401  (first: keys the kernels' numba cache)

# the fields of Bodies (numbers 3-7), in the order of recorder.schema; CONTACT_FIELDS are the
# record's (`isaac.engine.records.Contacts`): a NaN's field index is in BODY_FIELDS +
# CONTACT_FIELDS
BODY_FIELDS = ("position", "angle", "velocity", "angular_velocity", "exists")
CONTACT_FIELDS = RECORD_CONTACT_FIELDS
BODY_ROW_BYTES = (16, 8, 16, 8, 1)
BODY_ROW_BYTES_A = np.array(BODY_ROW_BYTES, dtype=np.int64)  # the same, for the kernel
# the Contacts message of format 2 (recorder.schema, recorder.mcap_writer.encode_contacts): its
# fields' numbers in message order, the bytes each takes per item, and what it has one item
# per: a manifold (K), a pushed manifold (P) or a point (M)
K, P, M = 0, 1, 2
CONTACT_NUMBERS = np.array([16, 17, 18, 19, 20, 21, 22, 25, 23, 24, 8, 10, 13, 14, 15])
CONTACT_UNIT_BYTES = np.array([4, 4, 4, 4, 4, 16, 8, 4, 16, 16, 16, 8, 8, 8, 8])
CONTACT_PER = np.array([K, K, K, K, K, K, K, P, P, P, M, M, M, M, M])

# The kernels take a step's arrays as named bundles (plain tuples, which numba types as
# tuples): state = (position (n, 2) m, angle (n,) rad, velocity (n, 2) m/s, angular_velocity
# (n,) rad/s, exists (n,) bool), BODY_FIELDS order; rows = the contact rows' arrays in
# CONTACT_FIELDS order (substep, a, b, feature, slot int32; point, normal, depth, pair_depth,
# push_a, push_b, impulse, tangent_impulse, restitution float64); model = (mass kg, inertia
# kg m^2 float64, concrete bool); gravity = (gx, gy) m/s^2. A batch's bundles hold (S, ...)
# state arrays and all its rows (`step_state`, `row_range` pick one step's).


def record_bundles(record) -> tuple[tuple, tuple]:
    """A record's (state, rows) bundles for the compiled packers (`recorder.pack`: BODY_FIELDS
    and CONTACT_FIELDS order; exists as bool, the indices as int32)."""
    c = record.contacts
    i32 = np.int32
    state = (
        record.position,
        record.angle,
        record.velocity,
        record.angular_velocity,
        np.asarray(record.exists, dtype=bool),
    )
    rows = (
        np.asarray(c.substep, dtype=i32),
        np.asarray(c.a, dtype=i32),
        np.asarray(c.b, dtype=i32),
        np.asarray(c.feature, dtype=i32),
        np.asarray(c.slot, dtype=i32),
        c.point,
        c.normal,
        c.depth,
        c.pair_depth,
        c.push_a,
        c.push_b,
        c.impulse,
        c.tangent_impulse,
        c.restitution,
    )
    return state, rows


def read_only(a: np.ndarray) -> np.ndarray:
    """A read-only view of ``a`` (``a`` itself is left writable): what the compiled packers and
    drawers are handed, always. numba compiles a kernel once per argument types, and a
    writable and a read-only array are two types: a `StepBatch`'s arrays are read-only, and
    the run's first record (`Simulation.record`), a writer process's frames and the empty
    placeholders were writable, so every kernel compiled twice or three times on a first
    run. `pack_records` alone took 14.3 + 8.8 + 2.8 s, and `isaac run scenes/default.yaml
    --mcap A --rrd B` 55 s before its first step with an empty cache (2-core machine,
    2026-12-03)."""
    view = a.view()
    view.flags.writeable = False
    return view


def batch_state(batch) -> tuple:
    """A `StepBatch`'s (S, n, ...) state bundle (`recorder.pack`)."""
    return batch.position, batch.angle, batch.velocity, batch.angular_velocity, batch.exists


def model_bundle(model) -> tuple:
    """(mass kg, inertia kg m^2, concrete) of ``model`` as the compiled packers take them."""
    return (
        np.ascontiguousarray(model.mass, dtype=np.float64),
        np.ascontiguousarray(model.inertia, dtype=np.float64),
        np.ascontiguousarray(model.concrete, dtype=bool),
    )


@numba.njit(cache=True, nogil=True)
def step_state(state, s):
    """Step s's state bundle of a batch's (S, n, ...) one."""
    position, angle, velocity, angular_velocity, exists = state
    return position[s], angle[s], velocity[s], angular_velocity[s], exists[s]


@numba.njit(cache=True, nogil=True)
def row_range(rows, r0, r1):
    """The rows bundle of rows r0 .. r1 - 1 (one step's, in a batch)."""
    (substep, a, b, feature, slot, point, normal, depth, pair_depth, push_a, push_b, impulse,
     tangent_impulse, restitution) = rows  # fmt: skip
    return (
        substep[r0:r1], a[r0:r1], b[r0:r1], feature[r0:r1], slot[r0:r1], point[r0:r1],
        normal[r0:r1], depth[r0:r1], pair_depth[r0:r1], push_a[r0:r1], push_b[r0:r1],
        impulse[r0:r1], tangent_impulse[r0:r1], restitution[r0:r1],
    )  # fmt: skip


@numba.njit(cache=True, nogil=True)
def varint_size(value: int) -> int:
    size = 1
    while value >= 0x80:
        value >>= 7
        size += 1
    return size


@numba.njit(cache=True, nogil=True)
def _message_size(head, rows, row_bytes):
    size = head
    if rows:
        for b in row_bytes:
            size += 1 + varint_size(rows * b) + rows * b
    return size


@numba.njit(cache=True, nogil=True)
def _count(per, m, k, p):
    return k if per == K else (p if per == P else m)


@numba.njit(cache=True, nogil=True)
def _contacts_size(head, m, k, p):
    """Bytes of a format 2 Contacts message of k manifolds (p of them pushed) holding m
    points."""
    size = head
    for j in range(CONTACT_NUMBERS.shape[0]):
        count = _count(CONTACT_PER[j], m, k, p)
        if count:
            nbytes = count * CONTACT_UNIT_BYTES[j]
            size += varint_size((CONTACT_NUMBERS[j] << 3) | 2) + varint_size(nbytes) + nbytes
    return size


@numba.njit(cache=True, nogil=True)
def message_sizes(step: int, n: int, m: int, k: int, p: int) -> tuple[int, int]:
    """Exact byte sizes of the Bodies and Contacts messages of a step with n bodies and m
    contact points in k manifolds, p of them pushed (compiled: the simulating process asks
    once per step)."""
    head = 1 + varint_size(step) + 1 + 8
    return (_message_size(head, n, BODY_ROW_BYTES_A), _contacts_size(head, m, k, p))


@numba.njit(cache=True, nogil=True)
def _moved(push_a, push_b, r):
    """Whether row r's push is stored: any component not +0.0 (-0.0 too: every bit is kept)."""
    moved = False
    for c in range(2):
        x = push_a[r, c]
        y = push_b[r, c]
        moved |= x != 0.0 or np.signbit(x) or y != 0.0 or np.signbit(y)
    return moved


@numba.njit(cache=True, nogil=True)
def manifold_counts(slot, push_a, push_b) -> tuple[int, int]:
    """(manifolds, pushed manifolds) of a step's contact rows: a manifold begins at slot 0;
    it is pushed when its push is stored (`_moved`)."""
    k = 0
    p = 0
    for r in range(slot.shape[0]):
        if slot[r] == 0:
            k += 1
            if _moved(push_a, push_b, r):
                p += 1
    return k, p


@numba.njit(cache=True, nogil=True)
def _varint(buf, at, value):
    while value >= 0x80:
        buf[at] = (value & 0x7F) | 0x80
        value >>= 7
        at += 1
    buf[at] = value
    return at + 1


@numba.njit(cache=True, nogil=True)
def _head(buf, at, step, time):
    """Fields 1 (uint step) and 2 (double time)."""
    at = _varint(buf, at, 1 << 3)
    at = _varint(buf, at, step)
    buf[at] = (2 << 3) | 1
    put_double(buf, at + 1, time)
    return at + 9


@numba.njit(cache=True, nogil=True)
def put_double(buf, at, value):
    """``value``'s 8 bytes (host order: little-endian) at ``buf[at:]``, whatever the alignment
    (a view of the bytes: no array allocated, which cost more than the write)."""
    buf[at : at + 8].view(np.float64)[0] = value


@numba.njit(cache=True, nogil=True)
def _field(buf, at, number, nbytes, offsets, k):
    """Tag and length of a packed field of ``nbytes`` (left out when empty); offsets[k] = where
    its values go (-1 when left out)."""
    if nbytes == 0:
        offsets[k] = -1
        return at
    at = _varint(buf, at, (number << 3) | 2)
    at = _varint(buf, at, nbytes)
    offsets[k] = at
    return at + nbytes


@numba.njit(cache=True, nogil=True)
def _finite(src):
    # .flat, not .ravel(): a ravel's reshape calls into numba's C helper, 40-50 ns a call,
    # which was most of the cost of checking a small step's thirteen arrays
    finite = True
    for v in src.flat:
        finite &= np.isfinite(v)
    return finite


@numba.njit(cache=True, nogil=True)
def _stat_sums(model, gravity, state, depth, impulse):
    """(kinetic, potential energy, linear momentum x, y, angular momentum, max depth, max
    impulse) of a step (bundles as above; depth, impulse: its rows'), as
    `recorder.stats.compute_stats` has them."""
    mass, inertia, concrete = model
    gx, gy = gravity
    position, _, velocity, angular_velocity, exists = state
    ke, pe, px, py, ang = _sums(
        mass, inertia, concrete, exists, position, velocity, angular_velocity, gx, gy
    )
    max_depth = depth[0] if depth.size else 0.0
    max_impulse = impulse[0] if impulse.size else 0.0
    for i in range(1, depth.size):
        max_depth = max(max_depth, depth[i])
        max_impulse = max(max_impulse, impulse[i])
    return ke, pe, px, py, ang, max_depth, max_impulse


@numba.njit(cache=True, nogil=True)
def _write_head(words, ints, base, step, time, n, m, sums):
    """The head both frames start with, from word ``base`` of ``words`` / ``ints`` (float64 and
    int64 views of one buffer): step, time (s), n, m, then the nine /stats values in
    frames.STAT_KEYS order (`_stat_sums`' and their derived ones)."""
    ke, pe, px, py, ang, max_depth, max_impulse = sums
    ints[base] = step
    words[base + 1] = time
    ints[base + 2] = n
    ints[base + 3] = m
    words[base + 4] = ke
    words[base + 5] = pe
    words[base + 6] = ke + pe
    words[base + 7] = px
    words[base + 8] = py
    words[base + 9] = ang
    words[base + 10] = m
    words[base + 11] = max_depth
    words[base + 12] = max_impulse


@numba.njit(cache=True, nogil=True)
def pack_layout(buf, base, step, time, n, m, k, p, contacts_at, state, rows, model, gravity):
    """Write the tags and lengths of Bodies at ``buf[base:]`` and of Contacts (format 2) at
    ``buf[base + contacts_at:]`` for n bodies and m contact points in k manifolds, p of them
    pushed (the step's bundles: see the top of this module).

    Returns (bad, offsets, bodies bytes, contacts bytes, stats): offsets (20,) = where each
    field's values go, the 5 of BODY_FIELDS then the 14 of the Contacts message in its order
    (`CONTACT_NUMBERS`; -1: left out, empty); bad = -1, or the index in BODY_FIELDS +
    CONTACT_FIELDS of the first float field holding a NaN or an infinity, in which case the
    frame must not be sent; stats = (kinetic, potential energy, linear momentum x, y, angular
    momentum, max depth, max impulse), as `recorder.stats.compute_stats` has them.
    """
    offsets = np.empty(5 + CONTACT_NUMBERS.shape[0], dtype=np.int64)
    at = _head(buf, base, step, time)
    for j in range(5):
        at = _field(buf, at, 3 + j, n * BODY_ROW_BYTES_A[j], offsets, j)
    bodies_len = at - base
    start = base + contacts_at
    at = _head(buf, start, step, time)
    for j in range(CONTACT_NUMBERS.shape[0]):
        count = _count(CONTACT_PER[j], m, k, p)
        at = _field(buf, at, CONTACT_NUMBERS[j], count * CONTACT_UNIT_BYTES[j], offsets, 5 + j)
    contacts_len = at - start
    position, angle, velocity, angular_velocity, _ = state
    (_, _, _, _, _, point, normal, depth, pair_depth, push_a, push_b, impulse, tangent_impulse,
     restitution) = rows  # fmt: skip
    bad = -1
    if not _finite(position):
        bad = 0
    if bad < 0 and not _finite(angle):
        bad = 1
    if bad < 0 and not _finite(velocity):
        bad = 2
    if bad < 0 and not _finite(angular_velocity):
        bad = 3
    if bad < 0 and not _finite(point):
        bad = 10
    if bad < 0 and not _finite(normal):
        bad = 11
    if bad < 0 and not _finite(depth):
        bad = 12
    if bad < 0 and not _finite(pair_depth):
        bad = 13
    if bad < 0 and not _finite(push_a):
        bad = 14
    if bad < 0 and not _finite(push_b):
        bad = 15
    if bad < 0 and not _finite(impulse):
        bad = 16
    if bad < 0 and not _finite(tangent_impulse):
        bad = 17
    if bad < 0 and not _finite(restitution):
        bad = 18
    return bad, offsets, bodies_len, contacts_len, _stat_sums(model, gravity, state, depth, impulse)


def copy_bytes(dst, at, src):
    """The bytes of array `src` (C order) into ``dst[at:]`` (a uint8 array).

    This body is the reference path (``NUMBA_DISABLE_JIT=1``): numpy copies the same bytes.
    Compiled code gets `_copy_bytes_memcpy` instead (the overload below)."""
    nbytes = src.size * src.itemsize
    dst[at : at + nbytes] = np.ascontiguousarray(src).reshape(-1).view(np.uint8)


@intrinsic
def _memcpy(typingctx, dst, at, src):
    """memcpy of a C-contiguous array's bytes to ``dst[at:]`` (uint8): numba's own byte loops
    ran at 2-3 GB/s, 30x slower than memcpy for a 160 kB step, and the packed fields sit at
    unaligned offsets, out of reach of a float64 view."""
    if not (
        isinstance(dst, types.Array)
        and isinstance(src, types.Array)
        and src.layout == "C"
        and isinstance(at, types.Integer)
    ):
        return None

    def codegen(context, builder, sig, args):
        d = context.make_array(sig.args[0])(context, builder, args[0])
        s = context.make_array(sig.args[2])(context, builder, args[2])
        offset = context.cast(builder, args[1], sig.args[1], types.intp)
        dst_ptr = builder.gep(d.data, [offset])
        src_ptr = builder.bitcast(s.data, dst_ptr.type)
        item = context.get_abi_sizeof(context.get_data_type(sig.args[2].dtype))
        nbytes = builder.mul(s.nitems, context.get_constant(types.intp, item))
        cgutils.raw_memcpy(builder, dst_ptr, src_ptr, nbytes, 1)
        return context.get_dummy_value()

    return types.void(dst, at, src), codegen


@overload(copy_bytes)
def _copy_bytes_memcpy(dst, at, src):
    """`copy_bytes` in compiled code: one memcpy (an intrinsic has no pure-Python form, so the
    function above stays the reference path)."""

    def impl(dst, at, src):
        _memcpy(dst, at, src)

    return impl


@numba.njit(cache=True, nogil=True)
def _put_values(buf, at, src):
    """src's bytes at ``buf[at:]`` (nothing when ``at`` < 0: the field is left out)."""
    if at >= 0:
        if at + src.size * src.itemsize > buf.size:  # memcpy checks nothing
            raise IndexError("pack_frame: a field runs past the buffer")
        copy_bytes(buf, at, np.ascontiguousarray(src))


HEAD_BYTES = 120  # frames.FRAME_HEAD: step, time, n, m, 9 stats, 2 message lengths


NOT_MANIFOLDS = 99  # pack_frame's answer for rows that are not manifolds (`_manifolds_ok`)


@numba.njit(cache=True, nogil=True)
def _same(x, y):
    """Whether two float64 are the same bits (-0.0 is not 0.0, a NaN is itself)."""
    return (x == y and np.signbit(x) == np.signbit(y)) or (x != x and y != y)


@numba.njit(cache=True, nogil=True)
def _manifolds_ok(substep, a, b, feature, slot, normal, pair_depth, push_a, push_b):
    """Whether the rows are manifolds as `recorder.mcap_writer.manifold_starts` requires (each
    begins at slot 0; a later row counts up and repeats its first row's sub-step, bodies,
    feature, normal and pair depth bit for bit, with a +0.0 push), so that format 2, which
    stores those once, keeps every bit."""
    m = slot.shape[0]
    if m and slot[0] != 0:
        return False
    for r in range(1, m):
        if slot[r] == 0:
            continue
        q = r - 1
        if slot[r] != slot[q] + 1 or substep[r] != substep[q] or a[r] != a[q] or b[r] != b[q]:
            return False
        if feature[r] != feature[q] or not _same(pair_depth[r], pair_depth[q]):
            return False
        if not (_same(normal[r, 0], normal[q, 0]) and _same(normal[r, 1], normal[q, 1])):
            return False
        if _moved(push_a, push_b, r):
            return False
    return True


@numba.njit(cache=True, nogil=True)
def _starts(slot, k):
    """The rows beginning a manifold (slot 0), k of them."""
    out = np.empty(k, dtype=np.int64)
    j = 0
    for r in range(slot.shape[0]):
        if slot[r] == 0:
            out[j] = r
            j += 1
    return out


@numba.njit(cache=True, nogil=True)
def _put_picked(buf, at, src, rows):
    """src's (k,) values at ``rows`` (a manifold's fields are its first row's) as packed values
    at ``buf[at:]``, written in place (nothing when ``at`` < 0: the field is left out)."""
    if at < 0:
        return
    nbytes = rows.shape[0] * src.itemsize
    if at + nbytes > buf.size:
        raise IndexError("pack_frame: a field runs past the buffer")
    dst = buf[at : at + nbytes].view(src.dtype)
    for j in range(rows.shape[0]):
        dst[j] = src[rows[j]]


@numba.njit(cache=True, nogil=True)
def _put_picked_pairs(buf, at, src, rows):
    """`_put_picked` of a (k, 2) float64 array (x0, y0, x1, y1, ...)."""
    if at < 0:
        return
    nbytes = rows.shape[0] * 16
    if at + nbytes > buf.size:
        raise IndexError("pack_frame: a field runs past the buffer")
    dst = buf[at : at + nbytes].view(np.float64)
    for j in range(rows.shape[0]):
        dst[2 * j] = src[rows[j], 0]
        dst[2 * j + 1] = src[rows[j], 1]


@numba.njit(cache=True, nogil=True)
def _int32s(buf, at, count):
    """``count`` int32 values at ``buf[at:]``, as a view to write into."""
    if at + 4 * count > buf.size:
        raise IndexError("pack_frame: a field runs past the buffer")
    return buf[at : at + 4 * count].view(np.int32)


@numba.njit(cache=True, nogil=True)
def pack_messages(buf, bodies_at, contacts_at, step, time, n, m, state, rows, model, gravity):
    """The Bodies message at byte ``bodies_at`` of ``buf`` (uint8) and the Contacts message
    (format 2: the manifold fields from each manifold's first row, slot 0; the rows must be
    manifolds as `recorder.mcap_writer.manifold_starts` checks) ``contacts_at`` bytes after
    it (`pack_layout`, then each field's values by memcpy). The int arrays must be int32,
    ``exists`` bool.

    Returns (k, bodies bytes, contacts bytes, offsets, stats): k = -1, or the index of the
    first float field holding a NaN or an infinity, or NOT_MANIFOLDS (nothing then is fit to
    send); offsets and stats as `pack_layout` gives them.
    """
    position, angle, velocity, angular_velocity, exists = state
    (substep, a, b, feature, slot, point, normal, depth, pair_depth, push_a, push_b, impulse,
     tangent_impulse, restitution) = rows  # fmt: skip
    k, p = manifold_counts(slot, push_a, push_b)
    bad, offsets, bodies_len, contacts_len, sums = pack_layout(
        buf, bodies_at, step, time, n, m, k, p, contacts_at, state, rows, model, gravity
    )
    if bad >= 0:
        return bad, bodies_len, contacts_len, offsets, sums
    if not _manifolds_ok(substep, a, b, feature, slot, normal, pair_depth, push_a, push_b):
        return NOT_MANIFOLDS, bodies_len, contacts_len, offsets, sums
    _put_values(buf, offsets[0], position)
    _put_values(buf, offsets[1], angle)
    _put_values(buf, offsets[2], velocity)
    _put_values(buf, offsets[3], angular_velocity)
    _put_values(buf, offsets[4], exists)
    if k:
        # the manifold fields written in place from each manifold's first row (slot 0)
        starts = _starts(slot, k)
        points = _int32s(buf, offsets[9], k)
        for j in range(k - 1):
            points[j] = starts[j + 1] - starts[j]
        points[k - 1] = m - starts[k - 1]
        moved = np.empty(p, dtype=np.int64)
        if p:
            pushed = _int32s(buf, offsets[12], p)
            q = 0
            for j in range(k):
                if _moved(push_a, push_b, starts[j]):
                    pushed[q] = j
                    moved[q] = starts[j]
                    q += 1
        _put_picked(buf, offsets[5], substep, starts)
        _put_picked(buf, offsets[6], a, starts)
        _put_picked(buf, offsets[7], b, starts)
        _put_picked(buf, offsets[8], feature, starts)
        _put_picked_pairs(buf, offsets[10], normal, starts)
        _put_picked(buf, offsets[11], pair_depth, starts)
        _put_picked_pairs(buf, offsets[13], push_a, moved)
        _put_picked_pairs(buf, offsets[14], push_b, moved)
    _put_values(buf, offsets[15], point)
    _put_values(buf, offsets[16], depth)
    _put_values(buf, offsets[17], impulse)
    _put_values(buf, offsets[18], tangent_impulse)
    _put_values(buf, offsets[19], restitution)
    return -1, bodies_len, contacts_len, offsets, sums


@numba.njit(cache=True, nogil=True)
def pack_frame(buf, pos, step, time, n, m, contacts_at, state, rows, model, gravity):
    """A whole MCAP frame at byte ``pos`` (a multiple of 8) of ``buf`` (uint8): the head
    (frames.FRAME_HEAD, native = little-endian: step, time s, n, m, the nine /stats values,
    the two messages' lengths), the Bodies message at ``pos + HEAD_BYTES`` and the Contacts
    message ``contacts_at`` bytes after it, in one call (`pack_messages`).

    Returns (k, bodies bytes, contacts bytes): k = -1, or the index of the first float field
    holding a NaN or an infinity, or NOT_MANIFOLDS (nothing then is fit to send).
    """
    bad, bodies_len, contacts_len, _, sums = pack_messages(
        buf, pos + HEAD_BYTES, contacts_at, step, time, n, m, state, rows, model, gravity
    )
    if bad >= 0:
        return bad, bodies_len, contacts_len
    # the padding after each message is zero, as `recorder.frames.pack` writes it (a ring
    # slot holds an older frame's bytes)
    body_end = pos + HEAD_BYTES + bodies_len
    buf[body_end : pos + HEAD_BYTES + contacts_at] = 0
    contacts_end = pos + HEAD_BYTES + contacts_at + contacts_len
    buf[contacts_end : pos + HEAD_BYTES + contacts_at + ((contacts_len + 7) & ~7)] = 0
    ints = buf[pos : pos + HEAD_BYTES].view(np.int64)
    _write_head(buf[pos : pos + HEAD_BYTES].view(np.float64), ints, 0, step, time, n, m, sums)
    ints[13] = bodies_len
    ints[14] = contacts_len
    return bad, bodies_len, contacts_len


# -- the Rerun writer's frame ------------------------------------------------------------------
# The Rerun writer process needs far less than the MCAP messages (no velocities, indices,
# depths...) and decoded protobuf cost it a quarter of its time, so its frame is raw
# native-endian arrays (both ends run on one machine), each at an 8-byte boundary, in units of
# 8-byte words: the head (RERUN_HEAD words: step int64, time float64 s, n int64, m int64, the
# nine `/stats` values as float64 in frames.STAT_KEYS order), then position (n, 2) m,
# angle (n,) rad, exists (n,) one byte each, point (m, 2) m, normal (m, 2), impulse (m,) N s,
# push_a (m, 2) m, push_b (m, 2) m.
RERUN_HEAD = 13


def rerun_offsets(n, m):
    """Word offsets of a Rerun frame's arrays for n bodies and m contact rows: position, angle,
    exists (a byte offset is 8x), point, normal, impulse, push_a, push_b, and the frame's end."""
    position = RERUN_HEAD
    angle = position + 2 * n
    exists = angle + n
    point = exists + (n + 7) // 8
    normal = point + 2 * m
    impulse = normal + 2 * m
    push_a = impulse + m
    push_b = push_a + 2 * m
    return position, angle, exists, point, normal, impulse, push_a, push_b, push_b + 2 * m


_rerun_offsets = numba.njit(cache=True, nogil=True)(rerun_offsets)  # the same rule, compiled


@numba.njit(cache=True, nogil=True)
def _put_pairs(words, at, src):
    """src (k, 2) float64 into words[at:at + 2k]; True when every value is finite."""
    ok = True
    for i in range(src.shape[0]):
        x = src[i, 0]
        y = src[i, 1]
        words[at + 2 * i] = x
        words[at + 2 * i + 1] = y
        ok &= np.isfinite(x) & np.isfinite(y)
    return ok


@numba.njit(cache=True, nogil=True)
def _put(words, at, src):
    """src (k,) float64 into words[at:at + k]; True when every value is finite."""
    ok = True
    for i in range(src.shape[0]):
        x = src[i]
        words[at + i] = x
        ok &= np.isfinite(x)
    return ok


@numba.njit(cache=True, nogil=True)
def _first(bad, k):
    """The smaller field index of ``bad`` (-1: none yet) and ``k``."""
    return k if bad < 0 or k < bad else bad


@numba.njit(cache=True, nogil=True)
def pack_rerun(buf, at, step, time, state, rows, model, gravity):
    """Write a step's Rerun frame (layout above) at byte ``at`` (a multiple of 8) of ``buf``
    (uint8, a multiple of 8 bytes long), check every float of the record and sum the `/stats`
    values as `pack_layout` does.

    Returns -1, or the index (in BODY_FIELDS + CONTACT_FIELDS) of the first float field holding
    a NaN or an infinity; the frame must then not be sent. Fields the frame leaves out
    (velocities, depths, tangent impulse, restitution) are checked all the same: the recorder's
    never-write-NaN check is this pass when the Rerun writer is the only one.
    """
    position, angle, velocity, angular_velocity, exists = state
    (_, _, _, _, _, point, normal, depth, pair_depth, push_a, push_b, impulse, tangent_impulse,
     restitution) = rows  # fmt: skip
    words = buf.view(np.float64)
    ints = buf.view(np.int64)
    n = angle.shape[0]
    m = depth.shape[0]
    base = at // 8
    o = _rerun_offsets(n, m)
    bad = -1
    if not _put_pairs(words, base + o[0], position):
        bad = _first(bad, 0)
    if not _put(words, base + o[1], angle):
        bad = _first(bad, 1)
    flags = (base + o[2]) * 8
    for i in range(n):
        buf[flags + i] = 1 if exists[i] else 0
    if not _put_pairs(words, base + o[3], point):
        bad = _first(bad, 10)
    if not _put_pairs(words, base + o[4], normal):
        bad = _first(bad, 11)
    if not _put(words, base + o[5], impulse):
        bad = _first(bad, 16)
    if not _put_pairs(words, base + o[6], push_a):
        bad = _first(bad, 14)
    if not _put_pairs(words, base + o[7], push_b):
        bad = _first(bad, 15)
    # the floats the frame leaves out
    if not _finite(velocity):
        bad = _first(bad, 2)
    if not _finite(angular_velocity):
        bad = _first(bad, 3)
    if not _finite(depth):
        bad = _first(bad, 12)
    if not _finite(pair_depth):
        bad = _first(bad, 13)
    if not _finite(tangent_impulse):
        bad = _first(bad, 17)
    if not _finite(restitution):
        bad = _first(bad, 18)
    sums = _stat_sums(model, gravity, state, depth, impulse)
    _write_head(words, ints, base, step, time, n, m, sums)
    return bad


# -- a batch of MCAP frames in one call --------------------------------------------------------
@numba.njit(cache=True, nogil=True)
def frame_sizes_of(first, n, offsets, slot, push_a, push_b, head_bytes):
    """Each step's (Bodies bytes, Contacts bytes, frame bytes) for a `StepBatch` whose first
    record is step `first` (offsets: its row offsets; slot, push_a, push_b: its rows'), as
    `recorder.frames.frame_sizes` gives them one at a time: a (steps, 3) int64 array."""
    steps = offsets.shape[0] - 1
    out = np.empty((steps, 3), dtype=np.int64)
    for s in range(steps):
        r0 = offsets[s]
        r1 = offsets[s + 1]
        k, p = manifold_counts(slot[r0:r1], push_a[r0:r1], push_b[r0:r1])
        bodies, contacts = message_sizes(first + s, n, r1 - r0, k, p)
        out[s, 0] = bodies
        out[s, 1] = contacts
        out[s, 2] = head_bytes + ((bodies + 7) & ~7) + ((contacts + 7) & ~7)
    return out


@numba.njit(cache=True, nogil=True)
def pack_frames(buf, pos, lo, hi, first, dt, sizes, offsets, state, rows, model, gravity):
    """Steps lo .. hi - 1 of a batch (the arrays of `isaac.engine.driver.Batch`; step s is
    state index first + s at time (first + s) * dt s, as `StepBatch.record` computes it) as
    consecutive `pack_frame` frames from byte `pos` of `buf`, frame sizes from
    `frame_sizes_of`. Returns the first step holding a NaN or an infinity or rows that are not
    manifolds (its frame and the ones after it unwritten), or hi."""
    n = state[1].shape[1]
    at = pos
    for s in range(lo, hi):
        r0 = offsets[s]
        r1 = offsets[s + 1]
        step = first + s
        bad, _, _ = pack_frame(
            buf, at, step, step * dt, n, r1 - r0, (sizes[s, 0] + 7) & ~7, step_state(state, s),
            row_range(rows, r0, r1), model, gravity,
        )  # fmt: skip
        if bad >= 0:
            return s
        at += sizes[s, 2]
    return hi
