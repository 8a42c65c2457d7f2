"""`isaac check` and `isaac run` print a scene's warnings (isaac.scene.warnings): one line each
on stderr, exit status 0, the scene still runs."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

HEAVY_ON_LIGHT = """
world: {fidelity: balanced, steps: 3}
bodies:
  - {name: ground, shape: {box: [10, 1]}, concrete: true}
  - {name: light, shape: {box: [1, 1]}, position: [0, 1]}
  - {name: heavy, shape: {box: [1, 1]}, position: [0, 2], density: 1000000000}
"""


def _isaac(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "isaac", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_check_and_run_warn_of_a_mass_ratio_the_preset_cannot_hold(tmp_path):
    scene = tmp_path / "heavy.yaml"
    scene.write_text(HEAVY_ON_LIGHT)
    for command in ("check", "run"):
        done = _isaac(command, str(scene), *(["--quiet"] if command == "run" else []))
        assert done.returncode == 0, done.stderr
        warnings = [line for line in done.stderr.splitlines() if "warning:" in line]
        assert len(warnings) == 1, done.stderr
        assert warnings[0].startswith(f"isaac {command}: warning: ")
        assert "1e+09:1" in warnings[0] and "'heavy'" in warnings[0] and "'light'" in warnings[0]


def test_shipped_scenes_give_no_warning():
    for scene in sorted((ROOT / "scenes").glob("*.yaml")):
        done = _isaac("check", str(scene))
        assert done.returncode == 0, done.stderr
        assert "warning" not in done.stderr, (scene.name, done.stderr)
