"""The replay takes its steps a batch per compiled call and packs each batch as the recorder
does (`replay.replayed.ReplayedSteps`): it must find exactly what the replay a step at a time
found, for any batch size, and a step that fails must be reported at that step, after every
step before it was compared."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from isaac.engine.simulation import Simulation
from isaac.errors import LogError, SimulationError
from recorder.mcap_writer import encode_world, joint_table_rows
from replay import replayed
from replay.compare import StepEncoder, replay_log
from replay.replayed import ReplayedSteps
from replay.report import to_json

sys.path.insert(0, str(Path(__file__).parent))
sys.path.insert(0, str(Path(__file__).parents[1]))
from logtools import COMINGS_AND_GOINGS, STACK, bodies_changed, record  # noqa: E402
from physics_helpers import diverging  # noqa: E402


@pytest.fixture(scope="module")
def stack_log(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("stack") / "stack.mcap"
    record(path, STACK)
    return path


def _counted(monkeypatch) -> list:
    """The steps of each batch the replay packs (each call of `ReplayedSteps._packed`)."""
    packed = []
    pack = ReplayedSteps._packed

    def counting(self, batch):
        packed.append(batch.steps)
        return pack(self, batch)

    monkeypatch.setattr(ReplayedSteps, "_packed", counting)
    return packed


def _verdict(report) -> dict:
    """What a report says, without its timings."""
    out = json.loads(to_json(report))
    for key in ("elapsed_s", "steps_per_s"):
        out.pop(key, None)
    return out


def _step_at_a_time(monkeypatch, path: str, **kw):
    """The replay as it was before batches: one `step()` at a time on the staged path, each
    record encoded by `StepEncoder` (what a cold cache still takes)."""
    with monkeypatch.context() as m:
        m.setattr(Simulation, "driver_cached", property(lambda self: False))
        m.setattr(replayed, "_packer_cold", lambda: True)
        packed = _counted(m)
        report = replay_log(path, **kw)
    assert not packed
    return report


@pytest.mark.parametrize("size", [1, 7, 64])
def test_a_log_where_bodies_come_and_go_replays_identically_in_batches_of_any_size(
    tmp_path, monkeypatch, size
):
    path = tmp_path / "run.mcap"
    hashes = record(path, COMINGS_AND_GOINGS)
    monkeypatch.setattr(replayed, "MAX_BATCH", size)
    packed = _counted(monkeypatch)
    report = replay_log(str(path))
    assert report.identical and report.steps_compared == len(hashes)
    # every step came from a packed batch of at most `size` steps (step 0: the record at hand)
    assert packed[0] == 1 and max(packed) == min(size, len(hashes) - 1)
    assert sum(packed) >= len(hashes)


@pytest.mark.parametrize("all_steps", [False, True])
@pytest.mark.parametrize("size", [1, 7, 64])
def test_batches_find_the_differences_a_step_at_a_time_finds(
    stack_log, tmp_path, monkeypatch, size, all_steps
):
    changed = {5, 20, 21, 63, 64, 80}

    def bump(arrays):
        arrays["angle"][1] = np.nextafter(arrays["angle"][1], -np.inf)

    bad = tmp_path / "bad.mcap"
    bodies_changed(stack_log, bad, changed, bump)
    want = _step_at_a_time(monkeypatch, str(bad), all_steps=all_steps)
    monkeypatch.setattr(replayed, "MAX_BATCH", size)
    packed = _counted(monkeypatch)
    got = replay_log(str(bad), all_steps=all_steps)
    assert packed
    assert _verdict(got) == _verdict(want)
    assert got.divergent_steps()[0] == 5
    if all_steps:
        assert changed <= set(got.divergent_steps()) and got.steps_compared == 121


def test_a_replayed_step_that_fails_is_reported_at_its_step_and_the_replay_goes_on(
    stack_log, tmp_path, monkeypatch
):
    # the logged velocity at step k is absurd: with --all the replay goes on from it, and the
    # step after it leaves the divergence bounds (1e12 m/s) at once
    k = 30

    def absurd(arrays):
        arrays["velocity"][2] = 1e300

    bad = tmp_path / "bad.mcap"
    bodies_changed(stack_log, bad, {k}, absurd)
    want = _step_at_a_time(monkeypatch, str(bad), all_steps=True)
    got = replay_log(str(bad), all_steps=True)
    assert _verdict(got) == _verdict(want)
    failed = [d for d in got.divergences if d.channel == "simulation"]
    assert [d.step for d in failed] == [k + 1]
    assert "the replay stopped: step 31" in failed[0].detail
    # after it, from the logged step k + 1, every later step is the logged one again
    assert set(got.divergent_steps()) == {k, k + 1} and got.steps_compared == 121


def _payloads(sim, encoder, joints, records) -> list[dict]:
    """Each record's payloads as the replay a step at a time made them."""
    out, last = [], None
    for r in records:
        p = encoder.encode(r)
        if last is None or not np.array_equal(r.exists, last):
            p["/world"] = encode_world(sim.model, r.step, r.time, r.exists, joints)
            last = r.exists.copy()
        out.append(p)
    return out


def test_a_step_that_fails_inside_a_batch_fails_after_every_step_before_it_was_given():
    scene = diverging()
    staged = Simulation(scene, staged=True)
    records = [staged.record()]
    with pytest.raises(SimulationError) as want:
        for _ in range(50):
            records.append(staged.step())
    failing = want.value.step
    assert failing > 2  # (inside the first batch of 64)

    sim = Simulation(scene)
    joints = joint_table_rows(scene.joints)
    encoder = StepEncoder(sim.model, tuple(scene.world.gravity))
    expected = _payloads(staged, encoder, joints, records)
    steps = ReplayedSteps(sim, encoder, joints, batched=True)
    for s in range(failing):
        assert steps.payloads(s) == expected[s], s
    assert steps.batches == 1
    with pytest.raises(SimulationError) as got:
        steps.payloads(failing)
    assert str(got.value) == str(want.value)
    assert sim.step_index == failing - 1
    assert np.array_equal(sim.state.position, records[-1].position)

    # a replay that stops before the failing step never hears of it (its batch computed the
    # steps past the log's end, and the failure is not a step of the log)
    ahead = ReplayedSteps(Simulation(scene), encoder, joints, batched=True)
    for s in range(failing - 1):
        assert ahead.payloads(s) == expected[s]


@pytest.mark.parametrize("all_steps", [False, True])
def test_a_logged_state_the_engine_refuses_is_reported_and_the_replay_goes_on_after_it(
    stack_log, tmp_path, all_steps
):
    # the logged velocity at step k is NaN: the step differs, and the engine cannot go on from
    # it (isaac.engine.guards refuses a state that is not finite); with --all the replay takes
    # the logged step k + 1 as a new start and compares every step after it
    k = 30

    def nan(arrays):
        arrays["velocity"][2] = np.nan

    bad = tmp_path / "bad.mcap"
    bodies_changed(stack_log, bad, {k}, nan)
    got = replay_log(str(bad), all_steps=all_steps)
    assert got.divergent_steps()[0] == k
    if not all_steps:
        assert got.stopped_early
        return
    failed = [d for d in got.divergences if d.channel == "simulation"]
    assert [d.step for d in failed] == [k]
    assert "cannot go on from the logged state" in failed[0].detail
    assert "not finite" in failed[0].detail or "nan" in failed[0].detail.lower()
    assert set(got.divergent_steps()) == {k} and got.steps_compared == 120


def test_a_replay_asked_to_start_from_a_refused_logged_state_says_so_in_one_line(
    stack_log, tmp_path
):
    def nan(arrays):
        arrays["velocity"][2] = np.nan

    bad = tmp_path / "bad.mcap"
    bodies_changed(stack_log, bad, {30}, nan)
    with pytest.raises(LogError, match="step 30 cannot be replayed from: .*"):
        replay_log(str(bad), from_step=30)
