"""Inline scenes and measurements shared by the stability suite (tests/extremes)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from physics_helpers import box

from isaac.engine.diagnostics import kinetic_energy, potential_energy
from isaac.engine.simulation import Simulation
from isaac.scene import PRESETS, BodySpec, Scene
from isaac.scene.polygon import validate_polygon

PRESET_NAMES = ("seed", "fast", "balanced", "accurate")
G = 9.81  # m/s^2


def ground(width: float = 20.0, height: float = 1.0, top: float = 0.0, **fields) -> BodySpec:
    """A concrete box whose top surface is at y = `top`."""
    return box("ground", width, height, position=(0.0, top - height / 2), concrete=True, **fields)


def container(width: float, height: float, thickness: float = 0.5) -> list[BodySpec]:
    """A concrete floor (top at y = 0) and two walls; the inside spans x in [-width/2, width/2]."""
    half = width / 2 + thickness / 2
    return [
        box(
            "floor", width + 2 * thickness, thickness, position=(0.0, -thickness / 2), concrete=True
        ),
        box("left", thickness, height, position=(-half, height / 2), concrete=True),
        box("right", thickness, height, position=(half, height / 2), concrete=True),
    ]


def polygon(name: str, vertices, **fields) -> BodySpec:
    """A body from a convex outline (validated and made counter-clockwise like the loader)."""
    ccw = validate_polygon([[float(x), float(y)] for x, y in vertices])
    return BodySpec(name=name, vertices=tuple((float(x), float(y)) for x, y in ccw), **fields)


def regular_vertices(sides: int, radius: float, phase: float = 0.0) -> list[tuple[float, float]]:
    return [
        (
            radius * math.cos(phase + 2 * math.pi * k / sides),
            radius * math.sin(phase + 2 * math.pi * k / sides),
        )
        for k in range(sides)
    ]


def with_preset(scene: Scene, preset: str, **overrides) -> Scene:
    """The scene under another preset (the preset's settings replace the scene's)."""
    return replace(
        scene, world=replace(scene.world, fidelity=preset, **PRESETS[preset], **overrides)
    )


def shifted(scene: Scene, dx: float, dy: float) -> Scene:
    """The scene with every body moved by (dx, dy) metres."""
    return replace(
        scene,
        bodies=tuple(
            replace(b, position=(b.position[0] + dx, b.position[1] + dy)) for b in scene.bodies
        ),
    )


def energy(sim: Simulation, record) -> float:
    """Kinetic + potential energy (J, potential about y = 0) of the moving bodies."""
    g = sim.scene.world.gravity
    return kinetic_energy(sim.model, record) + potential_energy(sim.model, record, g)


@dataclass
class Trace:
    """What a run did, step by step: depth[k] is the largest penetration (m) of step k + 1."""

    depth: list[float] = field(default_factory=list)
    energy: list[float] = field(default_factory=list)
    position: list[np.ndarray] = field(default_factory=list)
    angle: list[np.ndarray] = field(default_factory=list)

    @property
    def max_depth(self) -> float:
        return max(self.depth, default=0.0)


def run(
    sim: Simulation, steps: int, *, keep_states: bool = False, keep_energy: bool = False
) -> Trace:
    """Step `sim` `steps` times, tracking depth (and optionally states and energy)."""
    trace = Trace()
    for _ in range(steps):
        rec = sim.step()
        trace.depth.append(float(rec.contacts.depth.max()) if len(rec.contacts) else 0.0)
        if keep_energy:
            trace.energy.append(energy(sim, rec))
        if keep_states:
            trace.position.append(rec.position)
            trace.angle.append(rec.angle)
    return trace


def assert_finite(sim: Simulation) -> None:
    s = sim.state
    for name, arr in (
        ("position", s.position),
        ("angle", s.angle),
        ("velocity", s.velocity),
        ("angular velocity", s.angular_velocity),
    ):
        assert np.all(np.isfinite(arr)), f"non-finite {name} after step {s.step}"
