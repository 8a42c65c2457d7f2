"""A log's steps re-simulated a batch at a time, as the payload bytes the recorder would write.

A replay compares, step by step, the bytes of each logged message with the bytes of the same
step re-simulated. `ReplayedSteps` takes the steps from the engine a batch per compiled call
(`Simulation.batches`) and packs each batch's messages in one compiled call too
(`recorder.mcap_pack.BatchPacker`, the packer `isaac run` writes its logs with), so that no
Python runs per step except the comparison itself. One step a call, encoded a step at a time
(`StepEncoder`), replayed the 2-body bounce at about 8,700 steps/s, 17-18x the time a step of
the run that wrote the log; in batches 41,900 steps/s, 2.8-3.1x (bench/README.md, "Replay in
batches").

Until numba has the compiled driver (a cold cache), the steps are taken one at a time on the
staged path (`Simulation.driver_cached`), which does not wait for it to compile; until it has
the packer (`isaac run --mcap` compiles it), each step is encoded alone (`_packer_cold`).

The packer writes the current log format on little-endian machines; a log of format 1, a
machine of the other byte order, and a step the packer refuses (a NaN or an infinity in it)
take `StepEncoder`, one step at a time, as before. The bytes are the same either way: both
are the recorder's encoders, tested against each other.

Steps are simulated ahead of the log by up to a batch: a step past the log's end is computed
but never compared, and a step that diverges there stops nothing. The replay goes on from a
logged state after a difference (`restart`): what was simulated ahead is dropped.
"""

from __future__ import annotations

import sys

import numpy as np

from recorder.mcap_pack import BatchPacker, one_step_batch

# the steps of a batch: 64 for small scenes, fewer as they grow (about 4,096 body-steps a
# batch, as `isaac run` takes them), so that a log's last batch computes few steps past its end
MAX_BATCH = 64
BATCH_BODY_STEPS = 4096


class ReplayedSteps:
    """The replayed payloads of consecutive steps of one simulation, a batch at a time.

    sim: the `isaac.engine.simulation.Simulation` replaying the log; encoder: its
    `replay.compare.StepEncoder` (the one-step path); joints: the scene's joint table rows
    (`recorder.mcap_writer.joint_table_rows`); batched: whether batches are packed by the
    compiled packer (the log's format is the one it writes, and the machine little-endian);
    stop: the last step the caller will ask for, or None.
    """

    def __init__(self, sim, encoder, joints, *, batched: bool, stop: int | None = None) -> None:
        from recorder.mcap_writer import encode_world, record_channels

        self.sim = sim
        self.dt = sim.scene.world.dt
        self.encoder = encoder
        self.joints = joints
        self.stop = stop
        self.size = max(1, min(MAX_BATCH, BATCH_BODY_STEPS // max(1, sim.n_bodies)))
        channels = record_channels(bool(joints))
        self._topic = {
            channels.world: "/world",
            channels.bodies: "/bodies",
            channels.contacts: "/contacts",
            channels.joints: "/joints",
            channels.stats: "/stats",
        }
        self._packer = (
            BatchPacker(
                sim.model,
                encoder.gravity,
                self.dt,
                channels,
                joints,
                encode_world=encode_world,
            )
            if batched and sys.byteorder == "little" and not _packer_cold()
            else None
        )
        self._encode_world = encode_world
        self._last_exists: np.ndarray | None = None  # existence at the step before `next`
        self.next = sim.step_index  # the next step `payloads` can give
        self.batches = 0  # how many batches (or single staged steps) were simulated
        self._drop()

    def _drop(self) -> None:
        self._batch = None
        self._first = self.next  # the step of the batch's place 0
        self._messages: list[dict] = []  # the payloads of its first steps, packed

    def restart(self, exists: np.ndarray) -> None:
        """Go on from the simulation's state as it is now (after `Simulation.resume`), whose
        bodies' existence is ``exists``: the next step asked for is the one after it."""
        self.next = self.sim.step_index + 1
        self._last_exists = np.array(exists, dtype=bool)
        self._drop()

    def payloads(self, step: int) -> dict[str, bytes]:
        """The replayed payloads of ``step`` (topic -> bytes, ``/world`` when the set of
        existing bodies differs from the step before's): `next`, the step after the last one
        asked for (at the start, the simulation's current step, its record). Raises
        SimulationError when the step failed, with the simulation left before it."""
        if step != self.next:
            raise ValueError(f"step {step} asked for; the next replayed step is {self.next}")
        if step == self.sim.step_index and self._batch is None:  # the start: the state as it is
            record = self.sim.record()
            packed = [] if self._packer is None else self._packed(one_step_batch(record, self.dt))
            out = packed[0] if packed else self._encoded(record)
        else:
            place = step - self._first
            if self._batch is None or place >= self._batch.steps:
                if not self.sim.driver_cached:
                    # a cold cache: a step at a time on the staged path, as `step()` takes
                    # them, rather than waiting for the driver to compile
                    self.batches += 1
                    out = self._encoded(self.sim.step())
                    self.next = step + 1
                    return out
                self._new_batch(step)
                place = 0
            out = self._step_payloads(place)
        self.next = step + 1
        return out

    @property
    def next_batch(self) -> int:
        """The first step of the next batch (the step after the current batch's last)."""
        return self._first + (0 if self._batch is None else self._batch.steps)

    def _encoded(self, record) -> dict[str, bytes]:
        """A record's payloads, one step at a time (`StepEncoder`)."""
        out = self.encoder.encode(record)
        if self._last_exists is None or not np.array_equal(record.exists, self._last_exists):
            out["/world"] = self._encode_world(
                self.sim.model, record.step, record.time, record.exists, self.joints
            )
            self._last_exists = np.array(record.exists, dtype=bool)
        return out

    def _new_batch(self, step: int) -> None:
        """The batch of the steps from ``step`` on (one compiled call), packed (another)."""
        sim = self.sim
        if sim.step_index != step - 1:  # (the caller asks for the steps in order)
            raise ValueError(f"step {step} asked for at state {sim.step_index}")
        k = self.size if self.stop is None else max(1, min(self.size, self.stop - step + 1))
        self._drop()
        self._first = step
        # SimulationError when the first step fails. When a later one does, the batch holds
        # the steps before it and the simulation is left before it: the next batch takes it
        # again and raises then, at its step
        self._batch = next(sim.batches(k, size=k))
        self.batches += 1
        if self._packer is not None:
            self._messages = self._packed(self._batch)

    def _packed(self, batch) -> list[dict]:
        """The payloads of a batch's steps as `isaac run` writes them (one `pack_records` call,
        each step's sliced out of its Message records: `scan_records`), up to the first step
        the packer refuses."""
        from recorder.mcap_pack import RECORD_HEAD, scan_records

        plan = self._packer.plan(batch, self._last_exists)
        buf = np.empty(int(plan.sizes.sum()), dtype=np.uint8)
        done, end, _ = self._packer.pack(buf, 0, 0, batch.steps, batch, plan)
        if not done:
            return []
        starts, ends, channel, sequence, _ = scan_records(buf, 0, end)
        data = buf.tobytes()  # one copy; each payload a bytes slice of it
        topic = self._topic
        messages: list[dict] = [{} for _ in range(done)]
        first = batch.first
        for r in range(starts.shape[0]):
            head = int(starts[r]) + RECORD_HEAD
            messages[int(sequence[r]) - first][topic[int(channel[r])]] = data[head : int(ends[r])]
        self._last_exists = np.array(batch.exists[done - 1], dtype=bool)
        return messages

    def _step_payloads(self, place: int) -> dict[str, bytes]:
        if place < len(self._messages):
            return self._messages[place]
        # not packed (no packer, or the packer refused a step from here on): a step at a time
        return self._encoded(self._batch.record(place))


def _packer_cold() -> bool:
    """Whether numba's cache lacks the packer (`recorder.mcap_pack.pack_records`, some 14 s to
    compile on the 2-core machine; `isaac run --mcap` compiles it): the replay then encodes a
    step at a time with the frame encoder, as it did before batches, rather than wait for it."""
    from recorder.compile_ahead import cold

    return cold(mcap=True, rrd=False)
