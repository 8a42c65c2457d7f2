"""The stability suite on the shipped scenes with circles and joints (pendulum, rolling, chain):
far from the origin, under every preset that solves joints, and across time steps."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from isaac.engine.simulation import Simulation
from isaac.scene import load_scene

from .helpers import G, assert_finite, energy, shifted, with_preset

FAR = 1e6  # m
SAME_MOTION = 1e-6  # m


def _scene(name: str, **world):
    sc = load_scene(f"scenes/{name}.yaml")
    return replace(sc, world=replace(sc.world, **world)) if world else sc


@pytest.mark.parametrize("shift", [(FAR, 0.0), (-FAR, FAR)], ids=lambda s: f"{s[0]:g},{s[1]:g}")
@pytest.mark.parametrize("name, seconds", [("pendulum", 10.0), ("rolling", 4.0), ("chain", 1.0)])
def test_a_scene_with_circles_or_joints_moves_the_same_1e6_m_away(name, seconds, shift):
    # the joints' anchors are in the bodies' frames, the circle contacts relative to centres:
    # the shift leaves only float64's 1.2e-10 m resolution at 1e6 m. (The chain is chaotic
    # after its first swing: 1 s, before that.)
    base = _scene(name)
    near, far = Simulation(base), Simulation(shifted(base, *shift))
    start = near.state.position.copy()
    worst = moved = 0.0
    for _ in range(round(seconds / base.world.dt)):
        a, b = near.step(), far.step()
        moved = max(moved, float(np.abs(a.position - start).max()))
        worst = max(worst, float(np.abs(b.position - np.asarray(shift) - a.position).max()))
        worst = max(worst, float(np.abs(b.angle - a.angle).max()))
        if a.joints is not None:  # what the position pass left, the same near and far
            worst = max(worst, float(np.abs(b.joints.error - a.joints.error).max()))
    assert moved > 0.1  # m: it moved
    assert worst < SAME_MOTION, f"relative motion differs by {worst:.3g} m"


@pytest.mark.slow
@pytest.mark.parametrize("preset", ["fast", "balanced", "accurate"])
def test_the_chain_stays_finite_connected_and_gains_no_energy_under_every_preset(preset):
    # released at rest, horizontal, at y = 0: its energy (potential about y = 0) starts at 0
    # and a passive chain can only lose it; a whipping tip must not pump it up
    sim = Simulation(with_preset(_scene("chain"), preset))
    scale = float(sim.model.mass[~sim.model.concrete].sum()) * G * 10.0  # J: m g L
    e0 = energy(sim, sim.record())
    worst_error, peak = 0.0, -math.inf
    for rec in sim.run(2400):  # 10 s
        worst_error = max(worst_error, float(rec.joints.error[:, 0].max()))
        peak = max(peak, energy(sim, rec))
    assert_finite(sim)
    assert peak <= e0 + 1e-3 * scale, (peak - e0) / scale
    assert worst_error < 0.02, worst_error  # m: connected (a link is 0.25 m)


def _small_angle_period(theta0: float, length: float) -> float:
    """A simple pendulum's period (s) at amplitude theta0 (rad): the series in theta0^2."""
    return 2 * math.pi * math.sqrt(length / G) * (1 + theta0**2 / 16 + 11 * theta0**4 / 3072)


def _period(sim: Simulation, steps: int) -> float:
    """Mean period (s) between the bob's downward crossings of x = 0, interpolated."""
    t, x = [], []
    for rec in sim.run(steps):
        t.append(rec.time)
        x.append(rec.position[1, 0])
    t, x = np.array(t), np.array(x)
    z = np.flatnonzero((x[:-1] > 0.0) & (x[1:] <= 0.0))
    crossings = t[z] + (t[z + 1] - t[z]) * x[z] / (x[z] - x[z + 1])
    return float(np.diff(crossings).mean())


def test_the_pendulums_period_converges_as_dt_shrinks():
    exact = _small_angle_period(0.1, 1.0)
    errors = []
    for dt in (1 / 30, 1 / 120, 1 / 480):
        sim = Simulation(_scene("pendulum", dt=dt))
        errors.append(abs(_period(sim, round(10.0 / dt)) / exact - 1.0))
        assert_finite(sim)
        assert float(sim.record().joints.error.max()) < 1e-3
    assert errors[0] > errors[1] > errors[2]
    assert errors[2] < 1e-3, errors


@pytest.mark.parametrize("preset", ["fast", "balanced", "accurate"])
@pytest.mark.parametrize("dt", [1 / 30, 1 / 240])
def test_the_disc_rolls_without_slipping_under_every_preset_and_dt(preset, dt):
    theta = 0.3490658503988659  # the incline's angle (rad)
    sc = with_preset(_scene("rolling", dt=dt), preset)
    sim = Simulation(sc)
    down = -np.array([math.cos(theta), math.sin(theta)])
    sim.advance(round(0.2 / dt))
    v1, t1 = sim.body("disc").velocity @ down, sim.time
    sim.advance(round(2.0 / dt))
    disc = sim.body("disc")
    a = (disc.velocity @ down - v1) / (sim.time - t1)
    assert a == pytest.approx(2.0 / 3.0 * G * math.sin(theta), rel=0.01)
    r = 0.5 * np.array([math.sin(theta), -math.cos(theta)])  # centre to the touching point
    touching = disc.velocity + disc.angular_velocity * np.array([-r[1], r[0]])
    assert np.linalg.norm(touching) < 1e-3  # m/s, at a speed of about 5 m/s
    assert np.linalg.norm(sim.body("box").position - sc.bodies[2].position) < 1e-3
