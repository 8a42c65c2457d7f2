"""Scenes: the YAML contract (docs/scene-format.md) and its validated, immutable form.

A scene says everything a run needs. It is validated once, here; the engine trusts a `Scene`.
"""

from __future__ import annotations

import dataclasses
import difflib
import gc
import json
import math
import re
from dataclasses import dataclass
from pathlib import Path

import yaml

from isaac.errors import SceneError

# Fidelity presets: each sets the settings below; explicit keys in `world:` override a preset.
# `seed` reproduces the seed's algorithm exactly (docs/physics.md).
PRESETS: dict[str, dict[str, object]] = {
    "seed": dict(integrator="explicit", substeps=1, solver="seed", iterations=1,
                 warm_starting=False, contact_points=1, position_correction="full",
                 position_iterations=1, restitution_threshold=0.0, ccd="off",
                 axis_hysteresis=False),
    "fast": dict(integrator="semi_implicit", substeps=1, solver="sequential", iterations=6,
                 warm_starting=True, contact_points=2, position_correction="partial",
                 position_iterations=1, restitution_threshold=0.5, ccd="off",
                 axis_hysteresis=True),
    "balanced": dict(integrator="semi_implicit", substeps=1, solver="sequential", iterations=10,
                     warm_starting=True, contact_points=2, position_correction="partial",
                     position_iterations=3, restitution_threshold=1.0, ccd="speculative",
                     axis_hysteresis=True),
    "accurate": dict(integrator="semi_implicit", substeps=4, solver="sequential", iterations=20,
                     warm_starting=True, contact_points=2, position_correction="partial",
                     position_iterations=4, restitution_threshold=1.0, ccd="speculative",
                     axis_hysteresis=True),
}
DEFAULT_PRESET = "balanced"

MAX_VERTICES = 50  # the seed's LocalSpaceList[50][2]
MAX_BODIES = 100_000


@dataclass(frozen=True)
class WorldSettings:
    """Everything about the world a run needs, presets already resolved.

    gravity: (gx, gy) acceleration (m/s^2, world frame, y up).
    dt: time step (s), > 0.
    steps: default number of steps of a run.
    fidelity: the preset the settings came from (informative; the fields below are what counts).
    integrator: "explicit" (the seed: position with the old velocity, then gravity) or
        "semi_implicit" (gravity into velocity first, then position with the new velocity).
    substeps: each step is split into this many sub-steps of dt / substeps.
    solver: "seed" (one pass, the seed's impulse formula per contact) or "sequential"
        (iterative sequential impulses with accumulated, clamped impulses).
    iterations: velocity iterations of the sequential solver (1 for "seed").
    warm_starting: start the sequential solver from the previous step's impulses.
    contact_points: 1 (the seed's single point per pair) or 2 (clipped two-point manifolds).
    position_correction: "full" (the seed's whole MTD push), "partial" (push
        ``correction * (depth - slop)``) or "none".
    slop: penetration (m) left uncorrected by "partial".
    correction: fraction of (depth - slop) pushed out per step by "partial", in (0, 1].
    position_iterations: passes of the push-out over all pairs, each pushing only the depth the
        earlier passes left (1 is the seed's single push).
    restitution_rule: how two bodies' restitutions combine per contact: "max", "min", "mean",
        "product".
    restitution_threshold: approach speed (m/s) below which a contact does not bounce.
    friction: whether Coulomb friction is on at all.
    friction_rule: how two bodies' friction coefficients combine: "sqrt" (geometric mean),
        "min", "max", "mean", "product".
    ccd: "off" or "speculative" (speculative contacts against fast approach).
    axis_hysteresis: keep the previous step's separating axis for a pair while it is within a
        small tolerance of the best one, so near-ties do not flip the normal.
    """

    gravity: tuple[float, float] = (0.0, -9.81)
    dt: float = 0.01
    steps: int = 500
    fidelity: str = DEFAULT_PRESET
    integrator: str = "semi_implicit"
    substeps: int = 1
    solver: str = "sequential"
    iterations: int = 10
    warm_starting: bool = True
    contact_points: int = 2
    position_correction: str = "partial"
    slop: float = 0.005
    correction: float = 0.8
    position_iterations: int = 3
    restitution_rule: str = "max"
    restitution_threshold: float = 1.0
    friction: bool = False
    friction_rule: str = "sqrt"
    ccd: str = "speculative"
    axis_hysteresis: bool = True


@dataclass(frozen=True)
class BodySpec:
    """One body as the scene gives it (generators already expanded).

    name: unique name.
    vertices: polygon vertices (m) exactly as given (box / regular shapes already turned into
        vertices), counter-clockwise, 3..50 of them, convex. Not yet re-centred: the world builder
        re-centres them on their centroid (the seed's LocalSpaceList is relative to the centre of
        mass), so the same BodySpec always gives the same bits.
    position: world position of the centre of mass (m).
    angle: rad, counter-clockwise.
    velocity: m/s, world frame.
    angular_velocity: rad/s, counter-clockwise.
    density: kg/m^2 (mass = area * density).
    restitution: e in [0, 1].
    friction: Coulomb coefficient >= 0 (used only when the world's friction is on).
    concrete: immovable (infinite mass and inertia), the seed's IsConcrete.
    enters_at: time (s) from which the body exists (the seed's Exist).
    leaves_at: time (s) at which the body stops existing, or None.
    """

    name: str
    vertices: tuple[tuple[float, float], ...]
    position: tuple[float, float] = (0.0, 0.0)
    angle: float = 0.0
    velocity: tuple[float, float] = (0.0, 0.0)
    angular_velocity: float = 0.0
    density: float = 1.0
    restitution: float = 0.0
    friction: float = 0.5
    concrete: bool = False
    enters_at: float = 0.0
    leaves_at: float | None = None


@dataclass(frozen=True)
class Scene:
    """A validated scene: world settings and bodies, every generator expanded.

    name: the scene's name (from the file, or its stem).
    source: where it came from (path or "<text>"), for messages.
    analytic: optional analytic reference the scene declares (used by `isaac tradeoff`), or None.
    """

    name: str
    world: WorldSettings
    bodies: tuple[BodySpec, ...]
    source: str = "<scene>"
    analytic: dict | None = None


# ---------------------------------------------------------------------------------------------
# Loading: YAML text -> node tree (with line marks) -> checked values -> Scene.
#
# We never let PyYAML construct Python objects: we compose the node tree with a SafeLoader that
# refuses anchors, aliases and explicit tags, then read every scalar ourselves. That is how we get
# line numbers in every message, refuse duplicate keys (PyYAML keeps the last one silently), read
# `1e3` as a number (YAML 1.1 reads it as a string) and keep `off`/`no`/`yes` as strings (YAML 1.1
# reads them as booleans; only `true`/`false` are booleans here).
# ---------------------------------------------------------------------------------------------

MAX_SCENE_BYTES = 256 * 1024 * 1024  # a 100,000-body expanded scene is about 60 MB
MAX_COORDINATE = 1e9  # m: |position| and |vertex coordinate| bound (float64 keeps 1e-7 m there)
MIN_SIZE, MAX_SIZE = 1e-6, 1e6  # m: box sides, regular radius, polygon extent
MAX_SPEED = 1e6  # m/s and rad/s
MAX_TIME = 1e9  # s: enters_at / leaves_at
MAX_DENSITY = 1e9  # kg/m^2
MAX_FRICTION = 1e3
MAX_STEPS = 100_000_000
MAX_ITERATIONS = 1000
MAX_SUBSTEPS = 1000
MAX_GRAVITY = 1e4  # m/s^2 per component
MAX_NAME_LENGTH = 200

_INT_RE = re.compile(r"[-+]?[0-9]+\Z")
_FLOAT_RE = re.compile(r"[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?\Z")
_NONFINITE_RE = re.compile(r"[-+]?\.?(?:nan|inf|infinity)\Z", re.IGNORECASE)
_NULLS = ("null", "~", "")


class _RefuseAliases(yaml.composer.Composer):
    """A composer that refuses anchors, aliases and explicit tags.

    Aliases are refused outright rather than bounded: a "billion laughs" document composes in
    milliseconds but walking the result took 16.7 s and 1.6 GiB when measured.
    """

    def compose_node(self, parent, index):
        event = self.peek_event()
        if isinstance(event, yaml.AliasEvent):
            raise _Refused("YAML aliases (*name) are not allowed in a scene", event.start_mark)
        if getattr(event, "anchor", None) is not None:
            raise _Refused("YAML anchors (&name) are not allowed in a scene", event.start_mark)
        if getattr(event, "tag", None) not in (None, "!"):
            raise _Refused(f"YAML tags ({event.tag}) are not allowed in a scene",
                           event.start_mark)
        return super().compose_node(parent, index)

    def resolve(self, kind, value, implicit):
        # we read scalars ourselves (_scalar), so PyYAML's implicit typing is skipped: it is a
        # third of the load time of a large scene.
        if kind is yaml.ScalarNode:
            return "tag:yaml.org,2002:str"
        if kind is yaml.SequenceNode:
            return "tag:yaml.org,2002:seq"
        return "tag:yaml.org,2002:map"


class _NoAliasLoader(_RefuseAliases, yaml.SafeLoader):
    """Pure-Python scanner and parser, our composer."""


if getattr(yaml, "__with_libyaml__", False):
    class _FastNoAliasLoader(_RefuseAliases, yaml._yaml.CParser, yaml.constructor.SafeConstructor,
                             yaml.resolver.Resolver):
        """libyaml's scanner and parser (about 4x faster on a large expanded scene), our
        composer: same nodes, same marks, same refusals."""

        def __init__(self, stream) -> None:
            yaml._yaml.CParser.__init__(self, stream)
            _RefuseAliases.__init__(self)
            yaml.constructor.SafeConstructor.__init__(self)
            yaml.resolver.Resolver.__init__(self)

    _LOADER = _FastNoAliasLoader
else:
    _LOADER = _NoAliasLoader


class _Refused(Exception):
    def __init__(self, what: str, mark) -> None:
        self.what = what
        self.mark = mark


def _line(node) -> int:
    return node.start_mark.line + 1


def _join(path: str, key: str) -> str:
    return f"{path}.{key}" if path else key


def _describe(node) -> str:
    if isinstance(node, yaml.MappingNode):
        return "a mapping"
    if isinstance(node, yaml.SequenceNode):
        return "a list"
    value = _scalar(node)
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f"the string {node.value!r}"
    return f"the number {node.value}"


def _scalar(node):
    """Python value of a scalar node: None, bool, int, float (may be non-finite) or str."""
    text = node.value
    if node.style:  # quoted or block scalar: always a string (plain is None, or "" from libyaml)
        return text
    if text in _NULLS:
        return None
    if text == "true":
        return True
    if text == "false":
        return False
    if _INT_RE.match(text):
        if len(text) > 30:  # far out of every range, and int() refuses huge digit strings
            return math.copysign(math.inf, -1.0 if text.startswith("-") else 1.0)
        return int(text)
    if _FLOAT_RE.match(text) or _NONFINITE_RE.match(text):
        return float(text.replace(".nan", "nan").replace(".NaN", "nan").replace(".NAN", "nan")
                     .replace(".inf", "inf").replace(".Inf", "inf").replace(".INF", "inf"))
    return text


class _Reader:
    """Typed access to a composed node tree; every failure is a SceneError with line and path."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, what: str, node=None, path: str = "") -> SceneError:
        return SceneError(what, source=self.source, line=None if node is None else _line(node),
                          path=path)

    # containers
    def mapping(self, node, path: str, allowed) -> dict:
        """{key: (key node, value node)} in document order; refuses duplicates and unknown keys."""
        if not isinstance(node, yaml.MappingNode):
            raise self.fail(f"expected a mapping (key: value ...), got {_describe(node)}", node,
                            path)
        out: dict = {}
        for key_node, value_node in node.value:
            if not isinstance(key_node, yaml.ScalarNode):
                raise self.fail("keys must be plain names", key_node, path)
            key = key_node.value
            if key in out:
                raise self.fail(f"duplicate key {key!r} (first given at line "
                                f"{_line(out[key][0])})", key_node, _join(path, key))
            if allowed is not None and key not in allowed:
                close = difflib.get_close_matches(key, list(allowed), n=1, cutoff=0.6)
                hint = (f" (did you mean {close[0]!r}?)" if close
                        else f" (valid keys: {', '.join(allowed)})")
                raise self.fail(f"unknown key {key!r}{hint}", key_node, _join(path, key))
            out[key] = (key_node, value_node)
        return out

    def sequence(self, node, path: str, *, min_len: int = 0, max_len: int | None = None,
                 what: str = "items") -> list:
        if not isinstance(node, yaml.SequenceNode):
            raise self.fail(f"expected a list, got {_describe(node)}", node, path)
        n = len(node.value)
        if n < min_len:
            raise self.fail(f"expected at least {min_len} {what}, got {n}", node, path)
        if max_len is not None and n > max_len:
            raise self.fail(f"expected at most {max_len} {what}, got {n}", node, path)
        return node.value

    # scalars
    def number(self, node, path: str, lo: float, hi: float, *, lo_open: bool = False) -> float:
        value = _scalar(node) if isinstance(node, yaml.ScalarNode) else node
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(f"expected a number, got {_describe(node)}", node, path)
        if isinstance(value, float) and math.isnan(value):
            raise self.fail("NaN is not allowed (numbers must be finite)", node, path)
        if isinstance(value, float) and math.isinf(value) and _NONFINITE_RE.match(node.value):
            raise self.fail("infinity is not allowed (numbers must be finite)", node, path)
        value = float(value) if math.isfinite(value) else value
        if not (value > lo if lo_open else value >= lo) or not value <= hi:
            low = f"> {lo!r}" if lo_open else f">= {lo!r}"
            raise self.fail(f"{node.value} is out of range (must be {low} and <= {hi!r})",
                            node, path)
        return value

    def integer(self, node, path: str, lo: int, hi: int) -> int:
        value = _scalar(node) if isinstance(node, yaml.ScalarNode) else None
        if isinstance(value, float) and math.isinf(value) and _INT_RE.match(node.value):
            raise self.fail(f"{node.value} is out of range (must be {lo}..{hi})", node, path)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(f"expected a whole number, got {_describe(node)}", node, path)
        if not lo <= value <= hi:
            raise self.fail(f"{value} is out of range (must be {lo}..{hi})", node, path)
        return value

    def boolean(self, node, path: str) -> bool:
        value = _scalar(node) if isinstance(node, yaml.ScalarNode) else None
        if not isinstance(value, bool):
            raise self.fail(f"expected true or false, got {_describe(node)}", node, path)
        return value

    def string(self, node, path: str) -> str:
        value = _scalar(node) if isinstance(node, yaml.ScalarNode) else None
        if not isinstance(value, str):
            raise self.fail(f"expected a string, got {_describe(node)}", node, path)
        return value

    def name(self, node, path: str) -> str:
        value = _scalar(node) if isinstance(node, yaml.ScalarNode) else None
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            value = node.value  # `name: 7` is the name "7"
        else:
            value = self.string(node, path)
        if not value or len(value) > MAX_NAME_LENGTH or not value.isprintable():
            raise self.fail(f"a name must be 1 to {MAX_NAME_LENGTH} printable characters, got "
                            f"{value[:40]!r}", node, path)
        return value

    def choice(self, node, path: str, options) -> str:
        value = _scalar(node) if isinstance(node, yaml.ScalarNode) else None
        if not isinstance(value, str) or value not in options:
            shown = node.value if isinstance(node, yaml.ScalarNode) else _describe(node)
            close = difflib.get_close_matches(str(shown), list(options), n=1, cutoff=0.6)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise self.fail(f"{shown!r} is not one of {', '.join(options)}{hint}", node, path)
        return value

    def pair(self, node, path: str, lo: float, hi: float, *, lo_open: bool = False
             ) -> tuple[float, float]:
        items = self.sequence(node, path, min_len=2, max_len=2, what="numbers")
        return (self.number(items[0], f"{path}[0]", lo, hi, lo_open=lo_open),
                self.number(items[1], f"{path}[1]", lo, hi, lo_open=lo_open))

    def plain(self, node, path: str, depth: int = 0):
        """Free-form data (the `analytic` block): mappings, lists, finite numbers, booleans and
        strings."""
        if depth > 16:
            raise self.fail("nested too deeply", node, path)
        if isinstance(node, yaml.MappingNode):
            return {key: self.plain(v, _join(path, key), depth + 1)
                    for key, (_, v) in self.mapping(node, path, None).items()}
        if isinstance(node, yaml.SequenceNode):
            return [self.plain(v, f"{path}[{i}]", depth + 1) for i, v in enumerate(node.value)]
        value = _scalar(node)
        if isinstance(value, float) and not math.isfinite(value):
            raise self.fail("numbers must be finite", node, path)
        return value


def _optional(reader_fn, m: dict, key: str, path: str, default, *args, **kwargs):
    if key not in m:
        return default
    return reader_fn(m[key][1], _join(path, key), *args, **kwargs)


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


def _world_value(r: _Reader, key: str, node, path: str):
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


def _read_world(r: _Reader, node) -> WorldSettings:
    if node is None:
        m = {}
    else:
        m = r.mapping(node, "world", _WORLD_FIELDS)
    fidelity = _optional(r.choice, m, "fidelity", "world", DEFAULT_PRESET, tuple(PRESETS))
    # resolution: dataclass defaults, then the preset, then every explicit key.
    values = {f.name: f.default for f in dataclasses.fields(WorldSettings)}
    values.update(PRESETS[fidelity])
    values["fidelity"] = fidelity
    for key, (_, value_node) in m.items():
        if key != "fidelity":
            values[key] = _world_value(r, key, value_node, _join("world", key))
    return WorldSettings(**values)


# --- bodies ---------------------------------------------------------------------------------

_BODY_KEYS = ("name", "shape", "position", "angle", "velocity", "angular_velocity", "density",
              "restitution", "friction", "concrete", "enters_at", "leaves_at")


def _vertices_tuple(v) -> tuple[tuple[float, float], ...]:
    return tuple((float(x), float(y)) for x, y in v)


def _read_shape(r: _Reader, node, path: str) -> tuple[tuple[float, float], ...]:
    from isaac import polygon  # here, not at the top: polygon imports this module's constants

    m = r.mapping(node, path, ("box", "polygon", "regular"))
    if len(m) != 1:
        raise r.fail("give exactly one of box, polygon, regular", node, path)
    kind, (_, value) = next(iter(m.items()))
    path = _join(path, kind)
    if kind == "box":
        width, height = r.pair(value, path, MIN_SIZE, MAX_SIZE)
        return _vertices_tuple(polygon.box_vertices(width, height))
    if kind == "regular":
        p = r.mapping(value, path, ("sides", "radius", "phase"))
        for key in ("sides", "radius"):
            if key not in p:
                raise r.fail(f"missing key {key!r}", value, path)
        sides = r.integer(p["sides"][1], _join(path, "sides"), 3, MAX_VERTICES)
        radius = r.number(p["radius"][1], _join(path, "radius"), MIN_SIZE, MAX_SIZE)
        phase = _optional(r.number, p, "phase", path, 0.0, -MAX_SPEED, MAX_SPEED)
        return _vertices_tuple(polygon.regular_vertices(sides, radius, phase))
    items = r.sequence(value, path, min_len=3, max_len=MAX_VERTICES, what="vertices")
    raw = [r.pair(item, f"{path}[{i}]", -MAX_COORDINATE, MAX_COORDINATE)
           for i, item in enumerate(items)]
    try:
        ccw = polygon.validate_polygon(raw)
    except ValueError as exc:
        raise r.fail(str(exc), value, path) from None
    extent = float(math.hypot(*(ccw.max(axis=0) - ccw.min(axis=0))))
    if not MIN_SIZE <= extent <= MAX_SIZE:
        raise r.fail(f"the polygon's extent {extent!r} m is outside [{MIN_SIZE!r}, {MAX_SIZE!r}]",
                     value, path)
    return _vertices_tuple(ccw)


def _read_body(r: _Reader, node, path: str, index: int) -> BodySpec:
    m = r.mapping(node, path, _BODY_KEYS)
    if "shape" not in m:
        raise r.fail("missing key 'shape'", node, path)
    name = _optional(r.name, m, "name", path, f"body/{index + 1}")
    enters_at = _optional(r.number, m, "enters_at", path, 0.0, 0.0, MAX_TIME)
    leaves_at = None
    if "leaves_at" in m and _scalar_or_none(m["leaves_at"][1]) is not None:
        leaves_path = _join(path, "leaves_at")
        leaves_at = r.number(m["leaves_at"][1], leaves_path, 0.0, MAX_TIME)
        if leaves_at <= enters_at:
            raise r.fail(f"leaves_at ({leaves_at!r} s) must be later than enters_at "
                         f"({enters_at!r} s)", m["leaves_at"][1], leaves_path)
    return BodySpec(
        name=name,
        vertices=_read_shape(r, m["shape"][1], _join(path, "shape")),
        position=_optional(r.pair, m, "position", path, (0.0, 0.0), -MAX_COORDINATE,
                           MAX_COORDINATE),
        angle=_optional(r.number, m, "angle", path, 0.0, -MAX_SPEED, MAX_SPEED),
        velocity=_optional(r.pair, m, "velocity", path, (0.0, 0.0), -MAX_SPEED, MAX_SPEED),
        angular_velocity=_optional(r.number, m, "angular_velocity", path, 0.0, -MAX_SPEED,
                                   MAX_SPEED),
        density=_optional(r.number, m, "density", path, 1.0, 0.0, MAX_DENSITY, lo_open=True),
        restitution=_optional(r.number, m, "restitution", path, 0.0, 0.0, 1.0),
        friction=_optional(r.number, m, "friction", path, 0.5, 0.0, MAX_FRICTION),
        concrete=_optional(r.boolean, m, "concrete", path, False),
        enters_at=enters_at,
        leaves_at=leaves_at,
    )


def _scalar_or_none(node):
    return _scalar(node) if isinstance(node, yaml.ScalarNode) else node


# --- generators -----------------------------------------------------------------------------

_PYRAMID_KEYS = ("rows", "box", "base", "spacing", "density", "restitution", "friction", "name",
                 "ground")
_PILE_KEYS = ("count", "seed", "sides", "radius", "container", "density", "restitution",
              "friction", "name")
_CONTAINER_KEYS = ("width", "height", "thickness", "position")
MAX_PYRAMID_ROWS = 446  # 446 * 447 / 2 = 99,681 boxes: the largest pyramid under MAX_BODIES


def _material(r: _Reader, m: dict, path: str) -> dict:
    return dict(
        density=_optional(r.number, m, "density", path, 1.0, 0.0, MAX_DENSITY, lo_open=True),
        restitution=_optional(r.number, m, "restitution", path, 0.0, 0.0, 1.0),
        friction=_optional(r.number, m, "friction", path, 0.5, 0.0, MAX_FRICTION),
    )


def _require(r: _Reader, m: dict, keys, node, path: str) -> None:
    for key in keys:
        if key not in m:
            raise r.fail(f"missing key {key!r}", node, path)


def _read_pyramid(r: _Reader, node, path: str) -> tuple[dict, int]:
    m = r.mapping(node, path, _PYRAMID_KEYS)
    _require(r, m, ("rows", "box"), node, path)
    rows = r.integer(m["rows"][1], _join(path, "rows"), 1, MAX_PYRAMID_ROWS)
    options = dict(
        rows=rows,
        box=r.pair(m["box"][1], _join(path, "box"), MIN_SIZE, MAX_SIZE),
        base=_optional(r.pair, m, "base", path, (0.0, 0.0), -MAX_COORDINATE, MAX_COORDINATE),
        spacing=_optional(r.number, m, "spacing", path, 0.0, 0.0, MAX_SIZE),
        name=_optional(r.name, m, "name", path, "pyramid"),
        ground=_optional(r.boolean, m, "ground", path, True),
        **_material(r, m, path),
    )
    return options, rows * (rows + 1) // 2 + 1


def _read_pile(r: _Reader, node, path: str) -> tuple[dict, int]:
    m = r.mapping(node, path, _PILE_KEYS)
    _require(r, m, ("count",), node, path)
    count = r.integer(m["count"][1], _join(path, "count"), 1, MAX_BODIES)
    sides = (3, 8)
    if "sides" in m:
        sides_path = _join(path, "sides")
        items = r.sequence(m["sides"][1], sides_path, min_len=2, max_len=2, what="numbers")
        sides = (r.integer(items[0], f"{sides_path}[0]", 3, MAX_VERTICES),
                 r.integer(items[1], f"{sides_path}[1]", 3, MAX_VERTICES))
        if sides[0] > sides[1]:
            raise r.fail("min sides is greater than max sides", m["sides"][1], sides_path)
    radius = _optional(r.pair, m, "radius", path, (0.2, 0.5), MIN_SIZE, MAX_SIZE)
    if radius[0] > radius[1]:
        raise r.fail("min radius is greater than max radius", m["radius"][1],
                     _join(path, "radius"))
    container = {}
    if "container" in m:
        cpath = _join(path, "container")
        c = r.mapping(m["container"][1], cpath, _CONTAINER_KEYS)
        container = dict(
            width=_optional(r.number, c, "width", cpath, 10.0, MIN_SIZE, MAX_SIZE),
            height=_optional(r.number, c, "height", cpath, None, MIN_SIZE, MAX_COORDINATE),
            thickness=_optional(r.number, c, "thickness", cpath, 0.5, MIN_SIZE, MAX_SIZE),
            position=_optional(r.pair, c, "position", cpath, (0.0, 0.0), -MAX_COORDINATE,
                               MAX_COORDINATE),
        )
    options = dict(
        count=count,
        seed=_optional(r.integer, m, "seed", path, 0, 0, 2**63 - 1),
        sides=sides,
        radius=radius,
        name=_optional(r.name, m, "name", path, "pile"),
        **container,
        **_material(r, m, path),
    )
    return options, count + 3


def _expand_generator(r: _Reader, node, path: str, room: int) -> list[BodySpec]:
    from isaac import generators  # here: generators imports BodySpec from this module

    m = r.mapping(node, path, ("pyramid", "pile"))
    if len(m) != 1:
        raise r.fail("each generator has exactly one key: pyramid or pile", node, path)
    kind, (_, options_node) = next(iter(m.items()))
    path = _join(path, kind)
    reader = _read_pyramid if kind == "pyramid" else _read_pile
    options, size = reader(r, options_node, path)
    if size > room:
        raise r.fail(f"this generator makes {size} bodies; with the others the scene would "
                     f"exceed {MAX_BODIES} bodies", options_node, path)
    try:
        return getattr(generators, kind)(**options)
    except generators.GeneratorError as exc:
        key_node = options_node
        head = exc.key.split(".")[0]
        options_map = r.mapping(options_node, path, None)
        if head in options_map:
            key_node = options_map[head][1]
        raise r.fail(exc.what, key_node, _join(path, exc.key)) from None


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
        line = data[:exc.start].count(b"\n") + 1
        raise SceneError(f"not UTF-8 text (byte 0x{data[exc.start]:02x} at offset {exc.start})",
                         source=source, line=line) from None
    return load_scene_text(text, source=source, default_name=p.stem)


def _compose(text: str, source: str):
    try:
        return yaml.compose(text, Loader=_LOADER)
    except _Refused as exc:
        raise SceneError(exc.what, source=source, line=exc.mark.line + 1) from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        what = " ".join(str(exc.problem or exc.context or "invalid YAML").split())
        line = None if mark is None else mark.line + 1
        if "nesting depth" in what:
            # PyYAML >= 6.0.3 bounds the depth itself; older ones end in RecursionError below:
            # the same message either way
            raise SceneError("the document is nested too deeply", source=source,
                             line=line) from None
        raise SceneError(f"YAML syntax error: {what}", source=source, line=line) from None
    except yaml.reader.ReaderError as exc:
        line = text[:exc.position].count("\n") + 1
        raise SceneError(f"character #x{exc.character:04x} is not allowed in YAML",
                         source=source, line=line) from None
    except yaml.YAMLError as exc:
        raise SceneError(f"YAML error: {' '.join(str(exc).split())}", source=source) from None
    except RecursionError:
        raise SceneError("the document is nested too deeply", source=source) from None


def load_scene_text(text: str, source: str = "<text>", *, default_name: str | None = None
                    ) -> Scene:
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
        root = _compose(text, source)
        if root is None:
            raise SceneError("the scene is empty (expected a mapping with `bodies:` or "
                             "`generators:`)", source=source, line=1)
        return _read_scene(_Reader(source), root, default_name or "scene")
    except RecursionError:
        raise SceneError("the document is nested too deeply", source=source) from None
    finally:
        if collecting:
            gc.enable()


def _read_scene(r: _Reader, root, default_name: str) -> Scene:
    m = r.mapping(root, "", _SCENE_KEYS)
    name = _optional(r.name, m, "name", "", default_name)
    world_node = m["world"][1] if "world" in m else None
    world = _read_world(r, None if _scalar_or_none(world_node) is None else world_node)
    bodies: list[BodySpec] = []
    origin: dict[str, tuple[str, int]] = {}  # name -> (key path, line) where it was made

    def add(spec: BodySpec, path: str, node) -> None:
        if spec.name in origin:
            first_path, first_line = origin[spec.name]
            raise r.fail(f"duplicate body name {spec.name!r} (already used by {first_path} at "
                         f"line {first_line})", node, path)
        origin[spec.name] = (path, _line(node))
        bodies.append(spec)

    if "bodies" in m and _scalar_or_none(m["bodies"][1]) is not None:
        items = r.sequence(m["bodies"][1], "bodies", max_len=MAX_BODIES, what="bodies")
        for i, item in enumerate(items):
            path = f"bodies[{i}]"
            spec = _read_body(r, item, path, i)
            name_node = item
            if isinstance(item, yaml.MappingNode):
                for key_node, value_node in item.value:
                    if key_node.value == "name":
                        name_node = value_node
            add(spec, _join(path, "name") if name_node is not item else path, name_node)
    if "generators" in m and _scalar_or_none(m["generators"][1]) is not None:
        items = r.sequence(m["generators"][1], "generators")
        for i, item in enumerate(items):
            path = f"generators[{i}]"
            for spec in _expand_generator(r, item, path, MAX_BODIES - len(bodies)):
                add(spec, path, item)
    if not bodies:
        raise r.fail("the scene has no bodies (give `bodies:` or `generators:`)", root)
    analytic = None
    if "analytic" in m and _scalar_or_none(m["analytic"][1]) is not None:
        if not isinstance(m["analytic"][1], yaml.MappingNode):
            raise r.fail(f"expected a mapping, got {_describe(m['analytic'][1])}",
                         m["analytic"][1], "analytic")
        analytic = r.plain(m["analytic"][1], "analytic")
    return Scene(name=name, world=world, bodies=tuple(bodies), source=r.source,
                 analytic=analytic)


# --- writing --------------------------------------------------------------------------------

def _yaml_value(value) -> str:
    """Flow-style YAML for a value this loader reads back identically (floats via repr)."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"cannot write the non-finite number {value!r}")
        return repr(value)
    if isinstance(value, str):
        # JSON's escapes are a subset of YAML double-quoted escapes; non-ASCII stays as is.
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, (tuple, list)):
        return "[" + ", ".join(_yaml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{json.dumps(str(k), ensure_ascii=False)}: {_yaml_value(v)}"
                               for k, v in value.items()) + "}"
    raise TypeError(f"cannot write {type(value).__name__} as scene YAML")


def scene_to_yaml(scene: Scene) -> str:
    """The expanded scene as YAML text: every world setting and every body explicit (generators
    already expanded, shapes as `polygon:` of the stored vertices), floats written with `repr`.

    ``load_scene_text(scene_to_yaml(s), source=s.source)`` equals `s` field by field, bit for
    bit (`source` is not part of the text: it says where a text came from).
    """
    lines = [f"name: {_yaml_value(scene.name)}", "world:"]
    for key in _WORLD_FIELDS:
        lines.append(f"  {key}: {_yaml_value(getattr(scene.world, key))}")
    lines.append("bodies:")
    for body in scene.bodies:
        lines.append(f"  - name: {_yaml_value(body.name)}")
        lines.append(f"    shape: {{polygon: {_yaml_value(body.vertices)}}}")
        for field in dataclasses.fields(BodySpec):
            if field.name not in ("name", "vertices"):
                lines.append(f"    {field.name}: {_yaml_value(getattr(body, field.name))}")
    if scene.analytic is not None:
        lines.append(f"analytic: {_yaml_value(scene.analytic)}")
    return "\n".join(lines) + "\n"
