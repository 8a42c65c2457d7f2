"""Long runs: a spinning body keeps its angle. The stored angle is wrapped into [-pi, pi] by
whole turns each step, which is exact (world.wrap_angle), so the angle after N steps equals the
exactly summed rotation up to rounding of each addition (about 1e-16 rad per step)."""

from __future__ import annotations

import math

import pytest
from physics_helpers import box, scene

from isaac.engine.simulation import Simulation

OMEGA = 2.0  # rad/s
DT = 0.01  # s


def _angle_error(steps: int) -> float:
    sim = Simulation(
        scene(
            box("spinner", 1.0, 0.5, angular_velocity=OMEGA),
            preset="balanced",
            gravity=(0.0, 0.0),
            dt=DT,
        )
    )
    for _ in range(steps):
        sim.step()
    # exact: OMEGA * steps * DT turns, compared modulo 2 pi
    exact = math.remainder(OMEGA * steps * DT, 2 * math.pi)
    assert sim.body("spinner").angular_velocity == OMEGA  # a free body keeps its spin exactly
    return abs(math.remainder(sim.body("spinner").angle - exact, 2 * math.pi))


def test_spinning_body_angle_error_after_5e4_steps_below_5e8_rad():
    assert _angle_error(50_000) < 5e-8


@pytest.mark.slow
def test_spinning_body_angle_error_after_1e6_steps_below_1e6_rad():
    assert _angle_error(1_000_000) < 1e-6
