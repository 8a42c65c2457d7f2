"""SAT: normals, MTD depths and contact points for known overlaps."""

import numpy as np
import pytest
from physics_helpers import box, scene

from isaac.engine.simulation import Simulation

DT = 0.01  # s


def contacts_of(*bodies, **world):
    return Simulation(scene(*bodies, **world)).detect()


def test_overlapping_boxes_give_normal_from_a_to_b_and_the_overlap_as_depth():
    c = contacts_of(box("a", position=(0.0, 0.0)), box("b", position=(0.8, 0.1)))
    assert len(c) == 1
    assert c.a[0] == 0 and c.b[0] == 1
    np.testing.assert_allclose(c.normal[0], [1.0, 0.0], atol=1e-15)
    assert c.depth[0] == pytest.approx(0.2, abs=1e-12)


def test_vertical_overlap_gives_vertical_normal():
    c = contacts_of(box("a", position=(0.0, 0.0)), box("b", position=(0.3, -0.95)))
    np.testing.assert_allclose(c.normal[0], [0.0, -1.0], atol=1e-15)
    assert c.depth[0] == pytest.approx(0.05, abs=1e-12)


def test_separated_shapes_have_no_contact():
    assert len(contacts_of(box("a"), box("b", position=(1.01, 0.0)))) == 0
    # bounding circles overlap but the boxes do not (a rotated box near a corner)
    assert len(contacts_of(box("a"), box("b", position=(1.05, 1.05), angle=np.pi / 4))) == 0


def test_swapping_bodies_flips_the_normal_and_keeps_the_depth():
    first = contacts_of(
        box("a", position=(0.0, 0.0), angle=0.3), box("b", 2.0, 0.5, position=(0.9, 0.4))
    )
    second = contacts_of(
        box("b", 2.0, 0.5, position=(0.9, 0.4)), box("a", position=(0.0, 0.0), angle=0.3)
    )
    assert len(first) == len(second) == 1
    np.testing.assert_allclose(second.normal[0], -first.normal[0], atol=1e-14)
    assert second.depth[0] == pytest.approx(first.depth[0], abs=1e-14)


def test_vertex_face_contact_is_at_the_penetrating_vertex():
    # b is a diamond whose lowest vertex dips 0.1 m into a's top face
    r = np.sqrt(0.5)
    c = contacts_of(
        box("a", position=(0.0, 0.0)), box("b", position=(0.2, 0.5 + r - 0.1), angle=np.pi / 4)
    )
    assert len(c) == 1
    np.testing.assert_allclose(c.normal[0], [0.0, 1.0], atol=1e-12)
    assert c.depth[0] == pytest.approx(0.1, abs=1e-12)
    np.testing.assert_allclose(c.point[0], [0.2, 0.4], atol=1e-12)


def test_face_face_contact_is_the_middle_of_the_overlapping_segment():
    # b overlaps a's right face over y in [-0.5, 0.2]: the middle is y = -0.15
    c = contacts_of(box("a"), box("b", position=(0.9, -0.3)))
    np.testing.assert_allclose(c.normal[0], [1.0, 0.0], atol=1e-15)
    assert c.point[0, 1] == pytest.approx(-0.15, abs=1e-12)


def test_two_point_manifold_gives_both_ends_of_the_overlap():
    c = contacts_of(box("a"), box("b", position=(0.9, -0.3)), contact_points=2)
    assert len(c) == 2
    np.testing.assert_allclose(sorted(c.point[:, 1]), [-0.5, 0.2], atol=1e-12)
    np.testing.assert_allclose(c.depth, [0.1, 0.1], atol=1e-12)


def test_absent_bodies_do_not_collide():
    early = box("early", position=(0.0, 0.0))
    late = box("late", position=(0.5, 0.0), enters_at=1.0)
    # a body leaves after its last step (leaves_at > enters_at, as the loader requires): after
    # one step of dt it is gone, while `late` has not entered yet
    gone = box("gone", position=(-0.5, 0.0), leaves_at=0.5 * DT)
    sim = Simulation(scene(early, late, gone, gravity=(0.0, 0.0), dt=DT))
    assert len(sim.detect()) == 1  # early and gone overlap at step 0
    sim.step()
    assert len(sim.detect()) == 0


def test_concrete_pairs_are_skipped():
    assert (
        len(contacts_of(box("a", concrete=True), box("b", position=(0.5, 0.0), concrete=True))) == 0
    )


def test_near_tie_keeps_the_previous_axis():
    # a box resting exactly on another: a's top face and b's bottom face tie; with hysteresis
    # the normal chosen in the first step is kept while the tie persists
    sim = Simulation(
        scene(
            box("low", concrete=True),
            box("high", position=(0.0, 0.999)),
            preset="balanced",
            gravity=(0.0, -9.81),
            friction=True,
        )
    )
    features = set()
    for _ in range(50):
        rec = sim.step()
        features.update(int(f) // 64 for f in rec.contacts.feature)
        np.testing.assert_allclose(rec.contacts.normal, [[0.0, 1.0]] * len(rec.contacts), atol=1e-9)
    assert len(features) == 1
