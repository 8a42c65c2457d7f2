"""Engine adapters: each builds the same `isaac.scene.Scene` and exposes the same small surface.

An adapter has `name`, `settings` (a one-line statement of its solver settings for the table),
`step()`, `poses() -> (positions (n, 2), angles (n,))` and `velocities() -> (velocity (n, 2),
angular_velocity (n,))`, all in scene body order, positions being centres of mass (m).

`make_engine("pymunk" | "box2d" | "box2d-v3" | "isaac-<preset>", scene)`; peers are optional
dependencies (`pip install .[bench]`), so an adapter is imported only when asked for.

Box2D v3 (`box2d-v3`, bench/peers/box2d_v3.py) is built from a source the user names and runs
a whole scene in its own compiled process (OWN_PROCESS): its adapter has
`run_scene(warmup_steps, timed_steps)` (the timing figures) and `start()` in place of `step()`.
"""

from __future__ import annotations

from isaac.scene import Scene

PEERS = ("pymunk", "box2d", "box2d-v3")
# engines that run a whole scene in a compiled process of their own (no step() from Python)
OWN_PROCESS = ("box2d-v3",)


def make_engine(name: str, scene: Scene):
    if name == "pymunk":
        from bench.peers.pymunk_engine import PymunkEngine

        return PymunkEngine(scene)
    if name == "box2d":
        from bench.peers.box2d_engine import Box2DEngine

        return Box2DEngine(scene)
    if name == "box2d-v3":
        from bench.peers.box2d_v3 import Box2DV3Engine

        return Box2DV3Engine(scene)
    if name.startswith("isaac"):
        from bench.peers.isaac_engine import IsaacEngine

        preset, _, mode = (name.partition("-")[2] or "").partition("/")
        return IsaacEngine(scene, preset=preset or None, mode=mode or "step")
    raise ValueError(f"unknown engine {name!r}")


def engine_available(name: str) -> tuple[bool, str]:
    """(available, reason if not) without building anything (Box2D v3: whether a source is
    named by ISAAC_BOX2D_V3; the suite also takes `--box2d-v3 SRC`)."""
    import importlib

    if name == "box2d-v3":
        from bench.peers.box2d_v3 import NO_SOURCE_NOTE, source_from

        return (True, "") if source_from(None) is not None else (False, NO_SOURCE_NOTE)

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
