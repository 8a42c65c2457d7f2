"""Whole MCAP Message records of a stretch of steps, packed by one compiled call.

A step's messages leave the simulating process as the MCAP file holds them: each a Message
record (mcap spec: opcode 0x05, u64 record length, u16 channel id, u32 sequence, u64 log_time,
u64 publish_time, then the data), the records of consecutive steps laid end to end in one
buffer. `pack_records` writes every step's `/bodies`, `/contacts`, `/joints` (a scene with
joints) and `/stats` (with the state hash), byte for byte what `recorder.mcap_writer`'s
Python encoders give (tests compare), checks every float for NaN and infinity on the way and
copies in the `/world` records the caller encoded for the steps where a body entered or left
(rare: the caller finds them with `world_steps`). `recorder.mcap_file.McapFile.append` then
enters a whole stretch into the open chunk in one copy. No Python runs per step or per
message on this path; it replaced about 15 us of Python per message (mcap's `add_message`,
`Message.write`, the per-step encoders and frame parsing).

The state hash (`isaac.engine.records.state_hash`: sha256 of the step's body fields) is
computed by OpenSSL's ``SHA256``, the library Python's ``hashlib`` itself calls, reached through
the ``_hashlib`` module (`sha256_address`, checked against ``hashlib`` once). Where that symbol
cannot be found the kernel leaves the hash out and `fill_hashes` writes it with ``hashlib``,
one step at a time. With ``NUMBA_DISABLE_JIT=1`` (the reference path) the kernel's hash is
``hashlib``'s.

Little-endian machines only (the caller checks): the records' integers and the messages'
floats are written in the host's byte order.
"""

from __future__ import annotations

import functools
import hashlib
import struct
from typing import NamedTuple

import numba
import numpy as np
from llvmlite import ir
from numba import types
from numba.extending import intrinsic, overload

from recorder import kernel_cache  # noqa: F401  (first: keys the kernels' numba cache)
from recorder.log_time import LogClock
from recorder.pack import (
    _finite,
    _head,
    _manifolds_ok,
    _varint,
    batch_state,
    copy_bytes,
    manifold_counts,
    message_sizes,
    model_bundle,
    pack_messages,
    put_double,
    read_only,
    row_range,
    step_state,
    varint_size,
)

OP_MESSAGE = 0x05
RECORD_HEAD = 31  # opcode 1, record length 8, channel id 2, sequence 4, log_time 8, publish 8
HASH_HEX = 64  # a sha256 in hex: /stats field 12
MAX_SEQUENCE = 0xFFFFFFFF  # a Message record's sequence is a u32: sequence = step

# packed repeated doubles of isaac.log.Joints in field order (recorder.mcap_writer.JOINT_WIRE)
# and the float64s each takes per joint
JOINT_NUMBERS = np.array([3, 4, 5, 6, 7, 8, 9, 10])
JOINT_UNITS = np.array([2, 2, 2, 1, 1, 1, 2, 6])

# what `pack_records` found wrong with the step it stopped at (besides a field index of
# `recorder.pack.BODY_FIELDS + CONTACT_FIELDS`)
NOT_MANIFOLDS = 99  # = recorder.pack.NOT_MANIFOLDS
JOINT_NOT_FINITE = 100

_HEX = np.frombuffer(b"0123456789abcdef", dtype=np.uint8)
_RECORD = struct.Struct("<BQHIQQ")


def message_record(channel: int, step: int, log_time: int, data: bytes) -> bytes:
    """One Message record as `mcap.records.Message.write` lays it out (sequence = step,
    publish_time = log_time)."""
    return _RECORD.pack(OP_MESSAGE, 22 + len(data), channel, step, log_time, log_time) + data


# -- sha256 through OpenSSL ---------------------------------------------------------------------
def sha256_digest(fn, src, out):
    """sha256 of ``src``'s bytes (uint8, C order) into ``out`` (32 uint8).

    This body is the reference path (``NUMBA_DISABLE_JIT=1``): ``hashlib``. Compiled code calls
    OpenSSL's ``SHA256(data, length, out)`` at address ``fn`` (`sha256_address`) instead."""
    out[:] = np.frombuffer(hashlib.sha256(src.tobytes()).digest(), dtype=np.uint8)


@intrinsic
def _call_sha256(typingctx, fn, src, out):
    """``SHA256(src, len, out)`` through the function pointer ``fn`` (an int64 argument, so the
    compiled code holds no address and stays cacheable across processes)."""
    if not (
        isinstance(fn, types.Integer)
        and isinstance(src, types.Array)
        and isinstance(out, types.Array)
    ):
        return None

    def codegen(context, builder, sig, args):
        s = context.make_array(sig.args[1])(context, builder, args[1])
        o = context.make_array(sig.args[2])(context, builder, args[2])
        bytes_ptr = ir.IntType(8).as_pointer()
        size_t = ir.IntType(64)
        fnty = ir.FunctionType(bytes_ptr, [bytes_ptr, size_t, bytes_ptr])
        target = builder.inttoptr(args[0], fnty.as_pointer())
        nbytes = builder.zext(s.nitems, size_t) if s.nitems.type.width < 64 else s.nitems
        builder.call(
            target, [builder.bitcast(s.data, bytes_ptr), nbytes, builder.bitcast(o.data, bytes_ptr)]
        )
        return context.get_dummy_value()

    return types.void(fn, src, out), codegen


@overload(sha256_digest)
def _sha256_digest_openssl(fn, src, out):
    def impl(fn, src, out):
        _call_sha256(fn, src, out)

    return impl


@functools.cache
def sha256_address() -> int:
    """The address of OpenSSL's one-shot ``SHA256`` in the library ``hashlib`` uses (looked up
    through the ``_hashlib`` module, whose dependencies dlsym searches), checked on test data
    against ``hashlib``; 0 when it cannot be found or does not agree (the hashes are then
    written by `fill_hashes`)."""
    import ctypes

    try:
        import _hashlib

        fn = ctypes.CDLL(_hashlib.__file__).SHA256
    except (ImportError, OSError, AttributeError):
        return 0
    fn.restype = ctypes.c_void_p
    fn.argtypes = (ctypes.c_char_p, ctypes.c_size_t, ctypes.c_char_p)
    for data in (b"", b"abc", bytes(range(256)) * 5):
        out = ctypes.create_string_buffer(32)
        fn(data, len(data), out)
        if out.raw != hashlib.sha256(data).digest():
            return 0
    return ctypes.cast(fn, ctypes.c_void_p).value or 0


def hash_function() -> int:
    """What `pack_records` takes as ``sha256``: `sha256_address`, or 0 (no hash in the kernel).
    Without the JIT the kernel's hash is ``hashlib``'s, whatever the address."""
    if numba.config.DISABLE_JIT:
        return 1
    return sha256_address()


# -- sizes --------------------------------------------------------------------------------------
@numba.njit(cache=True, nogil=True)
def joints_size(step, joints):
    """Bytes of a Joints message of ``joints`` joints (0: none, no message)."""
    if joints == 0:
        return 0
    size = 1 + varint_size(step) + 9
    for j in range(JOINT_NUMBERS.shape[0]):
        nbytes = 8 * JOINT_UNITS[j] * joints
        size += 1 + varint_size(nbytes) + nbytes
    return size


@numba.njit(cache=True, nogil=True)
def stats_size(step, points):
    """Bytes of a Stats message (`recorder.mcap_writer.encode_stats`) of a step with ``points``
    contact points: step, time, six doubles, the count, two doubles, the 64-character hash."""
    return 1 + varint_size(step) + 9 + 6 * 9 + 1 + varint_size(points) + 2 * 9 + 2 + HASH_HEX


@numba.njit(cache=True, nogil=True)
def record_sizes(first, n, offsets, slot, push_a, push_b, joints):
    """Each step's bytes of Message records (`/bodies`, `/contacts`, `/joints` with ``joints``
    > 0, `/stats`; `/world` not counted) for a batch whose first record is step ``first``
    (offsets: its row offsets; slot, push_a, push_b: its rows'): a (steps,) int64 array."""
    steps = offsets.shape[0] - 1
    out = np.empty(steps, dtype=np.int64)
    for s in range(steps):
        r0 = offsets[s]
        r1 = offsets[s + 1]
        step = first + s
        k, p = manifold_counts(slot[r0:r1], push_a[r0:r1], push_b[r0:r1])
        bodies, contacts = message_sizes(step, n, r1 - r0, k, p)
        size = 3 * RECORD_HEAD + bodies + contacts + stats_size(step, r1 - r0)
        if joints:
            size += RECORD_HEAD + joints_size(step, joints)
        out[s] = size
    return out


# -- writing --------------------------------------------------------------------------------------
@numba.njit(cache=True, nogil=True)
def _put_uint(buf, at, value, nbytes):
    """``value`` as ``nbytes`` little-endian bytes at ``buf[at:]``."""
    for i in range(nbytes):
        buf[at + i] = (value >> (8 * i)) & 0xFF


@numba.njit(cache=True, nogil=True)
def _record_head(buf, at, channel, step, log_time, data_len):
    """A Message record's head before ``data_len`` bytes of data; returns where they go."""
    buf[at] = OP_MESSAGE
    _put_uint(buf, at + 1, 22 + data_len, 8)
    _put_uint(buf, at + 9, channel, 2)
    _put_uint(buf, at + 11, step, 4)
    _put_uint(buf, at + 15, log_time, 8)
    _put_uint(buf, at + 23, log_time, 8)
    return at + RECORD_HEAD


@numba.njit(cache=True, nogil=True)
def _double(buf, at, number, value):
    """A double scalar field (tag and 8 little-endian bytes)."""
    buf[at] = (number << 3) | 1
    put_double(buf, at + 1, value)
    return at + 9


@numba.njit(cache=True, nogil=True)
def _packed_doubles(buf, at, number, src):
    """A packed repeated double field of ``src`` (C-contiguous float64), left out when empty."""
    if src.size == 0:
        return at
    at = _varint(buf, at, (number << 3) | 2)
    at = _varint(buf, at, 8 * src.size)
    copy_bytes(buf, at, src)
    return at + 8 * src.size


@numba.njit(cache=True, nogil=True)
def _joints_message(buf, at, step, time, j0, j1, j2, j3, j4, j5, j6, j7):
    """The Joints message (`recorder.mcap_writer.encode_joints`) of one step's joint arrays."""
    at = _head(buf, at, step, time)
    at = _packed_doubles(buf, at, 3, np.ascontiguousarray(j0))
    at = _packed_doubles(buf, at, 4, np.ascontiguousarray(j1))
    at = _packed_doubles(buf, at, 5, np.ascontiguousarray(j2))
    at = _packed_doubles(buf, at, 6, np.ascontiguousarray(j3))
    at = _packed_doubles(buf, at, 7, np.ascontiguousarray(j4))
    at = _packed_doubles(buf, at, 8, np.ascontiguousarray(j5))
    at = _packed_doubles(buf, at, 9, np.ascontiguousarray(j6))
    at = _packed_doubles(buf, at, 10, np.ascontiguousarray(j7))
    return at


@numba.njit(cache=True, nogil=True)
def _stats_message(buf, at, step, time, points, sums):
    """The Stats message (`recorder.mcap_writer.encode_stats`) but for its hash's 64 hex
    digits, which go at the returned position less HASH_HEX."""
    ke, pe, px, py, ang, max_depth, max_impulse = sums
    at = _head(buf, at, step, time)
    at = _double(buf, at, 3, ke)
    at = _double(buf, at, 4, pe)
    at = _double(buf, at, 5, ke + pe)
    at = _double(buf, at, 6, px)
    at = _double(buf, at, 7, py)
    at = _double(buf, at, 8, ang)
    at = _varint(buf, at, 9 << 3)
    at = _varint(buf, at, points)
    at = _double(buf, at, 10, max_depth)
    at = _double(buf, at, 11, max_impulse)
    buf[at] = (12 << 3) | 2
    buf[at + 1] = HASH_HEX
    return at + 2 + HASH_HEX


@numba.njit(cache=True, nogil=True)
def _hash_hex(fn, scratch, digest, buf, at, position, angle, velocity, angular_velocity, exists):
    """The state hash (`isaac.engine.records.state_hash`: sha256 of position, angle, velocity,
    angular velocity as float64 and existence as one byte each, in body order) as 64 lowercase
    hex digits at ``buf[at:]``."""
    n = angle.shape[0]
    copy_bytes(scratch, 0, np.ascontiguousarray(position))
    copy_bytes(scratch, 16 * n, np.ascontiguousarray(angle))
    copy_bytes(scratch, 24 * n, np.ascontiguousarray(velocity))
    copy_bytes(scratch, 40 * n, np.ascontiguousarray(angular_velocity))
    copy_bytes(scratch, 48 * n, np.ascontiguousarray(exists))
    sha256_digest(fn, scratch, digest)
    for i in range(32):
        buf[at + 2 * i] = _HEX[digest[i] >> 4]
        buf[at + 2 * i + 1] = _HEX[digest[i] & 15]


@numba.njit(cache=True, nogil=True)
def _joints_finite(j0, j1, j2, j3, j4, j5, j6, j7):
    return (
        _finite(j0) and _finite(j1) and _finite(j2) and _finite(j3) and _finite(j4)
        and _finite(j5) and _finite(j6) and _finite(j7)
    )  # fmt: skip


@numba.njit(cache=True, nogil=True)
def pack_records(
    buf, pos, lo, hi, first, dt, log_times, channels, world, world_at, state, offsets, rows,
    joints, model, gravity, sha256, hash_at,
):  # fmt: skip
    """Steps lo .. hi - 1 of a batch as Message records laid end to end from byte ``pos`` of
    ``buf`` (uint8): per step its `/world` record when the caller has one (``world[world_at[s]
    :world_at[s + 1]]``, empty for none), then `/bodies`, `/contacts`, `/joints` (when
    ``joints`` holds any) and `/stats`, with sequence = step and log_time = publish_time =
    ``log_times[s]`` (ns).

    Step s is state index ``first + s`` at time ``(first + s) * dt`` s, as
    `isaac.engine.records.StepBatch.record` computes it. channels: (bodies, contacts, joints,
    stats) channel ids; state: the batch's (position, angle, velocity, angular_velocity,
    exists); offsets: its row offsets; rows: its row arrays (CONTACT_FIELDS order); joints: its
    eight (steps, m, ...) joint arrays (JOINT_FIELDS order; m = 0 without joints); model:
    (mass, inertia, concrete), gravity: (gx, gy) m/s^2, for the /stats sums (`recorder.pack`'s
    bundles); sha256:
    `hash_function` (0: the hashes are left for `fill_hashes`). hash_at (out): where each
    step's 64 hash digits go.

    Returns (s, end, why): s = hi, or the first step holding a NaN or an infinity or contact
    rows that are not manifolds (nothing of it written: the records of the steps before it end
    at byte ``end``); why = -1, the field index (`recorder.pack.BODY_FIELDS +
    CONTACT_FIELDS`), NOT_MANIFOLDS or JOINT_NOT_FINITE.
    """
    position, angle, velocity, angular_velocity, exists = state
    (substep, a, b, feature, slot, point, normal, depth, pair_depth, push_a, push_b, impulse,
     tangent_impulse, restitution) = rows  # fmt: skip
    j0, j1, j2, j3, j4, j5, j6, j7 = joints
    n = angle.shape[1]
    m_joints = j0.shape[1]
    ch_bodies, ch_contacts, ch_joints, ch_stats = channels
    scratch = np.empty(49 * n, dtype=np.uint8)
    digest = np.empty(32, dtype=np.uint8)
    at = pos
    for s in range(lo, hi):
        r0 = offsets[s]
        r1 = offsets[s + 1]
        m = r1 - r0
        step = first + s
        time = step * dt
        log_time = log_times[s]
        if m_joints and not _joints_finite(j0[s], j1[s], j2[s], j3[s], j4[s], j5[s], j6[s], j7[s]):
            return s, at, JOINT_NOT_FINITE
        k, p = manifold_counts(slot[r0:r1], push_a[r0:r1], push_b[r0:r1])
        bodies_len, contacts_len = message_sizes(step, n, m, k, p)
        start = at
        w0 = world_at[s]
        w1 = world_at[s + 1]
        for i in range(w1 - w0):
            buf[at + i] = world[w0 + i]
        at += w1 - w0
        bodies_at = _record_head(buf, at, ch_bodies, step, log_time, bodies_len)
        _record_head(buf, bodies_at + bodies_len, ch_contacts, step, log_time, contacts_len)
        bad, _, _, _, sums = pack_messages(
            buf, bodies_at, bodies_len + RECORD_HEAD, step, time, n, m, step_state(state, s),
            row_range(rows, r0, r1), model, gravity,
        )  # fmt: skip
        if bad >= 0:
            return s, start, bad
        at = bodies_at + bodies_len + RECORD_HEAD + contacts_len
        if m_joints:
            size = joints_size(step, m_joints)
            at = _record_head(buf, at, ch_joints, step, log_time, size)
            at = _joints_message(buf, at, step, time, j0[s], j1[s], j2[s], j3[s], j4[s], j5[s],
                                 j6[s], j7[s])  # fmt: skip
        at = _record_head(buf, at, ch_stats, step, log_time, stats_size(step, m))
        at = _stats_message(buf, at, step, time, m, sums)
        hash_at[s] = at - HASH_HEX
        if sha256 != 0:
            _hash_hex(sha256, scratch, digest, buf, at - HASH_HEX, position[s], angle[s],
                      velocity[s], angular_velocity[s], exists[s])  # fmt: skip
    return hi, at, -1


def fill_hashes(buf, lo: int, hi: int, hash_at, state) -> None:
    """The state hashes `pack_records` left out (``sha256`` 0), with ``hashlib``: steps
    lo .. hi - 1, at ``hash_at``."""
    position, angle, velocity, angular_velocity, exists = state
    for s in range(lo, hi):
        h = hashlib.sha256()
        for arr in (position[s], angle[s], velocity[s], angular_velocity[s]):
            h.update(np.ascontiguousarray(arr, dtype="<f8"))
        h.update(np.ascontiguousarray(exists[s], dtype=np.uint8))
        at = int(hash_at[s])
        buf[at : at + HASH_HEX] = np.frombuffer(h.hexdigest().encode("ascii"), dtype=np.uint8)


# -- reading the records back (the sink's side) ---------------------------------------------------
@numba.njit(cache=True, nogil=True)
def scan_records(buf, start, end):
    """The Message records laid end to end in ``buf[start:end]``: (starts, ends, channel,
    sequence, log_time), one entry per record (int64 arrays, offsets into ``buf``). Raises
    ValueError when a record is not a Message or runs past ``end``."""
    count = 0
    at = start
    while at < end:
        if buf[at] != OP_MESSAGE or at + RECORD_HEAD > end:
            raise ValueError("scan_records: not a Message record")
        length = 0
        for i in range(8):
            length |= np.int64(buf[at + 1 + i]) << (8 * i)
        at += 9 + length
        count += 1
    if at != end:
        raise ValueError("scan_records: a record runs past the end")
    starts = np.empty(count, dtype=np.int64)
    ends = np.empty(count, dtype=np.int64)
    channel = np.empty(count, dtype=np.int64)
    sequence = np.empty(count, dtype=np.int64)
    log_time = np.empty(count, dtype=np.int64)
    at = start
    for r in range(count):
        length = 0
        for i in range(8):
            length |= np.int64(buf[at + 1 + i]) << (8 * i)
        starts[r] = at
        ends[r] = at + 9 + length
        channel[r] = np.int64(buf[at + 9]) | (np.int64(buf[at + 10]) << 8)
        seq = 0
        lt = 0
        for i in range(4):
            seq |= np.int64(buf[at + 11 + i]) << (8 * i)
        for i in range(8):
            lt |= np.int64(buf[at + 15 + i]) << (8 * i)
        sequence[r] = seq
        log_time[r] = lt
        at = ends[r]
    return starts, ends, channel, sequence, log_time


# -- the caller's side: a batch's records ---------------------------------------------------------
class Channels(NamedTuple):
    """The channel ids of a log (`recorder.mcap_writer.channel_ids`); joints 0 without."""

    world: int
    bodies: int
    contacts: int
    joints: int
    stats: int


class BatchPacker:
    """Packs the steps of `isaac.engine.records.StepBatch`es into Message records
    (`pack_records`), the producer's side of `recorder.mcap_file.McapFile.append`: in this
    process (`recorder.mcap_writer.McapLogWriter.write_batch`) or into a writer process's
    shared memory (`recorder.writer_process.WriterProcess.write_batch`).

    model: ``names``, ``mass``, ``inertia``, ``concrete`` and what `/world` needs;
    gravity: (gx, gy) m/s^2; dt: s; channels: `Channels`; joints:
    `recorder.mcap_writer.joint_table_rows` (``()`` without); encode_world: the `/world`
    encoder, ``(model, step, time, exists, joints) -> bytes``
    (`recorder.mcap_writer.encode_world`, passed in so that this module does not import the
    writer that imports it). hashes: False leaves each step's 64 hash digits unwritten, for
    `put_hashes` where the records are entered.
    """

    def __init__(
        self,
        model,
        gravity,
        dt: float,
        channels: Channels,
        joints=(),
        *,
        encode_world,
        hashes: bool = True,
    ) -> None:
        self.model = model
        self.encode_world = encode_world
        self.masses = model_bundle(model)  # (mass, inertia, concrete), for the /stats sums
        self.gravity = tuple(float(g) for g in gravity)
        self.clock = LogClock(dt)
        self.clock_dt = float(dt)
        self.channels = channels
        self.joints = joints
        # hashes False: the state hashes are left for where the records are entered
        # (`put_hashes`, a writer process)
        self.hashes = hashes
        self.sha256 = hash_function() if hashes else 0

    def plan(self, batch, last_exists) -> BatchPlan:
        """What packing ``batch`` takes: each step's bytes (its /world record included), the
        /world records of the steps whose existence differs from the step before (the first
        step's from ``last_exists``, None: no step yet) and the log times."""
        steps = batch.steps
        if batch.first + steps - 1 > MAX_SEQUENCE:
            from isaac.errors import LogError

            raise LogError(f"step {batch.first + steps - 1}: past the MCAP sequence range (u32)")
        rows = batch.row_arrays
        joints = batch._joints
        m_joints = 0 if joints is None else joints[0].shape[1]
        sizes = record_sizes(
            batch.first, batch.angle.shape[1], batch.offsets, rows[4], rows[9], rows[10], m_joints
        )
        log_times = self.clock.times(batch.first, steps)
        ex = batch.exists
        changed = np.empty(steps, dtype=bool)
        changed[0] = last_exists is None or not np.array_equal(ex[0], last_exists)
        changed[1:] = (ex[1:] != ex[:-1]).any(axis=1)
        world_at = np.zeros(steps + 1, dtype=np.int64)
        parts = []
        for s in np.flatnonzero(changed):  # step 0 and bodies entering or leaving: rare
            step = batch.first + int(s)
            data = self.encode_world(self.model, step, step * batch.dt, ex[s], self.joints)
            parts.append(message_record(self.channels.world, step, int(log_times[s]), data))
            world_at[s + 1] = len(parts[-1])
        np.cumsum(world_at, out=world_at)
        sizes = sizes + np.diff(world_at)
        world = np.frombuffer(b"".join(parts), dtype=np.uint8) if parts else _NO_BYTES
        return BatchPlan(sizes, log_times, world, world_at)

    def pack(self, buf, pos: int, lo: int, hi: int, batch, plan: BatchPlan):
        """Steps lo .. hi - 1 of ``batch`` as records from byte ``pos`` of ``buf`` (uint8, room
        for ``plan.sizes[lo:hi]``): (steps packed up to, end byte, why: `pack_records`)."""
        c = self.channels
        hash_at = np.empty(batch.steps, dtype=np.int64)
        state, offsets, rows, joints = batch_arguments(batch)
        done, end, why = pack_records(
            buf, pos, lo, hi, batch.first, batch.dt, plan.log_times,
            (c.bodies, c.contacts, c.joints, c.stats), plan.world, plan.world_at, state,
            offsets, rows, joints, self.masses, self.gravity,
            self.sha256, hash_at,
        )  # fmt: skip
        if self.sha256 == 0 and self.hashes:
            fill_hashes(buf, lo, done, hash_at, state)
        return int(done), int(end), int(why)


class BatchPlan(NamedTuple):
    sizes: np.ndarray  # (steps,) int64: each step's record bytes, its /world record included
    log_times: np.ndarray  # (steps,) int64 ns
    world: np.ndarray  # uint8: the /world records, end to end
    world_at: np.ndarray  # (steps + 1,) int64: step s's /world record is world[at[s]:at[s + 1]]


# read-only, as the /world records of a batch (a bytes buffer) are: one compile of the packers
_NO_BYTES = read_only(np.zeros(0, dtype=np.uint8))


@functools.lru_cache(maxsize=8)
def _no_joints(steps: int) -> tuple:
    """Joint arrays of no joints, in the shapes `pack_records` takes."""
    pair = read_only(np.zeros((steps, 0, 2)))  # read-only, as a batch's joint arrays
    one = read_only(np.zeros((steps, 0)))
    return (pair, pair, pair, one, one, one, pair, read_only(np.zeros((steps, 0, 6))))


class _OneStep:
    """A `StepRecord` in the shape of a one-step `StepBatch`, as `BatchPacker` reads it (views
    of the record's arrays, copied only where a dtype or layout differs; read-only, as a
    batch's arrays are, so that the packers compile once: `recorder.pack.read_only`)."""

    def __init__(self, record, dt: float) -> None:
        from isaac.engine.records import CONTACT_FIELDS, JOINT_FIELDS

        def c(a, dtype):
            return read_only(np.ascontiguousarray(a, dtype=dtype))

        self.first = int(record.step)
        self.dt = dt
        self.steps = 1
        self.position = c(record.position, dtype=np.float64)[None]
        self.angle = c(record.angle, dtype=np.float64)[None]
        self.velocity = c(record.velocity, dtype=np.float64)[None]
        self.angular_velocity = c(record.angular_velocity, dtype=np.float64)[None]
        self.exists = c(record.exists, dtype=bool)[None]
        rows = record.contacts
        self.offsets = c([0, len(rows)], np.int64)
        self.row_arrays = tuple(
            c(getattr(rows, f), dtype=np.int32 if k < 5 else np.float64)
            for k, f in enumerate(CONTACT_FIELDS)
        )
        joints = record.joints
        self._joints = (
            None
            if joints is None or len(joints) == 0
            else tuple(c(getattr(joints, f), dtype=np.float64)[None] for f in JOINT_FIELDS)
        )


def one_step_batch(record, dt: float) -> _OneStep:
    """``record`` as a batch of one step for `BatchPacker` (no copies for a record the engine
    made)."""
    return _OneStep(record, dt)


@numba.njit(cache=True, nogil=True)
def index_entries(channel, log_time, starts, i, j, base):
    """What records i .. j - 1 (`scan_records`' arrays) add to a chunk that holds ``base``
    bytes before them: the channels in the order they first appear, how many records each,
    the message-index entries (log_time, offset in the chunk) grouped by channel in that order
    (uint64, (j - i, 2)), and the least and greatest log time."""
    count = j - i
    order = np.empty(count, dtype=np.int64)
    counts = np.zeros(count, dtype=np.int64)
    rank = np.empty(count, dtype=np.int64)
    kinds = 0
    lt_min = log_time[i]
    lt_max = log_time[i]
    for r in range(i, j):
        c = channel[r]
        q = 0
        while q < kinds and order[q] != c:
            q += 1
        if q == kinds:
            order[q] = c
            kinds += 1
        counts[q] += 1
        rank[r - i] = q
        lt_min = min(lt_min, log_time[r])
        lt_max = max(lt_max, log_time[r])
    at = np.zeros(kinds, dtype=np.int64)
    for q in range(1, kinds):
        at[q] = at[q - 1] + counts[q - 1]
    entries = np.empty((count, 2), dtype=np.uint64)
    first = starts[i]
    for r in range(i, j):
        q = rank[r - i]
        entries[at[q], 0] = log_time[r]
        entries[at[q], 1] = starts[r] - first + base
        at[q] += 1
    return order[:kinds], counts[:kinds], entries, lt_min, lt_max


@numba.njit(cache=True, nogil=True)
def first_unfit(lo, hi, state, offsets, rows, joints):
    """The first of steps lo .. hi - 1 of a batch that `pack_records` would stop at (a NaN or an
    infinity in any float, contact rows that are not manifolds), or hi; arguments as
    `pack_records` takes them. What a writer thread's caller checks, so that the packing
    itself may run in the thread."""
    position, angle, velocity, angular_velocity, exists = state
    (substep, a, b, feature, slot, point, normal, depth, pair_depth, push_a, push_b, impulse,
     tangent_impulse, restitution) = rows  # fmt: skip
    j0, j1, j2, j3, j4, j5, j6, j7 = joints
    for s in range(lo, hi):
        r0 = offsets[s]
        r1 = offsets[s + 1]
        if j0.shape[1] and not _joints_finite(j0[s], j1[s], j2[s], j3[s], j4[s], j5[s], j6[s],
                                              j7[s]):  # fmt: skip
            return s
        if not (
            _finite(position[s]) and _finite(angle[s]) and _finite(velocity[s])
            and _finite(angular_velocity[s]) and _finite(point[r0:r1]) and _finite(normal[r0:r1])
            and _finite(depth[r0:r1]) and _finite(pair_depth[r0:r1]) and _finite(push_a[r0:r1])
            and _finite(push_b[r0:r1]) and _finite(impulse[r0:r1])
            and _finite(tangent_impulse[r0:r1]) and _finite(restitution[r0:r1])
        ):  # fmt: skip
            return s
        manifolds = _manifolds_ok(
            substep[r0:r1], a[r0:r1], b[r0:r1], feature[r0:r1], slot[r0:r1], normal[r0:r1],
            pair_depth[r0:r1], push_a[r0:r1], push_b[r0:r1],
        )  # fmt: skip
        if not manifolds:
            return s
    return hi


def batch_arguments(batch) -> tuple:
    """(state, offsets, rows, joints) of a batch as `pack_records` and `first_unfit` take them."""
    joints = batch._joints
    return (
        batch_state(batch),
        batch.offsets,
        batch.row_arrays,
        tuple(_no_joints(batch.steps) if joints is None else joints),
    )


# -- the state hash written where the records are entered (a writer process) ----------------------
@numba.njit(cache=True, nogil=True)
def _read_varint(buf, at):
    """(value, the byte after it) of the protobuf varint at ``buf[at]``."""
    value = 0
    shift = 0
    while True:
        byte = buf[at]
        at += 1
        value |= np.int64(byte & 0x7F) << shift
        shift += 7
        if byte < 0x80:
            return value, at


@numba.njit(cache=True, nogil=True)
def _body_fields(buf, at, stop, spans):
    """(start, bytes) of the payloads of Bodies fields 3 .. 7 (position, angle, velocity,
    angular velocity, exists) of the message in ``buf[at:stop]`` into ``spans`` (5, 2), (0, 0)
    for a field left out."""
    spans[:] = 0
    while at < stop:
        key, at = _read_varint(buf, at)
        wire = key & 7
        if wire == 0:
            while buf[at] >= 0x80:
                at += 1
            at += 1
        elif wire == 1:
            at += 8
        else:
            length, at = _read_varint(buf, at)
            number = key >> 3
            if 3 <= number <= 7:
                spans[number - 3, 0] = at
                spans[number - 3, 1] = length
            at += length


@numba.njit(cache=True, nogil=True)
def hash_inputs(buf, start, end, bodies_channel, stats_channel):
    """For each step of the records in ``buf[start:end]`` (each step's `/bodies` record before
    its `/stats` record): the bytes its state hash covers, end to end (uint8), where each step's
    part ends in them, and where its 64 hash digits go (the end of its `/stats` record)."""
    starts, ends, channel, sequence, log_time = scan_records(buf, start, end)
    steps = 0
    total = 0
    spans = np.zeros((5, 2), dtype=np.int64)
    for r in range(starts.shape[0]):
        if channel[r] == stats_channel:
            steps += 1
        elif channel[r] == bodies_channel:
            _body_fields(buf, starts[r] + RECORD_HEAD, ends[r], spans)
            total += spans[:, 1].sum()
    data = np.empty(total, dtype=np.uint8)
    bounds = np.zeros(steps + 1, dtype=np.int64)
    hash_at = np.empty(steps, dtype=np.int64)
    at = 0
    s = 0
    for r in range(starts.shape[0]):
        if channel[r] == bodies_channel:
            _body_fields(buf, starts[r] + RECORD_HEAD, ends[r], spans)
            for f in range(5):
                p0 = spans[f, 0]
                for i in range(spans[f, 1]):
                    data[at + i] = buf[p0 + i]
                at += spans[f, 1]
        elif channel[r] == stats_channel:
            bounds[s + 1] = at
            hash_at[s] = ends[r] - HASH_HEX
            s += 1
    return data, bounds, hash_at


@numba.njit(cache=True, nogil=True)
def _put_hashes(fn, buf, data, bounds, hash_at):
    digest = np.empty(32, dtype=np.uint8)
    for s in range(hash_at.shape[0]):
        sha256_digest(fn, data[bounds[s] : bounds[s + 1]], digest)
        at = hash_at[s]
        for i in range(32):
            buf[at + 2 * i] = _HEX[digest[i] >> 4]
            buf[at + 2 * i + 1] = _HEX[digest[i] & 15]


def put_hashes(buf, start: int, end: int, channels: Channels) -> None:
    """Write the state hash of every step of the records in ``buf[start:end]``, packed without
    them (`BatchPacker` with ``hashes=False``), from the body fields in their `/bodies`
    records: what a writer process does, so that its parent does not hash."""
    data, bounds, hash_at = hash_inputs(buf, start, end, channels.bodies, channels.stats)
    fn = hash_function()
    if fn:
        _put_hashes(fn, buf, data, bounds, hash_at)
        return
    for s in range(len(hash_at)):
        digest = hashlib.sha256(data[bounds[s] : bounds[s + 1]]).hexdigest().encode("ascii")
        at = int(hash_at[s])
        buf[at : at + HASH_HEX] = np.frombuffer(digest, dtype=np.uint8)
