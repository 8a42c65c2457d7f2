"""Logs recorded by the engine before the fused compiled driver (commit 5d7cf6c, physics
version 1, tests/fixtures/pre_driver/README.md).

They replayed identical with the fused driver of physics version 1 (the driver changed how the
step runs, not what it computes; commit 747787c). Since physics version 2 (own sin/cos,
CHANGELOG.md) they are what a log of another physics version looks like to `isaac replay`: one
plain line and exit status 1 before anything is simulated, unless --tolerance is given."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from isaac.engine import PHYSICS_VERSION

ROOT = Path(__file__).resolve().parents[1]
LOGS = sorted((ROOT / "tests" / "fixtures" / "pre_driver").glob("*.mcap"))


def _isaac(*args: str) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_DISABLE_JIT"}
    return subprocess.run(
        [sys.executable, "-m", "isaac", *args],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_the_fixtures_are_there():
    assert [p.stem for p in LOGS] == ["head_on", "off_centre", "pile_small", "pyramid_small"]


@pytest.mark.parametrize("log", LOGS, ids=[p.stem for p in LOGS])
def test_a_log_of_another_physics_version_is_refused_in_one_line(log):
    assert PHYSICS_VERSION != 1
    done = _isaac("replay", str(log))
    assert done.returncode == 1
    assert done.stdout == ""  # no verdict, no divergence at step 1: only the reason
    lines = done.stderr.splitlines()
    assert len(lines) == 1, done.stderr
    assert lines[0].startswith(f"isaac replay: error: {log}: not replayed: physics version 1")
    assert f", {PHYSICS_VERSION} in this engine" in lines[0] and "--tolerance" in lines[0]


def test_inspect_shows_the_physics_version():
    done = _isaac("inspect", str(LOGS[0]))
    assert done.returncode == 0, done.stderr
    assert "physics 1 (not recorded)" in done.stdout


def test_with_a_tolerance_the_old_log_is_compared_and_the_reason_comes_first():
    log = next(p for p in LOGS if p.stem == "pile_small")
    done = _isaac("replay", str(log), "--tolerance", "1e-9")
    assert done.returncode == 0, done.stdout + done.stderr
    lines = done.stdout.splitlines()
    assert lines[0].startswith("equal within tolerance 1e-09: replayed 21 steps")
    assert lines[1].startswith(f"  note: physics version 1 in the log, {PHYSICS_VERSION} in")
