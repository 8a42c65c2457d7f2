"""Helpers of the API boundary tests (tests/test_api_boundary*.py): small scenes written
inline, a record of one, and a child interpreter for calls that could kill the one running
pytest."""

from __future__ import annotations

import os
import subprocess
import sys
from functools import cache
from pathlib import Path

import numpy as np

from isaac.engine.records import StepRecord
from isaac.engine.simulation import Simulation
from isaac.scene import load_scene_text

ROOT = Path(__file__).resolve().parent.parent
DT = "0.01"


def scene_text(n: int, *, joints: int = 0, dt: str = DT, enters: float | None = None) -> str:
    """n bodies: a concrete floor and n - 1 boxes resting on it side by side (so that records
    hold contacts), `joints` revolute joints between consecutive boxes, the last box entering
    at `enters` s."""
    lines = [f"name: s{n}j{joints}", "world:", f"  dt: {dt}", "  steps: 20", "bodies:"]
    lines += [
        "  - name: floor",
        "    shape: {box: [20.0, 1.0]}",
        "    position: [0.0, -0.5]",
        "    concrete: true",
    ]
    for i in range(1, n):
        lines += [
            f"  - name: box{i}",
            "    shape: {box: [1.0, 1.0]}",
            f"    position: [{1.5 * i}, 0.499]",
        ]
        if enters is not None and i == n - 1:
            lines.append(f"    enters_at: {enters}")
    if joints:
        lines.append("joints:")
        for j in range(joints):
            lines += [
                f"  - name: j{j}",
                "    type: revolute",
                f"    bodies: [box{j + 1}, box{j + 2}]",
                f"    anchor: [{1.5 * (j + 1) + 0.75}, 0.5]",
            ]
    return "\n".join(lines) + "\n"


@cache
def scene(n: int, **kw):
    return load_scene_text(scene_text(n, **kw))


@cache
def record_of(n: int, steps: int = 5, **kw) -> StepRecord:
    sim = Simulation(scene(n, **kw))
    return [sim.step() for _ in range(steps)][-1]


def in_child(code: str, timeout: float = 900) -> subprocess.CompletedProcess:
    """Run `code` in a child interpreter importing this tree (faulthandler on: a crash prints
    where)."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join((str(ROOT), str(ROOT / "tests")))}
    return subprocess.run(
        [sys.executable, "-X", "faulthandler", "-c", code],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
    )


# --- scenes built in Python -----------------------------------------------------------------

BOX = ((-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5))


def built(*, body: dict | None = None, world: dict | None = None, joints=(), bodies=None):
    """A scene built in Python, never seen by the loader: a concrete floor (bodies[0]) and a
    box (bodies[1], 'box') resting on it, the box's fields `body` and the world's `world`
    replaced, with `joints` (JointSpecs) or `bodies` instead of the two."""
    import dataclasses

    from isaac.scene import BodySpec, Scene, WorldSettings

    floor = BodySpec("floor", ((-5.0, -0.5), (5.0, -0.5), (5.0, 0.5), (-5.0, 0.5)), concrete=True)
    box = dataclasses.replace(BodySpec("box", BOX, position=(0.0, 0.999)), **(body or {}))
    return Scene(
        "built",
        WorldSettings(**(world or {})),
        (floor, box) if bodies is None else bodies,
        joints=joints,
    )


def joint(**fields):
    from isaac.scene.spec import JointSpec

    values = dict(name="j", kind="revolute", a=0, b=1, local_a=(0.0, 0.5), local_b=(0.0, -0.5))
    return JointSpec(**{**values, **fields})


def _circle_of(k: int):
    import math

    return tuple((math.cos(2 * math.pi * i / k), math.sin(2 * math.pi * i / k)) for i in range(k))


NAN, INF = float("nan"), float("inf")
# name: (the scene's arguments to `built`, the key path and words the refusal holds)
HOSTILE_SCENES = {
    "NaN position": (dict(body=dict(position=(NAN, 1.0))), "bodies[1].position: body 'box'"),
    "infinite velocity": (dict(body=dict(velocity=(0.0, -INF))), "bodies[1].velocity"),
    "NaN angle": (dict(body=dict(angle=NAN)), "bodies[1].angle"),
    "density 0": (dict(body=dict(density=0.0)), "density 0.0 is out of range"),
    "density NaN": (dict(body=dict(density=NAN)), "density nan is out of range"),
    "density negative": (dict(body=dict(density=-1.0)), "bodies[1].density"),
    "density a string": (dict(body=dict(density="1.0")), "density must be a number"),
    "subnormal mass": (dict(body=dict(density=1e-320)), "bodies[1].mass: body 'box': mass 1e-320"),
    "2 vertices": (dict(body=dict(vertices=BOX[:2])), "at least 3 vertices, got 2"),
    "clockwise": (dict(body=dict(vertices=BOX[::-1])), "clockwise"),
    "zero area": (dict(body=dict(vertices=((0.0, 0.0), (1.0, 0.0), (2.0, 0.0)))), "collinear"),
    "not convex": (
        dict(body=dict(vertices=((0.0, 0.0), (2.0, 0.0), (1.0, 0.2), (2.0, 2.0), (0.0, 2.0)))),
        "not convex",
    ),
    "1000 vertices": (dict(body=dict(vertices=_circle_of(1000))), "at most 50 vertices, got 1000"),
    "NaN vertex": (dict(body=dict(vertices=((0.0, 0.0), (1.0, NAN), (0.0, 1.0)))), "vertices"),
    "vertices an array": (
        dict(body=dict(vertices=np.array(BOX))),
        "got a ndarray of shape (4, 2)",
    ),
    "vertices None": (dict(body=dict(vertices=None)), "vertices must be a tuple"),
    "position of 3": (dict(body=dict(position=(0.0, 1.0, 2.0))), "position must be a tuple of two"),
    "circle radius 0": (dict(body=dict(vertices=(), circle=0.0)), "bodies[1].circle"),
    "circle radius -1": (dict(body=dict(vertices=(), circle=-1.0)), "circle's radius -1.0 m"),
    "circle and vertices": (dict(body=dict(circle=1.0)), "a polygon or a circle"),
    "restitution 2": (dict(body=dict(restitution=2.0)), "bodies[1].restitution"),
    "leaves before entering": (dict(body=dict(enters_at=1.0, leaves_at=0.5)), "leaves_at"),
    "category a float": (dict(body=dict(category=1.5)), "category must be an int"),
    "empty name": (dict(body=dict(name="")), "bodies[1].name"),
    "duplicate name": (dict(body=dict(name="floor")), "duplicate body name"),
    "no bodies": (dict(bodies=()), "bodies: the scene has no bodies"),
    "a body that is a string": (dict(bodies=("box",)), "bodies[0]: must be an isaac.scene."),
    "dt 0": (dict(world=dict(dt=0.0)), "world.dt: dt must be a number > 0.0"),
    "dt NaN": (dict(world=dict(dt=NAN)), "world.dt"),
    "dt negative": (dict(world=dict(dt=-0.01)), "world.dt"),
    "iterations -1": (dict(world=dict(iterations=-1)), "world.iterations"),
    "iterations 10^9": (dict(world=dict(iterations=10**9)), "in 1..1000, got 1000000000"),
    "substeps 0": (dict(world=dict(substeps=0)), "world.substeps"),
    "substeps 2.5": (dict(world=dict(substeps=2.5)), "world.substeps"),
    "gravity NaN": (dict(world=dict(gravity=(0.0, NAN))), "world.gravity"),
    "contact points 3": (dict(world=dict(contact_points=3)), "world.contact_points"),
    "solver unknown": (dict(world=dict(solver="magic")), "'magic' is not one of seed"),
    "joint to body 5 of 2": (dict(joints=(joint(b=5),)), "joints[0].b: joint 'j': body index 5"),
    "joint to body -1": (dict(joints=(joint(a=-1),)), "joints[0].a"),
    "joint of a body to itself": (dict(joints=(joint(a=1),)), "the same body 'box'"),
    "joint anchor NaN": (dict(joints=(joint(local_a=(NAN, 0.0)),)), "joints[0].local_a"),
    "joint axis an array": (
        dict(joints=(joint(axis=np.array([1.0, 0.0])),)),
        "joints[0].axis",
    ),
    "joint kind unknown": (dict(joints=(joint(kind="rope"),)), "joints[0].kind"),
    "joints with the seed solver": (
        dict(joints=(joint(),), world=dict(solver="seed")),
        "joints need the sequential solver",
    ),
}


def run_scene_cases(names) -> None:
    """The child: each named scene handed to `Simulation` (the driver's path, then the staged
    one) and, if it were taken, stepped 3 times; one JSON line per case, flushed."""
    import json

    for name in names:
        kw, _ = HOSTILE_SCENES[name]
        for staged in (False, True):
            try:
                sim = Simulation(built(**kw), staged=staged)
                for _ in range(3):
                    sim.step()
                outcome = {"raised": None}
            except Exception as exc:  # noqa: BLE001  (the parent checks which)
                outcome = {"raised": type(exc).__name__, "message": str(exc)}
            print(json.dumps({"case": name, "staged": staged, **outcome}), flush=True)
