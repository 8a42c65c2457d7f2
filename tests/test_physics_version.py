"""A log records the physics version beside the engine version (CHANGELOG.md lists each), and
`isaac inspect` shows it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from mcap.reader import make_reader

from isaac.engine import PHYSICS_VERSION

ROOT = Path(__file__).resolve().parents[1]


def test_a_new_log_records_and_shows_the_physics_version(tmp_path):
    log = tmp_path / "head_on.mcap"
    run = [sys.executable, "-m", "isaac", "run", "scenes/head_on.yaml", "--steps", "5"]
    done = subprocess.run(
        [*run, "--mcap", str(log), "--quiet"], cwd=ROOT, capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr
    with open(log, "rb") as f:
        meta = {m.name: m.metadata for m in make_reader(f).iter_metadata()}["isaac"]
    assert meta["physics_version"] == str(PHYSICS_VERSION)
    keys = list(meta)
    assert keys.index("physics_version") == keys.index("engine_version") + 1
    shown = subprocess.run(
        [sys.executable, "-m", "isaac", "inspect", str(log)],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    assert f"physics {PHYSICS_VERSION}, " in shown.stdout


def test_the_changelog_lists_every_physics_version():
    text = (ROOT / "CHANGELOG.md").read_text()
    for version in range(2, PHYSICS_VERSION + 1):
        assert f"## Physics version {version}" in text
