"""bench/joint_scenes.py: pymunk's chain and cradle are ISAAC's scenes (same masses, moments,
poses, anchors), and the quality figures read what they say."""

from __future__ import annotations

import numpy as np
import pytest

from bench import joint_scenes
from isaac.engine.simulation import Simulation

pymunk = pytest.importorskip("pymunk")


@pytest.mark.parametrize("name", joint_scenes.SCENES)
def test_pymunks_version_has_isaacs_bodies_and_anchors(name):
    scene = joint_scenes._scene(name)
    sim = Simulation(scene)
    space, bodies, joints = joint_scenes._pymunk_space(scene)
    for i, body in enumerate(bodies):
        assert tuple(body.position) == scene.bodies[i].position
        if scene.bodies[i].concrete:
            continue
        assert body.mass == pytest.approx(sim.model.mass[i], rel=1e-12)
        assert body.moment == pytest.approx(sim.model.inertia[i], rel=1e-9)
    start = sim.record().joints
    for k, j in enumerate(joints):
        # the anchors pymunk holds together are ISAAC's, in the world at step 0
        a = j.a.local_to_world(j.anchor_a)
        b = j.b.local_to_world(j.anchor_b)
        assert np.allclose([*a], start.anchor_a[k], atol=1e-12)
        assert np.allclose([*b], start.anchor_b[k], atol=1e-12)
        assert not j.collide_bodies
    assert len(joints) == len(scene.joints)


def test_the_cradles_figure_is_the_last_balls_speed_over_the_first_balls():
    # the first ball swings in at 2 m/s, stops at the hit (step 10); the last leaves at 1.9 m/s
    vx = np.zeros((40, 5))
    vx[:10, 0] = np.linspace(0.5, 2.0, 10)
    vx[10:, 4] = 1.9
    vx[10:, 2] = -0.02
    q = joint_scenes.cradle_quality(vx)
    assert q["last_over_first"] == pytest.approx(0.95)
    assert q["middle_over_first"] == pytest.approx(0.01)
    errors = np.array([[1e-4, 3e-4], [2e-4, 1e-4]])
    assert joint_scenes.chain_quality(errors) == {"worst_joint_error_m": 3e-4}
