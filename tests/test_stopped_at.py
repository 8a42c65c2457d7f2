"""One meaning of "stopped at step K" (issue 16): K is the last step whose state is in the log.

An interrupted run says so in its summary and its last line, the log's `isaac.end` says the
same K, `isaac inspect` says it of the log, and after a hard kill `isaac inspect` of the
.partial, `isaac recover` and `isaac inspect` of the recovered copy all name the same K, the
last step each log holds."""

from __future__ import annotations

import fcntl
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

from close_gate import REPO, TINY_SCENE, isaac

from recorder.reader import LogReader

LONG = 10**7  # steps: the run is stopped long before


def _start(tmp_path: Path, *extra: str) -> tuple[subprocess.Popen, Path]:
    scene = tmp_path / "tiny.yaml"
    scene.write_text(TINY_SCENE)
    mcap = tmp_path / "run.mcap"
    args = ["run", str(scene), "--quiet", "--steps", str(LONG), "--mcap", str(mcap), *extra]
    proc = subprocess.Popen(
        [sys.executable, "-m", "isaac", *args],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    return proc, mcap


# what a check reads of the growing .partial: some 500 steps of the tiny scene (116 bytes a step)
PREFIX_BYTES = 64 * 1024


def _wait_for_steps(proc: subprocess.Popen, partial: Path, steps: int) -> None:
    """Until the .partial holds `steps` steps (chunks are flushed every 100 steps). Each check
    reads a copy of the file's first PREFIX_BYTES, never the whole file: the run writes the
    tiny scene at 130,000 steps/s (15 MB/s), several times faster than a reader scans it, and
    a scan of the whole growing file let the run write 45-109 MB before it was stopped (then
    `isaac inspect` of it outlasted its 120 s)."""
    prefix = partial.with_name("prefix.mcap")
    deadline = time.time() + 240
    while time.time() < deadline:
        assert proc.poll() is None, proc.communicate()
        if partial.exists():
            with open(partial, "rb") as f:
                prefix.write_bytes(f.read(PREFIX_BYTES))
            try:
                if sum(1 for _ in LogReader(str(prefix)).steps()) >= steps:
                    return
            except Exception:  # noqa: BLE001 - the header may not be written yet
                pass
        time.sleep(0.05)
    raise AssertionError("the run wrote too few steps in time")


def _stopped_at(text: str) -> int:
    (k,) = {int(k) for k in re.findall(r"stopped at step (\d+), the last step in ", text)}
    return k


def test_an_interrupted_run_its_log_and_inspect_name_the_same_last_step(tmp_path):
    proc, mcap = _start(tmp_path)
    try:
        _wait_for_steps(proc, Path(str(mcap) + ".partial"), 150)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130, err
    summary = out.splitlines()[0]
    k = _stopped_at(summary)
    # the summary says it was interrupted, and how far the run got
    assert f"interrupted by SIGINT: {k} of {LONG} steps of 0.01 s" in summary
    assert summary.endswith(f"stopped at step {k}, the last step in {mcap}")
    # (a long run first says how large its log will be: 10M steps here)
    announced, *_, said = err.strip().splitlines()
    assert announced.startswith("expected MCAP log size: about ")
    assert said == f"isaac run: interrupted by SIGINT; stopped at step {k}, the last step in {mcap}"
    log = LogReader(str(mcap))
    steps = [s.step for s in log.steps()]
    assert steps == list(range(k + 1))  # every step up to K, and K the last
    assert log.end["stopped_at"] == str(k) and log.end["last_step"] == str(k)
    assert log.end["reason"] == "interrupted by SIGINT"
    shown = isaac("inspect", mcap).stdout
    assert f"closed cleanly; run interrupted by SIGINT; stopped at step {k}, the last step" in shown


def test_after_a_kill_inspect_recover_and_the_copy_name_the_same_last_step(tmp_path):
    proc, mcap = _start(tmp_path)
    partial = Path(str(mcap) + ".partial")
    try:
        _wait_for_steps(proc, partial, 150)
        os.kill(proc.pid, signal.SIGKILL)
        proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    # the writer process outlives the run and writes every step it was handed; it holds the
    # .partial's flock until then (recorder/outputs.py)
    with open(partial, "rb") as f:
        deadline = time.time() + 120
        while True:
            try:
                fcntl.flock(f.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                assert time.time() < deadline, "the writer process never let the file go"
                time.sleep(0.1)
    held = [s.step for s in LogReader(str(partial)).steps()]
    last = held[-1]
    assert held == list(range(last + 1))
    inspected = isaac("inspect", partial).stdout
    assert _stopped_at(inspected) == last
    assert "NOT closed" in inspected
    out = tmp_path / "recovered.mcap"
    done = isaac("recover", partial, out)
    assert done.returncode == 0, done.stderr
    assert (
        f"recovered {last + 1} step(s) into {out}: stopped at step {last}, the last step in the log"
        in done.stdout
    )
    copy = LogReader(str(out))
    assert [s.step for s in copy.steps()][-1] == last
    assert copy.end["stopped_at"] == str(last) and copy.end["complete"] == "false"
    again = isaac("inspect", out).stdout
    assert "closed cleanly; run did not complete" in again and _stopped_at(again) == last
