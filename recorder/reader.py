"""Read an ISAAC MCAP log back: metadata, the embedded scene, and every step as numpy arrays.

Used by ``isaac inspect`` / ``isaac recover`` / ``isaac view`` and by the replay package::

    log = LogReader("run.mcap")          # raises LogError if not a readable ISAAC log
    log.metadata                         # dict[str, str]: the `isaac` metadata (versions, settings)
    log.settings                         # dict: every world setting of the embedded scene, log.dt
    log.header_damage                    # Damage | None: metadata disagreeing with the scene
    log.scene_text                       # str: the expanded scene YAML (attachment scene.yaml)
    log.scene()                          # isaac.scene.Scene loaded from it
    log.world                            # WorldTable at step 0 (same names as Simulation.model)
    log.closed_cleanly                   # bool: footer + summary present (False for .partial)
    log.end                              # dict | None: the `isaac.end` metadata (complete, reason)
    for s in log.steps():                # LoggedStep(record: StepRecord, stats: dict, world)
        s.record.position, s.record.contacts.impulse, s.stats["state_hash"]
    log.step(k)                          # one LoggedStep (LogError if absent)
    log.summary()                        # LogSummary: counts, extremes, energies
    log.damage, log.claimed_steps        # after steps(): the first damage, what the log claims

The file is read in order, within bounds (`recorder.mcap_records`: only a regular file, every
length checked before it is allocated, every chunk CRC-checked), so a file that was never closed
(a run killed with SIGKILL, a file cut short) yields every step in its complete chunks. Steps are
checked as they come (`recorder.integrity.StepReader`): a step counts only when its ``/bodies``,
``/contacts`` and ``/stats`` are all there, and reading stops at the first damaged record,
missing, repeated or incomplete step; after `steps` ``log.damage`` (a `Damage` or None) says
what and where (the step, the byte), and a closed log's summary and ``isaac.end`` are compared
with what was read. A message whose arrays do not fit together (a ``/bodies`` array one value
short, a contact naming a body that does not exist) raises LogError ("damaged log").
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import math
import os
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field

import numpy as np
from mcap.records import Header, Metadata
from mcap.writer import CompressionType, Writer

from isaac.engine.records import JOINT_FIELDS, Contacts, JointRows, StepRecord
from isaac.errors import LogError, SceneError
from isaac.scene.limits import MAX_VERTICES
from recorder import schema as S
from recorder.integrity import SCENE_KEYS, SETTING_PREFIX, Damage, StepReader, check_metadata
from recorder.mcap_records import (
    MAGIC,
    OP_ATTACHMENT,
    OP_CHANNEL,
    OP_CHUNK,
    OP_FOOTER,
    OP_HEADER,
    OP_METADATA,
    OP_SCHEMA,
    McapScan,
    RecordError,
    open_log,
)
from recorder.mcap_writer import (
    FORMAT_NAME,
    META_END,
    META_START,
    SCENE_ATTACHMENT,
    build_metadata,
    end_metadata,
)

MCAP_MAGIC = MAGIC


@dataclass(frozen=True, eq=False)
class WorldTable:
    """The `/world` message as arrays, named like `Simulation.model`.

    step: the step from which this table holds.
    names: list of body names; vertices_local: (n, V, 2) m, body frame about the centre of mass,
    padded with zeros past ``vertex_count``; mass (kg), inertia (kg m^2), restitution, friction:
    (n,) float64; concrete, exists: (n,) bool; circle_radius: (n,) m, a circle's radius (its
    one vertex is its centre), 0 for a polygon; joints: the joint table, one dict per joint in
    index order with the fields of ``isaac.log.Joint`` (docs/log-format.md), empty without.
    """

    step: int
    names: list
    vertices_local: np.ndarray
    vertex_count: np.ndarray
    mass: np.ndarray
    inertia: np.ndarray
    restitution: np.ndarray
    friction: np.ndarray
    concrete: np.ndarray
    exists: np.ndarray
    circle_radius: np.ndarray
    joints: tuple = ()

    @staticmethod
    def from_message(msg: dict) -> WorldTable:
        """The table of a decoded `/world` message; ValueError (one line) if its bodies do not
        fit together: indices not 0..n-1, an odd number of vertex coordinates, or a polygon
        with fewer than 3 or more than MAX_VERTICES vertices."""
        bodies = sorted(msg["bodies"], key=lambda b: b["index"])
        n = len(bodies)
        if [b["index"] for b in bodies] != list(range(n)):
            raise ValueError(f"/world: the body indices are not 0..{n - 1}")
        radius = np.array([float(b.get("circle_radius", 0.0)) for b in bodies])
        for b, r in zip(bodies, radius):
            size = b["vertices_local"].size
            if r > 0.0:
                if size != 2:
                    raise ValueError(
                        f"/world: body {b['index']} is a circle with {size} vertex coordinates "
                        "(a circle has one vertex, its centre)"
                    )
            elif size % 2 or not 3 <= size // 2 <= MAX_VERTICES:
                raise ValueError(
                    f"/world: body {b['index']} has {size} vertex coordinates "
                    f"(a polygon has 3 to {MAX_VERTICES} x, y pairs)"
                )
        counts = np.array([b["vertices_local"].size // 2 for b in bodies], dtype=np.int64)
        v_max = int(counts.max()) if n else 0
        local = np.zeros((n, v_max, 2))
        for k, b in enumerate(bodies):
            local[k, : counts[k]] = b["vertices_local"].reshape(-1, 2)
        return WorldTable(
            step=int(msg["step"]),
            names=[b["name"] for b in bodies],
            vertices_local=local,
            vertex_count=counts,
            mass=np.array([b["mass"] for b in bodies], dtype=np.float64),
            inertia=np.array([b["inertia"] for b in bodies], dtype=np.float64),
            restitution=np.array([b["restitution"] for b in bodies], dtype=np.float64),
            friction=np.array([b["friction"] for b in bodies], dtype=np.float64),
            concrete=np.array([b["concrete"] for b in bodies], dtype=bool),
            exists=np.array([b["exists"] for b in bodies], dtype=bool),
            circle_radius=radius,
            joints=_joint_table(msg.get("joints", []), n),
        )


def _joint_table(joints: list, n: int) -> tuple:
    """The decoded ``World.joints`` as row dicts (2-vectors as tuples); ValueError (one line)
    if the indices are not 0..m-1 or a joint names a body outside the n."""
    rows = sorted(joints, key=lambda j: j["index"])
    if [j["index"] for j in rows] != list(range(len(rows))):
        raise ValueError(f"/world: the joint indices are not 0..{len(rows) - 1}")
    out = []
    for j in rows:
        for key in ("a", "b"):
            if not 0 <= j[key] < n:
                raise ValueError(
                    f"/world: joint {j['index']} ({j['name']}) names body {j[key]} as {key}; "
                    f"the world has {n}"
                )
        for key in ("local_a", "local_b", "axis"):
            if j[key].size != 2:
                raise ValueError(
                    f"/world: joint {j['index']} ({j['name']}): {key} has {j[key].size} values, "
                    "not 2"
                )
        row = {k: v for k, v in j.items() if k != "index"}
        for key in ("local_a", "local_b", "axis"):
            row[key] = tuple(float(x) for x in j[key])
        out.append(row)
    return tuple(out)


@dataclass(frozen=True, eq=False)
class LoggedStep:
    """One step read back: the record (state after the step + its contacts), its `/stats`
    values (dict) and the `/world` table in force at that step."""

    record: StepRecord
    stats: dict | None
    world: WorldTable

    @property
    def step(self) -> int:
        return self.record.step


@dataclass
class LogSummary:
    """What ``isaac inspect`` prints (energies in J, depth in m, impulse in N s)."""

    steps: int = 0
    first_step: int | None = None
    last_step: int | None = None
    contacts: int = 0
    max_depth: float = 0.0
    max_depth_step: int | None = None
    max_impulse: float = 0.0
    max_impulse_step: int | None = None
    energy_start: float | None = None
    energy_end: float | None = None
    world_changes: int = 0
    messages: dict = field(default_factory=dict)
    # a log with joints: the largest position error left after a step's correction (m, the
    # anchors' distance off the constraint), the step and the joint index holding it
    max_joint_error: float = 0.0
    max_joint_error_step: int | None = None
    max_joint_error_joint: int | None = None
    # the energy check over the steps read (`isaac.engine.energy_check.EnergyCheck`), None
    # without /stats
    energy_check: object = None


def _sized(msg: dict, topic: str, key: str, n: int, what: str):
    a = msg[key]
    if a.size != n:
        raise ValueError(f"{topic}: {key} holds {a.size} values for {what}")
    return a


def check_bodies(msg: dict) -> int:
    """The number of bodies n of a decoded `/bodies` message; ValueError (one line) unless every
    per-body array holds n values (2n for the 2-vectors)."""
    n = msg["angle"].size
    for key, size in (("position", 2 * n), ("velocity", 2 * n), ("angular_velocity", n)):
        _sized(msg, "/bodies", key, size, f"{n} bodies")
    _sized(msg, "/bodies", "exists", n, f"{n} bodies")
    return n


def joints_from_message(msg: dict, m: int | None = None) -> JointRows:
    """`JointRows` from a decoded `/joints` message (read-only views): ValueError (one line)
    unless every field holds the same number of joints (``m`` when given)."""
    from isaac.engine.joints import JOINT_IMPULSES

    if m is None:
        m = msg["angular_impulse"].size
    what = f"{m} joints"
    widths = {"anchor_a": 2, "anchor_b": 2, "linear_impulse": 2, "error": 2}
    widths["impulses"] = JOINT_IMPULSES
    fields = {}
    for name in JOINT_FIELDS:
        w = widths.get(name, 1)
        v = _sized(msg, "/joints", name, w * m, what)
        fields[name] = v.reshape(m, w) if w > 1 else v
    return JointRows(**fields)


def record_from_messages(bodies: dict, contacts: dict, joints: dict | None = None) -> StepRecord:
    """A StepRecord from decoded `/bodies`, `/contacts` and (a scene with joints) `/joints`
    messages (arrays are read-only views).

    Raises ValueError (one line) if the arrays do not fit together: every per-body array must
    hold n values (2n for 2-vectors), every per-contact array m (2m), and a contact's bodies
    must be among the n."""
    n = check_bodies(bodies)
    record = StepRecord(
        step=int(bodies["step"]),
        time=float(bodies["time"]),
        position=bodies["position"].reshape(n, 2),
        angle=bodies["angle"],
        velocity=bodies["velocity"].reshape(n, 2),
        angular_velocity=bodies["angular_velocity"],
        exists=bodies["exists"],
        contacts=contacts_from_message(contacts),
        joints=None if joints is None else joints_from_message(joints),
    )
    c = record.contacts
    if len(c):
        # the fixed32 indices were read as int32: a value past 2^31 shows as negative
        outside = (c.a < 0) | (c.a >= n) | (c.b < 0) | (c.b >= n)
        if outside.any():
            row = int(np.flatnonzero(outside)[0])
            raise ValueError(
                f"/contacts: row {row} names bodies {contacts['a'][row]} and "
                f"{contacts['b'][row]}; the step has {n} bodies"
            )
    return record


def contacts_from_message(msg: dict) -> Contacts:
    """`Contacts` (one row per point) from a decoded `/contacts` message of either format
    (`recorder.schema.decode`); ValueError if an array does not fit the counts. Format 2's
    manifold fields are repeated on each of the manifold's rows (``slot`` counts the points of
    a manifold from 0; a push sits on slot 0 of a manifold in ``pushed``, every other row's is
    +0.0); format 1 logs hold no pair depth: it reads NaN."""
    if "slot" in msg:
        return _contacts_v1(msg)
    k = msg["a"].size
    per = f"{k} contact manifolds"

    def manifold(key, width=1):
        return _sized(msg, "/contacts", key, width * k, per)

    counts = manifold("points").astype(np.int64)
    if k and int(counts.min()) < 1:
        raise ValueError(f"/contacts: manifold {int(np.argmin(counts))} has no point")
    m = int(counts.sum())
    what = f"{m} contact points"
    # checked before anything m long is made: the counts of a hostile log may claim billions
    _sized(msg, "/contacts", "point_depth", m, what)
    starts = np.zeros(k, dtype=np.int64)
    if k:
        np.cumsum(counts[:-1], out=starts[1:])
    of_row = np.repeat(np.arange(k), counts)
    slot = (np.arange(m) - starts[of_row]).astype(np.int32)

    def rows(key, dtype=None):
        values = manifold(key)[of_row]
        return values.astype(dtype) if dtype is not None else values

    pushed = msg["pushed"].astype(np.int64)
    p = pushed.size
    if p and (int(pushed.max()) >= k or (np.diff(pushed) <= 0).any()):
        raise ValueError(f"/contacts: pushed names manifolds out of order or past the {k}")

    def pushes(key):
        out = np.zeros((m, 2))
        out[starts[pushed]] = _sized(msg, "/contacts", key, 2 * p, f"{p} pushed manifolds").reshape(
            p, 2
        )
        return out

    return Contacts(
        substep=rows("substep", np.int32),
        a=rows("a", np.int32),
        b=rows("b", np.int32),
        feature=rows("feature", np.int32),
        slot=slot,
        point=_sized(msg, "/contacts", "point", 2 * m, what).reshape(m, 2),
        normal=manifold("normal", 2).reshape(k, 2)[of_row],
        depth=_sized(msg, "/contacts", "point_depth", m, what),
        pair_depth=rows("pair_depth"),
        push_a=pushes("push_a"),
        push_b=pushes("push_b"),
        impulse=_sized(msg, "/contacts", "impulse", m, what),
        tangent_impulse=_sized(msg, "/contacts", "tangent_impulse", m, what),
        restitution=_sized(msg, "/contacts", "restitution", m, what),
    )


def _contacts_v1(msg: dict) -> Contacts:
    """`Contacts` from a format 1 `/contacts` message (every field per row)."""
    m = msg["a"].size
    what = f"{m} contact rows"

    def i32(k):
        return _sized(msg, "/contacts", k, m, what).astype(np.int32)

    def f(k):
        return _sized(msg, "/contacts", k, m, what)

    def v(k):
        return _sized(msg, "/contacts", k, 2 * m, what).reshape(m, 2)

    return Contacts(
        substep=i32("substep"),
        a=i32("a"),
        b=i32("b"),
        feature=i32("feature"),
        slot=i32("slot"),
        point=v("point"),
        normal=v("normal"),
        depth=f("depth"),
        pair_depth=np.full(m, np.nan),  # not in format 1 logs
        push_a=v("push_a"),
        push_b=v("push_b"),
        impulse=f("impulse"),
        tangent_impulse=f("tangent_impulse"),
        restitution=f("restitution"),
    )


# what a decoder or `record_from_messages` raises on a malformed message
DECODE_ERRORS = (S.WireError, UnicodeDecodeError, ValueError, IndexError, KeyError, TypeError)


class LogReader:
    """A readable ISAAC MCAP log (clean or not). See the module docstring for the API."""

    def __init__(self, path: str) -> None:
        self.path = str(path)
        f, self.size = open_log(self.path)  # a regular file, or LogError before any open
        self.header: Header | None = None
        self.metadata: dict[str, str] = {}
        self.attachments: dict[str, bytes] = {}
        self._end: dict[str, str] | None = None
        self._scanned = False
        self.damage: Damage | None = None
        self.tail: int | None = None
        self.claimed_steps: int | None = None
        self._header_records: list = []  # metadata and attachments before the first chunk
        self._reader: StepReader | None = None  # of the last `steps`
        self.metadata_offset: int | None = None  # of the `isaac` metadata record
        self._scene = None
        self._checked: tuple[Damage | None, list[str]] | None = None
        header_damage: RecordError | None = None
        with f:
            scan = McapScan(f, self.size)
            # metadata and the scene come before the first chunk: read only that far
            try:
                for offset, opcode, body in scan.records(until=(OP_CHUNK,)):
                    if opcode in (OP_HEADER, OP_METADATA, OP_ATTACHMENT):
                        record = scan.parse(offset, opcode, body)
                        if isinstance(record, Header):
                            self.header = record
                            continue
                        if isinstance(record, Metadata):
                            if record.name == META_END:
                                continue
                            if record.name == META_START and not self.metadata:
                                self.metadata = dict(record.metadata)
                                self.metadata_offset = offset
                        else:
                            self.attachments.setdefault(record.name, bytes(record.data))
                        self._header_records.append(record)
                    elif opcode not in (OP_SCHEMA, OP_CHANNEL):
                        break
            except RecordError as exc:
                if exc.offset == 0:
                    what = "empty file" if self.size == 0 else "not an MCAP file"
                    raise LogError(f"{self.path}: {what}") from None
                header_damage = exc
        damaged = "" if header_damage is None else f" (damaged log: {header_damage})"
        if self.metadata.get("format") != FORMAT_NAME:
            raise LogError(f"{self.path}: not an ISAAC log (no '{META_START}' metadata){damaged}")
        if SCENE_ATTACHMENT not in self.attachments:
            raise LogError(f"{self.path}: the log has no {SCENE_ATTACHMENT} attachment{damaged}")
        self.recorded_settings, self.recorded_dt = _settings(self.path, self.metadata)
        self.closed_cleanly = self._has_footer()
        self._world0: WorldTable | None = None

    def _has_footer(self) -> bool:
        """True when the file ends with a footer and the magic (it was finished)."""
        if self.size < 2 * len(MAGIC) + 29:
            return False
        f, _size = open_log(self.path)
        with f:
            f.seek(self.size - len(MAGIC))
            if f.read() != MAGIC:
                return False
            f.seek(self.size - len(MAGIC) - 29)
            return f.read(1) == bytes([OP_FOOTER])

    def messages(self, topics=None) -> Iterator[tuple[str, object, dict]]:
        """(topic, message, decoded dict) in file order, for ``topics`` (all if None).

        The message has ``channel_id``, ``sequence``, ``log_time``, ``publish_time`` and
        ``data`` like an mcap Message. Stops at the first damaged record (``self.damage``);
        LogError if a message does not decode."""
        want = None if topics is None else set([topics] if isinstance(topics, str) else topics)
        f, size = open_log(self.path)
        with f:
            scan = McapScan(f, size)
            try:
                for msg in scan.messages():
                    channel = scan.channels.get(msg.channel_id)
                    topic = channel.topic if channel is not None else None
                    if topic not in S.TOPICS or (want is not None and topic not in want):
                        continue
                    try:
                        decoded = S.decode(S.TOPICS[topic], bytes(msg.data))
                    except DECODE_ERRORS as exc:
                        raise LogError(
                            f"{self.path}: damaged log: step {msg.sequence}: "
                            f"bad {topic} message ({exc})"
                        ) from None
                    yield topic, msg._replace(data=bytes(msg.data)), decoded
            except RecordError as exc:
                if not exc.what.startswith("the file ends without a footer"):
                    self.damage = Damage(exc.what, None, exc.offset)
        ends = [m for _o, m in scan.metadata if m.name == META_END]
        if ends:
            self._end = dict(ends[-1].metadata)

    # -- steps ---------------------------------------------------------------------------------

    def steps(self) -> Iterator[LoggedStep]:
        """Every complete step in order (state, contacts, stats and the `/world` in force), up
        to the first damage (``self.damage`` says what and where). LogError ("damaged log") if
        a step's messages do not decode or do not fit together."""
        reader = self._reader = StepReader(self.path, closed=self.closed_cleanly)
        world: WorldTable | None = None
        for step, messages in reader.steps():
            try:
                if "/world" in messages:
                    table = WorldTable.from_message(S.decode("World", bytes(messages["/world"])))
                    if world is not None and len(table.names) != len(world.names):
                        raise ValueError(
                            f"/world: {len(table.names)} bodies, {len(world.names)} before"
                        )
                    world = table
                    if self._world0 is None:
                        self._world0 = world
                assert world is not None  # the first step has one (recorder.integrity)
                # bytes: the decoder slices strings out and decodes them
                bodies = S.decode("Bodies", bytes(messages["/bodies"]))
                contacts = S.decode("Contacts", bytes(messages["/contacts"]))
                stats = S.decode("Stats", bytes(messages["/stats"]))
                joints = None
                if world.joints:
                    if "/joints" not in messages:
                        raise ValueError("no /joints message (the world has joints)")
                    joints = S.decode("Joints", bytes(messages["/joints"]))
                    if joints["step"] != step:
                        raise ValueError(f"/joints: the message says step {joints['step']}")
                for topic, msg in (("/bodies", bodies), ("/contacts", contacts), ("/stats", stats)):
                    if msg["step"] != step:
                        raise ValueError(f"{topic}: the message says step {msg['step']}")
                record = record_from_messages(bodies, contacts, joints)
                if joints is not None and len(record.joints) != len(world.joints):
                    raise ValueError(
                        f"/joints holds {len(record.joints)} joints, /world {len(world.joints)}"
                    )
                if record.position.shape[0] != len(world.names):
                    raise ValueError(
                        f"/bodies holds {record.position.shape[0]} bodies, /world "
                        f"{len(world.names)}"
                    )
            except DECODE_ERRORS as exc:
                raise LogError(f"{self.path}: damaged log: step {step}: {exc}") from None
            yield LoggedStep(record, stats, world)
        # the steps' damage first (it names a step), else the header's
        self.damage = reader.damage if reader.damage is not None else self.header_damage
        self.tail = reader.tail
        self.claimed_steps = reader.claimed_steps
        if reader.end is not None:
            self._end = reader.end
        self._scanned = True

    def step(self, k: int) -> LoggedStep:
        """The logged step ``k`` (LogError if the log does not hold it)."""
        for s in self.steps():
            if s.step == k:
                return s
            if s.step > k:
                break
        if self.damage is not None:
            raise LogError(
                f"{self.path}: step {k} is not readable: the log is damaged from "
                f"{self.damage.at()} on: {self.damage}"
            )
        raise LogError(f"{self.path}: step {k} is not in the log")

    @property
    def world(self) -> WorldTable:
        """The `/world` table of the log's first step."""
        if self._world0 is None:
            for _ in self.steps():
                break
        if self._world0 is None:
            why = f" ({self.damage})" if self.damage is not None else ""
            raise LogError(f"{self.path}: the log holds no complete step{why}")
        return self._world0

    @property
    def scene_text(self) -> str:
        """The expanded scene YAML the run used (attachment ``scene.yaml``)."""
        try:
            return self.attachments[SCENE_ATTACHMENT].decode("utf-8")
        except UnicodeDecodeError as exc:
            raise LogError(f"{self.path}: the embedded scene is not UTF-8 text ({exc})") from None

    def scene(self):
        """The run's `isaac.scene.Scene`, loaded from the embedded ``scene.yaml`` once its bytes
        match the ``scene_sha256`` recorded beside them: LogError (one line) if they do not,
        SceneError if the scene fails validation."""
        if self._scene is None:
            from isaac.scene import load_scene_text

            text = self.scene_text
            recorded = self.metadata.get("scene_sha256")
            if recorded is None:
                raise LogError(f"{self.path}: the log's metadata has no scene_sha256")
            if recorded != hashlib.sha256(text.encode("utf-8")).hexdigest():
                raise LogError(
                    f"{self.path}: the embedded scene does not match its recorded sha256 "
                    f"(the log was altered or is corrupt)"
                )
            self._scene = load_scene_text(text, f"{self.path}:{SCENE_ATTACHMENT}")
        return self._scene

    def _check_header(self) -> tuple[Damage | None, list[str]]:
        if self._checked is None:
            try:
                scene = self.scene()
            except LogError as exc:  # the scene's bytes are not the ones recorded
                what = str(exc).removeprefix(f"{self.path}: ")
                self._checked = (Damage(what, None, self.metadata_offset), [])
            except SceneError:
                # as recorded, but this version does not take it (the replay refuses it, exit
                # 2): nothing to check the metadata against
                self._checked = (None, [])
            else:
                what, notes = check_metadata(
                    self.metadata, scene, self.scene_text, len(scene.bodies)
                )
                damage = None if what is None else Damage(what, None, self.metadata_offset)
                self._checked = (damage, notes)
        return self._checked

    @property
    def header_damage(self) -> Damage | None:
        """The first value of the ``isaac`` metadata that disagrees with the embedded scene
        (`recorder.integrity.check_metadata`), or an embedded scene that does not match its
        sha256; None when the header is sound or the scene, as recorded, does not load."""
        return self._check_header()[0]

    def restated_metadata(self) -> dict[str, str]:
        """The ``isaac`` metadata with every value that restates the embedded scene rewritten
        from it, as the recorder writes it (`recorder.mcap_writer.build_metadata`); the
        versions and the machine as recorded."""
        scene = self.scene()
        expected = build_metadata(scene, self.scene_text, len(scene.bodies))
        kept = {
            k: v
            for k, v in self.metadata.items()
            if k not in SCENE_KEYS and k != "settings" and not k.startswith(SETTING_PREFIX)
        }
        restated = {
            k: v
            for k, v in expected.items()
            if k in SCENE_KEYS or k == "settings" or k.startswith(SETTING_PREFIX)
        }
        return {**kept, **restated}

    @property
    def header_notes(self) -> list[str]:
        """Settings only this version or only the log's recorder knows (a log of another
        version): what `check_metadata` could not compare."""
        return self._check_header()[1]

    @property
    def settings(self) -> dict:
        """Every world setting of the run (JSON values, as in the ``settings`` metadata): the
        embedded scene's, the one source the replay simulates from; the recorded ``settings``
        (``recorded_settings``) only when the scene cannot be loaded (``header_damage`` says
        when it was altered)."""
        self._check_header()  # loads the scene once, if it loads
        if self._scene is None:
            return self.recorded_settings
        return json.loads(json.dumps(asdict(self._scene.world), sort_keys=True))

    @property
    def dt(self) -> float:
        """The time step, s: the embedded scene's (``recorded_dt`` when it cannot be loaded)."""
        self._check_header()
        return self.recorded_dt if self._scene is None else float(self._scene.world.dt)

    @property
    def end(self) -> dict | None:
        """The ``isaac.end`` metadata (complete, steps_written, last_step, stopped_at, reason),
        or None if the file was never closed."""
        if self._end is None and not self._scanned and self.closed_cleanly:
            f, size = open_log(self.path)
            with f:
                scan = McapScan(f, size)
                scan.read_summary()  # the metadata index at the end points at it
            ends = [m for _o, m in scan.metadata if m.name == META_END]
            if ends:
                self._end = dict(ends[-1].metadata)
        return self._end

    @property
    def complete(self) -> bool:
        """True when the run finished all its steps and the file was closed."""
        end = self.end
        return bool(self.closed_cleanly and end is not None and end.get("complete") == "true")

    def summary(self) -> LogSummary:
        """Counts and extremes over every readable step (one pass over the file)."""
        s = LogSummary()
        totals, entered = [], []
        before = first = None
        for logged in self.steps():
            r = logged.record
            s.steps += 1
            if s.first_step is None:
                s.first_step = r.step
            s.last_step = r.step
            c = r.contacts
            s.contacts += len(c)
            if len(c):
                d = float(np.max(c.depth))
                if s.max_depth_step is None or d > s.max_depth:
                    s.max_depth, s.max_depth_step = d, r.step
                j = float(np.max(c.impulse))
                if s.max_impulse_step is None or j > s.max_impulse:
                    s.max_impulse, s.max_impulse_step = j, r.step
            if r.joints is not None and len(r.joints):
                k = int(np.argmax(r.joints.error[:, 0]))
                e = float(r.joints.error[k, 0])
                if s.max_joint_error_step is None or e > s.max_joint_error:
                    s.max_joint_error, s.max_joint_error_step = e, r.step
                    s.max_joint_error_joint = k
            if logged.stats is not None:
                if s.energy_start is None:
                    s.energy_start = logged.stats["total_energy"]
                s.energy_end = logged.stats["total_energy"]
                if first is None:
                    first = logged
                else:
                    totals.append(s.energy_end)
                    entered.append(self._entered(logged, before))
                before = logged
            if logged.world.step == r.step:
                s.world_changes += 1
        if first is not None:
            s.energy_check = self._energy_check(first, totals, entered)
        return s

    def _entered(self, logged: LoggedStep, before: LoggedStep) -> float:
        """Energy (J) bodies entering at this step brought in, less that of bodies leaving
        (`isaac.engine.diagnostics.record_energies`, called only when existence changed)."""
        if np.array_equal(logged.record.exists, before.record.exists):
            return 0.0
        from isaac.engine import diagnostics

        g = self.settings.get("gravity", (0.0, 0.0))
        return diagnostics.record_energies(logged.world, before.record, logged.record, g)[1]

    def _energy_check(self, first: LoggedStep, totals: list, entered: list):
        """The energy check of the run the log holds (`isaac.engine.energy_check`), from its
        `/stats` energies; the scale from the first step's `/world` table and state."""
        from types import SimpleNamespace

        from isaac.engine.energy_check import EnergyCheck

        w = first.world
        # a body's bounding radius (m): its farthest vertex, or a circle's radius
        radius = np.maximum(
            np.max(np.hypot(*np.moveaxis(w.vertices_local, -1, 0)), axis=1), w.circle_radius
        )
        model = SimpleNamespace(mass=w.mass, inertia=w.inertia, concrete=w.concrete, radius=radius)
        motors = any(j.get("motor") for j in w.joints)
        g = self.settings.get("gravity", (0.0, 0.0))
        start = first.stats["total_energy"]
        check = EnergyCheck.of(model, first.record, g, start, motors=motors)
        check.add(totals, entered)
        return check


def _settings(path: str, metadata: dict) -> tuple[dict, float]:
    """The ``isaac`` metadata's world settings (a JSON object) and dt (finite, > 0)."""
    try:
        settings = json.loads(metadata["settings"])
        dt = float(metadata["dt"])
    except KeyError as exc:
        raise LogError(f"{path}: damaged log: no {exc} in the '{META_START}' metadata") from None
    except (ValueError, RecursionError) as exc:
        why = "too deeply nested" if isinstance(exc, RecursionError) else exc
        raise LogError(f"{path}: damaged log: bad '{META_START}' metadata ({why})") from None
    if not isinstance(settings, dict):
        raise LogError(
            f"{path}: damaged log: the '{META_START}' metadata's settings are "
            f"{type(settings).__name__}, not a JSON object"
        )
    if not (math.isfinite(dt) and dt > 0):
        raise LogError(f"{path}: damaged log: the '{META_START}' metadata's dt is {dt!r}")
    return settings, dt


class Recovered(tuple):
    """What `recover` wrote: (steps kept, the last of them); ``lost`` says what it could not
    salvage (None when it kept everything the source claimed); ``restated``, what it rewrote
    from the embedded scene (the ``isaac`` metadata that disagreed with it), or None."""

    lost: str | None
    restated: str | None

    def __new__(
        cls, kept: int, last: int | None, lost: str | None, restated: str | None = None
    ) -> Recovered:
        self = super().__new__(cls, (kept, last))
        self.lost = lost
        self.restated = restated
        return self

    @property
    def kept(self) -> int:
        return self[0]

    @property
    def last(self) -> int | None:
        return self[1]


def recover(src: str, dst: str) -> Recovered:
    """Rewrite the readable part of ``src`` (e.g. a ``.partial`` file) as a clean, indexed MCAP.

    Keeps the metadata, the scene attachment, and every step up to the first damage or the end
    (complete steps, one after another: `recorder.integrity.StepReader`); messages are copied
    byte for byte. Writes ``dst.partial`` then renames. LogError if no complete step is left,
    or if a step's messages do not decode or fit together (`LogReader.steps`: a damaged log
    whose chunks are intact; copying it would pass the damage on).
    """
    log = LogReader(src)
    for _ in log.steps():
        pass
    reader = log._reader
    first, last, damage = reader.first, reader.last, reader.damage
    if last is None:
        why = f" (damaged log: {damage})" if damage is not None else ""
        raise LogError(f"{src}: no complete step to recover{why}")
    lost = _lost(reader)
    # the metadata that disagrees with the embedded scene (itself intact: it loads and matches
    # its sha256) is written as the recorder writes it from that scene
    header = log.header_damage
    restated = None if header is None or log._scene is None else header.what
    # the same chunk compression as the source's first chunk
    chunks = reader.scan.chunks
    compression = (chunks[0].compression if chunks else "") or "none"
    tmp = str(dst) + ".partial"
    if os.path.abspath(tmp) == os.path.abspath(src):
        tmp = str(dst) + ".recovering"
    try:
        out = open(tmp, "wb")
    except OSError as exc:
        raise LogError(f"cannot write {tmp}: {exc.strerror}") from exc
    try:
        with out:
            writer = Writer(
                out,
                chunk_size=256 * 1024,
                compression=_COMPRESSION.get(compression, CompressionType.NONE),
            )
            header = log.header
            writer.start(
                profile=header.profile if header else "isaac",
                library=header.library if header else "isaac-recorder",
            )
            # metadata and attachments first, as the writer puts them
            for record in log._header_records:
                if isinstance(record, Metadata):
                    values = dict(record.metadata)
                    if record.name == META_START and restated is not None:
                        values = log.restated_metadata()
                    writer.add_metadata(record.name, values)
                else:
                    writer.add_attachment(
                        record.create_time,
                        record.log_time,
                        record.name,
                        record.media_type,
                        record.data,
                    )
            count = _copy_steps(src, writer, first, last)
            end = reader.end if (lost is None and reader.end is not None) else None
            if end is not None and end.get("complete") != "true" and not end.get("stopped_at"):
                # a writer that outlived its run noted no step: "stopped at" is the last step
                # in the log, as everywhere (isaac inspect, isaac run)
                end = {**end, "stopped_at": "" if last is None else str(last)}
            if end is None:
                end = end_metadata(
                    complete=False,
                    steps=count,
                    last_step=last,
                    stopped_at=last,
                    reason="recovered from a log that was not closed"
                    if lost is None or not log.closed_cleanly
                    else f"recovered from a damaged log: {lost}",
                )
                end["recovered"] = "true"
            writer.add_metadata(META_END, end)
            writer.finish()
    except BaseException as exc:
        # never leave a half-written copy behind
        out.close()
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(exc, OSError):
            raise LogError(f"cannot write {tmp}: {exc.strerror or exc}") from None
        raise
    try:
        os.replace(tmp, dst)
    except OSError as exc:
        os.unlink(tmp)
        raise LogError(f"cannot write {dst}: {exc.strerror or exc}") from None
    return Recovered(count, last, lost, restated)


# a recovered copy's chunk compression, from the source's name of it
_COMPRESSION = {"lz4": CompressionType.LZ4, "zstd": CompressionType.ZSTD}


def _lost(reader: StepReader) -> str | None:
    """What `recover` cannot salvage, in one line (None: nothing)."""
    parts = []
    if reader.damage is not None and reader.damage.step is None:
        parts.append(f"{reader.damage} (every complete step read was kept)")
    elif reader.damage is not None:
        parts.append(f"{reader.damage.at()} and after: {reader.damage}")
    elif reader.tail is not None:
        parts.append(f"step {reader.tail}, only partly written")
    if not reader.closed:
        parts.append("the log was not closed, so steps after its last chunk may be missing")
    claimed = reader.claimed_steps
    if claimed is not None and reader.closed and reader.count < claimed:
        parts.append(f"{claimed - reader.count} of the {claimed} steps it claims")
    return "; ".join(parts) or None


def _copy_steps(src: str, writer: Writer, first: int, last: int) -> int:
    """Copy every message of steps ``first..last`` (in file order, up to where the step
    sequence stops rising) into ``writer``; returns the number of ``/stats`` messages copied."""
    f, size = open_log(src)
    schema_ids: dict[int, int] = {}
    channel_ids: dict[int, int] = {}
    count = 0
    previous = first
    with f:
        scan = McapScan(f, size)
        try:
            for msg in scan.messages():
                if not previous <= msg.sequence <= last:
                    break
                previous = msg.sequence
                cid = msg.channel_id
                if cid not in channel_ids:
                    channel = scan.channels.get(cid)
                    if channel is None:
                        continue
                    schema = scan.schemas.get(channel.schema_id)
                    if schema is not None and schema.id not in schema_ids:
                        schema_ids[schema.id] = writer.register_schema(
                            schema.name, schema.encoding, schema.data
                        )
                    channel_ids[cid] = writer.register_channel(
                        channel.topic,
                        channel.message_encoding,
                        schema_ids.get(channel.schema_id, 0),
                        dict(channel.metadata),
                    )
                writer.add_message(
                    channel_ids[cid], msg.log_time, bytes(msg.data), msg.publish_time, msg.sequence
                )
                if scan.channels[cid].topic == "/stats":
                    count += 1
        except RecordError:
            pass  # where the first pass stopped too: every step up to `last` was before it
    return count
