"""Write an ISAAC run to MCAP: the source of truth (exact float64, self-contained).

Layout (the public contract is docs/log-format.md):
- metadata ``isaac`` and attachment ``scene.yaml`` right after the header, before any chunk, so a
  crashed file still carries everything needed to re-simulate;
- channels ``/world``, ``/bodies``, ``/contacts``, ``/stats`` (protobuf, schema =
  FileDescriptorSet), and ``/joints`` in a scene with joints; one message per step on each
  (``/world`` only at step 0 and when a body enters or leaves), with
  ``log_time = publish_time = round(step * dt * 1e9)`` ns and ``sequence = step``;
- chunks are closed (and the file flushed to the OS) after step 0 and every ``flush_every`` steps
  (<= 100), at a step boundary; they also close whenever they pass ``chunk_size`` (256 KiB:
  measured fastest with the mcap library, whose chunk buffer slows down when it grows larger),
  so a crash loses at most the open chunk, and a reader counts a step only when it is complete;
- on close, metadata ``isaac.end`` says whether the run completed and where it stopped, then the
  summary and index. The file is written as ``PATH.partial`` and renamed to ``PATH`` on close.

Nothing here uses wall-clock time: two runs of one scene give byte-identical files.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import queue
import sys
import threading
from dataclasses import asdict
from typing import NamedTuple

import numpy as np

from isaac.engine.records import StepRecord, state_hash
from isaac.errors import LogError
from recorder import schema as S
from recorder.log_time import LogClock
from recorder.mcap_file import COMPRESSIONS, McapFile
from recorder.shapes import circle_radii

PROFILE = "isaac"
LIBRARY = "isaac-recorder"
FORMAT_NAME = "isaac-log"
FORMAT_VERSION = "2"  # 2: /contacts per manifold (1: every field per point row)
READ_FORMAT_VERSIONS = ("1", "2")  # what the readers take
SCENE_ATTACHMENT = "scene.yaml"
META_START = "isaac"
META_END = "isaac.end"


def channel_ids(joints: bool, foxglove: bool = False) -> dict[str, int]:
    """The channel id of each topic of a log, as `McapLogWriter` registers them (ids count up
    from 1 in `recorder.schema.TOPICS` order, ``/joints`` only with joints, then
    ``/foxglove/scene``): what a writer process's parent packs records for."""
    topics = [t for t in S.TOPICS if joints or t not in S.JOINT_TOPICS]
    if foxglove:
        topics.append("/foxglove/scene")
    return {topic: k + 1 for k, topic in enumerate(topics)}


def record_channels(joints: bool):
    """`recorder.mcap_pack.Channels` of a log without the Foxglove channel."""
    from recorder.mcap_pack import Channels

    ids = channel_ids(joints)
    return Channels(
        ids["/world"], ids["/bodies"], ids["/contacts"], ids.get("/joints", 0), ids["/stats"]
    )


@functools.cache
def _versions() -> dict[str, str]:
    import platform
    import sys

    import numba
    import numpy

    import isaac

    engine = getattr(isaac, "__version__", None)
    if engine is None:
        try:
            from importlib.metadata import version

            engine = version("isaac-physics")
        except Exception:  # noqa: BLE001 - not installed as a distribution
            engine = "unknown"
    from isaac.engine import PHYSICS_VERSION

    return {
        "engine_version": str(engine),
        "physics_version": str(PHYSICS_VERSION),
        "python_version": platform.python_version(),
        "python_implementation": platform.python_implementation(),
        "numpy_version": numpy.__version__,
        "numba_version": numba.__version__,
        "platform": platform_name(),
        "machine": platform.machine(),
        "cpu": _cpu_name(),
        "byteorder": sys.byteorder,
    }


def platform_name() -> str:
    """`platform.platform()`'s name of this system (``Linux-6.1.0-x86_64-with-glibc2.36``),
    on Linux without the ``uname -p`` child process it starts to ask for the processor (a
    fork and exec in the middle of opening a log), whose answer Linux's name leaves out
    anyway: "unknown" or the machine again. Elsewhere, `platform.platform()` itself."""
    import platform

    if not sys.platform.startswith("linux"):
        return platform.platform()
    u = os.uname()
    libc, version = platform.libc_ver()
    return "-".join(p for p in (u.sysname, u.release, u.machine, "with", libc + version) if p)


def _cpu_name() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    import platform

    return platform.processor() or "unknown"


def build_metadata(scene, scene_text: str, n_bodies: int) -> dict[str, str]:
    """The ``isaac`` metadata record: versions, machine, scene hash and every world setting.

    Values are strings (MCAP requires it). Settings are JSON (floats in repr form, which
    round-trips float64 exactly): ``settings`` holds them all, ``world.<key>`` each one.
    """
    world = asdict(scene.world)
    meta = {
        "format": FORMAT_NAME,
        "format_version": FORMAT_VERSION,
        **_versions(),  # (cached: the same for every log of a process, such as a sweep's)
        "scene_name": str(scene.name),
        "scene_sha256": hashlib.sha256(scene_text.encode("utf-8")).hexdigest(),
        "scene_attachment": SCENE_ATTACHMENT,
        "bodies": str(n_bodies),
        "dt": repr(float(scene.world.dt)),
        "gravity": json.dumps([float(g) for g in scene.world.gravity]),
        "settings": json.dumps(world, sort_keys=True),
        "log_time": "round(step * dt * 1e9) ns from the exact float64 value of dt",
    }
    for key, value in sorted(world.items()):
        meta[f"world.{key}"] = json.dumps(value)
    return meta


def joint_table_rows(joints) -> tuple[dict, ...]:
    """The joint table as plain dicts (what ``World.joints`` stores, picklable for a writer
    process), from `isaac.scene.JointSpec`s or such dicts; ``()`` for none. A limit that is not
    given is -inf (lower) or +inf (upper); a spring's stiffness and a motor's speed not given
    are 0 with ``spring`` / ``motor`` false."""
    if not joints:
        return ()
    rows = []
    for j in joints:
        if isinstance(j, dict):  # already a row
            rows.append(dict(j))
            continue
        get = lambda k, j=j: getattr(j, k)  # noqa: E731

        def opt(key, none, j=j):
            v = getattr(j, key)
            return none if v is None else float(v)

        rows.append(
            {
                "name": str(get("name")),
                "type": str(get("kind")),
                "a": int(get("a")),
                "b": int(get("b")),
                "local_a": tuple(float(x) for x in get("local_a")),
                "local_b": tuple(float(x) for x in get("local_b")),
                "axis": tuple(float(x) for x in get("axis")),
                "reference_angle": float(get("reference_angle")),
                "length": float(get("length")),
                "min_length": opt("min_length", -np.inf),
                "max_length": opt("max_length", np.inf),
                "stiffness": opt("stiffness", 0.0),
                "damping_ratio": float(get("damping_ratio")),
                "lower": opt("lower", -np.inf),
                "upper": opt("upper", np.inf),
                "motor_speed": opt("motor_speed", 0.0),
                "max_motor": float(get("max_motor")),
                "spring": get("stiffness") is not None,
                "motor": get("motor_speed") is not None,
                "collide_connected": bool(get("collide_connected")),
            }
        )
    return tuple(rows)


def encode_joint(index: int, row: dict) -> bytes:
    """``isaac.log.Joint``: one row of `joint_table_rows`."""
    d = S.enc_double
    return b"".join(
        (
            S.enc_uint(1, index),
            S.enc_string(2, row["name"]),
            S.enc_string(3, row["type"]),
            S.enc_uint(4, row["a"]),
            S.enc_uint(5, row["b"]),
            S.enc_doubles(6, np.array(row["local_a"], dtype=np.float64)),
            S.enc_doubles(7, np.array(row["local_b"], dtype=np.float64)),
            S.enc_doubles(8, np.array(row["axis"], dtype=np.float64)),
            d(9, row["reference_angle"]),
            d(10, row["length"]),
            d(11, row["min_length"]),
            d(12, row["max_length"]),
            d(13, row["stiffness"]),
            d(14, row["damping_ratio"]),
            d(15, row["lower"]),
            d(16, row["upper"]),
            d(17, row["motor_speed"]),
            d(18, row["max_motor"]),
            S.enc_uint(19, bool(row["spring"])),
            S.enc_uint(20, bool(row["motor"])),
            S.enc_uint(21, bool(row["collide_connected"])),
        )
    )


# (number, JointRows field) of ``isaac.log.Joints``, each a packed repeated double
JOINT_WIRE = (
    (3, "anchor_a"),
    (4, "anchor_b"),
    (5, "linear_impulse"),
    (6, "angular_impulse"),
    (7, "motor_impulse"),
    (8, "limit_impulse"),
    (9, "error"),
    (10, "impulses"),
)


@functools.lru_cache(maxsize=256)
def _packed_prefix(number: int, nbytes: int) -> bytes:
    return S.enc_bytes(number, b"")[:-1] + S.varint(nbytes)


def encode_joints(step: int, time: float, joints) -> bytes:
    """``isaac.log.Joints``: the step's `isaac.engine.records.JointRows`, raw float64 (what
    `recorder.schema.packed` writes, its field prefixes cached: a step's joints have the same
    sizes every step)."""
    parts = [S.enc_uint(1, step), S.enc_double(2, time)]
    for number, name in JOINT_WIRE:
        a = getattr(joints, name)
        if a.size == 0:
            continue
        if a.dtype != _F8 or not a.flags.c_contiguous:
            a = np.ascontiguousarray(a, dtype=_F8)
        parts.append(_packed_prefix(number, a.nbytes))
        parts.append(a)
    return b"".join(parts)


_F8 = np.dtype("<f8")


def encode_world(model, step: int, time: float, exists: np.ndarray, joints=()) -> bytes:
    """``isaac.log.World``: every body's constant data and whether it exists at ``step``, and
    the joint table (``joints``: `joint_table_rows`; field 4, left out when there is none)."""
    parts = [S.enc_uint(1, step), S.enc_double(2, time)]
    counts = np.asarray(model.vertex_count)
    radii = circle_radii(model)
    for k, name in enumerate(model.names):
        c = int(counts[k])
        # a circle's radius only for a circle: a polygon's body bytes are what they were
        circle = (S.enc_double(10, float(radii[k])),) if radii[k] > 0.0 else ()
        body = b"".join(
            (
                S.enc_uint(1, k),
                S.enc_string(2, str(name)),
                S.enc_doubles(3, np.asarray(model.vertices_local[k, :c], dtype=np.float64)),
                S.enc_double(4, float(model.mass[k])),
                S.enc_double(5, float(model.inertia[k])),
                S.enc_double(6, float(model.restitution[k])),
                S.enc_uint(7, bool(model.concrete[k])),
                S.enc_uint(8, bool(exists[k])),
                S.enc_double(9, float(model.friction[k])),
                *circle,
            )
        )
        parts.append(S.enc_bytes(3, body))
    for i, row in enumerate(joints):
        parts.append(S.enc_bytes(4, encode_joint(i, row)))
    return b"".join(parts)


def encode_bodies(record: StepRecord) -> bytes:
    """``isaac.log.Bodies``: the state after the step, raw float64 from the record's arrays."""
    parts = [S.enc_uint(1, record.step), S.enc_double(2, record.time)]
    S.packed(parts, 3, record.position, "<f8")
    S.packed(parts, 4, record.angle, "<f8")
    S.packed(parts, 5, record.velocity, "<f8")
    S.packed(parts, 6, record.angular_velocity, "<f8")
    S.packed(parts, 7, record.exists, np.uint8)
    return b"".join(parts)


_CONTACT_WIRE_V1 = (
    (3, "substep", "<u4"),
    (4, "a", "<u4"),
    (5, "b", "<u4"),
    (6, "feature", "<u4"),
    (7, "slot", "<u4"),
    (8, "point", "<f8"),
    (9, "normal", "<f8"),
    (10, "depth", "<f8"),
    (11, "push_a", "<f8"),
    (12, "push_b", "<f8"),
    (13, "impulse", "<f8"),
    (14, "tangent_impulse", "<f8"),
    (15, "restitution", "<f8"),
)
# format 2: (number, Contacts field, wire type), the manifold fields (taken from each
# manifold's first row; the pushes of the manifolds in ``pushed`` only, those whose push is not
# +0.0 in every component) then the point fields, in recorder.schema's order
CONTACT_MANIFOLD_WIRE = (
    (16, "substep", "<u4"),
    (17, "a", "<u4"),
    (18, "b", "<u4"),
    (19, "feature", "<u4"),
    (20, "points", "<u4"),
    (21, "normal", "<f8"),
    (22, "pair_depth", "<f8"),
    (25, "pushed", "<u4"),
    (23, "push_a", "<f8"),
    (24, "push_b", "<f8"),
)
CONTACT_POINT_WIRE = (
    (8, "point", "<f8"),
    (10, "depth", "<f8"),
    (13, "impulse", "<f8"),
    (14, "tangent_impulse", "<f8"),
    (15, "restitution", "<f8"),
)
_PER_MANIFOLD = ("substep", "a", "b", "feature", "normal", "pair_depth")


def manifold_starts(contacts) -> np.ndarray:
    """The rows that begin a manifold (slot 0), as indices; ValueError unless the rows are
    manifolds as the engine makes them: each begins at slot 0 and its later rows count up
    (slot 1, ...), share its sub-step, bodies, feature, normal and pair depth bit for bit and
    carry a +0.0 push. What format 2 stores once per manifold is then exactly what each row
    held."""
    c = contacts
    m = len(c)
    slot = np.asarray(c.slot)
    starts = np.flatnonzero(slot == 0)
    if m == 0:
        return starts
    first = np.zeros(m, dtype=np.int64)  # each row's manifold start
    if starts.size == 0 or starts[0] != 0:
        raise ValueError("contacts: row 0 does not begin a manifold (slot 0)")
    first[starts] = starts
    np.maximum.accumulate(first, out=first)
    bad = slot != np.arange(m) - first
    for name in _PER_MANIFOLD:
        v = np.asarray(getattr(c, name))
        if v.dtype.kind == "f":
            v = np.ascontiguousarray(v, dtype="<f8").view(np.uint64)
        v = v.reshape(m, -1)
        bad |= (v != v[first]).any(axis=1)
    later = slot != 0
    for name in ("push_a", "push_b"):
        v = np.ascontiguousarray(getattr(c, name), dtype="<f8").view(np.uint64).reshape(m, -1)
        bad |= later & (v != 0).any(axis=1)
    if bad.any():
        row = int(np.flatnonzero(bad)[0])
        raise ValueError(
            f"contacts: row {row} (slot {int(slot[row])}) is not a point of the manifold "
            f"beginning at row {int(first[row])} (its pair fields or push differ)"
        )
    return starts


def pushed_manifolds(contacts, starts: np.ndarray) -> np.ndarray:
    """The manifolds (indices into ``starts``) whose push is stored: any bit of push_a or
    push_b set (-0.0 included), so that leaving the others out keeps every bit."""
    bits = [
        np.ascontiguousarray(getattr(contacts, name), dtype="<f8").view(np.uint64)[starts]
        for name in ("push_a", "push_b")
    ]
    return np.flatnonzero((bits[0] != 0).any(axis=1) | (bits[1] != 0).any(axis=1))


def encode_contacts(record: StepRecord) -> bytes:
    """``isaac.log.Contacts`` (format 2): the step's manifolds, the pair fields once per
    manifold and the point fields per point, column by column. ValueError if the rows are
    not manifolds (`manifold_starts`)."""
    c = record.contacts
    starts = manifold_starts(c)
    parts = [S.enc_uint(1, record.step), S.enc_double(2, record.time)]
    points = np.diff(np.append(starts, len(c))).astype("<u4")
    pushed = pushed_manifolds(c, starts)
    for number, name, dtype in CONTACT_MANIFOLD_WIRE:
        if name == "points":
            values = points
        elif name == "pushed":
            values = pushed.astype("<u4")
        elif name in ("push_a", "push_b"):
            values = np.asarray(getattr(c, name))[starts[pushed]]
        else:
            values = np.asarray(getattr(c, name))[starts]
        S.packed(parts, number, values, dtype)
    for number, name, dtype in CONTACT_POINT_WIRE:
        S.packed(parts, number, getattr(c, name), dtype)
    return b"".join(parts)


def encode_contacts_v1(record: StepRecord) -> bytes:
    """``isaac.log.Contacts`` as format 1 wrote it (every field per row; no pair depth): for
    comparing a replay with a format 1 log."""
    c = record.contacts
    parts = [S.enc_uint(1, record.step), S.enc_double(2, record.time)]
    for number, name, dtype in _CONTACT_WIRE_V1:
        S.packed(parts, number, getattr(c, name), dtype)
    return b"".join(parts)


def encode_stats(step: int, time: float, stats: dict) -> bytes:
    """``isaac.log.Stats`` from the dict made by ``recorder.stats.compute_stats``."""
    return b"".join(
        (
            S.enc_uint(1, step),
            S.enc_double(2, time),
            S.enc_double(3, stats["kinetic_energy"]),
            S.enc_double(4, stats["potential_energy"]),
            S.enc_double(5, stats["total_energy"]),
            S.enc_double(6, stats["linear_momentum_x"]),
            S.enc_double(7, stats["linear_momentum_y"]),
            S.enc_double(8, stats["angular_momentum"]),
            S.enc_uint(9, stats["contact_count"]),
            S.enc_double(10, stats["max_depth"]),
            S.enc_double(11, stats["max_impulse"]),
            S.enc_string(12, stats["state_hash"]),
        )
    )


class McapLogWriter:
    """Writes one run to ``path`` (through ``path + '.partial'``).

    model: the simulation's model (``names``, ``mass``, ``inertia``, ``restitution``,
        ``friction``, ``concrete``, ``vertices_local``, ``vertex_count``).
    scene: the `isaac.scene.Scene` (its ``world`` settings and ``name``).
    scene_text: the expanded scene YAML, attached as ``scene.yaml``.
    flush_every: close the chunk and flush to the OS every this many steps (1..100).
    compression: "none", "lz4" or "zstd" (per chunk).
    foxglove: a `recorder.foxglove.SceneEncoder` to also write ``/foxglove/scene``, or None.
    metadata: the ``isaac`` metadata record; default `build_metadata` of ``scene`` (a writer
        process gets it ready-made, with ``scene`` reduced to its name and ``world.dt``).
    gravity: (gx, gy) m/s^2 for the /stats values of `write_batch`; default the scene's.
    joints: the scene's joints (`isaac.scene.JointSpec`s or `joint_table_rows`); default
        ``scene.joints`` when it has them. With joints, ``/world`` carries the joint table and
        every step a ``/joints`` message (the schema then holds the joint messages); without,
        the file is byte for byte what it was before joints existed.
    background: a writer thread enters the messages into the MCAP chunks, compresses them and
        writes the file: a batch's records packed in the caller (`write_batch`), a record's
        messages encoded there too (`write`). The bytes of the file are the same either way.
    """

    def __init__(
        self,
        path: str,
        model,
        scene,
        scene_text: str,
        *,
        flush_every: int = 100,
        compression: str = "none",
        chunk_size: int = 256 * 1024,
        background: bool = False,
        foxglove=None,
        metadata: dict[str, str] | None = None,
        joints=None,
        gravity=None,
    ) -> None:
        if not 1 <= flush_every <= 100:
            raise ValueError("flush_every must be in 1..100")
        if compression not in COMPRESSIONS:
            raise ValueError(f"compression must be one of {sorted(COMPRESSIONS)}")
        self.path = str(path)
        self.partial_path = self.path + ".partial"
        self.model = model
        if joints is None:
            joints = getattr(scene, "joints", ())
        self.joints = joint_table_rows(joints)
        self.flush_every = flush_every
        self.clock_dt = float(scene.world.dt)
        if gravity is None:
            gravity = getattr(scene.world, "gravity", None)
        self.gravity = None if gravity is None else tuple(float(g) for g in gravity)
        self.clock = LogClock(scene.world.dt)
        self.steps_written = 0
        self.last_step: int | None = None
        self._last_exists: np.ndarray | None = None
        self._closed = False
        self._error: BaseException | None = None
        try:
            self._file = open(self.partial_path, "wb")
        except OSError as exc:
            raise LogError(f"cannot write {self.partial_path}: {exc.strerror}") from exc
        # every message goes through it: it closes the chunk and flushes after the first step
        # and every flush_every steps, and takes whole stretches of packed records
        self._mcap = w = McapFile(
            self._file,
            chunk_size=chunk_size,
            compression=compression,
            flush_every=flush_every,
            profile=PROFILE,
            library=LIBRARY,
        )
        # metadata and attachment first: they sit before every chunk and survive a crash
        if metadata is None:
            metadata = build_metadata(scene, scene_text, len(model.names))
        w.add_metadata(META_START, metadata)
        w.add_attachment(
            create_time=0,
            log_time=0,
            name=SCENE_ATTACHMENT,
            media_type="application/yaml",
            data=scene_text.encode("utf-8"),
        )
        with_joints = bool(self.joints)
        fds = S.schema_bytes(with_joints)
        self._channel = {}
        for topic, message in S.TOPICS.items():
            if topic in S.JOINT_TOPICS and not with_joints:
                continue
            schema_id = w.register_schema(
                name=S.full_name(message), encoding=S.SCHEMA_ENCODING, data=fds
            )
            self._channel[topic] = w.register_channel(
                topic=topic, message_encoding=S.MESSAGE_ENCODING, schema_id=schema_id
            )
        self.foxglove = foxglove
        if foxglove is not None:
            from recorder import foxglove as FG

            fg_schema = w.register_schema(
                name=FG.SCHEMA_NAME, encoding=S.SCHEMA_ENCODING, data=FG.descriptor_set_bytes()
            )
            self._channel[FG.TOPIC] = w.register_channel(
                topic=FG.TOPIC, message_encoding=S.MESSAGE_ENCODING, schema_id=fg_schema
            )
        if self._channel != channel_ids(with_joints, foxglove is not None):
            raise LogError("channel ids differ from recorder.mcap_writer.channel_ids")
        w.stats_channel = self._channel["/stats"]
        self._packer = None  # recorder.mcap_pack.BatchPacker, made by the first write_batch
        self._file.flush()
        self._queue: queue.Queue | None = None
        self._room = threading.Condition()  # the bytes of packed batches queued for the thread
        self._queued_bytes = 0
        self._thread: threading.Thread | None = None
        if background:
            # bounded: at most ~2 flush intervals in memory; the caller waits if the disk lags
            self._queue = queue.Queue(maxsize=2 * flush_every)
            self._thread = threading.Thread(
                target=self._work, name="isaac-mcap-writer", daemon=True
            )
            self._thread.start()

    def write(self, record: StepRecord, stats: dict | None = None) -> bool | None:
        """Append one step (its state, contacts and stats); ``/world`` when existence changed.

        stats None (a writer that `takes_batches`): the step goes as a batch of one
        (`write_batch`: packed by the compiled packer, which computes the /stats values and the
        state hash); returns False, writing nothing, when a float of the record is NaN or
        infinite (or its rows are not manifolds). Given ``stats`` (``state_hash`` may be left
        out: it is then computed here), the messages are made by the Python encoders of this
        module, the reference the packer is tested against. With a writer thread, the record
        (immutable) is handed over as it is and encoded, hashed and written there.
        """
        if self._error is not None:
            raise LogError(f"writing {self.partial_path} failed: {self._error}")
        if stats is None:
            if not self.takes_batches:
                raise LogError("this MCAP writer needs each step's /stats values")
            from recorder.mcap_pack import one_step_batch

            return self.write_batch(one_step_batch(record, self.clock_dt)) == 1
        item = (record, stats, self._count(record.step, record.exists))
        if self._queue is None:
            self._emit(item)
        else:
            self._queue.put(item)

    def write_messages(
        self,
        step: int,
        time: float,
        exists: np.ndarray,
        bodies,
        contacts,
        stats: dict,
        joints=None,
    ) -> None:
        """Append one step already encoded (``bodies``, ``contacts``, ``joints``: the bytes
        `encode_bodies`, `encode_contacts` and `encode_joints` give, ``joints`` None without
        joints; ``stats`` with its ``state_hash``), in this thread: what a writer process does
        with the frames `recorder.pack` encodes."""
        if self._queue is not None:
            raise LogError("write_messages is for a writer without a background thread")
        world_changed = self._count(step, exists)
        self._add(
            step, time, exists if world_changed else None, bodies, contacts, stats, None, joints
        )

    def _joints_message(self, record: StepRecord) -> bytes | None:
        """The record's ``/joints`` message, None without joints; LogError if a scene with
        joints hands a record without them (its log would lose them)."""
        if not self.joints:
            return None
        if record.joints is None or len(record.joints) != len(self.joints):
            raise LogError(
                f"step {record.step}: the record carries "
                f"{0 if record.joints is None else len(record.joints)} joints; the scene has "
                f"{len(self.joints)}"
            )
        return encode_joints(record.step, record.time, record.joints)

    @property
    def checks_finite(self) -> bool:
        """Whether `write` refuses a record holding a NaN or an infinity itself (given no
        stats: the packer's check); `Recorder.write` then leaves the check to it."""
        return self.takes_batches

    @property
    def takes_batches(self) -> bool:
        """Whether whole step batches may be written (`write_batch`): not with /foxglove/scene
        (drawn from records), and on little-endian machines (the compiled packer's)."""
        return self.foxglove is None and self.gravity is not None and sys.byteorder == "little"

    def write_batch(self, batch) -> int:
        """Append the steps of an `isaac.engine.records.StepBatch`: their Message records
        packed by one compiled call (`recorder.mcap_pack.BatchPacker`, the /stats values and
        the state hash included) and entered into the chunk a
        stretch at a time (`recorder.mcap_file.McapFile.append`), in this thread; with a writer
        thread, this thread only checks the batch (`recorder.mcap_pack.first_unfit`) and the
        thread packs and enters it. Returns how many steps were written: all, or those before
        the first one holding a NaN or an infinity (or contact rows that are not manifolds)."""
        if self._error is not None:
            raise LogError(f"writing {self.partial_path} failed: {self._error}")
        if not self.takes_batches:
            raise LogError("this MCAP writer takes records, not batches")
        if self._packer is None:
            from recorder.mcap_pack import BatchPacker

            self._packer = BatchPacker(
                self.model,
                self.gravity,
                self.clock_dt,
                record_channels(bool(self.joints)),
                self.joints,
                encode_world=encode_world,
            )
        last_exists = self._last_exists
        if self._queue is None:
            done = self._pack_and_enter(batch, batch.steps, last_exists)
        else:
            from recorder.mcap_pack import batch_arguments, first_unfit

            done = int(first_unfit(0, batch.steps, *batch_arguments(batch)))
            if done:
                # the batch's own arrays (never written again) wait for the thread: at most
                # QUEUED_BYTES of them, one batch at least
                size = sum(a.nbytes for a in (batch.position, batch.velocity, *batch.row_arrays))
                with self._room:
                    while self._queued_bytes and self._queued_bytes + size > QUEUED_BYTES:
                        self._room.wait()
                    self._queued_bytes += size
                self._queue.put(_Batch(batch, done, last_exists, size))
        if done:
            self._last_exists = np.array(batch.exists[done - 1], dtype=bool)
            self.steps_written += done
            self.last_step = batch.first + done - 1
        return done

    def _pack_and_enter(self, batch, steps: int, last_exists) -> int:
        """Pack the batch's first ``steps`` steps (`recorder.mcap_pack.BatchPacker`, after a
        step whose existence was ``last_exists``) and enter them into the chunks; returns how
        many steps were packed (fewer at a NaN, an infinity or rows that are not manifolds)."""
        plan = self._packer.plan(batch, last_exists)
        buf = np.empty(int(plan.sizes[:steps].sum()), dtype=np.uint8)
        done, end, _ = self._packer.pack(buf, 0, 0, steps, batch, plan)
        if done:
            self._mcap.append(buf, 0, end)
        return done

    def write_records(self, buf: np.ndarray, start: int, end: int, hashed: bool = True) -> None:
        """Append whole steps already packed as Message records (`recorder.mcap_pack`) in
        ``buf[start:end]`` (uint8, writable), in this thread: what a writer process does with
        the records its parent packs into shared memory. hashed False: the state hashes are
        written here first (`recorder.mcap_pack.put_hashes`)."""
        if self._queue is not None:
            raise LogError("write_records is for a writer without a background thread")
        if not hashed:
            from recorder.mcap_pack import put_hashes

            put_hashes(buf, start, end, record_channels(bool(self.joints)))
        steps, last = self._mcap.append(buf, start, end)
        if steps:
            self.steps_written += steps
            self.last_step = last

    def _count(self, step: int, exists: np.ndarray) -> bool:
        """Note one more step: whether existence changed (a ``/world`` message is due)."""
        world_changed = self._last_exists is None or not np.array_equal(exists, self._last_exists)
        if world_changed:
            self._last_exists = np.array(exists, dtype=bool)
        self.steps_written += 1
        self.last_step = step
        return world_changed

    def _emit(self, item) -> None:
        if isinstance(item, _Batch):
            try:
                if self._pack_and_enter(item.batch, item.steps, item.last_exists) < item.steps:
                    raise LogError(f"step {item.batch.first}: a checked batch failed to pack")
            finally:
                with self._room:
                    self._queued_bytes -= item.size
                    self._room.notify_all()
            return
        record, stats, world_changed = item
        if "state_hash" not in stats:
            stats = {**stats, "state_hash": state_hash(record)}
        self._add(
            record.step,
            record.time,
            record.exists if world_changed else None,
            encode_bodies(record),
            encode_contacts(record),
            stats,
            record,
            self._joints_message(record),
        )

    def _add(self, step, time, world_exists, bodies, contacts, stats, record, joints=None) -> None:
        """The step's messages (``/world`` first, with ``world_exists``, when given;
        ``/foxglove/scene`` when enabled, from ``record``), then the chunk closed when one is
        due (`recorder.mcap_file.McapFile.end_step`). Uses nothing a later `write`
        changes: the writer thread runs behind."""
        if self.joints and joints is None:  # before any of the step's messages
            raise LogError(f"step {step}: no /joints message for a scene with joints")
        ch = self._channel
        t = self.clock(step)
        add = self._mcap.add
        if world_exists is not None:
            world = encode_world(self.model, step, time, world_exists, self.joints)
            add(ch["/world"], t, world, step)
        add(ch["/bodies"], t, bodies, step)
        add(ch["/contacts"], t, contacts, step)
        if joints is not None:
            add(ch["/joints"], t, joints, step)
        add(ch["/stats"], t, encode_stats(step, time, stats), step)
        if self.foxglove is not None:
            add(ch["/foxglove/scene"], t, self.foxglove.encode(record, t), step)
        self._mcap.end_step()

    def _work(self) -> None:
        assert self._queue is not None
        while True:
            item = self._queue.get()
            if item is None:
                return
            if self._error is not None:
                continue  # keep draining so the producer never blocks
            try:
                self._emit(item)
            except BaseException as exc:  # noqa: BLE001 - reported to the producer
                self._error = exc

    def _stop_worker(self) -> None:
        if self._thread is not None:
            self._queue.put(None)
            self._thread.join()
            self._thread = None

    def close(
        self,
        *,
        complete: bool = True,
        stopped_at: int | None = None,
        reason: str | None = None,
        sync: bool = True,
    ) -> str:
        """Finish the file (end metadata, summary, index) and rename it; returns the final path.

        sync: fsync the file before the rename (default), so that the final name never holds a
            half-written log, even after a power loss. False: the caller makes the file durable
            itself before it gives the file a name that says it is complete (`isaac sweep`
            syncs a chunk's logs at once, then moves them: isaac.app.sweep.worker).
        """
        if self._closed:
            return self.path
        self._closed = True
        self._stop_worker()
        if self._error is not None:
            self._file.close()
            raise LogError(f"writing {self.partial_path} failed: {self._error}")
        self._mcap.flush()
        self._mcap.add_metadata(
            META_END,
            end_metadata(
                complete=complete,
                steps=self.steps_written,
                last_step=self.last_step,
                stopped_at=stopped_at,
                reason=reason,
            ),
        )
        self._mcap.finish()
        self._file.flush()
        if sync:
            os.fsync(self._file.fileno())
        self._file.close()
        os.replace(self.partial_path, self.path)
        return self.path

    def abandon(self, reason: str | None = None) -> None:
        """Close the underlying file without finishing it (the .partial file stays, every step
        written so far flushed; no summary or index: `isaac recover` makes the clean copy).

        reason: also write the ``isaac.end`` metadata (complete: false) saying why, and sync the
            file to disk (a writer process whose run died: recorder.writer_process).
        """
        if not self._closed:
            self._closed = True
            try:
                self._stop_worker()
                self._mcap.flush()
                if reason is not None and self._error is None:
                    self._mcap.add_metadata(
                        META_END,
                        end_metadata(
                            complete=False,
                            steps=self.steps_written,
                            last_step=self.last_step,
                            stopped_at=None,
                            reason=reason,
                        ),
                    )
                    self._file.flush()
                    os.fsync(self._file.fileno())
            finally:
                self._file.close()


# batches waiting for the writer thread, in bytes of their arrays (a batch of the 503-body pile
# is about 1 MB: the thread may lag by a few dozen batches, not by the whole run)
QUEUED_BYTES = 32 << 20


class _Batch(NamedTuple):
    """A checked batch for the writer thread: its first ``steps`` steps, after a step whose
    existence was ``last_exists``; ``size``: its arrays' bytes."""

    batch: object
    steps: int
    last_exists: np.ndarray | None
    size: int


def end_metadata(
    *, complete: bool, steps: int, last_step: int | None, stopped_at: int | None, reason: str | None
) -> dict[str, str]:
    """The ``isaac.end`` metadata record written when a log is closed."""
    return {
        "complete": "true" if complete else "false",
        "steps_written": str(steps),
        "last_step": "" if last_step is None else str(last_step),
        "stopped_at": "" if stopped_at is None else str(stopped_at),
        "reason": "" if reason is None else " ".join(str(reason).split()),
    }
