"""ISAAC itself behind the same adapter surface as the peers.

The world settings come from the preset named in the row (`isaac-fast`, `isaac-balanced`, ...);
dt, gravity, friction and steps stay the scene's. Modes (the row name's suffix,
`isaac-balanced/advance`):
- step (no suffix): `Simulation.step()` per step; its `StepRecord` is part of the timed cost, as it
  is for a user;
- run: the records of `Simulation.run(k)` (the compiled driver, 64 steps per call);
- advance: `Simulation.advance(k)`, no records (one compiled call).
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
    def __init__(self, scene: Scene, *, preset: str | None = None, mode: str = "step") -> None:
        if preset:
            scene = with_preset(scene, preset)
        self.mode = mode
        self.name = f"isaac-{scene.world.fidelity}" + ("" if mode == "step" else f"/{mode}")
        self.settings = describe(scene) + ("" if mode == "step" else f", {mode}")
        self.sim = Simulation(scene)
        self.last = None

    def step(self) -> None:
        self.last = self.sim.step()

    def block(self, steps: int) -> None:
        """`steps` steps the way this row's mode takes them."""
        if self.mode == "step":
            for _ in range(steps):
                self.last = self.sim.step()
        elif self.mode == "run":
            for record in self.sim.run(steps):
                self.last = record
        else:
            self.sim.advance(steps)
            self.last = None

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
