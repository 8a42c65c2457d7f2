"""Scene generators: a few lines of YAML that expand into many plain `BodySpec`s at load time.

A generator runs once, when the scene is loaded; the simulation (and the log, which stores the
expanded scene) only ever sees the bodies it produced. Randomness comes from
``numpy.random.default_rng(seed)`` and is drawn in a fixed order, so one seed gives one scene on
one numpy version; logs do not depend on it because they store the expansion, not the seed.

The scene loader (isaac/scene.py) checks types and ranges of every option before calling these
functions; a generator raises `GeneratorError` only for problems that depend on several options
together (a container too small for its bodies), naming the option to change.

Conventions (world frame, m, y up):
* `pyramid`: row 1 is the bottom row (`rows` boxes), row `rows` the top (1 box); columns count
  from the left, from 1. Names ``PREFIX/ROW/COLUMN`` and ``PREFIX/ground``.
* `pile`: bodies ``PREFIX/1`` .. ``PREFIX/COUNT``, container ``PREFIX/floor``, ``PREFIX/left``,
  ``PREFIX/right``.
"""

from __future__ import annotations

import math

import numpy as np

from isaac import trig
from isaac.scene.polygon import box_vertices, mass_properties
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


def _vertex_tuple(vertices: np.ndarray) -> tuple[tuple[float, float], ...]:
    return tuple((float(x), float(y)) for x, y in vertices)


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
        vertices=_vertex_tuple(box_vertices(width, height)),
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
    vertices = _vertex_tuple(box_vertices(width, height))
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
                vertices=_vertex_tuple(local),
                position=(float(pos[0]), float(pos[1])),
                angle=angle,
                density=density,
                restitution=restitution,
                friction=friction,
            )
        )
    return bodies
