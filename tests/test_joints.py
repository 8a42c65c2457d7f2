"""Joints against closed forms and conservation laws (thresholds in each test).

Scenes are built from the dataclasses (`JointSpec` takes every anchor in its body's frame); the
scene-file form of the same joints is tested in tests/test_joints_scene.py.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from isaac.engine.records import state_hash
from isaac.engine.simulation import Simulation
from isaac.errors import SceneError
from isaac.scene import PRESETS, BodySpec, Scene, WorldSettings
from isaac.scene.polygon import box_vertices
from isaac.scene.spec import JointSpec

G = 9.81


def _world(preset="balanced", **overrides) -> WorldSettings:
    settings = {**PRESETS[preset], "fidelity": preset, "dt": 1 / 240, "steps": 240}
    settings.update(overrides)
    return WorldSettings(**settings)


def _box(name, w, h, **fields) -> BodySpec:
    return BodySpec(name=name, vertices=tuple(map(tuple, box_vertices(w, h))), **fields)


PIN = _box("pin", 0.1, 0.1, concrete=True)


def _joint(kind, a, b, local_a=(0.0, 0.0), local_b=(0.0, 0.0), **fields) -> JointSpec:
    return JointSpec(
        name=f"{kind}-{a}-{b}", kind=kind, a=a, b=b, local_a=local_a, local_b=local_b, **fields
    )


def _scene(bodies, joints, **world) -> Scene:
    return Scene(name="joints", world=_world(**world), bodies=tuple(bodies), joints=tuple(joints))


def _period(times, x) -> float:
    """Mean period (s) between downward zero crossings of x(t), interpolated."""
    x = np.asarray(x)
    z = np.flatnonzero((x[:-1] > 0.0) & (x[1:] <= 0.0))
    crossings = times[z] + (times[z + 1] - times[z]) * x[z] / (x[z] - x[z + 1])
    assert len(crossings) >= 3
    return float(np.diff(crossings).mean())


def _pendulum(length=1.0, angle=0.05, **world) -> Scene:
    """A 5 cm disc hung from a concrete pin by a rigid distance joint (a rod of `length` m) from
    its centre: the disc turns freely, so its centre is a simple pendulum's point mass."""
    bob = BodySpec(
        name="bob",
        vertices=(),
        circle=0.05,
        position=(length * math.sin(angle), -length * math.cos(angle)),
    )
    return _scene([PIN, bob], [_joint("distance", 0, 1, length=length)], **world)


def test_a_small_angle_pendulum_swings_with_period_2pi_sqrt_l_over_g():
    sim = Simulation(_pendulum())
    records = list(sim.run(240 * 10))
    t = np.array([r.time for r in records])
    period = _period(t, [r.position[1, 0] for r in records])
    assert period == pytest.approx(2 * math.pi * math.sqrt(1.0 / G), rel=0.005)


def test_a_compound_pendulum_swings_with_period_2pi_sqrt_i_over_mgd():
    # a 1 m x 0.1 m bar pinned at one end (revolute): I about the pin = m (L^2 + w^2) / 12 + m d^2
    length, width, angle = 1.0, 0.1, 0.05
    d = length / 2
    bar = _box(
        "bar",
        width,
        length,
        position=(d * math.sin(angle), -d * math.cos(angle)),
        angle=angle,
    )
    joint = _joint("revolute", 0, 1, local_a=(0.0, 0.0), local_b=(0.0, d))
    sim = Simulation(_scene([PIN, bar], [joint]))
    records = list(sim.run(240 * 10))
    t = np.array([r.time for r in records])
    m = sim.body("bar").mass
    inertia = m * (length**2 + width**2) / 12 + m * d * d
    period = _period(t, [r.angle[1] for r in records])
    assert period == pytest.approx(2 * math.pi * math.sqrt(inertia / (m * G * d)), rel=0.005)


def test_an_undamped_pendulum_keeps_its_energy_for_60_s():
    sim = Simulation(_pendulum(angle=1.0))
    m = sim.body("bob").mass
    inertia = sim.body("bob").inertia

    def energy(r):
        v = r.velocity[1]
        return (
            0.5 * m * (v @ v)
            + 0.5 * inertia * r.angular_velocity[1] ** 2
            + m * G * (r.position[1, 1] + 1.0)
        )

    e0 = energy(sim.record())
    ratios = [energy(r) / e0 for r in sim.run(240 * 60)]
    assert 0.98 <= min(ratios) and max(ratios) <= 1.01


def _chain(links=40, link=0.25, **world) -> Scene:
    """`links` boxes joined end to end by revolute joints, the first pinned to a concrete pin,
    held out horizontally at the start: it falls and swings."""
    bodies = [PIN] + [
        _box(f"link{i}", link, 0.05, position=(link * (i + 0.5), 0.0)) for i in range(links)
    ]
    joints = [_joint("revolute", 0, 1, local_b=(-link / 2, 0.0))]
    joints += [
        _joint("revolute", i, i + 1, local_a=(link / 2, 0.0), local_b=(-link / 2, 0.0))
        for i in range(1, links)
    ]
    return _scene(bodies, joints, **world)


@pytest.mark.slow
def test_a_40_link_chain_stays_connected_for_10_s():
    # 4 sub-steps, as scenes/chain.yaml: with one, the whipping tip leaves 3.9 mm
    sim = Simulation(_chain(substeps=4))
    worst = max(float(r.joints.error[:, 0].max()) for r in sim.run(240 * 10))
    assert worst < 1e-3


@pytest.mark.parametrize("substeps", [1, 3])
def test_a_chain_gives_the_same_bits_on_every_path_and_after_a_resume(substeps):
    # (with sub-steps the driver computes the joints' errors only in a recorded step's last)
    scene = _chain(links=8, dt=1 / 120, substeps=substeps)
    staged = Simulation(scene)
    by_step = [staged.step() for _ in range(120)]
    driven = Simulation(scene)
    driven.advance(120)
    batched = list(Simulation(scene).run(120, batch=7))
    resumed = Simulation(scene, start=by_step[59])
    again = [resumed.step() for _ in range(60)]
    last = driven.record()
    for other in (batched[-1], again[-1]):
        assert state_hash(other) == state_hash(by_step[-1])
    assert state_hash(last) == state_hash(by_step[-1])
    for field in by_step[-1].joints.__dataclass_fields__:
        expected = getattr(by_step[-1].joints, field)
        for other in (last, batched[-1], again[-1]):
            assert np.array_equal(getattr(other.joints, field), expected), field
    assert by_step[-1].joints.error[:, 0].max() < 1e-3


def test_revolute_limits_hold_a_loaded_arm():
    # a 1 m arm pinned at its end, released horizontal, limited to [-0.5, 0.3] rad
    arm = _box("arm", 1.0, 0.1, position=(0.5, 0.0), density=5.0)
    joint = _joint("revolute", 0, 1, local_b=(-0.5, 0.0), lower=-0.5, upper=0.3)
    sim = Simulation(_scene([PIN, arm], [joint]))
    angles = [r.angle[1] for r in sim.run(240 * 3)]
    assert min(angles) >= -0.5 - 0.01
    assert angles[-1] == pytest.approx(-0.5, abs=0.01)  # resting on its lower limit
    assert sim.record().joints.limit_impulse[0] > 0.0  # the lower limit holds it up


def test_prismatic_limits_hold_a_loaded_slider():
    # a box on a vertical slider whose lower limit is 1 m below its start
    box = _box("box", 0.5, 0.5, position=(0.0, -0.5), density=10.0)
    joint = _joint("prismatic", 0, 1, local_a=(0.0, -0.5), axis=(0.0, 1.0), lower=-1.0, upper=1.0)
    sim = Simulation(_scene([PIN, box], [joint]))
    ys = [r.position[1, 1] for r in sim.run(240 * 3)]
    assert min(ys) >= -1.5 - 1e-3
    assert ys[-1] == pytest.approx(-1.5, abs=1e-3)
    assert abs(sim.record().position[1, 0]) < 1e-9  # it slides along the axis only
    assert abs(sim.record().angle[1]) < 1e-9


def test_a_motor_reaches_its_speed_without_exceeding_its_torque():
    torque, speed = 2.0, 5.0
    wheel = BodySpec(name="wheel", vertices=(), circle=0.5, density=2.0)
    joint = _joint("revolute", 0, 1, motor_speed=speed, max_motor=torque)
    sim = Simulation(_scene([PIN, wheel], [joint], gravity=(0.0, 0.0)))
    inertia = sim.body("wheel").inertia
    h = 1 / 240
    records = list(sim.run(240 * 3))
    motor = np.array([r.joints.motor_impulse[0] for r in records])
    assert np.all(np.abs(motor) <= torque * h * (1 + 1e-12))
    # free of load, it accelerates at torque / I until it reaches the speed, then holds it
    reach = speed * inertia / torque
    early = [r for r in records if r.time < 0.5 * reach]
    assert early[-1].angular_velocity[1] == pytest.approx(
        torque / inertia * early[-1].time, rel=1e-9
    )
    assert records[-1].angular_velocity[1] == pytest.approx(speed, rel=1e-9)


def test_a_welded_pair_moves_like_one_body():
    # two boxes welded side by side; only the first is given a spin and a push
    a = _box("a", 1.0, 1.0, position=(-0.5, 0.0), velocity=(1.0, 0.0), angular_velocity=3.0)
    b = _box("b", 1.0, 1.0, position=(0.5, 0.0), density=3.0)
    joint = _joint("weld", 0, 1, local_a=(0.5, 0.0), local_b=(-0.5, 0.0))
    sim = Simulation(Scene(name="weld", world=_world(dt=1 / 240), bodies=(a, b), joints=(joint,)))
    m = np.array([sim.body("a").mass, sim.body("b").mass])
    inertia = np.array([sim.body("a").inertia, sim.body("b").inertia])
    x0 = np.array([[-0.5, 0.0], [0.5, 0.0]])
    v0 = np.array([[1.0, 0.0], [0.0, 0.0]])
    centre = (m[:, None] * x0).sum(0) / m.sum()
    momentum = (m[:, None] * v0).sum(0)
    r = x0 - centre
    spin = 3.0 * inertia[0] + (m * (r[:, 0] * v0[:, 1] - r[:, 1] * v0[:, 0])).sum()
    combined = inertia.sum() + (m * (r**2).sum(1)).sum()  # parallel axes
    sim.advance(240)
    rec = sim.record()
    # one body of the combined mass and inertia: momentum / mass, L / I, free fall of the centre
    assert rec.angular_velocity[0] == pytest.approx(spin / combined, rel=0.01)
    assert rec.angular_velocity[1] == pytest.approx(spin / combined, rel=0.01)
    centre_v = (m[:, None] * rec.velocity).sum(0) / m.sum()
    np.testing.assert_allclose(centre_v, momentum / m.sum() + np.array([0.0, -G]), rtol=0.01)
    assert rec.joints.error.max() < 1e-3


def test_a_distance_spring_oscillates_at_its_frequency():
    hz = 2.0
    bob = BodySpec(name="bob", vertices=(), circle=0.1, position=(1.2, 0.0))
    joint = _joint("distance", 0, 1, length=1.0, stiffness=hz, damping_ratio=0.0)
    sim = Simulation(_scene([PIN, bob], [joint], gravity=(0.0, 0.0)))
    records = list(sim.run(240 * 5))
    t = np.array([r.time for r in records])
    stretch = [r.position[1, 0] - 1.0 for r in records]
    assert 1.0 / _period(t, stretch) == pytest.approx(hz, rel=0.02)


def test_a_rope_only_pulls_at_its_length():
    bob = BodySpec(name="bob", vertices=(), circle=0.1, position=(0.0, -0.5))
    # length: the anchors' distance at step 0, as the loader sets it when none is given
    joint = _joint("distance", 0, 1, length=0.5, max_length=1.0)
    sim = Simulation(_scene([PIN, bob], [joint]))
    ys = [r.position[1, 1] for r in sim.run(240 * 2)]
    assert ys[10] < -0.5  # slack: it falls freely at first
    assert ys[10] == pytest.approx(-0.5 - 0.5 * G * (11 / 240) * (12 / 240), rel=1e-9)
    assert min(ys) >= -1.0 - 1e-3  # then the rope holds it at 1 m


@pytest.mark.parametrize("collide", [False, True])
def test_connected_bodies_collide_only_when_asked(collide):
    # two overlapping boxes pinned together at their common corner
    a = _box("a", 1.0, 1.0, position=(0.0, 0.0))
    b = _box("b", 1.0, 1.0, position=(0.8, 0.0))
    joint = _joint(
        "revolute", 0, 1, local_a=(0.4, 0.5), local_b=(-0.4, 0.5), collide_connected=collide
    )
    sim = Simulation(
        Scene(name="c", world=_world(gravity=(0.0, 0.0)), bodies=(a, b), joints=(joint,))
    )
    rows = sum(len(r.contacts) for r in sim.run(20))
    assert (rows > 0) == collide


def test_joints_under_the_seed_solver_are_refused():
    scene = _pendulum()
    seed = Scene(name="s", world=_world("seed"), bodies=scene.bodies, joints=scene.joints)
    with pytest.raises(SceneError, match="sequential solver"):
        Simulation(seed)


@pytest.mark.parametrize(
    "world",
    [dict(dt=1 / 120), dict(iterations=30, position_iterations=8)],
    ids=["dt 1/120", "30 iterations, 8 passes"],
)
def test_a_whipping_chain_stays_together_with_one_sub_step(world):
    # the tip turns by h w of a radian or more a sub-step: solved about the arms the sub-step
    # starts with, each iteration pushed it further round (161 m and 685 m of joint error);
    # the Newton step about the arms it ends with keeps it within centimetres
    sim = Simulation(_chain(**world))
    steps = round(10.0 / sim.scene.world.dt)
    worst = 0.0
    fastest = 0.0
    for r in sim.run(steps):
        worst = max(worst, float(r.joints.error[:, 0].max()))
        fastest = max(fastest, float(np.abs(r.angular_velocity).max()) * sim.settings.h)
    assert fastest > 0.05  # the fast-turn branch was taken
    assert worst < 0.02, worst


def test_the_position_passes_in_waves_give_the_scene_orders_bits(monkeypatch):
    """`in_waves` reorders the joints for the position passes; every body still sees its
    joints in the scene's order, so the run is the one in the scene's order, bit for bit
    (Box2D v3's joint grid, 8 x 8: consecutive joints share bodies; 60 steps)."""
    import isaac.engine.world
    from bench.joint_grid import grid_scene
    from isaac.engine.joints import in_waves

    scene = grid_scene(8)
    waves = Simulation(scene)
    reordered = in_waves(waves.model.joints, waves.model.n_bodies)
    assert not np.array_equal(reordered.a, waves.model.joints.a)  # a different order
    monkeypatch.setattr(isaac.engine.world, "in_waves", lambda table, n: table)
    in_order = Simulation(scene)
    assert np.array_equal(in_order.model.joint_waves.a, in_order.model.joints.a)
    for sim in (waves, in_order):
        sim.advance(60)
    assert state_hash(waves.record()) == state_hash(in_order.record())
    assert np.array_equal(waves.record().joints.error, in_order.record().joints.error)
