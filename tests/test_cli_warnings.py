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
        if scene.name.endswith(".sweep.yaml"):  # a sweep file (isaac sweep), not a scene
            continue
        done = _isaac("check", str(scene))
        assert done.returncode == 0, done.stderr
        assert "warning" not in done.stderr, (scene.name, done.stderr)


TRAPS = """
world: {steps: 100, dt: 0.01}
bodies:
  - {name: ground, shape: {box: [10, 1]}, position: [0, -0.5], concrete: true}
  - {name: sunk, shape: {box: [1, 1]}, position: [0.5, -0.3]}
  - {name: a, shape: {box: [1, 1]}, position: [3, 0.5], friction: 0.9}
  - {name: b, shape: {box: [1, 1]}, position: [3.5, 0.6]}
  - {name: late, shape: {box: [1, 1]}, position: [-3, 3], enters_at: 0.5}
"""


def test_check_and_run_name_each_trap_in_one_line_and_exit_0(tmp_path):
    scene = tmp_path / "traps.yaml"
    scene.write_text(TRAPS)
    expected = {
        f"{scene}:6: bodies[2].friction: friction is given but world.friction is off",
        f"{scene}:5: bodies[1]: the body 'sunk' is placed inside the concrete body 'ground'",
        f"{scene}:6: bodies[2]: 1 pair of bodies overlaps at step 0 by more than the slop",
    }
    # `isaac run --steps 10` ends at t = 0.1 s, before 'late' enters; `check` uses world.steps
    late = f"{scene}:8: bodies[4]: the body 'late' enters at 0.5 s, after the run's last step"
    for command, extra, want in (
        ("check", [], expected),
        ("run", ["--quiet", "--steps", "10"], expected | {late}),
    ):
        done = _isaac(command, str(scene), *extra)
        assert done.returncode == 0, done.stderr
        prefix = f"isaac {command}: warning: "
        lines = [
            line[len(prefix) :] for line in done.stderr.splitlines() if line.startswith(prefix)
        ]
        assert len(lines) == len(want), done.stderr
        for start in want:
            assert sum(line.startswith(start) for line in lines) == 1, (start, done.stderr)
        assert "Traceback" not in done.stderr
