"""Scenes: the YAML contract (docs/scene-format.md) turned into a validated, immutable `Scene`.

A scene says everything a run needs. It is validated once, here; the engine trusts a `Scene`.
Loading: YAML text -> node tree with line marks (isaac.scene.reader) -> checked values -> Scene.
"""

from __future__ import annotations

import dataclasses
import functools
import gc
import math
import os
import stat
from pathlib import Path

from isaac.errors import SceneError
from isaac.scene import checks, fast_reader, generators, polygon, validate
from isaac.scene.limits import (
    FILTER_BITS,
    MAX_ANCHOR,
    MAX_BODIES,
    MAX_COORDINATE,
    MAX_DAMPING_RATIO,
    MAX_DENSITY,
    MAX_FRICTION,
    MAX_GROUP,
    MAX_JOINT_LENGTH,
    MAX_JOINTS,
    MAX_MOTOR_FORCE,
    MAX_MOTOR_TORQUE,
    MAX_NAME_LENGTH,
    MAX_PILE_COUNT,
    MAX_PYRAMID_ROWS,
    MAX_REFERENCE_ANGLE,
    MAX_SCENE_BYTES,
    MAX_SIZE,
    MAX_SPEED,
    MAX_STIFFNESS,
    MAX_TIME,
    MAX_VERTICES,
    MAX_YAML_BYTES,
    MIN_AXIS,
    MIN_SIZE,
)
from isaac.scene.reader import (
    MappingNode,
    Reader,
    compose,
    describe,
    join_path,
    line_of,
    optional,
    scalar_or_none,
    shown,
    suggestion,
)
from isaac.scene.settings import DEFAULT_PRESET, PRESETS, WorldSettings
from isaac.scene.spec import (
    DEFAULT_CATEGORY,
    DEFAULT_MASK,
    JOINT_KINDS,
    BodySpec,
    JointSpec,
    Scene,
    SceneMarks,
)
from isaac.trig import sin_cos

# --- world ----------------------------------------------------------------------------------

_WORLD_FIELDS = tuple(f.name for f in dataclasses.fields(WorldSettings))


def _world_value(r: Reader, key: str, node, path: str):
    # the rules are checks.WORLD_*, which also check WorldSettings made in Python
    if key in checks.WORLD_CHOICES:
        return r.choice(node, path, checks.WORLD_CHOICES[key])
    if key in checks.WORLD_BOOLEANS:
        return r.boolean(node, path)
    kind, lo, hi, lo_open = checks.WORLD_RANGES[key]
    read = {"pair": r.pair, "time": r.time, "number": r.number}
    if kind == "integer":
        return r.integer(node, path, lo, hi)
    return read[kind](node, path, lo, hi, lo_open=lo_open)


def _read_world(r: Reader, node) -> WorldSettings:
    if node is None:
        m = {}
    else:
        m = r.mapping(node, "world", _WORLD_FIELDS)
    fidelity = optional(r.choice, m, "fidelity", "world", DEFAULT_PRESET, tuple(PRESETS))
    # resolution: dataclass defaults, then the preset, then every explicit key.
    values = {f.name: f.default for f in dataclasses.fields(WorldSettings)}
    values.update(PRESETS[fidelity])
    values["fidelity"] = fidelity
    for key, (_, value_node) in m.items():
        if key != "fidelity":
            values[key] = _world_value(r, key, value_node, join_path("world", key))
    return WorldSettings(**values)


# --- bodies ---------------------------------------------------------------------------------

_BODY_KEYS = (
    "name",
    "shape",
    "position",
    "angle",
    "velocity",
    "angular_velocity",
    "density",
    "restitution",
    "friction",
    "concrete",
    "enters_at",
    "leaves_at",
    "category",
    "mask",
    "group",
)


def _vertices_tuple(v) -> tuple[tuple[float, float], ...]:
    return tuple((float(x), float(y)) for x, y in v)


@functools.lru_cache(maxsize=256)
def _box(width: float, height: float) -> tuple[tuple[float, float], ...]:
    # one tuple for the many bodies of one box size: a 100,000-box scene holds one, not 100,000
    return _vertices_tuple(polygon.box_vertices(width, height))


_SHAPES = ("box", "polygon", "regular", "circle")


def _read_shape(r: Reader, node, path: str) -> tuple[tuple[tuple[float, float], ...], float | None]:
    """(vertices, circle radius or None) of a body's `shape:`."""
    m = r.mapping(node, path, _SHAPES)
    if len(m) != 1:
        raise r.fail(f"give exactly one of {', '.join(_SHAPES)}", node, path)
    kind, (_, value) = next(iter(m.items()))
    path = join_path(path, kind)
    if kind == "circle":
        c = r.mapping(value, path, ("radius",))
        if "radius" not in c:
            raise r.fail("missing key 'radius'", value, path)
        # the diameter is the circle's extent, bounded like a polygon's
        return (), r.number(c["radius"][1], join_path(path, "radius"), MIN_SIZE / 2, MAX_SIZE / 2)
    return _read_polygon(r, kind, value, path), None


def _read_polygon(r: Reader, kind: str, value, path: str) -> tuple[tuple[float, float], ...]:
    if kind == "box":
        return _box(*r.pair(value, path, MIN_SIZE, MAX_SIZE, names="w, h"))
    if kind == "regular":
        p = r.mapping(value, path, ("sides", "radius", "phase"))
        for key in ("sides", "radius"):
            if key not in p:
                raise r.fail(f"missing key {key!r}", value, path)
        sides = r.integer(p["sides"][1], join_path(path, "sides"), 3, MAX_VERTICES)
        radius = r.number(p["radius"][1], join_path(path, "radius"), MIN_SIZE, MAX_SIZE)
        phase = optional(r.number, p, "phase", path, 0.0, -MAX_SPEED, MAX_SPEED)
        return _vertices_tuple(polygon.regular_vertices(sides, radius, phase))
    items = r.sequence(value, path, min_len=3, max_len=MAX_VERTICES, what="vertices")
    raw = [
        r.pair(item, f"{path}[{i}]", -MAX_COORDINATE, MAX_COORDINATE)
        for i, item in enumerate(items)
    ]
    try:
        ccw = polygon.validate_polygon(raw)
    except ValueError as exc:
        raise r.fail(str(exc), value, path) from None
    extent = float(math.hypot(*(ccw.max(axis=0) - ccw.min(axis=0))))
    if not MIN_SIZE <= extent <= MAX_SIZE:
        raise r.fail(
            f"the polygon's extent {extent!r} m is outside [{MIN_SIZE!r}, {MAX_SIZE!r}]",
            value,
            path,
        )
    return _vertices_tuple(ccw)


def _read_body(r: Reader, node, path: str, index: int) -> BodySpec:
    m = r.mapping(node, path, _BODY_KEYS)
    if "shape" not in m:
        raise r.fail("missing key 'shape'", node, path)
    name = optional(r.name, m, "name", path, f"body/{index + 1}")
    enters_at = optional(r.time, m, "enters_at", path, 0.0, 0.0, MAX_TIME)
    leaves_at = None
    if "leaves_at" in m and scalar_or_none(m["leaves_at"][1]) is not None:
        leaves_path = join_path(path, "leaves_at")
        leaves_at = r.time(m["leaves_at"][1], leaves_path, 0.0, MAX_TIME)
        if leaves_at <= enters_at:
            raise r.fail(
                f"leaves_at ({leaves_at!r} s) must be later than enters_at ({enters_at!r} s)",
                m["leaves_at"][1],
                leaves_path,
            )
    vertices, circle = _read_shape(r, m["shape"][1], join_path(path, "shape"))
    return BodySpec(
        name=name,
        vertices=vertices,
        circle=circle,
        position=optional(r.pair, m, "position", path, (0.0, 0.0), -MAX_COORDINATE, MAX_COORDINATE),
        angle=optional(r.number, m, "angle", path, 0.0, -MAX_SPEED, MAX_SPEED),
        velocity=optional(r.pair, m, "velocity", path, (0.0, 0.0), -MAX_SPEED, MAX_SPEED),
        angular_velocity=optional(
            r.number, m, "angular_velocity", path, 0.0, -MAX_SPEED, MAX_SPEED
        ),
        density=optional(r.number, m, "density", path, 1.0, 0.0, MAX_DENSITY, lo_open=True),
        restitution=optional(r.number, m, "restitution", path, 0.0, 0.0, 1.0),
        friction=optional(r.number, m, "friction", path, 0.5, 0.0, MAX_FRICTION),
        concrete=optional(r.boolean, m, "concrete", path, False),
        enters_at=enters_at,
        leaves_at=leaves_at,
        category=optional(r.bits, m, "category", path, DEFAULT_CATEGORY, FILTER_BITS),
        mask=optional(r.bits, m, "mask", path, DEFAULT_MASK, FILTER_BITS),
        group=optional(r.integer, m, "group", path, 0, -MAX_GROUP, MAX_GROUP),
    )


# --- generators -----------------------------------------------------------------------------

_PYRAMID_KEYS = (
    "rows",
    "box",
    "base",
    "spacing",
    "density",
    "restitution",
    "friction",
    "name",
    "ground",
)
_PILE_KEYS = (
    "count",
    "seed",
    "sides",
    "radius",
    "container",
    "density",
    "restitution",
    "friction",
    "name",
)
_CONTAINER_KEYS = ("width", "height", "thickness", "position")


def _material(r: Reader, m: dict, path: str) -> dict:
    return dict(
        density=optional(r.number, m, "density", path, 1.0, 0.0, MAX_DENSITY, lo_open=True),
        restitution=optional(r.number, m, "restitution", path, 0.0, 0.0, 1.0),
        friction=optional(r.number, m, "friction", path, 0.5, 0.0, MAX_FRICTION),
    )


def _require(r: Reader, m: dict, keys, node, path: str) -> None:
    for key in keys:
        if key not in m:
            raise r.fail(f"missing key {key!r}", node, path)


def _prefix(r: Reader, m: dict, path: str, default: str, suffix: int, pattern: str) -> str:
    """The generator's `name`: its bodies are named PREFIX + a suffix of up to `suffix`
    characters, and every name must fit MAX_NAME_LENGTH."""
    if "name" not in m:
        return default
    node = m["name"][1]
    name = r.name(node, join_path(path, "name"))
    if len(name) + suffix > MAX_NAME_LENGTH:
        raise r.fail(
            f"a name of {len(name)} characters is too long here: this generator names its "
            f"bodies {pattern}, adding up to {suffix} characters, and a name has at most "
            f"{MAX_NAME_LENGTH} (use at most {MAX_NAME_LENGTH - suffix})",
            node,
            join_path(path, "name"),
        )
    return name


def _read_pyramid(r: Reader, node, path: str) -> tuple[dict, int]:
    m = r.mapping(node, path, _PYRAMID_KEYS)
    _require(r, m, ("rows", "box"), node, path)
    rows = r.integer(m["rows"][1], join_path(path, "rows"), 1, MAX_PYRAMID_ROWS)
    ground = optional(r.boolean, m, "ground", path, True)
    options = dict(
        rows=rows,
        box=r.pair(m["box"][1], join_path(path, "box"), MIN_SIZE, MAX_SIZE, names="w, h"),
        base=optional(r.pair, m, "base", path, (0.0, 0.0), -MAX_COORDINATE, MAX_COORDINATE),
        spacing=optional(r.number, m, "spacing", path, 0.0, 0.0, MAX_SIZE),
        name=_prefix(
            r,
            m,
            path,
            "pyramid",
            generators.pyramid_suffix_length(rows, ground),
            "NAME/ROW/COLUMN and NAME/ground",
        ),
        ground=ground,
        **_material(r, m, path),
    )
    return options, rows * (rows + 1) // 2 + (1 if ground else 0)


def _read_pile(r: Reader, node, path: str) -> tuple[dict, int]:
    m = r.mapping(node, path, _PILE_KEYS)
    _require(r, m, ("count",), node, path)
    count = r.integer(m["count"][1], join_path(path, "count"), 1, MAX_PILE_COUNT)
    sides = (3, 8)
    if "sides" in m:
        sides_path = join_path(path, "sides")
        items = r.sequence(m["sides"][1], sides_path, min_len=2, max_len=2, what="numbers")
        sides = (
            r.integer(items[0], f"{sides_path}[0]", 3, MAX_VERTICES),
            r.integer(items[1], f"{sides_path}[1]", 3, MAX_VERTICES),
        )
        if sides[0] > sides[1]:
            raise r.fail("min sides is greater than max sides", m["sides"][1], sides_path)
    radius = optional(r.pair, m, "radius", path, (0.2, 0.5), MIN_SIZE, MAX_SIZE)
    if radius[0] > radius[1]:
        raise r.fail(
            "min radius is greater than max radius", m["radius"][1], join_path(path, "radius")
        )
    container = {}
    if "container" in m:
        cpath = join_path(path, "container")
        c = r.mapping(m["container"][1], cpath, _CONTAINER_KEYS)
        height = None  # null or left out: just tall enough for the starting grid
        if "height" in c and scalar_or_none(c["height"][1]) is not None:
            height = r.number(c["height"][1], join_path(cpath, "height"), MIN_SIZE, MAX_SIZE)
        container = dict(
            width=optional(r.number, c, "width", cpath, 10.0, MIN_SIZE, MAX_SIZE),
            height=height,
            thickness=optional(r.number, c, "thickness", cpath, 0.5, MIN_SIZE, MAX_SIZE),
            position=optional(
                r.pair, c, "position", cpath, (0.0, 0.0), -MAX_COORDINATE, MAX_COORDINATE
            ),
        )
    options = dict(
        count=count,
        seed=optional(r.integer, m, "seed", path, 0, 0, 2**63 - 1),
        sides=sides,
        radius=radius,
        name=_prefix(
            r,
            m,
            path,
            "pile",
            generators.pile_suffix_length(count),
            "NAME/1 .. NAME/COUNT, NAME/floor, NAME/left and NAME/right",
        ),
        **container,
        **_material(r, m, path),
    )
    return options, count + 3


def _expand_generator(r: Reader, node, path: str, room: int):
    """(kind, options node, key path, bodies) of generator item `node`."""
    m = r.mapping(node, path, ("pyramid", "pile"))
    if len(m) != 1:
        raise r.fail("each generator has exactly one key: pyramid or pile", node, path)
    kind, (_, options_node) = next(iter(m.items()))
    path = join_path(path, kind)
    reader = _read_pyramid if kind == "pyramid" else _read_pile
    options, size = reader(r, options_node, path)
    if size > room:
        raise r.fail(
            f"this generator makes {size} bodies; with the others the scene would "
            f"exceed {MAX_BODIES} bodies",
            options_node,
            path,
        )
    try:
        bodies = getattr(generators, kind)(**options)
    except generators.GeneratorError as exc:
        key_node = _option_node(r, options_node, path, exc.key) or options_node
        raise r.fail(exc.what, key_node, join_path(path, exc.key)) from None
    return kind, options_node, path, options["name"], bodies


def _option_node(r: Reader, options_node, path: str, key: str):
    """The node of option `key` ("container.height") if the scene gives it, else None."""
    node = options_node
    for part in key.split("."):
        if not isinstance(node, MappingNode):
            return None
        m = r.mapping(node, path, None)
        if part not in m:
            return None
        node = m[part][1]
    return node


# --- joints ---------------------------------------------------------------------------------

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
    for key in (speed_key, max_key):
        if key not in motor:
            raise r.fail(f"missing key {key!r}", m["motor"][1], motor_path)
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


def _read_joints(r: Reader, m: dict, bodies, world: WorldSettings) -> tuple[JointSpec, ...]:
    """The scene's `joints:` (after its bodies), checked by checks.first_joint_problem too."""
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
        name_node, name_path = _name_at(r, item, path)
        if joint.name in origin:
            first_path, first_line = origin[joint.name]
            raise r.fail(
                f"duplicate joint name {shown(joint.name)} (already used by {first_path} at "
                f"line {first_line})",
                name_node,
                name_path,
            )
        origin[joint.name] = (name_path, line_of(name_node))
        joints.append(joint)
    problem = checks.first_joint_problem(bodies, joints)
    if problem is not None:
        i, field, what = problem
        raise _joint_refusal(r, field, what, items[i], f"joints[{i}]")
    return tuple(joints)


def _name_at(r: Reader, item, path: str):
    """(node, key path) of joint item `item`'s name, or of the item when it gives none."""
    m = r.mapping(item, path, None)
    if "name" in m:
        return m["name"][1], join_path(path, "name")
    return item, path


def _joint_refusal(r: Reader, field: str, what: str, item, path: str) -> SceneError:
    """The SceneError for the checks' refusal of JointSpec `field` of joint item `item`, at the
    key that gave it (the item when none did)."""
    m = r.mapping(item, path, None)
    for key in _JOINT_FIELD_KEYS.get(field, (field,)):
        if key in m:
            return r.fail(what, m[key][1], join_path(path, key))
    return r.fail(what, item, path)


def _joint_alone(r: Reader, text: str, line: int, index: int, bodies, index_of) -> JointSpec:
    """Joint item `text` (`  - name: ...` lines starting at `line`) read by the YAML reader as
    joints[index] over `bodies` (`index_of` their indices by name); raises its SceneError."""
    root = compose("\n" * (line - 2) + "joints:\n" + text, r.source)
    items = r.sequence(r.mapping(root, "", ("joints",))["joints"][1], "joints", min_len=1)
    path = f"joints[{index}]"
    joint = _read_joint(r, items[0], path, index, bodies, index_of)
    why = checks.joint_problem(bodies, joint)
    if why is not None:
        raise _joint_refusal(r, *why, items[0], path)
    return joint


# --- scene ----------------------------------------------------------------------------------

_SCENE_KEYS = ("name", "world", "bodies", "generators", "joints", "analytic")


def load_scene(path) -> Scene:
    """Read, check and expand the scene file at `path` (YAML, UTF-8; docs/scene-format.md).

    The scene's name defaults to the file's stem. Raises SceneError (one line:
    ``FILE:LINE: KEY.PATH: what is wrong``) for anything unreadable or invalid, including a
    path that is not a regular file (a FIFO, a device, a directory), which is refused before it
    is opened: reading a FIFO would wait for a writer forever.
    """
    source = str(path)
    p = Path(path)
    try:
        kind = _not_a_file(os.stat(p).st_mode)
        if kind:
            raise SceneError(f"is {kind}, not a scene file", source=source)
        # O_NONBLOCK: should the path have become a FIFO since the stat, opening it does not
        # wait for a writer, and fstat below refuses it.
        fd = os.open(p, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
        with open(fd, "rb") as f:
            kind = _not_a_file(os.fstat(f.fileno()).st_mode)
            if kind:
                raise SceneError(f"is {kind}, not a scene file", source=source)
            data = f.read(MAX_SCENE_BYTES + 1)
    except SceneError:
        raise
    except FileNotFoundError:
        raise SceneError("no such file", source=source) from None
    except OSError as exc:
        raise SceneError(f"cannot read the file: {exc.strerror or exc}", source=source) from None
    if len(data) > MAX_SCENE_BYTES:
        raise SceneError(f"the file is larger than {MAX_SCENE_BYTES} bytes", source=source)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise SceneError(
            f"not UTF-8 text (byte 0x{data[exc.start]:02x} at offset {exc.start})",
            source=source,
            line=line,
        ) from None
    del data
    return load_scene_text(text, source=source, default_name=p.stem)


def _not_a_file(mode: int) -> str | None:
    if stat.S_ISREG(mode):
        return None
    if stat.S_ISDIR(mode):
        return "a directory"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISSOCK(mode):
        return "a socket"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    return "not a regular file"


def load_scene_text(text: str, source: str = "<text>", *, default_name: str | None = None) -> Scene:
    """Check and expand scene YAML `text`; `source` names it in messages and in `Scene.source`.

    The name defaults to `default_name`, else "scene". Raises SceneError like `load_scene`.
    Text in the exact form `scene_to_yaml` writes (a log's scene) is read line by line without a
    YAML node tree (isaac.scene.fast_reader), to the same Scene; any other text goes through
    the YAML reader, bounded by MAX_YAML_BYTES and the node limits of isaac.scene.limits.
    """
    if len(text) > MAX_SCENE_BYTES:
        raise SceneError(f"the text is longer than {MAX_SCENE_BYTES} characters", source=source)
    # the node tree holds no cycles, yet its many nodes make the cyclic garbage collector run
    # over and over while it grows: pausing it halves the load time of a large scene.
    collecting = gc.isenabled()
    gc.disable()
    try:
        scene = fast_reader.read(
            text, source, default_name or "scene", _read_head, _body_alone, _joint_alone
        )
        if scene is not None:
            return validate.remember(scene)
        if len(text) > MAX_YAML_BYTES:
            raise SceneError(
                f"the text is longer than {MAX_YAML_BYTES} characters (the limit for YAML not "
                "written by scene_to_yaml)",
                source=source,
            )
        root = compose(text, source)
        if root is None:
            raise SceneError(
                "the scene is empty (expected a mapping with `bodies:` or `generators:`)",
                source=source,
                line=1,
            )
        return read_scene_tree(root, source, default_name=default_name)
    except RecursionError:
        raise SceneError("the document is nested too deeply", source=source) from None
    finally:
        if collecting:
            gc.enable()


def read_scene_tree(root, source: str = "<text>", *, default_name: str | None = None) -> Scene:
    """Check and expand the scene node tree `root`, as `load_scene_text` does the tree it
    composes from YAML text (isaac.scene.reader.compose); `source` names it in messages and
    in `Scene.source`. For a caller that holds a composed tree and changes a few of its nodes
    between reads (isaac.app.sweep: one scene, many runs), so as not to write and compose the
    whole text again each time. Raises SceneError like `load_scene_text`; its lines are the
    nodes' own."""
    collecting = gc.isenabled()
    gc.disable()  # as in load_scene_text: the readers' many small objects
    try:
        return validate.remember(_read_scene(Reader(source), root, default_name or "scene"))
    except RecursionError:
        raise SceneError("the document is nested too deeply", source=source) from None
    finally:
        if collecting:
            gc.enable()


def _read_head(r: Reader, root, default_name: str):
    """(mapping, name, world, analytic) of the scene mapping `root`."""
    m = r.mapping(root, "", _SCENE_KEYS)
    name = optional(r.name, m, "name", "", default_name)
    world = _read_world(r, r.given(m, "world", "", "a mapping of world settings"))
    analytic = None
    node = r.given(m, "analytic", "", "a mapping")
    if node is not None:
        if not isinstance(node, MappingNode):
            raise r.fail(f"expected a mapping, got {describe(node)}", node, "analytic")
        analytic = r.plain(node, "analytic")
    return m, name, world, analytic


def _read_scene(r: Reader, root, default_name: str) -> Scene:
    m, name, world, analytic = _read_head(r, root, default_name)
    bodies: list[BodySpec] = []
    origin: dict[str, tuple[str, int]] = {}  # name -> (key path, line) where it was made
    explicit = []  # (item node, key path) of each body of `bodies:`
    made = []  # (first body, end, kind, options node, key path, name prefix) of each generator
    friction_given = []  # (line, key path) of each `friction:` given, for the warnings

    def add(spec: BodySpec, path: str, node) -> None:
        if spec.name in origin:
            first_path, first_line = origin[spec.name]
            raise r.fail(
                f"duplicate body name {shown(spec.name)} (already used by {first_path} at "
                f"line {first_line})",
                node,
                path,
            )
        origin[spec.name] = (path, line_of(node))
        bodies.append(spec)

    node = r.given(m, "bodies", "", "a list of bodies")
    if node is not None:
        items = r.sequence(node, "bodies", max_len=MAX_BODIES, what="bodies")
        for i, item in enumerate(items):
            path = f"bodies[{i}]"
            spec = _read_body(r, item, path, i)
            name_node = item
            if isinstance(item, MappingNode):
                for key_node, value_node in item.value:
                    if key_node.value == "name":
                        name_node = value_node
            add(spec, join_path(path, "name") if name_node is not item else path, name_node)
            explicit.append((item, path))
            if isinstance(item, MappingNode):
                for key_node, value_node in item.value:
                    if key_node.value == "friction":
                        friction_given.append((line_of(value_node), join_path(path, "friction")))
    node = r.given(m, "generators", "", "a list of generators")
    if node is not None:
        items = r.sequence(node, "generators")
        for i, item in enumerate(items):
            path = f"generators[{i}]"
            first = len(bodies)
            kind, options_node, gen_path, prefix, specs = _expand_generator(
                r, item, path, MAX_BODIES - len(bodies)
            )
            for spec in specs:
                add(spec, path, item)
            made.append((first, len(bodies), kind, options_node, gen_path, prefix))
            friction_node = _option_node(r, options_node, gen_path, "friction")
            if friction_node is not None:
                friction_given.append((line_of(friction_node), join_path(gen_path, "friction")))
    if not bodies:
        raise r.fail("the scene has no bodies (give `bodies:` or `generators:`)", root)
    problem = checks.first_problem(bodies)
    if problem is not None:
        raise _refusal(r, problem, bodies, explicit, made)
    joints = _read_joints(r, m, bodies, world)
    marks = SceneMarks(
        bodies=tuple((line_of(item), path) for item, path in explicit),
        generators=tuple(
            (first, end, line_of(node), path) for first, end, _, node, path, _ in made
        ),
        friction=tuple(friction_given),
    )
    return Scene(
        name=name,
        world=world,
        bodies=tuple(bodies),
        source=r.source,
        analytic=analytic,
        joints=joints,
        marks=marks,
        as_written=tuple(r.as_written),
    )


def _body_alone(r: Reader, text: str, line: int, index: int) -> SceneError | None:
    """The error the YAML reader finds in one body item `text` (`  - name: ...` lines starting
    at `line`) read as body `index`, or None if it finds none."""
    try:
        root = compose("\n" * (line - 2) + "bodies:\n" + text, r.source)
        items = r.sequence(r.mapping(root, "", ("bodies",))["bodies"][1], "bodies", min_len=1)
        path = f"bodies[{index}]"
        body = _read_body(r, items[0], path, index)
    except SceneError as exc:
        return exc
    problem = checks.first_problem([body])
    if problem is None:
        return None
    return _refusal(r, problem, [body], [(items[0], path)], [])


# Which option of a generator decides a field of a body it makes, by the body's role (the
# naming conventions of isaac.scene.generators): (kind, role, field) -> option key; role "*"
# is every other body (the pile's polygons, the pyramid's boxes). A key the scene does not give
# falls back to the next in the tuple.
_OPTION_BEHIND = {
    ("pile", "floor", "vertices"): ("container.width", "container.thickness", "container"),
    ("pile", "left", "vertices"): ("container.height", "count"),
    ("pile", "right", "vertices"): ("container.height", "count"),
    ("pile", "*", "vertices"): ("radius", "sides"),
    ("pile", "*", "position"): ("container.position", "count"),
    ("pyramid", "*", "vertices"): ("box",),
    ("pyramid", "*", "position"): ("base", "rows"),
    ("pile", "*", "mass"): ("density", "radius"),
    ("pyramid", "*", "mass"): ("density", "box"),
    ("pile", "*", "name"): ("name",),
    ("pyramid", "*", "name"): ("name",),
}


def _refusal(r: Reader, problem: checks.Problem, bodies, explicit, made) -> SceneError:
    """The SceneError for `problem`, at the scene key that made the body."""
    i, field, what = problem
    body = bodies[i]
    if i < len(explicit):
        item, path = explicit[i]
        m = r.mapping(item, path, None)
        shape = r.mapping(m["shape"][1], path, None)
        kind = next(iter(shape))
        shape_at = (join_path(join_path(path, "shape"), kind), shape[kind][1])
        if field == "vertices":
            key_path, node = shape_at
        elif field == "mass":
            key_path, node = (
                (join_path(path, "density"), m["density"][1]) if "density" in m else shape_at
            )
        elif field in m:
            key_path, node = join_path(path, field), m[field][1]
        else:
            key_path, node = path, item
        return r.fail(what, node, key_path)
    first, end, kind, options_node, path, prefix = next(g for g in made if g[0] <= i < g[1])
    role = body.name[len(prefix) + 1 :]
    keys = _OPTION_BEHIND.get((kind, role, field)) or _OPTION_BEHIND.get((kind, "*", field), ())
    what = f"the body {shown(body.name)} it makes: {what}"
    for key in keys:
        node = _option_node(r, options_node, path, key)
        if node is not None:
            return r.fail(what, node, join_path(path, key))
    return r.fail(what, options_node, path)
