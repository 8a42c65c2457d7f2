"""Bodies of a scene's `bodies:` list (docs/scene-format.md) read into `BodySpec`s.

Each item is read and range-checked here; the checks every expanded body passes
(isaac.scene.checks) come after, and `refusal` points their message at the key that gave the
value they refuse.
"""

from __future__ import annotations

import functools
import math

from isaac.errors import SceneError
from isaac.scene import checks, polygon
from isaac.scene.limits import (
    FILTER_BITS,
    MAX_COORDINATE,
    MAX_DENSITY,
    MAX_FRICTION,
    MAX_GROUP,
    MAX_SIZE,
    MAX_SPEED,
    MAX_TIME,
    MAX_VERTICES,
    MIN_SIZE,
)
from isaac.scene.reader import Reader, join_path, key_at, optional, scalar_or_none
from isaac.scene.spec import DEFAULT_CATEGORY, DEFAULT_MASK, BodySpec

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
_SHAPES = ("box", "polygon", "regular", "circle")


def vertices_tuple(v) -> tuple[tuple[float, float], ...]:
    """Vertices `v` (m, body frame) as the tuple of float pairs a BodySpec holds."""
    return tuple((float(x), float(y)) for x, y in v)


@functools.lru_cache(maxsize=256)
def box_tuple(width: float, height: float) -> tuple[tuple[float, float], ...]:
    """The vertices (m, body frame, CCW, centred) of a `width` x `height` box, one tuple per
    size: a 100,000-box scene holds one, not 100,000."""
    return vertices_tuple(polygon.box_vertices(width, height))


def material(r: Reader, m: dict, path: str) -> dict:
    """density, restitution and friction of mapping `m` (a body's or a generator's), with
    their defaults."""
    return dict(
        density=optional(r.number, m, "density", path, 1.0, 0.0, MAX_DENSITY, lo_open=True),
        restitution=optional(r.number, m, "restitution", path, 0.0, 0.0, 1.0),
        friction=optional(r.number, m, "friction", path, 0.5, 0.0, MAX_FRICTION),
    )


def _read_shape(r: Reader, node, path: str) -> tuple[tuple[tuple[float, float], ...], float | None]:
    """(vertices, circle radius or None) of a body's `shape:`."""
    m = r.mapping(node, path, _SHAPES)
    if len(m) != 1:
        raise r.fail(f"give exactly one of {', '.join(_SHAPES)}", node, path)
    kind, (_, value) = next(iter(m.items()))
    path = join_path(path, kind)
    if kind == "circle":
        c = r.mapping(value, path, ("radius",))
        r.require(c, ("radius",), value, path)
        # the diameter is the circle's extent, bounded like a polygon's
        return (), r.number(c["radius"][1], join_path(path, "radius"), MIN_SIZE / 2, MAX_SIZE / 2)
    return _read_polygon(r, kind, value, path), None


def _read_polygon(r: Reader, kind: str, value, path: str) -> tuple[tuple[float, float], ...]:
    if kind == "box":
        return box_tuple(*r.pair(value, path, MIN_SIZE, MAX_SIZE, names="w, h"))
    if kind == "regular":
        p = r.mapping(value, path, ("sides", "radius", "phase"))
        r.require(p, ("sides", "radius"), value, path)
        sides = r.integer(p["sides"][1], join_path(path, "sides"), 3, MAX_VERTICES)
        radius = r.number(p["radius"][1], join_path(path, "radius"), MIN_SIZE, MAX_SIZE)
        phase = optional(r.number, p, "phase", path, 0.0, -MAX_SPEED, MAX_SPEED)
        return vertices_tuple(polygon.regular_vertices(sides, radius, phase))
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
    return vertices_tuple(ccw)


def read_body(r: Reader, node, path: str, index: int) -> BodySpec:
    """The BodySpec of `bodies:` item `node` (bodies[index], read at `path`)."""
    m = r.mapping(node, path, _BODY_KEYS)
    r.require(m, ("shape",), node, path)
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
        **material(r, m, path),
        concrete=optional(r.boolean, m, "concrete", path, False),
        enters_at=enters_at,
        leaves_at=leaves_at,
        category=optional(r.bits, m, "category", path, DEFAULT_CATEGORY, FILTER_BITS),
        mask=optional(r.bits, m, "mask", path, DEFAULT_MASK, FILTER_BITS),
        group=optional(r.integer, m, "group", path, 0, -MAX_GROUP, MAX_GROUP),
    )


def refusal(r: Reader, field: str, what: str, item, path: str) -> SceneError:
    """The SceneError for the checks' refusal `what` of BodySpec `field` of `bodies:` item
    `item` (read at `path`), at the key that gave it: the shape for the vertices, the density
    (else the shape) for the mass."""
    m = r.mapping(item, path, None)
    if field == "mass" and "density" in m:
        field = "density"
    if field in ("vertices", "mass"):
        shape = r.mapping(m["shape"][1], path, None)
        kind = next(iter(shape))
        return r.fail(what, shape[kind][1], join_path(join_path(path, "shape"), kind))
    return r.fail(what, *key_at(m, item, path, field))


def body_alone(r: Reader, text: str, line: int, index: int) -> SceneError | None:
    """The error the YAML reader finds in one body item `text` (`  - name: ...` lines starting
    at `line`) read as body `index`, or None if it finds none."""
    path = f"bodies[{index}]"
    try:
        item = r.item_alone("bodies", text, line)
        body = read_body(r, item, path, index)
    except SceneError as exc:
        return exc
    problem = checks.first_problem([body])
    if problem is None:
        return None
    return refusal(r, problem.field, problem.what, item, path)
