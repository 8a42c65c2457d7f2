"""Run one log writer (MCAP or Rerun) in a child process, fed step by step through shared memory.

Why a process: a step's record is 0.1 to several MB. Encoding, hashing and writing it in the
simulating process cost 40-90 % on top of the 500- and 2,000-body piles, and a writer *thread*
did not hide it: the mcap and Rerun libraries run Python code that holds the GIL, so the engine
waited for the writer at every kernel boundary. In a child process all of that runs beside the
engine. The engine's share of a step is one compiled copy of the record into shared memory
(`recorder.pack`, which also checks every float for NaN and infinity) and, every NOTIFY_EVERY
steps, one pipe write; the bytes of the files are the same as when written in-process.

Transport (both ends in this module):
- ring: shared memory (`ring_bytes_for`: 4-64 MiB; an anonymous ``memfd``, or an unlinked
  temporary file where memfd is missing), handed to the child as a file descriptor. Each step is one frame (`pack`)
  written contiguously at the next free offset, wrapping to 0 when it does not fit before the
  end. A frame larger than the ring travels inline in the command pipe instead.
- commands, parent -> child, each a 25-byte header ``<cQQQ`` (several in one ``os.write``):
  ``C`` config (pickled dict follows, first message), ``F`` frame (offset, length, end),
  ``I`` inline frame (length; the frame follows), ``S`` sync (answered once every earlier
  frame is written), ``Z`` close (JSON arguments follow).
- replies, child -> parent, 9-byte header ``<cQ``: ``K`` ready, ``R`` frame released (end),
  ``S`` synced (its number), ``D`` closed (JSON ``{"path": ...}`` follows), ``E`` failed (UTF-8 message follows).
  The parent waits only when the ring is full, on `drain` and at close.
- the child ignores SIGINT and sits in its own process group: Ctrl-C reaches the run loop, which
  stops between steps and closes the files through ``Z``. When the parent dies without closing
  (SIGKILL), the child sees the command pipe end, writes out every step it has received and
  leaves the ``.partial`` file unfinished, as an in-process writer would have after a flush.
"""

from __future__ import annotations

import json
import mmap
import os
import pickle
import select
import signal
import struct
import subprocess
import sys
import tempfile

import numpy as np

from isaac.errors import LogError
from isaac.records import Contacts, StepRecord

# shared memory per writer: about RING_FRAMES frames of the scene's size, within these bounds;
# small enough to stay in the last-level cache, mapped pre-faulted (a fresh page costs a fault
# in each process: measured 3x slower writes over a cold 32 MiB ring)
RING_FRAMES = 16
RING_MIN, RING_MAX = 4 << 20, 64 << 20

STAT_KEYS = ("kinetic_energy", "potential_energy", "total_energy", "linear_momentum_x",
             "linear_momentum_y", "angular_momentum", "contact_count", "max_depth",
             "max_impulse")

# frames are announced to the child in batches: one wake-up per NOTIFY_EVERY steps, not per
# step (a cross-CPU wake-up measured 10-20 us on this VM); a SIGKILLed parent loses at most
# the unannounced ones, which no flush had covered yet either
NOTIFY_EVERY = 8

_COMMAND = struct.Struct("<cQQQ")
_REPLY = struct.Struct("<cQ")
_HEAD = struct.Struct("<qdQQ" + "d" * len(STAT_KEYS))  # step, time, n, m, stats

# (field, dtype, values per row): bodies (n rows), then contact rows (m rows); every block
# starts on an 8-byte boundary so the child's views are aligned
_BODY_FIELDS = (("position", "<f8", 2), ("angle", "<f8", 1), ("velocity", "<f8", 2),
                ("angular_velocity", "<f8", 1), ("exists", "|b1", 1))
_CONTACT_FIELDS = (("substep", "<i4", 1), ("a", "<i4", 1), ("b", "<i4", 1), ("feature", "<i4", 1),
                   ("slot", "<i4", 1), ("point", "<f8", 2), ("normal", "<f8", 2),
                   ("depth", "<f8", 1), ("push_a", "<f8", 2), ("push_b", "<f8", 2),
                   ("impulse", "<f8", 1), ("tangent_impulse", "<f8", 1),
                   ("restitution", "<f8", 1))


def _pad8(n: int) -> int:
    return (n + 7) & ~7


_ROW_BYTES = np.array([per * np.dtype(dtype).itemsize for fields in (_BODY_FIELDS, _CONTACT_FIELDS)
                       for _name, dtype, per in fields], dtype=np.int64)
_CONTACT_ROW_BYTES = tuple(int(x) for x in _ROW_BYTES[len(_BODY_FIELDS):])


def _blocks(n: int, m: int):
    """[(owner, field, dtype, per-row, rows, offset, nbytes)] of a frame, and its total size."""
    out = []
    off = _HEAD.size
    for fields, rows, owner in ((_BODY_FIELDS, n, "body"), (_CONTACT_FIELDS, m, "contact")):
        for name, dtype, per in fields:
            nbytes = rows * per * np.dtype(dtype).itemsize
            out.append((owner, name, dtype, per, rows, off, nbytes))
            off += _pad8(nbytes)
    return out, off


def frame_size(record: StepRecord) -> int:
    """Bytes of `record`'s frame (a multiple of 8)."""
    n, m = int(record.angle.shape[0]), len(record.contacts)
    size = _HEAD.size + sum(_pad8(int(b) * n) for b in _ROW_BYTES[:len(_BODY_FIELDS)])
    return size + sum(_pad8(b * m) for b in _CONTACT_ROW_BYTES)


def pack_into(buf: memoryview, offset: int, record: StepRecord, stats: dict) -> int:
    """Write `record` and the numeric `stats` as a frame at ``buf[offset:]``; returns its size."""
    n, m = int(record.angle.shape[0]), len(record.contacts)
    blocks, size = _blocks(n, m)
    _HEAD.pack_into(buf, offset, int(record.step), float(record.time), n, m,
                    *(float(stats[k]) for k in STAT_KEYS))
    c = record.contacts
    for owner, name, dtype, _per, _rows, off, nbytes in blocks:
        if nbytes:
            arr = np.ascontiguousarray(getattr(record if owner == "body" else c, name),
                                       dtype=dtype)
            buf[offset + off: offset + off + nbytes] = memoryview(arr).cast("B")
    return size


def pack(record: StepRecord, stats: dict) -> bytes:
    """`record` and `stats` as one frame (bytes)."""
    buf = bytearray(frame_size(record))
    pack_into(memoryview(buf), 0, record, stats)
    return bytes(buf)


def unpack(data: bytes) -> tuple[StepRecord, dict]:
    """The record and stats of a frame made by `pack_into` (arrays are read-only views)."""
    head = _HEAD.unpack_from(data, 0)
    step, time, n, m = head[:4]
    stats = dict(zip(STAT_KEYS, head[4:]))
    stats["contact_count"] = int(stats["contact_count"])
    blocks, _ = _blocks(n, m)
    arrays = {}
    for _owner, name, dtype, per, rows, off, _nbytes in blocks:
        arr = np.frombuffer(data, dtype=dtype, count=rows * per, offset=off)
        arrays[name] = arr.reshape(rows, per) if per > 1 else arr
    contacts = Contacts(*(arrays[name] for name, _, _ in _CONTACT_FIELDS))
    record = StepRecord(step=step, time=time, contacts=contacts,
                        **{name: arrays[name] for name, _, _ in _BODY_FIELDS})
    return record, stats


def _all_finite(record: StepRecord) -> bool:
    c = record.contacts
    return all(bool(np.isfinite(a).all()) for a in (
        record.position, record.angle, record.velocity, record.angular_velocity, c.point,
        c.normal, c.depth, c.push_a, c.push_b, c.impulse, c.tangent_impulse, c.restitution))


def model_table(model) -> dict:
    """What a writer needs of the model, as plain lists and arrays (pickled to the child)."""
    return {
        "names": [str(x) for x in model.names],
        **{key: np.asarray(getattr(model, key)) for key in (
            "vertices_local", "vertex_count", "mass", "inertia", "restitution", "friction",
            "concrete")},
    }


def ring_bytes_for(n_bodies: int) -> int:
    """Ring size for a scene of `n_bodies`: RING_FRAMES frames of ~3 contact rows per body."""
    estimate = _blocks(n_bodies, 3 * n_bodies)[1]
    size = min(max(RING_FRAMES * estimate, RING_MIN), RING_MAX)
    return (size + mmap.PAGESIZE - 1) // mmap.PAGESIZE * mmap.PAGESIZE


def _map(fd: int, size: int) -> mmap.mmap:
    flags = mmap.MAP_SHARED | getattr(mmap, "MAP_POPULATE", 0)
    return mmap.mmap(fd, size, flags=flags)


def _shared_memory(size: int) -> int:
    """A file descriptor of `size` bytes of memory the child can map (inheritable)."""
    if hasattr(os, "memfd_create"):
        fd = os.memfd_create("isaac-recorder", 0)
    else:  # pragma: no cover - non-Linux
        f = tempfile.TemporaryFile()
        fd = os.dup(f.fileno())
        f.close()
    os.ftruncate(fd, size)
    return fd


class WriterProcess:
    """A log writer running in a child process; same calls as the in-process writers.

    kind: "mcap" (config: path, model, scene {name, dt}, scene_text, metadata, flush_every,
        compression, foxglove) or "rerun" (config: path, model, scene, impulse_scale).
    """

    def __init__(self, kind: str, path: str, config: dict, *, ring_bytes: int | None = None):
        self.path = str(path)
        self.partial_path = self.path + ".partial"
        self.kind = kind
        try:  # say at once when the file cannot be written, not at the first step
            open(self.partial_path, "wb").close()
        except OSError as exc:
            raise LogError(f"cannot write {self.partial_path}: {exc.strerror}") from exc
        if ring_bytes is None:
            ring_bytes = ring_bytes_for(len(config["model"]["names"]))
        self.capacity = ring_bytes
        self.head = 0  # bytes handed out (monotonic, wrap padding included)
        self.released = 0  # end of the last frame the child has copied out
        self._replies = bytearray()
        self._closed_reply: dict | None = None
        self._failed: str | None = None
        self._ready = False
        self._syncs_sent = 0
        self._pending = bytearray()  # frame notices not sent yet
        self._synced = 0
        self._eof = False
        self._finished = False
        ring_fd = _shared_memory(ring_bytes)
        cmd_r, self._cmd = os.pipe()
        self._rep, rep_w = os.pipe()
        self._stderr = tempfile.TemporaryFile()
        root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(p for p in (root, env.get("PYTHONPATH")) if p)
        try:
            self.proc = subprocess.Popen(
                [sys.executable, "-m", "recorder.writer_process", str(cmd_r), str(rep_w),
                 str(ring_fd), str(ring_bytes)],
                pass_fds=(cmd_r, rep_w, ring_fd), stdin=subprocess.DEVNULL,
                stdout=subprocess.DEVNULL, stderr=self._stderr, env=env, process_group=0)
            self._ring = _map(ring_fd, ring_bytes)
        finally:
            for fd in (cmd_r, rep_w, ring_fd):
                os.close(fd)
        self._view = memoryview(self._ring)
        self._ring_f8 = np.frombuffer(self._ring, dtype=np.float64)
        self._ring_i4 = np.frombuffer(self._ring, dtype=np.int32)
        self._ring_u8 = np.frombuffer(self._ring, dtype=np.uint8)
        os.set_blocking(self._rep, False)
        payload = pickle.dumps({"kind": kind, "path": self.path, **config},
                               protocol=pickle.HIGHEST_PROTOCOL)
        self._send(b"C", len(payload), payload=payload)

    # -- parent side -------------------------------------------------------------------------
    checks_finite = True  # `write` refuses a record holding a NaN or an infinity

    def write(self, record: StepRecord, stats: dict) -> bool:
        """Hand one step to the child (waits only while the ring is full).

        Returns False, sending nothing, when a float of the record is NaN or infinite (the
        caller says which: `recorder.recording.check_finite`).
        """
        size = frame_size(record)
        if size > self.capacity:
            if not _all_finite(record):
                return False
            self._notify()
            data = pack(record, stats)
            self._send(b"I", len(data), payload=data)
            return True
        pos = self.head % self.capacity
        head = self.head
        if pos + size > self.capacity:
            head += self.capacity - pos
            pos = 0
        if head + size - self.released > self.capacity:
            self._notify()
            while head + size - self.released > self.capacity:
                self._pump(block=True)
        if self._compiled_pack(pos, record, stats) >= 0:
            return False
        self.head = head + size
        self._pending += _COMMAND.pack(b"F", pos, size, self.head)
        if len(self._pending) >= NOTIFY_EVERY * _COMMAND.size:
            self._notify()
        return True

    def _notify(self) -> None:
        """Send the pending frame notices (one pipe write, one wake-up of the child) and read
        what the child said meanwhile."""
        if self._pending:
            data, self._pending = bytes(self._pending), bytearray()
            self._send_raw(data)
        self._pump(block=False)

    def _compiled_pack(self, pos: int, record: StepRecord, stats: dict) -> int:
        from recorder.pack import pack_frame

        n, m = int(record.angle.shape[0]), len(record.contacts)
        _HEAD.pack_into(self._view, pos, int(record.step), float(record.time), n, m,
                        *(float(stats[k]) for k in STAT_KEYS))
        c = record.contacts
        return pack_frame(self._ring_f8, self._ring_i4, self._ring_u8, pos, _HEAD.size,
                          _ROW_BYTES, n, m, record.position, record.angle, record.velocity,
                          record.angular_velocity, record.exists, c.substep, c.a, c.b,
                          c.feature, c.slot, c.point, c.normal, c.depth, c.push_a, c.push_b,
                          c.impulse, c.tangent_impulse, c.restitution)

    def wait_ready(self) -> None:
        """Block until the child has started and opened its file (start-up is ~0.3-1 s)."""
        while not self._ready:
            self._pump(block=True)

    def drain(self) -> None:
        """Block until the child has written every step handed to it so far."""
        self._notify()
        self._syncs_sent += 1
        self._send(b"S", self._syncs_sent)
        while self._synced < self._syncs_sent:
            self._pump(block=True)

    def close(self, *, complete: bool = True, stopped_at: int | None = None,
              reason: str | None = None) -> str:
        """Finish the file in the child (every step sent is written) and rename it."""
        if self._finished:
            return self.path
        self._finished = True
        try:
            self._notify()
            args = json.dumps({"complete": complete, "stopped_at": stopped_at,
                               "reason": reason}).encode()
            self._send(b"Z", len(args), payload=args)
            while self._closed_reply is None:
                self._pump(block=True)
        finally:
            self._shutdown()
        return self._closed_reply["path"]

    def abandon(self) -> None:
        """Stop without finishing: the child writes out what it has and keeps the .partial."""
        if not self._finished:
            self._finished = True
            try:
                self._notify()
            except LogError:
                pass
            self._shutdown()

    def _send(self, kind: bytes, a: int = 0, b: int = 0, c: int = 0, payload: bytes = b""):
        self._send_raw(_COMMAND.pack(kind, a, b, c) + payload)

    def _send_raw(self, data: bytes) -> None:
        data = memoryview(data)
        try:
            while data:
                data = data[os.write(self._cmd, data):]
        except BrokenPipeError:
            self._pump(block=True)  # raises with the child's own message
            raise LogError(f"writing {self.partial_path} failed: the writer process is gone")

    def _pump(self, *, block: bool) -> None:
        """Read the child's replies; with ``block``, wait for at least one. Raises LogError
        when the child failed or exited."""
        while True:
            if block:
                select.select([self._rep], [], [])
            try:
                chunk = os.read(self._rep, 65536)
            except BlockingIOError:
                chunk = None
            if chunk == b"":
                self._eof = True
            elif chunk:
                self._replies += chunk
            got = self._parse()
            if self._failed is not None:
                raise LogError(f"writing {self.partial_path} failed: {self._failed}")
            if self._eof and self._closed_reply is None:
                raise LogError(f"writing {self.partial_path} failed: the writer process "
                               f"stopped{self._child_reason()}")
            if got or not block:
                return

    def _parse(self) -> bool:
        buf, got, pos = self._replies, False, 0
        while len(buf) - pos >= _REPLY.size:
            kind, value = _REPLY.unpack_from(buf, pos)
            body_len = value if kind in (b"D", b"E") else 0
            if len(buf) - pos - _REPLY.size < body_len:
                break
            body = bytes(buf[pos + _REPLY.size: pos + _REPLY.size + body_len])
            pos += _REPLY.size + body_len
            got = True
            if kind == b"R":
                self.released = max(self.released, value)
            elif kind == b"K":
                self._ready = True
            elif kind == b"S":
                self._synced = max(self._synced, value)
            elif kind == b"D":
                self._closed_reply = json.loads(body)
            elif kind == b"E":
                self._failed = body.decode("utf-8", "replace")
        del buf[:pos]
        return got

    def _child_reason(self) -> str:
        code = self.proc.poll()
        if code is None:
            try:
                code = self.proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                return ""
        self._stderr.seek(0)
        lines = [ln for ln in self._stderr.read().decode("utf-8", "replace").splitlines()
                 if ln.strip()]
        last = f": {lines[-1].strip()}" if lines else ""
        return f" (exit code {code}){last}"

    def _shutdown(self) -> None:
        os.close(self._cmd)
        try:
            self.proc.wait(timeout=60)
        except subprocess.TimeoutExpired:  # pragma: no cover - a stuck child
            self.proc.kill()
            self.proc.wait()
        os.close(self._rep)
        del self._ring_f8, self._ring_i4, self._ring_u8
        self._view.release()
        self._ring.close()
        self._stderr.close()


# -- child side --------------------------------------------------------------------------------
class _Namespace:
    def __init__(self, **kw) -> None:
        self.__dict__.update(kw)


def _make_writer(config: dict):
    model = _Namespace(**config["model"])
    scene = _Namespace(name=config["scene"]["name"], world=_Namespace(dt=config["scene"]["dt"]))
    if config["kind"] == "mcap":
        from recorder.mcap_writer import McapLogWriter
        scene_encoder = None
        if config.get("foxglove"):
            from recorder.foxglove import SceneEncoder
            scene_encoder = SceneEncoder(model, **config["foxglove"])
        return McapLogWriter(config["path"], model, scene, config["scene_text"],
                             flush_every=config["flush_every"],
                             compression=config["compression"], foxglove=scene_encoder,
                             metadata=config["metadata"])
    from recorder.rerun_writer import RerunLogWriter
    return RerunLogWriter(config["path"], model, scene, impulse_scale=config["impulse_scale"])


def _read_exact(stream, n: int) -> bytes | None:
    data = stream.read(n)
    return data if len(data) == n else None


def child_main(argv: list[str]) -> int:
    """The child: read commands, write the log; see the module docstring for the protocol."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    from isaac.tuning import reuse_large_buffers
    reuse_large_buffers()  # a step's messages are 100 kB and more (see isaac.tuning)
    cmd_fd, rep_fd, ring_fd, ring_bytes = (int(x) for x in argv)
    commands = os.fdopen(cmd_fd, "rb", buffering=1 << 16)
    ring = _map(ring_fd, ring_bytes)
    os.close(ring_fd)

    def reply(kind: bytes, value: int = 0, body: bytes = b"") -> None:
        data = memoryview(_REPLY.pack(kind, value) + body)
        while data:
            data = data[os.write(rep_fd, data):]

    writer = None
    try:
        head = _read_exact(commands, _COMMAND.size)
        if head is None:
            return 0
        kind, length, _, _ = _COMMAND.unpack(head)
        if kind != b"C":
            raise LogError("writer process: expected its configuration first")
        writer = _make_writer(pickle.loads(_read_exact(commands, length)))
        reply(b"K")
        while True:
            head = _read_exact(commands, _COMMAND.size)
            if head is None:  # the parent is gone without closing: keep what arrived
                writer.abandon()
                return 0
            kind, a, b, c = _COMMAND.unpack(head)
            if kind == b"F":
                data = ring[a:a + b]  # a copy: the slot goes back to the parent at once
                reply(b"R", c)
                writer.write(*unpack(data))
            elif kind == b"I":
                writer.write(*unpack(_read_exact(commands, a)))
            elif kind == b"S":
                reply(b"S", a)
            elif kind == b"Z":
                args = json.loads(_read_exact(commands, a))
                path = writer.close(**args)
                body = json.dumps({"path": path}).encode()
                reply(b"D", len(body), body)
                return 0
            else:
                raise LogError(f"writer process: unknown command {kind!r}")
    except BrokenPipeError:  # the parent went away while we replied
        if writer is not None:
            writer.abandon()
        return 0
    except BaseException as exc:  # noqa: BLE001 - reported to the parent in one line
        msg = str(exc) if isinstance(exc, LogError) else f"{type(exc).__name__}: {exc}"
        try:
            body = " ".join(msg.split()).encode()
            reply(b"E", len(body), body)
        except OSError:
            pass
        if writer is not None:
            try:
                writer.abandon()
            except Exception:  # noqa: BLE001 - best effort; the error is already reported
                pass
        return 1


if __name__ == "__main__":
    sys.exit(child_main(sys.argv[1:]))
