"""The round trip, as a property: for every scene text, either the loader refuses it in one line,
or what `scene_to_yaml` writes for the scene loads back to the same bits (what a log stores and
a replay loads). And the fast reader of that text agrees with the YAML reader on any text.

Scenes are generated with values at and beyond every limit: sizes, coordinates, far positions,
tiny and huge densities, names of the longest length, generator options; a few bodies each, so
the examples stay fast.
"""

from __future__ import annotations

import dataclasses
import math
import re
import struct
from contextlib import contextmanager
from unittest import mock

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from isaac.errors import SceneError
from isaac.scene import PRESETS, fast_reader, load_scene_text, scene_to_yaml
from isaac.scene.limits import (
    MAX_COORDINATE,
    MAX_DENSITY,
    MAX_NAME_LENGTH,
    MAX_SIZE,
    MAX_SPEED,
    MAX_TIME,
    MAX_VERTICES,
    MIN_SIZE,
)
from isaac.scene.writer import _yaml_value

SETTINGS = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _bits(value):
    """Every float of a (nested) value as its 64 bits, so -0.0 != 0.0 and 1 ULP counts."""
    if isinstance(value, float):
        return struct.pack("<d", value)
    if isinstance(value, (tuple, list)):
        return tuple(_bits(v) for v in value)
    if isinstance(value, dict):
        return tuple((k, _bits(v)) for k, v in value.items())
    if dataclasses.is_dataclass(value):
        # fields left out of comparison (Scene.marks: where the YAML said it) are not the scene
        fields = [f for f in dataclasses.fields(value) if f.compare]
        return tuple((f.name, _bits(getattr(value, f.name))) for f in fields)
    return value


@contextmanager
def _yaml_reader_only():
    with mock.patch.object(fast_reader, "read", lambda *args, **kwargs: None):
        yield


def _load(text: str):
    """The scene, or the (line, path) of the one-line SceneError."""
    try:
        return load_scene_text(text, source="s.yaml")
    except SceneError as exc:
        assert "\n" not in str(exc)
        return (exc.line, exc.path)


# --- values ---------------------------------------------------------------------------------


def _rarely(usual, rare):
    """`usual`, and about one time in 30 `rare`."""
    return st.integers(0, 29).flatmap(lambda k: rare if k == 7 else usual)


def _number(lo: float, hi: float):
    """Inside [lo, hi] (hypothesis tries both edges often), rarely just outside."""
    inside = st.floats(lo, hi, allow_nan=False, allow_infinity=False)
    outside = st.sampled_from([math.nextafter(lo, -math.inf), math.nextafter(hi, math.inf)])
    return _rarely(inside, outside)


sizes = _number(MIN_SIZE, MAX_SIZE)
coordinates = _number(-MAX_COORDINATE, MAX_COORDINATE)
speeds = _number(-MAX_SPEED, MAX_SPEED)
densities = _rarely(
    st.floats(1e-12, MAX_DENSITY),
    st.sampled_from([5e-324, 1e-310, 2.2250738585072014e-308, 1e-300, 1e-30]),
)
printable = st.characters(categories=("L", "N", "P", "S", "Zs"))
names = _rarely(
    st.one_of(
        st.text(printable, min_size=1, max_size=MAX_NAME_LENGTH),
        st.text(alphabet='ab"\\/ \u00e9\U0001f600', min_size=1, max_size=12),
        st.integers(MAX_NAME_LENGTH - 10, MAX_NAME_LENGTH).map(lambda n: "n" * n),
    ),
    st.one_of(
        st.text(min_size=1, max_size=12),
        st.just("n" * (MAX_NAME_LENGTH + 1)),
        st.text(alphabet="\u2028\x85\x7f\t", min_size=1, max_size=3),
    ),
)


def _flow(items: dict) -> str:
    return "{" + ", ".join(f"{k}: {v}" for k, v in items.items()) + "}"


def _pair(a, b) -> str:
    return f"[{_yaml_value(a)}, {_yaml_value(b)}]"


@st.composite
def polygons(draw) -> str:
    n = draw(st.integers(3, MAX_VERTICES))
    radius = draw(sizes)
    cx, cy = draw(coordinates), draw(coordinates)
    angles = sorted(draw(st.lists(st.floats(0.0, 2 * math.pi), min_size=n, max_size=n)))
    vertices = [(cx + radius * math.cos(a), cy + radius * math.sin(a)) for a in angles]
    if draw(st.booleans()):
        vertices.reverse()
    return "{polygon: [" + ", ".join(_pair(x, y) for x, y in vertices) + "]}"


shapes = st.one_of(
    st.builds(lambda w, h: f"{{box: {_pair(w, h)}}}", sizes, sizes),
    st.builds(
        lambda n, r, p: f"{{regular: {{sides: {n}, radius: {_yaml_value(r)}, phase: {p!r}}}}}",
        st.integers(3, MAX_VERTICES),
        sizes,
        st.floats(-10.0, 10.0),
    ),
    polygons(),
)


@st.composite
def bodies(draw) -> str:
    keys = {"shape": draw(shapes)}
    optional = {
        "name": names.map(_yaml_value),
        "position": st.builds(_pair, coordinates, coordinates),
        "angle": speeds.map(_yaml_value),
        "velocity": st.builds(_pair, speeds, speeds),
        "angular_velocity": speeds.map(_yaml_value),
        "density": densities.map(_yaml_value),
        "restitution": st.floats(0.0, 1.0).map(_yaml_value),
        "friction": st.floats(0.0, 10.0).map(_yaml_value),
        "concrete": st.booleans().map(_yaml_value),
    }
    for key, strategy in optional.items():
        if draw(st.booleans()):
            keys[key] = draw(strategy)
    enters_at = draw(st.floats(0.0, MAX_TIME))
    if draw(st.booleans()):
        keys["enters_at"] = _yaml_value(enters_at)
    if draw(st.booleans()):
        leaves_at = draw(st.one_of(st.none(), st.floats(enters_at, MAX_TIME)))
        keys["leaves_at"] = _yaml_value(leaves_at)
    return _flow(keys)


@st.composite
def pyramids(draw) -> str:
    keys = {"rows": str(draw(st.integers(1, 4))), "box": draw(st.builds(_pair, sizes, sizes))}
    optional = {
        "base": st.builds(_pair, coordinates, coordinates),
        "spacing": _number(0.0, MAX_SIZE).map(_yaml_value),
        "name": names.map(_yaml_value),
        "ground": st.booleans().map(_yaml_value),
        "density": densities.map(_yaml_value),
    }
    for key, strategy in optional.items():
        if draw(st.booleans()):
            keys[key] = draw(strategy)
    return "{pyramid: " + _flow(keys) + "}"


@st.composite
def piles(draw) -> str:
    keys = {"count": str(draw(st.integers(1, 6))), "seed": str(draw(st.integers(0, 2**63 - 1)))}
    low, high = sorted([draw(sizes), draw(sizes)])
    container = {
        "width": _number(MIN_SIZE, MAX_SIZE).map(_yaml_value),
        "height": st.one_of(st.none(), sizes).map(_yaml_value),
        "thickness": sizes.map(_yaml_value),
        "position": st.builds(_pair, coordinates, coordinates),
    }
    optional = {
        "radius": st.just(_pair(low, high)),
        "sides": st.sampled_from(["[3, 3]", "[3, 8]", "[50, 50]", "[8, 3]"]),
        "name": names.map(_yaml_value),
        "density": densities.map(_yaml_value),
        "container": st.fixed_dictionaries({}, optional={k: v for k, v in container.items()}).map(
            _flow
        ),
    }
    for key, strategy in optional.items():
        if draw(st.booleans()):
            keys[key] = draw(strategy)
    return "{pile: " + _flow(keys) + "}"


plain = st.recursive(
    st.one_of(
        st.none(),
        st.booleans(),
        st.integers(-(10**29), 10**29),
        st.floats(allow_nan=False, allow_infinity=False),
        st.text(max_size=8),
    ),
    lambda children: st.one_of(
        st.lists(children, max_size=3), st.dictionaries(st.text(max_size=6), children, max_size=3)
    ),
    max_leaves=8,
)


@st.composite
def scenes(draw) -> str:
    lines = []
    if draw(st.booleans()):
        lines.append(f"name: {_yaml_value(draw(names))}")
    world = {"fidelity": _yaml_value(draw(st.sampled_from(sorted(PRESETS))))}
    if draw(st.booleans()):
        world["dt"] = _yaml_value(draw(st.floats(1e-6, 1.0)))
    lines.append(f"world: {_flow(world)}")
    generators = draw(st.lists(st.one_of(pyramids(), piles()), max_size=2))
    items = draw(st.lists(bodies(), min_size=0 if generators else 1, max_size=3))
    if items:
        lines.append("bodies:")
        lines += [f"  - {item}" for item in items]
    if generators:
        lines.append("generators:")
        lines += [f"  - {item}" for item in generators]
    if draw(st.booleans()):
        lines.append(f"analytic: {_yaml_value(draw(st.dictionaries(st.text(max_size=6), plain)))}")
    return "\n".join(lines) + "\n"


# --- properties -----------------------------------------------------------------------------


@SETTINGS
@given(scenes())
def test_every_scene_that_loads_comes_back_bit_for_bit_from_its_written_text(text):
    scene = _load(text)
    if isinstance(scene, tuple):
        return  # refused, in one line
    written = scene_to_yaml(scene)
    again = load_scene_text(written, source=scene.source)
    assert _bits(again) == _bits(scene)
    assert scene_to_yaml(again) == written
    with _yaml_reader_only():  # the fast reader gave what the YAML reader gives
        assert _bits(load_scene_text(written, source=scene.source)) == _bits(scene)


MUTATIONS = [
    "1e3", "1", "-0", ".nan", ".inf", "null", "true", "'1.0'", "[1.0, 2.0]", "1.0 # note",
    "1.5e+400", "5e-324", "-1e-05", "1.0e+9", "1000000000.0000001", '"x"', "{a: 1}", "",
    "0.0\n    extra: 1", "1.0\n  - name: x",
]  # fmt: skip


@SETTINGS
@given(scenes(), st.data())
def test_the_fast_reader_and_the_yaml_reader_agree_on_any_change_to_a_written_scene(text, data):
    scene = _load(text)
    if isinstance(scene, tuple):
        return
    lines = scene_to_yaml(scene).split("\n")
    first_body = lines.index("bodies:") + 1
    i = data.draw(
        st.one_of(st.integers(first_body, len(lines) - 1), st.integers(0, len(lines) - 1))
    )
    how = data.draw(
        st.sampled_from(["number"] * 4 + ["name"] * 2 + ["value", "delete", "duplicate", "indent"])
    )
    line = lines[i]
    if how == "number":  # one float replaced by another: still the writer's form
        floats = [m for m in re.finditer(r"-?[0-9][-+.e0-9]*", line) if "." in m.group()]
        if floats:
            m = data.draw(st.sampled_from(floats))
            value = data.draw(st.one_of(st.floats(allow_nan=False), st.floats(-2e9, 2e9)))
            text = _yaml_value(value) if math.isfinite(value) else "1e+400"
            lines[i] = line[: m.start()] + text + line[m.end() :]
    elif how == "name":  # another body's name, or any name
        other = data.draw(st.sampled_from([b.name for b in scene.bodies]))
        name = data.draw(st.one_of(st.just(other), names))
        lines[i] = f"  - name: {_yaml_value(name)}" if "- name:" in line else line
    elif how == "value" and ": " in line:
        key, _, _ = line.partition(": ")
        lines[i] = f"{key}: {data.draw(st.sampled_from(MUTATIONS))}"
    elif how == "delete":
        del lines[i]
    elif how == "duplicate":
        lines.insert(i, line)
    elif how == "indent":
        lines[i] = " " + line
    changed = "\n".join(lines)
    fast = _load(changed)
    with _yaml_reader_only():
        slow = _load(changed)
    assert _bits(fast) == _bits(slow)
