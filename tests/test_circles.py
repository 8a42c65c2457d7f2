"""Circles against closed forms: collisions, contact geometry, rolling and sliding.

Expected values are the textbook results (elastic collisions of equal masses, a uniform disc on
an incline) or computed independently of the engine from the scene's geometry.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from isaac.engine.simulation import Simulation
from isaac.scene import load_scene, load_scene_text, scene_to_yaml
from isaac.scene.fast_reader import read as fast_read

G = 9.81


def _sim(text: str) -> Simulation:
    return Simulation(load_scene_text(text, "<test>"))


def _two_circles(preset: str, b_position, a_velocity, radius_b=0.5) -> str:
    return f"""
world: {{gravity: [0, 0], dt: 1/240, steps: 240, fidelity: {preset}}}
bodies:
  - {{name: a, shape: {{circle: {{radius: 0.5}}}}, position: [-2, 0], velocity: {a_velocity},
      restitution: 1}}
  - {{name: b, shape: {{circle: {{radius: {radius_b}}}}}, position: {b_position},
      restitution: 1}}
"""


@pytest.mark.parametrize("preset", ["seed", "balanced"])
def test_equal_circles_at_e1_head_on_exchange_velocities_exactly(preset):
    sim = _sim(_two_circles(preset, "[1, 0]", "[3, 0]"))  # they meet at t = 2/3 s
    sim.advance(240)
    assert sim.body("a").velocity.tolist() == [0.0, 0.0]
    assert sim.body("b").velocity.tolist() == [3.0, 0.0]
    # a line-of-centres hit sets nothing spinning
    assert sim.body("a").angular_velocity == 0.0 and sim.body("b").angular_velocity == 0.0


@pytest.mark.parametrize("preset", ["seed", "balanced"])
def test_an_oblique_elastic_hit_of_equal_masses_leaves_at_right_angles(preset):
    sim = _sim(_two_circles(preset, "[0, 0.4]", "[5, 0]"))
    sim.advance(240)
    va, vb = sim.body("a").velocity, sim.body("b").velocity
    angle = math.degrees(math.acos(va @ vb / (np.linalg.norm(va) * np.linalg.norm(vb))))
    assert angle == pytest.approx(90.0, abs=1e-6)
    # the struck ball leaves along the line of centres at impact; energy and momentum kept
    assert np.linalg.norm(va) > 1.0 and np.linalg.norm(vb) > 1.0
    assert va @ va + vb @ vb == pytest.approx(25.0, rel=1e-12)
    np.testing.assert_allclose(va + vb, [5.0, 0.0], atol=1e-12)


def _polygon_distance(point, vertices):
    """Distance (m) from a point outside a convex polygon to it: the nearest of its edges."""
    best = np.inf
    for k in range(len(vertices)):
        p, q = vertices[k], vertices[(k + 1) % len(vertices)]
        t = np.clip((point - p) @ (q - p) / ((q - p) @ (q - p)), 0.0, 1.0)
        best = min(best, float(np.linalg.norm(point - (p + t * (q - p)))))
    return best


def _rotated(vertices, angle, position):
    c, s = math.cos(angle), math.sin(angle)
    v = np.asarray(vertices, dtype=float)
    centroid = v.mean(axis=0)  # a box's centroid is its vertex mean
    local = v - centroid
    return np.stack([c * local[:, 0] - s * local[:, 1], s * local[:, 0] + c * local[:, 1]], 1) + (
        position
    )


CIRCLE_HITS_BOX = """
world: {gravity: [0, 0], dt: 0.01, steps: 100, fidelity: seed}
bodies:
  - {name: box, shape: {box: [1, 2]}, position: [0, 0], angle: 0.3, restitution: 0.5}
  - {name: ball, shape: {circle: {radius: 0.3}}, position: [-2, 0.5], velocity: [4, 0],
     density: 3, restitution: 0.5}
"""


def test_a_circle_polygon_hit_matches_the_seed_formulas():
    """Depth against an independent distance, the point on the circle, the impulse from the
    seed's formula, and the velocity changes it makes (gravity off, one pass)."""
    scene = load_scene_text(CIRCLE_HITS_BOX, "<test>")
    sim = Simulation(scene)
    inv_m = 1.0 / np.array([sim.body("box").mass, sim.body("ball").mass])
    inv_i = 1.0 / np.array([sim.body("box").inertia, sim.body("ball").inertia])
    assert sim.body("ball").mass == pytest.approx(math.pi * 0.09 * 3.0, rel=1e-15)
    assert sim.body("ball").inertia == pytest.approx(0.5 * sim.body("ball").mass * 0.09, rel=1e-15)
    hits = 0
    for _ in range(100):
        before = sim.record()
        rec = sim.step()
        c = rec.contacts
        if not len(c):
            continue
        hits += 1
        assert len(c) == 1 and (c.a[0], c.b[0]) == (0, 1)
        n = c.normal[0]
        box_v = _rotated(scene.bodies[0].vertices, before.angle[0], before.position[0])
        centre = before.position[1]
        # the MTD: the radius less the centre's distance to the box (centre outside it)
        assert c.depth[0] == pytest.approx(0.3 - _polygon_distance(centre, box_v), abs=1e-12)
        assert c.pair_depth[0] == c.depth[0]
        # the point is on the ball's surface, after the push, opposite the normal
        pushed = [before.position[k] + (c.push_a[0] if k == 0 else c.push_b[0]) for k in (0, 1)]
        np.testing.assert_allclose(c.point[0], pushed[1] - 0.3 * n, atol=1e-12)
        r_a, r_b = c.point[0] - pushed[0], c.point[0] - pushed[1]
        v0, w0 = before.velocity, before.angular_velocity
        vel_a = v0[0] + w0[0] * np.array([-r_a[1], r_a[0]])
        vel_b = v0[1] + w0[1] * np.array([-r_b[1], r_b[0]])
        cross_a = r_a[0] * n[1] - r_a[1] * n[0]
        cross_b = r_b[0] * n[1] - r_b[1] * n[0]
        k = inv_m.sum() + cross_a**2 * inv_i[0] + cross_b**2 * inv_i[1]
        j = -(1.0 + 0.5) * float((vel_b - vel_a) @ n) / k
        assert c.impulse[0] == pytest.approx(j, rel=1e-12)
        np.testing.assert_allclose(rec.velocity[1], v0[1] + j * n * inv_m[1], rtol=1e-12)
        np.testing.assert_allclose(rec.velocity[0], v0[0] - j * n * inv_m[0], rtol=1e-12)
        assert rec.angular_velocity[0] == pytest.approx(w0[0] - cross_a * j * inv_i[0], rel=1e-12)
    assert hits >= 1
    assert sim.body("box").angular_velocity != 0.0  # an off-centre hit sets the box spinning


def _incline(mu: float, angle_deg: float = 20.0) -> tuple[str, float]:
    theta = math.radians(angle_deg)
    d = np.array([math.cos(theta), math.sin(theta)])
    n = np.array([-math.sin(theta), math.cos(theta)])
    centre = -0.5 * math.sin(theta), 0.5 * math.cos(theta)
    x, y = (float(v) for v in np.array(centre) + 8.0 * d + 0.5 * n)  # on the slope, 8 m up it
    text = f"""
world: {{gravity: [0, -9.81], dt: 1/240, steps: 480, friction: true}}
bodies:
  - {{name: incline, shape: {{box: [30, 1]}}, angle: {theta!r}, concrete: true, friction: {mu}}}
  - {{name: disc, shape: {{circle: {{radius: 0.5}}}}, position: [{x!r}, {y!r}], friction: {mu}}}
"""
    return text, theta


def _slope_motion(mu: float):
    """(acceleration along the slope downwards m/s^2, angular acceleration rad/s^2, speed of
    the disc's point touching the incline m/s), over 2 s after 0.2 s of settling."""
    text, theta = _incline(mu)
    sim = _sim(text)
    down = -np.array([math.cos(theta), math.sin(theta)])
    sim.advance(48)
    v1, w1, t1 = sim.body("disc").velocity @ down, sim.body("disc").angular_velocity, sim.time
    sim.advance(480)
    disc = sim.body("disc")
    v2, w2, t2 = disc.velocity @ down, disc.angular_velocity, sim.time
    r = 0.5 * np.array([math.sin(theta), -math.cos(theta)])  # centre to the touching point
    touching = disc.velocity + disc.angular_velocity * np.array([-r[1], r[0]])
    return (v2 - v1) / (t2 - t1), (w2 - w1) / (t2 - t1), float(np.linalg.norm(touching)), theta


def test_a_disc_with_enough_friction_rolls_at_two_thirds_g_sin_theta():
    mu = 0.6  # >= tan(20 deg) / 3 = 0.121
    a, alpha, slip, theta = _slope_motion(mu)
    assert a == pytest.approx(2.0 / 3.0 * G * math.sin(theta), rel=0.01)
    assert alpha == pytest.approx(a / 0.5, rel=0.01)  # rolling: alpha = a / r, counter-clockwise
    assert slip < 1e-6  # the contact point is at rest (speed ~5 m/s by then)


def test_a_disc_with_little_friction_slides_at_the_coulomb_rate():
    mu = 0.05  # < tan(20 deg) / 3
    a, alpha, slip, theta = _slope_motion(mu)
    assert a == pytest.approx(G * (math.sin(theta) - mu * math.cos(theta)), rel=0.01)
    assert alpha == pytest.approx(2.0 * mu * G * math.cos(theta) / 0.5, rel=0.01)
    assert slip > 1.0


def test_the_shipped_rolling_scene_rolls_the_disc_and_holds_the_box():
    sim = Simulation(load_scene("scenes/rolling.yaml"))
    box0 = sim.body("box").position.copy()
    sim.advance(960)
    assert np.linalg.norm(sim.body("box").position - box0) < 1e-4
    assert np.linalg.norm(sim.body("disc").velocity) == pytest.approx(
        2.0 / 3.0 * G * math.sin(0.3490658503988659) * 4.0, rel=0.01
    )


def test_circles_round_trip_through_the_log_text_and_its_fast_reader():
    scene = load_scene_text(CIRCLE_HITS_BOX, "<test>")
    text = scene_to_yaml(scene)
    assert "shape: {circle: {radius: 0.3}}" in text
    assert load_scene_text(text, "<test>") == scene
    from isaac.scene.bodies import body_alone
    from isaac.scene.loader import read_head

    fast = fast_read(text, "<test>", "inline", read_head, body_alone)
    assert fast is not None and fast == scene


@pytest.mark.parametrize(
    "shape, message",
    [
        ("{circle: {}}", "shape.circle: missing key 'radius'"),
        ("{circle: {radius: 0}}", "shape.circle.radius: 0 is out of range"),
        (
            "{circle: {radius: 6e5}}",
            "shape.circle.radius: 6e5 is out of range (must be >= 5e-07 and <= 500000.0)",
        ),
        (
            "{circle: {radius: 1, sides: 3}}",
            "shape.circle.sides: unknown key 'sides' (valid keys: radius)",
        ),
        ("{circle: {radius: 1}, box: [1, 1]}", "give exactly one of box, polygon, regular, circle"),
    ],
)
def test_a_bad_circle_is_refused_at_its_key(shape, message):
    from isaac.errors import SceneError

    with pytest.raises(SceneError) as caught:
        load_scene_text(f"bodies:\n  - {{name: c, shape: {shape}}}\n", "s.yaml")
    assert message in str(caught.value)
    assert str(caught.value).startswith("s.yaml:2: bodies[0].shape")


def test_a_circle_overlapping_the_ground_at_step_0_is_warned_about():
    from isaac.scene.warnings import scene_warnings

    text = """
world: {steps: 10}
bodies:
  - {name: ground, shape: {box: [10, 1]}, position: [0, -0.5], concrete: true}
  - {name: sunk, shape: {circle: {radius: 0.5}}, position: [3, 0.3]}
  - {name: resting, shape: {circle: {radius: 0.5}}, position: [-3, 0.5]}
  - {name: apart, shape: {circle: {radius: 0.5}}, position: [-1.9, 0.5]}
"""
    lines = scene_warnings(load_scene_text(text, "w.yaml"), 10)
    assert len(lines) == 1, lines
    assert "'ground' and 'sunk' by 0.2 m" in lines[0]
