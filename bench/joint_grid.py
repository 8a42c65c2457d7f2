"""`python -m bench.joint_grid`: Box2D v3's `joint_grid` benchmark, ISAAC against pymunk.

A grid of N x N circles (radius 0.4 m, 1 m apart), each pinned by a revolute joint to its
neighbour above and to its left at the point half-way between them; the middle seven of the
top row are concrete, so the net hangs from them and swings down under gravity. The circles
never collide with each other (ISAAC: one negative group; pymunk: one ShapeFilter group), so
the step is all joints. dt = 1/60 s, `balanced` (10 iterations, 3 position passes) against
pymunk's 10 iterations. Reported: us per step over `steps` steps after one warm-up step, best
of `repeats`, and ISAAC / pymunk (issue 14's target: at most 0.8). Run on the machine as it
is: say how busy it was beside the figures.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time

from isaac.scene import PRESETS, BodySpec, Scene, WorldSettings
from isaac.scene.spec import JointSpec

RADIUS = 0.4
DT = 1.0 / 60.0
TARGET = 0.8  # ISAAC / pymunk, at most


def _fixed(n: int, k: int, i: int) -> bool:
    """The middle seven bodies of the top row are concrete (Box2D v3's benchmark)."""
    return i == 0 and n // 2 - 3 <= k <= n // 2 + 3


def grid_scene(n: int) -> Scene:
    """The joint grid as an ISAAC scene: body (k, i) at (k, -i) m, joints to (k, i - 1) and
    (k - 1, i) at the midpoints (none between two concrete bodies)."""
    bodies, joints = [], []
    index = {}
    for k in range(n):
        for i in range(n):
            index[k, i] = len(bodies)
            bodies.append(
                BodySpec(
                    name=f"c{k}_{i}",
                    vertices=(),
                    circle=RADIUS,
                    position=(float(k), float(-i)),
                    concrete=_fixed(n, k, i),
                    group=-1,
                )
            )
            for other, half in (((k, i - 1), (0.0, 0.5)), ((k - 1, i), (-0.5, 0.0))):
                if other not in index or (_fixed(n, k, i) and _fixed(n, *other)):
                    continue
                joints.append(
                    JointSpec(
                        name=f"j{len(joints)}",
                        kind="revolute",
                        a=index[other],
                        b=index[k, i],
                        local_a=(-half[0], -half[1]),
                        local_b=half,
                    )
                )
    world = WorldSettings(**{**PRESETS["balanced"], "fidelity": "balanced", "dt": DT})
    return Scene(name=f"joint_grid-{n}", world=world, bodies=tuple(bodies), joints=tuple(joints))


def time_isaac(n: int, steps: int, repeats: int) -> float:
    """us per step of `Simulation.advance` (one compiled call per `steps`)."""
    from isaac.engine.simulation import Simulation

    best = math.inf
    for _ in range(repeats):
        sim = Simulation(grid_scene(n))
        sim.advance(1)  # compiled and warm
        start = time.perf_counter()
        sim.advance(steps)
        best = min(best, (time.perf_counter() - start) / steps * 1e6)
    return best


def time_pymunk(n: int, steps: int, repeats: int) -> float:
    """us per step of pymunk's `Space.step` on the same grid (PivotJoints, one shape group)."""
    import pymunk

    best = math.inf
    for _ in range(repeats):
        space = pymunk.Space()
        space.gravity = (0.0, -9.81)
        space.iterations = 10
        space.sleep_time_threshold = math.inf
        body = {}
        group = pymunk.ShapeFilter(group=1)  # shapes of one group never collide
        for k in range(n):
            for i in range(n):
                kind = pymunk.Body.STATIC if _fixed(n, k, i) else pymunk.Body.DYNAMIC
                b = pymunk.Body(body_type=kind)
                b.position = (float(k), float(-i))
                shape = pymunk.Circle(b, RADIUS)
                shape.density = 1.0
                shape.filter = group
                space.add(b, shape)
                body[k, i] = b
                for other, pivot in (((k, i - 1), (k, -i + 0.5)), ((k - 1, i), (k - 0.5, -i))):
                    if other in body and not (_fixed(n, k, i) and _fixed(n, *other)):
                        space.add(pymunk.PivotJoint(body[other], b, pivot))
        space.step(DT)
        start = time.perf_counter()
        for _ in range(steps):
            space.step(DT)
        best = min(best, (time.perf_counter() - start) / steps * 1e6)
    return best


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench.joint_grid", description=__doc__)
    parser.add_argument("--n", type=int, default=100, help="grid side (default 100)")
    parser.add_argument("--steps", type=int, default=120)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", action="store_true", help="print one JSON line")
    args = parser.parse_args(argv)
    isaac_us = time_isaac(args.n, args.steps, args.repeats)
    pymunk_us = time_pymunk(args.n, args.steps, args.repeats)
    ratio = isaac_us / pymunk_us
    row = {
        "case": f"joint_grid {args.n}x{args.n}",
        "isaac_us_per_step": round(isaac_us, 1),
        "pymunk_us_per_step": round(pymunk_us, 1),
        "ratio": round(ratio, 3),
        "target": TARGET,
        "met": ratio <= TARGET,
    }
    if args.json:
        print(json.dumps(row))
    else:
        print(
            f"{row['case']}: isaac {isaac_us:.0f} us/step, pymunk {pymunk_us:.0f} us/step, "
            f"ratio {ratio:.2f} (target <= {TARGET}: {'met' if row['met'] else 'not met'})"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
