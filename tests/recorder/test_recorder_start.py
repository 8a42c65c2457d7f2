"""`Recorder` given a fresh simulation writes its step 0 itself (issue 16): a loop over
`sim.run(n)` records the whole run, step 0 included; writing step 0 again, as callers did
before, changes nothing in the file."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from isaac import Simulation, load_scene_text
from isaac.errors import LogError
from recorder import Recorder
from recorder.reader import LogReader
from replay.compare import replay_log

SCENE = """
name: start
world: {dt: 0.01, steps: 20}
bodies:
  - {name: ground, shape: {box: [10, 1]}, position: [0, -0.5], concrete: true}
  - {name: box, shape: {box: [1, 1]}, position: [0, 1.0], angular_velocity: 0.5}
"""
STEPS = 20


def _record(path, *, write_step_0: bool) -> None:
    sim = Simulation(load_scene_text(SCENE))
    with Recorder(sim, mcap_path=str(path), offload="none") as rec:
        if write_step_0:
            rec.write(sim.record())  # the way callers wrote step 0 before
        for record in sim.run(STEPS):
            rec.write(record)


def test_a_fresh_simulations_run_is_recorded_from_step_0(tmp_path):
    path = tmp_path / "run.mcap"
    _record(path, write_step_0=False)
    log = LogReader(str(path))
    steps = list(log.steps())
    assert [s.step for s in steps] == list(range(STEPS + 1))
    start = Simulation(load_scene_text(SCENE)).record()
    np.testing.assert_array_equal(steps[0].record.position, start.position)
    np.testing.assert_array_equal(steps[0].record.angular_velocity, start.angular_velocity)
    assert replay_log(str(path)).verdict == "identical"


def test_writing_step_0_again_leaves_the_file_byte_for_byte_the_same(tmp_path):
    _record(tmp_path / "auto.mcap", write_step_0=False)
    _record(tmp_path / "explicit.mcap", write_step_0=True)
    assert (tmp_path / "auto.mcap").read_bytes() == (tmp_path / "explicit.mcap").read_bytes()


def test_a_different_step_0_is_refused(tmp_path):
    sim = Simulation(load_scene_text(SCENE))
    other = sim.record()
    moved = dataclasses.replace(other, position=other.position + 1.0)
    with Recorder(sim, mcap_path=str(tmp_path / "r.mcap"), offload="none") as rec:
        with pytest.raises(LogError, match="step 0 is already recorded"):
            rec.write(moved)


def test_a_simulation_already_stepped_is_recorded_from_the_callers_first_write(tmp_path):
    sim = Simulation(load_scene_text(SCENE))
    for _ in range(5):
        sim.step()
    path = tmp_path / "later.mcap"
    with Recorder(sim, mcap_path=str(path), offload="none") as rec:
        assert rec.steps_written == 0
        rec.write(sim.record())
        for record in sim.run(3):
            rec.write(record)
    assert [s.step for s in LogReader(str(path)).steps()] == [5, 6, 7, 8]
