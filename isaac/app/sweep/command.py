"""`isaac sweep SWEEP.yaml`: the runs fanned out over Dask, their rows gathered into one table.

Outline of `execute`:

1. read     the sweep file and its scene (its warnings said once); when a local cluster is to
            be started, the first PRE_CHECK runs' scenes checked by the scene loader here, so
            that most bad input is refused (one line, exit 2) before a cluster is started.
2. folder   OUT/ found holding this same sweep (resume: the rows of finished runs whose logs
            are complete are kept, the other runs are to do), or new.
3. check    on the cluster: every other run's scene loaded by the scene loader, in chunks
            (`worker.load_chunk`); the first run refused stops the sweep before anything runs
            or is written, with the message the loader gives here. The loaded scenes stay on
            the workers for step 5: each run's scene is read once.
4. warm up  one task (`worker.open_fan_out`) after every chunk's check: the kernels of each
            distinct world setting compiled into numba's on-disk cache once, by one worker (the
            others load them from there), and OUT/ written, unless a run was refused.
5. fan out  the same chunks as Dask tasks (`worker.run_chunk`), each after step 4's task and
            next to its loaded scenes; rows come back as chunks finish, with a progress bar.
6. gather   runs.parquet (every row, by index), the PNG plots, and the summary.

Steps 3 to 5 are one graph, sent at once: the workers go from the check to the runs without a
round trip to this process, which on a small machine has no core of its own (docs/sweep-format.md,
"Speed"). The chunks come in rounds of one equal chunk per worker that shrink towards the end of
the runs (`_round_chunks`), so that no worker waits long for the last chunk of another at the
end of the check or of the fan-out.

Ctrl-C (or SIGTERM) cancels the tasks, shuts the cluster down and writes the rows finished so
far; running the same command again resumes.
"""

from __future__ import annotations

import argparse
import math
import os
import shutil
import signal
import sys
import threading
import time
from dataclasses import dataclass, field

from isaac.app.options import integer, server_address
from isaac.app.sweep import worker as work
from isaac.app.sweep.cluster import MAX_LOCAL_WORKERS, result_noting, start_cluster
from isaac.app.sweep.spec import Sweep, SweepError, load_runs, load_sweep, refusal
from isaac.errors import IsaacError

# runs per task at most: a chunk costs several small runs' worth of CPU besides its runs (its
# check, summary and run tasks, in this process, which holds the scheduler, and in the workers);
# a rescheduled chunk redoes only its unfinished runs (their rows are on disk), so chunks may be
# big
MAX_CHUNK = 250
# chunk sizes shrink as the runs left do (guided self-scheduling, in rounds of one chunk per
# worker): each round's chunks are the runs left over TASKS_PER_WORKER x workers, so the last
# ones, which decide how long the slowest worker runs on alone at the end of the check and of
# the fan-out, are small, and the last round splits what is left evenly (no lone tail chunk)
TASKS_PER_WORKER = 2
# ... but no smaller than this many body-steps (the base scene's bodies x steps a run): 20 runs
# of a 2-body scene at 200 steps, one run of a 100-body pile
MIN_CHUNK_BODY_STEPS = 8_000
MAX_WARM_UP = 8  # distinct world settings compiled before the fan-out (others as they come)
# runs whose scenes are checked here before a local cluster is started, for at most this long:
# where the line falls changes which process finds a refusal, never which run it names (the
# cluster checks all the runs past it, and the first refused is said)
PRE_CHECK = 32
PRE_CHECK_SECONDS = 0.1
# the loaded scenes stay on the workers until their runs are done while the sweep's runs x the
# base scene's bodies are at most this (about 1 kB a body), else each run loads its own again
KEEP_SCENES_BODIES = 2_000_000


@dataclass
class SweepResult:
    """What a sweep did: `table` (pyarrow.Table, one row per finished run, by index), counts,
    wall time (s) and where it wrote."""

    table: object
    sweep: Sweep
    out: str
    kept: int
    ran: int
    seconds: float
    workers: int
    plots: list | None
    interrupted: bool = False
    # wall seconds of each step of `execute` (module docstring): read, cluster (started or
    # reached), check (until this process hears that step 4 is done, less its warm-up), warm_up
    # (as timed by the worker), runs (the fan-out, from then to the last row back), table, plots
    phases: dict = field(default_factory=dict)

    @property
    def failed(self) -> int:
        return sum(1 for s in self.table.column("status").to_pylist() if s != "ok")


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "sweep",
        help="run a scene many times (grid and random parameters) over Dask; one results table",
        usage="%(prog)s [options] SWEEP.yaml\n       %(prog)s verify DIR [--scheduler ADDRESS] "
        "[--workers N] [--quiet]",
        description="Run the sweep file's runs (docs/sweep-format.md) on a local Dask cluster "
        "(one worker process per core) or an existing one; write OUT/runs.parquet, the logs, "
        "plots and a summary. Running the same command again resumes.",
    )
    p.add_argument(
        "sweep",
        metavar="SWEEP.yaml | verify",
        help="the sweep file (YAML); or `verify DIR`: replay every log of the sweep in DIR "
        "on the cluster and write DIR/verify.parquet (identical, or the first divergence)",
    )
    p.add_argument("dir", nargs="?", metavar="DIR", help=argparse.SUPPRESS)
    p.add_argument(
        "-o", "--out", help="output folder (default: runs/STEM, STEM the sweep file's name)"
    )
    p.add_argument(
        "--scheduler",
        type=server_address,
        metavar="ADDRESS",
        help="run on this Dask scheduler (tcp://HOST:8786; default: $DASK_SCHEDULER_ADDRESS, "
        "else a local cluster); OUT must then be an absolute path every worker can write",
    )
    p.add_argument(
        "--workers",
        type=integer(minimum=1, maximum=MAX_LOCAL_WORKERS),
        metavar="N",
        help=f"local cluster size (default: one per core; at most {MAX_LOCAL_WORKERS})",
    )
    p.add_argument(
        "--chunk",
        type=integer(minimum=1),
        metavar="K",
        help=f"runs per task (default: up to {MAX_CHUNK}, fewer towards the end)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--no-plots", action="store_true", help="write no PNG plots")
    p.set_defaults(func=cmd_sweep)


def default_out(sweep_path: str) -> str:
    name = os.path.basename(sweep_path)
    stem = name[:-5] if name.endswith(".yaml") else os.path.splitext(name)[0]
    return os.path.join("runs", stem)


def run(sweep_path, out=None, *, client=None, scheduler=None, workers=None, chunk=None):
    """Run the sweep file `sweep_path` into folder `out` (default runs/STEM) and return its
    results table (pyarrow.Table; `.to_pandas()` with pandas installed).

    client: a `dask.distributed.Client` to run on (default: `scheduler`, else
    $DASK_SCHEDULER_ADDRESS, else a local cluster of `workers` processes, started and shut
    down here). Raises SweepError / SceneError for bad input, KeyboardInterrupt when
    interrupted (after writing the rows finished so far).
    """
    result = execute(
        str(sweep_path), out, client=client, scheduler=scheduler, workers=workers, chunk=chunk
    )
    if result.interrupted:
        raise KeyboardInterrupt
    return result.table


def _chunks(indices: list[int], size: int) -> list[list[int]]:
    return [indices[start : start + size] for start in range(0, len(indices), size)]


def _round_chunks(indices: list[int], n_workers: int, min_size: int) -> list[list[int]]:
    """`indices`, in order, in rounds of `n_workers` equal chunks of (runs left) /
    (TASKS_PER_WORKER x n_workers) runs each, at most MAX_CHUNK (guided self-scheduling: big
    chunks first, small ones at the end, where a worker that is done waits for the others).
    Once a round's chunks would be `min_size` runs or fewer, the last round splits the runs
    left evenly over the workers (sizes within one run of each other; fewer chunks only when
    fewer runs are left than workers): each worker's last chunk ends at about the same time,
    where chunks of `min_size` and a remainder would leave one worker running alone.

    Which run is in which chunk changes no result (a run depends on the sweep file and its
    index alone); the plan is a function of the runs, the workers and `min_size` alone."""
    out, start, n = [], 0, len(indices)
    while start < n:
        left = n - start
        size = min(MAX_CHUNK, math.ceil(left / (TASKS_PER_WORKER * n_workers)))
        if size <= min_size:  # the last round: what is left, evenly
            k = min(n_workers, left)
            for j in range(k):
                size = left // k + (j < left % k)
                out.append(indices[start : start + size])
                start += size
            break
        for _ in range(n_workers):
            out.append(indices[start : start + size])
            start += size
    return out


def _min_chunk(sweep: Sweep) -> int:
    """Runs per chunk at least (MIN_CHUNK_BODY_STEPS of the base scene's bodies x steps)."""
    steps = sweep.steps if sweep.steps is not None else sweep.scene.world.steps
    body_steps = max(1, len(sweep.scene.bodies)) * max(1, steps)
    return max(1, min(MAX_CHUNK, MIN_CHUNK_BODY_STEPS // body_steps))


def _tasks(sweep: Sweep, chunks: list[list[int]], out: str) -> list[dict]:
    base = {
        "out": out,
        "record": sweep.record,
        "steps": sweep.steps,
        "metrics": list(sweep.metrics),
        "final_bodies": list(sweep.final_bodies),
    }
    return [{**base, "runs": runs} for runs in chunks]


def execute(
    sweep_path: str,
    out: str | None = None,
    *,
    client=None,
    scheduler=None,
    workers=None,
    chunk=None,
    progress: bool = False,
    plots: bool = True,
    warn=None,
    note=None,
) -> SweepResult:
    """Steps 1-6 of the module docstring; see `run`. `warn`: called with each warning line of
    the base scene (isaac.scene.warnings), once, before anything runs; `note`: called with a
    status line when the workers' preparation is slow (a first sweep compiles the kernels)."""
    started = time.perf_counter()
    phases: dict[str, float] = {}
    sweep = load_sweep(sweep_path)
    if warn is not None:
        from isaac.scene.warnings import scene_warnings

        for line in scene_warnings(sweep.scene, sweep.steps):
            warn(line)
    remote = client is not None or bool(scheduler or os.environ.get("DASK_SCHEDULER_ADDRESS"))
    out = out or default_out(sweep_path)
    elsewhere = _remote_workers(client) if client is not None else remote
    if elsewhere and not os.path.isabs(out):
        raise SweepError(
            f"--out {out}: with a scheduler, give an absolute path on storage every worker can "
            "write (the workers write the logs there)",
            source=sweep.path,
        )
    if workers is not None and not 1 <= workers <= MAX_LOCAL_WORKERS:
        raise IsaacError(f"--workers must be >= 1 and <= {MAX_LOCAL_WORKERS}, got {workers}")
    if chunk is not None and chunk < 1:
        raise IsaacError(f"--chunk must be >= 1, got {chunk}")
    # a cluster that runs already costs nothing to ask: every run is checked there
    pre = load_runs(
        sweep,
        range(0 if remote else min(sweep.n_runs, PRE_CHECK)),
        keep=False,
        budget=PRE_CHECK_SECONDS,
    )
    if pre["refused"] is not None:
        raise refusal(sweep, pre["refused"])
    phases["read"] = time.perf_counter() - started
    from isaac.app.sweep import table as results  # pyarrow: imported when a sweep runs

    out = os.path.abspath(out)
    work.check_out(sweep, out)
    schema = results.schema(sweep)
    kept = results.kept_rows(out, sweep.n_runs, schema) if os.path.isdir(out) else {}
    todo = [i for i in range(sweep.n_runs) if i not in kept]
    done: dict[int, dict] = dict(kept)
    interrupted = False
    n_workers = 0
    if todo:
        interrupted, n_workers = _fan_out(
            sweep,
            todo,
            out,
            done,
            pre,
            client,
            scheduler,
            workers,
            chunk,
            progress,
            phases,
            note,
        )
    else:
        work.prepare_out(sweep, out)
    if interrupted:
        if not os.path.isfile(os.path.join(out, "sweep.yaml")):
            # stopped before anything ran: nothing to write
            return SweepResult(
                table=results.to_table(list(done.values()), schema),
                sweep=sweep,
                out=out,
                kept=len(kept),
                ran=0,
                seconds=time.perf_counter() - started,
                workers=n_workers,
                plots=None,
                interrupted=True,
                phases=phases,
            )
        # runs that finished after the client stopped listening left their rows on disk
        for i, row in results.kept_rows(out, sweep.n_runs, schema).items():
            done.setdefault(i, row)
    t0 = time.perf_counter()
    table = results.to_table(list(done.values()), schema)
    results.write(table, out)
    phases["table"] = time.perf_counter() - t0
    written = None
    if not interrupted:
        # every row is in the table: the per-chunk rows and the killed runs' files go
        shutil.rmtree(os.path.join(out, work.ROWS_DIR), ignore_errors=True)
        shutil.rmtree(os.path.join(out, work.TMP_DIR), ignore_errors=True)
        if plots:
            from isaac.app.sweep.plots import plot_all

            t0 = time.perf_counter()
            written = plot_all(table, sweep, out)
            phases["plots"] = time.perf_counter() - t0
        else:
            written = []
    return SweepResult(
        table=table,
        sweep=sweep,
        out=out,
        kept=len(kept),
        ran=len(done) - len(kept),
        seconds=time.perf_counter() - started,
        workers=n_workers,
        plots=written,
        interrupted=interrupted,
        phases=phases,
    )


def _check_on_cluster(client, sweep_f, sweep, todo_chunks, kept, checked) -> tuple[list, list]:
    """Step 3, submitted: (futures of the todo chunks' `load_chunk` results, kept on the
    workers; futures of every chunk's `chunk_summary`). `checked`: runs 0 .. checked - 1 were
    checked already."""
    keep = sweep.n_runs * len(sweep.scene.bodies) <= KEEP_SCENES_BODIES
    # the kept runs (a resume) are checked as well, past the ones checked here already
    others = [i for i in sorted(kept) if i >= checked]
    other_chunks = _chunks(others, max(len(c) for c in todo_chunks))
    n, m = len(todo_chunks), len(other_chunks)
    loads = client.map(
        work.load_chunk, todo_chunks, [sweep_f] * n, [keep] * n, pure=False, key="isaac-load"
    )
    checks = client.map(
        work.load_chunk, other_chunks, [sweep_f] * m, [False] * m, pure=False, key="isaac-check"
    )
    return loads, client.map(work.chunk_summary, loads + checks, pure=False)


def _take_rows(client, futures: list, done: dict) -> None:
    """The rows of the run tasks `futures` that finished, into `done` {index: row}; one gather
    (a message per worker holding some)."""
    ok = [f for f in futures if f.status == "finished"]
    for rows in client.gather(ok, errors="skip"):
        for row in rows:
            done[row["index"]] = row


def _remote_workers(client) -> bool:
    """Whether a caller's Dask client may have workers on other machines: any but a client of
    a `LocalCluster` made in this process (a scheduler reached by its address, dask-jobqueue's
    and Kubernetes' clusters), whose workers need an output path that means the same to them."""
    from dask.distributed import LocalCluster

    return not isinstance(getattr(client, "cluster", None), LocalCluster)


def _fan_out(
    sweep, todo, out, done, pre, client, scheduler, workers, chunk, progress, phases, note=None
):
    """Steps 3 to 5; fills `done` {index: row} and `phases` (seconds). Returns (interrupted,
    workers used)."""
    from dask.distributed import as_completed

    own = client is None
    cluster = None
    bar = None
    futures = []
    interrupted = False
    n_workers = 0
    try:
        t0 = time.perf_counter()
        if own:
            client, cluster = start_cluster(scheduler, workers)
        n_workers = max(1, len(client.scheduler_info().get("workers", {})))
        if chunk:
            chunks = _chunks(todo, chunk)
        else:
            chunks = _round_chunks(todo, n_workers, _min_chunk(sweep))
        sweep_f = client.scatter(sweep, broadcast=True, hash=False)
        phases["cluster"] = (t1 := time.perf_counter()) - t0
        # the whole graph at once: the checks, then one task that says whether every run's
        # scene was accepted and, if so, warms up the kernels and makes OUT (steps 3 and 4,
        # `worker.open_fan_out`), then the runs, which depend on it: they start as soon as it
        # is done, without waiting for this process, and do nothing if a run was refused
        loads, summaries = _check_on_cluster(
            client, sweep_f, sweep, chunks, set(done), len(pre["indices"])
        )
        gate = client.submit(
            work.open_fan_out,
            sweep_f,
            out,
            pre["worlds"],
            MAX_WARM_UP,
            *summaries,
            pure=False,
            key="isaac-open",
        )
        del summaries
        tasks = _tasks(sweep, chunks, out)
        futures = client.map(
            work.run_chunk,
            tasks,
            [sweep_f] * len(tasks),
            loads,
            [gate] * len(tasks),
            pure=False,
            key="isaac-run",
        )
        futures.append(gate)  # cancelled with the runs
        del loads  # each chunk's scenes go from the worker with its run task
        opened = result_noting(
            gate,
            note,
            "checking the runs and preparing the workers (the first sweep on this machine "
            "compiles the engine's kernels: up to a minute)",
        )
        if opened.get("refused") is not None:
            raise refusal(sweep, opened["refused"])
        if opened.get("error") is not None:
            raise SweepError(opened["error"], source=sweep.path)
        t0 = time.perf_counter()
        phases["check"] = t0 - t1 - opened["warm_up_s"]
        phases["warm_up"] = opened["warm_up_s"]
        t1 = t0
        if progress:
            from tqdm import tqdm

            bar = tqdm(total=sweep.n_runs, initial=len(done), unit="run", desc=sweep.scene_name)
        by_future = {f.key: k for k, f in enumerate(futures[:-1])}
        # the rows stay on the workers until every chunk is done and then come in one gather
        # (a message per worker): fetching each chunk's rows as it finished cost this process
        # and the workers CPU a chunk, taken from the runs on a 2-core machine
        # ... except that once no more than the last round is running (a chunk a worker at
        # most), the rows of the chunks finished so far are fetched while it runs: the gather
        # at the end then waits for the last chunks' rows alone
        finished, fetched = [], 0
        left = len(futures) - 1
        for future in as_completed(futures[:-1]):
            finished.append(future)
            left -= 1
            if bar is not None:
                bar.update(len(tasks[by_future[future.key]]["runs"]))
            if 0 < left <= n_workers and fetched == 0:
                fetched = len(finished)
                _take_rows(client, finished, done)
        _take_rows(client, finished[fetched:], done)
        for future in finished:
            task = tasks[by_future[future.key]]
            if all(i in done for i in task["runs"]):
                continue
            # e.g. KilledWorker: the chunk's unfinished runs fail
            if future.status == "error":
                exc = future.exception()
                message = " ".join(f"{type(exc).__name__}: {exc}".split())
            else:
                message = "the chunk's rows were lost with its worker"
            written = {
                r["index"]: r
                for r in work.read_rows(work.rows_path(out, task["runs"][0]))
                if work.row_is_complete(out, r)
            }
            for i in task["runs"]:
                done[i] = written.get(i) or {
                    "index": i,
                    **sweep.params(i),
                    "status": "failed",
                    "error": message,
                }
        phases["runs"] = time.perf_counter() - t1
    except KeyboardInterrupt:
        interrupted = True
    finally:
        # a second Ctrl-C must not cut the shutdown short (signals: main thread only)
        main_thread = threading.current_thread() is threading.main_thread()
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if main_thread else None
        try:
            if bar is not None:
                bar.close()
            if futures and client is not None:
                client.cancel(futures)
            if own and client is not None:
                client.close()
            if cluster is not None:
                cluster.close()
        finally:
            if main_thread:
                signal.signal(signal.SIGINT, previous)
    return interrupted, n_workers


# --- the command line -----------------------------------------------------------------------


def _summary(result: SweepResult) -> list[str]:
    import pyarrow as pa

    from isaac.app.sweep import table as results
    from isaac.app.sweep.metrics import columns

    t = result.table
    sweep = result.sweep
    rows = t.to_pylist()
    ok = [r for r in rows if r["status"] == "ok"]
    failed = [r for r in rows if r["status"] != "ok"]
    rate = result.ran / result.seconds if result.seconds > 0 else 0.0
    lines = [
        f"sweep {sweep.path}: {len(rows)} of {sweep.n_runs} runs: {len(ok)} ok, {len(failed)} "
        f"failed; {result.ran} run now ({result.kept} kept from before) in "
        f"{result.seconds:.1f} s, {rate:.2f} runs/s"
        + (
            f" on {result.workers} worker{'s' if result.workers > 1 else ''}"
            if result.workers
            else ""
        )
    ]
    numeric = [
        f.name
        for f in columns(sweep.metrics, sweep.final_bodies)
        if pa.types.is_floating(f.type) or pa.types.is_integer(f.type)
    ]
    if ok and numeric:
        width = max(len(n) for n in numeric)
        lines.append(f"  {'metric (ok runs)':<{width}}  {'min':>12} {'median':>12} {'max':>12}")
        for name in numeric:
            vals = sorted(r[name] for r in ok if r[name] is not None)
            if not vals:
                continue
            med = (
                vals[len(vals) // 2]
                if len(vals) % 2
                else 0.5 * (vals[len(vals) // 2 - 1] + vals[len(vals) // 2])
            )
            lines.append(f"  {name:<{width}}  {vals[0]:>12.6g} {med:>12.6g} {vals[-1]:>12.6g}")
    for r in failed[:5]:
        lines.append(f"  failed: run {r['index']}: {r['error']}")
    if len(failed) > 5:
        lines.append(f"  ... and {len(failed) - 5} more failed runs (status column)")
    lines.append(f"  table: {os.path.join(result.out, results.TABLE)}")
    if sweep.record != "none":
        lines.append(f"  logs: {os.path.join(result.out, work.LOGS_DIR)}/run-NNNNNN.mcap")
    if result.plots is None and not result.interrupted:
        lines.append(
            "  plots: skipped (matplotlib is not installed: pip install 'isaac-physics[plot]')"
        )
    elif result.plots:
        lines.append(
            f"  plots: {len(result.plots)} PNG files in {os.path.join(result.out, 'plots')}"
        )
    return lines


def _status(args: argparse.Namespace):
    """Where a status line goes (stderr), or None with --quiet."""
    if args.quiet:
        return None
    return lambda line: print(f"isaac sweep: {line}", file=sys.stderr)


def cmd_verify(args: argparse.Namespace) -> int:
    from isaac.app.sweep.verify import VERIFY_TABLE, verify

    if args.dir is None:
        raise IsaacError("isaac sweep verify DIR: give the sweep's output folder")
    started = time.perf_counter()
    table = verify(
        args.dir,
        scheduler=args.scheduler,
        workers=args.workers,
        progress=not args.quiet and sys.stderr.isatty(),
        note=_status(args),
    )
    rows = table.to_pylist()
    counts: dict[str, int] = {}
    for r in rows:
        counts[r["verdict"]] = counts.get(r["verdict"], 0) + 1
    took = time.perf_counter() - started
    print(
        f"verify {args.dir}: {len(rows)} logs: "
        + ", ".join(f"{n} {v}" for v, n in sorted(counts.items()))
        + f" ({took:.1f} s)"
    )
    bad = [r for r in rows if r["verdict"] != "identical"]
    for r in bad[:10]:
        where = ", ".join(
            str(x)
            for x in (
                r["channel"],
                r["where"],
                r["field"],
                None if r["ulps"] is None else f"{r['ulps']} ULP",
                r["detail"],
            )
            if x
        )
        step = r["first_divergent_step"]
        at = f" at step {step}" if step is not None else ""
        print(
            f"  run {r['index']} ({r['log_path']}): {r['verdict']}{at}"
            + (f": {where}" if where else "")
        )
    if len(bad) > 10:
        print(f"  ... and {len(bad) - 10} more (verdict column)")
    # the replay's notes on logs that are identical (versions, settings read differently)
    noted: dict[str, int] = {}
    for r in rows:
        if r["verdict"] == "identical" and r["detail"]:
            noted[r["detail"]] = noted.get(r["detail"], 0) + 1
    for text, n in sorted(noted.items(), key=lambda item: (-item[1], item[0]))[:5]:
        print(f"  note ({n} identical log{'s' if n > 1 else ''}): {text}")
    if len(noted) > 5:
        print(f"  ... and {len(noted) - 5} more notes (detail column)")
    print(f"  table: {os.path.join(args.dir, VERIFY_TABLE)}")
    return 1 if bad else 0


def cmd_sweep(args: argparse.Namespace) -> int:
    if args.sweep == "verify":
        return cmd_verify(args)
    if args.dir is not None:
        raise IsaacError(
            f"unexpected argument {args.dir!r} (did you mean `isaac sweep verify DIR`?)"
        )

    def stop(signum, frame):  # SIGTERM and SIGHUP stop the sweep as Ctrl-C does
        raise KeyboardInterrupt

    previous = {s: signal.signal(s, stop) for s in (signal.SIGTERM, signal.SIGHUP)}
    try:
        result = execute(
            args.sweep,
            args.out,
            scheduler=args.scheduler,
            workers=args.workers,
            chunk=args.chunk,
            progress=not args.quiet and sys.stderr.isatty(),
            plots=not args.no_plots,
            # the base scene's warnings, once (as isaac check and isaac run say them)
            warn=lambda line: print(f"isaac sweep: warning: {line}", file=sys.stderr),
            note=_status(args),
        )
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
    for line in _summary(result):
        print(line)
    if result.interrupted:
        print(
            f"isaac sweep: interrupted: {len(result.table)} of {result.sweep.n_runs} runs are "
            "in the table; run the same command again to resume",
            file=sys.stderr,
        )
        return 130
    return 1 if result.failed else 0
