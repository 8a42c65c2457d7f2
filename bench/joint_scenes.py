"""`python -m bench.joint_scenes`: the shipped chain and Newton's cradle, time per step beside
their quality figure, ISAAC against pymunk.

- chain (scenes/chain.yaml): 40 links of 0.25 m x 0.05 m on revolute joints, the first pinned,
  released horizontal, 10 s at dt = 1/240 s. Quality: the worst joint error over the run (m),
  the distance between a joint's two anchors after a step (issue 14's target: below 1 mm).
- cradle (scenes/newton_cradle.yaml): five discs on 2 m rods (distance joints), e = 1, the
  first released from 0.5 rad, 6 s at dt = 1/480 s. Quality: the last ball's speed 20 steps
  after it starts to move against the first ball's largest speed (1 is a perfect cradle), and
  the fastest of the three middle balls then, as a fraction of that speed.

ISAAC runs each scene with its own settings (the file's; the chain takes 4 sub-steps).
pymunk 7 gets the same bodies (density 1 kg/m^2, the same boxes and discs), PivotJoints and
PinJoints whose bodies do not collide (ISAAC's joints keep connected bodies apart), 10
iterations, collision slop 0.01 m (SI), elasticity 1 for the discs and friction 0 (the cradle
has friction off), the same dt; for a scene with sub-steps, a second pymunk row takes as many
pymunk steps of dt / sub-steps.
Time: `Simulation.advance` over the whole run (one compiled call) against pymunk's `Space.step`
loop, after one warm-up step, best of `repeats`; the quality figure from a separate run that
reads every step. Run on the machine as it is: say how busy it was beside the figures.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from isaac.scene import Scene, load_scene

ROOT = Path(__file__).resolve().parents[1]
SCENES = ("chain", "newton_cradle")
FOLLOW = 20  # steps after the last ball starts to move at which the cradle is judged


def _scene(name: str) -> Scene:
    return load_scene(ROOT / "scenes" / f"{name}.yaml")


def chain_quality(errors: np.ndarray) -> dict:
    """errors: (steps, joints) m after each step."""
    return {"worst_joint_error_m": float(errors.max())}


def cradle_quality(vx: np.ndarray) -> dict:
    """vx: (steps, 5) the balls' x velocities (m/s) after each step."""
    first = float(np.abs(vx[:, 0]).max())  # the first ball at the bottom of its swing
    hit = int(np.argmax(vx[:, 4] > 0.1 * first))  # the step the last ball starts to move
    after = vx[min(hit + FOLLOW, vx.shape[0] - 1)]
    return {
        "last_over_first": float(after[4] / first),
        "middle_over_first": float(np.abs(after[1:4]).max() / first),
    }


def isaac_row(name: str, repeats: int) -> dict:
    from isaac.engine.simulation import Simulation

    scene = _scene(name)
    steps = scene.world.steps
    best = math.inf
    for _ in range(repeats):
        sim = Simulation(scene)
        sim.advance(1)  # compiled and warm
        start = time.perf_counter()
        sim.advance(steps - 1)
        best = min(best, (time.perf_counter() - start) / (steps - 1) * 1e6)
    records = list(Simulation(scene).run(steps))
    if name == "chain":
        quality = chain_quality(np.array([r.joints.error[:, 0] for r in records]))
    else:
        quality = cradle_quality(np.array([r.velocity[1:, 0] for r in records]))
    w = scene.world
    settings = f"{w.fidelity}, {w.substeps} sub-steps, {w.iterations} iterations"
    return {"scene": name, "engine": "isaac", "settings": settings, "us_per_step": best, **quality}


def _pymunk_space(scene: Scene):
    """pymunk's version of a shipped joint scene: (space, dynamic bodies, joints)."""
    import pymunk

    space = pymunk.Space()
    space.gravity = scene.world.gravity
    space.iterations = 10
    space.collision_slop = 0.01
    space.sleep_time_threshold = math.inf
    bodies = []
    for spec in scene.bodies:
        kind = pymunk.Body.STATIC if spec.concrete else pymunk.Body.DYNAMIC
        body = pymunk.Body(body_type=kind)
        body.position = spec.position
        body.angle = spec.angle
        if spec.circle is not None:
            shape = pymunk.Circle(body, spec.circle)
        else:
            shape = pymunk.Poly(body, spec.vertices)  # centred on the centroid already (boxes)
        shape.density = spec.density
        shape.elasticity = spec.restitution
        shape.friction = spec.friction if scene.world.friction else 0.0
        space.add(body, shape)
        bodies.append(body)
    joints = []
    for j in scene.joints:
        a, b = bodies[j.a], bodies[j.b]
        if j.kind == "revolute":
            joint = pymunk.PivotJoint(a, b, j.local_a, j.local_b)
        elif j.kind == "distance":
            joint = pymunk.PinJoint(a, b, j.local_a, j.local_b)
        else:
            raise ValueError(f"no pymunk version of a {j.kind} joint here")
        joint.collide_bodies = False
        space.add(joint)
        joints.append(joint)
    return space, bodies, joints


def pymunk_row(name: str, repeats: int, substeps: int = 1) -> dict:
    """pymunk's figures; `substeps` > 1 takes each step as that many pymunk steps of dt /
    substeps (ISAAC's sub-steps, for a like-for-like quality)."""
    import pymunk

    scene = _scene(name)
    steps, h = scene.world.steps, scene.world.dt / substeps

    def step(space):
        for _ in range(substeps):
            space.step(h)

    best = math.inf
    for _ in range(repeats):
        space, _, _ = _pymunk_space(scene)
        step(space)
        start = time.perf_counter()
        for _ in range(steps - 1):
            step(space)
        best = min(best, (time.perf_counter() - start) / (steps - 1) * 1e6)
    space, bodies, joints = _pymunk_space(scene)
    per_step = []
    for _ in range(steps):
        step(space)
        if name == "chain":
            per_step.append(
                [
                    (j.a.local_to_world(j.anchor_a) - j.b.local_to_world(j.anchor_b)).length
                    for j in joints
                ]
            )
        else:
            per_step.append([b.velocity.x for b in bodies[1:]])
    values = np.array(per_step)
    quality = chain_quality(values) if name == "chain" else cradle_quality(values)
    settings = f"{substeps} sub-steps, 10 iterations, pymunk {pymunk.version}"
    return {"scene": name, "engine": "pymunk", "settings": settings, "us_per_step": best, **quality}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench.joint_scenes", description=__doc__)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--no-pymunk", action="store_true", help="ISAAC alone")
    parser.add_argument("--json", action="store_true", help="one JSON line per row")
    args = parser.parse_args(argv)
    rows = []
    for name in SCENES:
        isaac = isaac_row(name, args.repeats)
        rows.append(isaac)
        if not args.no_pymunk:
            peer = pymunk_row(name, args.repeats)
            isaac["ratio_to_pymunk"] = isaac["us_per_step"] / peer["us_per_step"]
            rows.append(peer)
            substeps = _scene(name).world.substeps
            if substeps > 1:  # also at ISAAC's sub-steps
                rows.append(pymunk_row(name, args.repeats, substeps))
    for row in rows:
        if args.json:
            print(json.dumps(row))
            continue
        figures = ", ".join(
            f"{k} {v:.4g}" for k, v in row.items() if k not in ("scene", "engine", "settings")
        )
        print(f"{row['scene']:<14} {row['engine']:<7} ({row['settings']}): {figures}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
