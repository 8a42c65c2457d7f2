"""`isaac run` held inside `Recorder.close` (the ISAAC_TEST_CLOSE_GATE hook), so that a test
acts at an exact moment: while the files are being finished.

    with held_in_close(tmp_path, "run", scene, "--mcap", out) as run:
        ...                      # run.proc is in Recorder.close, waiting on the gate
        run.release()            # let the close go on
    run.out, run.err             # its stdout and stderr, once it has exited
"""

from __future__ import annotations

import contextlib
import errno
import os
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
TINY_SCENE = """\
name: tiny
world: {gravity: [0.0, -9.81], dt: 0.01, steps: 40}
bodies:
  - {name: ground, shape: {box: [20.0, 1.0]}, position: [0.0, -0.5], concrete: true}
  - {name: box, shape: {box: [1.0, 1.0]}, position: [0.0, 0.6]}
"""


def isaac(*args, env=None, timeout=120):
    """`isaac ARGS...` in a subprocess; the CompletedProcess (text)."""
    return subprocess.run(
        [sys.executable, "-m", "isaac", *map(str, args)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env,
    )


class HeldRun:
    def __init__(self, gate: Path, args) -> None:
        self.gate = gate
        env = {**os.environ, "ISAAC_TEST_CLOSE_GATE": str(gate)}
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "isaac", *map(str, args)],
            cwd=REPO,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        )
        self.fd = self._open_gate()
        self.out = self.err = None

    def _open_gate(self, timeout: float = 120.0) -> int:
        """The gate's writing end, opened once the run has opened its reading end: then the
        run is inside Recorder.close. (Non-blocking, polled: a run that fails earlier must not
        leave the test waiting for ever.)"""
        deadline = time.time() + timeout
        while True:
            try:
                return os.open(self.gate, os.O_WRONLY | os.O_NONBLOCK)
            except OSError as exc:
                if exc.errno != errno.ENXIO:  # ENXIO: no reader yet
                    raise
            if self.proc.poll() is not None:
                out, err = self.proc.communicate()
                raise AssertionError(f"the run ended before closing its files:\n{out}\n{err}")
            assert time.time() < deadline, "the run never reached Recorder.close"
            time.sleep(0.01)

    def release(self) -> int:
        """Let the close go on (the run reads the gate to its end); wait for the run's exit."""
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None
        self.out, self.err = self.proc.communicate(timeout=120)
        return self.proc.returncode


@contextlib.contextmanager
def held_in_close(tmp_path: Path, *args):
    gate = tmp_path / "close-gate"
    os.mkfifo(gate)
    run = HeldRun(gate, args)
    try:
        yield run
    finally:
        if run.proc.poll() is None:
            if run.fd is not None:
                os.close(run.fd)
            run.proc.kill()
            run.proc.wait()
