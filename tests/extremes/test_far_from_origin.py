"""Far from the origin: float64 keeps about 1e-10 m of resolution at 1e6 m, so a scene shifted
by 1e6 m must move the same relative to its shift (float32 could not move a body at 0.01 m/s
there, NOTES.md 6)."""

from __future__ import annotations

import numpy as np
import pytest

from isaac.engine.simulation import Simulation
from isaac.scene import load_scene, load_scene_text

from .helpers import run, shifted

FAR = 1e6  # m
SAME_MOTION = 1e-6  # m over 10 s
SHIFTS = [(FAR, 0.0), (0.0, FAR), (FAR, FAR), (-FAR, -FAR)]


@pytest.mark.parametrize("shift", SHIFTS, ids=lambda s: f"{s[0]:g},{s[1]:g}")
@pytest.mark.parametrize("name", ["bounce", "head_on"])
def test_shifted_scene_moves_the_same_for_10_s(name, shift):
    base = load_scene(f"scenes/{name}.yaml")
    steps = round(10.0 / base.world.dt)
    near, far = Simulation(base), Simulation(shifted(base, *shift))
    worst = 0.0
    for _ in range(steps):
        a, b = near.step(), far.step()
        worst = max(worst, float(np.abs(b.position - np.asarray(shift) - a.position).max()))
        worst = max(worst, float(np.abs(b.angle - a.angle).max()))
    # the scene must actually move (not a vacuous pass)
    assert np.abs(near.state.position - np.array([b.position for b in base.bodies])).max() > 1.0
    assert worst < SAME_MOTION, f"relative motion differs by {worst:.3g} m"


def _pile(count: int, width: float) -> str:
    return (
        f"world: {{dt: 0.016666666666666666, friction: true}}\n"
        f"generators: [{{pile: {{count: {count}, seed: 1, container: {{width: {width}}}, "
        f"friction: 0.6}}}}]\n"
    )


def _pile_run(text: str, shift, steps: int):
    sc = shifted(load_scene_text(text), *shift)
    sim = Simulation(sc)
    trace = run(sim, steps)
    pos = sim.state.position - np.asarray(shift)
    moving = ~sim.model.concrete
    return trace, pos[moving]


def _check_pile(count: int, width: float, steps: int) -> None:
    text = _pile(count, width)
    floor_top, wall_x = 0.0, width / 2  # the container's inside (docs/scene-format.md)
    near, pos_near = _pile_run(text, (0.0, 0.0), steps)
    far, pos_far = _pile_run(text, (FAR, FAR), steps)
    settled = steps // 10  # the last tenth of the run
    for trace, pos in ((near, pos_near), (far, pos_far)):
        # stays in its container: every centre above the floor and between the walls
        assert pos[:, 1].min() > floor_top, pos[:, 1].min()
        assert np.abs(pos[:, 0]).max() < wall_x, np.abs(pos[:, 0]).max()
        # bounded overlap: settled contacts within 2 cm, the drop's peak within 0.3 m
        assert max(trace.depth[-settled:]) < 0.02, max(trace.depth[-settled:])
        assert trace.max_depth < 0.3, trace.max_depth
    # and the shift does not make it worse
    assert far.max_depth <= 1.5 * near.max_depth + 0.01, (far.max_depth, near.max_depth)


def test_pile_shifted_1e6_m_stays_in_its_container():
    _check_pile(100, 8.0, 600)


@pytest.mark.slow
def test_pile_of_500_shifted_1e6_m_stays_in_its_container():
    _check_pile(500, 20.0, 1200)
