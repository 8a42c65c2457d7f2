"""What a Dask worker does: the runs of one chunk, each simulated, measured and recorded in this
process, its log put under its final name only once it is finished, and its row kept on disk.

A run's files, in the sweep's output folder:

- ``logs/.tmp/run-000123.mcap`` (and ``.rrd``): where the recorder writes (as ``.partial``,
  renamed there on close). A run killed or interrupted leaves its file here, never under the
  final name.
- ``logs/run-000123.mcap``: moved there (one rename) once the log is on disk. The recorder
  closes a run's log without an fsync; at the end of its chunk, one sync of the file system
  (`publish_logs`: ``syncfs``) makes all the chunk's logs durable, and only then are they moved
  to their final names. An fsync per file would make every small recorded run wait on the
  disk; one sync per chunk is paid once for up to 250 logs. So a final name never holds a
  half-written log, even after a power loss.
- ``rows/chunk-000120.jsonl``: the rows of the chunk whose first run is 120, one JSON line per
  run, each appended (and flushed) once the run's logs are closed (and their sha256 taken). A
  chunk that Dask runs again after its worker died finds the rows of the runs already done and
  keeps them (`row_is_complete` moves their logs, still in ``logs/.tmp``, into place): a
  killed worker costs only the run it was in. A line cut short by a kill is not a row.

Where a run's time goes is what shapes this module (docs/sweep-format.md, "Speed"): a small run
simulates in well under a millisecond, so everything per run besides the simulation is kept
small. Each run's scene is loaded once, by the task that checked it (`load_chunk`, whose
result Dask keeps on the worker for the chunk's `run_chunk`, or sends to the worker that runs
the chunk: a few ms for 100 small scenes); the whole run is one compiled
batch of steps (`batch_size`); its row is one appended line, not a file. The recorder writes in
this process (``offload="none"``): one writer process per run would cost more than a small run.
"""

from __future__ import annotations

import hashlib
import json
import os
import time

ROWS_DIR = "rows"
LOGS_DIR = "logs"
TMP_DIR = os.path.join(LOGS_DIR, ".tmp")


def log_names(index: int, record: str) -> dict[str, str]:
    """{"mcap": relative path, "rrd": relative path} of run `index`'s logs."""
    out = {}
    if record in ("mcap", "mcap+rrd"):
        out["mcap"] = os.path.join(LOGS_DIR, f"run-{index:06d}.mcap")
    if record == "mcap+rrd":
        out["rrd"] = os.path.join(LOGS_DIR, f"run-{index:06d}.rrd")
    return out


ROW_FILE_PREFIX = "chunk-"
BATCH_BODY_STEPS = 100_000  # body-steps per batch of records at most (memory per batch)


def rows_path(out_dir: str, first: int) -> str:
    """The row file of the chunk whose first run is `first`."""
    return os.path.join(out_dir, ROWS_DIR, f"{ROW_FILE_PREFIX}{first:06d}.jsonl")


def sha256_of(path: str) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(1 << 20):
            h.update(chunk)
    return h.hexdigest()


def tmp_path(out_dir: str, rel: str) -> str:
    """Where the log whose final name is OUT/`rel` is written (logs/.tmp/NAME)."""
    return os.path.join(out_dir, TMP_DIR, os.path.basename(rel))


def log_differs(path: str, want: str | None) -> str | None:
    """Why the file at `path` is not the log a row names by its sha256 `want` (hex), in a few
    words; None when it is. The one check of a log against its row: a resume keeps a run only
    when it passes (`row_is_complete`), and `isaac sweep verify` calls any other file a `wrong
    log`."""
    if want is None:
        return "the row names no sha256 for it"
    try:
        got = sha256_of(path)
    except FileNotFoundError:
        return "no such file"
    except OSError as exc:
        return f"not readable: {exc.strerror or exc}"
    if got != want:
        return f"its sha256 is {got[:12]}..., the row names {want[:12]}..."
    return None


def row_is_complete(out_dir: str, row: dict) -> bool:
    """Whether `row`'s logs are there and are the files the row describes (sha256). A log that
    is not under its final name yet but finished in logs/.tmp with that sha256 (its chunk was
    stopped before `publish_logs`: a killed worker, Ctrl-C) is synced and moved there first."""
    for kind in ("mcap", "rrd"):
        rel = row.get("log_path" if kind == "mcap" else "rrd_path")
        if rel is None:
            continue
        path = os.path.join(out_dir, rel)
        want = row.get("log_sha256" if kind == "mcap" else "rrd_sha256")
        if log_differs(path, want) is None:
            continue
        tmp = tmp_path(out_dir, rel)
        if log_differs(tmp, want) is not None:
            return False
        try:
            publish_logs(out_dir, [(tmp, path)], each=True)
        except OSError:
            return False
    return True


def _syncfs(path: str) -> bool:
    """syncfs(2) of the file system holding `path` (Linux): every file written there reaches
    the disk, in one call; False where the C library has none."""
    import ctypes

    try:
        syncfs = ctypes.CDLL(None, use_errno=True).syncfs
    except (OSError, AttributeError):
        return False
    fd = os.open(path, os.O_RDONLY)
    try:
        if syncfs(fd) != 0:
            err = ctypes.get_errno()
            raise OSError(err, os.strerror(err), path)
    finally:
        os.close(fd)
    return True


def _fsync_path(path: str) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def publish_logs(out_dir: str, moves: list[tuple[str, str]], each: bool = False) -> None:
    """Make the finished logs `moves` ([(path in logs/.tmp, final path)]) durable, then give
    them their final names: one sync of OUT's file system for them all (or an fsync per file:
    `each`, or no syncfs here), a rename each, and an fsync of logs/ so that the renames last
    too. OSError if any step fails (the files not yet moved stay in logs/.tmp)."""
    if not moves:
        return
    if each or not _syncfs(out_dir):
        for tmp, _ in moves:
            _fsync_path(tmp)
    for tmp, final in moves:
        os.replace(tmp, final)
    _fsync_path(os.path.join(out_dir, LOGS_DIR))


def read_rows(path: str) -> list[dict]:
    """The rows of row file `path` in the order written (none if it is absent or unreadable;
    a line that is not a whole JSON row, as a kill mid-write leaves, is skipped)."""
    try:
        with open(path, encoding="utf-8") as f:
            lines = f.read().split("\n")
    except (OSError, UnicodeDecodeError):
        return []
    rows = []
    for line in lines:
        try:
            row = json.loads(line)
        except ValueError:
            continue
        if isinstance(row, dict) and isinstance(row.get("index"), int):
            rows.append(row)
    return rows


def check_out(sweep, out: str) -> None:
    """SweepError unless OUT is absent, empty, or holds this same sweep (then it is resumed).
    Reads only."""
    from isaac.app.sweep.spec import SweepError

    copy = os.path.join(out, "sweep.yaml")
    scene_copy = os.path.join(out, "scene.yaml")
    if os.path.lexists(out) and not os.path.isdir(out):
        raise SweepError(f"--out {out} is not a folder", source=sweep.path)
    if os.path.isdir(out) and os.listdir(out):
        if not os.path.isfile(copy):
            raise SweepError(
                f"--out {out} is not empty and holds no sweep: choose an empty or new folder",
                source=sweep.path,
            )
        for path, text, what in (
            (copy, sweep.text, "sweep file"),
            (scene_copy, sweep.scene_text, "scene"),
        ):
            try:
                with open(path, encoding="utf-8") as f:
                    same = f.read() == text
            except OSError:
                same = False
            if not same:
                raise SweepError(
                    f"--out {out} holds a sweep of another {what} ({path} differs): resume "
                    "only with the same files, or choose another folder",
                    source=sweep.path,
                )


def prepare_out(sweep, out: str) -> None:
    """Make OUT (checked by `check_out` first) and copy the sweep file and its scene there."""
    from isaac.app.sweep.spec import SweepError

    check_out(sweep, out)
    copy = os.path.join(out, "sweep.yaml")
    scene_copy = os.path.join(out, "scene.yaml")
    try:
        for sub in ("", LOGS_DIR, TMP_DIR, ROWS_DIR):
            os.makedirs(os.path.join(out, sub), exist_ok=True)
        for path, text in ((copy, sweep.text), (scene_copy, sweep.scene_text)):
            if not os.path.exists(path):
                with open(path + ".tmp", "w", encoding="utf-8") as f:
                    f.write(text)
                os.replace(path + ".tmp", path)
    except OSError as exc:
        raise SweepError(
            f"cannot write --out {out}: {exc.strerror or exc}", source=sweep.path
        ) from None


class _RowFile:
    """The row file of one chunk, opened for appending on the first row."""

    def __init__(self, path: str) -> None:
        self.path = path
        self.f = None

    def append(self, row: dict) -> None:
        if self.f is None:
            self.f = open(self.path, "a", encoding="utf-8")
            if self.f.tell() > 0:
                self.f.write("\n")  # a line a killed attempt cut short ends here, alone
        self.f.write(json.dumps(row) + "\n")  # floats as repr: exact float64 (NaN as NaN)
        self.f.flush()  # on disk (the page cache) before the next run: a kill loses no row

    def close(self) -> None:
        if self.f is not None:
            self.f.close()


class Clock:
    """Wall seconds of each part of the runs timed with it, summed (bench/sweep.py reports them
    per run): scene (loading a run's scene, when the run does it itself), build (the
    Simulation: the engine's model and state), simulate (the compiled batches), record (the
    recorder: open, write, close, sha256; and the chunk's one sync and renames at its end),
    metrics (their start, each batch's share and the values), row (the row's line appended)."""

    PARTS = ("scene", "build", "simulate", "record", "metrics", "row")

    def __init__(self) -> None:
        self.seconds = dict.fromkeys(self.PARTS, 0.0)
        self.runs = 0
        self._t = 0.0

    def start(self) -> None:
        self._t = time.perf_counter()
        self.runs += 1

    def lap(self, part: str) -> None:
        """The time since the last lap (or start) goes to `part`."""
        t = time.perf_counter()
        self.seconds[part] += t - self._t
        self._t = t

    def mark(self) -> None:
        """Start timing work that is no run's (a chunk's), without counting a run."""
        self._t = time.perf_counter()


class _NoClock:
    def start(self) -> None:
        pass

    def mark(self) -> None:
        pass

    def lap(self, part: str) -> None:
        pass


def _worker_name() -> str:
    try:
        from distributed import get_worker

        return str(get_worker().address)
    except (ImportError, ValueError):
        return f"pid {os.getpid()}"


def load_chunk(indices: list[int], sweep, keep: bool) -> dict:
    """`isaac.app.sweep.spec.load_runs` as a Dask task: the chunk's scenes checked (and kept in
    the result, which Dask holds on this worker for the chunk's `run_chunk`, when `keep`)."""
    from isaac.app.sweep.spec import load_runs

    return load_runs(sweep, indices, keep=keep)


def chunk_summary(loaded: dict) -> dict:
    """What the client needs of a `load_chunk` result (not the scenes): runs checked, the first
    refused, the world settings seen."""
    return {k: loaded[k] for k in ("indices", "refused", "worlds")}


_WARMED: set = set()  # (world settings repr, record mode) warmed up by `open_fan_out` here


def open_fan_out(sweep, out: str, pre_worlds: dict, max_warm_up: int, *summaries: dict) -> dict:
    """The step between the check and the fan-out, one task on one worker (the run tasks depend
    on it: they start when it is done, without a round trip to the client), from the chunks'
    `chunk_summary` results and the world settings of the runs checked by the client
    (`pre_worlds`):

    - a run refused: {"refused": its index}; nothing is written (the runs do nothing);
    - else the kernels of the first `max_warm_up` distinct world settings compiled into numba's
      on-disk cache (shared by the workers of one machine: the others load them from there in
      their first run, rather than each compiling them), OUT made and the sweep file and its
      scene copied there: {"ok": True, "warm_up_s": seconds}, or {"error": why OUT cannot be
      written}."""
    from isaac.app.sweep.spec import SweepError

    refused = [s["refused"] for s in summaries if s["refused"] is not None]
    if refused:
        return {"refused": min(refused)}
    worlds = dict(pre_worlds)
    for s in summaries:
        for w, i in s["worlds"].items():
            worlds[w] = min(i, worlds.get(w, i))
    t0 = time.perf_counter()
    first = sorted((i, w) for w, i in worlds.items())[:max_warm_up]
    # a world setting this process has warmed up before (an earlier sweep on this cluster) has
    # its kernels in the on-disk cache already
    cold = [(i, w) for i, w in first if (w, sweep.record) not in _WARMED]
    warm = [sweep.run_scene_text(i) for i, _ in cold]
    warm_up(warm, sweep.scene_path, sweep.scene_name, sweep.record)
    _WARMED.update((w, sweep.record) for _, w in cold)
    warm_up_s = time.perf_counter() - t0
    try:
        prepare_out(sweep, out)
    except SweepError as exc:
        return {"error": exc.what}
    return {"ok": True, "warm_up_s": warm_up_s}


def batch_size(steps: int, n_bodies: int) -> int:
    """Steps per compiled call: the whole run for small scenes, capped so that a batch's
    records hold at most BATCH_BODY_STEPS body-steps."""
    return max(1, min(steps, BATCH_BODY_STEPS // max(1, n_bodies)))


def run_chunk(
    task: dict, sweep, loaded: dict | None = None, opened: dict | None = None, clock=None
) -> list[dict]:
    """The rows of the runs of `task` (see `isaac.app.sweep.command._tasks`), in order.
    `loaded`: the chunk's `load_chunk` result (scenes and table values), else each run's scene
    is loaded here. `opened`: `open_fan_out`'s result; nothing is run (no rows) unless it is
    ok. `clock`: a `Clock` that times the parts of each run."""
    if opened is not None and not opened.get("ok"):
        return []
    clock = clock or _NoClock()
    out_dir, first = task["out"], task["runs"][0]
    path = rows_path(out_dir, first)
    # an earlier attempt at this chunk (its worker died): the runs it finished are kept
    done = {r["index"]: r for r in read_rows(path) if r["index"] in set(task["runs"])}
    done = {i: r for i, r in done.items() if row_is_complete(out_dir, r)}
    scenes, params = {}, {}
    if loaded is not None:
        params = dict(zip(loaded["indices"], loaded["params"]))
        if loaded["scenes"] is not None:
            scenes = dict(zip(loaded["indices"], loaded["scenes"]))
    worker = _worker_name()
    rows = []
    moves: list[tuple[str, str]] = []  # the chunk's finished logs, moved into place at its end
    file = _RowFile(path)
    try:
        for index in task["runs"]:
            row = done.get(index)
            if row is None:
                row = run_one(
                    task,
                    sweep,
                    index,
                    scenes.get(index),
                    params.get(index),
                    worker,
                    clock,
                    moves=moves,
                )
                file.append(row)
                clock.lap("row")
            rows.append(row)
    finally:
        file.close()
    clock.mark()
    publish_logs(out_dir, moves)
    clock.lap("record")
    return rows


def run_one(
    task: dict, sweep, index: int, scene=None, params=None, worker=None, clock=None, moves=None
) -> dict:
    """Simulate, measure and (maybe) record run `index`; its row (status "ok" or "failed").
    `scene`, `params`: the run's loaded scene and table values, when already known; `clock`:
    a `Clock` to time the run's parts with. `moves`: a list to which the run's finished logs
    are added as (path in logs/.tmp, final path), closed without an fsync, for the caller to
    sync and move (`publish_logs`); else each is synced and moved here."""
    from isaac.app.sweep.metrics import Measure
    from isaac.engine.simulation import Simulation
    from isaac.errors import IsaacError

    clock = clock or _NoClock()
    clock.start()
    started = time.perf_counter()
    out_dir = task["out"]
    names = log_names(index, task["record"])
    tmp = {k: tmp_path(out_dir, v) for k, v in names.items()}
    steps = task["steps"]
    error = None
    recorder = None
    measure = None
    try:
        if scene is None:
            scene = sweep.load_run(index)
        clock.lap("scene")
        sim = Simulation(scene)
        clock.lap("build")
        measure = Measure(sim, task["metrics"], task["final_bodies"])
        clock.lap("metrics")
        if tmp:
            from recorder import Recorder

            recorder = Recorder(
                sim,
                mcap_path=tmp.get("mcap"),
                rrd_path=tmp.get("rrd"),
                offload="none",
                replace_partial=True,  # a run killed earlier left it: this run replaces it
            )
            recorder.write(measure.first)
            clock.lap("record")
        n = scene.world.steps if steps is None else steps
        for batch in sim.batches(n, size=batch_size(n, len(scene.bodies))):
            clock.lap("simulate")
            if recorder is not None:
                recorder.write_batch(batch)  # one compiled call packs the batch's MCAP frames
                clock.lap("record")
            measure.add(batch)
            clock.lap("metrics")
        clock.lap("simulate")
    except IsaacError as exc:  # diverged, a non-finite value, a log that cannot be written
        error = " ".join(str(exc).split())
    except Exception as exc:  # noqa: BLE001 - any other failure is this run's row, not the sweep's
        error = " ".join(f"{type(exc).__name__}: {exc}".split())
    except BaseException:
        # interrupted or shut down: the file stays under logs/.tmp, never the final name
        if recorder is not None:
            try:
                recorder.close(complete=False, reason="interrupted")
            except Exception:  # noqa: BLE001 - the process is going away
                pass
        raise
    paths: dict[str, str] = {}  # kind: final path (relative), of the logs finished
    if recorder is not None:
        try:
            sync = moves is None
            if error is None:
                recorder.close(complete=True, sync=sync)
            else:
                recorder.close(complete=False, reason=error, sync=sync)
            for kind, rel in names.items():
                if sync:
                    os.replace(tmp[kind], os.path.join(out_dir, rel))
                paths[kind] = rel
        except (OSError, IsaacError) as exc:
            error = error or " ".join(f"could not finish the log: {exc}".split())
        clock.lap("record")
    row = {"index": index, **(sweep.params(index) if params is None else params)}
    if measure is not None:
        row.update(measure.values())
    clock.lap("metrics")
    row["status"] = "ok" if error is None else "failed"
    row["error"] = error
    # the bytes are the same in logs/.tmp and under the final name
    where = tmp if moves is not None else {k: os.path.join(out_dir, v) for k, v in paths.items()}
    if task["record"] != "none":
        row["log_path"] = paths.get("mcap")
        row["log_sha256"] = sha256_of(where["mcap"]) if "mcap" in paths else None
    if task["record"] == "mcap+rrd":
        row["rrd_path"] = paths.get("rrd")
        row["rrd_sha256"] = sha256_of(where["rrd"]) if "rrd" in paths else None
    if moves is not None:
        moves.extend((tmp[k], os.path.join(out_dir, v)) for k, v in paths.items())
    clock.lap("record")
    row["wall_time_s"] = time.perf_counter() - started
    row["worker"] = worker or _worker_name()
    return row


def warm_up(scene_texts: list[str], scene_path: str, scene_name: str, record: str = "none"):
    """Compile (or load from numba's on-disk cache) the kernels these scenes' settings use: two
    steps of each, through the compiled driver, and recorded when `record` is not "none" (the
    recorder packs a batch's frames in compiled code too). Run once before the fan-out, so the
    workers, which share the cache on one machine, load the kernels instead of each compiling
    them."""
    import tempfile

    from isaac.engine.simulation import Simulation
    from isaac.errors import IsaacError
    from isaac.scene import load_scene_text

    with tempfile.TemporaryDirectory(prefix="isaac-sweep-warm-") as tmp:
        for k, text in enumerate(scene_texts):
            sim = Simulation(load_scene_text(text, source=scene_path, default_name=scene_name))
            recorder = None
            try:
                if record != "none":
                    from recorder import Recorder

                    recorder = Recorder(
                        sim, mcap_path=os.path.join(tmp, f"warm-{k}.mcap"), offload="none"
                    )
                    recorder.write(sim.record())
                for batch in sim.batches(2, size=2):
                    if recorder is not None:
                        recorder.write_batch(batch)
            except IsaacError:
                pass  # a run that fails at once: its kernels are loaded all the same
            finally:
                if recorder is not None:
                    try:
                        recorder.close(complete=False, reason="warm-up", sync=False)
                    except IsaacError:
                        pass
