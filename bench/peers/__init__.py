"""Engine adapters: each builds the same `isaac.scene.Scene` and exposes the same small surface.

An adapter has `name`, `settings` (a one-line statement of its solver settings for the table),
`step()`, `poses() -> (positions (n, 2), angles (n,))` and `velocities() -> (velocity (n, 2),
angular_velocity (n,))`, all in scene body order, positions being centres of mass (m).

`make_engine("pymunk" | "box2d" | "isaac-<preset>", scene)`; peers are optional dependencies
(`pip install .[bench]`), so an adapter is imported only when asked for.
"""

from __future__ import annotations

from isaac.scene import Scene

PEERS = ("pymunk", "box2d")


def make_engine(name: str, scene: Scene):
    if name == "pymunk":
        from bench.peers.pymunk_engine import PymunkEngine

        return PymunkEngine(scene)
    if name == "box2d":
        from bench.peers.box2d_engine import Box2DEngine

        return Box2DEngine(scene)
    if name.startswith("isaac"):
        from bench.peers.isaac_engine import IsaacEngine

        preset, _, mode = (name.partition("-")[2] or "").partition("/")
        return IsaacEngine(scene, preset=preset or None, mode=mode or "step")
    raise ValueError(f"unknown engine {name!r}")


def engine_available(name: str) -> tuple[bool, str]:
    """(available, reason if not) without building anything."""
    import importlib

    module = {"pymunk": "pymunk", "box2d": "Box2D"}.get(name)
    try:
        if module is not None:
            importlib.import_module(module)
        elif name.startswith("isaac"):
            importlib.import_module("isaac.engine.simulation").Simulation  # noqa: B018
        else:
            return False, f"unknown engine {name!r}"
    except (ImportError, AttributeError) as exc:
        return False, f"{type(exc).__name__}: {exc}"
    return True, ""
