"""Read a log's steps as raw message payloads, in bulk, for the replay comparison.

`recorder.reader.LogReader` decodes every message into numpy arrays; replay does not need that:
it compares the logged payload bytes with the bytes the recorder's own encoders make from the
re-simulated record, and decodes a message only when the bytes differ (or to start from a keyframe).
So this module reads the file with MCAP's stream reader one *chunk* at a time (``emit_chunks``),
decompresses the chunk in one call and walks its records with ``struct`` offsets, handing out
message payloads as byte slices: about 0.13 ms per step of the 500-body pile (163 kB a step, from
the page cache), against 1.5 to 3 ms to simulate the step.

A file that was never closed (a crash) or was cut short is read up to the first damaged record;
`RawLog.damage` then says what was wrong. A step counts only when its ``/bodies``, ``/contacts``
and ``/stats`` messages are all there (``/stats`` is written last).

The header (metadata, embedded scene) is read and validated by `LogReader`; everything else here
is the MCAP record layout (https://mcap.dev/spec): ``opcode u8, length u64, body``; a Message body
is ``channel_id u16, sequence u32, log_time u64, publish_time u64, data``; a Channel body starts
``id u16, schema_id u16, topic (u32 length + UTF-8)``.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass

from mcap.exceptions import McapError
from mcap.records import Channel, Chunk, Message, Metadata
from mcap.stream_reader import StreamReader

from isaac.errors import LogError
from recorder.mcap_writer import FORMAT_VERSION, META_END
from recorder.reader import LogReader

STEP_TOPICS = ("/bodies", "/contacts", "/stats")
TOPICS = ("/world",) + STEP_TOPICS

_OP_CHANNEL = 0x04
_OP_MESSAGE = 0x05
_RECORD_HEAD = struct.Struct("<BQ")
_MESSAGE_HEAD = struct.Struct("<HI")  # channel id, sequence (the step index)
_CHANNEL_HEAD = struct.Struct("<HHI")  # id, schema id, topic length


@dataclass
class RawStep:
    """One logged step: its index and the raw payload of each of its messages.

    messages: topic -> payload bytes, for the topics present at this step (``/world`` only at
        step 0 and when a body entered or left).
    """

    step: int
    messages: dict

    @property
    def complete(self) -> bool:
        return all(t in self.messages for t in STEP_TOPICS)


class RawLog:
    """An ISAAC MCAP log opened for replay: its validated header and its steps as raw payloads.

    Raises LogError (one line) if the file is missing, empty, not MCAP, or not an ISAAC log.
    After `steps()` has run to the end: ``damage`` (str or None) says where a damaged or
    unfinished file stopped being readable, ``end`` holds the ``isaac.end`` metadata (None when
    the file was never closed), ``incomplete_tail`` the index of a last step that was only partly
    written (None if none).
    """

    def __init__(self, path: str) -> None:
        self.path = str(path)
        self.header = LogReader(self.path)  # metadata, scene text, settings; LogError if bad
        self.metadata: dict[str, str] = self.header.metadata
        self.closed_cleanly: bool = self.header.closed_cleanly
        self.damage: str | None = None
        self.end: dict[str, str] | None = None
        self.incomplete_tail: int | None = None
        version = self.metadata.get("format_version")
        if version != FORMAT_VERSION:
            raise LogError(
                f"{self.path}: log format version {version!r} is not supported "
                f"(this version reads {FORMAT_VERSION!r})"
            )

    @property
    def scene_text(self) -> str:
        try:
            return self.header.scene_text
        except UnicodeDecodeError as exc:
            raise LogError(f"{self.path}: the embedded scene is not UTF-8 text ({exc})") from None

    # -- raw records ---------------------------------------------------------------------------

    def _messages(self) -> Iterator[tuple[str, int, bytes]]:
        """(topic, sequence, payload) of every message in file order, chunk by chunk."""
        topics: dict[int, str] = {}
        size = max(self.header.size, 1)
        with open(self.path, "rb") as f:
            # each chunk's CRC is checked below, on its uncompressed bytes; the reader's own
            # running CRC of the whole data section would read every byte a second time
            reader = StreamReader(f, emit_chunks=True, validate_crcs=False, record_size_limit=size)
            records = reader.records
            while True:
                try:
                    record = next(records)
                    if isinstance(record, Chunk):
                        batch = list(self._chunk_messages(record, topics))
                    elif isinstance(record, Channel):
                        topics[record.id] = record.topic
                        continue
                    elif isinstance(record, Message):
                        batch = [(topics.get(record.channel_id), record.sequence, record.data)]
                    elif isinstance(record, Metadata) and record.name == META_END:
                        self.end = dict(record.metadata)
                        continue
                    else:
                        continue
                except StopIteration:
                    return
                except Exception as exc:  # noqa: BLE001 - cut files fail in many ways
                    # the end of what is readable: a cut, unfinished or corrupt file
                    self.damage = (
                        f"a damaged or incomplete record near byte {f.tell()} "
                        f"({type(exc).__name__})"
                    )
                    return
                yield from batch

    def _chunk_messages(self, chunk: Chunk, topics: dict) -> Iterator[tuple[str, int, bytes]]:
        """Decompress one chunk and walk its records (raises on a damaged chunk)."""
        if chunk.compression == "lz4":
            import lz4.frame

            data = lz4.frame.decompress(chunk.data)
        elif chunk.compression == "zstd":
            import zstandard

            data = zstandard.decompress(chunk.data, chunk.uncompressed_size)
        elif chunk.compression == "":
            data = chunk.data
        else:
            raise McapError(f"unsupported chunk compression {chunk.compression!r}")
        if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
            raise McapError("chunk CRC mismatch")
        pos, end = 0, len(data)
        view = memoryview(data)
        while pos < end:
            if pos + 9 > end:
                raise McapError("truncated record in chunk")
            opcode, length = _RECORD_HEAD.unpack_from(data, pos)
            pos += 9
            if pos + length > end:
                raise McapError("record runs past the end of its chunk")
            if opcode == _OP_MESSAGE:
                channel, sequence = _MESSAGE_HEAD.unpack_from(data, pos)
                yield topics.get(channel), sequence, view[pos + 22 : pos + length]
            elif opcode == _OP_CHANNEL:
                cid, _schema, n = _CHANNEL_HEAD.unpack_from(data, pos)
                topics[cid] = bytes(view[pos + 8 : pos + 8 + n]).decode("utf-8")
            pos += length

    # -- steps ---------------------------------------------------------------------------------

    def steps(self, *, start: int = 0, stop: int | None = None) -> Iterator[RawStep]:
        """Every complete step with ``start <= step <= stop``, in file order.

        Messages of steps before ``start`` are skipped without being copied. Raises LogError if
        the steps are out of order (not a log written by the recorder).
        """
        current: RawStep | None = None
        last = -1
        for topic, sequence, data in self._messages():
            if topic not in TOPICS:
                continue
            if current is not None and sequence != current.step:
                if sequence < current.step:
                    raise LogError(
                        f"{self.path}: step {sequence} comes after step "
                        f"{current.step}: the log is out of order"
                    )
                if current.complete:
                    yield current
                else:
                    self.incomplete_tail = current.step
                current = None
            if sequence < start:
                continue
            if stop is not None and sequence > stop:
                return
            if current is None:
                if sequence <= last:
                    raise LogError(f"{self.path}: step {sequence} appears twice")
                current = RawStep(sequence, {})
                last = sequence
            current.messages[topic] = bytes(data)
        if current is not None:
            if current.complete:
                yield current
            else:
                self.incomplete_tail = current.step


class Prefetch:
    """Iterate `items` in a thread of its own, up to `depth` items ahead of the consumer.

    Why: a replay's reading (file reads, chunk CRCs, slicing messages out of chunks) is ~0.1 ms
    per step of the 500-body pile, a fifth of the step it checks; file reads and ``zlib.crc32``
    release the GIL, as do the engine's kernels (``nogil``), so the two overlap. Items arrive in
    the same order; an exception raised by `items` is raised by ``next`` at the same place in
    the sequence. ``close()`` stops the thread (and closes `items`) early.
    """

    _END = object()

    def __init__(self, items, depth: int = 16) -> None:
        import queue
        import threading

        self._items = items
        self._queue: queue.Queue = queue.Queue(maxsize=depth)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="isaac-replay-reader", daemon=True)
        self._done = False
        self._thread.start()

    def _run(self) -> None:
        try:
            for item in self._items:
                if self._stop.is_set():
                    return
                self._queue.put((item, None))
            self._queue.put((self._END, None))
        except BaseException as exc:  # noqa: BLE001 - handed to the consumer, raised there
            self._queue.put((self._END, exc))

    def __iter__(self) -> Prefetch:
        return self

    def __next__(self):
        if self._done:
            raise StopIteration
        item, exc = self._queue.get()
        if item is self._END:
            self._done = True
            self._thread.join()
            if exc is not None:
                raise exc
            raise StopIteration
        return item

    def close(self) -> None:
        """Stop reading ahead; the thread ends after the item it is working on."""
        if not self._done:
            self._done = True
            self._stop.set()
            while self._thread.is_alive():
                try:  # make room for an item the thread is blocked putting
                    self._queue.get(timeout=0.05)
                except Exception:  # noqa: BLE001 - queue.Empty: it may be finishing
                    pass
            self._thread.join()
        close = getattr(self._items, "close", None)
        if close is not None:
            close()
