"""Scene generators: a few lines of YAML that expand into many plain `BodySpec`s at load time.

A generator runs once, when the scene is loaded; the simulation (and the log, which stores the
expanded scene) only ever sees the bodies it produced. Randomness comes from
``numpy.random.default_rng(seed)`` and is drawn in a fixed order, so one seed gives one scene on
one numpy version; logs do not depend on it because they store the expansion, not the seed.

`expand` reads a `generators:` item, checks the types and ranges of its options and calls
`pyramid` or `pile`; these raise `GeneratorError` only for problems that depend on several
options together (a container too small for its bodies), naming the option to change, and
`expand` turns that into the SceneError at that option. `refusal` does the same for the checks'
refusal of a body a generator made (isaac.scene.checks).

Conventions (world frame, m, y up):
* `pyramid`: row 1 is the bottom row (`rows` boxes), row `rows` the top (1 box); columns count
  from the left, from 1. Names ``PREFIX/ROW/COLUMN`` and ``PREFIX/ground``.
* `pile`: bodies ``PREFIX/1`` .. ``PREFIX/COUNT``, container ``PREFIX/floor``, ``PREFIX/left``,
  ``PREFIX/right``.
"""

from __future__ import annotations

import inspect
import math

import numpy as np

from isaac import trig
from isaac.errors import SceneError
from isaac.scene.bodies import box_tuple, material, vertices_tuple
from isaac.scene.limits import (
    MAX_BODIES,
    MAX_COORDINATE,
    MAX_NAME_LENGTH,
    MAX_PILE_COUNT,
    MAX_PYRAMID_ROWS,
    MAX_SIZE,
    MAX_VERTICES,
    MIN_SIZE,
)
from isaac.scene.polygon import mass_properties
from isaac.scene.reader import MappingNode, Reader, join_path, optional, scalar_or_none, shown
from isaac.scene.spec import BodySpec

# Each pile body gets a square cell of side CELL_MARGIN * 2 * max radius, so bodies start apart.
CELL_MARGIN = 1.05
# Angular gaps between a random polygon's vertices are drawn in [GAP_MIN, 1] and normalised: the
# largest gap stays below pi (the circle's centre lies inside) and no edge is a sliver.
GAP_MIN = 0.6


class GeneratorError(ValueError):
    """A generator's options do not fit together; `key` is the option to change (e.g.
    "container.height")."""

    def __init__(self, key: str, what: str) -> None:
        self.key = key
        self.what = what
        super().__init__(f"{key}: {what}")


def pile_suffix_length(count: int) -> int:
    """Characters a pile of `count` bodies adds to its prefix in its longest name."""
    return max(len("/floor"), len("/right"), len(f"/{count}"))


def pyramid_suffix_length(rows: int, ground: bool) -> int:
    """Characters a pyramid of `rows` rows adds to its prefix in its longest name."""
    longest = max(len(f"/{row}/{rows - row + 1}") for row in range(1, rows + 1))
    return max(longest, len("/ground")) if ground else longest


def _concrete_box(
    name: str,
    width: float,
    height: float,
    centre: tuple[float, float],
    restitution: float,
    friction: float,
) -> BodySpec:
    return BodySpec(
        name=name,
        vertices=box_tuple(width, height),
        position=centre,
        restitution=restitution,
        friction=friction,
        concrete=True,
    )


def pyramid(
    *,
    rows: int,
    box: tuple[float, float],
    base: tuple[float, float] = (0.0, 0.0),
    spacing: float = 0.0,
    density: float = 1.0,
    restitution: float = 0.0,
    friction: float = 0.5,
    name: str = "pyramid",
    ground: bool = True,
) -> list[BodySpec]:
    """A pyramid of boxes resting on each other (and on a concrete ground if `ground`).

    rows: boxes in the bottom row (the top row has 1); rows * (rows + 1) / 2 boxes in all.
    box: (width, height) of each box (m).
    base: world point (m) at the centre of the bottom edge of the bottom row; the ground's top
        surface passes through it.
    spacing: horizontal gap between neighbouring boxes of a row (m, >= 0).
    ground: add ``NAME/ground``, a concrete box as tall as one box and four boxes wider than the
        bottom row, its top at base[1].
    """
    width, height = box
    pitch = width + spacing
    vertices = box_tuple(width, height)
    bodies = []
    if ground:
        ground_width = rows * width + (rows - 1) * spacing + 4.0 * width
        bodies.append(
            _concrete_box(
                f"{name}/ground",
                ground_width,
                height,
                (base[0], base[1] - 0.5 * height),
                restitution,
                friction,
            )
        )
    for row in range(1, rows + 1):
        count = rows - row + 1
        y = base[1] + (row - 0.5) * height
        for column in range(1, count + 1):
            # centred on base[0]: offsets -(count-1)/2 .. +(count-1)/2 pitches
            x = base[0] + (column - 1 - 0.5 * (count - 1)) * pitch
            bodies.append(
                BodySpec(
                    name=f"{name}/{row}/{column}",
                    vertices=vertices,
                    position=(x, y),
                    density=density,
                    restitution=restitution,
                    friction=friction,
                )
            )
    return bodies


def pile_layout(count: int, radius_max: float, width: float) -> tuple[int, int, float]:
    """(columns, rows, cell side in m) of the starting grid of a pile of `count` bodies of
    circumradius at most `radius_max` (m) in a container `width` (m) wide inside."""
    cell = CELL_MARGIN * 2.0 * radius_max
    columns = int(width // cell)
    if columns < 1:
        raise GeneratorError(
            "container.width",
            f"{width!r} m is narrower than one body cell ({cell!r} m); "
            "widen the container or lower radius",
        )
    rows = -(-count // columns)
    return columns, rows, cell


def pile(
    *,
    count: int,
    seed: int = 0,
    sides: tuple[int, int] = (3, 8),
    radius: tuple[float, float] = (0.2, 0.5),
    width: float = 10.0,
    height: float | None = None,
    thickness: float = 0.5,
    position: tuple[float, float] = (0.0, 0.0),
    density: float = 1.0,
    restitution: float = 0.0,
    friction: float = 0.5,
    name: str = "pile",
) -> list[BodySpec]:
    """`count` random convex polygons falling into an open box made of 3 concrete boxes.

    sides: (min, max) vertex count, inclusive, each polygon drawn uniformly.
    radius: (min, max) circumradius (m), drawn uniformly.
    width, height, thickness: the container's inside width, wall height above the floor's top and
        wall/floor thickness (m). height None: just tall enough for the starting grid.
    position: world point (m) at the centre of the floor's top surface.
    Bodies start at rest on a grid of square cells (side 1.05 * 2 * max radius) filling the
    container from the bottom row upwards, left to right, each at a random angle; the polygon's
    circumcircle is centred in its cell so no two bodies overlap at the start.
    Raises GeneratorError if the grid does not fit the container.
    """
    columns, rows, cell = pile_layout(count, radius[1], width)
    needed = rows * cell
    if height is None:
        height = needed
    elif height < needed:
        raise GeneratorError(
            "container.height",
            f"{height!r} m is too low for {count} bodies: they start in {rows} "
            f"rows of {columns} cells of {cell!r} m, which need {needed!r} m; "
            "raise height, widen the container, or leave height out",
        )
    x0, y0 = position
    bodies = [
        _concrete_box(
            f"{name}/floor",
            width + 2.0 * thickness,
            thickness,
            (x0, y0 - 0.5 * thickness),
            restitution,
            friction,
        ),
        _concrete_box(
            f"{name}/left",
            thickness,
            height,
            (x0 - 0.5 * width - 0.5 * thickness, y0 + 0.5 * height),
            restitution,
            friction,
        ),
        _concrete_box(
            f"{name}/right",
            thickness,
            height,
            (x0 + 0.5 * width + 0.5 * thickness, y0 + 0.5 * height),
            restitution,
            friction,
        ),
    ]
    rng = np.random.default_rng(seed)
    left = x0 - 0.5 * columns * cell
    for i in range(count):
        # determinism: the draws happen in this order, one body at a time.
        n = int(rng.integers(sides[0], sides[1] + 1))
        r = float(rng.uniform(radius[0], radius[1]))
        phase = float(rng.uniform(0.0, 2.0 * math.pi))
        gaps = rng.uniform(GAP_MIN, 1.0, size=n)
        angle = float(rng.uniform(-math.pi, math.pi))
        steps = np.cumsum(gaps)
        local = np.empty((n, 2), dtype=np.float64)
        for k in range(n):
            a = phase + 2.0 * math.pi * (float(steps[k]) - float(gaps[0])) / float(steps[-1])
            # determinism: isaac.trig, the same bits on every machine (libm's are not)
            sa, ca = trig.sin_cos(a)
            local[k, 0] = r * ca
            local[k, 1] = r * sa
        # the engine puts the centroid at `position`; place it so the circumcircle's centre (the
        # local origin), rotated by `angle`, lands on the cell's centre.
        centroid = mass_properties(local)[1]
        s, c = trig.sin_cos(angle)
        cell_x = left + (i % columns + 0.5) * cell
        cell_y = y0 + (i // columns + 0.5) * cell
        pos = (
            cell_x + c * centroid[0] - s * centroid[1],
            cell_y + s * centroid[0] + c * centroid[1],
        )
        bodies.append(
            BodySpec(
                name=f"{name}/{i + 1}",
                vertices=vertices_tuple(local),
                position=(float(pos[0]), float(pos[1])),
                angle=angle,
                density=density,
                restitution=restitution,
                friction=friction,
            )
        )
    return bodies


# --- reading a scene's `generators:` items --------------------------------------------------

# the options are the generators' keywords, in order; the pile's container keys sit together
# under `container:`
_PYRAMID_KEYS = tuple(inspect.signature(pyramid).parameters)
_CONTAINER_KEYS = ("width", "height", "thickness", "position")
_PILE_KEYS = tuple(
    dict.fromkeys(
        "container" if key in _CONTAINER_KEYS else key for key in inspect.signature(pile).parameters
    )
)


# how each generator names its bodies, as the refusal of a too long `name` says it
_NAMING = {
    "pyramid": "NAME/ROW/COLUMN and NAME/ground",
    "pile": "NAME/1 .. NAME/COUNT, NAME/floor, NAME/left and NAME/right",
}


def _prefix(r: Reader, m: dict, path: str, kind: str, suffix: int) -> str:
    """The `kind` generator's `name` (default: `kind`): its bodies are named PREFIX + a suffix
    of up to `suffix` characters, and every name must fit MAX_NAME_LENGTH."""
    if "name" not in m:
        return kind
    node = m["name"][1]
    name = r.name(node, join_path(path, "name"))
    if len(name) + suffix > MAX_NAME_LENGTH:
        raise r.fail(
            f"a name of {len(name)} characters is too long here: this generator names its "
            f"bodies {_NAMING[kind]}, adding up to {suffix} characters, and a name has at most "
            f"{MAX_NAME_LENGTH} (use at most {MAX_NAME_LENGTH - suffix})",
            node,
            join_path(path, "name"),
        )
    return name


def _read_pyramid(r: Reader, node, path: str) -> tuple[dict, int]:
    m = r.mapping(node, path, _PYRAMID_KEYS)
    r.require(m, ("rows", "box"), node, path)
    rows = r.integer(m["rows"][1], join_path(path, "rows"), 1, MAX_PYRAMID_ROWS)
    ground = optional(r.boolean, m, "ground", path, True)
    options = dict(
        rows=rows,
        box=r.pair(m["box"][1], join_path(path, "box"), MIN_SIZE, MAX_SIZE, names="w, h"),
        base=optional(r.pair, m, "base", path, (0.0, 0.0), -MAX_COORDINATE, MAX_COORDINATE),
        spacing=optional(r.number, m, "spacing", path, 0.0, 0.0, MAX_SIZE),
        name=_prefix(r, m, path, "pyramid", pyramid_suffix_length(rows, ground)),
        ground=ground,
        **material(r, m, path),
    )
    return options, rows * (rows + 1) // 2 + (1 if ground else 0)


def read_pile(r: Reader, node, path: str) -> tuple[dict, int]:
    """(keyword arguments of `pile`, bodies it makes) of a `pile:` mapping `node` at `path`."""
    m = r.mapping(node, path, _PILE_KEYS)
    r.require(m, ("count",), node, path)
    count = r.integer(m["count"][1], join_path(path, "count"), 1, MAX_PILE_COUNT)
    sides = (3, 8)
    if "sides" in m:
        sides_path = join_path(path, "sides")
        items = r.sequence(m["sides"][1], sides_path, min_len=2, max_len=2, what="numbers")
        sides = tuple(
            r.integer(item, f"{sides_path}[{k}]", 3, MAX_VERTICES) for k, item in enumerate(items)
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
        name=_prefix(r, m, path, "pile", pile_suffix_length(count)),
        **container,
        **material(r, m, path),
    )
    return options, count + 3


def expand(r: Reader, node, path: str, room: int):
    """(kind, options node, key path, name prefix, bodies) of `generators:` item `node` (read
    at `path`), which may make at most `room` bodies."""
    m = r.mapping(node, path, ("pyramid", "pile"))
    if len(m) != 1:
        raise r.fail("each generator has exactly one key: pyramid or pile", node, path)
    kind, (_, options_node) = next(iter(m.items()))
    path = join_path(path, kind)
    reader = _read_pyramid if kind == "pyramid" else read_pile
    options, size = reader(r, options_node, path)
    if size > room:
        raise r.fail(
            f"this generator makes {size} bodies; with the others the scene would "
            f"exceed {MAX_BODIES} bodies",
            options_node,
            path,
        )
    try:
        bodies = (pyramid if kind == "pyramid" else pile)(**options)
    except GeneratorError as exc:
        key_node = option_node(r, options_node, path, exc.key) or options_node
        raise r.fail(exc.what, key_node, join_path(path, exc.key)) from None
    return kind, options_node, path, options["name"], bodies


def option_node(r: Reader, options_node, path: str, key: str):
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


# Which option of a generator decides a field of a body it makes, by the body's role (the
# naming conventions above): (kind, role, field) -> option key; role "*" is every other body
# (the pile's polygons, the pyramid's boxes). A key the scene does not give falls back to the
# next in the tuple.
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


def refusal(
    r: Reader, field: str, what: str, name: str, kind: str, options_node, path: str, prefix: str
) -> SceneError:
    """The SceneError for the checks' refusal `what` of BodySpec `field` of body `name`, made
    by the `kind` generator of options `options_node` (read at `path`, name prefix `prefix`),
    at the option behind that field (the options when the scene gives none of them)."""
    role = name[len(prefix) + 1 :]
    keys = _OPTION_BEHIND.get((kind, role, field)) or _OPTION_BEHIND.get((kind, "*", field), ())
    what = f"the body {shown(name)} it makes: {what}"
    for key in keys:
        node = option_node(r, options_node, path, key)
        if node is not None:
            return r.fail(what, node, join_path(path, key))
    return r.fail(what, options_node, path)
