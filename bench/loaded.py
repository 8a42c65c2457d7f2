"""Recording on a deliberately loaded machine: `isaac run` with each `--offload` mode, idle, busy.

    .venv/bin/python -m bench.loaded [--reps 5] [--scene scenes/default.yaml] [--out DIR]

Each repetition times, as whole processes, `isaac run SCENE` without files and
`isaac run SCENE --mcap A --rrd B --offload MODE` for MODE in process, thread, none, auto: first
on the machine as it is ("idle": other people's work goes on), then with BUSY_LOOPS busy-loop
processes started by the bench (`busy_loops`), which are stopped before the next repetition
and, whatever happens (an error, Ctrl-C, SIGTERM), before the bench ends. Idle and loaded
passes alternate so that a drift in the shared machine's speed hits both alike.

Figures per command: the loop rate `isaac run` prints (steps/s after the first step, up to the
last step handed to the recorder), the recorded rate (the same steps over the loop time plus
the time the files took to finish, so writers that lag behind are charged), the process's wall
time (start-up and kernel loading included: what a user waits for), and for `auto` the mode it
chose (`isaac run` prints it). Medians and ranges over the repetitions; the fastest mode is
the one with the smallest median wall time.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import re
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
BUSY_LOOPS = 2
REPS = 5  # about 20 s a repetition on the 2-core machine: the whole measurement under 2 minutes
MODES = ("process", "thread", "none", "auto")
RATE_RE = re.compile(r"([0-9.]+) steps/s")
TAKEN_RE = re.compile(r": ([0-9]+) steps of")
FINISH_RE = re.compile(r"files finished ([0-9.]+) s after the last step")
OFFLOAD_RE = re.compile(r"written by offload (\w+)")

# A pure-Python busy loop. It checks every ~10 ms of spinning that the bench that started it is
# still its parent, so even a bench killed by SIGKILL (no `finally`) leaves no loop behind; its
# SIGINT does the default (exit, no traceback), and it runs in a session of its own, so a
# terminal's Ctrl-C reaches only the bench, which stops it.
_LOOP = """
import os, signal, sys
signal.signal(signal.SIGINT, signal.SIG_DFL)
parent = int(sys.argv[1])
while os.getppid() == parent:
    for _ in range(200000):
        pass
"""


def _gone(proc: subprocess.Popen) -> bool:
    return proc.poll() is not None


@contextlib.contextmanager
def busy_loops(n: int = BUSY_LOOPS):
    """Start `n` busy-loop processes (each wants a whole CPU) for the body of the `with`; yields
    their `subprocess.Popen` objects. On leaving, by any path, each is sent SIGTERM, then
    SIGKILL if it has not exited within 2 s, and waited for. While inside, in the main thread,
    a SIGTERM to this process raises SystemExit(143) (unless it already had a handler), so the
    loops are stopped then too."""
    procs: list[subprocess.Popen] = []
    previous = None
    if threading.current_thread() is threading.main_thread():
        if signal.getsignal(signal.SIGTERM) is signal.SIG_DFL:

            def _terminated(signum, frame):
                raise SystemExit(128 + signum)

            previous = signal.signal(signal.SIGTERM, _terminated)
    try:
        for _ in range(n):
            procs.append(
                subprocess.Popen(
                    [sys.executable, "-c", _LOOP, str(os.getpid())],
                    stdin=subprocess.DEVNULL,
                    stdout=subprocess.DEVNULL,
                    stderr=subprocess.DEVNULL,
                    start_new_session=True,
                )
            )
        yield procs
    finally:
        for p in procs:
            if not _gone(p):
                p.terminate()
        for p in procs:
            try:
                p.wait(timeout=2.0)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


def _isaac_run(scene: str, out_dir: Path, offload: str | None, timeout: float) -> dict:
    """One `isaac run SCENE` (with MCAP and .rrd files and `--offload offload` unless offload is
    None) as a whole process; its figures."""
    cmd = [sys.executable, "-m", "isaac", "run", scene, "--quiet"]
    if offload is not None:
        cmd += ["--mcap", str(out_dir / "loaded.mcap"), "--rrd", str(out_dir / "loaded.rrd")]
        cmd += ["--offload", offload, "--force"]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=REPO, timeout=timeout)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or [f"exit {proc.returncode}"]
        raise RuntimeError(f"{' '.join(cmd[2:])}: {tail[0]}")
    out = proc.stdout
    rate = float(RATE_RE.search(out).group(1))
    timed = int(TAKEN_RE.search(out).group(1)) - 1
    row = {"wall_s": wall, "loop_steps_per_s": rate, "steps_per_s": rate}
    if offload is not None:
        finish = float(FINISH_RE.search(out).group(1))
        row["finish_s"] = finish
        row["steps_per_s"] = timed / (timed / rate + finish)
        row["chose"] = OFFLOAD_RE.search(out).group(1)
    return row


def _load() -> float | None:
    try:
        return os.getloadavg()[0]
    except OSError:
        return None


def _summary(rows: list[dict], key: str) -> dict:
    values = [r[key] for r in rows]
    return {"median": statistics.median(values), "min": min(values), "max": max(values)}


def measure(scene: str = "scenes/default.yaml", reps: int = REPS, timeout: float = 300.0) -> dict:
    """`reps` alternating idle and loaded passes over the five commands; medians and ranges."""
    cases = ("no files", *MODES)
    runs: dict[str, dict[str, list[dict]]] = {c: {k: [] for k in cases} for c in ("idle", "loaded")}
    loads: dict[str, list[float]] = {"idle": [], "loaded": []}
    with tempfile.TemporaryDirectory(prefix="isaac-bench-loaded-") as tmp:
        out_dir = Path(tmp)
        _isaac_run(scene, out_dir, "none", timeout)  # the kernels compiled / cached before timing
        for _rep in range(reps):
            for condition in ("idle", "loaded"):
                with busy_loops(BUSY_LOOPS if condition == "loaded" else 0):
                    for case in cases:
                        offload = None if case == "no files" else case
                        load = _load()
                        if load is not None:
                            loads[condition].append(load)
                        runs[condition][case].append(_isaac_run(scene, out_dir, offload, timeout))
    result: dict = {
        "kind": "loaded",
        "scene": scene,
        "reps": reps,
        "busy_loops": BUSY_LOOPS,
        "cpus": len(os.sched_getaffinity(0))
        if hasattr(os, "sched_getaffinity")
        else os.cpu_count(),
        "runs": runs,
        "load_average": {c: [min(v), max(v)] if v else None for c, v in loads.items()},
    }
    for condition, by_case in runs.items():
        table = {}
        for case, rows in by_case.items():
            table[case] = {k: _summary(rows, k) for k in ("wall_s", "steps_per_s")}
            if case != "no files":
                table[case]["loop_steps_per_s"] = _summary(rows, "loop_steps_per_s")
        chose = sorted({r["chose"] for r in by_case["auto"]})
        fastest = min(MODES[:-1], key=lambda m: table[m]["wall_s"]["median"])
        best = table[fastest]["wall_s"]["median"]
        auto_wall = table["auto"]["wall_s"]["median"]
        result[condition] = {
            "table": table,
            "auto_chose": chose,
            "fastest": fastest,
            "auto_wall_over_fastest": auto_wall / best,
            # good: auto chose the fastest mode, or ran within the fastest's own spread
            "auto_picks_well": chose == [fastest] or auto_wall <= table[fastest]["wall_s"]["max"],
        }
    return result


def _fmt(s: dict, digits: int) -> str:
    return f"{s['median']:.{digits}f} ({s['min']:.{digits}f}-{s['max']:.{digits}f})"


def markdown(result: dict) -> str:
    la = result["load_average"]
    load = ", ".join(f"{c} {v[0]:.1f}-{v[1]:.1f}" for c, v in la.items() if v is not None)
    lines = [
        f"Recording on a loaded machine: `isaac run {result['scene']}` as whole processes, "
        f"without files and with `--mcap A --rrd B --offload MODE`; idle passes alternating "
        f"with passes beside {result['busy_loops']} busy-loop processes started by the bench, "
        f"{result['reps']} of each; medians (range); {result['cpus']} CPUs; one-minute load "
        f"average when each command started: {load}. steps/s: the steps over the loop time "
        f"plus the time the files took to finish; wall: the whole process.",
        "",
        "| command | idle steps/s | idle wall, s | loaded steps/s | loaded wall, s |",
        "|---|---|---|---|---|",
    ]
    for case in ("no files", *MODES):
        name = "no files" if case == "no files" else f"--offload {case}"
        cells = []
        for condition in ("idle", "loaded"):
            t = result[condition]["table"][case]
            cells += [_fmt(t["steps_per_s"], 0), _fmt(t["wall_s"], 2)]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    lines.append("")
    for condition in ("idle", "loaded"):
        r = result[condition]
        lines.append(
            f"- {condition}: auto chose {', '.join(r['auto_chose'])}; fastest by wall time "
            f"{r['fastest']}; auto's wall time {r['auto_wall_over_fastest']:.2f}x the fastest's"
            + (
                " (auto picks well)"
                if r["auto_picks_well"]
                else " (auto picks badly: slower than the fastest's whole range)"
            )
            + "."
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m bench.loaded", description=__doc__.split("\n")[0]
    )
    parser.add_argument("--scene", default="scenes/default.yaml")
    parser.add_argument("--reps", type=int, default=REPS)
    parser.add_argument("--out", default=str(REPO / "bench" / "results"))
    args = parser.parse_args(argv)
    t0 = time.perf_counter()
    result = measure(args.scene, args.reps)
    result["elapsed_s"] = time.perf_counter() - t0
    text = markdown(result)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "loaded.json").write_text(json.dumps(result, indent=1) + "\n")
    (out / "loaded.md").write_text(text + "\n")
    print(text)
    print(
        f"bench.loaded: {result['elapsed_s']:.0f} s; wrote {out / 'loaded.json'}", file=sys.stderr
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
