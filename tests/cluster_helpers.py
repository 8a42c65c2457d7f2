"""One local Dask cluster for the sweep tests: bound to 127.0.0.1, no dashboard, quiet logs."""

from __future__ import annotations

import logging
from collections.abc import Iterator
from contextlib import contextmanager


@contextmanager
def local_cluster(n_workers: int) -> Iterator[tuple]:
    """(cluster, client) for a `with` block; the client closes before the cluster (NOTES.md:
    out of order, the heartbeats print tracebacks)."""
    from dask.distributed import Client, LocalCluster

    with LocalCluster(
        n_workers=n_workers,
        threads_per_worker=1,
        processes=True,
        host="127.0.0.1",
        dashboard_address=None,
        scheduler_kwargs={"dashboard": False, "dashboard_address": "127.0.0.1:0"},
        silence_logs=logging.ERROR,
    ) as c:
        with Client(c) as client:
            yield c, client
