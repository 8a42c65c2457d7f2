"""A writer process whose run dies (SIGKILL) writes every step it was handed into its .partial
file, notes that the run was abandoned, and holds the output's lock until it is done.

The run is a child Python process that hands N steps to a writer process it has stopped
(SIGSTOP), then kills itself: when the writer resumes, every one of the N steps is still to be
written and the run's end of the reply pipe is closed, so its first reply fails with EPIPE.
A keeper process between the test and the run adopts the orphaned writer (a child subreaper):
a stopped process whose group is orphaned would get SIGHUP from the kernel, and the keeper
can wait for the writer and say how it exited.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from isaac.errors import LogError
from recorder.outputs import claim

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
sys.path.insert(0, str(HERE))
from recorder_synth import SynthSim  # noqa: E402

HANDED = 300  # steps 0..299: three flush intervals of 100 and more than a batch of Rerun's

_RUN_THAT_DIES = r"""
import os, signal, sys
sys.path.insert(0, {here!r})
from recorder_synth import SynthSim, SCENE_TEXT
from recorder import Recorder

sim = SynthSim(12, 6)
rec = Recorder(sim, {kind}_path={path!r}, scene_text=SCENE_TEXT, offload="process")
rec.wait_ready()
writer = (rec.mcap or rec.rerun).proc.pid
os.kill(writer, signal.SIGSTOP)  # the writer takes nothing until the run is dead
rec.write(sim.record())
for _ in range({handed} - 1):
    rec.write(sim.step())
rec.hand_over()  # every frame announced to the writer: it has all {handed} steps
print(writer, flush=True)
os.kill(os.getpid(), signal.SIGKILL)
"""

_KEEPER = r"""
import ctypes, os, signal, subprocess, sys
ctypes.CDLL(None, use_errno=True).prctl(36, 1, 0, 0, 0)  # PR_SET_CHILD_SUBREAPER
run = subprocess.run([sys.executable, "-c", sys.argv[1]], capture_output=True, text=True)
writer = int(run.stdout.split()[0]) if run.stdout.strip() else 0
print(run.returncode, writer, flush=True)
if not writer:
    sys.exit(run.stderr)
sys.stdin.readline()  # the test looks at the output meanwhile
os.kill(writer, signal.SIGCONT)
_, status = os.waitpid(writer, 0)
print(os.waitstatus_to_exitcode(status), flush=True)
"""


class _Keeper:
    """The keeper process: `.run_status` and `.writer` once the run is dead; `resume()` lets
    the writer go on and returns its exit status."""

    def __init__(self, kind: str, path: Path) -> None:
        script = _RUN_THAT_DIES.format(here=str(HERE), kind=kind, path=str(path), handed=HANDED)
        self.proc = subprocess.Popen(
            [sys.executable, "-c", _KEEPER, script],
            cwd=REPO,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        line = self.proc.stdout.readline().split()
        assert len(line) == 2, self.proc.stderr.read()
        self.run_status, self.writer = int(line[0]), int(line[1])

    def resume(self) -> int:
        self.proc.stdin.write("\n")
        self.proc.stdin.flush()
        status = int(self.proc.stdout.readline())
        self.proc.wait(timeout=60)
        return status

    def __enter__(self) -> _Keeper:
        return self

    def __exit__(self, *exc) -> None:
        if self.proc.poll() is None:  # a failed test: leave nothing stopped behind
            if self.writer:
                for sig in (signal.SIGKILL, signal.SIGCONT):
                    try:
                        os.kill(self.writer, sig)
                    except ProcessLookupError:
                        pass
            self.proc.kill()
            self.proc.wait()


def test_an_mcap_writer_whose_run_died_writes_every_step_it_was_handed(tmp_path):
    from recorder.reader import LogReader, recover

    path = tmp_path / "orphan.mcap"
    with _Keeper("mcap", path) as keeper:
        assert keeper.run_status == -signal.SIGKILL
        # the run is dead, its writer is not: the output is still taken
        with pytest.raises(LogError, match="being written by another run"):
            claim(str(path), "mcap")
        assert keeper.resume() == 0
    partial = Path(str(path) + ".partial")
    assert partial.exists() and not path.exists()  # never passed off as a finished log
    log = LogReader(str(partial))
    assert not log.closed_cleanly  # no summary or index: `isaac recover` makes those
    assert [s.step for s in log.steps()] == list(range(HANDED))
    # after the last step, read with them: the note that the run was abandoned
    assert log.end["complete"] == "false" and log.end["reason"].startswith("abandoned")
    assert log.end["steps_written"] == str(HANDED)
    fixed = tmp_path / "fixed.mcap"
    assert recover(str(partial), str(fixed)) == (HANDED, HANDED - 1)
    sim = SynthSim(12, 6)
    expected = [sim.record()] + [sim.step() for _ in range(HANDED - 1)]
    got = list(LogReader(str(fixed)).steps())
    assert [s.step for s in got] == list(range(HANDED))
    for s, r in zip(got, expected):
        np.testing.assert_array_equal(s.record.position, r.position)
        np.testing.assert_array_equal(s.record.contacts.impulse, r.contacts.impulse)
    # the writer is gone, so is its lock; what is left is an earlier run's steps
    with pytest.raises(LogError, match=f"holds {HANDED} steps of an earlier run"):
        claim(str(path), "mcap")


@pytest.mark.slow  # 4-7 s (Rerun's start-up); the MCAP test above proves the same child loop
def test_a_rerun_writer_whose_run_died_writes_every_step_it_was_handed(tmp_path):
    from rerun.chunk import RrdReader

    path = tmp_path / "orphan.rrd"
    with _Keeper("rrd", path) as keeper:
        assert keeper.run_status == -signal.SIGKILL
        assert keeper.resume() == 0
    partial = Path(str(path) + ".partial")
    assert partial.exists() and not path.exists()
    steps, notes = set(), []
    for chunk in RrdReader(str(partial)).stream():  # readable as a whole: flushed and closed
        batch = chunk.to_record_batch()
        if chunk.entity_path == "/world/contacts" and "Points2D:positions" in batch.schema.names:
            steps.update(batch.column("step").to_pylist())
        if chunk.entity_path == "/log" and "TextLog:text" in batch.schema.names:
            notes += [text for row in batch.column("TextLog:text").to_pylist() for text in row]
    assert steps == set(range(HANDED))
    assert any(str(n).startswith("abandoned") for n in notes), notes
