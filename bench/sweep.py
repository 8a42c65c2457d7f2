"""Sweep throughput (issue 13): runs per second of `isaac sweep`, and where a run's time goes.

`python -m bench.sweep` (also run by `python -m bench`, `make bench`) prints the tables;
`--json` prints one JSON line instead (what the suite reads).

Cases, as the issue words them: 1,000 runs of scenes/bounce.yaml (2 bodies) at 200 steps each,
and 100 runs of a 100-body pile (bench.scenes' pile-100: 100 polygons in a container of 3
concrete walls) at 200 steps; each with `record: none` and `record: mcap`, on a local cluster
of 1 and of 2 worker processes. The bounce runs draw the box's sideways speed and
restitution, the pile runs the generator's seed.

How:
- Both clusters (1 and 2 workers) are started once (`isaac.app.sweep.cluster.start_cluster`,
  as `isaac sweep` starts its own; the start is timed and reported apart) and warmed by a small
  sweep of each case, so every kernel is loaded in every worker before the clock starts.
- Then `reps` repetitions, interleaved: in each, every case x record on 1 worker and then on 2
  (`isaac.app.sweep.execute(..., client=...)`, no plots). runs/s = runs / the sweep's wall
  time (reading the file, checking every run's scene, warm-up, fan-out, table). The speed-up is
  taken per repetition (2-worker rate / 1-worker rate of the same case, a few seconds apart),
  then the median: this shared machine's speed drifts by more than the effect between minutes.
- Where the time goes: the sweep's own phases (SweepResult.phases), per run: scene checked and
  loaded on the cluster, time inside the runs on their workers (the rows' wall_time_s), and
  scheduling (the fan-out's wall time x workers less the time inside runs: Dask, transfers,
  idle workers at the end); and, in this process, one chunk of runs timed part by part
  (isaac.app.sweep.worker.Clock): scene (loaded once per run by the check), build, simulate,
  record, metrics, row.
- Whole command: `isaac sweep` (cluster start, every phase, no plots) as a process, timed
  from outside, once per worker count, for the bounce case without recording; and the plots of
  one 1,000-run table, timed apart.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
STEPS = 200
CASES = (
    # (name, runs, the runs: section of the sweep file)
    (
        "bounce",
        1000,
        "  random:\n    n: {n}\n    seed: 42\n"
        "    bodies.box.velocity.x: {{uniform: [-1.5, 1.5]}}\n"
        "    bodies.box.restitution: {{uniform: [0.2, 0.9]}}\n",
    ),
    (
        "pile-100",
        100,
        "  random:\n    n: {n}\n    seed: 42\n"
        "    generators.0.pile.seed: {{integers: [0, 1000000]}}\n",
    ),
)
RECORDS = ("none", "mcap")
WORKERS = (1, 2)
# the targets on this 2-core machine
SPEEDUP_TARGET = 1.7  # 2-worker runs/s over 1-worker runs/s
SMALL_PLAIN_TARGET = 300.0  # bounce, no recording, 2 workers, runs/s
SMALL_MCAP_TARGET = 100.0  # bounce, MCAP, 2 workers, runs/s
PROFILE_RUNS = {"bounce": 300, "pile-100": 20}  # runs timed part by part in this process


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _load() -> str:
    try:
        return " ".join(Path("/proc/loadavg").read_text().split()[:3])
    except OSError:
        return "?"


def _spin(_=None) -> float:
    """Seconds of a fixed pure-Python loop (CPU only)."""
    t0 = time.perf_counter()
    total = 0
    for i in range(3_000_000):
        total += i * i
    return time.perf_counter() - t0


def machine_scaling() -> float:
    """What two processes get done at once against one alone, on this machine now: a fixed CPU
    loop timed in 1 process, then in 2 processes started together (2 x t1 / the slower t2).
    2.0 on two free cores; about 1.0 while other work holds one of them. The ceiling of any
    speed-up from 1 to 2 workers at that moment."""
    import multiprocessing as mp

    ctx = mp.get_context("spawn")
    with ctx.Pool(2) as pool:
        pool.map(_spin, [0, 0])  # both processes started and warm
        one = pool.apply(_spin)
        two = pool.map(_spin, [0, 1], chunksize=1)
    return 2.0 * one / max(two)


def write_sweeps(folder: Path, scale: float = 1.0) -> dict:
    """{(case, record): sweep file} in `folder`, with the pile's scene beside them."""
    from bench.scenes import PILE_SEED, _generator_yaml, _pile_params

    folder.mkdir(parents=True, exist_ok=True)
    (folder / "pile-100.yaml").write_text(
        _generator_yaml("pile-100", STEPS, "pile", _pile_params(100, PILE_SEED))
    )
    scenes = {"bounce": ROOT / "scenes" / "bounce.yaml", "pile-100": folder / "pile-100.yaml"}
    out = {}
    for name, runs, section in CASES:
        n = max(2, round(runs * scale))
        for record in RECORDS:
            path = folder / f"{name}-{record}.sweep.yaml"
            path.write_text(
                f"scene: {scenes[name]}\nruns:\n{section.format(n=n)}"
                f"steps: {STEPS}\nrecord: {record}\n"
            )
            out[name, record] = path
    return out


def _sweep_once(path: Path, out: Path, client) -> dict:
    from isaac.app.sweep import execute

    r = execute(str(path), str(out), client=client, plots=False)
    rows = r.table.to_pylist()
    inside = sum(row["wall_time_s"] for row in rows)
    shutil.rmtree(out, ignore_errors=True)  # 1,000 logs a sweep: the disk is shared too
    return dict(
        runs=len(rows),
        failed=r.failed,
        seconds=r.seconds,
        runs_per_s=len(rows) / r.seconds,
        workers=r.workers,
        phases=r.phases,
        inside_runs_s=inside,
    )


def profile_chunk(path: Path, runs: int) -> dict:
    """One chunk of `runs` runs of sweep `path` in this process, timed part by part: ms per
    run of each part (scene: the check's load, once per run; then worker.Clock's parts)."""
    from isaac.app.sweep import worker as work
    from isaac.app.sweep.command import _tasks
    from isaac.app.sweep.spec import load_runs, load_sweep

    sweep = load_sweep(path)
    indices = list(range(min(runs, sweep.n_runs)))
    with tempfile.TemporaryDirectory(prefix="isaac-bench-sweep-") as tmp:
        work.prepare_out(sweep, tmp)
        work.warm_up([sweep.run_scene_text(0)], sweep.scene_path, sweep.scene_name, sweep.record)
        t0 = time.perf_counter()
        loaded = load_runs(sweep, indices)
        scene_s = time.perf_counter() - t0
        clock = work.Clock()
        t0 = time.perf_counter()
        work.run_chunk(_tasks(sweep, [indices], tmp)[0], sweep, loaded, clock=clock)
        chunk_s = time.perf_counter() - t0
    n = len(indices)
    parts = {"scene": 1e3 * scene_s / n}
    parts.update({k: 1e3 * v / n for k, v in clock.seconds.items() if k != "scene"})
    parts["other"] = 1e3 * chunk_s / n - sum(v for k, v in parts.items() if k != "scene")
    return dict(runs=n, ms_per_run=parts, total_ms=sum(parts.values()))


def whole_command(path: Path, workers: int, out: Path) -> dict:
    """`isaac sweep PATH --workers N --no-plots` as a process, timed from outside."""
    cmd = [sys.executable, "-m", "isaac", "sweep", str(path), "--out", str(out)]
    cmd += ["--workers", str(workers), "--no-plots", "--quiet"]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, timeout=900)
    seconds = time.perf_counter() - t0
    shutil.rmtree(out, ignore_errors=True)
    if proc.returncode != 0:
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or ["?"]
        return dict(workers=workers, error=tail[0])
    return dict(workers=workers, seconds=seconds)


def measure(reps: int, scale: float = 1.0) -> dict:
    from isaac.app.sweep.cluster import start_cluster

    result: dict = dict(kind="sweep", steps=STEPS, reps=reps, load_before=_load())
    with tempfile.TemporaryDirectory(prefix="isaac-bench-sweep-") as tmp:
        folder = Path(tmp)
        sweeps = write_sweeps(folder, scale)
        warm = write_sweeps(folder / "warm", 0.02)
        clients, started = {}, {}
        try:
            for n in WORKERS:
                t0 = time.perf_counter()
                clients[n] = start_cluster(None, n)
                started[n] = time.perf_counter() - t0
                for path in warm.values():  # every kernel loaded in every worker
                    _sweep_once(path, folder / "o", clients[n][0])
            result["cluster_start_s"] = started
            samples: dict = {}
            ceilings = []
            for rep in range(reps):
                ceilings.append(machine_scaling())
                log(f"  sweep rep {rep}: 2 processes do {ceilings[-1]:.2f}x one's work now")
                for name, _, _ in CASES:
                    for record in RECORDS:
                        for n in WORKERS:
                            s = _sweep_once(sweeps[name, record], folder / "o", clients[n][0])
                            samples.setdefault(f"{name}/{record}/{n}", []).append(s)
                            log(
                                f"  sweep rep {rep} {name:8s} {record:4s} {n} worker(s): "
                                f"{s['runs_per_s']:7.1f} runs/s ({s['seconds']:.2f} s"
                                + (f", {s['failed']} failed" if s["failed"] else "")
                                + ")"
                            )
        finally:
            for client, cluster in clients.values():
                client.close()
                cluster.close()
        result["cases"] = _aggregate(samples, ceilings)
        result["machine_scaling"] = ceilings
        result["profile"] = {
            f"{name}/{record}": profile_chunk(sweeps[name, record], PROFILE_RUNS[name])
            for name, _, _ in CASES
            for record in RECORDS
        }
        result["whole_command"] = [
            whole_command(sweeps["bounce", "none"], n, folder / "cmd") for n in WORKERS
        ]
        result["plots_s"] = _plots_time(sweeps["bounce", "none"], folder / "plots")
    result["load_after"] = _load()
    result["targets"] = targets(result)
    return result


def _plots_time(path: Path, out: Path) -> float | None:
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return None
    from isaac.app.sweep import execute
    from isaac.app.sweep.plots import plot_all

    r = execute(str(path), str(out), workers=1, plots=False)
    t0 = time.perf_counter()
    plot_all(r.table, r.sweep, str(out))
    return time.perf_counter() - t0


def _aggregate(samples: dict, ceilings: list[float]) -> list[dict]:
    out = []
    for name, _, _ in CASES:
        for record in RECORDS:
            one, two = samples[f"{name}/{record}/1"], samples[f"{name}/{record}/2"]
            row = dict(case=name, record=record, runs=one[0]["runs"])
            for n, ss in ((1, one), (2, two)):
                rates = [s["runs_per_s"] for s in ss]
                med = statistics.median(rates)
                pick = min(ss, key=lambda s: abs(s["runs_per_s"] - med))  # the median sweep
                runs = pick["runs"]
                ph = pick["phases"]
                row[f"w{n}"] = dict(
                    runs_per_s=med,
                    runs_per_s_range=(min(rates), max(rates)),
                    failed=max(s["failed"] for s in ss),
                    # per run (ms), from the median sweep
                    check_ms=1e3 * ph.get("check", 0.0) * n / runs,
                    inside_ms=1e3 * pick["inside_runs_s"] / runs,
                    scheduling_ms=1e3 * (ph.get("runs", 0.0) * n - pick["inside_runs_s"]) / runs,
                    # per sweep (s)
                    fixed_s={k: ph.get(k, 0.0) for k in ("read", "cluster", "warm_up", "table")},
                    seconds=pick["seconds"],
                )
            ratios = [b["runs_per_s"] / a["runs_per_s"] for a, b in zip(one, two)]
            row["speedup"] = statistics.median(ratios)
            row["speedup_range"] = (min(ratios), max(ratios))
            # the speed-up as a share of what the machine gave two processes in that repetition
            row["speedup_of_ceiling"] = statistics.median(r / c for r, c in zip(ratios, ceilings))
            out.append(row)
    return out


def targets(result: dict) -> list[dict]:
    by = {(c["case"], c["record"]): c for c in result["cases"]}
    out = []
    for c in result["cases"]:
        out.append(
            dict(
                what=f"speed-up 1 -> 2 workers, {c['case']}, record {c['record']}",
                limit=f">= {SPEEDUP_TARGET}",
                value=c["speedup"],
                met=c["speedup"] >= SPEEDUP_TARGET,
            )
        )
    for record, limit in (("none", SMALL_PLAIN_TARGET), ("mcap", SMALL_MCAP_TARGET)):
        v = by["bounce", record]["w2"]["runs_per_s"]
        out.append(
            dict(
                what=f"runs/s, bounce, record {record}, 2 workers",
                limit=f">= {limit:g}",
                value=v,
                met=v >= limit,
            )
        )
    return [dict(kind="target", engine="isaac sweep", **t) for t in out]


def markdown(result: dict) -> str:
    if result.get("error"):
        return f"Sweep throughput: not measured ({result['error']})."
    lines = [
        f"Sweep throughput (`isaac sweep`, bench/sweep.py): {STEPS} steps a run, local cluster "
        f"already started and warmed (its start: "
        + ", ".join(f"{n} worker(s) {s:.1f} s" for n, s in result["cluster_start_s"].items())
        + f"); {result['reps']} interleaved repetitions, medians (range); speed-up per "
        f"repetition, then the median. Load average before {result['load_before']}, after "
        f"{result['load_after']} (a shared machine: other people's tests ran beside it). "
        "What 2 processes got done at once against one alone, measured before each repetition "
        "(a CPU loop; the ceiling of any 1 -> 2 worker speed-up then): "
        + ", ".join(f"{c:.2f}x" for c in result.get("machine_scaling", []))
        + ".",
        "",
        "| case | record | runs | 1 worker, runs/s | 2 workers, runs/s | speed-up | speed-up / "
        "machine's | per run on 2 workers, ms: check / in run / scheduling |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for c in result["cases"]:
        w1, w2 = c["w1"], c["w2"]
        lines.append(
            f"| {c['case']} | {c['record']} | {c['runs']} | {w1['runs_per_s']:.1f} "
            f"({w1['runs_per_s_range'][0]:.0f}–{w1['runs_per_s_range'][1]:.0f}) | "
            f"{w2['runs_per_s']:.1f} ({w2['runs_per_s_range'][0]:.0f}–"
            f"{w2['runs_per_s_range'][1]:.0f}) | {c['speedup']:.2f} "
            f"({c['speedup_range'][0]:.2f}–{c['speedup_range'][1]:.2f}) | "
            f"{c['speedup_of_ceiling']:.2f} | {w2['check_ms']:.2f} / {w2['inside_ms']:.2f} / "
            f"{w2['scheduling_ms']:.2f} |"
        )
    lines += [
        "",
        "Fixed cost per sweep on 2 workers, s (read the sweep file / scatter it to the workers"
        " / warm-up / table): "
        + "; ".join(
            f"{c['case']} {c['record']}: "
            + " / ".join(f"{v:.2f}" for v in c["w2"]["fixed_s"].values())
            for c in result["cases"]
        )
        + ".",
        "",
        "Inside one worker (one chunk in one process), ms per run:",
        "",
        "| case | record | scene (check's load) | build | simulate | record | metrics | row "
        "| other | total |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for key, p in result["profile"].items():
        case, record = key.split("/")
        m = p["ms_per_run"]
        lines.append(
            f"| {case} | {record} | "
            + " | ".join(
                f"{m[k]:.3f}"
                for k in ("scene", "build", "simulate", "record", "metrics", "row", "other")
            )
            + f" | {p['total_ms']:.3f} |"
        )
    wc = result.get("whole_command", [])
    if wc:
        parts = []
        for w in wc:
            if "error" in w:
                parts.append(f"{w['workers']} worker(s): failed ({w['error']})")
            else:
                rate = next(c["runs"] for c in result["cases"] if c["case"] == "bounce")
                parts.append(
                    f"{w['workers']} worker(s) {w['seconds']:.1f} s ({rate / w['seconds']:.0f} "
                    "runs/s)"
                )
        lines += [
            "",
            "Whole command, bounce without recording (`isaac sweep --workers N --no-plots`, "
            "a process timed from outside: Python start, cluster start, every phase): "
            + "; ".join(parts)
            + "."
            + (
                f" The plots of that 1,000-run table: {result['plots_s']:.1f} s."
                if result.get("plots_s") is not None
                else ""
            ),
        ]
    lines += ["", "| target | limit | measured | met |", "|---|---|---|---|"]
    for t in result["targets"]:
        lines.append(
            f"| {t['what']} | {t['limit']} | {t['value']:.3g} | {'yes' if t['met'] else '**no**'} |"
        )
    return "\n".join(lines) + "\n"


# This machine's speed drifts by up to 40 % within a second (a fixed loop in one process: 0.14 to
# 0.20 s, three times in a row) and a 1,000-run bounce sweep lasts about one: with 3 repetitions
# the median speed-up of one pass was 1.59, of the next (9 repetitions) 1.86, on the same main.
REPS = 9


def run_subprocess(env: dict | None = None, reps: int = REPS, timeout: float = 1800.0) -> dict:
    """`measure` in a process of its own (what bench.suite runs): the result, or
    {"kind": "sweep", "error": ...}."""
    cmd = [sys.executable, "-m", "bench.sweep", "--json", "--reps", str(reps)]
    try:
        proc = subprocess.run(
            cmd, capture_output=True, text=True, cwd=ROOT, env=env, timeout=timeout
        )
    except subprocess.TimeoutExpired:
        return dict(kind="sweep", error=f"timed out after {timeout:.0f} s")
    if proc.returncode != 0:
        tail = (proc.stderr or "").strip().splitlines()[-1:] or [f"exit {proc.returncode}"]
        return dict(kind="sweep", error=tail[0])
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench.sweep", description=__doc__.split("\n")[0])
    p.add_argument("--reps", type=int, default=REPS, help="repetitions (default: %(default)s)")
    p.add_argument(
        "--scale", type=float, default=1.0, help="fraction of the runs (a quick look: 0.1)"
    )
    p.add_argument("--json", action="store_true", help="print one JSON line (the suite reads it)")
    args = p.parse_args(argv)
    os.environ.setdefault("PYTHONWARNINGS", "ignore")
    result = measure(args.reps, args.scale)
    if args.json:
        print(json.dumps(result))
    else:
        print(markdown(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
