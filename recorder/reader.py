"""Read an ISAAC MCAP log back: metadata, the embedded scene, and every step as numpy arrays.

Used by ``isaac inspect`` / ``isaac recover`` / ``isaac view`` and by the replay package::

    log = LogReader("run.mcap")          # raises LogError if not a readable ISAAC log
    log.metadata                         # dict[str, str]: the `isaac` metadata (versions, settings)
    log.settings                         # dict: every world setting (JSON-decoded), log.dt
    log.scene_text                       # str: the expanded scene YAML (attachment scene.yaml)
    log.scene()                          # isaac.scene.Scene loaded from it
    log.world                            # WorldTable at step 0 (same names as Simulation.model)
    log.closed_cleanly                   # bool: footer + summary present (False for .partial)
    log.end                              # dict | None: the `isaac.end` metadata (complete, reason)
    for s in log.steps():                # LoggedStep(record: StepRecord, stats: dict, world)
        s.record.position, s.record.contacts.impulse, s.stats["state_hash"]
    log.step(k)                          # one LoggedStep (LogError if absent)
    log.summary()                        # LogSummary: counts, extremes, energies

The file is read sequentially with MCAP's stream reader, so a file that was never closed (a run
killed with SIGKILL, a file cut short) yields every step in its complete chunks: the read stops
quietly at the first damaged record (``log.damage`` then says what was wrong). A step counts only
when its ``/bodies`` and ``/contacts`` messages are both there.
"""

from __future__ import annotations

import io
import json
import os
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np
from mcap.exceptions import McapError
from mcap.records import Attachment, Channel, Header, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import Writer

from isaac.engine.records import Contacts, StepRecord
from isaac.errors import LogError
from recorder import schema as S
from recorder.mcap_writer import (
    COMPRESSION,
    FORMAT_NAME,
    META_END,
    META_START,
    SCENE_ATTACHMENT,
    end_metadata,
)

MCAP_MAGIC = b"\x89MCAP0\r\n"


@dataclass(frozen=True, eq=False)
class WorldTable:
    """The `/world` message as arrays, named like `Simulation.model`.

    step: the step from which this table holds.
    names: list of body names; vertices_local: (n, V, 2) m, body frame about the centre of mass,
    padded with zeros past ``vertex_count``; mass (kg), inertia (kg m^2), restitution, friction:
    (n,) float64; concrete, exists: (n,) bool.
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

    @staticmethod
    def from_message(msg: dict) -> WorldTable:
        bodies = sorted(msg["bodies"], key=lambda b: b["index"])
        n = len(bodies)
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
        )


@dataclass(frozen=True, eq=False)
class LoggedStep:
    """One step read back: the record (state after the step + its contacts), its `/stats`
    values (dict, or None if missing) and the `/world` table in force at that step."""

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


def record_from_messages(bodies: dict, contacts: dict) -> StepRecord:
    """A StepRecord from decoded `/bodies` and `/contacts` messages (arrays are read-only views)."""
    n = bodies["angle"].size
    return StepRecord(
        step=int(bodies["step"]),
        time=float(bodies["time"]),
        position=bodies["position"].reshape(n, 2),
        angle=bodies["angle"],
        velocity=bodies["velocity"].reshape(n, 2),
        angular_velocity=bodies["angular_velocity"],
        exists=bodies["exists"] if bodies["exists"].size == n else np.ones(n, dtype=bool),
        contacts=contacts_from_message(contacts),
    )


def contacts_from_message(msg: dict) -> Contacts:
    m = msg["a"].size

    def i32(k):
        return msg[k].astype(np.int32) if msg[k].size == m else np.zeros(m, np.int32)

    def f(k):
        return msg[k] if msg[k].size == m else np.zeros(m)

    def v(k):
        return msg[k].reshape(m, 2) if msg[k].size == 2 * m else np.zeros((m, 2))

    return Contacts(
        substep=i32("substep"),
        a=i32("a"),
        b=i32("b"),
        feature=i32("feature"),
        slot=i32("slot"),
        point=v("point"),
        normal=v("normal"),
        depth=f("depth"),
        push_a=v("push_a"),
        push_b=v("push_b"),
        impulse=f("impulse"),
        tangent_impulse=f("tangent_impulse"),
        restitution=f("restitution"),
    )


class LogReader:
    """A readable ISAAC MCAP log (clean or not). See the module docstring for the API."""

    def __init__(self, path: str) -> None:
        self.path = str(path)
        try:
            self.size = os.path.getsize(self.path)
            with open(self.path, "rb") as f:
                head = f.read(len(MCAP_MAGIC))
        except OSError as exc:
            raise LogError(f"{self.path}: {exc.strerror or exc}") from exc
        if head != MCAP_MAGIC:
            what = "empty file" if self.size == 0 else "not an MCAP file"
            raise LogError(f"{self.path}: {what}")
        self.header: Header | None = None
        self.metadata: dict[str, str] = {}
        self.attachments: dict[str, bytes] = {}
        self._end: dict[str, str] | None = None
        self._scanned = False
        self.damage: str | None = None
        # metadata and the scene come before the first chunk: read only that far
        for record in self._records(emit_chunks=True):
            if isinstance(record, Header):
                self.header = record
            elif isinstance(record, Metadata) and record.name == META_START:
                self.metadata = dict(record.metadata)
            elif isinstance(record, Attachment):
                self.attachments[record.name] = record.data
            elif not isinstance(record, (Metadata, Schema, Channel)):
                break
        if self.metadata.get("format") != FORMAT_NAME:
            raise LogError(f"{self.path}: not an ISAAC log (no '{META_START}' metadata)")
        if SCENE_ATTACHMENT not in self.attachments:
            raise LogError(f"{self.path}: the log has no {SCENE_ATTACHMENT} attachment")
        try:
            self.settings = json.loads(self.metadata["settings"])
            self.dt = float(self.metadata["dt"])
        except (KeyError, ValueError) as exc:
            raise LogError(f"{self.path}: bad '{META_START}' metadata ({exc})") from exc
        self.closed_cleanly = self._has_footer()
        self._world0: WorldTable | None = None

    # -- raw records ---------------------------------------------------------------------------

    def _records(self, *, emit_chunks: bool = False) -> Iterator:
        """Every MCAP record in file order; stops quietly at the first damaged one."""
        with open(self.path, "rb") as f:
            reader = StreamReader(
                f, emit_chunks=emit_chunks, validate_crcs=True, record_size_limit=max(self.size, 1)
            )
            it = reader.records
            while True:
                try:
                    record = next(it)
                except StopIteration:
                    return
                except (McapError, ValueError, EOFError, RuntimeError, OSError) as exc:
                    # the end of what is readable (a cut or unfinished file, a bad CRC)
                    self.damage = f"{type(exc).__name__} at byte {f.tell()}"
                    return
                except Exception as exc:  # noqa: BLE001 - decompressor errors vary by library
                    self.damage = f"{type(exc).__name__} at byte {f.tell()}"
                    return
                yield record

    def _has_footer(self) -> bool:
        """True when the file ends with a footer and the magic (it was finished)."""
        if self.size < 2 * len(MCAP_MAGIC) + 29:
            return False
        with open(self.path, "rb") as f:
            f.seek(-len(MCAP_MAGIC), io.SEEK_END)
            if f.read() != MCAP_MAGIC:
                return False
            f.seek(-(len(MCAP_MAGIC) + 29), io.SEEK_END)
            return f.read(1) == b"\x02"  # footer opcode

    def messages(self, topics=None) -> Iterator[tuple[str, Message, dict]]:
        """(topic, raw MCAP message, decoded dict) in file order, for ``topics`` (all if None)."""
        channels: dict[int, str] = {}
        want = None if topics is None else set([topics] if isinstance(topics, str) else topics)
        for record in self._records():
            if isinstance(record, Channel):
                channels[record.id] = record.topic
            elif isinstance(record, Message):
                topic = channels.get(record.channel_id)
                if topic not in S.TOPICS or (want is not None and topic not in want):
                    continue
                try:
                    decoded = S.decode(S.TOPICS[topic], record.data)
                except (S.WireError, UnicodeDecodeError) as exc:
                    raise LogError(
                        f"{self.path}: step {record.sequence}: bad {topic} message ({exc})"
                    ) from exc
                yield topic, record, decoded
            elif isinstance(record, Metadata) and record.name == META_END:
                self._end = dict(record.metadata)

    # -- steps ---------------------------------------------------------------------------------

    def steps(self) -> Iterator[LoggedStep]:
        """Every complete step in order (state, contacts, stats and the `/world` in force)."""
        world: WorldTable | None = None
        pending: dict = {}
        current = None

        def emit():
            if "/bodies" in pending and "/contacts" in pending and world is not None:
                return LoggedStep(
                    record_from_messages(pending["/bodies"], pending["/contacts"]),
                    pending.get("/stats"),
                    world,
                )
            return None

        for topic, message, decoded in self.messages():
            if current is not None and message.sequence != current:
                done = emit()
                if done is not None:
                    yield done
                pending = {}
            current = message.sequence
            if topic == "/world":
                world = WorldTable.from_message(decoded)
                if self._world0 is None:
                    self._world0 = world
            else:
                pending[topic] = decoded
        if current is not None and "/stats" in pending:
            # the last step counts only if it was written completely (stats come last)
            done = emit()
            if done is not None:
                yield done
        self._scanned = True

    def step(self, k: int) -> LoggedStep:
        """The logged step ``k`` (LogError if the log does not hold it)."""
        for s in self.steps():
            if s.step == k:
                return s
            if s.step > k:
                break
        raise LogError(f"{self.path}: step {k} is not in the log")

    @property
    def world(self) -> WorldTable:
        """The `/world` table of step 0."""
        if self._world0 is None:
            for _topic, _message, decoded in self.messages("/world"):
                self._world0 = WorldTable.from_message(decoded)
                break
        if self._world0 is None:
            raise LogError(f"{self.path}: the log holds no /world message")
        return self._world0

    @property
    def scene_text(self) -> str:
        """The expanded scene YAML the run used (attachment ``scene.yaml``)."""
        return self.attachments[SCENE_ATTACHMENT].decode("utf-8")

    def scene(self):
        """The run's `isaac.scene.Scene`, loaded from the embedded ``scene.yaml``."""
        from isaac.scene import load_scene_text

        return load_scene_text(self.scene_text, f"{self.path}:{SCENE_ATTACHMENT}")

    @property
    def end(self) -> dict | None:
        """The ``isaac.end`` metadata (complete, steps_written, last_step, stopped_at, reason),
        or None if the file was never closed."""
        if self._end is None and not self._scanned:
            for record in self._records(emit_chunks=True):
                if isinstance(record, Metadata) and record.name == META_END:
                    self._end = dict(record.metadata)
            self._scanned = True
        return self._end

    @property
    def complete(self) -> bool:
        """True when the run finished all its steps and the file was closed."""
        end = self.end
        return bool(self.closed_cleanly and end is not None and end.get("complete") == "true")

    def summary(self) -> LogSummary:
        """Counts and extremes over every readable step (one pass over the file)."""
        s = LogSummary()
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
            if logged.stats is not None:
                if s.energy_start is None:
                    s.energy_start = logged.stats["total_energy"]
                s.energy_end = logged.stats["total_energy"]
            if logged.world.step == r.step:
                s.world_changes += 1
        return s


def recover(src: str, dst: str) -> tuple[int, int | None]:
    """Rewrite the readable part of ``src`` (e.g. a ``.partial`` file) as a clean, indexed MCAP.

    Keeps the metadata, the scene attachment, and every complete step (a step whose
    ``/bodies``, ``/contacts`` and ``/stats`` are all present); messages are copied byte for
    byte. Writes ``dst.partial`` then renames. Returns (steps kept, last step kept).
    """
    log = LogReader(src)
    complete_steps: set[int] = set()
    seen: dict[int, set] = {}
    channels: dict[int, str] = {}
    for record in log._records():
        if isinstance(record, Channel):
            channels[record.id] = record.topic
        elif isinstance(record, Message):
            seen.setdefault(record.sequence, set()).add(channels.get(record.channel_id))
    for step, topics in seen.items():
        if {"/bodies", "/contacts", "/stats"} <= topics:
            complete_steps.add(step)
    last = max(complete_steps) if complete_steps else None
    # the same chunk compression as the source's first chunk
    compression = "none"
    for record in log._records(emit_chunks=True):
        if type(record).__name__ == "Chunk":
            compression = record.compression or "none"
            break
    tmp = str(dst) + ".partial"
    if os.path.abspath(tmp) == os.path.abspath(src):
        tmp = str(dst) + ".recovering"
    try:
        out = open(tmp, "wb")
    except OSError as exc:
        raise LogError(f"cannot write {tmp}: {exc.strerror}") from exc
    with out:
        writer = Writer(
            out,
            chunk_size=256 * 1024,
            compression=COMPRESSION.get(compression, COMPRESSION["none"]),
        )
        header = log.header
        writer.start(
            profile=header.profile if header else "isaac",
            library=header.library if header else "isaac-recorder",
        )
        schema_ids: dict[int, int] = {}
        channel_ids: dict[int, int] = {}
        end = None
        # metadata and attachments first, as the writer puts them
        for record in log._records(emit_chunks=True):
            if isinstance(record, Metadata):
                if record.name == META_END:
                    end = dict(record.metadata)
                else:
                    writer.add_metadata(record.name, dict(record.metadata))
            elif isinstance(record, Attachment):
                writer.add_attachment(
                    record.create_time, record.log_time, record.name, record.media_type, record.data
                )
        count = 0
        for record in log._records():
            if isinstance(record, Schema) and record.id not in schema_ids:
                schema_ids[record.id] = writer.register_schema(
                    record.name, record.encoding, record.data
                )
            elif isinstance(record, Channel) and record.id not in channel_ids:
                channel_ids[record.id] = writer.register_channel(
                    record.topic,
                    record.message_encoding,
                    schema_ids.get(record.schema_id, 0),
                    dict(record.metadata),
                )
            elif isinstance(record, Message):
                if record.sequence in complete_steps or (
                    channels.get(record.channel_id) == "/world"
                    and last is not None
                    and record.sequence <= last
                ):
                    writer.add_message(
                        channel_ids[record.channel_id],
                        record.log_time,
                        record.data,
                        record.publish_time,
                        record.sequence,
                    )
                    if channels.get(record.channel_id) == "/stats":
                        count += 1
        if end is None or not log.closed_cleanly:
            end = end_metadata(
                complete=False,
                steps=count,
                last_step=last,
                stopped_at=None if last is None else last + 1,
                reason="recovered from a log that was not closed",
            )
            end["recovered"] = "true"
        writer.add_metadata(META_END, end)
        writer.finish()
    os.replace(tmp, dst)
    return count, last
