"""`NUMBA_DISABLE_JIT=1` is the reference path: every command runs there, and what it records is
the same bytes as the compiled run's."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "scenes" / "head_on.yaml"


def _isaac(*args: str, jit: bool) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    if jit:
        env.pop("NUMBA_DISABLE_JIT", None)
    else:
        env["NUMBA_DISABLE_JIT"] = "1"
    return subprocess.run(
        [sys.executable, "-m", "isaac", *args],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_recording_without_the_jit_gives_the_compiled_runs_bytes(tmp_path):
    logs = {}
    for jit in (True, False):
        log = tmp_path / f"{'jit' if jit else 'nojit'}.mcap"
        rrd = tmp_path / f"{'jit' if jit else 'nojit'}.rrd"
        args = ("run", str(SCENE), "--steps", "20", "--mcap", str(log), "--rrd", str(rrd))
        done = _isaac(*args, "--quiet", jit=jit)
        assert done.returncode == 0, done.stderr
        assert rrd.stat().st_size > 0
        logs[jit] = log.read_bytes()
    assert logs[True] == logs[False]


def test_every_log_command_runs_without_the_jit(tmp_path):
    log = tmp_path / "run.mcap"
    assert _isaac("run", str(SCENE), "--steps", "20", "--mcap", str(log), jit=True).returncode == 0
    replay = _isaac("replay", str(log), jit=False)
    assert replay.returncode == 0, replay.stderr
    assert replay.stdout.startswith("identical"), replay.stdout
    step = _isaac("inspect", str(log), "--step", "5", jit=False)
    assert step.returncode == 0, step.stderr
    check = _isaac("check", str(SCENE), jit=False)
    assert check.returncode == 0 and ": ok:" in check.stdout
    diff = _isaac("diff", str(log), str(log), jit=False)
    assert diff.returncode == 0, diff.stderr
    assert "Traceback" not in replay.stderr + step.stderr + diff.stderr
