"""Helpers of the API boundary tests (tests/test_api_boundary*.py): small scenes written
inline, a record of one, and a child interpreter for calls that could kill the one running
pytest."""

from __future__ import annotations

import os
import subprocess
import sys
from functools import cache
from pathlib import Path

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
