"""A diverging simulation stops with a SimulationError naming the step and the body, and a log
being written keeps only the finite steps before it."""

from __future__ import annotations

import numpy as np
import pytest
from physics_helpers import box, scene

from isaac.engine.simulation import DIVERGED_POSITION, Simulation
from isaac.errors import SimulationError
from isaac.scene import validate

from .helpers import G

ABSURD_DT = 1e5  # s: one step falls about g dt^2 = 1e11 m (past the scene format's limit of
# 1 s, which the engine checks a Python-built scene against too: the scene is marked as checked,
# since the divergence guard is what these tests are about)


def _absurd() -> Simulation:
    return Simulation(
        validate.remember(
            scene(box("anvil", 1.0, 1.0), preset="balanced", gravity=(0.0, -G), dt=ABSURD_DT)
        )
    )


def _diverging_step() -> int:
    """First step whose semi-implicit free fall passes DIVERGED_POSITION (computed here)."""
    y, v, k = 0.0, 0.0, 0
    while abs(y) <= DIVERGED_POSITION:
        k += 1
        v -= G * ABSURD_DT
        y += v * ABSURD_DT
    return k


def test_absurd_dt_stops_with_an_error_naming_step_and_body():
    sim = _absurd()
    expected = _diverging_step()
    with pytest.raises(SimulationError) as info:
        for _ in range(100):
            sim.step()
    err = info.value
    assert err.step == expected
    assert err.body == "anvil"
    assert f"step {expected}" in str(err) and "'anvil'" in str(err)
    # the state is the last good one: finite, one step before the failure
    assert sim.step_index == expected - 1
    assert np.all(np.isfinite(sim.state.position))


def test_nan_in_the_state_stops_the_run_at_once():
    sim = Simulation(
        scene(
            box("anvil", 1.0, 1.0),
            box("feather", 1.0, 1.0, position=(3.0, 0.0)),
            preset="balanced",
            gravity=(0.0, 0.0),
            dt=0.01,
        )
    )
    sim.step()
    sim.state.velocity[1, 0] = np.nan  # forced: what an engine bug would produce
    with pytest.raises(SimulationError) as info:
        sim.step()
    assert info.value.step == 2 and info.value.body == "feather"


def test_a_diverging_run_never_writes_nan_into_its_log(tmp_path):
    recorder = pytest.importorskip("recorder")
    from recorder.reader import LogReader

    sim = _absurd()
    path = tmp_path / "diverge.mcap"
    rec = recorder.Recorder(sim, mcap_path=str(path))
    rec.write(sim.record())
    try:
        while True:
            rec.write(sim.step())
    except SimulationError as exc:
        rec.close(complete=False, stopped_at=sim.step_index, reason=str(exc))
    log = LogReader(str(path))
    steps = list(log.steps())
    assert steps[-1].step == _diverging_step() - 1
    assert not log.complete
    for logged in steps:
        r = logged.record
        for arr in (r.position, r.angle, r.velocity, r.angular_velocity):
            assert np.all(np.isfinite(arr)), f"non-finite value logged at step {logged.step}"
