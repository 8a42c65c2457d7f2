"""Read a log's steps as raw message payloads, in bulk, for the replay comparison.

`recorder.reader.LogReader` decodes every message into numpy arrays; replay does not need that:
it compares the logged payload bytes with the bytes the recorder's own encoders make from the
re-simulated record, and decodes a message only when the bytes differ (or to start from a keyframe).
So the file is walked one *chunk* at a time (`recorder.mcap_records.McapScan`: each chunk read,
decompressed and CRC-checked in one call each, its records walked with ``struct`` offsets), and
message payloads are handed out as bytes: about 0.13 ms per step of the 500-body pile (163 kB a
step, from the page cache), against 1.5 to 3 ms to simulate the step.

Every step is checked as it comes by `recorder.integrity.StepReader` (O(1) a step: the step
expected next, the topics seen): a step counts only when its ``/bodies``, ``/contacts`` and
``/stats`` messages are all there, steps must follow one another, and reading stops at the first
damaged record, missing, repeated or incomplete step. After `steps` has run to its end, a closed
log's summary and ``isaac.end`` metadata are compared with what was read; ``RawLog.damage`` then
holds the first problem (a `recorder.integrity.Damage`: what, the first step not read whole,
the byte offset) and ``RawLog.complete`` says whether every step the log claims was read.

The header (metadata, embedded scene) is read and validated by `LogReader`.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

from isaac.errors import LogError
from recorder.integrity import STEP_TOPICS, TOPICS, Damage, StepReader
from recorder.mcap_writer import READ_FORMAT_VERSIONS
from recorder.reader import LogReader

__all__ = ["STEP_TOPICS", "TOPICS", "Damage", "Prefetch", "RawLog", "RawStep"]


@dataclass
class RawStep:
    """One logged step: its index and the raw payload of each of its messages.

    messages: topic -> payload bytes, for the topics present at this step (``/world`` only at
        the first step and when a body entered or left).
    """

    step: int
    messages: dict

    @property
    def complete(self) -> bool:
        return all(t in self.messages for t in STEP_TOPICS)


class RawLog:
    """An ISAAC MCAP log opened for replay: its validated header and its steps as raw payloads.

    Raises LogError (one line) if the path is not a regular file, or the file is empty, not
    MCAP, or not an ISAAC log. After `steps()`: ``damage`` (a `Damage` or None), ``end`` (the
    ``isaac.end`` metadata, None when the file was never closed), ``incomplete_tail`` (a
    not-closed log's last step, only partly written, or None), ``claimed_steps`` and
    ``claimed_last`` (what the log claims: its ``isaac.end`` when closed, the steps its readable
    chunks hold otherwise), ``read_through`` (the reading reached the end of the file or the
    first damage, rather than stopping at ``stop``) and ``complete`` (read through, closed, no
    damage: every step the log claims was there, whole and intact).
    """

    def __init__(self, path: str) -> None:
        self.path = str(path)
        self.header = LogReader(self.path)  # metadata, scene text, settings; LogError if bad
        self.metadata: dict[str, str] = self.header.metadata
        self.closed_cleanly: bool = self.header.closed_cleanly
        self.damage: Damage | None = None
        self.end: dict[str, str] | None = None
        self.incomplete_tail: int | None = None
        self.claimed_steps: int | None = None
        self.claimed_last: int | None = None
        self.read_through = False
        self.complete = False
        version = self.metadata.get("format_version")
        if version not in READ_FORMAT_VERSIONS:
            raise LogError(
                f"{self.path}: log format version {version!r} is not supported "
                f"(this version reads {', '.join(map(repr, READ_FORMAT_VERSIONS))})"
            )
        self.format_version = version  # "1": /contacts one row per point; "2": per manifold

    @property
    def scene_text(self) -> str:
        return self.header.scene_text

    def steps(self, *, start: int = 0, stop: int | None = None) -> Iterator[RawStep]:
        """Every complete step with ``start <= step <= stop``, in file order, up to the first
        damage. Messages of steps before ``start`` are skipped without being copied."""
        reader = StepReader(self.path, closed=self.closed_cleanly)
        inner = reader.steps()
        try:
            for step, messages in inner:
                if step < start:
                    continue
                if stop is not None and step > stop:
                    return
                yield RawStep(step, {t: bytes(v) for t, v in messages.items()})
        finally:
            inner.close()
            # the steps' damage first (it names a step), else the header's (the metadata
            # disagreeing with the embedded scene: recorder.integrity.check_metadata)
            self.damage = reader.damage if reader.damage is not None else self.header.header_damage
            self.end = reader.end
            self.incomplete_tail = reader.tail
            self.claimed_steps = reader.claimed_steps
            self.claimed_last = reader.claimed_last
            self.read_through = reader.ended
            self.complete = reader.complete and self.damage is None
            self.closed_cleanly = reader.closed


class Prefetch:
    """Iterate `items` in a thread of its own, up to `depth` groups of items ahead of the
    consumer.

    Why: a replay's reading (file reads, chunk CRCs, slicing messages out of chunks) is ~0.1 ms
    per step of the 500-body pile, a fifth of the step it checks; file reads and ``zlib.crc32``
    release the GIL, as do the engine's kernels (``nogil``), so the two overlap. Items arrive in
    the same order; an exception raised by `items` is raised by ``next`` at the same place in
    the sequence. ``close()`` stops the thread (and closes `items`) early.
    """

    _END = object()

    def __init__(self, items, depth: int = 16, *, group: int = 1, weigh=None, budget=0) -> None:
        """depth: how many groups may wait; group: items handed over at once, at most (one
        queue hand-over costs some microseconds, a small scene's step to read about 8); weigh,
        budget: a group is handed over early once its items weigh ``budget`` (``weigh(item)``,
        say bytes), so that at most about ``depth`` budgets of large items wait."""
        import queue
        import threading

        self._items = items
        self._group = max(1, group)
        self._weigh = weigh
        self._budget = budget
        self._queue: queue.Queue = queue.Queue(maxsize=depth)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="isaac-replay-reader", daemon=True)
        self._ahead: list = []  # the group being handed out, reversed
        # what the thread ended with (_END, or the exception it raised) once its last group
        # came; None while it reads
        self._end = None
        self._thread.start()

    def _run(self) -> None:
        pending: list = []
        weight = 0
        try:
            for item in self._items:
                if self._stop.is_set():
                    return
                pending.append(item)
                if self._weigh is not None:
                    weight += self._weigh(item)
                if len(pending) >= self._group or (self._budget and weight >= self._budget):
                    self._queue.put((pending, None))
                    pending, weight = [], 0
            self._queue.put((pending, self._END))
        except BaseException as exc:  # noqa: BLE001 - handed to the consumer, raised there
            self._queue.put((pending, exc))

    def __iter__(self) -> Prefetch:
        return self

    def __next__(self):
        while not self._ahead:
            if self._end is not None:  # the thread's last group was handed out
                end, self._end = self._end, self._END
                if end is not self._END:
                    raise end  # (once: the calls after it stop)
                raise StopIteration
            group, end = self._queue.get()
            self._ahead = group[::-1]
            if end is not None:
                self._thread.join()
                self._end = end
        return self._ahead.pop()

    def close(self) -> None:
        """Stop reading ahead; the thread ends after the item it is working on."""
        self._ahead = []
        if self._end is None:  # still reading
            self._end = self._END  # (what `next` says from now on)
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
