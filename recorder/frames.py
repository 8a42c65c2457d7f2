"""Frames: one step as the writer processes receive it, packed by the simulating process.

MCAP frames (`pack`, `pack_into`, read back by `Frame`): a head with step, time, body and contact
counts and the /stats values, then the encoded `/bodies` and `/contacts` messages, which the mcap
library takes as they are; in a scene with joints, then a trailer (`joints_trailer`): the
`/joints` message's byte count (uint64) and the message, encoded by
`recorder.mcap_writer.encode_joints` (Python, not the compiled packer), padded to 8 bytes. A
frame without joints has no trailer, so its bytes are what they were before joints. Only a log
with the `/foxglove/scene` channel (which the child draws from records) and a big-endian
machine still send MCAP frames: every other MCAP step leaves the simulating process as whole
Message records (`recorder.mcap_pack`).

Rerun frames (`recorder.pack.pack_rerun`, read back by
`read_rerun_frame`): only what the recording draws, as raw native-endian arrays. The transport
that carries them (shared-memory ring, command pipe) is `recorder.writer_process`.
"""

from __future__ import annotations

import hashlib
import struct
from typing import NamedTuple

import numpy as np

from isaac.engine.records import CONTACT_FIELDS, StepRecord
from recorder.shapes import circle_radii

STAT_KEYS = (
    "kinetic_energy",
    "potential_energy",
    "total_energy",
    "linear_momentum_x",
    "linear_momentum_y",
    "angular_momentum",
    "contact_count",
    "max_depth",
    "max_impulse",
)

# step, time, n, m, stats (STAT_KEYS), bytes of the Bodies and of the Contacts message; the
# two messages follow, each from an 8-byte boundary
FRAME_HEAD = struct.Struct("<qdQQ" + "d" * len(STAT_KEYS) + "QQ")
# byte offset of the /stats values in an MCAP frame's head and in a Rerun frame (after step,
# time, n and m in both), where `write`'s caller-given stats replace the computed ones
STATS_AT = 32


def _pad8(n: int) -> int:
    return (n + 7) & ~7


def frame_sizes(record: StepRecord) -> tuple[int, int, int]:
    """Bytes of `record`'s Bodies and Contacts messages, and of its frame (a multiple of 8)."""
    from recorder.pack import manifold_counts, message_sizes

    c = record.contacts
    k, p = (
        manifold_counts(np.asarray(c.slot, dtype=np.int32), c.push_a, c.push_b)
        if len(c)
        else (0, 0)
    )
    bodies, contacts = message_sizes(int(record.step), int(record.angle.shape[0]), len(c), k, p)
    return bodies, contacts, FRAME_HEAD.size + _pad8(bodies) + _pad8(contacts)


# contact rows a moving body keeps a step, and points per manifold, for `expected_log_bytes`
# (measured: 1.6 points and 1.25 points a manifold on the default scene, 2.1 and 1.36 in the
# first 400 steps of the 503-body pile)
ROWS_PER_MOVING_BODY = 2.0
POINTS_PER_MANIFOLD = 1.3
PUSHED_SHARE = 0.75  # of the manifolds: 0.006 on the default scene, 0.76 on the pile
STEP_OVERHEAD_BYTES = 400  # /stats message, the MCAP message records and the chunk index share


def expected_log_bytes(n_bodies: int, n_moving: int, steps: int) -> tuple[int, int]:
    """(bytes a step, bytes) an MCAP log of `steps` steps (after step 0) is expected to take,
    uncompressed: the exact /bodies size and /contacts at ROWS_PER_MOVING_BODY points per
    moving body, POINTS_PER_MANIFOLD to a manifold, PUSHED_SHARE of them pushed (an upper
    bound rather than a guess: a pile pushes most manifolds, a scene at rest few)."""
    from recorder.pack import message_sizes

    rows = int(round(ROWS_PER_MOVING_BODY * n_moving))
    k = int(round(rows / POINTS_PER_MANIFOLD))
    bodies, contacts = message_sizes(steps, n_bodies, rows, k, int(round(PUSHED_SHARE * k)))
    per_step = bodies + contacts + STEP_OVERHEAD_BYTES
    return per_step, per_step * (steps + 1)


def frame_size(record: StepRecord) -> int:
    """Bytes of `record`'s frame (a multiple of 8)."""
    return frame_sizes(record)[2]


def rerun_frame_size(record: StepRecord) -> int:
    """Bytes of `record`'s Rerun frame (`recorder.pack.rerun_offsets`; a multiple of 8)."""
    from recorder.pack import rerun_offsets

    return 8 * rerun_offsets(int(record.angle.shape[0]), len(record.contacts))[-1]


class RerunFrame(NamedTuple):
    """One step as the Rerun writer process receives it (`recorder.pack.pack_rerun`): views of
    the frame's arrays, valid while its ring slot is, in `RerunLogWriter.append`'s order."""

    step: int
    time: float  # s
    position: np.ndarray  # (n, 2) m, world
    angle: np.ndarray  # (n,) rad, CCW
    exists: np.ndarray  # (n,) bool
    point: np.ndarray  # (m, 2) m, world
    normal: np.ndarray  # (m, 2) unit, from a towards b
    impulse: np.ndarray  # (m,) N s
    push_a: np.ndarray  # (m, 2) m
    push_b: np.ndarray  # (m, 2) m
    stats: np.ndarray  # (9,) the /stats values in STAT_KEYS order


def read_rerun_frame(buf: np.ndarray, at: int = 0) -> RerunFrame:
    """The Rerun frame at byte ``at`` (a multiple of 8) of ``buf`` (uint8), as views."""
    from recorder.pack import RERUN_HEAD, rerun_offsets

    head = buf[at : at + 8 * RERUN_HEAD].view(np.int64)
    step, n, m = int(head[0]), int(head[2]), int(head[3])
    o = rerun_offsets(n, m)
    words = buf[at : at + 8 * o[-1]].view(np.float64)
    pairs = lambda k, rows: words[o[k] : o[k] + 2 * rows].reshape(rows, 2)  # noqa: E731
    return RerunFrame(
        step,
        float(words[1]),
        pairs(0, n),
        words[o[1] : o[1] + n],
        buf[at + 8 * o[2] : at + 8 * o[2] + n].view(np.bool_),
        pairs(3, m),
        pairs(4, m),
        words[o[5] : o[5] + m],
        pairs(6, m),
        pairs(7, m),
        words[4:RERUN_HEAD],
    )


_TRAILER_LEN = struct.Struct("<Q")


def joints_trailer(step: int, time: float, joints) -> bytes:
    """A frame's trailer holding the `/joints` message of ``joints`` (`JointRows`), or b""
    for None (a scene without joints)."""
    if joints is None:
        return b""
    from recorder.mcap_writer import encode_joints

    message = encode_joints(step, time, joints)
    return b"".join(
        (_TRAILER_LEN.pack(len(message)), message, bytes(_pad8(len(message)) - len(message)))
    )


def joints_finite(joints) -> bool:
    """Whether every float of ``joints`` (`JointRows`) is finite (the compiled packer checks
    the bodies and contacts, not the joints)."""
    from isaac.engine.records import JOINT_FIELDS

    return all(np.isfinite(getattr(joints, f)).all() for f in JOINT_FIELDS)


def put_trailer(buf: np.ndarray, pos: int, trailer: bytes) -> None:
    """Copy a trailer to byte ``pos`` of ``buf`` (uint8): right after the frame's messages."""
    if trailer:
        buf[pos : pos + len(trailer)] = np.frombuffer(trailer, dtype=np.uint8)


def pack(record: StepRecord, stats: dict) -> bytes:
    """`record` and its `stats` as one frame, encoded by the reference encoders
    (`recorder.mcap_writer`); the compiled `recorder.pack` writes the same bytes."""
    from recorder.mcap_writer import encode_bodies, encode_contacts

    bodies, contacts = encode_bodies(record), encode_contacts(record)
    head = FRAME_HEAD.pack(
        int(record.step),
        float(record.time),
        int(record.angle.shape[0]),
        len(record.contacts),
        *(float(stats[k]) for k in STAT_KEYS),
        len(bodies),
        len(contacts),
    )
    pad = bytes(_pad8(len(bodies)) - len(bodies))
    trailer = joints_trailer(int(record.step), float(record.time), record.joints)
    return b"".join(
        (head, bodies, pad, contacts, bytes(_pad8(len(contacts)) - len(contacts)), trailer)
    )


def pack_into(
    buf: np.ndarray,
    pos: int,
    record: StepRecord,
    masses: tuple,
    gravity,
    stats: dict | None = None,
    sizes: tuple[int, int] | None = None,
) -> bool:
    """Encode `record`'s frame (`pack`'s bytes) at byte ``pos`` (a multiple of 8) of ``buf``
    (uint8, ``frame_size(record)`` bytes from ``pos`` at least) with the compiled
    `recorder.pack.pack_frame`; little-endian machines only.

    masses: the model's (mass, inertia, concrete) bundle (`recorder.pack.model_bundle`), for
    the /stats sums; gravity: (gx, gy) m/s^2. stats: the /stats values to write instead of the
    computed ones. sizes: the messages' sizes when the caller has them (`frame_sizes`). Returns
    False, the frame
    unusable, when a float of the record is NaN or infinite; ValueError when its contact rows
    are not manifolds (`recorder.mcap_writer.manifold_starts`).
    """
    from recorder.pack import NOT_MANIFOLDS, pack_frame, record_bundles

    bodies_size, contacts_size = sizes if sizes is not None else frame_sizes(record)[:2]
    state, rows = record_bundles(record)
    bad, bodies_len, contacts_len = pack_frame(
        buf,
        pos,
        int(record.step),
        float(record.time),
        int(record.angle.shape[0]),
        len(record.contacts),
        _pad8(bodies_size),
        state,
        rows,
        masses,
        (float(gravity[0]), float(gravity[1])),
    )
    if bad >= 0:
        if bad == NOT_MANIFOLDS:
            from recorder.mcap_writer import manifold_starts

            manifold_starts(record.contacts)  # raises ValueError naming the row
        return False
    assert (bodies_len, contacts_len) == (bodies_size, contacts_size)
    if stats is not None:
        put_stats(buf, pos, stats)
    return True


def put_stats(buf: np.ndarray, pos: int, stats: dict) -> None:
    """The caller's /stats values over the computed ones, in the head of the frame at ``pos``
    (MCAP or Rerun frame: both keep them at STATS_AT)."""
    words = buf[pos + STATS_AT : pos + STATS_AT + 8 * len(STAT_KEYS)].view(np.float64)
    words[:] = [float(stats[k]) for k in STAT_KEYS]


class Frame:
    """One step as the writer process receives it: the encoded `/bodies` and `/contacts`
    messages (memoryviews of the frame) and the `/stats` values, without a state hash."""

    def __init__(self, data) -> None:
        head = FRAME_HEAD.unpack_from(data, 0)
        self.step, self.time, self.n, self.m = head[:4]
        k = 4 + len(STAT_KEYS)
        self.stats = dict(zip(STAT_KEYS, head[4:k]))
        self.stats["contact_count"] = int(self.stats["contact_count"])
        bodies_len, contacts_len = head[k:]
        view = memoryview(data)
        self.bodies = view[FRAME_HEAD.size : FRAME_HEAD.size + bodies_len]
        at = FRAME_HEAD.size + _pad8(bodies_len)
        self.contacts = view[at : at + contacts_len]
        at += _pad8(contacts_len)
        # the /joints message (bytes), None in a frame without the trailer
        self.joints = None
        if len(view) >= at + _TRAILER_LEN.size:
            (joints_len,) = _TRAILER_LEN.unpack_from(view, at)
            at += _TRAILER_LEN.size
            self.joints = view[at : at + joints_len]
        self._fields: list[memoryview] | None = None

    def body_fields(self) -> list[memoryview]:
        """The raw little-endian values of Bodies fields 3-7 (position, angle, velocity,
        angular velocity, exists), empty when left out."""
        if self._fields is None:
            self._fields = _packed_fields(self.bodies, 5)
        return self._fields

    def state_hash(self) -> str:
        """`isaac.engine.records.state_hash` of the step, from the message's bytes (the same)."""
        h = hashlib.sha256()
        for part in self.body_fields():
            h.update(part)
        return h.hexdigest()

    def exists(self) -> np.ndarray:
        flags = self.body_fields()[4]
        return np.frombuffer(flags, dtype=np.bool_) if len(flags) else np.ones(self.n, dtype=bool)

    def record(self) -> StepRecord:
        """The step as a StepRecord: read-only views of one copy of the frame's messages
        (`recorder.reader.record_from_messages`)."""
        from recorder import schema as S
        from recorder.reader import record_from_messages

        # one copy each: the ring slot is reused
        bodies = S.decode("Bodies", bytes(self.bodies))
        joints = None if self.joints is None else S.decode("Joints", bytes(self.joints))
        return record_from_messages(
            bodies, S.decode("Contacts", bytes(self.contacts)), joints=joints
        )


def _field_spans(buf, count: int) -> list[tuple[int, int]]:
    """(start, bytes) of the payloads of fields 3 .. count + 2 of an encoded Bodies or
    Contacts message (their packed values), (0, 0) when left out."""
    from recorder.schema import _read_varint

    out = {}
    pos = 0
    while pos < len(buf):
        key, pos = _read_varint(buf, pos)
        number, wire = key >> 3, key & 7
        if wire == 0:
            _, pos = _read_varint(buf, pos)
        elif wire == 1:
            pos += 8
        else:
            length, pos = _read_varint(buf, pos)
            out[number] = (pos, length)
            pos += length
    return [out.get(k, (0, 0)) for k in range(3, count + 3)]


def _packed_fields(buf, count: int) -> list[memoryview]:
    """The payloads of fields 3 .. count + 2 of an encoded message, empty when left out."""
    return [buf[start : start + size] for start, size in _field_spans(buf, count)]


def model_table(model) -> dict:
    """What a writer needs of the model, as plain lists and arrays (pickled to the child)."""
    return {
        "names": [str(x) for x in model.names],
        **{
            key: np.asarray(getattr(model, key))
            for key in (
                "vertices_local",
                "vertex_count",
                "mass",
                "inertia",
                "restitution",
                "friction",
                "concrete",
            )
        },
        "circle_radius": circle_radii(model),
    }


def batch_frame_sizes(batch) -> np.ndarray:
    """(steps, 3) int64: each step's Bodies bytes, Contacts bytes and frame bytes (a multiple
    of 8) for an `isaac.engine.records.StepBatch`, as `frame_sizes` gives them one at a time."""
    from recorder.pack import HEAD_BYTES, frame_sizes_of

    rows = dict(zip(CONTACT_FIELDS, batch.row_arrays))
    return frame_sizes_of(
        batch.first, batch.angle.shape[1], batch.offsets, rows["slot"], rows["push_a"],
        rows["push_b"], HEAD_BYTES,
    )  # fmt: skip


def pack_batch(buf, pos: int, lo: int, hi: int, batch, sizes, model, gravity) -> int:
    """Steps lo .. hi - 1 of a `StepBatch` as consecutive MCAP frames from byte ``pos`` of
    ``buf`` (uint8), by one compiled call (`recorder.pack.pack_frames`, with the /stats sums).
    sizes: `batch_frame_sizes`; model: ``mass``, ``inertia``, ``concrete`` arrays; gravity:
    (gx, gy) m/s^2. Returns the first step holding a NaN or an infinity, or hi."""
    from recorder.pack import batch_state, model_bundle, pack_frames

    return pack_frames(
        buf, pos, lo, hi, batch.first, batch.dt, sizes, batch.offsets, batch_state(batch),
        tuple(batch.row_arrays), model_bundle(model), (float(gravity[0]), float(gravity[1])),
    )  # fmt: skip


def batch_frame_sizes_with_joints(batch) -> tuple[np.ndarray, list[bytes]]:
    """`batch_frame_sizes` with each frame's joints trailer counted in its frame bytes, and
    the trailers (`joints_trailer`; all b"" for a scene without joints). The compiled packer
    lays the frames out by these sizes, leaving each trailer's room free; the caller copies
    the trailers in (`put_trailer`, at the frame's end less the trailer's length)."""
    sizes = batch_frame_sizes(batch)
    if batch.joints_of(0) is None:
        return sizes, [b""] * batch.steps
    trailers = [
        joints_trailer(batch.first + s, (batch.first + s) * batch.dt, batch.joints_of(s))
        for s in range(batch.steps)
    ]
    sizes = sizes.copy()
    sizes[:, 2] += np.array([len(t) for t in trailers], dtype=sizes.dtype)
    return sizes, trailers
