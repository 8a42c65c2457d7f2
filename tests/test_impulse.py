"""Collision impulses against the seed's formula and the conservation laws."""

import numpy as np
import pytest
from physics_helpers import box, scene

from isaac.engine.simulation import Simulation


def first_contact_step(sim):
    for rec in sim.run():
        if len(rec.contacts):
            return rec
    raise AssertionError("no contact happened")


def momentum(sim, rec):
    return (sim.model.mass[:, None] * rec.velocity).sum(axis=0)


def test_equal_masses_with_e_1_exchange_velocities_exactly_without_spin():
    sim = Simulation(
        scene(
            box("left", position=(-2.0, 0.0), velocity=(3.0, 0.0), restitution=1.0),
            box("right", position=(2.0, 0.0), velocity=(-1.0, 0.0), restitution=1.0),
        )
    )
    rec = first_contact_step(sim)
    assert rec.velocity.tolist() == [[-1.0, 0.0], [3.0, 0.0]]
    assert rec.angular_velocity.tolist() == [0.0, 0.0]


def test_e_0_leaves_zero_relative_normal_velocity():
    sim = Simulation(
        scene(
            box("a", position=(-2.0, 0.0), velocity=(3.0, 0.5), restitution=0.0),
            box(
                "b",
                2.0,
                1.0,
                position=(2.0, 0.2),
                velocity=(-1.0, 0.0),
                restitution=0.0,
                density=3.0,
            ),
        )
    )
    rec = first_contact_step(sim)
    c = rec.contacts
    n = c.normal[0]
    r_a = c.point[0] - (rec.position[0] - rec.velocity[0] * 0.01)
    r_b = c.point[0] - (rec.position[1] - rec.velocity[1] * 0.01)

    def point_velocity(i, r):
        w = rec.angular_velocity[i]
        return rec.velocity[i] + w * np.array([-r[1], r[0]])

    vn = (point_velocity(1, r_b) - point_velocity(0, r_a)) @ n
    assert vn == pytest.approx(0.0, abs=1e-12)


def test_momentum_is_conserved_between_dynamic_bodies():
    sim = Simulation(
        scene(
            box("a", position=(-2.0, 0.1), velocity=(3.0, 0.5), angle=0.2, restitution=0.7),
            box(
                "b",
                2.0,
                1.0,
                position=(2.0, 0.0),
                velocity=(-1.0, 0.0),
                restitution=0.3,
                density=3.0,
            ),
        )
    )
    before = momentum(sim, sim.record())
    rec = first_contact_step(sim)
    assert rec.contacts.impulse[0] > 0.0
    np.testing.assert_allclose(momentum(sim, rec), before, rtol=0, atol=1e-12)


def test_body_against_concrete_reverses_its_normal_velocity_times_e():
    sim = Simulation(
        scene(
            box("ground", 10.0, 1.0, position=(0.0, 0.0), concrete=True, restitution=0.5),
            box("falling", position=(0.0, 2.0), velocity=(0.7, -4.0), restitution=0.5),
            restitution_rule="max",
        )
    )
    rec = first_contact_step(sim)
    assert rec.velocity[1, 1] == pytest.approx(2.0, rel=1e-12)
    assert rec.velocity[1, 0] == 0.7
    assert rec.angular_velocity[1] == pytest.approx(0.0, abs=1e-12)
    assert rec.position[0].tolist() == [0.0, 0.0]
    assert rec.contacts.push_a[0].tolist() == [0.0, 0.0]


def test_off_centre_hit_spins_as_the_formula_predicts():
    # a small box hits the lower half of a long bar: the bar picks up angular velocity
    # w_b = (r_b x j n) / I_b with j from the seed's formula
    e = 1.0
    sim = Simulation(
        scene(
            box("bullet", 0.2, 0.2, position=(-1.0, -0.6), velocity=(5.0, 0.0), restitution=e),
            box("bar", 0.2, 2.0, position=(0.0, 0.0), restitution=e),
        )
    )
    before = sim.record()
    rec = first_contact_step(sim)
    c = rec.contacts
    m, inertia = sim.model.mass, sim.model.inertia
    n = c.normal[0]
    x_a = before.position[0] + before.velocity[0] * (rec.step - 1) * 0.01 + c.push_a[0]
    x_b = before.position[1] + c.push_b[0]
    r_a, r_b = c.point[0] - x_a, c.point[0] - x_b

    def cross(u, v):
        return u[0] * v[1] - u[1] * v[0]

    v_ab = (before.velocity[1] - before.velocity[0]) @ n
    j = (
        -(1 + e)
        * v_ab
        / (1 / m[0] + 1 / m[1] + cross(r_a, n) ** 2 / inertia[0] + cross(r_b, n) ** 2 / inertia[1])
    )
    assert c.impulse[0] == pytest.approx(j, rel=1e-12)
    assert rec.angular_velocity[1] == pytest.approx(cross(r_b, j * n) / inertia[1], rel=1e-12)
    assert rec.angular_velocity[1] > 0.0  # pushed +x below its centre: counter-clockwise
    np.testing.assert_allclose(rec.velocity[1], j * n / m[1], rtol=1e-12)


def test_no_impulse_when_bodies_separate():
    # overlapping but moving apart: the push-out separates them and no impulse is applied
    sim = Simulation(
        scene(
            box("a", position=(0.0, 0.0), velocity=(-1.0, 0.0)),
            box("b", position=(0.9, 0.0), velocity=(1.0, 0.0)),
        )
    )
    rec = sim.step()
    assert len(rec.contacts) == 1
    assert rec.contacts.impulse[0] == 0.0
    assert rec.velocity.tolist() == [[-1.0, 0.0], [1.0, 0.0]]


def test_push_out_leaves_no_overlap():
    sim = Simulation(
        scene(
            box("a", position=(0.0, 0.0), angle=0.1),
            box("b", 1.5, 0.7, position=(0.7, 0.45), angle=-0.4, density=2.0),
        )
    )
    assert len(sim.detect()) == 1
    sim.step()
    assert len(sim.detect()) == 0 or sim.detect().depth.max() <= 1e-12


def test_push_is_shared_by_inverse_mass():
    sim = Simulation(
        scene(
            box("light", position=(0.0, 0.0), density=1.0),
            box("heavy", position=(0.9, 0.0), density=3.0),
        )
    )
    c = sim.step().contacts
    assert c.push_a[0, 0] == pytest.approx(-0.075, abs=1e-15)
    assert c.push_b[0, 0] == pytest.approx(0.025, abs=1e-15)
