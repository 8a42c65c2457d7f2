"""Joints of a scene's `joints:` list (docs/scene-format.md) read into `JointSpec`s.

Read after the bodies, which they name: anchors given in the world frame are turned into each
body's frame at step 0 (`to_body_frame`). The checks every joint passes (isaac.scene.checks)
come after, and their refusal is said at the key behind the field they refuse.
"""

from __future__ import annotations

import math

from isaac.errors import SceneError
from isaac.scene import checks
from isaac.scene.limits import (
    MAX_ANCHOR,
    MAX_COORDINATE,
    MAX_DAMPING_RATIO,
    MAX_JOINT_LENGTH,
    MAX_JOINTS,
    MAX_MOTOR_FORCE,
    MAX_MOTOR_TORQUE,
    MAX_REFERENCE_ANGLE,
    MAX_SPEED,
    MAX_STIFFNESS,
    MIN_AXIS,
)
from isaac.scene.reader import Reader, join_path, key_at, optional, shown, suggestion
from isaac.scene.settings import WorldSettings
from isaac.scene.spec import JOINT_KINDS, BodySpec, JointSpec
from isaac.trig import sin_cos

_COMMON_JOINT_KEYS = (
    "name",
    "type",
    "bodies",
    "frame",
    "anchor",
    "anchor_a",
    "anchor_b",
    "reference_angle",
    "collide_connected",
)
_KIND_KEYS = {
    "revolute": ("limits", "motor"),
    "distance": ("length", "min_length", "max_length", "stiffness", "damping_ratio"),
    "weld": ("stiffness", "damping_ratio"),
    "prismatic": ("axis", "limits", "motor"),
}
_JOINT_KEYS = _COMMON_JOINT_KEYS + tuple(
    dict.fromkeys(key for keys in _KIND_KEYS.values() for key in keys)
)
_MOTOR_KEYS = {"revolute": ("speed", "max_torque"), "prismatic": ("speed", "max_force")}
# the key of the scene file behind each JointSpec field, for a refusal of the checks
_JOINT_FIELD_KEYS = {
    "kind": ("type",),
    "a": ("bodies",),
    "b": ("bodies",),
    "local_a": ("anchor_a", "anchor"),
    "local_b": ("anchor_b", "anchor"),
    "lower": ("limits",),
    "upper": ("limits",),
    "motor_speed": ("motor",),
    "max_motor": ("motor",),
}


def to_body_frame(body: BodySpec, point: tuple[float, float]) -> tuple[float, float]:
    """World point `point` (m) in `body`'s frame at step 0: R(-angle) (point - position)."""
    s, c = sin_cos(body.angle)
    dx = point[0] - body.position[0]
    dy = point[1] - body.position[1]
    return (c * dx + s * dy, c * dy - s * dx)


def _joint_bodies(r: Reader, node, path: str, bodies, index_of: dict) -> tuple[int, int]:
    items = r.sequence(node, path, min_len=2, max_len=2, what="body names")
    found = []
    for k, item in enumerate(items):
        item_path = f"{path}[{k}]"
        name = r.name(item, item_path)
        i = index_of.get(name)
        if i is None:
            close = suggestion(name, index_of)
            hint = f" (did you mean {close!r}?)" if close else ""
            raise r.fail(f"no body named {shown(name)}{hint}", item, item_path)
        found.append(i)
    a, b = found
    if a == b:
        raise r.fail(
            f"the joint's two bodies are the same body {shown(bodies[a].name)}: a joint joins "
            "two different bodies",
            items[1],
            f"{path}[1]",
        )
    if bodies[a].concrete and bodies[b].concrete:
        raise r.fail(
            f"both bodies ({shown(bodies[a].name)} and {shown(bodies[b].name)}) are concrete: "
            "a joint needs a movable body (one concrete body pins the other to the world)",
            node,
            path,
        )
    return a, b


def _given(r: Reader, m: dict, node, path: str, wanted, refused, why: str) -> None:
    """Refuse every key of `refused` in `m` and require every key of `wanted`, saying `why`."""
    for key in refused:
        if key in m:
            raise r.fail(f"{key} is not taken here: {why}", m[key][0], join_path(path, key))
    for key in wanted:
        if key not in m:
            raise r.fail(f"missing key {key!r}: {why}", node, path)


def _read_joint(r: Reader, node, path: str, index: int, bodies, index_of: dict) -> JointSpec:
    """The JointSpec of joint item `node` (joints[index]) over the scene's `bodies`;
    `index_of` maps body names to their indices."""
    m = r.mapping(node, path, _JOINT_KEYS)
    if "type" not in m:
        raise r.fail(f"missing key 'type' (one of {', '.join(JOINT_KINDS)})", node, path)
    kind = r.choice(m["type"][1], join_path(path, "type"), JOINT_KINDS)
    if "bodies" not in m:
        raise r.fail("missing key 'bodies' ([NAME_A, NAME_B])", node, path)
    own = _KIND_KEYS[kind]
    for key, (key_node, _) in m.items():
        if key not in _COMMON_JOINT_KEYS and key not in own:
            raise r.fail(
                f"a {kind} joint has no key {key!r} (its own keys: {', '.join(own)})",
                key_node,
                join_path(path, key),
            )
    name = optional(r.name, m, "name", path, f"joint/{index + 1}")
    a, b = _joint_bodies(r, m["bodies"][1], join_path(path, "bodies"), bodies, index_of)
    body_a, body_b = bodies[a], bodies[b]
    frame = optional(r.choice, m, "frame", path, "world", ("world", "body"))
    if frame == "body":
        _given(
            r, m, node, path, ("anchor_a", "anchor_b"), ("anchor",),
            "with frame: body give anchor_a and anchor_b, each in its body's frame",
        )  # fmt: skip
        local_a = r.pair(m["anchor_a"][1], join_path(path, "anchor_a"), -MAX_ANCHOR, MAX_ANCHOR)
        local_b = r.pair(m["anchor_b"][1], join_path(path, "anchor_b"), -MAX_ANCHOR, MAX_ANCHOR)
        world_a, world_b = checks.to_world(body_a, local_a), checks.to_world(body_b, local_b)
    else:
        if kind == "distance":
            _given(
                r, m, node, path, ("anchor_a", "anchor_b"), ("anchor",),
                "a distance joint takes two world points, anchor_a and anchor_b",
            )  # fmt: skip
            keys = ("anchor_a", "anchor_b")
        else:
            _given(
                r, m, node, path, ("anchor",), ("anchor_a", "anchor_b"),
                f"with frame: world a {kind} joint takes one world point, anchor, for both "
                "bodies (give anchor_a and anchor_b with frame: body)",
            )  # fmt: skip
            keys = ("anchor", "anchor")
        world_a, world_b = (
            r.pair(m[key][1], join_path(path, key), -MAX_COORDINATE, MAX_COORDINATE) for key in keys
        )
        local_a, local_b = to_body_frame(body_a, world_a), to_body_frame(body_b, world_b)
    values = dict(
        name=name,
        kind=kind,
        a=a,
        b=b,
        local_a=local_a,
        local_b=local_b,
        reference_angle=optional(
            r.number,
            m,
            "reference_angle",
            path,
            body_b.angle - body_a.angle,
            -MAX_REFERENCE_ANGLE,
            MAX_REFERENCE_ANGLE,
        ),
        collide_connected=optional(r.boolean, m, "collide_connected", path, False),
    )
    if kind == "prismatic":
        values["axis"] = _read_axis(r, m, node, path, body_a, frame)
    if kind in ("revolute", "prismatic"):
        values.update(_read_limits(r, m, path, kind))
        values.update(_read_motor(r, m, path, kind))
    if kind == "distance":
        # before the length: with coincident anchors none would do (checks.joint_problem
        # refuses them too, for joints made in Python or read from a log)
        why = checks.coincident_anchors(body_a, local_a, body_b, local_b)
        if why is not None:
            raise r.fail(why, m["anchor_b"][1], join_path(path, "anchor_b"))
        values.update(_read_lengths(r, m, node, path, world_a, world_b))
    if kind in ("distance", "weld"):
        stiffness = optional(r.number, m, "stiffness", path, None, 0.0, MAX_STIFFNESS, lo_open=True)
        if "damping_ratio" in m and stiffness is None:
            raise r.fail(
                "damping_ratio needs stiffness (a rigid joint has no spring to damp)",
                m["damping_ratio"][0],
                join_path(path, "damping_ratio"),
            )
        values["stiffness"] = stiffness
        values["damping_ratio"] = optional(
            r.number, m, "damping_ratio", path, 0.0, 0.0, MAX_DAMPING_RATIO
        )
    return JointSpec(**values)


def _read_axis(r: Reader, m: dict, node, path: str, body_a: BodySpec, frame: str):
    if "axis" not in m:
        raise r.fail("missing key 'axis' (the slide direction)", node, path)
    axis_path = join_path(path, "axis")
    x, y = r.pair(m["axis"][1], axis_path, -MAX_COORDINATE, MAX_COORDINATE)
    if not math.sqrt(x * x + y * y) >= MIN_AXIS:
        raise r.fail(
            f"the axis [{x!r}, {y!r}] is zero or shorter than {MIN_AXIS!r}: it gives no direction",
            m["axis"][1],
            axis_path,
        )
    if frame == "world":
        s, c = sin_cos(body_a.angle)
        x, y = c * x + s * y, c * y - s * x
    return checks.unit_axis((x, y))


def _read_limits(r: Reader, m: dict, path: str, kind: str) -> dict:
    if "limits" not in m:
        return {}
    limits_path = join_path(path, "limits")
    items = r.sequence(m["limits"][1], limits_path, min_len=2, max_len=2, what="numbers")
    # a revolute's limits: any finite number read, then [-pi, pi] said with its reason
    bound = math.inf if kind == "revolute" else MAX_JOINT_LENGTH
    lower, upper = (
        r.number(item, f"{limits_path}[{k}]", -bound, bound) for k, item in enumerate(items)
    )
    for k, value in enumerate((lower, upper)):
        if kind == "revolute" and not -math.pi <= value <= math.pi:
            raise r.fail(
                f"the limit {value!r} rad is outside [-pi, pi]: the joint angle (angle_b - "
                "angle_a - reference_angle) is wrapped to [-pi, pi]",
                items[k],
                f"{limits_path}[{k}]",
            )
    if lower > upper:
        unit = "rad" if kind == "revolute" else "m"
        raise r.fail(
            f"the lower limit {lower!r} {unit} is greater than the upper limit {upper!r} {unit}",
            m["limits"][1],
            limits_path,
        )
    return {"lower": lower, "upper": upper}


def _read_motor(r: Reader, m: dict, path: str, kind: str) -> dict:
    if "motor" not in m:
        return {}
    motor_path = join_path(path, "motor")
    speed_key, max_key = _MOTOR_KEYS[kind]
    motor = r.mapping(m["motor"][1], motor_path, (speed_key, max_key))
    r.require(motor, (speed_key, max_key), m["motor"][1], motor_path)
    top = MAX_MOTOR_TORQUE if kind == "revolute" else MAX_MOTOR_FORCE
    return {
        "motor_speed": r.number(
            motor[speed_key][1], join_path(motor_path, speed_key), -MAX_SPEED, MAX_SPEED
        ),
        "max_motor": r.number(motor[max_key][1], join_path(motor_path, max_key), 0.0, top),
    }


def _read_lengths(r: Reader, m: dict, node, path: str, world_a, world_b) -> dict:
    if "length" in m:
        length = r.number(
            m["length"][1], join_path(path, "length"), 0.0, MAX_JOINT_LENGTH, lo_open=True
        )
        said = "the length"
    else:
        dx, dy = world_b[0] - world_a[0], world_b[1] - world_a[1]
        length = math.sqrt(dx * dx + dy * dy)
        said = "the anchors' distance at step 0"
        if not 0.0 < length <= MAX_JOINT_LENGTH:
            raise r.fail(
                f"{said} is {length!r} m: give length (> 0 and <= {MAX_JOINT_LENGTH!r} m)",
                node,
                path,
            )
    low = optional(r.number, m, "min_length", path, None, 0.0, MAX_JOINT_LENGTH)
    high = optional(r.number, m, "max_length", path, None, 0.0, MAX_JOINT_LENGTH, lo_open=True)
    if low is not None and high is not None and low > high:
        raise r.fail(
            f"min_length {low!r} m is greater than max_length {high!r} m",
            m["min_length"][1],
            join_path(path, "min_length"),
        )
    if low is not None and low > length:
        raise r.fail(
            f"min_length {low!r} m is greater than {said} ({length!r} m; the rest length must "
            "lie within the limits)",
            m["min_length"][1],
            join_path(path, "min_length"),
        )
    if high is not None and high < length:
        raise r.fail(
            f"max_length {high!r} m is less than {said} ({length!r} m; the rest length must "
            "lie within the limits)",
            m["max_length"][1],
            join_path(path, "max_length"),
        )
    return {"length": length, "min_length": low, "max_length": high}


def read_joints(r: Reader, m: dict, bodies, world: WorldSettings) -> tuple[JointSpec, ...]:
    """The `joints:` of scene mapping `m` over its `bodies` (read first), checked by
    checks.first_joint_problem too; `world` decides whether joints are taken at all."""
    node = r.given(m, "joints", "", "a list of joints")
    if node is None:
        return ()
    key_node = m["joints"][0]
    items = r.sequence(node, "joints", max_len=MAX_JOINTS, what="joints")
    if not items:
        return ()
    problem = checks.joint_solver_problem(world.solver, items)
    if problem is not None:
        raise r.fail(problem, key_node, "joints")
    index_of = {body.name: i for i, body in enumerate(bodies)}
    joints: list[JointSpec] = []
    origin: dict[str, tuple[str, int]] = {}
    for i, item in enumerate(items):
        path = f"joints[{i}]"
        joint = _read_joint(r, item, path, i, bodies, index_of)
        name_node, name_path = key_at(r.mapping(item, path, None), item, path, "name")
        r.claim_name(origin, "joint", joint.name, name_node, name_path)
        joints.append(joint)
    problem = checks.first_joint_problem(bodies, joints)
    if problem is not None:
        i, field, what = problem
        raise _refusal(r, field, what, items[i], f"joints[{i}]")
    return tuple(joints)


def _refusal(r: Reader, field: str, what: str, item, path: str) -> SceneError:
    """The SceneError for the checks' refusal of JointSpec `field` of joint item `item`, at the
    key that gave it (the item when none did)."""
    keys = _JOINT_FIELD_KEYS.get(field, (field,))
    return r.fail(what, *key_at(r.mapping(item, path, None), item, path, *keys))


def joint_alone(r: Reader, text: str, line: int, index: int, bodies, index_of) -> JointSpec:
    """Joint item `text` (`  - name: ...` lines starting at `line`) read by the YAML reader as
    joints[index] over `bodies` (`index_of` their indices by name); raises its SceneError."""
    item = r.item_alone("joints", text, line)
    path = f"joints[{index}]"
    joint = _read_joint(r, item, path, index, bodies, index_of)
    why = checks.joint_problem(bodies, joint)
    if why is not None:
        raise _refusal(r, *why, item, path)
    return joint
