"""The `joints:` section of scene files: parsing to JointSpecs (anchors and axes turned into the
bodies' frames at step 0), the round trip through `scene_to_yaml` (YAML and fast readers), the
checks a JointSpec built in Python passes, and every refusal as one line naming file, line and
key."""

import argparse
import dataclasses
import json
import math

import pytest

from isaac.app.run import cmd_check
from isaac.errors import SceneError
from isaac.scene import checks, fast_reader, load_scene, load_scene_text, loader, scene_to_yaml
from isaac.scene.bodies import body_alone
from isaac.scene.checks import first_joint_problem, joint_problem
from isaac.scene.joints import joint_alone
from isaac.scene.reader import compose
from isaac.scene.spec import JointSpec

BODIES = """\
bodies:
  - name: ceiling
    shape: {box: [4.0, 0.2]}
    position: [0.0, 5.0]
    angle: 0.25
    concrete: true
  - name: wheel_left
    shape: {circle: {radius: 0.4}}
    position: [1.5, 3.0]
    angle: 0.7
  - name: chassis
    shape: {box: [2.0, 0.5]}
    position: [3.0, 2.5]
    angle: -2.9
  - name: floor
    shape: {box: [10.0, 1.0]}
    position: [0.0, -1.0]
    concrete: true
"""
BODY_LINES = BODIES.count("\n")  # the line of `joints:` is BODY_LINES + 1
POSE = {  # name: (position, angle), as BODIES gives them
    "ceiling": ((0.0, 5.0), 0.25),
    "wheel_left": ((1.5, 3.0), 0.7),
    "chassis": ((3.0, 2.5), -2.9),
}


def scene_of(joints: str, world: str = ""):
    return load_scene_text(world + BODIES + "joints:\n" + joints, source="j.yaml")


def local(name: str, point) -> tuple[float, float]:
    """`point` in body `name`'s frame by an independent rotation (math.cos and math.sin)."""
    (px, py), angle = POSE[name]
    c, s = math.cos(-angle), math.sin(-angle)
    dx, dy = point[0] - px, point[1] - py
    return (c * dx - s * dy, s * dx + c * dy)


def close(p, q, tol=1e-12):
    return all(abs(a - b) <= tol * max(1.0, abs(b)) for a, b in zip(p, q, strict=True))


def test_revolute_world_anchor_in_both_bodies_frames():
    scene = scene_of(
        """\
  - name: axle
    type: revolute
    bodies: [chassis, wheel_left]
    anchor: [2.0, 2.75]
    limits: [-1.0, 1.5]
    motor: {speed: -3.0, max_torque: 40}
"""
    )
    (j,) = scene.joints
    assert (j.name, j.kind, j.a, j.b) == ("axle", "revolute", 2, 1)
    assert close(j.local_a, local("chassis", (2.0, 2.75)))
    assert close(j.local_b, local("wheel_left", (2.0, 2.75)))
    assert j.local_a != (2.0 - 3.0, 2.75 - 2.5)  # the rotation was applied (chassis at -2.9 rad)
    assert j.reference_angle == 0.7 - -2.9
    assert (j.lower, j.upper, j.motor_speed, j.max_motor) == (-1.0, 1.5, -3.0, 40.0)
    assert (j.length, j.stiffness, j.min_length, j.axis) == (0.0, None, None, (1.0, 0.0))
    assert j.collide_connected is False


def test_distance_default_length_and_spring():
    scene = scene_of(
        """\
  - type: distance
    bodies: [ceiling, wheel_left]
    anchor_a: [0.5, 5.0]
    anchor_b: [1.5, 3.4]
    stiffness: 2.5
    damping_ratio: 0.3
    max_length: 4
    collide_connected: true
"""
    )
    (j,) = scene.joints
    assert j.name == "joint/1"
    assert close(j.local_a, local("ceiling", (0.5, 5.0)))
    assert close(j.local_b, local("wheel_left", (1.5, 3.4)))
    assert j.length == math.sqrt(1.0**2 + 1.6**2)
    assert (j.stiffness, j.damping_ratio, j.min_length, j.max_length) == (2.5, 0.3, None, 4.0)
    assert j.collide_connected is True


def test_rope_and_rod():
    rope, rod = scene_of(
        """\
  - {type: distance, bodies: [ceiling, chassis], anchor_a: [3, 5], anchor_b: [3, 2.5], max_length: 3}
  - {type: distance, bodies: [wheel_left, chassis], frame: body, anchor_a: [0, 0], anchor_b: [0.5, 0], length: 2}
"""  # noqa: E501
    ).joints
    assert (rope.length, rope.min_length, rope.max_length, rope.stiffness) == (2.5, None, 3.0, None)
    assert (rod.length, rod.local_b, rod.max_length) == (2.0, (0.5, 0.0), None)


def test_weld_in_body_frame_keeps_the_anchors_as_given():
    (j,) = scene_of(
        """\
  - type: weld
    bodies: [wheel_left, chassis]
    frame: body
    anchor_a: [0.1, -0.2]
    anchor_b: [-1.0, 0.25]
    stiffness: 5
    reference_angle: 0.5
"""
    ).joints
    assert (j.local_a, j.local_b, j.reference_angle) == ((0.1, -0.2), (-1.0, 0.25), 0.5)
    assert (j.stiffness, j.damping_ratio) == (5.0, 0.0)


def test_prismatic_axis_turned_into_a_frame_and_normalised():
    (j,) = scene_of(
        """\
  - type: prismatic
    bodies: [chassis, wheel_left]
    anchor: [2.0, 3.0]
    axis: [0.0, 2.0]
    limits: [-0.5, 0.25]
    motor: {speed: 1.0, max_force: 100}
"""
    ).joints
    angle = POSE["chassis"][1]
    expected = (math.sin(angle), math.cos(angle))  # (0, 1) turned by -angle
    assert close(j.axis, expected)
    assert abs(math.hypot(*j.axis) - 1.0) < 1e-15
    assert (j.lower, j.upper, j.motor_speed, j.max_motor) == (-0.5, 0.25, 1.0, 100.0)
    # in body frame the axis is a's: given unit, it is kept bit for bit
    (k,) = scene_of(
        """\
  - {type: prismatic, bodies: [chassis, wheel_left], frame: body, anchor_a: [0, 0],
     anchor_b: [0, 0], axis: [0.6, 0.8]}
"""
    ).joints
    assert k.axis == (0.6, 0.8)


ALL_KINDS = """\
  - name: "pin \\"1\\""
    type: revolute
    bodies: [ceiling, wheel_left]
    anchor: [1.0, 4.0]
    limits: [-3.141592653589793, 0.5]
    motor: {speed: 2.0, max_torque: 1e-3}
  - type: revolute
    bodies: [wheel_left, chassis]
    anchor: [2.0, 2.5]
    collide_connected: true
  - type: distance
    bodies: [ceiling, chassis]
    anchor_a: [0.1, 5.0]
    anchor_b: [3.0, 2.4]
    min_length: 1.0
    max_length: 9.0
    stiffness: 3.0
  - type: distance
    bodies: [chassis, wheel_left]
    frame: body
    anchor_a: [0.3, 0.1]
    anchor_b: [0.0, 0.2]
    length: 0.1
  - type: weld
    bodies: [wheel_left, chassis]
    anchor: [2.2, 2.8]
    stiffness: 1.0
    damping_ratio: 0.7
  - type: weld
    bodies: [chassis, floor]
    anchor: [3.0, 0.0]
  - type: prismatic
    bodies: [floor, chassis]
    anchor: [3.0, 2.5]
    axis: [1.0, 1.0]
    limits: [-2.0, 2.0]
    motor: {speed: -0.5, max_force: 10.0}
  - type: prismatic
    bodies: [wheel_left, chassis]
    anchor: [2.5, 2.7]
    axis: [-3.0, 0.1]
"""


def bits(scene) -> str:
    """repr of every joint: tells -0.0 from 0.0 and every last bit of a float."""
    return repr(scene.joints)


def test_round_trip_bit_for_bit_through_both_readers():
    scene = scene_of(ALL_KINDS, world="world: {fidelity: accurate}\n")
    assert len(scene.joints) == 8
    text = scene_to_yaml(scene)
    assert "frame: body" in text and "anchor:" not in text
    back = load_scene_text(text, source=scene.source)
    assert back == scene and bits(back) == bits(scene)
    assert scene_to_yaml(back) == text
    fast = fast_reader.read(text, scene.source, "x", loader.read_head, body_alone, joint_alone)
    assert fast is not None, "the fast reader read the writer's joints"
    assert fast == scene and bits(fast) == bits(scene)
    # the YAML reader alone agrees (the text parsed as a node tree)
    tree = loader.read_scene_tree(compose(text, scene.source), scene.source, default_name="x")
    assert tree == scene and bits(tree) == bits(scene)


def test_a_scene_without_joints_writes_no_joints_line():
    scene = load_scene_text(BODIES, source="j.yaml")
    text = scene_to_yaml(scene)
    assert "joints" not in text
    assert scene_to_yaml(dataclasses.replace(scene, joints=())) == text


def test_python_built_joints_round_trip():
    base = load_scene_text(BODIES, source="j.yaml")
    joints = (
        JointSpec("p", "prismatic", 1, 2, (0.0, -0.0), (1e-300, 2.5), axis=(0.6, 0.8)),
        JointSpec("d", "distance", 0, 1, (0.5, 0.0), (0.0, 0.0), length=3, max_length=3.5),
        JointSpec("w", "weld", 2, 3, (0.0, 0.0), (1.0, 1.0), reference_angle=-7.0),
    )
    scene = dataclasses.replace(base, joints=joints)
    assert first_joint_problem(scene.bodies, scene.joints) is None
    back = load_scene_text(scene_to_yaml(scene), source="j.yaml")
    assert back == scene and bits(back) == repr(
        tuple(dataclasses.replace(j, length=float(j.length)) for j in joints)
    )


@pytest.mark.parametrize(
    "spec, field, fragment",
    [
        (dict(a=0, b=0), "b", "same body"),
        (dict(a=0, b=3), "a", "both bodies ('ceiling' and 'floor') are concrete"),
        (dict(b=9), "b", "not one of the scene's 4 bodies"),
        (dict(kind="hinge"), "kind", "not one of"),
        (dict(kind="prismatic", axis=(1.0, 1.0)), "axis", "unit vector"),
        (dict(lower=1.0, upper=-1.0), "lower", "greater than the upper"),
        (dict(lower=-4.0, upper=0.0), "lower", "must be in"),
        (dict(lower=-1.0), "lower", "both limits"),
        (dict(motor_speed=1.0, max_motor=-1.0), "max_motor", "must be in"),
        (dict(max_motor=2.0), "max_motor", "without a motor speed"),
        (dict(stiffness=2.0), "stiffness", "a revolute joint has no stiffness"),
        (dict(kind="distance"), "length", "must be > 0"),
        (dict(kind="distance", length=2.0, max_length=1.0), "max_length", "less than the length"),
        (dict(kind="weld", damping_ratio=0.5), "damping_ratio", "needs stiffness"),
        (dict(local_a=(math.nan, 0.0)), "local_a", "anchor"),
        (dict(collide_connected=1), "collide_connected", "true or false"),
        (dict(name=""), "name", "printable"),
    ],
)
def test_checks_refuse_bad_python_built_joints(spec, field, fragment):
    bodies = load_scene_text(BODIES).bodies
    joint = JointSpec(**{**dict(name="j", kind="revolute", a=1, b=2, local_a=(0.0, 0.0),
                                local_b=(0.0, 0.0)), **spec})  # fmt: skip
    why = joint_problem(bodies, joint)
    assert why is not None and why[0] == field and fragment in why[1], why
    problem = first_joint_problem(bodies, [dataclasses.replace(joint, name="ok", **_fine()), joint])
    assert problem is not None and problem.index == 1 and problem.field == field


def _fine():
    return dict(kind="revolute", a=1, b=2, local_a=(0.0, 0.0), local_b=(0.0, 0.0), axis=(1.0, 0.0),
                length=0.0, min_length=None, max_length=None, stiffness=None, damping_ratio=0.0,
                lower=None, upper=None, motor_speed=None, max_motor=0.0,
                collide_connected=False)  # fmt: skip


def test_checks_refuse_duplicate_names():
    bodies = load_scene_text(BODIES).bodies
    j = JointSpec("j", "weld", 1, 2, (0.0, 0.0), (0.0, 0.0))
    problem = first_joint_problem(bodies, [j, dataclasses.replace(j, a=0)])
    assert problem == (1, "name", "duplicate joint name 'j' (already used by joints[0])")


J = BODY_LINES + 2  # the line of the first joint's first key
PIN = "  - type: revolute\n    bodies: [ceiling, wheel_left]\n    anchor: [0, 0]\n"
# (id, joints text, line, key path, fragment of the message)
ERRORS = [
    (
        "unknown_body",
        "  - type: revolute\n    bodies: [ceiling, wheel_l]\n    anchor: [0, 0]\n",
        J + 1,
        "joints[0].bodies[1]",
        "no body named 'wheel_l' (did you mean 'wheel_left'?)",
    ),
    (
        "same_body",
        "  - type: weld\n    bodies: [chassis, chassis]\n    anchor: [0, 0]\n",
        J + 1,
        "joints[0].bodies[1]",
        "the same body 'chassis'",
    ),
    (
        "both_concrete",
        "  - type: weld\n    bodies: [ceiling, floor]\n    anchor: [0, 0]\n",
        J + 1,
        "joints[0].bodies",
        "are concrete: a joint needs a movable body",
    ),
    ("bad_type", "  - type: hinge\n", J, "joints[0].type", "'hinge' is not one of revolute"),
    (
        "limits_reversed",
        PIN + "    limits: [1, -1]\n",
        J + 3,
        "joints[0].limits",
        "lower limit 1.0",
    ),
    ("limit_beyond_pi", PIN + "    limits: [-4, 1]\n", J + 3, "joints[0].limits[0]", "wrapped"),
    (
        "negative_torque",
        PIN + "    motor: {speed: 1, max_torque: -2}\n",
        J + 3,
        "joints[0].motor.max_torque",
        "out of range",
    ),
    (
        "motor_without_max",
        PIN + "    motor: {speed: 1}\n",
        J + 3,
        "joints[0].motor",
        "missing key 'max_torque'",
    ),
    (
        "zero_axis",
        "  - {type: prismatic, bodies: [chassis, wheel_left], anchor: [0, 0],\n"
        "     axis: [0, 0]}\n",
        J + 1,
        "joints[0].axis",
        "zero or shorter",
    ),
    (
        "missing_axis",
        "  - {type: prismatic, bodies: [chassis, wheel_left], anchor: [0, 0]}\n",
        J,
        "joints[0]",
        "missing key 'axis'",
    ),
    ("unknown_key", PIN + "    anchr_b: [0, 0]\n", J + 3, "joints[0].anchr_b", "did you mean"),
    (
        "key_of_another_kind",
        PIN + "    stiffness: 3\n",
        J + 3,
        "joints[0].stiffness",
        "a revolute joint has no key 'stiffness'",
    ),
    (
        "one_anchor_for_distance",
        "  - {type: distance, bodies: [ceiling, chassis], anchor: [0, 0]}\n",
        J,
        "joints[0].anchor",
        "anchor_a and anchor_b",
    ),
    (
        "two_anchors_in_world_frame",
        "  - {type: revolute, bodies: [ceiling, chassis], anchor_a: [0, 0], anchor_b: [0, 0]}\n",
        J,
        "joints[0].anchor_a",
        "takes one world point",
    ),
    (
        "coincident_anchors_no_length",
        "  - {type: distance, bodies: [ceiling, chassis], anchor_a: [1, 1], anchor_b: [1, 1]}\n",
        J,
        "joints[0].anchor_b",
        "anchors coincide at step 0",
    ),
    (  # a length does not help: there is no line to hold it along
        "coincident_anchors_with_length",
        "  - type: distance\n    bodies: [wheel_left, chassis]\n    anchor_a: [1, 1]\n"
        "    anchor_b: [1, 1]\n    length: 0.5\n",
        J + 3,
        "joints[0].anchor_b",
        "move anchor_b away from anchor_a",
    ),
    (
        "rest_length_beyond_max",
        "  - {type: distance, bodies: [ceiling, chassis], anchor_a: [3, 5], anchor_b: [3, 2.5],\n"
        "     max_length: 2}\n",
        J + 1,
        "joints[0].max_length",
        "less than the anchors' distance at step 0",
    ),
    (
        "min_above_max",
        "  - {type: distance, bodies: [ceiling, chassis], anchor_a: [3, 5], anchor_b: [3, 2.5],\n"
        "     min_length: 3, max_length: 2}\n",
        J + 1,
        "joints[0].min_length",
        "greater than max_length",
    ),
    (
        "damping_without_stiffness",
        "  - {type: weld, bodies: [ceiling, chassis], anchor: [0, 0], damping_ratio: 1}\n",
        J,
        "joints[0].damping_ratio",
        "needs stiffness",
    ),
    (
        "duplicate_names",
        "  - {name: j, type: weld, bodies: [ceiling, chassis], anchor: [0, 0]}\n"
        "  - {name: j, type: weld, bodies: [wheel_left, chassis], anchor: [0, 0]}\n",
        J + 1,
        "joints[1].name",
        f"duplicate joint name 'j' (already used by joints[0].name at line {J})",
    ),
    ("not_a_list", "  type: weld\n", J, "joints", "expected a list"),
]


@pytest.mark.parametrize(
    "text, line, path, fragment", [c[1:] for c in ERRORS], ids=[c[0] for c in ERRORS]
)
def test_refusals_name_file_line_and_key(text, line, path, fragment):
    with pytest.raises(SceneError) as caught:
        scene_of(text)
    e = caught.value
    assert (e.source, e.line, e.path) == ("j.yaml", line, path), str(e)
    assert fragment in e.what, str(e)
    assert str(e).startswith(f"j.yaml:{line}: {path}: ")
    assert "\n" not in str(e)


@pytest.mark.parametrize("world", ["world: {solver: seed}\n", "world: {fidelity: seed}\n"])
def test_joints_are_refused_under_the_seed_solver(world):
    with pytest.raises(SceneError) as caught:
        scene_of(PIN, world=world)
    e = caught.value
    assert (e.line, e.path) == (BODY_LINES + 2, "joints")  # the `joints:` key, after `world:`
    assert "joints need the sequential solver" in e.what
    # and so is a log's text of such a scene (fast reader)
    ok = scene_of(PIN)
    text = scene_to_yaml(ok).replace('  solver: "sequential"\n', '  solver: "seed"\n')
    with pytest.raises(SceneError, match="joints need the sequential solver"):
        load_scene_text(text)
    # no joints, no refusal
    assert load_scene_text(world + BODIES + "joints: []\n").joints == ()


def _writer_text():
    return scene_to_yaml(scene_of(ALL_KINDS))


def _both_readers(text):
    """The SceneError of the fast reader (itself: it raises, never hands the text on) and of
    the YAML reader alone, on `text`."""
    errors = []
    for read in (
        lambda: fast_reader.read(text, "log", "x", loader.read_head, body_alone, joint_alone),
        lambda: loader.read_scene_tree(compose(text, "log"), "log", default_name="x"),
    ):
        with pytest.raises(SceneError) as caught:
            read()
        errors.append(str(caught.value))
    return errors


def test_fast_reader_refusals_are_the_yaml_readers():
    text = _writer_text()
    joints_at = text.index("joints:\n")
    line_of = text.count("\n", 0, joints_at) + 1
    # an unknown body in the third joint
    bad = text[:joints_at] + text[joints_at:].replace(
        '["ceiling", "chassis"]', '["ceiling", "chasis"]', 1
    )  # noqa: E501
    fast, tree = _both_readers(bad)
    assert fast == tree
    assert "joints[2].bodies[1]: no body named 'chasis' (did you mean 'chassis'?)" in fast
    assert f"log:{line_of + 1 + 10 + 8 + 2}:" in fast  # 2 joints of 10 and 8 lines before it
    # a limit the checks refuse, and a duplicate name
    fast, tree = _both_readers(text.replace("limits: [-2.0, 2.0]", "limits: [2.0, -2.0]"))
    assert fast == tree and "joints[6].limits" in fast
    fast, tree = _both_readers(text.replace('name: "joint/2"', 'name: "joint/3"'))
    assert fast == tree and "duplicate joint name 'joint/3'" in fast


def test_fast_reader_reads_hand_edited_joints_alone():
    # a distance joint without `length` (the default is the YAML reader's): still the same scene
    text = _writer_text()
    start = text.index("    length: 0.1\n")
    edited = text[:start] + text[start + len("    length: 0.1\n") :]
    a = load_scene_text(edited, source="log")
    b = loader.read_scene_tree(compose(edited, "log"), "log", default_name="x")
    assert a == b and bits(a) == bits(b)
    assert a.joints[3].length != 0.1


def test_isaac_check_says_the_joints(tmp_path, capsys):
    path = tmp_path / "car.yaml"
    path.write_text(BODIES + "joints:\n" + ALL_KINDS)
    assert cmd_check(argparse.Namespace(scene=str(path))) == 0
    assert "4 bodies (2 concrete), 8 joints, dt" in capsys.readouterr().out
    path.write_text(BODIES)
    cmd_check(argparse.Namespace(scene=str(path)))
    assert "joints" not in capsys.readouterr().out


def test_load_scene_file_errors_carry_the_path(tmp_path):
    path = tmp_path / "scene.yaml"
    path.write_text(BODIES + "joints:\n" + ERRORS[0][1])
    with pytest.raises(SceneError) as caught:
        load_scene(path)
    assert str(caught.value).startswith(f"{path}:{J + 1}: joints[0].bodies[1]: no body named")


def test_the_docs_example_loads():
    import re
    from pathlib import Path

    doc = (Path(__file__).resolve().parent.parent / "docs" / "scene-format.md").read_text()
    example = re.search(r"A pendulum, and a car's wheel:\n\n```yaml\n(.*?)```", doc, re.S)
    string, axle = load_scene_text(example.group(1)).joints
    assert (string.kind, string.length, string.local_b) == ("distance", 1.0, (0.0, 0.0))
    assert (axle.kind, axle.motor_speed, axle.max_motor, axle.local_b) == (
        "revolute",
        -10.0,
        50.0,
        (0.0, 0.0),
    )


def test_no_overlap_warning_for_bodies_a_joint_keeps_apart():
    from isaac.scene.warnings import scene_warnings

    text = """\
world: {gravity: [0, 0]}
bodies:
  - {name: chassis, shape: {box: [2.0, 0.5]}, position: [0.0, 0.0]}
  - {name: wheel, shape: {circle: {radius: 0.4}}, position: [0.8, -0.2]}
joints:
  - {type: revolute, bodies: [chassis, wheel], anchor: [0.8, -0.2]COLLIDE}
"""
    quiet = scene_warnings(load_scene_text(text.replace("COLLIDE", "")))
    loud = scene_warnings(load_scene_text(text.replace("COLLIDE", ", collide_connected: true")))
    assert not any("overlaps" in line for line in quiet), quiet
    assert any("'chassis' and 'wheel'" in line for line in loud), loud


def test_a_text_too_long_for_yaml_says_what_is_wrong_with_its_joint(monkeypatch):
    # the writer's form up to a joint that does not match it, in a text "too long" for the YAML
    # reader (the limit lowered): the joint alone is read for its message
    text = _writer_text()
    monkeypatch.setattr(fast_reader, "MAX_YAML_BYTES", 100)
    monkeypatch.setattr(loader, "MAX_YAML_BYTES", 100)
    second = text.index('  - name: "joint/2"')
    edited = text[:second] + text[second:].replace("frame: body", "frame: world", 1)
    line = text.count("\n", 0, second) + 1
    with pytest.raises(SceneError) as caught:
        load_scene_text(edited, source="log")
    e = caught.value
    assert (e.line, e.path) == (line + 4, "joints[1].anchor_a"), str(e)
    assert "takes one world point" in e.what
    # a joint the YAML reader accepts though not in the writer's form: the text is too long
    edited = text[:second] + text[second:].replace("    frame: body\n", "    frame: 'body'\n", 1)
    with pytest.raises(SceneError, match="longer than 100 characters"):
        load_scene_text(edited, source="log")


def _random_scene(rng):
    """A valid scene of random bodies and joints of every kind and option, floats of every
    kind (negative zero, tiny, huge, many digits)."""
    import random

    assert isinstance(rng, random.Random)

    def num(lo, hi):
        return rng.choice([rng.uniform(lo, hi), 0.0, -0.0 if lo < 0 else 0.0, lo, hi, 1e-300])

    names = ["a", 'q"uote', "back\\slash", "ünï", "sp ace", "x" * 200, "7"]
    bodies = "bodies:\n" + "".join(
        f"  - {{name: {json.dumps(name)}, shape: {{circle: {{radius: 0.5}}}}, "
        f"position: [{num(-1e9, 1e9)!r}, {num(-1e3, 1e3)!r}], angle: {num(-1e6, 1e6)!r}, "
        f"concrete: {'true' if k == 0 else 'false'}}}\n"
        for k, name in enumerate(names)
    )
    base = load_scene_text(bodies, source="r")
    joints = []
    for k in range(40):
        a, b = rng.sample(range(len(names)), 2)
        kind = rng.choice(["revolute", "distance", "weld", "prismatic"])
        spec = dict(
            name=rng.choice([f"j{k}", f'j"{k}\\', f"ü/{k}"]),
            kind=kind,
            a=a,
            b=b,
            local_a=(num(-3e9, 3e9), num(-1.0, 1.0)),
            local_b=(num(-1.0, 1.0), num(-3e9, 3e9)),
            reference_angle=num(-2e6, 2e6),
            collide_connected=rng.random() < 0.5,
        )
        if kind in ("revolute", "prismatic"):
            bound = math.pi if kind == "revolute" else 1e10
            if rng.random() < 0.5:
                lo = num(-bound, bound)
                spec.update(lower=lo, upper=rng.choice([lo, bound, rng.uniform(lo, bound)]))
            if rng.random() < 0.5:
                spec.update(motor_speed=num(-1e6, 1e6), max_motor=num(0.0, 1e15))
        if kind == "prismatic":
            t = rng.uniform(-4.0, 4.0)
            spec["axis"] = checks.unit_axis((math.cos(t), math.sin(t) * rng.uniform(0.1, 9.0)))
        if kind == "distance":
            bodies = base.bodies
            if checks.coincident_anchors(bodies[a], spec["local_a"], bodies[b], spec["local_b"]):
                # refused (no line to act along): move b's anchor 1 m along its body's x
                spec["local_b"] = (spec["local_b"][0] + 1.0, spec["local_b"][1])
            spec["length"] = rng.choice([rng.uniform(1e-9, 1e10), 1e10, 5e-324])
            if rng.random() < 0.5:
                spec["min_length"] = rng.choice([0.0, spec["length"] * rng.random()])
            if rng.random() < 0.5:
                spec["max_length"] = min(1e10, spec["length"] * rng.uniform(1.0, 2.0))
        if kind in ("distance", "weld") and rng.random() < 0.5:
            spec.update(stiffness=rng.uniform(1e-6, 1e6), damping_ratio=num(0.0, 1e3))
        joints.append(JointSpec(**spec))
    # names unique
    joints = [dataclasses.replace(j, name=f"{j.name}#{k}") for k, j in enumerate(joints)]
    return dataclasses.replace(base, joints=tuple(joints))


def test_random_scenes_round_trip_bit_for_bit():
    import random

    for seed in range(25):
        scene = _random_scene(random.Random(seed))
        problem = first_joint_problem(scene.bodies, scene.joints)
        assert problem is None, (seed, problem)
        text = scene_to_yaml(scene)
        fast = fast_reader.read(text, "r", "x", loader.read_head, body_alone, joint_alone)
        tree = loader.read_scene_tree(compose(text, "r"), "r", default_name="x")
        for back in (fast, tree):
            assert back is not None and back == scene and bits(back) == bits(scene), seed
        assert scene_to_yaml(fast) == text
