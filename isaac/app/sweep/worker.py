"""What a Dask worker does: the runs of one chunk, each simulated, measured and recorded in this
process, its log put under its final name only once it is finished, and its row kept on disk.

A run's files, in the sweep's output folder:

- ``logs/.tmp/run-000123.mcap`` (and ``.rrd``): where the recorder writes (as ``.partial``,
  renamed there on close). A run killed or interrupted leaves its file here, never under the
  final name.
- ``logs/run-000123.mcap``: moved there (one rename) once the recorder has closed the file.
- ``rows/run-000123.json``: the run's row, written (temporary name, then a rename) after its
  logs are in place. A chunk that Dask runs again after its worker died finds the rows of the
  runs already done and keeps them: a killed worker costs only the run it was in.

The recorder writes in this process (``offload="none"``): one writer process per run would cost
more than a small run.
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


def row_path(out_dir: str, index: int) -> str:
    return os.path.join(out_dir, ROWS_DIR, f"run-{index:06d}.json")


def sha256_of(path: str) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(1 << 20):
            h.update(chunk)
    return h.hexdigest()


def row_is_complete(out_dir: str, row: dict) -> bool:
    """Whether `row`'s logs are there and are the files the row describes (sha256)."""
    for kind in ("mcap", "rrd"):
        rel = row.get("log_path" if kind == "mcap" else "rrd_path")
        if rel is None:
            continue
        path = os.path.join(out_dir, rel)
        want = row.get("log_sha256" if kind == "mcap" else "rrd_sha256")
        try:
            if sha256_of(path) != want:
                return False
        except OSError:
            return False
    return True


def read_row(out_dir: str, index: int) -> dict | None:
    """Run `index`'s row as a finished run left it, or None (absent, unreadable, or its logs
    not the files it names)."""
    try:
        with open(row_path(out_dir, index), encoding="utf-8") as f:
            row = json.load(f)
    except (OSError, ValueError):
        return None
    if row.get("index") != index or not row_is_complete(out_dir, row):
        return None
    return row


def _write_row(out_dir: str, row: dict) -> None:
    path = row_path(out_dir, row["index"])
    tmp = path + ".tmp"
    with open(tmp, "w", encoding="utf-8") as f:
        json.dump(row, f)  # floats as repr: exact float64 (NaN as NaN)
    os.replace(tmp, path)


def _worker_name() -> str:
    try:
        from distributed import get_worker

        return str(get_worker().address)
    except (ImportError, ValueError):
        return f"pid {os.getpid()}"


def run_chunk(task: dict) -> list[dict]:
    """The rows of the runs of `task` (see `isaac.app.sweep.command._tasks`), in order."""
    rows = []
    for run in task["runs"]:
        row = read_row(task["out"], run["index"])
        if row is None:
            row = run_one(task, run)
        rows.append(row)
    return rows


def run_one(task: dict, run: dict) -> dict:
    """Simulate, measure and (maybe) record one run; its row (status "ok" or "failed")."""
    from isaac.app.sweep.metrics import Measure
    from isaac.engine.simulation import Simulation
    from isaac.errors import IsaacError
    from isaac.scene import load_scene_text

    started = time.perf_counter()
    out_dir, index = task["out"], run["index"]
    names = log_names(index, task["record"])
    tmp = {k: os.path.join(out_dir, TMP_DIR, os.path.basename(v)) for k, v in names.items()}
    steps = task["steps"]
    error = None
    recorder = None
    measure = None
    try:
        scene = load_scene_text(
            run["scene_text"], source=task["scene_path"], default_name=task["scene_name"]
        )
        sim = Simulation(scene)
        measure = Measure(sim, task["metrics"], task["final_bodies"])
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
        n = scene.world.steps if steps is None else steps
        for batch in sim.batches(n, size=64):
            if recorder is not None:
                recorder.write_batch(batch)  # one compiled call packs the batch's MCAP frames
            measure.add(batch)
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
    paths: dict[str, str] = {}
    if recorder is not None:
        try:
            if error is None:
                recorder.close(complete=True)
            else:
                recorder.close(complete=False, reason=error)
            for kind, rel in names.items():
                os.replace(tmp[kind], os.path.join(out_dir, rel))
                paths[kind] = rel
        except (OSError, IsaacError) as exc:
            error = error or " ".join(f"could not finish the log: {exc}".split())
    row = {"index": index, **run["params"]}
    if measure is not None:
        row.update(measure.values())
    row["status"] = "ok" if error is None else "failed"
    row["error"] = error
    if task["record"] != "none":
        row["log_path"] = paths.get("mcap")
        row["log_sha256"] = (
            sha256_of(os.path.join(out_dir, paths["mcap"])) if "mcap" in paths else None
        )
    if task["record"] == "mcap+rrd":
        row["rrd_path"] = paths.get("rrd")
        row["rrd_sha256"] = (
            sha256_of(os.path.join(out_dir, paths["rrd"])) if "rrd" in paths else None
        )
    row["wall_time_s"] = time.perf_counter() - started
    row["worker"] = _worker_name()
    _write_row(out_dir, row)
    return row


def warm_up(scene_texts: list[str], scene_path: str, scene_name: str) -> None:
    """Compile (or load from numba's on-disk cache) the kernels these scenes' settings use: two
    steps of each, through the compiled driver. Run once before the fan-out, so the workers,
    which share the cache on one machine, load the kernels instead of each compiling them."""
    from isaac.engine.simulation import Simulation
    from isaac.errors import SimulationError
    from isaac.scene import load_scene_text

    for text in scene_texts:
        sim = Simulation(load_scene_text(text, source=scene_path, default_name=scene_name))
        try:
            for _ in sim.batches(2, size=2):
                pass
        except SimulationError:
            pass
