"""The round trip: a `Scene` written back as scene YAML that loads to the same bits."""

from __future__ import annotations

import dataclasses
import json
import math
import operator
import re

from isaac.scene.reader import fraction
from isaac.scene.settings import WorldSettings
from isaac.scene.spec import BodySpec, JointSpec, Scene

_WORLD_FIELDS = tuple(f.name for f in dataclasses.fields(WorldSettings))

# Characters JSON leaves as they are but YAML may not read back as themselves inside a
# double-quoted scalar: C1 controls and DEL (refused), NEL, LS, PS (line breaks, folded), the
# byte order mark and non-characters (refused by libyaml), lone surrogates (not UTF-8).
_YAML_UNSAFE = re.compile("[\x7f-\x9f\u2028\u2029\ufeff\ufffe\uffff\ud800-\udfff]")


def _quoted(text: str) -> str:
    """`text` as a YAML double-quoted scalar that reads back as `text` (JSON's escapes are a
    subset of YAML's; non-ASCII stays as is, except what YAML would not keep)."""
    return _YAML_UNSAFE.sub(
        lambda m: f"\\u{ord(m.group()):04x}", json.dumps(text, ensure_ascii=False)
    )


def _yaml_value(value) -> str:
    """Flow-style YAML for a value this loader reads back identically (floats via repr)."""
    if type(value) is float and value - value == 0.0:  # finite: the common case, first
        return repr(value)
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
        return _quoted(value)
    if isinstance(value, (tuple, list)):
        return "[" + ", ".join(map(_yaml_value, value)) + "]"
    if isinstance(value, dict):
        return (
            "{" + ", ".join(f"{_quoted(str(k))}: {_yaml_value(v)}" for k, v in value.items()) + "}"
        )
    raise TypeError(f"cannot write {type(value).__name__} as scene YAML")


def _value(value, written: dict, path: str) -> str:
    """`value` as the author wrote it at `path` if they wrote a fraction that is still exactly
    this value (a scene changed with dataclasses.replace may hold another), else as repr."""
    text = written.get(path)
    if text is not None and value == fraction(text):
        return text
    return _yaml_value(value)


# the collision filter's fields, written only for a body whose filter is not the default (so the
# text of every scene without filters, and every log of one, is what it was before filters)
_FILTER_FIELDS = ("category", "mask", "group")
# every other field of a body after its name and shape, in the order the fast reader expects
_BODY_FIELDS = tuple(
    f.name
    for f in dataclasses.fields(BodySpec)
    if f.name not in ("name", "vertices", "circle", *_FILTER_FIELDS)
)


def _shape(body: BodySpec) -> str:
    if body.circle is not None:
        return f"    shape: {{circle: {{radius: {_yaml_value(body.circle)}}}}}"
    return f"    shape: {{polygon: {_yaml_value(body.vertices)}}}"


def scene_to_yaml(scene: Scene) -> str:
    """The expanded scene as YAML text: every world setting and every body explicit (generators
    already expanded, shapes as `polygon:` of the stored vertices or `circle:`), floats written
    with `repr`; a body's collision filter only when it is not the default; the joints (none:
    no `joints:` line) each in its bodies' frames with every value it uses.

    ``load_scene_text(scene_to_yaml(s), source=s.source)`` equals `s` field by field, bit for
    bit (`source` is not part of the text: it says where a text came from), and writes the same
    text again. Times given as fractions are written as given (`dt: 1/120`). The loader reads
    this exact form line by line (isaac.scene.fast_reader), in a few seconds for 100,000 bodies.
    """
    # times the author wrote as fractions are written as they wrote them (Scene.as_written)
    written = dict(scene.as_written)
    body_written = any(path.startswith("bodies[") for path in written)
    lines = [f"name: {_yaml_value(scene.name)}", "world:"]
    for key in _WORLD_FIELDS:
        lines.append(f"  {key}: {_value(getattr(scene.world, key), written, f'world.{key}')}")
    lines.append("bodies:")
    add = lines.append
    fields = [(f"    {name}: ", operator.attrgetter(name)) for name in _BODY_FIELDS]
    for index, body in enumerate(scene.bodies):
        add(f"  - name: {_yaml_value(body.name)}")
        add(_shape(body))
        if body_written:
            for (head, get), name in zip(fields, _BODY_FIELDS):
                add(head + _value(get(body), written, f"bodies[{index}].{name}"))
        else:
            for head, get in fields:
                add(head + _yaml_value(get(body)))
        if body.filtered:
            for name in _FILTER_FIELDS:
                add(f"    {name}: {getattr(body, name)}")
    if scene.joints:
        lines.append("joints:")
        names = [body.name for body in scene.bodies]
        for joint in scene.joints:
            lines.extend(_joint_lines(joint, names))
    if scene.analytic is not None:
        lines.append(f"analytic: {_yaml_value(scene.analytic)}")
    return "\n".join(lines) + "\n"


def _number(value) -> str:
    return _yaml_value(float(value))


def _joint_lines(joint: JointSpec, names) -> list[str]:
    """One joint, fully explicit in its bodies' frames (`frame: body`), every key in the order
    the fast reader expects; a key the joint does not use, or an option it leaves out, is not
    written."""
    j = joint
    lines = [
        f"  - name: {_yaml_value(j.name)}",
        f"    type: {j.kind}",
        f"    bodies: [{_yaml_value(names[j.a])}, {_yaml_value(names[j.b])}]",
        "    frame: body",
        f"    anchor_a: [{_number(j.local_a[0])}, {_number(j.local_a[1])}]",
        f"    anchor_b: [{_number(j.local_b[0])}, {_number(j.local_b[1])}]",
    ]
    if j.kind == "prismatic":
        lines.append(f"    axis: [{_number(j.axis[0])}, {_number(j.axis[1])}]")
    lines.append(f"    reference_angle: {_number(j.reference_angle)}")
    if j.kind == "distance":
        lines.append(f"    length: {_number(j.length)}")
        for key in ("min_length", "max_length"):
            if getattr(j, key) is not None:
                lines.append(f"    {key}: {_number(getattr(j, key))}")
    if j.kind in ("distance", "weld") and j.stiffness is not None:
        lines.append(f"    stiffness: {_number(j.stiffness)}")
        lines.append(f"    damping_ratio: {_number(j.damping_ratio)}")
    if j.kind in ("revolute", "prismatic"):
        if j.lower is not None:
            lines.append(f"    limits: [{_number(j.lower)}, {_number(j.upper)}]")
        if j.motor_speed is not None:
            most = "max_torque" if j.kind == "revolute" else "max_force"
            lines.append(
                f"    motor: {{speed: {_number(j.motor_speed)}, {most}: {_number(j.max_motor)}}}"
            )
    lines.append(f"    collide_connected: {_yaml_value(j.collide_connected)}")
    return lines
