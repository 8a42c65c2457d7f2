"""The Dask cluster a sweep runs on: an existing one by address, or a local one on 127.0.0.1."""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import threading

# the most worker processes a local cluster starts (`--workers`): each is a Python process
# with numba's kernels loaded; past this a machine spends its time starting them
MAX_LOCAL_WORKERS = 256


class _IgnoreInterrupt:
    """Worker plugin of the local cluster: Ctrl-C reaches every process of the terminal's group;
    the workers leave it to the client, which cancels their tasks and shuts them down (a worker
    interrupted on its own would print tracebacks and be restarted)."""

    name = "isaac-sweep-ignore-sigint"

    def setup(self, worker=None) -> None:
        try:
            signal.signal(signal.SIGINT, signal.SIG_IGN)
        except ValueError:  # not the main thread of the worker process
            pass


# Dask's monitoring, for the local cluster only: each of the scheduler's and the workers' event
# loops otherwise wakes every 20 ms (tick: is the loop blocked?), samples the running task's
# stack every 10 ms (the dashboard's profile, which a sweep's cluster does not serve), and reads
# the process's memory and CPU every 100 / 500 ms (Dask's defaults). Idle, that keeps a
# noticeable part of a core busy, and a sweep on 2 workers of a 2-core machine has no core to
# spare for it (bench/HISTORY.md has the figures).
QUIET = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "5s",
    "distributed.worker.memory.monitor-interval": "1s",
}


def start_cluster(scheduler, workers):
    """(client, LocalCluster or None): a client of the scheduler at `scheduler` (else
    $DASK_SCHEDULER_ADDRESS), else of a new local cluster of `workers` processes (default: one
    per core this process may use), one thread each, bound to 127.0.0.1, without a dashboard."""
    import dask
    from dask.distributed import Client, LocalCluster

    address = scheduler or os.environ.get("DASK_SCHEDULER_ADDRESS")
    if address:
        try:
            return Client(address), None
        except (OSError, ValueError, TypeError) as exc:  # unreachable, or a malformed address
            from isaac.errors import IsaacError

            said = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise IsaacError(f"cannot use the Dask scheduler at {address}: {said}") from None
    n = workers or len(os.sched_getaffinity(0))  # one worker process per core we may use
    with _interrupt_held() as interrupted:
        client = cluster = None
        try:
            # the workers take the config of their nanny, made here (dask.config.set is undone
            # at exit)
            with dask.config.set(QUIET):
                cluster = LocalCluster(
                    n_workers=n,
                    threads_per_worker=1,
                    processes=True,
                    host="127.0.0.1",  # scheduler and workers listen on this machine only
                    dashboard_address=None,
                    # no dashboard; the scheduler's HTTP routes (health, metrics) on a free port
                    # of 127.0.0.1 (its default, 8787, is taken by a second sweep or another)
                    scheduler_kwargs={"dashboard": False, "dashboard_address": "127.0.0.1:0"},
                    silence_logs=logging.ERROR,
                )
            client = Client(cluster)
            from distributed.diagnostics.plugin import WorkerPlugin

            plugin = type("IgnoreInterrupt", (_IgnoreInterrupt, WorkerPlugin), {})()
            client.register_plugin(plugin)
        except BaseException:
            _close(client, cluster)
            raise
    if interrupted:  # Ctrl-C came while it started: stopped again, then said
        _close(client, cluster)
        raise KeyboardInterrupt
    return client, cluster


def _close(client, cluster) -> None:
    for part in (client, cluster):
        if part is not None:
            try:
                part.close()
            except Exception:  # noqa: BLE001 - stopping after an error or Ctrl-C: best effort
                pass


SLOW_START_S = 3.0  # s of waiting for the first results before the command says what it waits for


def result_noting(future, note, why: str):
    """`future.result()`; when it has not come after SLOW_START_S, `note(why)` first (a first
    sweep or verify compiles the kernels for half a minute with nothing on screen)."""
    if note is None:
        return future.result()
    try:
        return future.result(timeout=SLOW_START_S)
    except TimeoutError:  # (dask.distributed.TimeoutError is the built-in one)
        note(why)
        return future.result()


@contextlib.contextmanager
def _interrupt_held():
    """Ctrl-C (SIGINT) held while the local cluster starts, and noted: yields a list that holds
    an item once one came. Raised at any moment of the start, it left Dask's start-up half done
    (tracebacks from the scheduler's and the nannies' coroutines, a cluster nobody stops), and
    the worker processes, which get the terminal's Ctrl-C too, died with tracebacks of their own
    before the plugin told them to leave it to this process. So SIGINT is blocked in this thread
    while the cluster starts: the processes and threads started meanwhile inherit the mask
    (the workers never see it; they ignore it afterwards anyway), and a thread that was
    running before can only set the flag. Outside the main thread (no signal handlers there),
    nothing is done."""
    caught: list = []
    if threading.current_thread() is not threading.main_thread():
        yield caught
        return
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        # ignored from the start (a background job of a shell script): it stays ignored, as it
        # is for the rest of the sweep, rather than stopping it only while the cluster starts
        yield caught
        return
    # the resource tracker's start blocks and then unblocks SIGINT itself: started first, so
    # that it does not unblock it in the middle of the cluster's start
    from multiprocessing import resource_tracker

    resource_tracker.ensure_running()
    previous = signal.signal(signal.SIGINT, lambda signum, frame: caught.append(signum))
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield caught
    finally:
        try:
            # a Ctrl-C held meanwhile is delivered here, to the handler above
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        finally:
            signal.signal(signal.SIGINT, previous)
