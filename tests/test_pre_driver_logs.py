"""Logs recorded by the engine before the fused compiled driver (commit 5d7cf6c,
tests/fixtures/pre_driver/README.md) replay bit for bit with today's engine: the driver changed
how the step is run, not what it computes."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

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
def test_a_pre_driver_log_replays_identical(log):
    done = _isaac("replay", str(log))
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.startswith("identical: replayed"), done.stdout
