"""Warnings about a valid scene that will not behave as its author expects: data, not errors.

`scene_warnings(scene)` returns one-line messages; the command line prints them (a scene that
warns still loads, runs and replays).

Mass ratio. A light body under a much heavier one is squeezed into what it rests on once the
ratio passes what the solver can hold (pymunk and Box2D 2.3 lose a 1000:1 stack within 0.5 s).
HELD_MASS_RATIO is, per preset, the largest heavy:light ratio measured to stay stacked:
scenes/mass_ratio.yaml (a heavy 1 m box on a light one on concrete ground, dt 1/60 s) run for
10 s, held meaning neither box moves more than 5 cm and no overlap passes 5 cm (the criterion
of tests/extremes/test_mass_ratio.py), with friction on and off alike. Measured:

    seed      holds 1.5 (2: 5.0 cm)          fast      holds 70 (100: 7.3 cm)
    balanced  holds 100 (150: 6.3 cm)        accurate  holds 2500 (3000: 5.2 cm)

The table keeps a margin below the edge for fast (50) and accurate (1000, the ratio the
stability suite asserts). At 1e9:1 the light box ends inside the concrete ground.
"""

from __future__ import annotations

from isaac.scene.checks import mass_properties
from isaac.scene.reader import shown
from isaac.scene.spec import Scene

HELD_MASS_RATIO = {"seed": 1.5, "fast": 50.0, "balanced": 100.0, "accurate": 1000.0}


def scene_warnings(scene: Scene) -> list[str]:
    """One line per thing in `scene` that the engine is not measured to handle well.

    Today: the ratio of the heaviest to the lightest movable (not concrete) body, when it
    exceeds HELD_MASS_RATIO for the scene's `world.fidelity` preset (keys given explicitly in
    `world:` are not taken into account).
    """
    movable = [i for i, b in enumerate(scene.bodies) if not b.concrete]
    if len(movable) < 2:
        return []
    masses = mass_properties([scene.bodies[i] for i in movable]).mass
    heavy, light = int(masses.argmax()), int(masses.argmin())
    ratio = float(masses[heavy] / masses[light])
    held = HELD_MASS_RATIO.get(scene.world.fidelity)
    if held is None or not ratio > held:
        return []
    return [
        f"{scene.source}: the mass ratio {ratio:.3g}:1 between "
        f"{shown(scene.bodies[movable[heavy]].name)} ({float(masses[heavy]):.3g} kg) and "
        f"{shown(scene.bodies[movable[light]].name)} ({float(masses[light]):.3g} kg) is beyond "
        f"the {held:g}:1 the {scene.world.fidelity!r} preset is measured to hold in a stack: a "
        "light body under a heavy one may be pushed into what it rests on "
        "(docs/scene-format.md, Warnings)"
    ]
