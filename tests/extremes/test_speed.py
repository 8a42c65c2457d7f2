"""Speed: a small box (0.1 m) at 10 to 1000 m/s against a 0.05 m thick concrete wall, from many
starting offsets (where the last step before the wall lands decides tunneling, NOTES.md 6)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from physics_helpers import box, scene

from isaac.engine.simulation import Simulation
from isaac.scene import load_scene

from .helpers import with_preset

DT = 1 / 60
WALL = 0.05  # m thick, face at x = -WALL / 2
BULLET = 0.1  # m side
SPEEDS = (10, 20, 50, 100, 200, 500, 1000)  # m/s
SCAN = (1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 15, 20, 30, 50, 100, 200, 500, 1000)
OFFSETS = 20  # starting offsets per speed, spread over one step of travel
REST_GAP = 0.01  # m: with e = 0 the box must end touching the wall, not short of it


def _shoot(speed: float, offset: float, ccd: str) -> tuple[bool, float]:
    """(went through, final gap to the wall's face in m) for one shot from 0.5 m + offset."""
    start = -0.5 - offset * speed * DT
    sim = Simulation(
        scene(
            box("wall", WALL, 4.0, concrete=True),
            box("bullet", BULLET, BULLET, position=(start, 0.0), velocity=(speed, 0.0)),
            preset="balanced",
            ccd=ccd,
            gravity=(0.0, 0.0),
            dt=DT,
        )
    )
    steps = math.ceil((abs(start) + 2.0) / (speed * DT)) + 5
    crossed = False
    for _ in range(steps):
        sim.step()
        crossed |= bool(sim.body("bullet").position[0] > 0.0)
    gap = -WALL / 2 - (sim.body("bullet").position[0] + BULLET / 2)
    return crossed, gap


def _offsets():
    return np.linspace(0.0, 1.0, OFFSETS, endpoint=False)


@pytest.mark.parametrize("speed", SPEEDS)
def test_ccd_never_lets_a_fast_box_through_a_thin_wall(speed):
    through = [o for o in _offsets() if _shoot(speed, o, "speculative")[0]]
    assert not through, f"{speed} m/s went through the wall from offsets {through}"


def test_ccd_stops_a_fast_box_at_the_wall_not_short_of_it():
    # e = 0: the box must end at rest against the wall. A speculative contact may only take away
    # the approach speed beyond the gap (v_n >= -gap / dt); stopping early is a bug.
    short = {}
    for speed in SPEEDS:
        gaps = [_shoot(speed, o, "speculative")[1] for o in _offsets()]
        assert min(gaps) > -WALL, f"{speed} m/s: ended {-min(gaps):.4g} m inside the wall"
        short[speed] = max(gaps)
    assert max(short.values()) < REST_GAP, (
        "stopped short of the wall by up to (m, per speed in m/s): "
        + ", ".join(f"{v}: {g:.3g}" for v, g in short.items())
    )


def test_without_ccd_tunneling_begins_above_half_the_combined_thickness_per_step(record_property):
    """Without ccd: below v dt = (WALL + BULLET) / 2 the push-out always picks the near side,
    so nothing passes; at 1000 m/s (16.7 m per step) everything does. The onset speed between
    is recorded (docs/tradeoff.md)."""
    fraction = {}
    for speed in SCAN:
        fraction[speed] = np.mean([_shoot(speed, o, "off")[0] for o in _offsets()])
    onset = min((s for s in SCAN if fraction[s] > 0.0), default=None)
    record_property("tunneling_onset_mps", onset)
    print(
        f"\ntunneling without ccd at dt = 1/60 s (fraction of {OFFSETS} offsets): "
        + ", ".join(f"{s}: {fraction[s]:.2f}" for s in SCAN)
        + f"; onset {onset} m/s"
    )
    safe = (WALL + BULLET) / 2 / DT  # 4.5 m/s
    assert all(fraction[s] == 0.0 for s in SCAN if s < safe), fraction
    assert fraction[1000] == 1.0, fraction
    assert onset is not None and onset >= safe


@pytest.mark.parametrize("dt", [1 / 60, 1 / 120], ids=["1/60", "1/120"])
def test_ccd_bounces_a_falling_box_off_the_ground_not_off_the_air(dt):
    """bounce.yaml (e = 0.8) under balanced: the impact falls inside a step, so no recorded
    state touches the ground; the step that bounces must end where the reflection *at the
    ground* puts the box: e times as far above it as the box would have sunk below it, had the
    ground not been there (not reversed in the air, where the speculative gap opened)."""
    sc = with_preset(load_scene("scenes/bounce.yaml"), "balanced")
    sim = Simulation(replace(sc, world=replace(sc.world, dt=dt)))
    box_index = sim.model.names.index("box")
    half_height, e, g = 0.5, 0.8, 9.81
    prev = sim.record()
    for _ in range(round(1.5 / dt)):  # the first impact is at 0.96 s
        rec = sim.step()
        if rec.velocity[box_index, 1] > 0.0:
            break
        prev = rec
    else:
        pytest.fail("the box never bounced")
    # where semi-implicit Euler would have taken the box without the ground (m, below it < 0)
    v_free = prev.velocity[box_index, 1] - g * dt
    sunk = -(prev.position[box_index, 1] + v_free * dt - half_height)
    assert sunk > 0.0
    gap = rec.position[box_index, 1] - half_height
    assert gap == pytest.approx(e * sunk, abs=1e-9), (gap, e * sunk)
    # the impact happens after this step's gravity: it reflects e times the speed it hit with
    assert rec.velocity[box_index, 1] == pytest.approx(-e * v_free, rel=1e-9)
