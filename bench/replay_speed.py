"""Replay speed against the original run: `isaac run SCENE --mcap` vs `isaac replay` of its log.

    .venv/bin/python bench/replay_speed.py [--scene scenes/pile.yaml] [--reps 3] [--out DIR]

Each repetition runs the two commands one after the other (interleaved, so machine load hits both
alike) as whole processes and reads two figures from each:
- the loop rate (steps/s) each command reports, measured after its first step (which also loads
  the compiled kernels): `isaac run` prints it, `isaac replay --json` writes ``steps_per_s``;
  `isaac run` also prints how long its files took to finish after the last step, which counts
  as part of the run (``time_ratio``) or is left out (``loop_time_ratio``, stricter);
- the wall time of the whole process (start-up, kernel loading, closing the file included).
Prints one line per repetition, then the medians and the ratios replay/original as JSON (the
median of the per-repetition ratios, and from the best repetition of each side); `compare` is
what `bench.recording` calls for the suite's replay row. The target
(issue "replay") is a replay no more than 20% slower than the original run: time ratio <= 1.2.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

# run from the checkout this script sits in (a copy of the repo works too: `python -m isaac`
# imports the package from the working directory)
REPO = Path(__file__).resolve().parents[1]
RATE_RE = re.compile(r"([0-9.]+) steps/s")
TAKEN_RE = re.compile(r": ([0-9]+) steps of")
FINISH_RE = re.compile(r"files finished ([0-9.]+) s after the last step")


def _isaac(*args: str) -> tuple[float, str]:
    t0 = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-m", "isaac", *args], capture_output=True, text=True, cwd=REPO
    )
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(
            f"isaac {' '.join(args)} failed ({proc.returncode}): "
            f"{proc.stderr.strip() or proc.stdout.strip()}"
        )
    return wall, proc.stdout


def compare(scene: str, reps: int, out_dir: Path, steps: int | None = None) -> dict:
    """`reps` interleaved repetitions of `isaac run SCENE --mcap LOG` and `isaac replay LOG`;
    returns the repetitions (``rows``), the medians and the ratios replay/original."""
    out_dir.mkdir(parents=True, exist_ok=True)
    log = out_dir / (Path(scene).stem + ".mcap")
    report = out_dir / "replay.json"
    extra = [] if steps is None else ["--steps", str(steps)]
    # warm-up: compile (or load) the kernels once so neither side of repetition 0 pays for it
    _isaac("run", scene, "--steps", "2", "--mcap", str(log), "--quiet")
    _isaac("replay", str(log))
    rows = []
    for rep in range(reps):
        run_wall, run_out = _isaac("run", scene, *extra, "--mcap", str(log), "--quiet")
        run_rate = float(RATE_RE.search(run_out).group(1))
        # the run's recording ends when its files are finished (the writers' last steps,
        # summary, index): that tail is part of the run's time per step too
        timed = int(TAKEN_RE.search(run_out).group(1)) - 1
        finish = float(FINISH_RE.search(run_out).group(1))
        replay_wall, replay_out = _isaac("replay", str(log), "--json", str(report))
        result = json.loads(report.read_text())
        if not result["identical"]:
            raise RuntimeError(f"the replay diverged: {replay_out.strip()}")
        rows.append(
            dict(
                rep=rep,
                steps=result["steps_compared"],
                run_steps_per_s=run_rate,
                run_finish_s=finish,
                run_with_finish_steps_per_s=timed / (timed / run_rate + finish),
                replay_steps_per_s=result["steps_per_s"],
                run_wall_s=run_wall,
                replay_wall_s=replay_wall,
            )
        )
    med = {
        k: statistics.median(r[k] for r in rows)
        for k in (
            "run_steps_per_s",
            "run_with_finish_steps_per_s",
            "run_finish_s",
            "replay_steps_per_s",
            "run_wall_s",
            "replay_wall_s",
        )
    }
    return dict(
        scene=scene,
        steps=rows[0]["steps"],
        reps=reps,
        log_bytes=os.path.getsize(log),
        rows=rows,
        **{f"median_{k}": v for k, v in med.items()},
        # time per step of the replay over time per step of the original run, its files'
        # finishing included (<= 1.2 required), per repetition (the two commands a few seconds
        # apart), then the median
        time_ratio=statistics.median(
            r["run_with_finish_steps_per_s"] / r["replay_steps_per_s"] for r in rows
        ),
        # the same against the run's loop alone (its files' finishing left out): stricter
        loop_time_ratio=statistics.median(
            r["run_steps_per_s"] / r["replay_steps_per_s"] for r in rows
        ),
        wall_time_ratio=statistics.median(r["replay_wall_s"] / r["run_wall_s"] for r in rows),
        # the same from the best repetition of each (least disturbed by other load)
        best_loop_time_ratio=max(r["run_steps_per_s"] for r in rows)
        / max(r["replay_steps_per_s"] for r in rows),
        best_wall_time_ratio=min(r["replay_wall_s"] for r in rows)
        / min(r["run_wall_s"] for r in rows),
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="bench/replay_speed.py")
    parser.add_argument("--scene", default=str(REPO / "scenes" / "pile.yaml"))
    parser.add_argument("--reps", type=int, default=3)
    parser.add_argument("--out", default=None, help="directory for the logs (default: a temp dir)")
    args = parser.parse_args(argv)
    out_dir = Path(args.out or tempfile.mkdtemp(prefix="isaac-replay-speed-"))
    try:
        summary = compare(args.scene, args.reps, out_dir)
    except RuntimeError as exc:
        raise SystemExit(str(exc)) from None
    for row in summary.pop("rows"):
        print(json.dumps(row), flush=True)
    print(json.dumps(summary, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
