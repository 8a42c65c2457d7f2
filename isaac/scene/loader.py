"""Scenes: the YAML contract (docs/scene-format.md) turned into a validated, immutable `Scene`.

A scene says everything a run needs. It is validated once, here; the engine trusts a `Scene`.
Loading: YAML text -> node tree with line marks (isaac.scene.reader) -> checked values -> Scene.
"""

from __future__ import annotations

import dataclasses
import gc
import math
from pathlib import Path

import yaml

from isaac.errors import SceneError
from isaac.scene import generators, polygon
from isaac.scene.limits import (
    MAX_BODIES,
    MAX_COORDINATE,
    MAX_DENSITY,
    MAX_FRICTION,
    MAX_GRAVITY,
    MAX_ITERATIONS,
    MAX_PYRAMID_ROWS,
    MAX_SCENE_BYTES,
    MAX_SIZE,
    MAX_SPEED,
    MAX_STEPS,
    MAX_SUBSTEPS,
    MAX_TIME,
    MAX_VERTICES,
    MIN_SIZE,
)
from isaac.scene.reader import (
    Reader,
    compose,
    describe,
    join_path,
    line_of,
    optional,
    scalar_or_none,
)
from isaac.scene.settings import DEFAULT_PRESET, PRESETS, WorldSettings
from isaac.scene.spec import BodySpec, Scene

# --- world ----------------------------------------------------------------------------------

_WORLD_FIELDS = tuple(f.name for f in dataclasses.fields(WorldSettings))
_CHOICES = {
    "integrator": ("explicit", "semi_implicit"),
    "solver": ("seed", "sequential"),
    "position_correction": ("full", "partial", "none"),
    "restitution_rule": ("max", "min", "mean", "product"),
    "friction_rule": ("sqrt", "min", "max", "mean", "product"),
    "ccd": ("off", "speculative"),
}


def _world_value(r: Reader, key: str, node, path: str):
    if key in _CHOICES:
        return r.choice(node, path, _CHOICES[key])
    if key in ("warm_starting", "friction", "axis_hysteresis"):
        return r.boolean(node, path)
    if key == "gravity":
        return r.pair(node, path, -MAX_GRAVITY, MAX_GRAVITY)
    if key == "dt":
        return r.number(node, path, 0.0, 1.0, lo_open=True)
    if key == "steps":
        return r.integer(node, path, 1, MAX_STEPS)
    if key == "substeps":
        return r.integer(node, path, 1, MAX_SUBSTEPS)
    if key in ("iterations", "position_iterations"):
        return r.integer(node, path, 1, MAX_ITERATIONS)
    if key == "contact_points":
        return r.integer(node, path, 1, 2)
    if key == "slop":
        return r.number(node, path, 0.0, 1.0)
    if key == "correction":
        return r.number(node, path, 0.0, 1.0, lo_open=True)
    if key == "restitution_threshold":
        return r.number(node, path, 0.0, 1e3)
    raise AssertionError(f"world key {key} has no reader")


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
)


def _vertices_tuple(v) -> tuple[tuple[float, float], ...]:
    return tuple((float(x), float(y)) for x, y in v)


def _read_shape(r: Reader, node, path: str) -> tuple[tuple[float, float], ...]:
    m = r.mapping(node, path, ("box", "polygon", "regular"))
    if len(m) != 1:
        raise r.fail("give exactly one of box, polygon, regular", node, path)
    kind, (_, value) = next(iter(m.items()))
    path = join_path(path, kind)
    if kind == "box":
        width, height = r.pair(value, path, MIN_SIZE, MAX_SIZE)
        return _vertices_tuple(polygon.box_vertices(width, height))
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
    enters_at = optional(r.number, m, "enters_at", path, 0.0, 0.0, MAX_TIME)
    leaves_at = None
    if "leaves_at" in m and scalar_or_none(m["leaves_at"][1]) is not None:
        leaves_path = join_path(path, "leaves_at")
        leaves_at = r.number(m["leaves_at"][1], leaves_path, 0.0, MAX_TIME)
        if leaves_at <= enters_at:
            raise r.fail(
                f"leaves_at ({leaves_at!r} s) must be later than enters_at ({enters_at!r} s)",
                m["leaves_at"][1],
                leaves_path,
            )
    return BodySpec(
        name=name,
        vertices=_read_shape(r, m["shape"][1], join_path(path, "shape")),
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


def _read_pyramid(r: Reader, node, path: str) -> tuple[dict, int]:
    m = r.mapping(node, path, _PYRAMID_KEYS)
    _require(r, m, ("rows", "box"), node, path)
    rows = r.integer(m["rows"][1], join_path(path, "rows"), 1, MAX_PYRAMID_ROWS)
    options = dict(
        rows=rows,
        box=r.pair(m["box"][1], join_path(path, "box"), MIN_SIZE, MAX_SIZE),
        base=optional(r.pair, m, "base", path, (0.0, 0.0), -MAX_COORDINATE, MAX_COORDINATE),
        spacing=optional(r.number, m, "spacing", path, 0.0, 0.0, MAX_SIZE),
        name=optional(r.name, m, "name", path, "pyramid"),
        ground=optional(r.boolean, m, "ground", path, True),
        **_material(r, m, path),
    )
    return options, rows * (rows + 1) // 2 + 1


def _read_pile(r: Reader, node, path: str) -> tuple[dict, int]:
    m = r.mapping(node, path, _PILE_KEYS)
    _require(r, m, ("count",), node, path)
    count = r.integer(m["count"][1], join_path(path, "count"), 1, MAX_BODIES)
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
        container = dict(
            width=optional(r.number, c, "width", cpath, 10.0, MIN_SIZE, MAX_SIZE),
            height=optional(r.number, c, "height", cpath, None, MIN_SIZE, MAX_COORDINATE),
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
        name=optional(r.name, m, "name", path, "pile"),
        **container,
        **_material(r, m, path),
    )
    return options, count + 3


def _expand_generator(r: Reader, node, path: str, room: int) -> list[BodySpec]:
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
        return getattr(generators, kind)(**options)
    except generators.GeneratorError as exc:
        key_node = options_node
        head = exc.key.split(".")[0]
        options_map = r.mapping(options_node, path, None)
        if head in options_map:
            key_node = options_map[head][1]
        raise r.fail(exc.what, key_node, join_path(path, exc.key)) from None


# --- scene ----------------------------------------------------------------------------------

_SCENE_KEYS = ("name", "world", "bodies", "generators", "analytic")


def load_scene(path) -> Scene:
    """Read, check and expand the scene file at `path` (YAML, UTF-8; docs/scene-format.md).

    The scene's name defaults to the file's stem. Raises SceneError (one line:
    ``FILE:LINE: KEY.PATH: what is wrong``) for anything unreadable or invalid.
    """
    source = str(path)
    try:
        p = Path(path)
        if p.is_dir():
            raise SceneError("is a directory, not a scene file", source=source)
        with open(p, "rb") as f:
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
    return load_scene_text(text, source=source, default_name=p.stem)


def load_scene_text(text: str, source: str = "<text>", *, default_name: str | None = None) -> Scene:
    """Check and expand scene YAML `text`; `source` names it in messages and in `Scene.source`.

    The name defaults to `default_name`, else "scene". Raises SceneError like `load_scene`.
    """
    if len(text) > MAX_SCENE_BYTES:
        raise SceneError(f"the text is longer than {MAX_SCENE_BYTES} characters", source=source)
    # the node tree holds no cycles, yet its ~30 nodes per body make the cyclic garbage collector
    # run over and over while it grows: pausing it halves the load time of a large scene.
    collecting = gc.isenabled()
    gc.disable()
    try:
        root = compose(text, source)
        if root is None:
            raise SceneError(
                "the scene is empty (expected a mapping with `bodies:` or `generators:`)",
                source=source,
                line=1,
            )
        return _read_scene(Reader(source), root, default_name or "scene")
    except RecursionError:
        raise SceneError("the document is nested too deeply", source=source) from None
    finally:
        if collecting:
            gc.enable()


def _read_scene(r: Reader, root, default_name: str) -> Scene:
    m = r.mapping(root, "", _SCENE_KEYS)
    name = optional(r.name, m, "name", "", default_name)
    world_node = m["world"][1] if "world" in m else None
    world = _read_world(r, None if scalar_or_none(world_node) is None else world_node)
    bodies: list[BodySpec] = []
    origin: dict[str, tuple[str, int]] = {}  # name -> (key path, line) where it was made

    def add(spec: BodySpec, path: str, node) -> None:
        if spec.name in origin:
            first_path, first_line = origin[spec.name]
            raise r.fail(
                f"duplicate body name {spec.name!r} (already used by {first_path} at "
                f"line {first_line})",
                node,
                path,
            )
        origin[spec.name] = (path, line_of(node))
        bodies.append(spec)

    if "bodies" in m and scalar_or_none(m["bodies"][1]) is not None:
        items = r.sequence(m["bodies"][1], "bodies", max_len=MAX_BODIES, what="bodies")
        for i, item in enumerate(items):
            path = f"bodies[{i}]"
            spec = _read_body(r, item, path, i)
            name_node = item
            if isinstance(item, yaml.MappingNode):
                for key_node, value_node in item.value:
                    if key_node.value == "name":
                        name_node = value_node
            add(spec, join_path(path, "name") if name_node is not item else path, name_node)
    if "generators" in m and scalar_or_none(m["generators"][1]) is not None:
        items = r.sequence(m["generators"][1], "generators")
        for i, item in enumerate(items):
            path = f"generators[{i}]"
            for spec in _expand_generator(r, item, path, MAX_BODIES - len(bodies)):
                add(spec, path, item)
    if not bodies:
        raise r.fail("the scene has no bodies (give `bodies:` or `generators:`)", root)
    analytic = None
    if "analytic" in m and scalar_or_none(m["analytic"][1]) is not None:
        if not isinstance(m["analytic"][1], yaml.MappingNode):
            raise r.fail(
                f"expected a mapping, got {describe(m['analytic'][1])}",
                m["analytic"][1],
                "analytic",
            )
        analytic = r.plain(m["analytic"][1], "analytic")
    return Scene(name=name, world=world, bodies=tuple(bodies), source=r.source, analytic=analytic)
