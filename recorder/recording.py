"""`Recorder`: feeds the engine's step records to the MCAP log and/or the Rerun recording.

Usage (the run loop in isaac/app/run.py)::

    with Recorder(sim, mcap_path="out.mcap", rrd_path="out.rrd") as rec:
        # a fresh simulation's step 0 (the initial state) is written by the recorder itself
        for record in sim.run(steps):
            rec.write(record)
    # or explicitly: rec.close(complete=False, stopped_at=k, reason="interrupted")

Every record is checked for NaN / infinity before anything is written: a bad value raises
`SimulationError` naming the step and the body, and the log keeps every step before it.
Both files are written as ``NAME.partial`` and renamed on close (clean or interrupted). Each is
claimed first (`recorder.outputs.claim`): refused in one line when it is not a file, when another
run is writing it, or when its ``.partial`` holds an earlier run's steps; the claim's lock lasts
until the file is closed, and with writer processes until the last of them has finished it.
The recorder never re-derives physics: it writes the record's arrays and the diagnostics of them.
"""

from __future__ import annotations

import os

import numpy as np

from isaac.engine.records import StepRecord
from isaac.errors import IsaacError, LogError, SimulationError
from isaac.tuning import reuse_large_buffers
from recorder.outputs import OutputClaim, check_distinct, claim
from recorder.stats import check_finite, compute_stats

# test hook: a FIFO that `Recorder.close` reads to its end before finishing the files, so that a
# test can act (send a signal, start another run) at an exact moment of closing
CLOSE_GATE_ENV = "ISAAC_TEST_CLOSE_GATE"


class Recorder:
    """Records a `Simulation` run to MCAP (``mcap_path``) and/or Rerun (``rrd_path``).

    sim: the simulation (``.scene``, ``.model``); only read, never stepped here. Given a fresh
        one (at step 0, nothing stepped), the recorder writes its step 0 (``sim.record()``)
        itself, so the log starts at the initial state; writing that step 0 again, as callers
        of earlier versions did, is a no-op. Given one at a later step, the first step written
        is the caller's.
    mcap_path, rrd_path: output files (None to skip); written as ``PATH.partial`` until closed.
        Either may be an `recorder.outputs.OutputClaim` made beforehand (the recorder then owns
        it and releases it on close).
    replace_partial: replace a ``PATH.partial`` that holds an earlier run's steps (default:
        LogError, the file untouched).
    scene_text: the expanded scene YAML to embed; default ``isaac.scene.scene_to_yaml(sim.scene)``.
    compression: MCAP chunk compression, "lz4" (default: a third smaller on the default
        scene, a fifth on the 503-body pile, for about 0.01-0.1 ms of a writer's CPU a step),
        "zstd" or "none" (docs/log-format.md has the figures).
    flush_every: MCAP chunks are closed and flushed every this many steps (<= 100).
    foxglove: also write ``/foxglove/scene`` (foxglove.SceneUpdate: outlines, normals, impulses)
        for Foxglove's 3D panel; off by default (it costs more than the physics channels).
    impulse_scale: length (m) of an impulse arrow per N s in the Rerun view; default from the
        scene's sizes and masses (written in the recording).
    offload: where the files are encoded and written: "process" (one child process per file,
        fed through shared memory, see recorder.writer_process), "thread" (MCAP in a thread of
        this process, Rerun in the caller), "none" (all in the caller), or "auto" (default:
        "process" when the machine has an idle CPU per writer, else "thread":
        `recorder.writer_process.choose_offload`, which gives the measurements). The files'
        bytes are the same in all of them; ``self.offload`` says which was used.
    children: writer processes started beforehand (`recorder.spawn.start_writer_child`),
        keyed "mcap" and/or "rrd": those files are written by them whatever ``offload`` says,
        which then applies to the other file. The "rrd" one may be the Rerun sender
        (`recorder.spawn.start_sender_child`): the recording is then drawn in this process and
        sent by it (``offload`` then says "thread (rrd: sender process)"). `isaac run` starts
        them before it imports the engine, so that their start-up overlaps its own. The
        recorder owns them: any it does not use (an error came first) are stopped.
    """

    def __init__(
        self,
        sim,
        mcap_path: str | OutputClaim | None = None,
        rrd_path: str | OutputClaim | None = None,
        *,
        scene_text: str | None = None,
        compression: str = "lz4",
        flush_every: int = 100,
        foxglove: bool = False,
        impulse_scale: float | None = None,
        offload: str = "auto",
        replace_partial: bool = False,
        children: dict | None = None,
    ) -> None:
        self.mcap = None
        self.rerun = None
        self.steps_written = 0
        self.last_step: int | None = None
        self.closed = False
        self.paths: dict[str, str] = {}
        self._claims: dict[str, OutputClaim] = {}
        self._cpus = iter(())
        self._restore_affinity: set[int] | None = None
        try:
            if offload not in ("auto", "process", "thread", "none"):
                raise ValueError("offload must be 'auto', 'process', 'thread' or 'none'")
            self._children = dict(children or {})
            if set(self._children) - {"mcap", "rrd"}:
                raise ValueError("children are keyed 'mcap' and 'rrd'")
            if offload == "auto":
                from recorder.writer_process import choose_offload

                offload = choose_offload((mcap_path is not None) + (rrd_path is not None))
            # each file's mode: "process" for those whose writer process was started
            # beforehand, ``offload`` for the others
            self._modes = {
                k: _child_mode(self._children[k]) if k in self._children else offload
                for k, p in (("mcap", mcap_path), ("rrd", rrd_path))
                if p is not None
            }
            self.offload = _describe_offload(self._modes, offload)
            self._claim(mcap_path, rrd_path, replace_partial)
        except BaseException:
            for c in (mcap_path, rrd_path):
                if isinstance(c, OutputClaim):
                    c.release(discard=True)
            self._release_claims(discard=True)
            self._discard_children()
            raise
        self._start_record: StepRecord | None = None
        try:
            self._start(sim, scene_text, compression, flush_every, foxglove, impulse_scale, offload)
            if getattr(sim, "step_index", None) == 0:
                self._start_record = sim.record()
                self.write(self._start_record)
        except BaseException:
            self._discard_children()
            self._abandon()
            raise

    def _discard_children(self) -> None:
        """Stop the started writer processes that no writer took (an error came first)."""
        while self._children:
            self._children.popitem()[1].discard()

    def _start(self, sim, scene_text, compression, flush_every, foxglove, impulse_scale, offload):
        # a step's messages are 100 kB and more: keep such buffers in the heap (isaac.tuning)
        reuse_large_buffers()
        self.sim = sim
        self.model = sim.model
        self.scene = sim.scene
        self.gravity = tuple(float(g) for g in self.scene.world.gravity)
        if scene_text is None:
            try:
                from isaac.scene import scene_to_yaml
            except ImportError as exc:
                raise LogError("isaac.scene.scene_to_yaml is not available") from exc
            scene_text = scene_to_yaml(self.scene)
        self.scene_text = scene_text
        mcap, rrd = self._claims.get("mcap"), self._claims.get("rrd")
        if offload == "process":
            from recorder.writer_process import plan_cpus

            plan = plan_cpus((mcap is not None) + (rrd is not None))
            if plan is not None:
                # the writers on CPUs of their own, this process on the others, until close
                self._restore_affinity = os.sched_getaffinity(0)
                os.sched_setaffinity(0, plan[0])
                self._cpus = iter(plan[1])
        if mcap is not None:
            self.mcap = self._mcap_writer(
                mcap.path,
                self._modes["mcap"],
                compression,
                flush_every,
                foxglove,
                impulse_scale,
            )
        if rrd is not None:
            self.rerun = self._rerun_writer(rrd.path, self._modes["rrd"], impulse_scale)

    def _claim(self, mcap_path, rrd_path, replace_partial: bool) -> None:
        paths = {"mcap_path": mcap_path, "rrd_path": rrd_path}
        check_distinct(
            {
                k: p.path if isinstance(p, OutputClaim) else str(p)
                for k, p in paths.items()
                if p is not None
            }
        )
        for key, kind, path in (("mcap", "mcap", mcap_path), ("rrd", "rrd", rrd_path)):
            if isinstance(path, OutputClaim):
                self._claims[key] = path
            elif path is not None:
                self._claims[key] = claim(str(path), kind, replace_partial=replace_partial)

    def _release_claims(self, discard: bool = False) -> None:
        for c in self._claims.values():
            c.release(discard=discard)

    def _lock_fd(self, key: str) -> int | None:
        c = self._claims.get(key)
        return None if c is None else c.fd

    def _mcap_writer(self, path, offload, compression, flush_every, foxglove, impulse_scale):
        from recorder.mcap_writer import McapLogWriter, build_metadata, joint_table_rows

        fox = None
        if foxglove:
            from recorder.rerun_writer import default_scales

            auto_impulse, normal_length = default_scales(self.model)
            fox = {
                "normal_length": normal_length,
                "impulse_scale": auto_impulse if impulse_scale is None else impulse_scale,
            }
        if offload == "process":
            from recorder.frames import model_table
            from recorder.writer_process import WriterProcess

            return WriterProcess(
                "mcap",
                path,
                cpus=next(self._cpus, None),
                keep_fd=self._lock_fd("mcap"),
                child=self._children.pop("mcap", None),
                config={
                    "model": model_table(self.model),
                    "gravity": self.gravity,
                    "scene": {"name": str(self.scene.name), "dt": float(self.scene.world.dt)},
                    "scene_text": self.scene_text,
                    "metadata": build_metadata(self.scene, self.scene_text, len(self.model.names)),
                    "flush_every": flush_every,
                    "compression": compression,
                    "foxglove": fox,
                    "joints": joint_table_rows(getattr(self.scene, "joints", ())),
                },
            )
        scene_encoder = None
        if fox is not None:
            from recorder.foxglove import SceneEncoder

            scene_encoder = SceneEncoder(self.model, **fox)
        return McapLogWriter(
            path,
            self.model,
            self.scene,
            self.scene_text,
            flush_every=flush_every,
            compression=compression,
            foxglove=scene_encoder,
            background=offload == "thread",
            gravity=self.gravity,
        )

    def _rerun_writer(self, path, offload, impulse_scale):
        from recorder.rerun_writer import RerunLogWriter

        if offload == SENDER_MODE:
            from recorder.writer_process import RerunSendProcess

            sender = RerunSendProcess(self._children.pop("rrd"))
            try:
                return RerunLogWriter(
                    path, self.model, self.scene, impulse_scale=impulse_scale, sender=sender.open
                )
            except BaseException:
                sender.abandon()
                raise
        if offload == "process":
            from recorder.frames import model_table
            from recorder.mcap_writer import joint_table_rows
            from recorder.writer_process import WriterProcess

            return WriterProcess(
                "rerun",
                path,
                cpus=next(self._cpus, None),
                keep_fd=self._lock_fd("rrd"),
                child=self._children.pop("rrd", None),
                config={
                    "model": model_table(self.model),
                    "gravity": self.gravity,
                    "scene": {"name": str(self.scene.name), "dt": float(self.scene.world.dt)},
                    "impulse_scale": impulse_scale,
                    "joints": joint_table_rows(getattr(self.scene, "joints", ())),
                },
            )
        return RerunLogWriter(path, self.model, self.scene, impulse_scale=impulse_scale)

    def wait_ready(self) -> None:
        """Block until the writer processes have started (a one-off 0.3-1 s, normally hidden
        behind the first steps); a no-op for in-process writers. Benchmarks call it so that
        they time the steady state."""
        for writer in (self.mcap, self.rerun):
            if writer is not None and hasattr(writer, "wait_ready"):
                writer.wait_ready()

    def drain(self, settle: bool = False) -> None:
        """Block until the writers have taken every step written so far (in-process writers
        take them at once); with ``settle``, also until the Rerun writer has written out the
        batches it has sent (its open batch stays buffered)."""
        for writer in (self.mcap, self.rerun):
            if writer is not None and hasattr(writer, "drain"):
                writer.drain(settle)
            elif settle and writer is not None and hasattr(writer, "settle"):
                writer.settle()

    def hand_over(self) -> None:
        """Send every step written so far to the writer processes, without waiting for them to
        take it (writes are announced to them in batches, `writer_process.NOTIFY_EVERY`): from
        then on those steps reach the ``.partial`` file even if this process dies. A no-op for
        in-process writers."""
        for writer in (self.mcap, self.rerun):
            if writer is not None and hasattr(writer, "hand_over"):
                writer.hand_over()

    def write(self, record: StepRecord) -> None:
        """Record one step (in order, starting with step 0). Raises SimulationError on NaN/inf."""
        if self.closed:
            raise LogError("the recorder is closed")
        if self._start_record is not None and self.steps_written == 1 and record.step == 0:
            if not _same_state(record, self._start_record):
                raise LogError(
                    "step 0 is already recorded: the recorder wrote the fresh simulation's "
                    "initial state itself, and this step 0 differs from it"
                )
            return  # the step 0 written at the start, written again: already in the log
        first = self.mcap if self.mcap is not None else self.rerun
        if not getattr(first, "checks_finite", False):
            check_finite(self.model.names, record)
        # only MCAP's /stats carries the state hash: its writer computes it; writer processes
        # get the rest of the stats from the pass that copies the record (recorder.pack)
        stats = None
        if not all(
            getattr(w, "checks_finite", False) for w in (self.mcap, self.rerun) if w is not None
        ):
            stats = compute_stats(self.model, self.gravity, record, with_hash=False)
        for writer in (self.mcap, self.rerun):
            if writer is None:
                continue
            # a writer that checks the record computes its stats in the same pass
            given = None if getattr(writer, "checks_finite", False) else stats
            if writer.write(record, given) is False:
                # the writer found a NaN or infinity (or rows that are not manifolds) while
                # packing: nothing was written; named by the checks of write_batch
                from recorder.mcap_writer import manifold_starts

                check_finite(self.model.names, record)
                manifold_starts(record.contacts)
                raise SimulationError(
                    f"step {record.step}: a recorded value is not finite", step=record.step
                )
        self.steps_written += 1
        self.last_step = record.step

    def write_batch(self, batch) -> None:
        """Record the steps of an `isaac.engine.records.StepBatch` (`Simulation.batches`), in
        order after the steps written so far. The MCAP writer (in this process, in a thread or
        in a writer process) takes a whole batch's Message records from one compiled call
        (`recorder.mcap_pack`), as does any writer whose ``takes_batches``; a writer that does
        not takes the batch's records one by one, after the others have checked them. A NaN or
        infinity raises SimulationError as `write` does, with every step before it recorded."""
        if self.closed:
            raise LogError("the recorder is closed")
        writers = [w for w in (self.mcap, self.rerun) if w is not None]
        batched = [w for w in writers if getattr(w, "takes_batches", False)]
        if not batched or not _batch_joints_finite(batch):
            # one by one: a step whose joints hold a NaN or infinity stops there, named
            for s in range(batch.steps):
                self.write(batch.record(s))
            return
        good = min(w.write_batch(batch) for w in batched)
        for w in writers:
            if w in batched:
                continue
            for s in range(good):  # checked by the batch writers
                record = batch.record(s)
                w.write(record, compute_stats(self.model, self.gravity, record, with_hash=False))
        if good:
            self.steps_written += good
            self.last_step = batch.first + good - 1
        if good < batch.steps:
            # the step a writer found a NaN or infinity in (or rows that are not manifolds):
            # named by the same checks as write()
            from recorder.mcap_writer import manifold_starts

            record = batch.record(good)
            check_finite(self.model.names, record)
            manifold_starts(record.contacts)
            raise SimulationError(
                f"step {record.step}: a recorded value is not finite", step=record.step
            )

    def close(
        self,
        complete: bool = True,
        stopped_at: int | None = None,
        reason: str | None = None,
        *,
        sync: bool = True,
    ) -> dict[str, str]:
        """Finish both files cleanly (keeping every step written) and rename them.

        complete: False when the run was interrupted or failed; then ``stopped_at`` and
            ``reason`` are written into the log. stopped_at: the last step whose state is in the
            log, the meaning `isaac run`, `inspect` and `recover` give "stopped at step K"
            (default: the last recorded step).
        sync: False skips the fsync of an MCAP file written in this process (offload "none" or
            "thread") before its rename: for a caller that syncs many files at once and only
            then gives them their final names (`isaac sweep`). Writer processes sync as always.
        Returns {"mcap": path, "rrd": path} for the files written.
        With ``ISAAC_TEST_CLOSE_GATE`` set (tests only), first waits on that FIFO.
        """
        if self.closed:
            return self.paths
        self.closed = True
        if not complete and stopped_at is None:
            stopped_at = self.last_step
        gate = os.environ.get(CLOSE_GATE_ENV)
        if gate:
            with open(gate, "rb") as f:  # returns once the test's end of the FIFO is closed
                f.read()
        errors = []
        for key, writer in (("mcap", self.mcap), ("rrd", self.rerun)):
            if writer is None:
                continue
            try:
                extra = (
                    {}
                    if sync or self._modes.get(key) == "process" or key != "mcap"
                    else {"sync": False}
                )
                self.paths[key] = writer.close(
                    complete=complete, stopped_at=stopped_at, reason=reason, **extra
                )
            except Exception as exc:  # noqa: BLE001 - close the other file, then report
                errors.append(f"{key}: {exc}")
        self._release_claims()  # after the writers: their processes held the locks too
        self._release_cpus()
        if errors:
            raise LogError("could not finish the log: " + "; ".join(errors))
        return self.paths

    def _release_cpus(self) -> None:
        if self._restore_affinity is not None:
            try:
                os.sched_setaffinity(0, self._restore_affinity)
            except OSError:
                pass
            self._restore_affinity = None

    def _abandon(self) -> None:
        self._release_cpus()
        for writer in (self.mcap, self.rerun):
            if writer is not None:
                try:
                    writer.abandon()
                except Exception:  # noqa: BLE001 - best effort on a failed start
                    pass
        self._release_claims(discard=True)
        self.closed = True

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        if exc_type is None:
            self.close(complete=True)
        elif issubclass(exc_type, KeyboardInterrupt):
            self.close(complete=False, reason="interrupted")
        elif issubclass(exc_type, IsaacError):
            # stopped at the last step recorded (a SimulationError's `step` failed: not in it)
            self.close(complete=False, reason=str(exc))
        else:
            self.close(complete=False, reason=f"{exc_type.__name__}: {exc}")
        return False


def _batch_joints_finite(batch) -> bool:
    """Whether every joint float of a `StepBatch` is finite (True without joints): the batch
    packers check the bodies and contacts only."""
    joints = getattr(batch, "_joints", None)  # (steps, m, ...) per field, None without joints
    if joints is None:
        return True
    return all(np.isfinite(a).all() for a in joints)


def _same_state(a: StepRecord, b: StepRecord) -> bool:
    """Whether two records hold the same state, bit for bit (NaN equal to NaN)."""
    fields = ("position", "angle", "velocity", "angular_velocity", "exists")
    return all(
        np.array_equal(getattr(a, f), getattr(b, f), equal_nan=f != "exists") for f in fields
    )


# the mode of a Rerun recording drawn here and sent by the sender process (`recorder.rerun_send`)
SENDER_MODE = "sender process"


def _child_mode(child) -> str:
    """The mode of a file whose process was started beforehand: "process" for a writer
    process, SENDER_MODE for the Rerun sender."""
    from recorder.spawn import SENDER

    return SENDER_MODE if child.kind == SENDER else "process"


def _describe_offload(modes: dict, offload: str) -> str:
    """`Recorder.offload`: the mode of every writer, or each file's when they differ
    ("rrd process, mcap thread": the Rerun recording by a process started beforehand)."""
    if modes.get("rrd") == SENDER_MODE:  # "thread (rrd: sender process)": MCAP's mode first
        rest = {k: v for k, v in modes.items() if k != "rrd"}
        return f"{_describe_offload(rest, offload)} (rrd: {SENDER_MODE})" if rest else SENDER_MODE
    if len(set(modes.values())) <= 1:
        return next(iter(modes.values()), offload)
    return ", ".join(f"{k} {modes[k]}" for k in sorted(modes, key=lambda k: k != "rrd"))
