"""Deep stacks: a column of 30 boxes (scenes/stack.yaml) stays standing."""

from __future__ import annotations

import numpy as np
import pytest

from isaac.engine.simulation import Simulation
from isaac.scene import load_scene

from .helpers import run, with_preset

HEIGHT = 30
DT = 1 / 60
SIDEWAYS = 0.1  # m: largest sideways displacement of any box
SINK = 0.01 * HEIGHT  # m: largest vertical displacement of any box, 1% of the column's height
# (each contact may keep up to `slop` = 5 mm of overlap, 30 contacts 0.15 m)
TILT = 0.05  # rad


def _column(preset: str, steps: int) -> None:
    sc = with_preset(load_scene("scenes/stack.yaml"), preset)  # 30 boxes, friction, dt 1/60
    assert len(sc.bodies) == HEIGHT + 1 and sc.world.dt == DT and sc.world.friction
    sim = Simulation(sc)
    trace = run(sim, steps, keep_states=True)
    pos = np.array(trace.position)[:, 1:]  # (steps, 30, 2), without the ground
    nominal_y = 0.5 + np.arange(HEIGHT)
    dx = np.abs(pos[:, :, 0]).max(axis=1)
    dy = np.abs(pos[:, :, 1] - nominal_y).max(axis=1)
    tilt = np.abs(np.array(trace.angle)[:, 1:]).max(axis=1)
    bad = (dx > SIDEWAYS) | (dy > SINK) | (tilt > TILT)
    first = int(np.argmax(bad)) + 1 if bad.any() else None
    assert first is None, (
        f"{preset}: the column failed at step {first} (t = {first * DT:.2f} s); over the run "
        f"max sideways {dx.max():.4g} m, max vertical {dy.max():.4g} m, max tilt "
        f"{tilt.max():.4g} rad; top box ends at {pos[-1, -1].round(3).tolist()}"
    )


def test_thirty_box_column_stands_for_10_s_under_balanced():
    _column("balanced", 600)


def test_thirty_box_column_stands_for_10_s_under_accurate():
    _column("accurate", 600)


@pytest.mark.slow
def test_thirty_box_column_stands_for_60_s_under_balanced():
    _column("balanced", 3600)
