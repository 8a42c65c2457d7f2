"""The traps isaac.scene.warnings names (issue 16): friction given while world.friction is off,
bodies overlapping at step 0 beyond the slop, a body that never exists in the run, a body placed
inside a concrete body. Each is one line, at the scene key at fault; a clean scene gives none.

The geometry (isaac.scene.overlaps) is checked against plain loops written here: every pair of
bounding boxes, and SAT over every edge normal one pair at a time."""

from __future__ import annotations

import math
import random

import numpy as np
import pytest

from isaac.engine import push_out
from isaac.scene import load_scene_text, overlaps
from isaac.scene.spec import BodySpec
from isaac.scene.warnings import SLOP_SHARE, existence, scene_warnings


def _warnings(text: str, steps: int | None = None) -> list[str]:
    lines = scene_warnings(load_scene_text(text, source="s.yaml"), steps)
    assert all("\n" not in line for line in lines)
    return lines


# --- a clean scene ---------------------------------------------------------------------------

CLEAN = """
world: {steps: 100, dt: 0.01, friction: true}
bodies:
  - {name: ground, shape: {box: [10, 1]}, position: [0, -0.5], concrete: true, friction: 0.8}
  - {name: low, shape: {box: [1, 1]}, position: [0, 0.5]}
  - {name: high, shape: {box: [1, 1]}, position: [0, 1.5], enters_at: 0.5, leaves_at: 0.9}
generators:
  - pyramid: {rows: 5, box: [1, 1], base: [20, 0], friction: 0.6}
"""


def test_a_clean_scene_of_touching_boxes_gives_no_warning():
    # boxes resting on one another touch (depth 0) and their bounding boxes meet: no warning
    assert _warnings(CLEAN) == []


# --- friction given while world.friction is off ----------------------------------------------


def test_friction_given_while_world_friction_is_off_is_named_at_its_line():
    text = CLEAN.replace("friction: true", "friction: false")
    (line,) = _warnings(text)
    # the first friction key given: the ground's, on line 4 of the text (line 1 is empty)
    assert line.startswith("s.yaml:4: bodies[0].friction: friction is given but world.friction")
    assert line.endswith("and 1 more friction keys likewise")


def test_a_generators_friction_alone_is_named_at_the_generator():
    text = (
        "world: {friction: false}\ngenerators:\n  - pyramid: {rows: 2, box: [1, 1], friction: 0}\n"
    )
    (line,) = _warnings(text)
    assert line.startswith("s.yaml:3: generators[0].pyramid.friction: ")


def test_no_friction_key_gives_no_friction_warning():
    text = "bodies:\n  - {name: a, shape: {box: [1, 1]}}\n"  # world.friction defaults to off
    assert _warnings(text) == []


# --- bodies that never exist ------------------------------------------------------------------


def _brute_existence(enters, leaves, dt, steps):
    """Per body, the steps k in 0..steps with enters <= k * dt < leaves, by trying each k."""
    first, last = [], []
    for e, lv in zip(enters, leaves):
        ks = [k for k in range(steps + 1) if e <= k * dt < lv]
        first.append(ks[0] if ks else steps + 1)
        last.append(ks[-1] if ks else -1)
    return first, last


def test_existence_matches_trying_every_step_including_times_that_fall_on_a_step():
    rng = random.Random(16)
    dt, steps = 0.1, 40  # k * 0.1 is inexact: 3 * 0.1 = 0.30000000000000004 > 0.3
    enters = [k * dt for k in range(0, 45)] + [k / 10 for k in range(0, 45)]
    enters += [rng.uniform(0, 5) for _ in range(200)]
    leaves = [e + rng.choice([1e-9, 0.05, 0.1, 0.3, 2.0, math.inf]) for e in enters]
    leaves = [lv if rng.random() < 0.8 else math.inf for lv in leaves]
    bodies = [
        BodySpec(
            f"b{i}", ((0, 0), (1, 0), (0, 1)), enters_at=e, leaves_at=None if lv == math.inf else lv
        )
        for i, (e, lv) in enumerate(zip(enters, leaves))
    ]
    first, last = existence(bodies, dt, steps)
    want_first, want_last = _brute_existence(enters, leaves, dt, steps)
    exists = [k <= j for k, j in zip(want_first, want_last)]
    assert ((first <= last) == exists).all()
    got = np.flatnonzero(first <= last)
    assert first[got].tolist() == [want_first[i] for i in got]
    assert last[got].tolist() == [want_last[i] for i in got]


def test_a_body_entering_after_the_run_ends_is_named_and_steps_given_to_the_run_count():
    text = """
world: {steps: 100, dt: 0.01}
bodies:
  - {name: ground, shape: {box: [10, 1]}, position: [0, -0.5], concrete: true}
  - {name: late, shape: {box: [1, 1]}, position: [0, 3], enters_at: 0.5}
"""
    assert _warnings(text) == []  # 100 steps: t up to 1 s, it enters at step 50
    (line,) = _warnings(text, steps=10)  # `isaac run --steps 10`: t up to 0.1 s
    assert line.startswith("s.yaml:5: bodies[1]: the body 'late' enters at 0.5 s, after")
    assert "(10, t = 0.1 s)" in line and "never exists in the run" in line
    # entering exactly at the last step's time: it exists at that step
    assert _warnings(text.replace("enters_at: 0.5", "enters_at: 1.0")) == []


def test_a_body_that_enters_and_leaves_between_two_steps_is_named():
    text = """
world: {steps: 100, dt: 0.01}
bodies:
  - {name: blink, shape: {box: [1, 1]}, enters_at: 0.501, leaves_at: 0.505}
  - {name: other, shape: {box: [1, 1]}, position: [5, 0], enters_at: 0.2001, leaves_at: 0.2009}
"""
    (line,) = _warnings(text)
    assert (
        "the body 'blink' enters at 0.501 s and leaves at 0.505 s, between steps 50 and 51" in line
    )
    assert line.endswith("and 1 more bodies likewise")


# --- a body inside a concrete body -------------------------------------------------------------


INSIDE = """
world: {steps: 200, dt: 0.01}
bodies:
  - {name: wall, shape: {box: [1, 4]}, concrete: true}
  - {name: stuck, shape: {box: [0.5, 0.5]}, position: [0.3, 1.0]}
"""


def test_a_body_whose_centre_is_inside_a_concrete_body_is_named_with_its_depth():
    (line,) = _warnings(INSIDE)
    # the centre (0.3, 1.0) is 0.2 m from the wall's right face, 1 m from its top
    assert line.startswith(
        "s.yaml:5: bodies[1]: the body 'stuck' is placed inside the concrete body 'wall'"
    )
    assert "its centre 0.2 m deep" in line
    # and it is not reported a second time as an overlap at step 0
    assert "overlap" not in line


def test_a_body_entering_later_inside_concrete_is_named_unless_the_concrete_has_left():
    later = INSIDE.replace("position: [0.3, 1.0]}", "position: [0.3, 1.0], enters_at: 1.0}")
    assert "placed inside the concrete body 'wall'" in _warnings(later)[0]
    gone = later.replace("concrete: true}", "concrete: true, leaves_at: 0.5}")
    assert _warnings(gone) == []


def test_a_centre_just_outside_concrete_is_an_overlap_not_inside():
    outside = INSIDE.replace("[0.3, 1.0]", "[0.7, 1.0]")  # centre 0.2 m right of the face
    (line,) = _warnings(outside)
    assert "1 pair of bodies overlaps at step 0" in line and "by 0.05 m" in line


def test_a_body_entering_later_into_concrete_beyond_the_slop_is_named_at_its_entry():
    # a box entering at 1 s sunk 0.1 m into the floor (its centre 0.4 m above the floor)
    text = """
world: {steps: 200, dt: 0.01}
bodies:
  - {name: floor, shape: {box: [10, 1]}, position: [0, -0.5], concrete: true}
  - {name: drop, shape: {box: [1, 1]}, position: [0, 0.4], enters_at: 1.0}
"""
    (line,) = _warnings(text)
    assert line.startswith("s.yaml:5: bodies[1]: the body 'drop' enters at step 100 (t = 1 s)")
    assert "overlapping the concrete body 'floor' by 0.1 m" in line
    assert _warnings(text.replace("[0, 0.4]", "[0, 0.498]")) == []  # 2 mm: within the slop


def test_a_concrete_body_entering_where_a_body_started_is_not_warned_of():
    # the box exists from step 0 and may have moved by the time the concrete body appears
    text = """
world: {steps: 200, dt: 0.01}
bodies:
  - {name: gate, shape: {box: [10, 1]}, position: [0, -0.5], concrete: true, enters_at: 1.0}
  - {name: box, shape: {box: [1, 1]}, position: [0, 0.4]}
"""
    assert _warnings(text) == []


# --- overlaps at step 0 -----------------------------------------------------------------------


def _pair(dx: float, dy: float, size_b=(1.0, 1.0), angle_b=0.0, extra="") -> str:
    return (
        "world: {steps: 10}\nbodies:\n"
        "  - {name: a, shape: {box: [1, 1]}}\n"
        f"  - {{name: b, shape: {{box: [{size_b[0]}, {size_b[1]}]}}, position: [{dx}, {dy}], "
        f"angle: {angle_b}{extra}}}\n"
    )


def test_an_overlap_beyond_the_slop_warns_and_one_within_it_does_not():
    # two unit boxes 0.994 apart overlap by 0.006 m along x: beyond the 0.005 m slop
    (line,) = _warnings(_pair(0.994, 0.3))
    assert line.startswith("s.yaml:3: bodies[0]: 1 pair of bodies overlaps at step 0")
    assert "'a' and 'b' by 0.006 m" in line and "world.slop 0.005 m" in line
    assert _warnings(_pair(0.996, 0.3)) == []  # 0.004 m: within the slop
    # world.slop raised: the same 0.006 m is within it
    assert _warnings(_pair(0.994, 0.3).replace("{steps: 10}", "{steps: 10, slop: 0.01}")) == []


def test_the_slop_is_capped_at_a_share_of_the_thinner_body_as_the_push_out_caps_it():
    assert SLOP_SHARE == push_out.SLOP_SHARE
    # a 2 cm plank overlapping a box by 4 mm: the slop for the pair is 5 % of 2 cm = 1 mm
    assert len(_warnings(_pair(0.0, 0.506, size_b=(1.0, 0.02)))) == 1
    assert _warnings(_pair(0.0, 0.5105, size_b=(1.0, 0.02))) == []  # 0.5 mm


def test_a_diamonds_corner_sunk_into_a_box_overlaps_by_how_deep_the_corner_is():
    # a unit square turned 45 degrees: its lowest corner is 1/sqrt(2) below its centre
    half = math.sqrt(0.5)
    (line,) = _warnings(_pair(0.0, 0.5 + half - 0.02, angle_b=math.pi / 4))
    assert "by 0.02 m" in line
    assert _warnings(_pair(0.0, 0.5 + half - 0.004, angle_b=math.pi / 4)) == []


def test_bodies_not_both_present_at_step_0_are_not_an_overlap():
    assert _warnings(_pair(0.5, 0.0, extra=", enters_at: 0.05")) == []


def test_many_overlaps_are_one_line_counting_them():
    text = "world: {steps: 10}\nbodies:\n" + "".join(
        f"  - {{name: b{i}, shape: {{box: [1, 1]}}, position: [{0.5 * i}, 0]}}\n" for i in range(50)
    )
    (line,) = _warnings(text)
    # each box overlaps the next by 0.5 m; the next but one it only touches
    assert "49 pairs of bodies overlap at step 0" in line and "by 0.5 m" in line


# --- the geometry against plain loops ----------------------------------------------------------


def _random_bodies(rng: random.Random, n: int, spread: float):
    bodies = []
    for i in range(n):
        sides = rng.randint(3, 8)
        radius = rng.uniform(0.1, 0.6)
        phase = rng.uniform(0, 2 * math.pi)
        vertices = tuple(
            (
                radius * math.cos(phase + 2 * math.pi * k / sides),
                radius * math.sin(phase + 2 * math.pi * k / sides),
            )
            for k in range(sides)
        )
        position = (rng.uniform(-spread, spread), rng.uniform(-spread, spread))
        bodies.append(BodySpec(f"b{i}", vertices, position=position, angle=rng.uniform(-3, 3)))
    # a floor and a wall: boxes far larger than the grid's cells
    bodies.append(
        BodySpec("floor", ((-40, -0.5), (40, -0.5), (40, 0.5), (-40, 0.5)), position=(0, -3))
    )
    bodies.append(
        BodySpec("wall", ((-0.3, -30), (0.3, -30), (0.3, 30), (-0.3, 30)), position=(2, 0))
    )
    return bodies


def _world_polygon(body: BodySpec):
    """The body's vertices in the world, re-centred on the area centroid, with plain floats."""
    v = body.vertices
    area = cx = cy = 0.0
    for (x0, y0), (x1, y1) in zip(v, v[1:] + v[:1]):
        cross = x0 * y1 - x1 * y0
        area += cross / 2
        cx += (x0 + x1) * cross
        cy += (y0 + y1) * cross
    cx, cy = cx / (6 * area), cy / (6 * area)
    c, s = math.cos(body.angle), math.sin(body.angle)
    px, py = body.position
    return [(c * (x - cx) - s * (y - cy) + px, s * (x - cx) + c * (y - cy) + py) for x, y in v]


def _sat_depth(p, q) -> float:
    best = math.inf
    for poly in (p, q):
        for (x0, y0), (x1, y1) in zip(poly, poly[1:] + poly[:1]):
            length = math.hypot(x1 - x0, y1 - y0)
            nx, ny = (y1 - y0) / length, -(x1 - x0) / length
            pa = [nx * x + ny * y for x, y in p]
            pb = [nx * x + ny * y for x, y in q]
            # how far q must move along the normal, either way, to clear p (the MTD's
            # candidate on this axis, also when one projection holds the other)
            best = min(best, max(pa) - min(pb), max(pb) - min(pa))
    return best


def test_box_pairs_and_depths_match_every_pair_tried_one_by_one():
    rng = random.Random(7)
    bodies = _random_bodies(rng, 300, 6.0)
    placed = overlaps.place(bodies)
    a, b, complete = overlaps.box_pairs(placed.lo, placed.hi, 10**6)
    assert complete
    polygons = [_world_polygon(body) for body in bodies]
    boxes = [
        (min(x for x, _ in p), min(y for _, y in p), max(x for x, _ in p), max(y for _, y in p))
        for p in polygons
    ]
    want = [
        (i, j)
        for i in range(len(bodies))
        for j in range(i + 1, len(bodies))
        if boxes[i][0] <= boxes[j][2]
        and boxes[j][0] <= boxes[i][2]
        and boxes[i][1] <= boxes[j][3]
        and boxes[j][1] <= boxes[i][3]
    ]
    assert list(zip(a.tolist(), b.tolist())) == want
    assert len(want) > 300  # the floor and the wall meet many boxes; a real test
    depth = overlaps.depths(placed, a, b)
    expected = np.array([_sat_depth(polygons[i], polygons[j]) for i, j in want])
    np.testing.assert_allclose(depth, expected, rtol=0, atol=1e-12)
    assert (expected > 0).sum() > 50 and (expected <= 0).sum() > 50
    np.testing.assert_allclose(
        placed.thickness[-2:], [1.0, 0.6], rtol=0, atol=1e-12
    )  # the floor's and the wall's smallest widths


def test_box_pairs_stops_at_its_limit_and_says_so():
    bodies = [
        BodySpec(f"b{i}", ((0, 0), (1, 0), (1, 1), (0, 1)), position=(i * 1e-3, 0))
        for i in range(100)
    ]
    placed = overlaps.place(bodies)
    a, b, complete = overlaps.box_pairs(placed.lo, placed.hi, 1000)
    assert not complete and len(a) == 1000
    a, b, complete = overlaps.box_pairs(placed.lo, placed.hi, 100 * 99 // 2)
    assert complete and len(a) == 100 * 99 // 2


@pytest.mark.parametrize("n", [0, 1])
def test_scenes_of_fewer_than_two_bodies_have_no_pairs(n):
    lo = np.zeros((n, 2))
    a, b, complete = overlaps.box_pairs(lo, lo, 10)
    assert len(a) == 0 and complete


def test_the_overlap_warned_of_is_the_depth_the_engine_finds_at_step_0():
    from isaac import Simulation

    for text in (_pair(0.994, 0.3), _pair(0.0, 0.5 + math.sqrt(0.5) - 0.02, angle_b=math.pi / 4)):
        scene = load_scene_text(text)
        (line,) = scene_warnings(scene)
        placed = overlaps.place(scene.bodies)
        (ours,) = overlaps.depths(placed, np.array([0]), np.array([1]))
        engine = float(Simulation(scene).detect().depth.max())
        assert abs(ours - engine) < 1e-9, (ours, engine)
        assert f"by {ours:.3g} m" in line


def test_the_grid_cell_quantile_is_numpys_to_the_bit():
    # (box_pairs' cell size without np.quantile, which imports numpy.ma at start-up)
    rng = np.random.default_rng(7)
    for n in [*range(1, 60), 1000, 4321]:
        for scale in (1e-3, 1.0, 1e3):
            x = rng.random(n) * scale
            assert overlaps._quantile_90(x) == float(np.quantile(x, 0.9))


# --- containment: the MTD, not the length the projections share ------------------------------


def _depth(text: str) -> float:
    placed = overlaps.place(load_scene_text(text).bodies)
    (depth,) = overlaps.depths(placed, np.array([0]), np.array([1]))
    return float(depth)


def _two(a: str, b: str) -> str:
    return f"world: {{gravity: [0, 0]}}\nbodies:\n  - {{name: a, {a}}}\n  - {{name: b, {b}}}\n"


@pytest.mark.parametrize(
    "a, b, mtd",
    [
        # a circle of radius 0.3 centred in a 1 m box: out by 0.5 + 0.3 along any face
        ("shape: {box: [1, 1]}", "shape: {circle: {radius: 0.3}}", 0.8),
        # 0.1 m off centre: out through the nearer face, 0.5 - 0.1 + 0.3
        ("shape: {box: [1, 1]}", "shape: {circle: {radius: 0.3}}, position: [0.1, 0]", 0.7),
        # a 0.2 x 0.4 box at (0.1, 0) inside a 2 x 2 box: out to the right, 1 - (0.1 - 0.1)
        ("shape: {box: [2, 2]}", "shape: {box: [0.2, 0.4]}, position: [0.1, 0]", 1.0),
        # circle in circle: r1 + r2 - d
        (
            "shape: {circle: {radius: 1}}",
            "shape: {circle: {radius: 0.25}}, position: [0.5, 0]",
            0.75,
        ),
        # a partial overlap is unchanged: two unit boxes 0.75 m apart overlap by 0.25
        ("shape: {box: [1, 1]}", "shape: {box: [1, 1]}, position: [0.75, 0.1]", 0.25),
    ],
)
def test_the_depth_of_a_body_held_inside_another_is_its_minimum_translation_distance(a, b, mtd):
    assert _depth(_two(a, b)) == pytest.approx(mtd, abs=1e-12)
    assert _depth(_two(b, a)) == pytest.approx(mtd, abs=1e-12)  # either order


def test_a_huge_circle_swallowing_the_ground_is_reported_by_its_mtd():
    text = (
        "bodies:\n  - {name: ground, shape: {box: [20, 1]}, position: [0, -0.5], concrete: true}\n"
        "  - {name: huge, shape: {circle: {radius: 500000}}}\n"
    )
    # the ground's top (y = 0) must go below the circle's bottom (y = -5e5)
    assert _depth(text) == pytest.approx(5e5, rel=1e-12)
    (line,) = _warnings(text)
    assert "'ground' and 'huge' by 5e+05 m" in line
