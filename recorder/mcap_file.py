"""Write an MCAP file: ISAAC's own writer of the published format (https://mcap.dev/spec).

The file, in order: magic; Header; each Metadata and Attachment record where it is added (the
recorder adds its own before any chunk, so they survive a crash); Chunk records (uncompressed,
lz4 or zstd, each with the CRC of its uncompressed records), each followed by one MessageIndex
record per channel it holds; on `finish`, DataEnd, the summary (the Schema, Channel,
Statistics, ChunkIndex, AttachmentIndex and MetadataIndex groups, then a SummaryOffset record
for each group), the Footer (with the CRC of the summary) and magic again.

Where the specification leaves a choice, the layout is the one the mcap Python library's
`Writer` gives for the same calls (mcap 1.6: Schema and Channel records at the head of the
first chunk that holds a message, a chunk closed after the first message that takes it past
``chunk_size`` bytes), so logs are byte for byte what they were when the recorder wrote them
through that library: tests/recorder/test_mcap_file.py compares the two and reads the files
with mcap's readers and with `recorder.mcap_records`.

Messages go in one at a time (`add`) or as stretches of Message records already laid out as
the file holds them (`append`: packed by `recorder.mcap_pack`), entered into the chunk with one
copy, their index entries computed by one compiled call (`recorder.mcap_pack.index_entries`).
A stretch holds whole steps, each ending with its ``/stats`` message (``stats_channel``); after
the first step and every ``flush_every`` steps the chunk is closed and the file flushed to the
OS, so a crash loses at most the open chunk.
"""

from __future__ import annotations

import struct
import zlib

import numpy as np

from recorder.mcap_pack import index_entries, scan_records
from recorder.mcap_records import (
    MAGIC,
    OP_ATTACHMENT,
    OP_ATTACHMENT_INDEX,
    OP_CHANNEL,
    OP_CHUNK,
    OP_CHUNK_INDEX,
    OP_DATA_END,
    OP_FOOTER,
    OP_HEADER,
    OP_MESSAGE,
    OP_MESSAGE_INDEX,
    OP_METADATA,
    OP_METADATA_INDEX,
    OP_SCHEMA,
    OP_STATISTICS,
    OP_SUMMARY_OFFSET,
)

COMPRESSIONS = ("none", "lz4", "zstd")

_OPEN = struct.Struct("<BQ")  # a record's opcode and the length of what follows
_MESSAGE = struct.Struct("<BQHIQQ")  # ... channel id, sequence, log_time, publish_time
_ENTRY = struct.Struct("<QQ")  # a MessageIndex entry: log_time, offset in the chunk


def _u(fmt: str, *values: int) -> bytes:
    return struct.pack("<" + fmt, *values)


def _string(text: str) -> bytes:
    data = text.encode()
    return _u("I", len(data)) + data


def _map(values: dict[str, str]) -> bytes:
    body = b"".join(_string(k) + _string(v) for k, v in values.items())
    return _u("I", len(body)) + body


def _record(opcode: int, *parts: bytes) -> bytes:
    body = b"".join(parts)
    return _OPEN.pack(opcode, len(body)) + body


def _compressor(compression: str):
    """The chunk compression's name in the file and its function (None: stored as it is),
    with the codecs' default settings (lz4 frame, zstd level 3)."""
    if compression == "lz4":
        import lz4.frame

        return "lz4", lz4.frame.compress
    if compression == "zstd":
        import zstandard

        return "zstd", zstandard.compress
    if compression != "none":
        raise ValueError(f"compression must be one of {list(COMPRESSIONS)}")
    return "", None


class McapFile:
    """An MCAP file written to ``stream`` (binary, positioned at its start; never closed here).

    chunk_size: a chunk closes after the message that takes it past this many bytes
        (uncompressed). compression: one of COMPRESSIONS. flush_every: steps between chunk
        closes and file flushes (besides after the first step). profile, library: the Header's.
    stats_channel: the id of the channel whose message ends a step (set once registered).
    """

    def __init__(
        self,
        stream,
        *,
        chunk_size: int,
        compression: str,
        flush_every: int,
        profile: str,
        library: str,
    ) -> None:
        self._out = stream
        self._pos = stream.tell()
        self.chunk_size = chunk_size
        self.compression, self._compress = _compressor(compression)
        self.flush_every = flush_every
        self.stats_channel: int | None = None
        self.steps = 0  # steps entered: a chunk closes after the first and every flush_every
        # the open chunk: its records, each channel's index entries (buffers of (log_time,
        # offset) u64 pairs) in the order the channels first came, its messages and times
        self._chunk = bytearray()
        self._index: dict[int, list] = {}
        self._messages = 0
        self._times = (0, 0)
        # for the summary
        self._schemas: list[bytes] = []
        self._channels: list[bytes] = []
        self._counts: dict[int, int] = {}  # messages per channel, in the order they first came
        self._message_count = 0
        self._span = (0, 0)  # the least and greatest log time of every message
        self._chunk_indexes: list[bytes] = []
        self._attachment_indexes: list[bytes] = []
        self._metadata_indexes: list[bytes] = []
        self._write(MAGIC + _record(OP_HEADER, _string(profile), _string(library)))

    def _write(self, data) -> None:
        self._out.write(data)
        self._pos += len(data)

    # -- records outside the chunks ---------------------------------------------------------
    def add_metadata(self, name: str, values: dict[str, str]) -> None:
        """A Metadata record (``values``: str to str), where the file is now."""
        record = _record(OP_METADATA, _string(name), _map(values))
        self._metadata_indexes.append(
            _record(OP_METADATA_INDEX, _u("QQ", self._pos, len(record)), _string(name))
        )
        self._write(record)

    def add_attachment(
        self, *, create_time: int, log_time: int, name: str, media_type: str, data: bytes
    ) -> None:
        """An Attachment record (times in ns), where the file is now."""
        body = b"".join(
            (_u("QQ", log_time, create_time), _string(name), _string(media_type))
            + (_u("Q", len(data)), data)
        )
        record = _record(OP_ATTACHMENT, body, _u("I", zlib.crc32(body)))
        self._attachment_indexes.append(
            _record(
                OP_ATTACHMENT_INDEX,
                _u("QQQQQ", self._pos, len(record), log_time, create_time, len(data)),
                _string(name),
                _string(media_type),
            )
        )
        self._write(record)

    def register_schema(self, *, name: str, encoding: str, data: bytes) -> int:
        """A Schema record (in the next chunk and the summary); returns its id (1, 2, ...)."""
        sid = len(self._schemas) + 1
        record = _record(
            OP_SCHEMA, _u("H", sid), _string(name), _string(encoding), _u("I", len(data)), data
        )
        self._schemas.append(record)
        self._chunk += record
        return sid

    def register_channel(self, *, topic: str, message_encoding: str, schema_id: int) -> int:
        """A Channel record (in the next chunk and the summary); returns its id (1, 2, ...)."""
        cid = len(self._channels) + 1
        record = _record(
            OP_CHANNEL,
            _u("HH", cid, schema_id),
            _string(topic),
            _string(message_encoding),
            _map({}),
        )
        self._channels.append(record)
        self._chunk += record
        return cid

    # -- messages ---------------------------------------------------------------------------
    def add(self, channel: int, log_time: int, data, step: int) -> None:
        """One message (sequence = step, publish_time = log_time, ns); the chunk closes after
        it when it is past ``chunk_size``."""
        at = len(self._chunk)
        self._chunk += _MESSAGE.pack(OP_MESSAGE, 22 + len(data), channel, step, log_time, log_time)
        self._chunk += data
        index = self._index.get(channel)
        if index is None:
            index = self._index[channel] = []
        index.append(_ENTRY.pack(log_time, at))
        self._note(1, log_time, log_time)
        if len(self._chunk) > self.chunk_size:
            self._close_chunk()

    def end_step(self) -> None:
        """A step's messages are all in: close the chunk and flush when one is due."""
        self.steps += 1
        if self.steps == 1 or self.steps % self.flush_every == 0:
            self.flush()

    def append(self, buf: np.ndarray, start: int = 0, end: int | None = None) -> tuple[int, int]:
        """The Message records in ``buf[start:end]`` (uint8): whole steps, each ending with its
        ``/stats`` message (a step's ``/world`` message may come first), entered as `add` and
        `end_step` would enter them one by one. Returns (steps, the last one's sequence number,
        -1 for none)."""
        end = len(buf) if end is None else end
        if end <= start:
            return 0, -1
        starts, ends, channel, sequence, log_time = scan_records(buf, start, end)
        # the messages after which the chunk is closed and the file flushed: the /stats
        # messages that end the first step and every flush_every-th
        step_ends = np.flatnonzero(channel == self.stats_channel)
        counts = self.steps + 1 + np.arange(len(step_ends))
        flushes = [int(x) for x in step_ends[(counts == 1) | (counts % self.flush_every == 0)]]
        self.steps += len(step_ends)
        total = len(starts)
        cuts = flushes if flushes and flushes[-1] == total - 1 else [*flushes, total - 1]
        flush_at = set(flushes)
        i = 0
        with memoryview(buf) as view:
            for cut in cuts:
                while i <= cut:
                    # `add` closes the chunk after the first message that takes it past
                    # chunk_size: the first j >= i with size + (ends[j] - starts[i]) > chunk_size
                    room = self.chunk_size - len(self._chunk)
                    j = max(i, int(np.searchsorted(ends, starts[i] + room, side="right")))
                    last = min(j, cut)
                    order, per, entries, lt_min, lt_max = index_entries(
                        channel, log_time, starts, i, last + 1, len(self._chunk)
                    )
                    at = 0
                    for c, k in zip(order.tolist(), per.tolist()):
                        self._index.setdefault(c, []).append(entries[at : at + k])
                        at += k
                    self._chunk += view[starts[i] : ends[last]]
                    self._note(last + 1 - i, int(lt_min), int(lt_max))
                    if last == j:
                        self._close_chunk()
                    i = last + 1
                if cut in flush_at:
                    self.flush()
        return len(step_ends), int(sequence[-1])

    def _note(self, count: int, lt_min: int, lt_max: int) -> None:
        t0, t1 = self._times
        self._times = (lt_min if not self._messages else min(t0, lt_min), max(t1, lt_max))
        self._messages += count

    # -- chunks -----------------------------------------------------------------------------
    def _close_chunk(self) -> None:
        """Write the open chunk (if it holds a message) and its MessageIndex records."""
        if not self._messages:
            return
        data = self._chunk
        stored = self._compress(data) if self._compress is not None else data
        t0, t1 = self._times
        chunk_at = self._pos
        head = _u("QQQI", t0, t1, len(data), zlib.crc32(data)) + _string(self.compression)
        head += _u("Q", len(stored))
        self._write(_OPEN.pack(OP_CHUNK, len(head) + len(stored)) + head)
        self._write(stored)
        chunk_length = self._pos - chunk_at
        offsets = []
        index_at = self._pos
        for cid, parts in self._index.items():
            entries = b"".join(parts)
            offsets.append(_u("HQ", cid, self._pos))
            self._write(_record(OP_MESSAGE_INDEX, _u("HI", cid, len(entries)), entries))
            self._counts[cid] = self._counts.get(cid, 0) + len(entries) // _ENTRY.size
        self._chunk_indexes.append(
            _record(
                OP_CHUNK_INDEX,
                _u("QQQQI", t0, t1, chunk_at, chunk_length, 10 * len(offsets)),
                *offsets,
                _u("Q", self._pos - index_at),
                _string(self.compression),
                _u("QQ", len(stored), len(data)),
            )
        )
        s0, s1 = self._span
        self._span = (t0 if not self._message_count else min(s0, t0), max(s1, t1))
        self._message_count += self._messages
        self._chunk = bytearray()
        self._index = {}
        self._messages = 0
        self._times = (0, 0)

    def flush(self) -> None:
        """Close the open chunk (if it holds a message) and flush the file to the OS."""
        self._close_chunk()
        self._out.flush()

    def finish(self) -> None:
        """Close the open chunk, then DataEnd, the summary, its offsets, Footer and magic."""
        self._close_chunk()
        self._write(_record(OP_DATA_END, _u("I", 0)))  # no data section CRC
        start = self._pos
        counts = b"".join(_u("HQ", c, k) for c, k in self._counts.items())
        statistics = _record(
            OP_STATISTICS,
            _u(
                "QHIIII",
                self._message_count,
                len(self._schemas),
                len(self._channels),
                len(self._attachment_indexes),
                len(self._metadata_indexes),
                len(self._chunk_indexes),
            ),
            _u("QQI", *self._span, len(counts)),
            counts,
        )
        groups = (
            (OP_SCHEMA, self._schemas),
            (OP_CHANNEL, self._channels),
            (OP_STATISTICS, [statistics]),
            (OP_CHUNK_INDEX, self._chunk_indexes),
            (OP_ATTACHMENT_INDEX, self._attachment_indexes),
            (OP_METADATA_INDEX, self._metadata_indexes),
        )
        summary, offsets, at = [], [], start
        for opcode, records in groups:
            group = b"".join(records)
            summary.append(group)
            offsets.append(_record(OP_SUMMARY_OFFSET, _u("BQQ", opcode, at, len(group))))
            at += len(group)
        summary = b"".join(summary + offsets)
        footer = _OPEN.pack(OP_FOOTER, 20) + _u("QQ", start, at)
        self._write(summary + footer + _u("I", zlib.crc32(footer, zlib.crc32(summary))) + MAGIC)
