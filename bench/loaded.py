"""Recording on a deliberately loaded machine: `isaac run` with each `--offload` mode, idle, busy.

    .venv/bin/python -m bench.loaded [--reps 4] [--scene scenes/default.yaml] [--out DIR]

Each repetition times, as whole processes, `isaac run SCENE` without files and
`isaac run SCENE --mcap A --rrd B --offload MODE` for MODE in process, thread, none, auto, and
the same with `--mcap A` alone: first on the machine as it is ("idle": other people's work goes
on), then with BUSY_LOOPS busy-loop processes started by the bench (`busy_loops`), which are
stopped before the next repetition and, whatever happens (an error, Ctrl-C, SIGTERM), before
the bench ends. Idle and loaded
passes alternate so that a drift in the shared machine's speed hits both alike.

Figures per command: the loop rate `isaac run` prints (steps/s after the first step, up to the
last step handed to the recorder), the recorded rate (the same steps over the loop time plus
the time the files took to finish, so writers that lag behind are charged), the process's wall
time (start-up and kernel loading included: what a user waits for), and for `auto` the mode it
chose (`isaac run` prints it). Medians and ranges over the repetitions; the fastest mode is
the explicit one with the smallest median wall time; auto picks well when it chose that mode or
its wall time was at most PICKS_WELL times the fastest's in the same pass (median over passes).
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

from bench.suite import meta_info, provenance

REPO = Path(__file__).resolve().parents[1]
BUSY_LOOPS = 2
REPS = 4  # about 35 s a repetition on the 2-core machine: the whole measurement under 3 minutes
MODES = ("process", "thread", "none", "auto")
# the command writes both files; MCAP alone is the case where `auto` may choose writer
# processes on 2 CPUs (one writer: one idle CPU besides the simulation's)
# auto picks well when it chose the fastest mode or its run took at most this times as long
PICKS_WELL = 1.05
FILE_SETS = {"mcap+rrd": ("--mcap", "--rrd"), "mcap": ("--mcap",)}
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


def _isaac_run(scene: str, out_dir: Path, files: str | None, offload: str, timeout: float) -> dict:
    """One `isaac run SCENE` as a whole process, without files (files None) or with FILE_SETS[files]
    written by `--offload offload`; its figures."""
    cmd = [sys.executable, "-m", "isaac", "run", scene, "--quiet"]
    if files is not None:
        for flag in FILE_SETS[files]:
            cmd += [flag, str(out_dir / f"loaded.{flag[2:]}")]
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
    if files is not None:
        finish = float(FINISH_RE.search(out).group(1))
        row["finish_s"] = finish
        row["steps_per_s"] = timed / (timed / rate + finish)
        row["chose"] = OFFLOAD_RE.search(out).group(1)
    return row


def _machine() -> dict:
    """What the machine looked like as a command started: the one-minute load average (what
    `choose_offload` reads; it lags the truth by about a minute) and the processes running or
    runnable at that instant (/proc/stat, this bench's own process included)."""
    out: dict = {}
    with contextlib.suppress(OSError):
        out["load_1min"] = os.getloadavg()[0]
    with contextlib.suppress(OSError, ValueError, StopIteration):
        with open("/proc/stat") as f:
            line = next(x for x in f if x.startswith("procs_running"))
        out["running"] = int(line.split()[1])
    return out


def _summary(rows: list[dict], key: str) -> dict:
    values = [r[key] for r in rows]
    return {"median": statistics.median(values), "min": min(values), "max": max(values)}


def _cases() -> list[tuple[str, str | None, str]]:
    """(key, file set, offload) of each command of a pass: first without files."""
    cases = [("no files", None, "none")]
    cases += [(f"{files} {mode}", files, mode) for files in FILE_SETS for mode in MODES]
    return cases


def measure(scene: str = "scenes/default.yaml", reps: int = REPS, timeout: float = 300.0) -> dict:
    """`reps` alternating idle and loaded passes over the commands; medians and ranges, and per
    file set what `auto` chose against the fastest explicit mode."""
    cases = _cases()
    conditions = ("idle", "loaded")
    runs: dict = {c: {key: [] for key, _, _ in cases} for c in conditions}
    seen: dict = {c: [] for c in conditions}
    with tempfile.TemporaryDirectory(prefix="isaac-bench-loaded-") as tmp:
        out_dir = Path(tmp)
        # the kernels compiled (or loaded from the cache) before anything is timed
        _isaac_run(scene, out_dir, "mcap+rrd", "none", timeout)
        for _rep in range(reps):
            for condition in conditions:
                with busy_loops(BUSY_LOOPS if condition == "loaded" else 0):
                    for key, files, offload in cases:
                        machine = _machine()
                        seen[condition].append(machine)
                        row = _isaac_run(scene, out_dir, files, offload, timeout)
                        runs[condition][key].append({**row, **machine})
    return summarise(scene, reps, runs, seen)


def summarise(scene: str, reps: int, runs: dict, seen: dict) -> dict:
    """`measure`'s result from its rows (runs: condition -> case -> one row a repetition; seen:
    condition -> `_machine()` at each command's start)."""
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    result: dict = {
        "kind": "loaded",
        "scene": scene,
        "reps": reps,
        "busy_loops": BUSY_LOOPS,
        "cpus": cpus,
        "runs": runs,
        "machine": {
            c: {
                k: [min(m[k] for m in ms), max(m[k] for m in ms)]
                for k in ("load_1min", "running")
                if ms and all(k in m for m in ms)
            }
            for c, ms in seen.items()
        },
    }
    for condition, by_case in runs.items():
        table = {}
        for key, rows in by_case.items():
            table[key] = {k: _summary(rows, k) for k in ("wall_s", "steps_per_s")}
            if key != "no files":
                table[key]["loop_steps_per_s"] = _summary(rows, "loop_steps_per_s")
        auto = {}
        for files in FILE_SETS:
            chose = sorted({r["chose"] for r in by_case[f"{files} auto"]})
            explicit = [m for m in MODES if m != "auto"]
            fastest = min(explicit, key=lambda m: table[f"{files} {m}"]["wall_s"]["median"])
            # auto against the fastest in the same pass (a few seconds apart: the same machine)
            ratios = [
                a["wall_s"] / f["wall_s"]
                for a, f in zip(by_case[f"{files} auto"], by_case[f"{files} {fastest}"])
            ]
            ratio = statistics.median(ratios)
            auto[files] = {
                "chose": chose,
                "fastest": fastest,
                "auto_wall_over_fastest": ratio,
                "auto_wall_over_fastest_range": [min(ratios), max(ratios)],
                # well: auto chose the fastest mode, or took at most PICKS_WELL times its time
                "picks_well": chose == [fastest] or ratio <= PICKS_WELL,
            }
        result[condition] = {"table": table, "auto": auto}
    return result


def _fmt(s: dict, digits: int) -> str:
    return f"{s['median']:.{digits}f} ({s['min']:.{digits}f}-{s['max']:.{digits}f})"


def markdown(result: dict) -> str:
    said = []
    for condition, m in result["machine"].items():
        parts = []
        if "load_1min" in m:
            parts.append(f"load average {m['load_1min'][0]:.1f}-{m['load_1min'][1]:.1f}")
        if "running" in m:
            parts.append(f"{m['running'][0]}-{m['running'][1]} processes running")
        said.append(f"{condition} {', '.join(parts)}")
    lines = [
        f"Recording on a loaded machine, {provenance(result['meta'])}: "
        f"`isaac run {result['scene']}` as whole processes, "
        f"without files, with `--mcap A --rrd B` and with `--mcap A` alone, each file set with "
        f"`--offload` process, thread, none and auto; idle passes alternating with passes "
        f"beside {result['busy_loops']} busy-loop processes started by the bench, "
        f"{result['reps']} of each; medians (range); {result['cpus']} CPUs; as each command "
        f"started: {'; '.join(said)} (the bench's own included). steps/s: the steps over the "
        f"loop time plus the time the files took to finish; wall: the whole process.",
        "",
        "| command | idle steps/s | idle wall, s | loaded steps/s | loaded wall, s |",
        "|---|---|---|---|---|",
    ]
    for key, files, offload in _cases():
        name = "no files" if files is None else f"{' '.join(FILE_SETS[files])} --offload {offload}"
        cells = []
        for condition in ("idle", "loaded"):
            t = result[condition]["table"][key]
            cells += [_fmt(t["steps_per_s"], 0), _fmt(t["wall_s"], 2)]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    lines.append("")
    for condition in ("idle", "loaded"):
        for files, r in result[condition]["auto"].items():
            lo, hi = r["auto_wall_over_fastest_range"]
            lines.append(
                f"- {condition}, {' '.join(FILE_SETS[files])}: auto chose "
                f"{', '.join(r['chose'])}; fastest by wall time {r['fastest']}; auto's wall "
                f"time {r['auto_wall_over_fastest']:.2f}x the fastest's in the same pass "
                f"({lo:.2f}-{hi:.2f})"
                + (
                    " (auto picks well)"
                    if r["picks_well"]
                    else f" (auto picks badly: more than {PICKS_WELL}x)"
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
    result["meta"] = meta_info(args.reps, [])
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
