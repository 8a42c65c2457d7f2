"""ISAAC: a 2D rigid-body physics engine whose every step is recorded and can be replayed.

Scripting API (SI units, y up, angles counter-clockwise)::

    import isaac
    scene = isaac.load_scene("scenes/bounce.yaml")
    sim = isaac.Simulation(scene)
    for record in sim.run(100):          # isaac.StepRecord per step
        print(record.step, record.position[1], len(record.contacts))

Names are imported lazily so that `isaac check` and `isaac --help` do not load the compiled
kernels.
"""

from __future__ import annotations

__version__ = "0.1.0"

_EXPORTS = {
    "load_scene": "isaac.scene",
    "load_scene_text": "isaac.scene",
    "scene_to_yaml": "isaac.scene",
    "Scene": "isaac.scene",
    "BodySpec": "isaac.scene",
    "WorldSettings": "isaac.scene",
    "PRESETS": "isaac.scene",
    "Simulation": "isaac.engine.simulation",
    "BodyView": "isaac.engine.simulation",
    "StepRecord": "isaac.engine.records",
    "StepBatch": "isaac.engine.records",
    "Contacts": "isaac.engine.records",
    "IsaacError": "isaac.errors",
    "SceneError": "isaac.errors",
    "SimulationError": "isaac.errors",
    "LogError": "isaac.errors",
}

# modules of the public API, also imported on first use: isaac.sweep.run("sweep.yaml", out=...)
_MODULES = {"sweep": "isaac.app.sweep"}

__all__ = ["__version__", *_EXPORTS, *_MODULES]


def __dir__() -> list[str]:
    """The public names (imported on first use), for dir(isaac) and completion."""
    return sorted(__all__)


def __getattr__(name: str):
    import importlib

    if name in _MODULES:
        return importlib.import_module(_MODULES[name])
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'isaac' has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)
