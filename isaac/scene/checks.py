"""The checks every body of an expanded scene passes, however it was made.

A log stores the expanded scene as the text `scene_to_yaml` writes, every shape as `polygon:`,
and a replay loads it back with `load_scene_text`. So a box, a regular polygon or a body a
generator makes must pass exactly what a `polygon:` body given by hand passes, or the log of a
scene that ran could not be replayed. The loader runs `first_problem` on every expanded scene,
and the log's line reader (isaac.scene.fast_reader) runs it on every body it reads: one
function, so `load_scene_text(scene_to_yaml(scene))` accepts every scene that loads.

Besides the ranges of docs/scene-format.md, a body's mass (area x density) and moment of
inertia (second moment of area x density), as the engine computes them, and their inverses
must be finite normal floats: a subnormal or zero mass makes the impulses infinite.
"""

from __future__ import annotations

import itertools
import operator
import sys
from typing import NamedTuple

import numpy as np

from isaac.scene import circle, polygon
from isaac.scene.limits import (
    FILTER_BITS,
    MAX_COORDINATE,
    MAX_DENSITY,
    MAX_FRICTION,
    MAX_GROUP,
    MAX_NAME_LENGTH,
    MAX_SIZE,
    MAX_SPEED,
    MAX_TIME,
    MIN_SIZE,
)
from isaac.scene.reader import shown, valid_name
from isaac.scene.spec import BodySpec

MIN_NORMAL = sys.float_info.min  # 2.2250738585072014e-308, the smallest normal float64


class Problem(NamedTuple):
    """What is wrong with body `index`: `field` is the BodySpec field at fault ("vertices",
    "position", ...) or "mass" (mass or inertia from vertices and density); `what` one line."""

    index: int
    field: str
    what: str


class MassProperties(NamedTuple):
    """(n,) arrays, as the engine's model computes them: mass = area * density (kg), inertia =
    second moment * density (kg m^2)."""

    area: np.ndarray
    second_moment: np.ndarray
    mass: np.ndarray
    inertia: np.ndarray


# field: (lowest, highest, lowest excluded); NaN fails every one.
_RANGES = {
    "position": (-MAX_COORDINATE, MAX_COORDINATE, False),
    "angle": (-MAX_SPEED, MAX_SPEED, False),
    "velocity": (-MAX_SPEED, MAX_SPEED, False),
    "angular_velocity": (-MAX_SPEED, MAX_SPEED, False),
    "density": (0.0, MAX_DENSITY, True),
    "restitution": (0.0, 1.0, False),
    "friction": (0.0, MAX_FRICTION, False),
    "enters_at": (0.0, MAX_TIME, False),
}


_PAIRS = ("position", "velocity")


def _outside(values: np.ndarray, lo: float, hi: float, lo_open: bool) -> np.ndarray:
    inside = (values > lo if lo_open else values >= lo) & (values <= hi)
    return ~inside.reshape(len(values), -1).all(axis=1)


def _normal(x: np.ndarray) -> np.ndarray:
    with np.errstate(all="ignore"):
        return np.isfinite(x) & (np.abs(x) >= MIN_NORMAL)


def survey(bodies) -> polygon.PolygonFacts:
    """`polygon.survey` of every body's shape: polygons from their vertices; a circle's extent is
    its diameter, its largest coordinate its radius, its area and second moment those of
    `circle.mass_properties`. A body with both vertices and a circle radius (or neither) has a
    problem."""
    circles = [i for i, b in enumerate(bodies) if b.circle is not None]
    if not circles:
        return polygon.survey([b.vertices for b in bodies])
    facts = polygon.survey([() if b.circle is not None else b.vertices for b in bodies])
    index = np.array(circles)
    with np.errstate(all="ignore"):
        radius = np.array([float(bodies[i].circle) for i in circles], dtype=np.float64)
        area, second = circle.mass_properties(radius)
        facts.extents[index] = 2.0 * radius
        facts.largest_coordinates[index] = radius
    facts.areas[index] = area
    facts.second_moments[index] = second
    for i in circles:
        facts.problems[i] = (
            "a body is a polygon or a circle: it has vertices and a circle radius"
            if len(bodies[i].vertices)
            else None
        )
    return facts


def mass_properties(bodies, facts: polygon.PolygonFacts | None = None) -> MassProperties:
    """Mass and inertia of every body of `bodies` (concrete ones too), bit for bit what the
    engine's model holds before it zeroes the inverses of concrete bodies."""
    if facts is None:
        facts = survey(bodies)
    density = np.fromiter((b.density for b in bodies), dtype=np.float64, count=len(bodies))
    with np.errstate(all="ignore"):
        return MassProperties(
            facts.areas,
            facts.second_moments,
            facts.areas * density,
            facts.second_moments * density,
        )


def first_problem(bodies) -> Problem | None:
    """The first body of `bodies` (BodySpecs) that a scene may not hold, and why; None if none.

    Checks, per body in this order: the name (1 to MAX_NAME_LENGTH printable characters); the
    vertices (what `polygon.validate_polygon` accepts and returns unchanged: counter-clockwise,
    3..MAX_VERTICES, convex, no duplicates; extent in [MIN_SIZE, MAX_SIZE]; every coordinate in
    [-MAX_COORDINATE, MAX_COORDINATE] of the body's own frame); position, angle, velocity,
    angular velocity, density, restitution, friction, enters_at and leaves_at in the ranges of
    docs/scene-format.md; then mass, inertia and their inverses finite and normal.
    """
    n = len(bodies)
    if n == 0:
        return None
    facts = survey(bodies)
    bad = np.zeros(n, dtype=bool)
    bad |= np.fromiter((not valid_name(b.name) for b in bodies), dtype=bool, count=n)
    bad |= np.array([p is not None for p in facts.problems])
    with np.errstate(invalid="ignore"):
        bad |= ~((facts.extents >= MIN_SIZE) & (facts.extents <= MAX_SIZE))
        bad |= ~(facts.largest_coordinates <= MAX_COORDINATE)
    columns = {}
    for field, (lo, hi, lo_open) in _RANGES.items():
        values = map(operator.attrgetter(field), bodies)
        if field in _PAIRS:
            flat = itertools.chain.from_iterable(values)
            column = np.fromiter(flat, np.float64, count=2 * n).reshape(n, 2)
        else:
            column = np.fromiter(values, np.float64, count=n)
        columns[field] = column
        bad |= _outside(column, lo, hi, lo_open)
    leaves = np.array(
        [np.nan if b.leaves_at is None else b.leaves_at for b in bodies], dtype=np.float64
    )
    given = ~np.isnan(leaves)
    with np.errstate(invalid="ignore"):
        bad |= given & ~((leaves > columns["enters_at"]) & (leaves <= MAX_TIME))
    bad |= np.fromiter((not isinstance(b.concrete, bool) for b in bodies), dtype=bool, count=n)
    bad |= np.fromiter((_filter_problem(b) is not None for b in bodies), dtype=bool, count=n)
    props = mass_properties(bodies, facts)
    with np.errstate(all="ignore"):
        for x in (props.mass, props.inertia, 1.0 / props.mass, 1.0 / props.inertia):
            bad |= ~_normal(x) | (x <= 0.0)
    failing = np.flatnonzero(bad)
    if len(failing) == 0:
        return None
    i = int(failing[0])
    return Problem(i, *_why(bodies[i], facts, i, props))


def _filter_problem(body: BodySpec) -> tuple[str, str] | None:
    """(field, one line) when the body's collision filter is not whole numbers in range."""
    hi = 2**FILTER_BITS - 1
    for field, lo, top in (("category", 0, hi), ("mask", 0, hi), ("group", -MAX_GROUP, MAX_GROUP)):
        value = getattr(body, field)
        if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= top:
            return field, f"{field} {value!r} must be a whole number in {lo}..{top}"
    return None


def _why(body: BodySpec, facts: polygon.PolygonFacts, i: int, props: MassProperties):
    """(field, one line) for body `body`, the i-th of the survey, known to fail a check."""
    if not valid_name(body.name):
        return "name", (
            f"the name {shown(body.name)} ({len(body.name)} characters) is not 1 to "
            f"{MAX_NAME_LENGTH} printable characters"
        )
    if facts.problems[i] is not None:
        return "vertices", facts.problems[i]
    extent = float(facts.extents[i])
    if not MIN_SIZE <= extent <= MAX_SIZE:
        return "vertices", (
            f"the polygon's extent {extent!r} m is outside [{MIN_SIZE!r}, {MAX_SIZE!r}]"
        )
    largest = float(facts.largest_coordinates[i])
    if not largest <= MAX_COORDINATE:
        return "vertices", (
            f"a vertex coordinate of {largest!r} m is outside [{-MAX_COORDINATE!r}, "
            f"{MAX_COORDINATE!r}]"
        )
    for field, (lo, hi, lo_open) in _RANGES.items():
        value = getattr(body, field)
        if _outside(np.array([value], dtype=np.float64), lo, hi, lo_open)[0]:
            low = f"> {lo!r}" if lo_open else f">= {lo!r}"
            each = " (each coordinate" if field in _PAIRS else " (it"
            return field, f"{field} {value!r} is out of range{each} must be {low} and <= {hi!r})"
    if body.leaves_at is not None and not body.enters_at < body.leaves_at <= MAX_TIME:
        return "leaves_at", (
            f"leaves_at ({body.leaves_at!r} s) must be later than enters_at "
            f"({body.enters_at!r} s) and <= {MAX_TIME!r}"
        )
    if not isinstance(body.concrete, bool):
        return "concrete", f"expected true or false, got {body.concrete!r}"
    filter_problem = _filter_problem(body)
    if filter_problem is not None:
        return filter_problem
    mass, inertia = float(props.mass[i]), float(props.inertia[i])
    area, second = float(props.area[i]), float(props.second_moment[i])
    return "mass", (
        f"mass {mass!r} kg (area {area!r} m^2 x density {body.density!r} kg/m^2) and moment of "
        f"inertia {inertia!r} kg m^2 (second moment {second!r} m^4 x density) and their "
        "inverses must be finite normal numbers; change the density or the size"
    )
