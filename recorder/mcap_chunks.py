"""Hand whole stretches of packed Message records (`recorder.mcap_pack`) to the mcap library.

The mcap library's `Writer.add_message` costs several microseconds of Python per message
(building a `Message`, writing it field by field into the chunk, one message-index tuple,
statistics). `RecordSink` takes a stretch of records already laid out as the file holds them
and enters it into the open chunk with one write, as if each message had gone through
`add_message` in turn: the chunk closes at exactly the message where `add_message` would have
closed it (the library checks ``count > chunk_size`` after every message), the message indexes
and the statistics (counts per channel, first and last log time) come out the same, and so does
every byte of the file (tests/recorder/test_mcap_chunks.py). Everything else (chunk
compression, Chunk, MessageIndex, ChunkIndex, Statistics records, summary, footer) stays the
library's.

How: `PackedChunkBuilder`, a `mcap._chunk_builder.ChunkBuilder` whose message indexes keep
their (log_time, offset) entries as arrays (`PackedMessageIndex` writes the same record), is
installed into the `Writer` in place of its own, and the sink updates the writer's statistics.
Both are the writer's private (name-mangled) attributes: `install` checks them once, and when
they are not what mcap 1.6 has, the sink says why (`RecordSink.fast`, `reason`) and feeds
every message through `add_message` instead (the same bytes, at the old speed).

Steps: a stretch holds whole steps, each ending with its `/stats` message (a step's `/world`
message may come in the stretch before); after the first step and every ``flush_every`` steps
the sink closes the chunk and flushes the file (`Writer.flush`), as the per-step writer did.
"""

from __future__ import annotations

import numpy as np
from mcap._chunk_builder import ChunkBuilder
from mcap.opcode import Opcode
from mcap.records import MessageIndex
from mcap.writer import Writer

from recorder.mcap_pack import index_entries, scan_records


class PackedMessageIndex(MessageIndex):
    """A chunk's MessageIndex for one channel whose entries are kept as (k, 2) uint64 arrays
    of (log_time, offset in the chunk), or lists of such pairs for single messages, in the
    order they came; `write` gives `MessageIndex.write`'s bytes."""

    def __init__(self, channel_id: int) -> None:
        super().__init__(channel_id=channel_id, records=[])
        self.parts: list = []

    def append_one(self, log_time: int, offset: int) -> None:
        if not self.parts or not isinstance(self.parts[-1], list):
            self.parts.append([])
        self.parts[-1].append((log_time, offset))

    def write(self, stream) -> None:
        parts = [p if isinstance(p, np.ndarray) else np.array(p, dtype="<u8") for p in self.parts]
        entries = np.concatenate(parts) if parts else np.empty((0, 2), dtype="<u8")
        entries = entries.astype("<u8", copy=False)
        stream.start_record(Opcode.MESSAGE_INDEX)
        stream.write2(self.channel_id)
        stream.write4(entries.nbytes)
        stream.write(entries.tobytes())
        stream.finish_record()


class PackedChunkBuilder(ChunkBuilder):
    """mcap's ChunkBuilder taking whole stretches of Message records (`add_records`) as well as
    single messages (`add_message`, for the /world message of the per-record path and the
    Foxglove channel), keeping the chunk's bookkeeping exactly as `add_message` keeps it."""

    def _index(self, channel_id: int) -> PackedMessageIndex:
        index = self.message_indices.get(channel_id)
        if index is None:
            index = self.message_indices[channel_id] = PackedMessageIndex(channel_id)
        return index

    def add_message(self, message) -> None:
        if self.num_messages == 0:
            self.message_start_time = message.log_time
        else:
            self.message_start_time = min(self.message_start_time, message.log_time)
        self.message_end_time = max(self.message_end_time, message.log_time)
        self._index(message.channel_id).append_one(message.log_time, self.record_writer.count)
        self.num_messages += 1
        message.write(self.record_writer)

    def add_records(self, data, order, counts, entries, lt_min: int, lt_max: int) -> None:
        """Whole Message records ``data`` (bytes-like), whose channels are ``order`` in the
        order they first appear, ``counts`` records each, their message-index entries
        ``entries`` grouped in that order (`recorder.mcap_pack.index_entries`, offsets from
        this chunk's current end), log times from ``lt_min`` to ``lt_max``."""
        if self.num_messages == 0:
            self.message_start_time = lt_min
        else:
            self.message_start_time = min(self.message_start_time, lt_min)
        self.message_end_time = max(self.message_end_time, lt_max)
        at = 0
        for ch, k in zip(order.tolist(), counts.tolist()):
            self._index(ch).parts.append(entries[at : at + k])
            at += k
        self.num_messages += at
        self.record_writer.write(data)


def install(writer: Writer) -> str | None:
    """Put a `PackedChunkBuilder` into a fresh ``writer`` (before `Writer.start`); None when
    done, else why not (the writer is then left as it was)."""
    builder = getattr(writer, "_Writer__chunk_builder", None)
    stats = getattr(writer, "_Writer__statistics", None)
    if type(builder) is not ChunkBuilder:
        return "mcap's Writer has no ChunkBuilder where mcap 1.6 keeps it (chunking off?)"
    if builder.num_messages or builder.count:
        return "the mcap Writer has already written into its chunk"
    if not all(
        hasattr(stats, key)
        for key in (
            "message_count",
            "message_start_time",
            "message_end_time",
            "channel_message_counts",
        )
    ):
        return "mcap's Writer keeps no Statistics where mcap 1.6 does"
    size = getattr(writer, "_Writer__chunk_size", None)
    finalize = getattr(writer, "_Writer__finalize_chunk", None)
    if not isinstance(size, int) or not callable(finalize):
        return "mcap's Writer has no chunk size or chunk finalizer where mcap 1.6 has them"
    writer._Writer__chunk_builder = PackedChunkBuilder()
    return None


class RecordSink:
    """Enters Message records into an mcap `Writer`, stretch by stretch (`append`) or one
    message at a time (`add`, `end_step`), closing its chunk and flushing after the first step
    and every ``flush_every`` steps.

    writer: a fresh `mcap.writer.Writer` (not started); stats_channel: the `/stats` channel's
    id (the last message of every step in a stretch). fast: the stretches go into the chunk
    whole (`install` succeeded); else ``reason`` says why not and they go message by message.
    """

    def __init__(self, writer: Writer, stats_channel: int | None, flush_every: int) -> None:
        self.writer = writer
        self.stats_channel = stats_channel
        self.flush_every = flush_every
        self.steps = 0  # steps entered: a chunk closes after the first and every flush_every
        self.reason = install(writer)
        self.fast = self.reason is None

    def add(self, channel: int, log_time: int, data, step: int) -> None:
        """One message through `Writer.add_message` (sequence = step, publish = log time)."""
        self.writer.add_message(channel, log_time, data, log_time, step)

    def end_step(self) -> None:
        """A step's messages are all in: close the chunk and flush when one is due."""
        self.steps += 1
        if self.steps == 1 or self.steps % self.flush_every == 0:
            self.writer.flush()

    def append(self, buf: np.ndarray, start: int = 0, end: int | None = None) -> tuple[int, int]:
        """The Message records in ``buf[start:end]`` (uint8): whole steps, each ending with its
        `/stats` message, a step's `/world` message may come first. Returns (steps, the last
        one's sequence number, -1 for none)."""
        end = len(buf) if end is None else end
        if end <= start:
            return 0, -1
        starts, ends, channel, sequence, log_time = scan_records(buf, start, end)
        steps = int(np.count_nonzero(channel == self.stats_channel))
        last = int(sequence[-1])
        if not self.fast:
            with memoryview(buf) as view:
                for r in range(len(starts)):
                    data = view[starts[r] + 31 : ends[r]]
                    self.add(int(channel[r]), int(log_time[r]), data, int(sequence[r]))
                    if channel[r] == self.stats_channel:
                        self.end_step()
            return steps, last
        self._append_fast(buf, starts, ends, channel, log_time)
        return steps, last

    def _append_fast(self, buf, starts, ends, channel, log_time) -> None:
        w = self.writer
        builder: PackedChunkBuilder = w._Writer__chunk_builder
        chunk_size = w._Writer__chunk_size
        # the messages after which a chunk is closed and the file flushed: the /stats messages
        # that end the first step and every flush_every-th
        step_ends = np.flatnonzero(channel == self.stats_channel)
        counts = self.steps + 1 + np.arange(len(step_ends))
        flushes = step_ends[(counts == 1) | (counts % self.flush_every == 0)]
        self.steps += len(step_ends)
        total = len(starts)
        cuts = [int(x) for x in flushes]
        if not cuts or cuts[-1] != total - 1:
            cuts.append(total - 1)
        flush_at = set(int(x) for x in flushes)
        i = 0
        view = memoryview(buf)
        for cut in cuts:
            while i <= cut:
                # add_message closes the chunk after the first message that takes it past
                # chunk_size: the first j >= i with count + (ends[j] - starts[i]) > chunk_size
                room = chunk_size - builder.count
                j = max(i, int(np.searchsorted(ends, starts[i] + room, side="right")))
                last = min(j, cut)
                self._enter(builder, view, starts, ends, channel, log_time, i, last + 1)
                if last == j:
                    w._Writer__finalize_chunk()
                i = last + 1
            if cut in flush_at:
                w.flush()

    def _enter(self, builder, view, starts, ends, channel, log_time, i, j) -> None:
        """Records i .. j - 1 into the open chunk, with the writer's statistics."""
        order, counts, entries, lt_min, lt_max = index_entries(
            channel, log_time, starts, i, j, builder.count
        )
        lt_min, lt_max = int(lt_min), int(lt_max)
        builder.add_records(view[starts[i] : ends[j - 1]], order, counts, entries, lt_min, lt_max)
        stats = self.writer._Writer__statistics
        if stats.message_count == 0:
            stats.message_start_time = lt_min
        else:
            stats.message_start_time = min(stats.message_start_time, lt_min)
        stats.message_end_time = max(stats.message_end_time, lt_max)
        per_channel = stats.channel_message_counts
        for c, k in zip(order.tolist(), counts.tolist()):
            per_channel[c] += k
        stats.message_count += j - i
