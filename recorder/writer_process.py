"""Run one log writer (MCAP or Rerun) in a child process, fed step by step through shared memory.

(`RerunSendProcess`, at the end of the parent side, is the other kind of child: the Rerun
sender, fed drawn batches through a pipe; `isaac run --rrd` uses it unless ``--offload`` is
process or none. Its protocol is in `recorder.rerun_send`.)

Why a process: a step's record is 0.1 to several MB. Encoding, hashing and writing it in the
simulating process cost 40-90 % on top of the 500- and 2,000-body piles, and a writer *thread*
did not hide it: the mcap and Rerun libraries run Python code that holds the GIL, so the engine
waited for the writer at every kernel boundary. In a child process all of that runs beside the
engine. The engine's share of a step is one compiled copy of the record into shared memory
(`recorder.pack`, which also checks every float for NaN and infinity and sums the /stats
values) and, every NOTIFY_EVERY steps, one pipe write; the files' bytes are the same as when
written in-process.

Transport (both ends in this module):
- ring: shared memory (`ring_bytes_for`: 4-64 MiB; an anonymous ``memfd``, or an unlinked
  temporary file where memfd is missing), handed to the child as a file descriptor when it is
  started (`recorder.spawn`: `isaac run` starts it before it imports the engine, the ring still
  empty) and sized by the parent once it knows the scene; the child maps it when its
  configuration, which gives the size, arrives. Each step is one frame written contiguously
  at the next free offset, wrapping to 0 when it does not fit before the end. A frame larger
  than the ring travels inline in the command pipe instead.
  MCAP frames (`recorder.frames`: `pack`, `Frame`): a head with the /stats values, then the encoded
  `/bodies` and `/contacts` messages, which the mcap library takes as they are. Rerun frames
  (`recorder.pack.pack_rerun`, `read_rerun_frame`): only what the recording draws, as raw
  native-endian arrays, from which the child computes each step's outlines and arrows in place
  (`RerunLogWriter.append`); decoding protobuf back into a record had cost that child a
  quarter of its time.
- commands, parent -> child, each a 25-byte header ``<cQQQ`` (several in one ``os.write``):
  ``C`` config (pickled dict follows, first message; its ``ring_bytes`` is the ring's size),
  ``F`` frame (offset, length, end),
  ``B`` Message records of whole steps (offset, length, end; MCAP, `recorder.mcap_pack`),
  ``I`` inline frame (length; the frame follows), ``J`` inline records (length; they follow),
  ``S`` sync (number, settle flag; answered once every earlier frame is taken), ``Z`` close
  (JSON arguments follow).
- replies, child -> parent, 9-byte header ``<cQ``: ``K`` ready, ``R`` frame released (end),
  ``S`` synced (its number), ``D`` closed (JSON ``{"path": ...}`` follows), ``E`` failed
  (UTF-8 message follows).
  The parent waits only when the ring is full, on `drain` and at close.
- the child ignores SIGINT and sits in its own process group: Ctrl-C reaches the run loop, which
  stops between steps and closes the files through ``Z``. When the parent dies without closing
  (SIGKILL), its replies fail (EPIPE) and are given up, not the file: the child goes on taking
  every frame announced before the command pipe ended, then writes them out, notes in the file
  that the run was abandoned (the MCAP ``isaac.end`` metadata, complete: false, with the
  reason; a warning in the Rerun log) and leaves it as a flushed ``.partial`` without summary
  or index (`isaac recover` makes the clean copy). What the parent had not announced yet (at
  most NOTIFY_EVERY - 1 steps; none after `WriterProcess.hand_over`) is lost with it.
- the child holds the output's lock (`recorder.outputs`, passed as ``keep_fd``) until it exits,
  so no new run takes the file while a child whose parent died is still finishing it.
"""

from __future__ import annotations

import gc
import json
import mmap
import os
import pickle
import select
import signal
import struct
import subprocess
import sys
import time

import numpy as np

from isaac.engine.records import StepRecord
from isaac.errors import LogError
from recorder.frames import (
    FRAME_HEAD,
    Frame,
    batch_frame_sizes_with_joints,
    frame_sizes,
    joints_finite,
    joints_trailer,
    pack,
    pack_batch,
    pack_into,
    put_stats,
    put_trailer,
    read_rerun_frame,
)
from recorder.pack import model_bundle
from recorder.spawn import SENDER, WriterChild, reap, start_writer_child

# shared memory per writer, in frames of the scene's size, within RING_MIN..RING_MAX bytes,
# mapped pre-faulted (a fresh page costs a fault in each process: writes over a cold 32 MiB
# ring measured 3x slower). The MCAP writer takes each step as it comes; 64 frames ride out
# its hiccups on a shared machine. The Rerun writer sends a batch of 100 steps at once
# (10-30 ms on the 500-body pile) and the run goes on meanwhile: 128 frames.
RING_FRAMES = {"mcap": 64, "rerun": 128}
RING_MIN, RING_MAX = 4 << 20, 64 << 20

# what the child writes into a file whose parent died without closing it
ABANDONED = "abandoned: the recording process ended without closing the log"

# frames are announced to the child in batches: one wake-up per NOTIFY_EVERY steps, not per
# step (a cross-CPU wake-up measured 10-20 us on this VM); a SIGKILLed parent loses at most
# the unannounced ones, which no flush had covered yet either
NOTIFY_EVERY = 8

_COMMAND = struct.Struct("<cQQQ")
_REPLY = struct.Struct("<cQ")


def ring_bytes_for(kind: str, n_bodies: int) -> int:
    """Ring size for writer `kind` and a scene of `n_bodies`: RING_FRAMES[kind] frames of
    ~3 contact rows per body."""
    from recorder.pack import message_sizes

    estimate = (
        FRAME_HEAD.size
        + sum(message_sizes(0, n_bodies, 3 * n_bodies, 3 * n_bodies, 3 * n_bodies))
        + 16
    )
    size = min(max(RING_FRAMES[kind] * estimate, RING_MIN), RING_MAX)
    return (size + mmap.PAGESIZE - 1) // mmap.PAGESIZE * mmap.PAGESIZE


def _current_cpu() -> int | None:
    """The CPU this process runs on now (Linux /proc), or None."""
    try:
        with open("/proc/self/stat", encoding="ascii") as f:
            return int(f.read().rsplit(")", 1)[1].split()[36])
    except (OSError, ValueError, IndexError):
        return None


def plan_cpus(writers: int) -> tuple[set[int], list[set[int]]] | None:
    """CPUs for the simulating process and for each of `writers` writer processes, or None
    (one CPU, or affinity not available): the writers get CPUs of their own, away from the one
    the simulation runs on now, and the simulation keeps every other CPU it may use.

    Why: schedulers that pack tasks onto few CPUs (this VM's kernel runs with
    ``sched_vcpu_pack``) placed the writer process on the simulation's CPU and left the other
    idle; a writer process only on other CPUs was soon joined there by the simulation. Measured
    on the 500-body pile: the simulation's own step 40-70 % slower while recording, against
    0-25 % with the CPUs apart.
    """
    try:
        allowed = sorted(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return None
    here = _current_cpu()
    if here is None or len(allowed) < 2 or here not in allowed:
        return None
    others = [c for c in allowed if c != here]
    spare = max(1, min(writers, len(allowed) // 2))  # at most half the CPUs go to writers
    writer_cpus = others[:spare]
    plan = [{writer_cpus[k % len(writer_cpus)]} for k in range(writers)]
    return set(allowed) - set(writer_cpus), plan


# a recording expected to be smaller than this is written by a thread even on an idle machine:
# writer processes took 3.4-4.0 s to start and 0.9-1.9 s to finish on the loaded 2-core machine
# (a thread 0.08 s and 0.03 s), more than a short run takes; and with the packed-record path
# (2026-12-02) their parent still packs every record, so on the small scenes they were the
# slowest mode even once started (choose_offload)
SMALL_RUN_BYTES = 200_000_000


def choose_offload(
    writers: int,
    cpus: int | None = None,
    load: float | None = None,
    log_bytes: int | None = None,
) -> str:
    """What `Recorder(offload="auto")` picks: "process" when the machine has an idle CPU for
    each writer besides the simulation's own (cpus: the CPUs this process may use; load: the
    one-minute load average, this process included) and the recording is not small (log_bytes:
    its expected MCAP size, when known, at least SMALL_RUN_BYTES), else "thread".

    Measured again 2026-12-02 with the packed-record path, where every mode takes whole
    batches (bench/README.md, "Writing MCAP"; the 2-core machine at load average 2-3.5 from
    other work): `isaac run SCENE --steps 50000 --mcap`, whole process, medians of 3: head_on
    none 1.61 s, thread 1.79, process 2.54 (no file 1.07); bounce 2.30, 3.24, 4.63; off_centre
    2.75, 3.27, 4.70; a paired comparison of head_on (5 pairs, load 1.6) put thread at 1.05x
    (0.98-1.10) none's wall time, and an earlier pass at load 3 at 0.75x (1.65 against 2.21 s:
    the thread pays when a core is free). Writer processes stay the slowest for small runs (their
    start-up, and the parent packs every record all the same): hence "thread" below
    SMALL_RUN_BYTES, where it costs at most about 5 % more than "none" and gains when a core is
    free, and for `--mcap --rrd`, where it overlaps the MCAP writing with the Rerun writer.
    Before the packed records (whole runs, load 5-6): head_on 20,000 steps MCAP: process 12.6 s,
    thread 3.8 s, none 16.9 s; default scene MCAP + .rrd: 24.9, 5.4, 6.5 s; pile MCAP + .rrd:
    14.4, 8.0, 9.1 s. Writer processes pay only when they have CPUs to themselves (the recording
    bench, on an idle machine: see bench/README.md).
    """
    if cpus is None:
        try:
            cpus = len(os.sched_getaffinity(0))
        except (AttributeError, OSError):
            cpus = os.cpu_count() or 1
    if load is None:
        try:
            load = os.getloadavg()[0]
        except OSError:
            load = float(cpus)
    if log_bytes is not None and log_bytes < SMALL_RUN_BYTES:
        return "thread"
    idle = cpus - max(0.0, load - 1.0)  # the load counts this process too
    return "process" if idle >= writers + 1 else "thread"


def _map(fd: int, size: int) -> mmap.mmap:
    flags = mmap.MAP_SHARED | getattr(mmap, "MAP_POPULATE", 0)
    return mmap.mmap(fd, size, flags=flags)


class WriterProcess:
    """A log writer running in a child process; same calls as the in-process writers.

    kind: "mcap" (config: path, model, scene {name, dt}, scene_text, metadata, flush_every,
        compression, foxglove) or "rerun" (config: path, model, scene, impulse_scale).
    cpus: the CPUs the child may run on (`plan_cpus`); None: wherever the scheduler likes.
    keep_fd: a descriptor the child keeps open, unused, until it exits: the output's lock
        (`recorder.outputs.OutputClaim.fd`).
    child: the process, when it was started earlier (`recorder.spawn.start_writer_child`,
        which `isaac run` calls before it imports the engine); else it is started here.
    """

    def __init__(
        self,
        kind: str,
        path: str,
        config: dict,
        *,
        ring_bytes: int | None = None,
        cpus: set[int] | None = None,
        keep_fd: int | None = None,
        child: WriterChild | None = None,
    ):
        self.path = str(path)
        self.partial_path = self.path + ".partial"
        self.kind = kind
        try:  # say at once when the file cannot be written, not at the first step
            open(self.partial_path, "wb").close()
        except OSError as exc:
            if child is not None:
                child.discard()
            raise LogError(f"cannot write {self.partial_path}: {exc.strerror}") from exc
        if ring_bytes is None:
            ring_bytes = ring_bytes_for(kind, len(config["model"]["names"]))
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
        if child is None:
            child = start_writer_child(kind, keep_fd)
        elif child.kind != kind:
            raise ValueError(f"a {child.kind} writer process cannot write {kind}")
        self.proc, self._cmd, self._rep, self._stderr = (
            child.proc,
            child.cmd_fd,
            child.reply_fd,
            child.stderr,
        )
        try:
            os.ftruncate(child.ring_fd, ring_bytes)
            self._ring = _map(child.ring_fd, ring_bytes)
            if cpus:
                try:
                    os.sched_setaffinity(self.proc.pid, cpus)
                except OSError:
                    pass
        except BaseException:
            child.discard()
            raise
        finally:
            os.close(child.ring_fd)
        self._view = memoryview(self._ring)
        self._ring_u8 = np.frombuffer(self._ring, dtype=np.uint8)
        model = config["model"]
        self._stats_model = _Namespace(
            mass=np.ascontiguousarray(model["mass"], dtype=np.float64),
            inertia=np.ascontiguousarray(model["inertia"], dtype=np.float64),
            concrete=np.ascontiguousarray(model["concrete"], dtype=bool),
        )
        self._gravity = tuple(float(g) for g in config["gravity"])
        self._masses = model_bundle(self._stats_model)  # (mass, inertia, concrete), compiled
        # the compiled encoder writes the host's byte order: little-endian only
        self._compiled = sys.byteorder == "little"
        if kind == "rerun":  # native byte order: both ends are on this machine
            from recorder.pack import pack_rerun, record_bundles, rerun_offsets

            self._pack_rerun, self._rerun_offsets = pack_rerun, rerun_offsets
            self._record_bundles = record_bundles
        # MCAP without the Foxglove channel (drawn from records in the child): every step goes
        # as Message records packed here (recorder.mcap_pack), which the child enters into its
        # chunks a stretch at a time; /world is encoded here too, when existence changes
        self._packer = None
        self._last_exists = None  # existence at the last step sent (None: none yet)
        if kind == "mcap" and not config.get("foxglove") and self._compiled:
            from recorder.mcap_pack import BatchPacker
            from recorder.mcap_writer import encode_world, record_channels

            joints = config.get("joints", ())
            self._packer = BatchPacker(
                _Namespace(**model),
                self._gravity,
                float(config["scene"]["dt"]),
                record_channels(bool(joints)),
                joints,
                encode_world=encode_world,
                hashes=False,  # the child hashes (recorder.mcap_pack.put_hashes)
            )
        os.set_blocking(self._rep, False)
        payload = pickle.dumps(
            {"kind": kind, "path": self.path, "ring_bytes": ring_bytes, **config},
            protocol=pickle.HIGHEST_PROTOCOL,
        )
        self._send(b"C", len(payload), payload=payload)

    # -- parent side -------------------------------------------------------------------------
    checks_finite = True  # `write` refuses a record holding a NaN or an infinity

    def write(self, record: StepRecord, stats: dict | None = None) -> bool:
        """Hand one step to the child (waits only while the ring is full).

        stats: the step's `/stats` values without the hash (`recorder.stats.compute_stats`);
            None: computed here, with the same kernel, in the pass that copies the record.
        Returns False, sending nothing, when a float of the record is NaN or infinite (the
        caller says which: `recorder.stats.check_finite`).
        """
        if self.kind == "rerun":
            return self._write_rerun(record, stats)
        if self._packer is not None:
            from recorder.mcap_pack import one_step_batch

            # stats: the packer computes the same values (recorder.pack._stat_sums)
            return self.write_batch(one_step_batch(record, self._packer.clock_dt)) == 1
        if record.joints is not None and not joints_finite(record.joints):
            return False
        bodies_size, contacts_size, size = frame_sizes(record)
        trailer = joints_trailer(int(record.step), float(record.time), record.joints)
        if size + len(trailer) > self.capacity or not self._compiled:
            return self._write_inline(record, stats)
        pos, end = self._reserve(size + len(trailer))
        if not self._compiled_pack(pos, record, stats, bodies_size, contacts_size):
            return False
        put_trailer(self._ring_u8, pos + size, trailer)
        self._announce(pos, size + len(trailer), end)
        return True

    takes_batches = True  # `write_batch`

    def write_batch(self, batch) -> int:
        """Hand the steps of a `isaac.engine.records.StepBatch` to the child, their MCAP frames
        packed by one compiled call per stretch of the ring (`recorder.pack.pack_frames`) rather
        than one call per step. Returns how many steps were sent: all of them, or the steps
        before the first one holding a NaN or an infinity (the caller says which)."""
        if self._packer is not None:
            return self._write_records(batch)
        if self.kind == "rerun" or not self._compiled:
            for s in range(batch.steps):
                if not self.write(batch.record(s)):
                    return s
            return batch.steps
        sizes, trailers = batch_frame_sizes_with_joints(batch)
        ends = np.cumsum(sizes[:, 2])
        lo = 0
        while lo < batch.steps:
            if sizes[lo, 2] > self.capacity:  # too large for the ring: the one-step path
                if not self.write(batch.record(lo)):
                    return lo
                lo += 1
                continue
            # the frames from lo that fit in a quarter of the ring, laid end to end
            base = ends[lo - 1] if lo else 0
            hi = lo + max(1, int(np.searchsorted(ends[lo:] - base, self.capacity // 4, "right")))
            hi = min(hi, batch.steps)
            while hi > lo + 1 and sizes[hi - 1, 2] > self.capacity:
                hi -= 1
            total = int(ends[hi - 1] - base)
            pos, end = self._reserve(total)
            done = pack_batch(
                self._ring_u8, pos, lo, hi, batch, sizes, self._stats_model, self._gravity
            )
            at, head = pos, end - total
            for s in range(lo, done):
                size = int(sizes[s, 2])
                put_trailer(self._ring_u8, at + size - len(trailers[s]), trailers[s])
                head += size
                self._announce(at, size, head)
                at += size
            if done < hi:
                return done
            self.head = end
            lo = hi
        return batch.steps

    def _write_records(self, batch) -> int:
        """`write_batch` for MCAP: the batch's Message records (`recorder.mcap_pack`) packed
        straight into the ring by one compiled call per stretch of at most a quarter of it,
        each stretch announced to the child as one ``B`` command; a step too large for that
        goes through the command pipe (``J``)."""
        packer = self._packer
        plan = packer.plan(batch, self._last_exists)
        sizes = plan.sizes
        ends = np.cumsum(sizes)
        quarter = self.capacity // 4
        lo = 0
        done = batch.steps
        while lo < batch.steps:
            base = int(ends[lo - 1]) if lo else 0
            if sizes[lo] > quarter:  # one step, through the pipe
                hi = lo + 1
                buf = np.empty(int(sizes[lo]), dtype=np.uint8)
                done, end, _ = packer.pack(buf, 0, lo, hi, batch, plan)
                if done > lo:
                    self._notify()
                    self._send(b"J", end, payload=buf[:end].tobytes())
            else:
                hi = lo + int(np.searchsorted(ends[lo:] - base, quarter, "right"))
                total = int(ends[hi - 1]) - base
                pos, stop = self._reserve(total)
                done, end, _ = packer.pack(self._ring_u8, pos, lo, hi, batch, plan)
                if end > pos:
                    self._announce(pos, end - pos, stop - total + (end - pos), kind=b"B")
            if done < hi:
                break
            lo = hi
        if done:
            self._last_exists = np.array(batch.exists[done - 1], dtype=bool)
        return done

    def _reserve(self, size: int) -> tuple[int, int]:
        """Where the next frame of ``size`` bytes goes: its offset in the ring and its end in
        bytes handed out; waits while the child still holds that part of the ring."""
        pos = self.head % self.capacity
        head = self.head
        if pos + size > self.capacity:
            head += self.capacity - pos
            pos = 0
        if head + size - self.released > self.capacity:
            self._notify()
            while head + size - self.released > self.capacity:
                self._pump(block=True)
        return pos, head + size

    def _announce(self, pos: int, size: int, end: int, kind: bytes = b"F") -> None:
        self.head = end
        self._pending += _COMMAND.pack(kind, pos, size, end)
        if len(self._pending) >= NOTIFY_EVERY * _COMMAND.size:
            self._notify()

    def _write_rerun(self, record: StepRecord, stats: dict | None) -> bool:
        """The Rerun writer's share: one compiled pass (`recorder.pack.pack_rerun`) copies what
        it draws into the ring, checks every float and sums the stats."""
        n, m = int(record.angle.shape[0]), len(record.contacts)
        size = 8 * self._rerun_offsets(n, m)[-1]
        inline = size > self.capacity
        if inline:
            buf, pos = np.empty(size, dtype=np.uint8), 0
        else:
            (pos, end), buf = self._reserve(size), self._ring_u8
        state, rows = self._record_bundles(record)
        if (
            self._pack_rerun(
                buf,
                pos,
                int(record.step),
                float(record.time),
                state,
                rows,
                self._masses,
                self._gravity,
            )  # fmt: skip
            >= 0
        ):
            return False
        if stats is not None:
            put_stats(buf, pos, stats)
        if inline:
            self._notify()
            self._send(b"I", size, payload=buf.tobytes())
        else:
            self._announce(pos, size, end)
        return True

    def _write_inline(self, record: StepRecord, stats: dict | None) -> bool:
        """A frame too large for the ring (or a big-endian machine): encoded by the reference
        encoders and sent through the command pipe."""
        from isaac.engine.diagnostics import all_finite
        from recorder.stats import compute_stats

        if not all_finite(record):
            return False
        if stats is None:
            stats = compute_stats(self._stats_model, self._gravity, record, with_hash=False)
        self._notify()
        data = pack(record, stats)
        self._send(b"I", len(data), payload=data)
        return True

    def _notify(self) -> None:
        """Send the pending frame notices (one pipe write, one wake-up of the child) and read
        what the child said meanwhile."""
        if self._pending:
            data, self._pending = bytes(self._pending), bytearray()
            self._send_raw(data)
        self._pump(block=False)

    def _compiled_pack(
        self,
        pos: int,
        record: StepRecord,
        stats: dict | None,
        bodies_size: int | None = None,
        contacts_size: int | None = None,
    ) -> bool:
        """Encode the frame at ``pos`` of the ring (its messages' sizes from `frame_sizes`, given by
        `write`, which needed them first); False (frame unusable) on NaN/infinity."""
        return pack_into(
            self._ring_u8,
            pos,
            record,
            self._masses,
            self._gravity,
            stats,
            None if bodies_size is None else (bodies_size, contacts_size),
        )

    def hand_over(self) -> None:
        """Send the frame notices not sent yet: the child has every step written so far (it
        writes them out even if this process dies next), without waiting for it to take them."""
        self._notify()

    def wait_ready(self) -> None:
        """Block until the child has started and opened its file (start-up is ~0.3-1 s)."""
        while not self._ready:
            self._pump(block=True)

    def drain(self, settle: bool = False) -> None:
        """Block until the child has taken every step handed to it so far; with ``settle``,
        also until its writer has written out what it has sent (`RerunLogWriter.settle`)."""
        self._notify()
        self._syncs_sent += 1
        self._send(b"S", self._syncs_sent, int(settle))
        while self._synced < self._syncs_sent:
            self._pump(block=True)

    def close(
        self, *, complete: bool = True, stopped_at: int | None = None, reason: str | None = None
    ) -> str:
        """Finish the file in the child (every step sent is written) and rename it."""
        if self._finished:
            return self.path
        self._finished = True
        try:
            self._notify()
            args = json.dumps(
                {"complete": complete, "stopped_at": stopped_at, "reason": reason}
            ).encode()
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
                data = data[os.write(self._cmd, data) :]
        except BrokenPipeError:
            self._pump(block=True)  # raises with the child's own message
            raise LogError(
                f"writing {self.partial_path} failed: the writer process is gone"
            ) from None

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
                raise LogError(
                    f"writing {self.partial_path} failed: the writer process "
                    f"stopped{self._child_reason()}"
                )
            if got or not block:
                return

    def _parse(self) -> bool:
        buf, got, pos = self._replies, False, 0
        while len(buf) - pos >= _REPLY.size:
            kind, value = _REPLY.unpack_from(buf, pos)
            body_len = value if kind in (b"D", b"E") else 0
            if len(buf) - pos - _REPLY.size < body_len:
                break
            body = bytes(buf[pos + _REPLY.size : pos + _REPLY.size + body_len])
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
        return _child_reason(self.proc, self._stderr)

    def _shutdown(self) -> None:
        os.close(self._cmd)
        reap(self.proc, 60)
        os.close(self._rep)
        del self._ring_u8
        self._view.release()
        self._stderr.close()
        try:
            self._ring.close()
        except BufferError:
            # a view of the ring is still alive somewhere (a frame kept by an exception's
            # traceback: seen once, on a fresh machine, closing a diverged run's log). The
            # child wrote the file; this is only the parent's mapping: collect and try again,
            # else it is unmapped when the last view goes.
            gc.collect()
            try:
                self._ring.close()
            except BufferError:
                pass


def _child_reason(proc, stderr) -> str:
    """`` (exit code N): its last line of standard error`` of a writer child that stopped, for
    the parent's one-line error; "" if it is still running after 5 s."""
    code = proc.poll()
    if code is None:
        try:
            code = proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            return ""
    stderr.seek(0)
    lines = [ln for ln in stderr.read().decode("utf-8", "replace").splitlines() if ln.strip()]
    last = f": {lines[-1].strip()}" if lines else ""
    return f" (exit code {code}){last}"


class RerunSendProcess:
    """The Rerun sender (`recorder.rerun_send.RerunSender`) in a child process: the same calls,
    each pickled and written to the child's command pipe by a thread of this process (the
    caller only pickles: a batch's drawn arrays are copied at once, and may be reused).

    Why: importing rerun-sdk (0.4-0.5 s of CPU) and the Python half of ``send_columns`` ran in
    the simulating process and took most of what ``--rrd`` added to a short run; the child,
    started by `isaac run` before the engine is imported (`recorder.spawn.start_sender_child`),
    does both beside it. The drawing (`recorder.rerun_writer`, compiled kernels) stays here, so
    the child imports neither numba nor the engine.

    child: the started process (its kind `recorder.spawn.SENDER`). `open` is what
    `RerunLogWriter` takes as its ``sender``. `finish` returns once the child has closed and
    renamed the file and exited; a failure in the child is raised (LogError, its message) by
    the next call that waits for it (`flush`, `finish`) or by any call once the pipe broke.
    """

    def __init__(self, child: WriterChild) -> None:
        import queue
        import threading

        if child.kind != SENDER:
            raise ValueError(f"a {child.kind} process is not the Rerun sender")
        self.proc, self._cmd, self._rep, self._stderr = (
            child.proc,
            child.cmd_fd,
            child.reply_fd,
            child.stderr,
        )
        self.partial_path = "the Rerun recording"  # until `open`
        self._replies = bytearray()
        self._error: str | None = None  # the pipe broke (set by the thread)
        self._finished = False
        # at most a few batches in flight (a few MB): a caller ahead of the child waits here
        self._queue = queue.Queue(maxsize=8)
        self._thread = threading.Thread(target=self._work, name="isaac-rerun-pipe", daemon=True)
        self._thread.start()

    def open(self, partial_path: str, recording_id: str, **header):
        """Start the recording (`recorder.rerun_send.open_sender`'s arguments); returns self.
        The file is not touched here: the output's claim (`recorder.outputs`) made sure it can
        be written, and a child told the scene beforehand (`recorder.spawn.WriterChild.prepare`)
        is writing it already."""
        self.partial_path = partial_path
        self._call("open", ((partial_path, recording_id), header))
        return self

    def info(self, markdown: str) -> None:
        self._call("info", (markdown,))

    def concrete(self, outlines, labels) -> None:
        self._call("concrete", (outlines, labels))

    def labels(self, step: int, time: float, labels) -> None:
        self._call("labels", (int(step), float(time), labels))

    def warn(self, step: int | None, text: str) -> None:
        self._call("warn", (step, text))

    def batch(self, *job) -> None:
        self._call("batch", job)

    def flush(self) -> None:
        """Block until the child has written out everything sent so far."""
        self._call("flush", ())
        self._wait(b"S")

    def finish(self, path: str) -> str:
        """Close and rename the file in the child; returns once it has, and has exited."""
        try:
            self._call("close", (path,))
            self._wait(b"D")
        finally:
            self._shutdown()
        return path

    def abandon(self, reason: str | None = None) -> None:
        """The child writes out what it has and keeps the ``.partial``; returns once it exited."""
        if self._finished:
            return
        try:
            self._call("abandon", (reason,))
        except LogError:
            pass
        self._shutdown()

    def _call(self, method: str, args) -> None:
        if self._finished:
            raise LogError(f"writing {self.partial_path} failed: the recording is closed")
        self._raise_if_broken()
        body = pickle.dumps((method, args), protocol=pickle.HIGHEST_PROTOCOL)
        self._queue.put(len(body).to_bytes(8, "little") + body)

    def _work(self) -> None:
        """The pipe's writer: commands in order; once the pipe broke, it only drains."""
        while True:
            data = self._queue.get()
            try:
                if data is None:
                    return
                if self._error is None:
                    view = memoryview(data)
                    while view:
                        view = view[os.write(self._cmd, view) :]
            except OSError:
                self._error = "the Rerun sender process is gone"
            finally:
                self._queue.task_done()

    def _raise_if_broken(self) -> None:
        if self._error is not None:
            self._read_replies(block=False)  # its own message, when it sent one
            raise LogError(
                f"writing {self.partial_path} failed: {self._error}{self._child_reason()}"
            )

    def _wait(self, kind: bytes) -> None:
        """Wait for the reply ``kind`` (after every command queued so far was written)."""
        self._queue.join()
        self._raise_if_broken()
        while kind not in self._replies:
            if not self._read_replies(block=True):
                self._error = self._error or "the Rerun sender process stopped"
                self._raise_if_broken()
        self._replies = self._replies[self._replies.index(kind) + 1 :]

    def _read_replies(self, *, block: bool) -> bool:
        """Read what the child said; False at the end of the pipe. A failure it reported
        (``E`` and its message) is raised."""
        if not block and not select.select([self._rep], [], [], 0)[0]:
            return True
        chunk = os.read(self._rep, 65536)
        self._replies += chunk
        at = self._replies.find(b"E")
        if at >= 0 and len(self._replies) >= at + 5:
            n = int.from_bytes(self._replies[at + 1 : at + 5], "little")
            if len(self._replies) < at + 5 + n and chunk:
                return self._read_replies(block=True)
            msg = bytes(self._replies[at + 5 : at + 5 + n]).decode("utf-8", "replace")
            raise LogError(f"writing {self.partial_path} failed: {msg}")
        return bool(chunk)

    def _child_reason(self) -> str:
        return _child_reason(self.proc, self._stderr)

    def _shutdown(self) -> None:
        if self._finished:
            return
        self._finished = True
        self._queue.put(None)
        self._thread.join()
        os.close(self._cmd)  # the child ends at the end of the pipe, if not before
        reap(self.proc, 60)
        os.close(self._rep)
        self._stderr.close()


# -- child side --------------------------------------------------------------------------------
class _Namespace:
    def __init__(self, **kw) -> None:
        self.__dict__.update(kw)


class _FrameWriter:
    """Feeds frames to a writer: the MCAP writer takes the encoded messages as they are (with
    the Foxglove channel, the decoded record); the Rerun writer copies a `RerunFrame`'s arrays
    into its batch (`RerunLogWriter.append`)."""

    def __init__(self, writer, kind: str, encoded: bool) -> None:
        self.writer, self.encoded = writer, encoded
        self.raw = kind == "rerun"  # frames of `recorder.pack.pack_rerun`

    def write(self, data, at: int = 0, length: int | None = None) -> None:
        """The frame at byte ``at`` of ``data`` (the ring or an inline frame's bytes)."""
        if self.raw:
            self.writer.append(*read_rerun_frame(data, at))
            return
        if length is None:
            self._write_frame(Frame(data))
        else:
            with memoryview(data)[at : at + length] as view:
                self._write_frame(Frame(view))

    def _write_frame(self, frame: Frame) -> None:
        if self.encoded:
            self.writer.write_messages(
                frame.step,
                frame.time,
                frame.exists(),
                frame.bodies,
                frame.contacts,
                {**frame.stats, "state_hash": frame.state_hash()},
                frame.joints,
            )
        else:
            self.writer.write(frame.record(), frame.stats)

    def __getattr__(self, name):
        return getattr(self.writer, name)


def _make_writer(config: dict):
    encoded = config["kind"] == "mcap" and not config.get("foxglove")
    return _FrameWriter(_make_bare_writer(config), config["kind"], encoded)


def _make_bare_writer(config: dict):
    model = _Namespace(**config["model"])
    scene = _Namespace(name=config["scene"]["name"], world=_Namespace(dt=config["scene"]["dt"]))
    if config["kind"] == "mcap":
        from recorder.mcap_writer import McapLogWriter

        scene_encoder = None
        if config.get("foxglove"):
            from recorder.foxglove import SceneEncoder

            scene_encoder = SceneEncoder(model, **config["foxglove"])
        return McapLogWriter(
            config["path"],
            model,
            scene,
            config["scene_text"],
            flush_every=config["flush_every"],
            compression=config["compression"],
            foxglove=scene_encoder,
            metadata=config["metadata"],
            joints=config.get("joints", ()),
            gravity=config.get("gravity"),
        )
    from recorder.rerun_writer import RerunLogWriter

    # each batch sent from a thread: the steps behind it are taken meanwhile (a batch's
    # send_columns took 2-12 ms on the 500-body pile, and the run waited whenever it caught up)
    sys.setswitchinterval(0.0005)  # and the GIL comes back to this thread within 0.5 ms
    return RerunLogWriter(
        config["path"],
        model,
        scene,
        impulse_scale=config["impulse_scale"],
        background=True,
        joints=config.get("joints", ()),
    )


POLL_S = 0.001  # the writer process looks for commands every millisecond while it has none


class _PolledReader:
    """The command pipe, read by polling rather than by sleeping in read().

    Why: a pipe write wakes a reader sleeping in read() with the kernel's "sync" hint, which
    places it on the writer's CPU; the writer process then ran on the simulation's CPU while the
    other one idled (measured: the run 30-50 % slower, 1.8 ms per wake-up). Woken by its own
    timer, the writer process stays on its own CPU. Commands wait at most POLL_S; the ring holds
    several steps, so the run does not notice.
    """

    def __init__(self, fd: int) -> None:
        self.fd = fd
        os.set_blocking(fd, False)
        self.buf = bytearray()

    def read(self, n: int) -> bytes | None:
        """Exactly n bytes, or None when the pipe ended first (the parent is gone)."""
        while len(self.buf) < n:
            try:
                chunk = os.read(self.fd, max(1 << 16, n - len(self.buf)))
            except BlockingIOError:
                time.sleep(POLL_S)
                continue
            if not chunk:
                return None
            self.buf += chunk
        data = bytes(self.buf[:n])
        del self.buf[:n]
        return data


def child_main(argv: list[str]) -> int:
    """The child: read commands, write the log; see the module docstring for the protocol."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    from isaac.tuning import reuse_large_buffers

    reuse_large_buffers()  # a step's messages are 100 kB and more (see isaac.tuning)
    kind = argv[0]
    cmd_fd, rep_fd, ring_fd = (int(x) for x in argv[1:])
    commands = _PolledReader(cmd_fd)
    # the writer's libraries now, while the parent imports the engine (recorder.spawn)
    if kind == "rerun":
        import recorder.rerun_send  # noqa: F401 - rerun-sdk (the drawing half does without it)
        import recorder.rerun_writer  # noqa: F401
    else:
        import recorder.mcap_writer  # noqa: F401

    parent_gone = False

    def reply(kind: bytes, value: int = 0, body: bytes = b"") -> None:
        nonlocal parent_gone
        if parent_gone:
            return
        data = memoryview(_REPLY.pack(kind, value) + body)
        try:
            while data:
                data = data[os.write(rep_fd, data) :]
        except BrokenPipeError:
            # the parent died: nobody reads replies any more, but the frames it announced are
            # still in the ring and the command pipe, and they go into the file
            parent_gone = True

    writer = None
    try:
        head = commands.read(_COMMAND.size)
        if head is None:
            return 0
        kind, length, _, _ = _COMMAND.unpack(head)
        if kind != b"C":
            raise LogError("writer process: expected its configuration first")
        config = commands.read(length)
        if config is None:
            return 0
        config = pickle.loads(config)
        ring = _map(ring_fd, config["ring_bytes"])  # sized by the parent once it knew the scene
        ring_u8 = np.frombuffer(ring, dtype=np.uint8)
        os.close(ring_fd)
        writer = _make_writer(config)
        reply(b"K")
        while True:
            head = commands.read(_COMMAND.size)
            if head is None:  # the parent is gone without closing: keep what arrived
                writer.abandon(reason=ABANDONED)
                return 0
            kind, a, b, c = _COMMAND.unpack(head)
            if kind == b"F":
                # read in place (the mcap library copies what it keeps, the Rerun writer copies
                # into its batch); the slot goes back to the parent once the step is taken
                writer.write(ring_u8 if writer.raw else ring, a, b)
                reply(b"R", c)
            elif kind == b"B":  # Message records of whole steps (recorder.mcap_pack)
                writer.write_records(ring_u8, a, a + b, hashed=False)
                reply(b"R", c)
            elif kind == b"J":
                data = commands.read(a)
                if data is None:  # the parent died while sending these records
                    writer.abandon(reason=ABANDONED)
                    return 0
                records = np.frombuffer(bytearray(data), dtype=np.uint8)  # writable
                writer.write_records(records, 0, a, hashed=False)
            elif kind == b"I":
                data = commands.read(a)
                if data is None:  # the parent died while sending this frame
                    writer.abandon(reason=ABANDONED)
                    return 0
                writer.write(np.frombuffer(data, dtype=np.uint8) if writer.raw else data)
            elif kind == b"S":
                settle = getattr(writer, "settle", None)
                if b and settle is not None:
                    settle()
                reply(b"S", a)
            elif kind == b"Z":
                args = commands.read(a)
                if args is None:
                    writer.abandon(reason=ABANDONED)
                    return 0
                path = writer.close(**json.loads(args))
                body = json.dumps({"path": path}).encode()
                reply(b"D", len(body), body)
                return 0
            else:
                raise LogError(f"writer process: unknown command {kind!r}")
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
    code = child_main(sys.argv[1:])
    # the file is closed, or written out and flushed (abandoned): the interpreter's teardown
    # (0.1-0.2 s: numba, rerun-sdk, the mcap library) would only delay the parent, which waits
    # for this process to exit before it reports the files finished
    sys.stderr.flush()
    os._exit(code)
