"""The round trip: a `Scene` written back as scene YAML that loads to the same bits."""

from __future__ import annotations

import dataclasses
import json
import math

from isaac.scene.settings import WorldSettings
from isaac.scene.spec import BodySpec, Scene

_WORLD_FIELDS = tuple(f.name for f in dataclasses.fields(WorldSettings))


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
        return (
            "{"
            + ", ".join(
                f"{json.dumps(str(k), ensure_ascii=False)}: {_yaml_value(v)}"
                for k, v in value.items()
            )
            + "}"
        )
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
