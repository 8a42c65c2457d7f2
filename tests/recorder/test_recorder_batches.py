"""Recording whole step batches (`Recorder.write_batch`): the same file bytes as writing the
records one by one, and a NaN still stops the log at the step before it."""

from __future__ import annotations

import numpy as np
import pytest

from isaac import Simulation, load_scene
from isaac.engine.records import StepBatch
from isaac.errors import SimulationError
from recorder import Recorder
from recorder.reader import LogReader

SCENE = "scenes/default.yaml"  # contacts, bodies that enter: rows vary from step to step


def _record(path, offload, by_batch, steps=90, size=7):
    sim = Simulation(load_scene(SCENE))
    with Recorder(sim, mcap_path=str(path), offload=offload) as rec:
        rec.write(sim.record())
        for batch in sim.batches(steps, size=size):
            if by_batch:
                rec.write_batch(batch)
            else:
                for s in range(batch.steps):
                    rec.write(batch.record(s))
    return path.read_bytes()


@pytest.mark.parametrize("offload", ["process", "thread", "none"])
def test_a_batch_gives_the_bytes_of_its_records_written_one_by_one(tmp_path, offload):
    one_by_one = _record(tmp_path / "records.mcap", offload, by_batch=False)
    batched = _record(tmp_path / "batches.mcap", offload, by_batch=True)
    assert batched == one_by_one
    steps = [s.step for s in LogReader(str(tmp_path / "batches.mcap")).steps()]
    assert steps == list(range(91))


def test_a_ring_smaller_than_a_batch_takes_it_in_stretches(tmp_path, monkeypatch):
    # a ring of 64 kB holds a few of the default scene's frames (up to 16 kB a stretch):
    # write_batch must wait for the child between stretches and still give the same bytes
    import recorder.writer_process as wp

    reference = _record(tmp_path / "big.mcap", "process", by_batch=True, size=64)
    monkeypatch.setattr(wp, "ring_bytes_for", lambda kind, n: 1 << 16)
    small = _record(tmp_path / "small.mcap", "process", by_batch=True, size=64)
    assert small == reference


def _poisoned(batch: StepBatch, s: int) -> StepBatch:
    """The batch with a NaN in body 3's y at its step s (a fresh, writable copy)."""
    arrays = [batch.position.copy(), batch.angle, batch.velocity, batch.angular_velocity]
    arrays[0][s, 3, 1] = np.nan
    rest = [batch.exists, batch.offsets, *batch.row_arrays]
    return StepBatch(batch.first, batch.dt, tuple(a.copy() for a in (*arrays, *rest)), batch.steps)


@pytest.mark.parametrize("offload", ["process", "thread", "none"])
def test_a_nan_in_a_batch_stops_the_log_at_the_step_before_it(tmp_path, offload):
    sim = Simulation(load_scene(SCENE))
    path = tmp_path / "nan.mcap"
    with pytest.raises(SimulationError) as info:
        with Recorder(sim, mcap_path=str(path), offload=offload) as rec:
            rec.write(sim.record())
            for batch in sim.batches(20, size=10):
                rec.write_batch(_poisoned(batch, 4) if batch.first == 11 else batch)
    assert info.value.step == 15
    log = LogReader(str(path))
    assert [s.step for s in log.steps()] == list(range(15))
    assert log.end["complete"] == "false"
