"""The checks every body of an expanded scene passes, however it was made.

A log stores the expanded scene as the text `scene_to_yaml` writes, every shape as `polygon:`,
and a replay loads it back with `load_scene_text`. So a box, a regular polygon or a body a
generator makes must pass exactly what a `polygon:` body given by hand passes, or the log of a
scene that ran could not be replayed. The loader runs `first_problem` on every expanded scene,
and the log's line reader (isaac.scene.fast_reader) runs it on every body it reads: one
function, so `load_scene_text(scene_to_yaml(scene))` accepts every scene that loads. Joints
likewise: `first_joint_problem` holds the rules of the `joints:` section for JointSpecs however
they were made (the loader's, a scene built in Python, a log's text read back).

Besides the ranges of docs/scene-format.md, a body's mass (area x density) and moment of
inertia (second moment of area x density), as the engine computes them, and their inverses
must be finite normal floats: a subnormal or zero mass makes the impulses infinite.
"""

from __future__ import annotations

import itertools
import math
import numbers
import operator
import sys
from typing import NamedTuple

import numpy as np

from isaac.scene import circle, polygon
from isaac.scene.limits import (
    AXIS_TOLERANCE,
    COINCIDENT_ANCHORS,
    FILTER_BITS,
    MAX_ANCHOR,
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
    MAX_QUOTED,
    MAX_REFERENCE_ANGLE,
    MAX_SIZE,
    MAX_SPEED,
    MAX_STIFFNESS,
    MAX_TIME,
    MIN_SIZE,
)
from isaac.scene.reader import shown, valid_name
from isaac.scene.settings import (
    WORLD_BOOLEANS,
    WORLD_CHOICES,
    WORLD_RANGES,
    WorldSettings,
)
from isaac.scene.spec import JOINT_KINDS, BodySpec, JointSpec
from isaac.trig import sin_cos

MIN_NORMAL = sys.float_info.min  # 2.2250738585072014e-308, the smallest normal float64


class Problem(NamedTuple):
    """What is wrong with body `index`: `field` is the BodySpec field at fault ("vertices",
    "position", ...) or "mass" (mass or inertia from vertices and density); `what` one line.
    From `first_joint_problem`: joint `index` and a JointSpec field."""

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
    if body.circle is not None and not MIN_SIZE <= extent <= MAX_SIZE:
        return "circle", (
            f"the circle's radius {body.circle!r} m is outside [{MIN_SIZE / 2!r}, {MAX_SIZE / 2!r}]"
        )
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


# --- world settings -------------------------------------------------------------------------


def world_problem(world) -> tuple[str, str] | None:
    """(WorldSettings field, one line) of the first setting of `world` outside the rules of
    `world:` (WORLD_CHOICES, WORLD_BOOLEANS, WORLD_RANGES), or None. Numbers are Python ints or
    floats (not bool); an integer setting a whole number (an int)."""
    if not isinstance(world, WorldSettings):
        return "world", f"must be an isaac.scene.WorldSettings, got {type(world).__name__}"
    for field, options in WORLD_CHOICES.items():
        value = getattr(world, field)
        if not isinstance(value, str) or value not in options:
            return field, f"{field} {_shown_value(value)} is not one of {', '.join(options)}"
    for field in WORLD_BOOLEANS:
        value = getattr(world, field)
        if not isinstance(value, bool):
            return field, f"{field} must be True or False, got {_shown_value(value)}"
    for field, (kind, lo, hi, lo_open) in WORLD_RANGES.items():
        value = getattr(world, field)
        low = f"> {lo!r}" if lo_open else f">= {lo!r}"
        if kind == "pair":
            ok = isinstance(value, (tuple, list)) and len(value) == 2
            ok = ok and all(_real(v, lo, hi, lo_open) for v in value)
            what = f"two numbers, each {low} and <= {hi!r}"
        elif kind == "integer":
            ok = type(value) is int and lo <= value <= hi
            what = f"a whole number (int) in {lo}..{hi}"
        else:
            ok = _real(value, lo, hi, lo_open)
            what = f"a number {low} and <= {hi!r}"
        if not ok:
            return field, f"{field} must be {what}, got {_shown_value(value)}"
    return None


def _shown_value(value) -> str:
    """`value`'s repr for a message, cut to MAX_QUOTED characters."""
    text = repr(value)
    return text if len(text) <= MAX_QUOTED else f"{text[:MAX_QUOTED]}... ({len(text)} characters)"


# --- joints ---------------------------------------------------------------------------------

SEED_JOINTS = (
    "joints need the sequential solver (world.solver: sequential, or fidelity fast, balanced "
    "or accurate): the seed's single pass has no joint rows"
)

# the JointSpec fields each kind uses; every other one keeps its default
_KIND_FIELDS = {
    "revolute": ("lower", "upper", "motor_speed", "max_motor"),
    "distance": ("length", "min_length", "max_length", "stiffness", "damping_ratio"),
    "weld": ("stiffness", "damping_ratio"),
    "prismatic": ("axis", "lower", "upper", "motor_speed", "max_motor"),
}
_JOINT_DEFAULTS = {
    "axis": (1.0, 0.0),
    "length": 0.0,
    "min_length": None,
    "max_length": None,
    "stiffness": None,
    "damping_ratio": 0.0,
    "lower": None,
    "upper": None,
    "motor_speed": None,
    "max_motor": 0.0,
}


def unit_axis(axis: tuple[float, float]) -> tuple[float, float]:
    """`axis` as a unit vector: itself when its length is already within AXIS_TOLERANCE of 1
    (so a stored axis read back is the same bits), else divided by its length (IEEE sqrt, the
    same bits everywhere)."""
    x, y = float(axis[0]), float(axis[1])
    n = math.sqrt(x * x + y * y)
    if abs(n - 1.0) <= AXIS_TOLERANCE:
        return (x, y)
    return (x / n, y / n)


def to_world(body: BodySpec, local: tuple[float, float]) -> tuple[float, float]:
    """`body`'s point `local` (m, its frame) in the world at step 0: position + R(angle) local."""
    s, c = sin_cos(body.angle)
    return (
        body.position[0] + (c * local[0] - s * local[1]),
        body.position[1] + (s * local[0] + c * local[1]),
    )


def coincident_anchors(body_a: BodySpec, local_a, body_b: BodySpec, local_b) -> str | None:
    """Why a distance joint with anchors `local_a` on `body_a` and `local_b` on `body_b` (m,
    each body's frame) cannot be, or None: its anchors coincide at step 0 (within
    COINCIDENT_ANCHORS of the largest coordinate, at least 1 m). A distance joint acts along the
    line between its anchors; with none, the engine falls back on the world x axis and a rigid
    rod holds the anchors together, not `length` apart (Box2D has no axis there either):
    refused, whatever `length` says."""
    xa, ya = to_world(body_a, local_a)
    xb, yb = to_world(body_b, local_b)
    gap = math.sqrt((xb - xa) * (xb - xa) + (yb - ya) * (yb - ya))
    coordinates = (*body_a.position, *body_b.position, *local_a, *local_b, xa, ya, xb, yb)
    if not gap <= COINCIDENT_ANCHORS * max(1.0, *map(abs, coordinates)):  # NaN: not this check
        return None
    return (
        f"the distance joint's anchors coincide at step 0 (both at [{xa!r}, {ya!r}] in the "
        f"world, {gap!r} m apart): it acts along the line between them, which they do not give; "
        "move anchor_b away from anchor_a (the length is then held along that line), or join "
        "the bodies with a revolute joint to hold the two points together"
    )


def joint_solver_problem(solver: str, joints) -> str | None:
    """Why a world with solver `solver` cannot hold `joints`, or None."""
    return SEED_JOINTS if len(joints) and solver == "seed" else None


def _real(x, lo: float, hi: float, lo_open: bool = False) -> bool:
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        return False
    return (x > lo if lo_open else x >= lo) and x <= hi  # NaN fails both


def _point(p, bound: float) -> bool:
    return isinstance(p, tuple) and len(p) == 2 and all(_real(v, -bound, bound) for v in p)


def joint_problem(bodies, joint: JointSpec) -> tuple[str, str] | None:
    """(JointSpec field, one line) of what is wrong with `joint` among `bodies`, or None.

    The rules of docs/scene-format.md, `joints:`: a valid name and kind; two different bodies
    (indices into `bodies`), not both concrete; anchors (body frames) within MAX_ANCHOR; the
    fields its kind does not use at their defaults; a distance joint's anchors apart at step 0
    (`coincident_anchors`); reference angle, lengths (min <= length <=
    max), stiffness, damping (only with stiffness), limits (both or neither, lower <= upper,
    revolute within [-pi, pi]), motor (speed and a max >= 0, both or neither) in range; a
    prismatic axis of unit length (within AXIS_TOLERANCE); collide_connected a bool.
    """
    j = joint
    if not isinstance(j.name, str) or not valid_name(j.name):
        return "name", f"a joint name must be 1 to {MAX_NAME_LENGTH} printable characters"
    if j.kind not in JOINT_KINDS:
        return "kind", f"{j.kind!r} is not one of {', '.join(JOINT_KINDS)}"
    n = len(bodies)
    for field in ("a", "b"):
        i = getattr(j, field)
        if isinstance(i, bool) or not isinstance(i, numbers.Integral) or not 0 <= i < n:
            return field, f"body index {i!r} is not one of the scene's {n} bodies (0..{n - 1})"
    if j.a == j.b:
        return "b", (
            f"the joint's two bodies are the same body {shown(bodies[j.a].name)}: a joint joins "
            "two different bodies"
        )
    if bodies[j.a].concrete and bodies[j.b].concrete:
        return "a", (
            f"both bodies ({shown(bodies[j.a].name)} and {shown(bodies[j.b].name)}) are "
            "concrete: a joint needs a movable body (one concrete body pins the other to the "
            "world)"
        )
    for field in ("local_a", "local_b"):
        if not _point(getattr(j, field), MAX_ANCHOR):
            return field, (
                f"the anchor {getattr(j, field)!r} must be two numbers (m, the body's frame), "
                f"each in [{-MAX_ANCHOR!r}, {MAX_ANCHOR!r}]"
            )
    if not _real(j.reference_angle, -MAX_REFERENCE_ANGLE, MAX_REFERENCE_ANGLE):
        return "reference_angle", (
            f"reference_angle {j.reference_angle!r} rad must be in "
            f"[{-MAX_REFERENCE_ANGLE!r}, {MAX_REFERENCE_ANGLE!r}]"
        )
    if not isinstance(j.collide_connected, bool):
        return "collide_connected", f"expected true or false, got {j.collide_connected!r}"
    used = _KIND_FIELDS[j.kind]
    for field, default in _JOINT_DEFAULTS.items():
        value = getattr(j, field)
        if field not in used and value != default:
            return field, f"a {j.kind} joint has no {field} (it must stay {default!r})"
    if j.kind == "distance":
        why = coincident_anchors(bodies[j.a], j.local_a, bodies[j.b], j.local_b)
        if why is not None:
            return "local_b", why
    return _kind_problem(j)


def _kind_problem(j: JointSpec) -> tuple[str, str] | None:
    if j.kind == "prismatic":
        ok = _point(j.axis, 2.0)
        if ok:
            x, y = j.axis
            ok = abs(math.sqrt(x * x + y * y) - 1.0) <= AXIS_TOLERANCE
        if not ok:
            return "axis", f"the axis {j.axis!r} must be a unit vector (a's frame)"
    if j.kind == "distance":
        if not _real(j.length, 0.0, MAX_JOINT_LENGTH, lo_open=True):
            return "length", f"length {j.length!r} m must be > 0 and <= {MAX_JOINT_LENGTH!r}"
        lo, hi = j.min_length, j.max_length
        if lo is not None and not _real(lo, 0.0, MAX_JOINT_LENGTH):
            return "min_length", f"min_length {lo!r} m must be in [0, {MAX_JOINT_LENGTH!r}]"
        if hi is not None and not _real(hi, 0.0, MAX_JOINT_LENGTH, lo_open=True):
            return "max_length", (f"max_length {hi!r} m must be > 0 and <= {MAX_JOINT_LENGTH!r}")
        if lo is not None and hi is not None and lo > hi:
            return "min_length", f"min_length {lo!r} m is greater than max_length {hi!r} m"
        if lo is not None and lo > j.length:
            return "min_length", f"min_length {lo!r} m is greater than the length {j.length!r} m"
        if hi is not None and hi < j.length:
            return "max_length", f"max_length {hi!r} m is less than the length {j.length!r} m"
    if j.kind in ("distance", "weld"):
        if j.stiffness is not None and not _real(j.stiffness, 0.0, MAX_STIFFNESS, lo_open=True):
            return "stiffness", f"stiffness {j.stiffness!r} Hz must be > 0 and <= {MAX_STIFFNESS!r}"
        if not _real(j.damping_ratio, 0.0, MAX_DAMPING_RATIO):
            return "damping_ratio", (
                f"damping_ratio {j.damping_ratio!r} must be in [0, {MAX_DAMPING_RATIO!r}]"
            )
        if j.stiffness is None and j.damping_ratio != 0.0:
            return "damping_ratio", "damping_ratio needs stiffness (a rigid joint has no spring)"
    if j.kind in ("revolute", "prismatic"):
        bound = math.pi if j.kind == "revolute" else MAX_JOINT_LENGTH
        unit = "rad" if j.kind == "revolute" else "m"
        if (j.lower is None) != (j.upper is None):
            return "lower", "give both limits (lower and upper) or neither"
        if j.lower is not None:
            for field in ("lower", "upper"):
                if not _real(getattr(j, field), -bound, bound):
                    return field, (
                        f"the {field} limit {getattr(j, field)!r} {unit} must be in "
                        f"[{-bound!r}, {bound!r}]"
                    )
            if j.lower > j.upper:
                return "lower", (
                    f"the lower limit {j.lower!r} {unit} is greater than the upper limit "
                    f"{j.upper!r} {unit}"
                )
        top = MAX_MOTOR_TORQUE if j.kind == "revolute" else MAX_MOTOR_FORCE
        if j.motor_speed is not None and not _real(j.motor_speed, -MAX_SPEED, MAX_SPEED):
            return "motor_speed", (
                f"the motor speed {j.motor_speed!r} must be in [{-MAX_SPEED!r}, {MAX_SPEED!r}]"
            )
        if not _real(j.max_motor, 0.0, top):
            return "max_motor", f"the motor's maximum {j.max_motor!r} must be in [0, {top!r}]"
        if j.motor_speed is None and j.max_motor != 0.0:
            return "max_motor", "max_motor is given without a motor speed"
    return None


def first_joint_problem(bodies, joints) -> Problem | None:
    """The first joint of `joints` (JointSpecs over `bodies`) a scene may not hold, and why
    (`joint_problem`, then names unique among the joints, at most MAX_JOINTS); None if none."""
    if len(joints) > MAX_JOINTS:
        return Problem(MAX_JOINTS, "name", f"a scene has at most {MAX_JOINTS} joints")
    seen: dict[str, int] = {}
    for i, joint in enumerate(joints):
        why = joint_problem(bodies, joint)
        if why is not None:
            return Problem(i, *why)
        first = seen.setdefault(joint.name, i)
        if first != i:
            return Problem(
                i,
                "name",
                f"duplicate joint name {shown(joint.name)} (already used by joints[{first}])",
            )
    return None
