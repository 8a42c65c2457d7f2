"""Tiny inline scenes for the physics tests (built from the dataclasses, no YAML)."""

from __future__ import annotations

from isaac.scene import PRESETS, BodySpec, Scene, WorldSettings, validate
from isaac.scene.polygon import box_vertices


def world(preset: str = "seed", **overrides) -> WorldSettings:
    settings = dict(PRESETS[preset])
    settings.update(fidelity=preset, gravity=(0.0, 0.0), dt=0.01, steps=100)
    settings.update(overrides)
    return WorldSettings(**settings)


def box(name: str, width: float = 1.0, height: float = 1.0, **fields) -> BodySpec:
    vertices = tuple((float(x), float(y)) for x, y in box_vertices(width, height))
    return BodySpec(name=name, vertices=vertices, **fields)


def scene(*bodies: BodySpec, name: str = "inline", **world_fields) -> Scene:
    preset = world_fields.pop("preset", "seed")
    return Scene(name=name, world=world(preset, **world_fields), bodies=tuple(bodies))


def diverging() -> Scene:
    """Boxes in a free fall that passes the divergence bound (1e12 m) within a few steps
    (dt = 2e4 s: past the scene format's limit of 1 s, which the engine checks a Python-built
    scene against too; the scene is marked as checked, since the divergence check is what
    these tests are about)."""
    world = WorldSettings(**{**PRESETS["balanced"], "dt": 2e4, "steps": 50})
    box = ((-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5))
    bodies = (
        BodySpec("floor", box, concrete=True),
        BodySpec("resting", box, position=(3.0, 0.9)),
        BodySpec("anvil", box, position=(0.0, 0.9)),
    )
    return validate.remember(Scene("diverging", world, bodies))


# a blade turning on an axle through its centre, the axle's hub concrete: the blade's centre is
# inside the hub in every step, and the joint keeps the two from colliding
ROTOR = """name: rotor
world: {dt: 0.01, steps: 20}
bodies:
  - {name: hub, shape: {box: [0.3, 0.3]}, position: [0.0, 2.0], concrete: true}
  - {name: blade, shape: {box: [2.0, 0.1]}, position: [0.0, 2.0], angular_velocity: 3.0}
joints:
  - {name: axle, type: revolute, bodies: [hub, blade], anchor: [0.0, 2.0]}
"""

# a box whose mask leaves out the concrete ledge's category: it falls through, by design
LEDGE = """name: ledge
world: {dt: 0.01, steps: 60}
bodies:
  - {name: ledge, shape: {box: [4.0, 0.2]}, position: [0.0, 0.0], concrete: true, category: 0x2}
  - {name: ghost, shape: {box: [0.2, 0.2]}, position: [0.0, 1.0], mask: 0x1}
"""
