"""bench.loaded's busy loops: started as asked, and none left behind however the bench ends."""

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from bench.loaded import busy_loops

REPO = Path(__file__).resolve().parents[1]


def _running(pid: int) -> bool:
    """True while `pid` is a live process (a zombie, already dead, counts as gone)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def _wait_gone(pids, timeout=10.0) -> list[int]:
    """The pids still running after up to `timeout` s (polled: not a timing assertion)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        alive = [p for p in pids if _running(p)]
        if not alive:
            return []
        time.sleep(0.05)
    return [p for p in pids if _running(p)]


def test_starts_n_busy_processes_and_stops_them_on_normal_exit():
    with busy_loops(3) as procs:
        pids = [p.pid for p in procs]
        assert len(set(pids)) == 3
        assert all(_running(p) for p in pids)
        # each is a child of this process spinning, not exited
        assert all(p.poll() is None for p in procs)
    assert [p for p in pids if _running(p)] == []
    assert all(p.returncode is not None for p in procs)


def test_stops_them_when_the_body_raises():
    pids = []
    with pytest.raises(RuntimeError, match="boom"):
        with busy_loops(2) as procs:
            pids = [p.pid for p in procs]
            assert all(_running(p) for p in pids)
            raise RuntimeError("boom")
    assert len(pids) == 2
    assert [p for p in pids if _running(p)] == []


def test_zero_loops_is_a_no_op():
    with busy_loops(0) as procs:
        assert procs == []


# a bench stand-in: prints its loops' pids, waits inside `busy_loops` to be stopped, and on its
# way out prints their exit codes as `busy_loops` left them (None: not stopped and waited for)
_HOLDER = textwrap.dedent(
    """
    import signal, sys, time
    from bench.loaded import busy_loops
    # Ctrl-C's usual handler, even when started from a shell job that ignores SIGINT
    signal.signal(signal.SIGINT, signal.default_int_handler)
    procs = []
    try:
        with busy_loops(2) as procs:
            print(" ".join(str(p.pid) for p in procs), flush=True)
            while True:
                time.sleep(0.05)
    finally:
        print(" ".join(str(p.returncode) for p in procs), flush=True)
    """
)


def _holder():
    proc = subprocess.Popen(
        [sys.executable, "-c", _HOLDER], cwd=REPO, stdout=subprocess.PIPE, text=True
    )
    pids = [int(x) for x in proc.stdout.readline().split()]
    assert len(pids) == 2 and all(_running(p) for p in pids)
    return proc, pids


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGKILL])
def test_no_loop_left_when_the_bench_is_stopped(sig):
    """Ctrl-C (SIGINT) and SIGTERM run the `finally`; after SIGKILL, which skips it, the loops
    see they were orphaned and exit by themselves."""
    proc, pids = _holder()
    try:
        proc.send_signal(sig)
        rest = proc.stdout.read()
        proc.wait(timeout=20)
        if sig != signal.SIGKILL:
            # `busy_loops` stopped and reaped both loops before the holder went
            codes = rest.split()
            assert len(codes) == 2 and "None" not in codes, rest
            assert [p for p in pids if _running(p)] == []
        assert _wait_gone(pids) == []
    finally:
        for p in pids:  # never leave a spinning process behind a failed test
            if _running(p):
                os.kill(p, signal.SIGKILL)
        if proc.poll() is None:
            proc.kill()
            proc.wait()
