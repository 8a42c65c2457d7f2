"""Process-level tuning of the `isaac` command (`isaac.tuning`): what it changes in the process
and in the processes it starts, and that a user's own choice wins."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest

from isaac.tuning import one_blas_thread
from recorder.spawn import start_sender_child

# the number of OS threads of a Python process once numpy is imported (Linux: /proc)
_THREADS_AFTER_NUMPY = (
    "import sys, os; sys.path.insert(0, {root!r})\n"
    "from isaac.tuning import one_blas_thread\n"
    "{call}\n"
    "import numpy\n"
    "print(len(os.listdir('/proc/self/task')))\n"
)
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


# what sets OpenBLAS's thread count; Dask's LocalCluster sets the first three in the process that
# starts it (an earlier sweep test), and the children of this one would inherit them
_BLAS_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "GOTO_NUM_THREADS")


def _threads_after_numpy(call: str) -> int:
    env = {k: v for k, v in os.environ.items() if k not in _BLAS_VARIABLES}
    code = _THREADS_AFTER_NUMPY.format(root=ROOT, call=call)
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    )
    return int(out.stdout)


@pytest.mark.skipif(not os.path.isdir("/proc/self/task"), reason="counts threads in /proc")
def test_numpy_starts_without_its_blas_thread_pool_after_one_blas_thread():
    alone = _threads_after_numpy("one_blas_thread()")
    assert alone == 1  # the main thread only
    if (os.cpu_count() or 1) > 1:  # the pool's threads, one per further CPU, without it
        assert _threads_after_numpy("pass") > alone


def test_a_blas_thread_count_the_user_set_is_kept(monkeypatch):
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "3")
    one_blas_thread()
    assert os.environ["OPENBLAS_NUM_THREADS"] == "3"
    monkeypatch.delenv("OPENBLAS_NUM_THREADS")
    one_blas_thread()
    assert os.environ["OPENBLAS_NUM_THREADS"] == "1"


def _read(path: str) -> bytes:
    with open(path, "rb") as f:
        return f.read()


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="reads /proc/PID/environ")
def test_the_rerun_sender_process_starts_with_one_blas_thread(monkeypatch):
    for name in _BLAS_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    child = start_sender_child()
    try:
        # until the child has exec'd Python, /proc shows the environment it was forked with
        deadline = time.monotonic() + 30
        while b"rerun_send" not in _read(f"/proc/{child.proc.pid}/cmdline"):
            assert time.monotonic() < deadline, "the sender did not start"
            time.sleep(0.01)
        with open(f"/proc/{child.proc.pid}/environ", "rb") as f:
            environ = dict(item.split(b"=", 1) for item in f.read().split(b"\0") if b"=" in item)
    finally:
        child.discard()
    assert environ.get(b"OPENBLAS_NUM_THREADS") == b"1"
