"""MCAP records of a file that may be damaged or hostile, read within bounds.

mcap's own `StreamReader` checks a record's outer length against one limit, then trusts every
length inside the record (a chunk's data length, a metadata string's), decompresses a chunk to
whatever it expands to, and opens whatever it is given (opening a FIFO for reading blocks until
something writes to it). Here, instead:

- the path must name a regular file (`open_log`: ``os.stat`` before opening, so a FIFO, a device
  or a directory is refused without being opened);
- a record's length is checked against the bytes left in the file and `MAX_RECORD_BYTES` before
  anything is allocated; the record is then read whole and parsed from its own bytes, so no
  field inside it can reach past its end;
- a chunk's declared uncompressed size is checked against `MAX_RECORD_BYTES`, it is
  decompressed to at most that size and its CRC checked (`chunk_data`);
- the first record that fails any of this ends the walk with `RecordError` (its byte offset and
  what is wrong); the caller decides what that means for the log.

`McapScan` walks a whole file once: every message in file order (inside chunks or not), and on
the way what the file says about itself (channels, metadata, the summary's statistics, chunk,
attachment and metadata indexes, summary offsets) and what was actually read (messages per
channel, the chunks and where they start, the records of the summary), so a caller can compare
the two (`recorder.integrity`). The MessageIndex records after each chunk, which this reader
does not need but seeking readers use to find a message, are checked against the chunk as they
come (`McapScan.index_error`: the first that does not list exactly the chunk's messages of its
channel, each at its offset with its log time). Record layout: https://mcap.dev/spec.
"""

from __future__ import annotations

import os
import stat
import struct
import zlib
from array import array
from collections.abc import Iterator
from dataclasses import dataclass, field
from io import BytesIO
from typing import NamedTuple

import numpy as np
from mcap.data_stream import ReadDataStream
from mcap.records import (
    Attachment,
    AttachmentIndex,
    Channel,
    ChunkIndex,
    Footer,
    Header,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)

from isaac.errors import LogError
from isaac.sizes import byte_size

MAGIC = b"\x89MCAP0\r\n"

# The largest record (and the largest chunk once decompressed) read, in bytes. ISAAC's chunks
# close at 256 KiB plus at most one step's messages (~300 B a body-step uncompressed, so 3 MB a
# step for 10,000 bodies); 1 GiB leaves room for a million bodies while refusing the length
# field of a corrupt or crafted file before it is allocated.
MAX_RECORD_BYTES = 1 << 30

OP_HEADER = 0x01
OP_FOOTER = 0x02
OP_SCHEMA = 0x03
OP_CHANNEL = 0x04
OP_MESSAGE = 0x05
OP_CHUNK = 0x06
OP_MESSAGE_INDEX = 0x07
OP_CHUNK_INDEX = 0x08
OP_ATTACHMENT = 0x09
OP_ATTACHMENT_INDEX = 0x0A
OP_STATISTICS = 0x0B
OP_METADATA = 0x0C
OP_METADATA_INDEX = 0x0D
OP_SUMMARY_OFFSET = 0x0E
OP_DATA_END = 0x0F

_RECORD_HEAD = struct.Struct("<BQ")  # opcode, length of the body that follows
_MESSAGE_HEAD = struct.Struct("<HIQQ")  # channel id, sequence, log_time, publish_time (22 bytes)
_CHUNK_HEAD = struct.Struct("<QQQII")  # start, end time, uncompressed size, crc, compression len

_PARSERS = {
    OP_HEADER: Header,
    OP_FOOTER: Footer,
    OP_SCHEMA: Schema,
    OP_CHANNEL: Channel,
    OP_ATTACHMENT: Attachment,
    OP_METADATA: Metadata,
    OP_STATISTICS: Statistics,
    OP_CHUNK_INDEX: ChunkIndex,
    OP_METADATA_INDEX: MetadataIndex,
    OP_ATTACHMENT_INDEX: AttachmentIndex,
    OP_SUMMARY_OFFSET: SummaryOffset,
}
# a MessageIndex record: channel id, byte length of the (log_time, offset) pairs that follow
_INDEX_HEAD = struct.Struct("<HI")
_BYTE = np.arange(8)


class RecordError(Exception):
    """A record that cannot be read: ``offset`` (bytes from the file's start) and ``what``."""

    def __init__(self, offset: int, what: str) -> None:
        self.offset = offset
        self.what = what
        super().__init__(f"{what} (at byte {offset})")


def check_regular(path: str) -> None:
    """LogError (one line) unless ``path`` names a regular file, decided from ``os.stat`` alone:
    a FIFO, a socket, a device or a directory is never opened (opening a FIFO for reading waits
    for a writer; a device may never end)."""
    try:
        st = os.stat(path)
    except OSError as exc:
        raise LogError(f"{path}: {exc.strerror or exc}") from None
    if not stat.S_ISREG(st.st_mode):
        raise LogError(f"{path}: not a regular file ({_kind(st.st_mode)}); a log is a file")


def open_log(path: str):
    """Open ``path`` for reading if it is a regular file (`check_regular`); returns (file, size
    in bytes). Raises LogError (one line)."""
    check_regular(path)
    try:
        f = open(path, "rb")
    except OSError as exc:
        raise LogError(f"{path}: {exc.strerror or exc}") from None
    st = os.fstat(f.fileno())
    if not stat.S_ISREG(st.st_mode):  # replaced between the stat and the open
        f.close()
        raise LogError(f"{path}: not a regular file ({_kind(st.st_mode)}); a log is a file")
    return f, st.st_size


def _kind(mode: int) -> str:
    for test, name in (
        (stat.S_ISDIR, "a directory"),
        (stat.S_ISFIFO, "a FIFO"),
        (stat.S_ISSOCK, "a socket"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
    ):
        if test(mode):
            return name
    return "not a file"


@dataclass(frozen=True)
class ChunkHead:
    """A Chunk record's fields, its data left undecompressed (a view into the record)."""

    offset: int  # of the record (its opcode byte)
    length: int  # of the whole record, opcode and length field included
    message_start_time: int
    message_end_time: int
    uncompressed_size: int
    uncompressed_crc: int
    compression: str
    compressed_size: int
    data: memoryview


def _parse_chunk(offset: int, body: memoryview) -> ChunkHead:
    if len(body) < _CHUNK_HEAD.size:
        raise RecordError(offset, "a chunk record too short for its fields")
    start, end, usize, crc, clen = _CHUNK_HEAD.unpack_from(body, 0)
    pos = _CHUNK_HEAD.size
    if pos + clen + 8 > len(body):
        raise RecordError(offset, "a chunk's compression name runs past its record")
    try:
        compression = bytes(body[pos : pos + clen]).decode("utf-8")
    except UnicodeDecodeError:
        raise RecordError(offset, "a chunk's compression name is not UTF-8") from None
    pos += clen
    (dlen,) = struct.unpack_from("<Q", body, pos)
    pos += 8
    if dlen != len(body) - pos:
        raise RecordError(
            offset, f"a chunk's data length ({dlen}) does not match its record ({len(body) - pos})"
        )
    return ChunkHead(
        offset, len(body) + 9, start, end, usize, crc, compression, dlen, body[pos : pos + dlen]
    )


def chunk_data(chunk: ChunkHead):
    """The chunk's records, decompressed to at most their declared size and CRC-checked.

    Raises RecordError if the declared size exceeds `MAX_RECORD_BYTES`, the data does not
    decompress to exactly that size, or the CRC (when the writer computed one) does not match.
    """
    n = chunk.uncompressed_size
    at = chunk.offset
    if n > MAX_RECORD_BYTES:
        raise RecordError(
            at,
            f"a chunk claims {byte_size(n)} uncompressed, more than the "
            f"{byte_size(MAX_RECORD_BYTES)} a chunk may hold",
        )
    kind = chunk.compression
    try:
        if kind == "":
            data = chunk.data
        elif kind == "lz4":
            import lz4.frame

            # at most n + 1 bytes come out, so a chunk that expands past its size is caught
            # without holding what it expands to
            data = lz4.frame.LZ4FrameDecompressor().decompress(chunk.data, max_length=n + 1)
        elif kind == "zstd":
            import zstandard

            declared = zstandard.frame_content_size(chunk.data)
            if declared > n:
                raise RecordError(at, f"a zstd chunk's frame claims {declared} bytes, not {n}")
            data = zstandard.ZstdDecompressor().decompress(chunk.data, max_output_size=max(n, 1))
        else:
            raise RecordError(at, f"a chunk with unknown compression {kind[:20]!r}")
    except RecordError:
        raise
    except MemoryError:
        what = f"not enough memory to decompress a chunk of {byte_size(n)}"
        raise RecordError(at, what) from None
    except Exception as exc:  # noqa: BLE001 - lz4 and zstandard raise their own error types
        raise RecordError(at, f"a chunk that does not decompress ({type(exc).__name__})") from None
    if len(data) != n:
        raise RecordError(
            at, f"a chunk that decompresses to {len(data)} bytes, not the {n} it declares"
        )
    if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
        raise RecordError(at, "a chunk whose CRC does not match its data (corrupt)")
    return data


class Msg(NamedTuple):
    """One message record: where it sits and its fields (``data`` a view, not a copy)."""

    offset: int  # of the chunk holding it, or of the record itself outside chunks
    channel_id: int
    sequence: int
    log_time: int
    publish_time: int
    data: memoryview


@dataclass
class McapScan:
    """One pass over an MCAP file's records (see the module docstring).

    After `messages` has run to its end without raising: ``footer`` is the Footer (None if the
    file has none), and the attributes below say what the file declared and what was read.
    """

    f: object
    size: int
    # what was read
    channels: dict = field(default_factory=dict)  # id -> Channel (data section)
    schemas: dict = field(default_factory=dict)  # id -> Schema (data section)
    metadata: list = field(default_factory=list)  # (offset, Metadata) in file order
    attachments: list = field(default_factory=list)  # (offset, Attachment)
    chunks: list = field(default_factory=list)  # ChunkHead of every chunk, data released
    counts: dict = field(default_factory=dict)  # channel id -> messages read
    messages_read: int = 0
    header: Header | None = None
    data_end: int | None = None  # offset of the DataEnd record
    # what the summary declares
    statistics: Statistics | None = None
    chunk_indexes: list = field(default_factory=list)
    metadata_indexes: list = field(default_factory=list)
    summary_channels: dict = field(default_factory=dict)
    footer: Footer | None = None
    footer_offset: int | None = None
    first_summary_offset: int | None = None
    summary_schemas: dict = field(default_factory=dict)
    attachment_indexes: list = field(default_factory=list)
    summary_offsets: list = field(default_factory=list)  # SummaryOffset records
    summary_records: list = field(default_factory=list)  # (offset, opcode, length) after DataEnd
    # the MessageIndex records after each chunk (parallel to ``chunks``): channel id -> offset
    # of its record, and their bytes in all; the first one that disagrees with its chunk
    message_indexes: list = field(default_factory=list)
    message_index_lengths: list = field(default_factory=list)
    index_error: RecordError | None = None
    position: int = 0  # just past the last record read
    # the chunk whose message indexes may follow: (offset, data, message starts, the
    # (offset, channel id, body) of each of its message indexes read so far)
    _open: list | None = None

    def records(
        self, *, start: int = 0, until: tuple = ()
    ) -> Iterator[tuple[int, int, memoryview]]:
        """(offset, opcode, body) of every record from ``start`` (0: check the magic first) to
        the footer and the closing magic; raises RecordError at the first unreadable one.
        Stops, without reading it, at the first record whose opcode is in ``until``."""
        f, size = self.f, self.size
        pos = start
        f.seek(pos)
        if pos == 0:
            if f.read(len(MAGIC)) != MAGIC:
                raise RecordError(0, "not an MCAP file (no magic)")
            pos = len(MAGIC)
        while True:
            head = f.read(9)
            if len(head) < 9:
                if not head:
                    raise RecordError(pos, "the file ends without a footer (unfinished or cut)")
                raise RecordError(pos, "the file ends inside a record (cut short)")
            opcode, length = _RECORD_HEAD.unpack(head)
            if opcode in until:
                return
            if opcode == 0:
                raise RecordError(pos, "an invalid record (opcode 0: zeroed or corrupt bytes)")
            left = size - pos - 9
            if length > left:
                raise RecordError(
                    pos,
                    f"a record that claims {byte_size(length)}, more than the "
                    f"{byte_size(max(left, 0))} left in the file (cut short or corrupt)",
                )
            if length > MAX_RECORD_BYTES:
                raise RecordError(
                    pos,
                    f"a record that claims {byte_size(length)}, more than the "
                    f"{byte_size(MAX_RECORD_BYTES)} a record may hold",
                )
            try:
                body = f.read(length)
            except MemoryError:
                raise RecordError(pos, f"not enough memory to read {byte_size(length)}") from None
            if len(body) != length:
                raise RecordError(pos, "the file ends inside a record (cut short)")
            self.position = pos + 9 + length
            yield pos, opcode, memoryview(body)
            pos += 9 + length
            if opcode == OP_FOOTER:
                if f.read(len(MAGIC)) != MAGIC:
                    raise RecordError(pos, "no closing magic after the footer")
                if pos + len(MAGIC) != size:
                    raise RecordError(pos + len(MAGIC), "bytes after the footer's closing magic")
                return

    @staticmethod
    def parse(offset: int, opcode: int, body: memoryview):
        """The mcap record object of one record's body (RecordError if it is malformed)."""
        cls = _PARSERS[opcode]
        stream = ReadDataStream(BytesIO(body))
        try:
            record = cls.read(stream)
        except Exception:  # noqa: BLE001 - short reads surface as struct or decode errors
            raise RecordError(offset, f"a malformed {cls.__name__} record") from None
        return record

    def messages(self, *, start: int = 0) -> Iterator[Msg]:
        """Every message in file order, inside chunks or not (raises RecordError)."""
        in_summary = False
        for offset, opcode, body in self.records(start=start):
            if opcode != OP_MESSAGE_INDEX and self._open is not None:
                self._chunk_indexed()
            if in_summary:
                self.summary_records.append((offset, opcode, 9 + len(body)))
            if opcode == OP_CHUNK:
                if in_summary:
                    raise RecordError(offset, "a chunk after the end of the data section")
                chunk = _parse_chunk(offset, body)
                data = chunk_data(chunk)
                self.chunks.append(_released(chunk))
                self.message_indexes.append({})
                self.message_index_lengths.append(0)
                starts = array("q")  # appended per message, read by numpy without a copy
                self._open = [chunk.offset, data, starts, []]
                yield from self._chunk_messages(chunk.offset, data, starts)
            elif opcode == OP_MESSAGE:
                if in_summary:
                    raise RecordError(offset, "a message after the end of the data section")
                yield self._message(offset, body, 0, len(body))
            elif opcode == OP_MESSAGE_INDEX:
                if in_summary:
                    if self.first_summary_offset is None:
                        self.first_summary_offset = offset
                elif self.index_error is None:
                    self._check_message_index(offset, body)
            elif opcode == OP_DATA_END:
                in_summary = True
                self.data_end = offset
            elif opcode in _PARSERS:
                record = self.parse(offset, opcode, body)
                if in_summary and opcode != OP_FOOTER and self.first_summary_offset is None:
                    self.first_summary_offset = offset
                self._note(offset, record, in_summary)
            # other opcodes: records this version does not know, skipped as the spec says

    def summary_crc_ok(self) -> bool | None:
        """Whether the footer's summary CRC matches the summary bytes (None: nothing to check).

        The CRC covers every byte from the summary's start up to the footer's CRC field."""
        footer = self.footer
        if footer is None or not footer.summary_crc or not footer.summary_start:
            return None
        end = self.footer_offset + 9 + 16  # opcode, length, summary_start, summary_offset_start
        if not 0 < footer.summary_start < end or end - footer.summary_start > MAX_RECORD_BYTES:
            return False
        self.f.seek(footer.summary_start)
        return zlib.crc32(self.f.read(end - footer.summary_start)) == footer.summary_crc

    def read_rest(self) -> bool:
        """Walk the records after the last one read, to the footer, noting metadata and the
        summary as they come (chunks are not opened): what a file whose data could not be read
        through still says about itself. False if a record on the way cannot be read."""
        in_summary = self.data_end is not None
        try:
            for offset, opcode, body in self.records(start=self.position):
                if opcode == OP_DATA_END:
                    in_summary = True
                elif opcode in _PARSERS and opcode not in (OP_SCHEMA, OP_CHANNEL):
                    self._note(offset, self.parse(offset, opcode, body), in_summary)
        except RecordError:
            return False
        return True

    def read_summary(self) -> None:
        """Read the summary of a file whose data section could not be read through, from its
        footer (the last 37 bytes): statistics, chunk indexes, metadata indexes and the
        metadata they point at. Quietly reads nothing if the end of the file is damaged too."""
        footer_at = self.size - len(MAGIC) - 29
        try:
            (offset, opcode, body) = next(self.records(start=footer_at))
            if opcode != OP_FOOTER:
                return
            footer = self.parse(offset, opcode, body)
            if not len(MAGIC) < footer.summary_start < footer_at:
                return
            for offset, opcode, body in self.records(start=footer.summary_start):
                if opcode in _PARSERS:
                    self._note(offset, self.parse(offset, opcode, body), True)
            for index in list(self.metadata_indexes):
                if len(MAGIC) <= index.offset < footer_at:
                    offset, opcode, body = next(self.records(start=index.offset))
                    if opcode == OP_METADATA:
                        self._note(offset, self.parse(offset, opcode, body), True)
        except (RecordError, StopIteration):
            return

    def _check_message_index(self, offset: int, body: memoryview) -> None:
        """Note one MessageIndex record after the open chunk (its framing checked here, its
        entries with the chunk's others in `_chunk_indexed`)."""
        if self._open is None:
            self.index_error = RecordError(offset, "a message index that follows no chunk")
            return
        if len(body) < _INDEX_HEAD.size:
            self.index_error = RecordError(offset, "a message index record too short")
            return
        cid, size = _INDEX_HEAD.unpack_from(body, 0)
        if size != len(body) - _INDEX_HEAD.size or size % 16:
            self.index_error = RecordError(
                offset, f"a message index whose entries ({size} bytes) do not fit its record"
            )
            return
        k = len(self.chunks) - 1
        seen = self.message_indexes[k]
        if cid in seen:
            self.index_error = RecordError(
                offset,
                f"a second message index of {self._topic(cid)} after the chunk at byte "
                f"{self._open[0]}",
            )
            return
        seen[cid] = offset
        self.message_index_lengths[k] += 9 + len(body)
        self._open[3].append((offset, cid, body))

    def _chunk_indexed(self) -> None:
        """The open chunk's message indexes have all come: unless it has none (an MCAP file may
        leave them out), together they must list each of its messages once, by its channel,
        its log time and its offset in the chunk. One pass of array operations a chunk (the
        entries of every index against the messages' starts, channels and log times gathered
        from the chunk's bytes), no Python work per message."""
        chunk_at, data, starts, indexes = self._open
        self._open = None
        if not indexes or self.index_error is not None:
            return
        starts = np.frombuffer(starts, dtype=np.int64)
        buf = np.frombuffer(data, dtype=np.uint8)
        channels = buf[starts + 9].astype(np.int64) | (buf[starts + 10].astype(np.int64) << 8)
        times = buf[(starts + 15)[:, None] + _BYTE].copy().view("<u8").ravel()
        entries = [
            np.frombuffer(body, dtype="<u8", offset=_INDEX_HEAD.size) for *_x, body in indexes
        ]
        listed = np.concatenate(entries).reshape(-1, 2)
        owner = np.repeat(np.arange(len(indexes)), [len(e) // 2 for e in entries])
        order = np.argsort(listed[:, 1], kind="stable")
        cids = np.array([cid for _o, cid, _b in indexes], dtype=np.int64)
        if len(listed) == len(starts) and (
            np.array_equal(listed[order, 1], starts)
            and np.array_equal(listed[order, 0], times)
            and np.array_equal(cids[owner[order]], channels)
        ):
            return
        self.index_error = self._index_error(chunk_at, indexes, starts, channels, times)

    def _index_error(self, chunk_at, indexes, starts, channels, times) -> RecordError:
        """The first index of a chunk that does not list its channel's messages (slow path,
        once a log)."""
        for offset, cid, body in indexes:
            listed = np.frombuffer(body, dtype="<u8", offset=_INDEX_HEAD.size).reshape(-1, 2)
            mine = channels == cid
            held = np.column_stack((times[mine], starts[mine].astype(np.uint64)))
            topic = self._topic(cid)
            if len(listed) != len(held):
                return RecordError(
                    offset,
                    f"the message index of {topic} after the chunk at byte {chunk_at} lists "
                    f"{len(listed)} messages; the chunk holds {len(held)}",
                )
            listed = listed[np.argsort(listed[:, 1], kind="stable")]
            wrong = np.flatnonzero((listed != held).any(axis=1))
            if len(wrong):
                t, at = (int(v) for v in listed[wrong[0]])
                return RecordError(
                    offset,
                    f"the message index of {topic} after the chunk at byte {chunk_at} lists a "
                    f"message at offset {at} with log time {t}: the chunk has no {topic} "
                    f"message there with that log time",
                )
        missing = sorted(set(channels.tolist()) - {cid for _o, cid, _b in indexes})
        return RecordError(
            chunk_at,
            f"the chunk at byte {chunk_at} has no message index of {self._topic(missing[0])}"
            if missing
            else f"the message indexes after the chunk at byte {chunk_at} do not list its messages",
        )

    def _topic(self, cid: int) -> str:
        channel = self.channels.get(cid)
        return channel.topic if channel is not None else f"channel {cid}"

    def _note(self, offset: int, record, in_summary: bool) -> None:
        if isinstance(record, Channel):
            (self.summary_channels if in_summary else self.channels)[record.id] = record
        elif isinstance(record, Schema):
            (self.summary_schemas if in_summary else self.schemas)[record.id] = record
        elif isinstance(record, AttachmentIndex):
            self.attachment_indexes.append(record)
        elif isinstance(record, SummaryOffset):
            self.summary_offsets.append(record)
        elif isinstance(record, Metadata):
            self.metadata.append((offset, record))
        elif isinstance(record, Attachment):
            self.attachments.append((offset, record))
        elif isinstance(record, Header):
            self.header = record
        elif isinstance(record, Statistics):
            self.statistics = record
        elif isinstance(record, ChunkIndex):
            self.chunk_indexes.append(record)
        elif isinstance(record, MetadataIndex):
            self.metadata_indexes.append(record)
        elif isinstance(record, Footer):
            self.footer = record
            self.footer_offset = offset

    def _message(self, offset: int, buf, pos: int, end: int) -> Msg:
        if end - pos < _MESSAGE_HEAD.size:
            raise RecordError(offset, "a message record too short for its fields")
        cid, seq, log_time, publish_time = _MESSAGE_HEAD.unpack_from(buf, pos)
        self.counts[cid] = self.counts.get(cid, 0) + 1
        self.messages_read += 1
        view = buf if isinstance(buf, memoryview) else memoryview(buf)
        return Msg(offset, cid, seq, log_time, publish_time, view[pos + 22 : end])

    def _chunk_messages(self, offset: int, data, starts: array) -> Iterator[Msg]:
        """Walk one decompressed chunk's records with struct offsets (no copies); the offset of
        each message record within the chunk is appended to ``starts``."""
        pos, end = 0, len(data)
        view = memoryview(data)
        while pos < end:
            if pos + 9 > end:
                raise RecordError(offset, "a chunk whose last record is cut short")
            opcode, length = _RECORD_HEAD.unpack_from(data, pos)
            pos += 9
            if length > end - pos:
                raise RecordError(offset, "a record that runs past the end of its chunk")
            if opcode == OP_MESSAGE:
                starts.append(pos - 9)
                yield self._message(offset, view, pos, pos + length)
            elif opcode in (OP_CHANNEL, OP_SCHEMA):
                self._note(offset, self.parse(offset, opcode, view[pos : pos + length]), False)
            elif opcode == 0:
                raise RecordError(offset, "a chunk holding an invalid record (opcode 0)")
            pos += length


def _released(chunk: ChunkHead) -> ChunkHead:
    # kept for the comparison with the chunk indexes; without its data
    return ChunkHead(
        chunk.offset,
        chunk.length,
        chunk.message_start_time,
        chunk.message_end_time,
        chunk.uncompressed_size,
        chunk.uncompressed_crc,
        chunk.compression,
        chunk.compressed_size,
        memoryview(b""),
    )
