"""The shipped scenes with circles and joints: each records and replays `identical`, the
reference path (no JIT) gives the compiled run's bits, and each shows what its comment says."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from isaac.engine.records import state_hash
from isaac.engine.simulation import Simulation
from isaac.scene import load_scene
from replay.compare import replay_log

ROOT = Path(__file__).resolve().parents[1]
SCENES = ["pendulum", "double_pendulum", "chain", "newton_cradle", "car", "rolling", "filtering"]


def _scene(name):
    return load_scene(ROOT / "scenes" / f"{name}.yaml")


@pytest.mark.parametrize("name", SCENES)
def test_a_shipped_scene_records_and_replays_identical(tmp_path, name):
    log = tmp_path / f"{name}.mcap"
    done = subprocess.run(
        [sys.executable, "-m", "isaac", "run", str(ROOT / "scenes" / f"{name}.yaml"),
         "--steps", "120", "--mcap", str(log), "--quiet"],
        cwd=ROOT, capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    result = replay_log(str(log))
    assert result.verdict == "identical"
    assert result.steps_compared == 121


_HASH = """
import sys
from isaac.engine.records import state_hash
from isaac.engine.simulation import Simulation
from isaac.scene import load_scene
sim = Simulation(load_scene(sys.argv[1]), compile_ahead=False)
sim.advance(int(sys.argv[2]))
print(state_hash(sim.record()))
"""


@pytest.mark.parametrize("name", ["double_pendulum", "car"])
def test_the_reference_path_gives_the_compiled_bits(name):
    path = str(ROOT / "scenes" / f"{name}.yaml")
    env = {**os.environ, "NUMBA_DISABLE_JIT": "1"}
    done = subprocess.run(
        [sys.executable, "-c", _HASH, path, "60"],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    sim = Simulation(_scene(name))
    sim.advance(60)
    assert done.stdout.strip() == state_hash(sim.record())


def test_newtons_cradle_passes_the_first_balls_speed_to_the_last():
    sim = Simulation(_scene("newton_cradle"))
    v = np.array([r.velocity[1:, 0] for r in sim.run(700)])
    first = np.abs(v[:, 0]).max()  # the first ball's speed at the bottom of its swing
    hit = int(np.argmax(v[:, 4] > 0.1))  # the step the last ball starts to move
    after = v[hit + 20]
    assert after[4] == pytest.approx(first, rel=0.01)
    assert np.all(np.abs(after[:4]) < 0.01 * first)


def test_the_car_drives_at_its_motors_speed_and_climbs_the_ramp():
    sim = Simulation(_scene("car"))
    records = list(sim.run(960))
    chassis = sim.model.names.index("chassis")
    wheel = sim.model.names.index("rear_wheel")
    flat = records[500]  # on the flat: rolling at the motor's speed, 8 rad/s x 0.4 m
    assert flat.angular_velocity[wheel] == pytest.approx(-8.0, rel=1e-3)
    assert flat.velocity[chassis, 0] == pytest.approx(3.2, rel=0.01)
    assert records[-1].position[chassis, 1] > 1.5  # up the ramp towards the plateau
    assert max(float(r.joints.error.max()) for r in records) < 1e-3


def test_the_double_pendulum_keeps_its_bars_pinned():
    sim = Simulation(_scene("double_pendulum"))
    errors = [float(r.joints.error[:, 0].max()) for r in sim.run(2400)]
    assert max(errors) < 1e-3
    assert state_hash(sim.record()) != state_hash(Simulation(_scene("double_pendulum")).record())
