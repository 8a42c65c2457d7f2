"""Free fall and long spins against the integrators' closed forms."""

import math

import pytest
from physics_helpers import box, scene

from isaac.engine.simulation import Simulation

G = 9.81
H = 0.01


@pytest.mark.parametrize("integrator, offset", [("explicit", -1), ("semi_implicit", +1)])
def test_free_fall_matches_the_integrators_closed_form(integrator, offset):
    # explicit: y_n = y0 + v0 n h - g h^2 n (n - 1) / 2; semi-implicit: ... n (n + 1) / 2
    y0, v0 = 10.0, 2.0
    sim = Simulation(
        scene(
            box("ball", position=(0.0, y0), velocity=(0.0, v0)),
            gravity=(0.0, -G),
            dt=H,
            integrator=integrator,
        )
    )
    for rec in sim.run(200):
        n = rec.step
        expected_y = y0 + v0 * n * H - G * H * H * n * (n + offset) / 2
        assert rec.position[0, 1] == pytest.approx(expected_y, rel=1e-12, abs=1e-12)
        assert rec.velocity[0, 1] == pytest.approx(v0 - G * H * n, rel=1e-12, abs=1e-12)


def test_concrete_body_never_moves_under_gravity():
    sim = Simulation(
        scene(
            box("rock", position=(1.0, 2.0), concrete=True, velocity=(5.0, 0.0)), gravity=(0.0, -G)
        )
    )
    for rec in sim.run(50):
        assert rec.position[0].tolist() == [1.0, 2.0]
        assert rec.velocity[0].tolist() == [0.0, 0.0]


def test_spin_keeps_its_angle_bounded_and_exact_over_a_long_run():
    w = 7.3  # rad/s
    steps = 100_000
    sim = Simulation(scene(box("spinner", angular_velocity=w), dt=H))
    for _ in sim.run(steps):
        pass
    rec = sim.record()
    assert -math.pi <= rec.angle[0] <= math.pi
    # the exact angle, reduced into [-pi, pi]
    error = math.remainder(rec.angle[0] - w * H * steps, 2 * math.pi)
    assert abs(error) < 1e-9


def test_time_is_step_index_times_dt():
    sim = Simulation(scene(box("b"), dt=0.1))
    for rec in sim.run(30):
        assert rec.time == rec.step * 0.1


def test_bodies_enter_and_leave_at_their_times():
    sim = Simulation(
        scene(
            box("late", position=(0.0, 5.0), enters_at=0.5),
            box("brief", position=(3.0, 5.0), leaves_at=0.3),
            gravity=(0.0, -G),
            dt=0.1,
        )
    )
    history = [(rec.time, rec.exists.tolist(), rec.position[:, 1].tolist()) for rec in sim.run(10)]
    for t, exists, _y in history:
        assert exists == [t >= 0.5, t < 0.3]
    # a body that has not entered stays where the scene put it; one that left stays where it was
    assert history[3][2][0] == 5.0
    assert history[-1][2][1] == history[2][2][1] < 5.0


@pytest.mark.parametrize("how", ["staged", "step", "advance"])
@pytest.mark.parametrize("spin", [math.inf, 1e19, 2e9])
def test_a_spin_past_any_scene_fails_at_its_step_instead_of_wrapping_for_ever(how, spin):
    # |w h| = 1e17 rad: x - 2 pi == x, the turn-by-turn wrap never ended; inf: the same;
    # 2e7 rad: 3 million turns, past WRAP_LIMIT (a scene's first step moves at most 1e6 rad)
    from isaac.engine.integrate import WRAP_LIMIT
    from isaac.errors import SimulationError

    sim = Simulation(scene(box("top", angular_velocity=1.0)), staged=how == "staged")
    sim.step()
    assert abs(spin * H) > WRAP_LIMIT
    sim.state.angular_velocity[0] = spin
    with pytest.raises(SimulationError) as err:
        sim.advance(1) if how == "advance" else sim.step()
    assert err.value.step == 2 and err.value.body == "top"
    assert "angle" in str(err.value)
    assert sim.step_index == 1  # the failing step was undone


def test_the_fastest_spin_a_scene_may_start_with_still_wraps():
    from isaac.scene.limits import MAX_SPEED

    sim = Simulation(scene(box("top", angular_velocity=MAX_SPEED), dt=1.0))
    rec = sim.step()
    assert abs(rec.angle[0]) <= math.pi
    # 159,155 turns subtracted one at a time, each rounded: within 1e-3 rad of the exact angle
    assert abs(math.remainder(rec.angle[0] - MAX_SPEED, 2 * math.pi)) < 1e-3
