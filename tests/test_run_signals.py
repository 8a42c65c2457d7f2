"""`isaac run` and signals while its files are being finished: the close goes on, the files are
complete under their final names, then the run exits 130 saying it was interrupted.

Each run is held inside `Recorder.close` (tests/close_gate.py) while the signal is sent, so the
signal lands in the close, not before or after it.
"""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest
from close_gate import TINY_SCENE, held_in_close

from recorder.reader import LogReader

STEPS = 40


def _assert_interrupted_while_finishing(run, status: int, *names: str) -> None:
    assert status == 130, run.err
    lines = run.err.splitlines()
    assert len(lines) == 1 and "Traceback" not in run.err, run.err
    assert any(f"interrupted ({name}) while finishing the files" in lines[0] for name in names)
    assert f"{STEPS} steps of" in run.out  # the summary still says what ran


def _assert_complete_log(path: Path) -> None:
    assert not Path(str(path) + ".partial").exists()
    log = LogReader(str(path))
    assert log.closed_cleanly and log.complete
    assert [s.step for s in log.steps()] == list(range(STEPS + 1))


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])  # SIGHUP: the terminal closed
def test_a_signal_while_the_log_is_finished_lets_the_close_finish(tmp_path, sig):
    scene = tmp_path / "tiny.yaml"
    scene.write_text(TINY_SCENE)
    mcap = tmp_path / "run.mcap"
    args = ("run", scene, "--quiet", "--steps", STEPS, "--mcap", mcap)
    with held_in_close(tmp_path, *args) as run:
        os.kill(run.proc.pid, sig)
        status = run.release()
    _assert_interrupted_while_finishing(run, status, signal.Signals(sig).name)
    _assert_complete_log(mcap)


def test_signals_while_both_files_are_finished_leave_both_complete(tmp_path):
    from rerun.chunk import RrdReader

    scene = tmp_path / "tiny.yaml"
    scene.write_text(TINY_SCENE)
    mcap, rrd = tmp_path / "run.mcap", tmp_path / "run.rrd"
    args = ("run", scene, "--quiet", "--steps", STEPS, "--mcap", mcap, "--rrd", rrd)
    with held_in_close(tmp_path, *args) as run:
        os.kill(run.proc.pid, signal.SIGINT)  # Ctrl-C: not ignored, not a KeyboardInterrupt
        os.kill(run.proc.pid, signal.SIGTERM)  # and a second signal changes nothing either
        status = run.release()
    # both pending at once: the kernel delivers the lower-numbered (SIGINT) first
    _assert_interrupted_while_finishing(run, status, "SIGINT", "SIGTERM")
    _assert_complete_log(mcap)
    assert not Path(str(rrd) + ".partial").exists()
    steps = set()
    for chunk in RrdReader(str(rrd)).stream():
        batch = chunk.to_record_batch()
        if chunk.entity_path == "/world/bodies/moving" and "step" in batch.schema.names:
            steps.update(batch.column("step").to_pylist())
    assert steps == set(range(STEPS + 1))
