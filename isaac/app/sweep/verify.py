"""`isaac sweep verify DIR`: every log of a sweep replayed on the cluster (`replay.replay_log`, the
check `isaac replay` makes), one verdict row per run in DIR/verify.parquet.

A sweep recorded on one machine can be checked on another: the logs carry their scenes, and the
verdict is the replay's own (identical, or the first divergence: step, body, field), unless the
file is not the log its row names by sha256 (`wrong log`): a log replaced by another run's, or
two logs swapped, replay identical, since each is a true log of some run.
"""

from __future__ import annotations

import os
import time

from isaac.app.sweep.spec import SweepError

VERIFY_TABLE = "verify.parquet"
WRONG_LOG = "wrong log"  # the verdict of a file whose sha256 is not the one its row names


def verify_chunk(task: dict) -> list[dict]:
    """Check and replay the logs of `task["runs"]` ([(index, log path relative to
    `task["out"]`, the row's log_sha256)]); a verdict row each.

    A file that is not the log its row names (`worker.log_differs`: another run's log, one
    edited or replaced) is `wrong log` whatever its replay says, for a log swapped with another
    run's replays identical; it is replayed all the same, and its `detail` says both (`verify`
    adds whose log it is). The replay's notes (versions, recorded settings read differently,
    ...) go into `detail` too, after the divergence's or the damage's own."""
    from isaac.app.sweep.worker import log_differs, sha256_of
    from isaac.errors import IsaacError
    from replay.compare import replay_log

    rows = []
    for index, rel, want in task["runs"]:
        started = time.perf_counter()
        path = os.path.join(task["out"], rel)
        row = {"index": index, "log_path": rel}
        differs = log_differs(path, want)
        try:
            report = replay_log(path)
            row["verdict"] = report.verdict
            row["steps_compared"] = report.steps_compared
            first = report.divergences[0] if report.divergences else None
            row["first_divergent_step"] = None if first is None else first.step
            row["channel"] = None if first is None else first.channel
            row["where"] = (first.where() or None) if first is not None else None
            row["field"] = (first.field or None) if first is not None else None
            row["ulps"] = None if first is None else first.ulps
            why = first.detail if first is not None else report.damage or report.truncated_detail
            row["detail"] = "; ".join(x for x in (why, *report.notes) if x) or None
        except IsaacError as exc:  # not a readable log, another physics version: its verdict
            row.update(verdict="not replayed", steps_compared=0)
            row["detail"] = " ".join(str(exc).split())
        if differs is not None and os.path.isfile(path):
            row["differs"] = differs
            row["file_sha256"] = sha256_of(path)
        row["wall_time_s"] = time.perf_counter() - started
        rows.append(row)
    return rows


def _wrong_log(row: dict, owner: dict) -> None:
    """Make `row` (from `verify_chunk`) a `wrong log` verdict when its file is not its row's
    log, naming the run whose log the file is (`owner`: {log_sha256: index}) when it is one."""
    differs = row.pop("differs", None)
    sha = row.pop("file_sha256", None)
    if differs is None:
        return
    whose = f" (it is run {owner[sha]}'s log)" if sha in owner else ""
    replayed = row["verdict"] + (f": {row['detail']}" if row["detail"] else "")
    row["detail"] = f"not the log the row names: {differs}{whose}; the replay: {replayed}"
    row["verdict"] = WRONG_LOG


def verify(out_dir: str, *, client=None, scheduler=None, workers=None, progress=False, note=None):
    """Replay every log named in OUT/runs.parquet; (pyarrow.Table of verdicts, sorted by index,
    written to OUT/verify.parquet). SweepError for a folder that holds no sweep table.

    The first log is replayed alone, before the others go out: on a cold numba cache one worker
    compiles the replay's kernels and the others load them, instead of each compiling them.
    `note` is called with a status line when that first replay is slow."""
    import pyarrow as pa
    import pyarrow.parquet as pq
    from dask.distributed import as_completed

    from isaac.app.sweep.cluster import result_noting, start_cluster
    from isaac.app.sweep.table import TABLE

    source = os.path.join(out_dir, TABLE)
    try:
        runs = pq.read_table(source).to_pylist()
    except FileNotFoundError:
        raise SweepError("no such file (is the folder a sweep's output?)", source=source) from None
    except Exception as exc:  # noqa: BLE001 - whatever pyarrow raises for a damaged table
        raise SweepError(f"not a readable table: {exc}", source=source) from None
    missing = [c for c in ("index", "log_path", "log_sha256") if runs and c not in runs[0]]
    if missing:
        raise SweepError(
            f"not a sweep's table of logs: it has no column {', '.join(missing)} (record: none?)",
            source=source,
        )
    logged = [(r["index"], r["log_path"], r["log_sha256"]) for r in runs if r["log_path"]]
    if not logged:
        raise SweepError("no run of this sweep has a log (record: none?)", source=source)
    owner = {sha: index for index, _, sha in logged if sha}
    out_dir = os.path.abspath(out_dir)
    own = client is None
    cluster = None
    bar = None
    rows: list[dict] = []
    try:
        if own:
            client, cluster = start_cluster(scheduler, workers)
        n_workers = max(1, len(client.scheduler_info().get("workers", {})))
        size = max(1, min(20, -(-len(logged) // (n_workers * 8))))
        lead = {"runs": logged[:1], "out": out_dir}
        tasks = [
            {"runs": logged[k : k + size], "out": out_dir} for k in range(1, len(logged), size)
        ]
        if progress:
            from tqdm import tqdm

            bar = tqdm(total=len(logged), unit="log", desc="verify")
        got = result_noting(
            client.submit(verify_chunk, lead, pure=False),
            note,
            "replaying the first log (the first verify on this machine compiles the replay's "
            "kernels: up to a minute)",
        )
        rows.extend(got)
        if bar is not None:
            bar.update(len(got))
        futures = client.map(verify_chunk, tasks, pure=False)
        for future in as_completed(futures):
            got = future.result()
            rows.extend(got)
            if bar is not None:
                bar.update(len(got))
    finally:
        if bar is not None:
            bar.close()
        if own:
            client.close()
        if cluster is not None:
            cluster.close()
    rows.sort(key=lambda r: r["index"])
    for row in rows:
        _wrong_log(row, owner)
    schema = pa.schema(
        [
            pa.field("index", pa.int64()),
            pa.field("log_path", pa.string()),
            pa.field("verdict", pa.string()),
            pa.field("steps_compared", pa.int64()),
            pa.field("first_divergent_step", pa.int64()),
            pa.field("channel", pa.string()),
            pa.field("where", pa.string()),
            pa.field("field", pa.string()),
            pa.field("ulps", pa.int64()),
            pa.field("detail", pa.string()),
            pa.field("wall_time_s", pa.float64()),
        ]
    )
    table = pa.Table.from_pylist(rows, schema=schema)
    path = os.path.join(out_dir, VERIFY_TABLE)
    pq.write_table(table, path + ".tmp")
    os.replace(path + ".tmp", path)
    return table
