"""The Dask cluster a sweep runs on: an existing one by address, or a local one on 127.0.0.1."""

from __future__ import annotations

import logging
import os
import signal


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
# the process's memory and CPU every 100 / 500 ms. Idle, that cost the 2-worker cluster about
# 0.09 of a core (the client's process 0.03, each worker 0.027); with these, 0.018. A sweep on
# 2 workers of a 2-core machine has no core to spare for it.
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
        return Client(address), None
    n = workers or len(os.sched_getaffinity(0))  # one worker process per core we may use
    # the workers take the config of their nanny, made here (dask.config.set is undone at exit)
    with dask.config.set(QUIET):
        cluster = LocalCluster(
            n_workers=n,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",  # scheduler and workers listen on this machine only
            dashboard_address=None,
            # no dashboard; the scheduler's HTTP routes (health, metrics) on a free port of
            # 127.0.0.1 (its default, 8787, is taken by a second sweep or another cluster)
            scheduler_kwargs={"dashboard": False, "dashboard_address": "127.0.0.1:0"},
            silence_logs=logging.ERROR,
        )
    client = Client(cluster)
    from distributed.diagnostics.plugin import WorkerPlugin

    plugin = type("IgnoreInterrupt", (_IgnoreInterrupt, WorkerPlugin), {})()
    client.register_plugin(plugin)
    return client, cluster
