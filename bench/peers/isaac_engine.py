"""ISAAC itself behind the same adapter surface as the peers.

The world settings come from the preset named in the row (`isaac-fast`, `isaac-balanced`, ...);
dt, gravity, friction and steps stay the scene's. Every step returns a `StepRecord` (a private
copy of the state), and that copy is part of the timed cost, as it is for a user.
"""

from __future__ import annotations

import numpy as np

from bench.scenes import with_preset
from isaac.engine.simulation import Simulation
from isaac.scene import Scene


def describe(scene: Scene) -> str:
    w = scene.world
    position = getattr(w, "position_iterations", None)
    position_text = f" + {position} position" if position is not None else ""
    return (
        f"preset {w.fidelity}: {w.solver} {w.iterations} velocity{position_text} it, "
        f"{w.substeps} substep(s), {w.contact_points}-pt, ccd {w.ccd}"
    )


class IsaacEngine:
    def __init__(self, scene: Scene, *, preset: str | None = None) -> None:
        if preset:
            scene = with_preset(scene, preset)
        self.name = f"isaac-{scene.world.fidelity}"
        self.settings = describe(scene)
        self.sim = Simulation(scene)
        self.last = None

    def step(self) -> None:
        self.last = self.sim.step()

    def _record(self):
        if self.last is None:
            self.last = self.sim.record()
        return self.last

    def poses(self) -> tuple[np.ndarray, np.ndarray]:
        r = self._record()
        return np.asarray(r.position, float), np.asarray(r.angle, float)

    def velocities(self) -> tuple[np.ndarray, np.ndarray]:
        r = self._record()
        return np.asarray(r.velocity, float), np.asarray(r.angular_velocity, float)
