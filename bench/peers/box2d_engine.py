"""Box2D 2.3.10 (pybox2d) built from an ISAAC scene.

Settings: 8 velocity and 3 position iterations, warm starting and time of impact against static
bodies (Box2D's defaults), sleeping switched off on every body (the world's doSleep flag is
ignored by this binding). Mixing: friction sqrt(a * b), restitution max (Box2D's own rules, the
same as ISAAC's defaults). Box2D keeps a 1 cm skin around polygons and caps a body's travel at
2 m per step (120 m/s at dt = 1/60).
"""

from __future__ import annotations

import Box2D
import numpy as np

from bench.geometry import local_vertices
from isaac.scene import Scene

SETTINGS = "8 velocity + 3 position iterations, no sleeping"


class Box2DEngine:
    name = "box2d"
    settings = SETTINGS

    def __init__(self, scene: Scene) -> None:
        self.dt = scene.world.dt
        world = Box2D.b2World(gravity=tuple(scene.world.gravity), doSleep=False)
        self.world = world
        self.bodies = []
        for spec in scene.bodies:
            kwargs = dict(position=tuple(spec.position), angle=spec.angle)
            if spec.concrete:
                body = world.CreateStaticBody(**kwargs)
            else:
                body = world.CreateDynamicBody(
                    **kwargs,
                    linearVelocity=tuple(spec.velocity),
                    angularVelocity=spec.angular_velocity,
                    allowSleep=False,
                    awake=True,
                )
            body.CreatePolygonFixture(
                vertices=local_vertices(spec.vertices),
                density=spec.density,
                friction=spec.friction if scene.world.friction else 0.0,
                restitution=spec.restitution,
            )
            if not spec.concrete:
                body.sleepingAllowed = False
            self.bodies.append(body)

    def step(self) -> None:
        self.world.Step(self.dt, 8, 3)

    def poses(self) -> tuple[np.ndarray, np.ndarray]:
        pos = np.array([tuple(b.worldCenter) for b in self.bodies])
        ang = np.array([b.angle for b in self.bodies])
        return pos.reshape(-1, 2), ang

    def velocities(self) -> tuple[np.ndarray, np.ndarray]:
        vel = np.array([tuple(b.linearVelocity) for b in self.bodies])
        return vel.reshape(-1, 2), np.array([b.angularVelocity for b in self.bodies])
