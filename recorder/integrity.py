"""Whether a log holds every step it claims, each one whole: the check behind every verdict.

A step is complete when its ``/bodies``, ``/contacts`` and ``/stats`` messages are all there
(``/world`` too at the log's first step). The recorder writes steps one after another, so in a
sound log each step's messages follow the previous step's, with no step missing, repeated or out
of order. `StepReader` walks a log once (`recorder.mcap_records.McapScan`: bounded, every chunk
CRC-checked) and hands out its complete steps in order, checking each against the one before in
O(1): the step index it expects next and the topics seen so far at this step. The first problem
ends the walk and is kept as a `Damage` (what, the first step not read whole and intact, the
byte offset where reading stopped).

What a log claims:
- a cleanly closed log (footer and summary): its ``isaac.end`` metadata (``steps_written``,
  ``last_step``: recorder/mcap_writer.py), the summary's statistics (messages per channel,
  chunk count), its chunk indexes (where each chunk starts, its sizes, compression and times),
  its metadata index and the footer's summary CRC. After the walk all of it is compared with
  what was read (`check_claims`); the first disagreement is a `Damage` too. So is what a seeking
  reader trusts instead of the data: the MessageIndex records after each chunk (checked as the
  chunk is read: `McapScan.index_error`), the statistics' other counts and times, the attachment
  and metadata indexes, the summary's schemas and channels, and its summary offsets;
- a log never closed (a ``.partial`` left by a crash): only what its readable chunks hold; with
  no summary it cannot prove that nothing is missing after its last step (``complete`` False).

The embedded scene (``scene.yaml``, checked against its recorded sha256) is what a replay
re-simulates from: every other copy of what it says, in the ``isaac`` metadata (``settings``,
each ``world.<key>``, ``dt``, ``gravity``, ``bodies``, ``scene_name``), must be what the recorder
writes from it (`check_metadata`).
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass

from recorder.mcap_records import (
    OP_FOOTER,
    OP_SUMMARY_OFFSET,
    McapScan,
    RecordError,
    open_log,
)
from recorder.mcap_writer import META_END, META_START, build_metadata

# the `isaac` metadata keys that restate the embedded scene (recorder.mcap_writer.build_metadata);
# the rest (versions, machine) say where the log was made and have nothing to be checked against
SCENE_KEYS = ("scene_name", "scene_attachment", "bodies", "dt", "gravity", "log_time")
SETTING_PREFIX = "world."

STEP_TOPICS = ("/bodies", "/contacts", "/stats")
# /joints (a scene with joints only) is read with the step; written before /stats, it is there
# whenever /stats is
TOPICS = ("/world",) + STEP_TOPICS + ("/joints",)

# the RecordError of a file that stops at a record boundary: what a crash leaves at the end of
# a .partial log, not damage (a file cut inside a record is: part of a record is lost)
_CLEAN_END = "the file ends without a footer"


@dataclass(frozen=True)
class Damage:
    """The first thing wrong with a log.

    what: one line. step: the first step not read whole and intact (None when unknown: then
    ``offset`` says where). offset: byte offset (from the file's start) of the record where
    reading stopped or that disagrees, or None.
    """

    what: str
    step: int | None = None
    offset: int | None = None

    def __str__(self) -> str:
        return self.what + ("" if self.offset is None else f", at byte {self.offset}")

    def at(self) -> str:
        """``step K`` or ``byte N``: where the damage starts, for a verdict line."""
        if self.step is not None:
            return f"step {self.step}"
        return "byte ?" if self.offset is None else f"byte {self.offset}"


class StepReader:
    """Every complete step of one log, in file order, checked as it goes (`steps`).

    closed: the file ends with a footer (`LogReader.closed_cleanly`); then, after `steps` has
    run to its end, the whole is checked against the log's claims (module docstring).

    After `steps` ends: ``damage`` (Damage or None), ``ended`` (the walk reached the end of the
    file, or the first damage, rather than being stopped by its consumer), ``complete`` (every
    step the log claims was read whole: closed, no damage), ``first``/``last``/``count`` of the
    complete steps handed out, ``tail`` (a not-closed log's last step, only partly written),
    ``seen`` (steps with at least one message), ``end`` (the ``isaac.end`` metadata),
    ``claimed_steps``/``claimed_last`` (what the log claims: from ``isaac.end`` for a closed
    log, the steps its readable chunks hold otherwise), and ``scan`` (the record walk, with the
    channels and schemas it met).
    """

    def __init__(self, path: str, *, closed: bool) -> None:
        self.path = str(path)
        self.closed = closed
        self.damage: Damage | None = None
        self.ended = False
        self.first: int | None = None
        self.last: int | None = None
        self.count = 0
        self.tail: int | None = None
        self.seen = 0
        self.end: dict | None = None
        self.claimed_steps: int | None = None
        self.claimed_last: int | None = None
        self.scan: McapScan | None = None

    @property
    def complete(self) -> bool:
        return self.ended and self.closed and self.damage is None

    def _next(self) -> int | None:
        return None if self.last is None else self.last + 1

    def steps(self) -> Iterator[tuple[int, dict]]:
        """(step, {topic: payload memoryview}) for each complete step (module docstring)."""
        f, size = open_log(self.path)
        scan = self.scan = McapScan(f, size)
        step: int | None = None
        messages: dict = {}
        error: RecordError | None = None
        topics = scan.channels
        try:
            try:
                for msg in scan.messages():
                    channel = topics.get(msg.channel_id)
                    topic = channel.topic if channel is not None else None
                    if topic not in TOPICS:
                        continue
                    sequence = msg.sequence
                    if sequence == step:
                        if topic in messages:
                            self.damage = Damage(
                                f"step {step} has two {topic} messages", step, msg.offset
                            )
                            break
                        messages[topic] = msg.data
                        continue
                    if step is not None:
                        if not self._whole(step, messages, msg.offset):
                            break
                        yield step, messages
                    expected = self._next()
                    if expected is not None and sequence != expected:
                        self.damage = Damage(self._gap(expected, sequence), expected, msg.offset)
                        break
                    step, messages = sequence, {topic: msg.data}
                    self.seen += 1
            except RecordError as exc:
                error = exc
            if self.damage is None and step is not None:
                # the last step: no later message closed it
                if error is None:
                    if self._whole(step, messages, None):
                        yield step, messages
                elif all(t in messages for t in STEP_TOPICS):
                    if self._first_ok(step, messages, None):
                        self._accept(step)
                        yield step, messages
                else:
                    self.tail = step  # only partly written where reading stopped
            if self.damage is None:
                if error is None:
                    self.closed = True  # the walk reached the footer at the file's end
                    self.damage = check_claims(scan, self)
                elif self.closed or not error.what.startswith(_CLEAN_END):
                    # anything but a .partial that simply stops after its last record; past
                    # the data section's end every step was read: the damage is a byte's
                    step_at = None if scan.data_end is not None else self._next()
                    self.damage = Damage(error.what, step_at, error.offset)
            self.ended = True
            self._claims(scan)
        finally:
            f.close()

    def _gap(self, expected: int, sequence: int) -> str:
        if sequence < expected:
            return f"step {sequence} comes after step {self.last} (steps out of order or repeated)"
        missing = (
            f"step {expected} is"
            if sequence == expected + 1
            else (f"steps {expected}..{sequence - 1} are")
        )
        return f"{missing} missing (step {sequence} follows step {self.last})"

    def _first_ok(self, step: int, messages: dict, offset: int | None) -> bool:
        if self.last is None and "/world" not in messages:
            self.damage = Damage(
                f"the log's first step, {step}, has no /world message (its start is missing)",
                step,
                offset,
            )
            return False
        return True

    def _whole(self, step: int, messages: dict, offset: int | None) -> bool:
        """Accept ``step`` if it is complete (else keep the damage): True when accepted."""
        missing = [t for t in STEP_TOPICS if t not in messages]
        if missing:
            self.damage = Damage(
                f"step {step} has no {' and no '.join(missing)} message", step, offset
            )
            return False
        if not self._first_ok(step, messages, offset):
            return False
        self._accept(step)
        return True

    def _accept(self, step: int) -> None:
        if self.first is None:
            self.first = step
        self.last = step
        self.count += 1

    def _claims(self, scan: McapScan) -> None:
        """What the log claims, for the report: its isaac.end (read from the summary when the
        walk stopped short of it; a never-closed log has one when its writer outlived the run
        and noted where it stopped), else the steps its readable chunks hold."""
        if self.end is None:
            if self.closed and self.damage is not None and not scan.read_rest():
                scan.read_summary()
            self.end = _end_metadata(scan)
        written, last = _parse_end(self.end) if self.end is not None else (None, None)
        if written is None:
            if not self.closed:
                self.claimed_steps = self.seen
                self.claimed_last = self.last if self.tail is None else self.tail
            return
        self.claimed_steps, self.claimed_last = written, last
        if not self.closed and self.damage is None and (self.count, self.last) != (written, last):
            held = "none" if not self.count else f"{self.count} ({self.first}..{self.last})"
            self.damage = Damage(
                f"its {META_END} metadata says {written} steps were written; it holds {held}",
                self._next() if self.count < written else None,
            )
        if self.damage is not None and self.damage.step is None and not self.count:
            if written and self.damage.offset is not None:
                # nothing was read: the damage starts at the first step claimed
                self.damage = Damage(self.damage.what, last - written + 1, self.damage.offset)


def _end_metadata(scan: McapScan) -> dict | None:
    ends = [m for _o, m in scan.metadata if m.name == META_END]
    return dict(ends[-1].metadata) if ends else None


def _parse_end(end: dict) -> tuple[int | None, int | None]:
    """(steps_written, last_step) of ``isaac.end``, or (None, None) if malformed."""
    try:
        written = int(end.get("steps_written", ""))
        last_text = end.get("last_step", "")
        last = int(last_text) if last_text != "" else None
    except ValueError:
        return None, None
    if written < 0 or (written == 0) != (last is None) or (last is not None and last < 0):
        return None, None
    if last is not None and last - written + 1 < 0:
        return None, None
    return written, last


def _first_unheld(written: int, last: int | None, first_held, last_held) -> int | None:
    """The first step the log claims but does not hold, else the first it holds unclaimed."""
    if not written:
        return first_held
    first = last - written + 1
    if first_held is None or first_held > first:
        return first
    if last_held < last:
        return last_held + 1
    return first_held if first_held < first else last + 1


def check_claims(scan: McapScan, reader: StepReader) -> Damage | None:
    """The first disagreement between what a closed log claims and what was read, or None."""
    ends = [(o, m) for o, m in scan.metadata if m.name == META_END]
    if not ends:
        return Damage(f"the log was closed without its {META_END} metadata", None, scan.data_end)
    if len(ends) > 1:
        return Damage(f"the log holds {len(ends)} {META_END} records", None, ends[1][0])
    end_offset, end_record = ends[0]
    reader.end = dict(end_record.metadata)
    written, last = _parse_end(reader.end)
    if written is None:
        return Damage(
            f"its {META_END} metadata is malformed (steps_written "
            f"{reader.end.get('steps_written')!r}, last_step {reader.end.get('last_step')!r})",
            None,
            end_offset,
        )
    if (reader.count, reader.last) != (written, last) or (
        written and reader.first != last - written + 1
    ):
        claimed = "no step" if not written else f"{written} steps ({last - written + 1}..{last})"
        held = "none" if not reader.count else f"{reader.count} ({reader.first}..{reader.last})"
        return Damage(
            f"the log claims {claimed} and holds {held}",
            _first_unheld(written, last, reader.first, reader.last),
            end_offset,
        )
    if scan.index_error is not None:
        return Damage(scan.index_error.what, None, scan.index_error.offset)
    stats = scan.statistics
    if stats is None:
        return Damage("the log's summary has no statistics record", None, scan.footer_offset)
    times = [(c.message_start_time, c.message_end_time) for c in scan.chunks]
    counted = (
        (
            ("schemas", stats.schema_count, len(scan.schemas)),
            ("channels", stats.channel_count, len(scan.channels)),
            ("attachments", stats.attachment_count, len(scan.attachments)),
            ("metadata records", stats.metadata_count, len(scan.metadata)),
            ("as its first message time", stats.message_start_time, min(t[0] for t in times)),
            ("as its last message time", stats.message_end_time, max(t[1] for t in times)),
        )
        if times
        else ()
    )
    for name, said, read in counted:
        if said != read:
            return Damage(
                f"the summary's statistics count {said} {name}, the file holds {read}"
                if not name.startswith("as ")
                else f"the summary's statistics give {said} {name}, the file {read}",
                None,
                scan.footer_offset,
            )
    if stats.chunk_count != len(scan.chunks):
        return Damage(
            f"the summary counts {stats.chunk_count} chunks, the file holds {len(scan.chunks)}",
            None,
            scan.footer_offset,
        )
    names = {cid: ch.topic for cid, ch in {**scan.summary_channels, **scan.channels}.items()}
    for cid in sorted(set(stats.channel_message_counts) | set(scan.counts)):
        said, read = stats.channel_message_counts.get(cid, 0), scan.counts.get(cid, 0)
        if said != read:
            topic = names.get(cid, f"channel {cid}")
            return Damage(
                f"the summary counts {said} {topic} messages, the file holds {read}",
                None,
                scan.footer_offset,
            )
    if stats.message_count != scan.messages_read:
        return Damage(
            f"the summary counts {stats.message_count} messages, the file holds "
            f"{scan.messages_read}",
            None,
            scan.footer_offset,
        )
    if len(scan.chunk_indexes) != len(scan.chunks):
        return Damage(
            f"the summary indexes {len(scan.chunk_indexes)} chunks, the file holds "
            f"{len(scan.chunks)}",
            None,
            scan.footer_offset,
        )
    index = {ci.chunk_start_offset: ci for ci in scan.chunk_indexes}
    for k, chunk in enumerate(scan.chunks):
        ci = index.get(chunk.offset)
        if ci is None:
            return Damage("a chunk the summary's index does not list", None, chunk.offset)
        fields = (
            ("length", ci.chunk_length, chunk.length),
            ("compression", ci.compression, chunk.compression),
            ("compressed size", ci.compressed_size, chunk.compressed_size),
            ("uncompressed size", ci.uncompressed_size, chunk.uncompressed_size),
            ("first message time", ci.message_start_time, chunk.message_start_time),
            ("last message time", ci.message_end_time, chunk.message_end_time),
            ("message index offsets", ci.message_index_offsets, scan.message_indexes[k]),
            ("message index length", ci.message_index_length, scan.message_index_lengths[k]),
        )
        for name, indexed, actual in fields:
            if indexed != actual:
                return Damage(
                    f"a chunk whose {name} ({actual}) is not the one its index gives ({indexed})",
                    None,
                    chunk.offset,
                )
    if not any(mi.name == META_END and mi.offset == end_offset for mi in scan.metadata_indexes):
        return Damage(
            f"the summary's metadata index does not point at the {META_END} record",
            None,
            scan.footer_offset,
        )
    damage = _check_summary_indexes(scan)
    if damage is not None:
        return damage
    footer = scan.footer
    if footer.summary_start != (scan.first_summary_offset or 0):
        return Damage("the footer does not point at the summary's start", None, scan.footer_offset)
    if scan.summary_crc_ok() is False:
        return Damage(
            "the summary's CRC does not match its bytes (corrupt)", None, footer.summary_start
        )
    return None


def _settings_keys(metadata: dict) -> dict:
    """setting -> its ``world.<setting>`` value (JSON text)."""
    n = len(SETTING_PREFIX)
    return {k[n:]: v for k, v in metadata.items() if k.startswith(SETTING_PREFIX)}


def check_metadata(
    metadata: dict, scene, scene_text: str, n_bodies: int
) -> tuple[str | None, list[str]]:
    """Whether the ``isaac`` metadata says what the embedded scene says: (the first value that
    disagrees, in one line, or None; notes).

    ``scene`` is the `isaac.scene.Scene` loaded from ``scene_text`` (the attachment, whose sha256
    the caller has checked) and ``n_bodies`` its body count. Expected is what
    `recorder.mcap_writer.build_metadata` writes from it: `SCENE_KEYS` and every setting,
    in ``settings`` (one JSON object) and in ``world.<key>`` (one JSON value each), byte for
    byte. The two copies of the settings must list the same settings and agree with each other
    and with the scene; a setting that only this version knows, or only the log's (a log of
    another version), is a note, not damage.
    """
    expected = build_metadata(scene, scene_text, n_bodies)
    what = f"the '{META_START}' metadata"
    for key in SCENE_KEYS:
        if metadata.get(key) != expected[key]:
            return (
                f"{what} says {key} {metadata.get(key)!r}, the embedded scene "
                f"{expected[key]!r} (edited or corrupt)",
                [],
            )
    try:
        logged = json.loads(metadata.get("settings", ""))
    except (ValueError, RecursionError):
        logged = None
    if not isinstance(logged, dict):
        return f"{what}'s settings are not a JSON object", []
    flat, ours = _settings_keys(metadata), _settings_keys(expected)
    if set(flat) != set(logged):
        only = sorted(set(flat) ^ set(logged))
        return (
            f"{what} lists other settings in settings than as world.<key> "
            f"({', '.join(only[:5])}: edited or corrupt)",
            [],
        )
    for key in sorted(logged):
        # each copy against the scene; a setting this version does not know, copy against copy
        text = json.dumps(logged[key])
        truth, source = (ours[key], "the embedded scene") if key in ours else (text, "settings")
        if flat[key] != truth:
            return f"{what} says world.{key} {flat[key]}, {source} {truth} (edited or corrupt)", []
        if text != truth:
            return f"{what}'s settings say {key} {text}, {source} {truth} (edited or corrupt)", []
    changed = sorted(set(ours) ^ set(logged))
    if not changed:
        if metadata["settings"] != expected["settings"]:
            return f"{what}'s settings are not the JSON the recorder writes (edited)", []
        return None, []
    # recorded by a version with other settings: those both know were checked above
    return None, [
        "this version reads the embedded scene's world settings differently from the log's "
        "recorded settings: "
        + ", ".join(
            f"{k} (log {logged.get(k)!r}, now {json.loads(ours[k]) if k in ours else None!r})"
            for k in changed
        )
    ]


def _check_summary_indexes(scan: McapScan) -> Damage | None:
    """What a seeking reader (the official `mcap` reader, Foxglove) takes from the summary
    instead of the data: the metadata and attachment indexes, the repeated schemas and
    channels, and the summary offsets (each group where it says, holding that group's records)."""
    where = scan.footer_offset
    listed = {(mi.offset, mi.name): mi.length for mi in scan.metadata_indexes}
    for offset, record in scan.metadata:
        length = listed.pop((offset, record.name), None)
        if length is None:
            return Damage(
                f"the summary's metadata index does not point at the {record.name} record",
                None,
                offset,
            )
    if listed:
        (offset, name), _length = next(iter(listed.items()))
        return Damage(
            f"the summary's metadata index lists a {name} record at byte {offset} the file "
            "does not hold there",
            None,
            where,
        )
    held = {offset: a for offset, a in scan.attachments}
    if len(scan.attachment_indexes) != len(held):
        return Damage(
            f"the summary indexes {len(scan.attachment_indexes)} attachments, the file holds "
            f"{len(held)}",
            None,
            where,
        )
    for ai in scan.attachment_indexes:
        a = held.get(ai.offset)
        if a is None or (ai.name, ai.media_type, ai.data_size, ai.log_time, ai.create_time) != (
            a.name,
            a.media_type,
            len(a.data),
            a.log_time,
            a.create_time,
        ):
            return Damage(
                f"the summary's attachment index of {ai.name[:40]!r} does not match the "
                f"attachment at byte {ai.offset}",
                None,
                where,
            )
    for name, summary, data in (
        ("schema", scan.summary_schemas, scan.schemas),
        ("channel", scan.summary_channels, scan.channels),
    ):
        for rid, record in summary.items():
            if data.get(rid) != record:
                return Damage(
                    f"the summary's {name} {rid} is not the one the data section holds",
                    None,
                    where,
                )
    groups: dict = {}
    for offset, opcode, length in scan.summary_records:
        if opcode in (OP_SUMMARY_OFFSET, OP_FOOTER):
            continue
        start, end = groups.get(opcode, (offset, offset))
        if end != offset:
            return Damage(
                f"the summary's records of opcode 0x{opcode:02x} are not one group", None, offset
            )
        groups[opcode] = (start, offset + length)
    said = {so.group_opcode: so for so in scan.summary_offsets}
    for opcode, so in said.items():
        start, end = groups.get(opcode, (so.group_start, so.group_start))  # (an empty group)
        if (so.group_start, so.group_length) != (start, end - start):
            return Damage(
                f"the summary offset of opcode 0x{opcode:02x} does not point at that group",
                None,
                where,
            )
    first = next((o for o, op, _n in scan.summary_records if op == OP_SUMMARY_OFFSET), 0)
    if scan.summary_offsets and scan.footer.summary_offset_start != first:
        return Damage("the footer does not point at the summary offsets", None, where)
    return None
