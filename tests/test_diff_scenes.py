"""`isaac diff` of logs of different scenes (other body names or shapes) says so in one line
(exit 2) unless --force; logs of one scene under other settings (world settings, a body's
material or starting state) are compared, what differs listed first."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCENE = """
world: {{fidelity: seed, gravity: [0, 0], dt: {dt}, steps: 30}}
bodies:
  - {{name: left, shape: {{box: [1, 1]}}, position: [-2, 0], velocity: [{v}, 0], restitution: 1}}
  - {{name: right, shape: {{box: [1, {h}]}}, position: [0, 0], restitution: 1}}
"""


def _isaac(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "isaac", *args], cwd=ROOT, capture_output=True, text=True,
        timeout=300,
    )  # fmt: skip


@pytest.fixture(scope="module")
def logs(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("diff")
    out = {}
    for name, dt, v, h in (
        ("base", 0.01, 3, 1),
        ("finer", 0.005, 3, 1),  # the same scene under another dt
        ("faster", 0.01, 4, 1),  # the same scene, another starting velocity
        ("taller", 0.01, 3, 2),  # another scene: the right box's shape differs
    ):
        scene = folder / f"{name}.yaml"
        scene.write_text(SCENE.format(dt=dt, v=v, h=h))
        out[name] = folder / f"{name}.mcap"
        done = _isaac("run", str(scene), "--mcap", str(out[name]), "--quiet")
        assert done.returncode == 0, done.stderr
    return out


def test_logs_of_different_scenes_are_refused_in_one_line_unless_forced(logs):
    done = _isaac("diff", str(logs["base"]), str(logs["taller"]))
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1 and "are logs of different scenes" in done.stderr
    assert "--force" in done.stderr
    forced = _isaac("diff", str(logs["base"]), str(logs["taller"]), "--force")
    assert forced.returncode == 1 and forced.stdout.startswith("DIVERGED")


def test_the_same_scene_under_other_settings_lists_them_before_the_first_divergence(logs):
    done = _isaac("diff", str(logs["base"]), str(logs["finer"]))
    assert done.returncode == 1, done.stderr
    lines = done.stdout.splitlines()
    assert lines[0].startswith("DIVERGED")
    assert lines[1] == "  settings differ (A, B): dt 0.01, 0.005"
    assert lines[2].startswith("  step ")
    faster = _isaac("diff", str(logs["base"]), str(logs["faster"])).stdout.splitlines()
    assert faster[1] == "  settings differ (A, B): left.velocity (3.0, 0.0), (4.0, 0.0)"
