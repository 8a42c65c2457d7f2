"""The scene contract: YAML scene files (docs/scene-format.md) read into a validated `Scene`.

Holds the YAML reader with line marks (`reader`), the limits every value is checked against
(`limits`), world settings, fidelity presets and the reading of `world:` (`settings`), the
validated scene and bodies (`spec`), polygons and their mass properties (`polygon`), the
reading of `bodies:` (`bodies`), of `joints:` (`joints`) and of `generators:` with the bodies
they expand into at load time (`generators`), the checks every expanded body passes
(`checks`), loading a scene file or text by those readers (`loader`), the round trip back to
YAML (`writer`) and its fast reader (`fast_reader`), and the warnings about a valid scene the
engine is not measured to handle (`warnings`).

May import: the standard library, numpy, PyYAML and `isaac.errors`. Never numba, the engine,
the recorder, replay or the app: a scene is plain data that the engine is built from.
"""

from __future__ import annotations

from isaac.scene.limits import MAX_BODIES, MAX_VERTICES
from isaac.scene.loader import load_scene, load_scene_text
from isaac.scene.settings import DEFAULT_PRESET, PRESETS, WorldSettings
from isaac.scene.spec import BodySpec, Scene
from isaac.scene.writer import scene_to_yaml

__all__ = [
    "DEFAULT_PRESET",
    "MAX_BODIES",
    "MAX_VERTICES",
    "PRESETS",
    "BodySpec",
    "Scene",
    "WorldSettings",
    "load_scene",
    "load_scene_text",
    "scene_to_yaml",
]
