"""pymunk 7 (Chipmunk2D) built from an ISAAC scene.

Settings: 10 iterations, collision slop 0.01 m (the scene is in SI units; pymunk's default 0.1
assumes pixels), no sleeping (sleep_time_threshold stays infinite), no damping.
Mixing: Chipmunk multiplies both shapes' friction and elasticity; each shape is given the square
root of its coefficient so a pair gets sqrt(a * b) (Box2D's and ISAAC's friction rule; for the
equal restitutions of these scenes also the "max" rule).
"""

from __future__ import annotations

import math

import numpy as np
import pymunk

from bench.geometry import local_vertices
from isaac.scene import Scene

SETTINGS = "10 iterations, slop 0.01 m, no sleeping"


class PymunkEngine:
    name = "pymunk"
    settings = SETTINGS

    def __init__(self, scene: Scene) -> None:
        self.dt = scene.world.dt
        space = pymunk.Space()
        space.gravity = tuple(scene.world.gravity)
        space.iterations = 10
        space.collision_slop = 0.01
        space.sleep_time_threshold = math.inf
        self.space = space
        self.bodies: list[pymunk.Body] = []
        for spec in scene.bodies:
            body_type = pymunk.Body.STATIC if spec.concrete else pymunk.Body.DYNAMIC
            body = pymunk.Body(body_type=body_type)
            body.position = tuple(spec.position)
            body.angle = spec.angle
            shape = pymunk.Poly(body, local_vertices(spec.vertices), radius=0.0)
            shape.density = spec.density
            shape.friction = math.sqrt(spec.friction) if scene.world.friction else 0.0
            shape.elasticity = math.sqrt(spec.restitution)
            space.add(body, shape)
            if not spec.concrete:
                body.velocity = tuple(spec.velocity)
                body.angular_velocity = spec.angular_velocity
            self.bodies.append(body)

    def step(self) -> None:
        self.space.step(self.dt)

    def poses(self) -> tuple[np.ndarray, np.ndarray]:
        pos = np.array([tuple(b.local_to_world(b.center_of_gravity)) for b in self.bodies])
        ang = np.array([b.angle for b in self.bodies])
        return pos.reshape(-1, 2), ang

    def velocities(self) -> tuple[np.ndarray, np.ndarray]:
        vel = np.array([tuple(b.velocity) for b in self.bodies])
        return vel.reshape(-1, 2), np.array([b.angular_velocity for b in self.bodies])
