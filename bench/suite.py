"""The benchmark suite: `python -m bench` (what `make bench` runs).

What it does, in order:
1. For each scene, `reps` repetitions of every engine interleaved (A B C A B C ...), each run in
   its own process (`bench.worker`): ms/step over a timed block after warm-up (compile and
   start-up excluded), memory per body, and a quality figure from the final poses measured by
   the same code for every engine (bench.quality).
2. Medians over repetitions; each engine's ratio to pymunk (and to Box2D v3 when it ran) is
   computed per repetition (the same run) and the median of those ratios is reported.
3. Growth: least-squares slope of log(ms/step) against log(bodies) over the piles.
4. Start-up: first run (fresh NUMBA_CACHE_DIR: compile included) and cached start-up to the
   first step, each a whole `python -c` process timed from outside.
5. Recording overhead (MCAP, Rerun) and replay speed (`bench.recording`), skipped with a note
   while the recorder or the replay command is not there.
6. Sweep throughput (`bench.sweep`, in a process of its own): runs/s of `isaac sweep` on 1 and
   2 workers and where a run's time goes; its targets in its own table.
7. Targets (from the issue) against the measurements.

Output: bench/results/latest.jsonl (one JSON object a line: `meta`, every `run`, the aggregated
`row`s, `growth`, `startup`, `recording`, `targets`) and bench/results/latest.md (the tables),
also printed. A run with any selection flag (`--quick`, `--scenes`, ...) writes partial.jsonl /
partial.md instead, so the published results are always a full run. After a full run, if
bench/README.md holds the markers `<!-- bench:start -->` and `<!-- bench:end -->`, the tables
replace what is between them (`--no-readme` to leave it alone).
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import math
import os
import platform
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from bench.peers import OWN_PROCESS, PEERS, box2d_v3, engine_available
from bench.scenes import ALL_SCENES, GROWTH_SCENES, QUICK_SCENES

ROOT = Path(__file__).resolve().parent.parent
RESULTS = Path(__file__).resolve().parent / "results"
README_START = "<!-- bench:start -->"
README_END = "<!-- bench:end -->"
DEFAULT_PRESETS = ("fast", "balanced")
BASELINE = "pymunk"
# the second baseline, when its row ran (bench/peers/box2d_v3.py: built from --box2d-v3 SRC)
BOX2D_V3 = "box2d-v3"

# the targets for ISAAC: (what, limit)
TARGETS = (
    ("ratio", "pile-2000", 0.8),
    ("ratio", "pyramid-40", 0.8),
    ("ratio", "pile-100", 0.7),
    ("ratio", "pyramid-10", 0.7),
    ("growth", None, 1.15),
    ("startup_cached_s", None, 0.5),
    ("startup_first_s", None, 15.0),
)
# the fused-stepping issue's targets: ms/step of an ISAAC mode over pymunk's, small scenes
MODE_TARGETS = (
    *(("advance", scene, 1.0) for scene in ("head-on", "bounce", "off-centre")),
    *(("run", scene, 3.0) for scene in ("head-on", "bounce", "off-centre")),
)
# the recorder issue's targets (overhead on top of the simulation alone, a fraction) and the
# replay issue's (replay time per step over that of the original `isaac run --mcap`), measured
# on the recording scenes with the preset named in the recording rows
RECORDING_TARGETS = (("mcap", 0.25), ("rerun", 0.50))
REPLAY_TARGET = 1.2

# how an ISAAC row steps (bench.peers.isaac_engine): one row per mode asked for
ISAAC_MODES = ("step", "run", "advance")
# the scenes the fused-stepping issue judges through `run` and `advance` (MODE_TARGETS and the
# 0.7x ratios): a run that leaves --isaac-modes at `step` times them through those paths too
FUSED_SCENES = ("head-on", "bounce", "off-centre", "pile-100", "pyramid-10")
FUSED_MODES = ("run", "advance")


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def python_cmd(module: str, *args: str) -> list[str]:
    return [sys.executable, "-m", module, *args]


def subprocess_env(**extra: str) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    env.update(extra)
    return env


def fused_engines(engines: list[str], modes: list[str]) -> list[str]:
    """The `run` and `advance` rows of each ISAAC preset in `engines`, timed on FUSED_SCENES
    only, when the run asked for `step` rows alone (the default): the fused-stepping targets
    are then judged in every full run, at the cost of the small scenes alone."""
    if modes != ["step"]:
        return []
    presets = [e for e in engines if e.startswith("isaac") and "/" not in e]
    return [f"{e}/{m}" for e in presets for m in FUSED_MODES]


def run_worker(scene: str, engine: str, timeout: float, env: dict[str, str] | None = None) -> dict:
    """One (scene, engine) repetition in a fresh process (`env`: extra environment variables);
    a failure becomes a row with `error`."""
    cmd = python_cmd("bench.worker", "--scene", scene, "--engine", engine)
    try:
        proc = subprocess.run(
            cmd,
            capture_output=True,
            text=True,
            cwd=ROOT,
            env=subprocess_env(**(env or {})),
            timeout=timeout,
        )
    except subprocess.TimeoutExpired:
        return dict(scene=scene, engine=engine, error=f"timed out after {timeout:.0f} s")
    if proc.returncode != 0:
        tail = (proc.stderr or "").strip().splitlines()[-1:] or [f"exit {proc.returncode}"]
        return dict(scene=scene, engine=engine, error=tail[0])
    return json.loads(proc.stdout.strip().splitlines()[-1])


# ---- aggregation ----------------------------------------------------------------------------


def quality_text(q: dict | None) -> str:
    """One short phrase per scene kind, for the table."""
    if not q:
        return ""
    bad = "" if q.get("finite", True) else "NON-FINITE; "
    if "standing" in q:
        state = "stands" if q["standing"] else "FALLS"
        return (
            f"{bad}{state}: top drift {q['top_drift_m']:.3f} m; any box: sideways "
            f"{q['max_sideways_m']:.2f} m, sink {q['max_sink_m']:.2f} m, turn "
            f"{q['max_turn_rad']:.2f} rad; max overlap {q['max_overlap_m']:.3f} m"
        )
    if "holds" in q:
        state = "holds" if q["holds"] else "FAILS"
        return (
            f"{bad}{state}: heavy box dropped {q['heavy_drop_m']:.3f} m, "
            f"max overlap {q['max_overlap_m']:.3f} m"
        )
    if "max_overlap_m" in q:
        return (
            f"{bad}max overlap {q['max_overlap_m']:.4f} m (p99 {q['p99_overlap_m']:.4f} m, "
            f"{q['touching_pairs']} pairs)"
        )
    if "exchange_error_mps" in q:
        v = q["final_velocities_x"]
        return (
            f"{bad}exchange error {q['exchange_error_mps']:.2e} m/s "
            f"(final vx {v[0]:.3f}, {v[1]:.3f}; expected -1, 3)"
        )
    if "stopped" in q:
        return f"{bad}stopped {q['stopped']}/{q['lanes']} bullets at 200 m/s"
    return bad + json.dumps(q)


def _median_ratio(ok: list[dict], base: list[dict]) -> float | None:
    """The median over repetitions of ms/step over the baseline's in the same repetition."""
    base_ms = {b["rep"]: b["ms_per_step"] for b in base if "error" not in b}
    ratios = [r["ms_per_step"] / base_ms[r["rep"]] for r in ok if r["rep"] in base_ms]
    return statistics.median(ratios) if ratios else None


def aggregate(runs: list[dict], scenes: list[str], engines: list[str]) -> list[dict]:
    """Median ms/step per (scene, engine) and the median of per-repetition ratios to pymunk and
    to Box2D v3 (None where that baseline did not run)."""
    rows = []
    for scene in scenes:
        by_engine: dict[str, list[dict]] = {}
        for r in runs:
            if r["scene"] == scene:
                by_engine.setdefault(r["engine_arg"], []).append(r)
        for engine in engines:
            reps = by_engine.get(engine, [])
            ok = [r for r in reps if "error" not in r]
            if not reps:
                continue
            if not ok:
                rows.append(dict(kind="row", scene=scene, engine=engine, error=reps[0]["error"]))
                continue
            ms = [r["ms_per_step"] for r in ok]
            first = ok[0]
            rows.append(
                dict(
                    kind="row",
                    scene=scene,
                    engine=first["engine"],
                    engine_arg=engine,
                    settings=first["settings"],
                    n_bodies=first["n_bodies"],
                    reps=len(ok),
                    ms_per_step=statistics.median(ms),
                    ms_per_step_min=min(ms),
                    ms_per_step_max=max(ms),
                    steps_per_s=1000.0 / statistics.median(ms),
                    ratio_to_pymunk=_median_ratio(ok, by_engine.get(BASELINE, [])),
                    ratio_to_box2d_v3=_median_ratio(ok, by_engine.get(BOX2D_V3, [])),
                    memory_per_body_bytes=statistics.median(r["memory_per_body_bytes"] for r in ok),
                    timed_steps=first["timed_steps"],
                    warmup_steps=first["warmup_steps"],
                    quality=first["quality"],
                    quality_text=quality_text(first["quality"]),
                    quality_varies=any(r["quality"] != first["quality"] for r in ok),
                    scene_source=first.get("scene_source"),
                )
            )
    return rows


def growth(rows: list[dict]) -> list[dict]:
    """Per engine: slope of log(ms/step) vs log(bodies) over the piles (least squares)."""
    out = []
    engines = sorted({r["engine_arg"] for r in rows if "error" not in r})
    for engine in engines:
        pts = [
            (r["n_bodies"], r["ms_per_step"])
            for r in rows
            if r.get("engine_arg") == engine and r["scene"] in GROWTH_SCENES and "error" not in r
        ]
        if len(pts) < 2:
            continue
        n, ms = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
        slope, intercept = np.polyfit(n, ms, 1)
        out.append(
            dict(
                kind="growth",
                engine=engine,
                exponent=float(slope),
                bodies=[p[0] for p in pts],
                ms_per_step=[p[1] for p in pts],
            )
        )
    return out


# ---- start-up and compile -------------------------------------------------------------------

STARTUP_CODE = """\
from bench.peers import make_engine
from bench.scenes import build
engine = make_engine({engine!r}, build('pyramid-10').scene)
engine.block(1) if hasattr(engine, "block") else engine.step()  # the row's own path
import time
print("first step done", time.monotonic())
"""


def startup(engines: list[str], reps: int) -> list[dict]:
    """Whole-process time of `python -c` (import, build pyramid-10, first step).

    ISAAC: first run with a fresh, empty NUMBA_CACHE_DIR (every kernel compiled), then `reps`
    runs with that cache filled (cached start-up). Peers: `reps` runs (nothing to compile)."""
    out = []
    for engine in engines:
        code = STARTUP_CODE.format(engine=engine)

        def once(env: dict[str, str], code: str = code) -> tuple[float, float]:
            """(s from the start to the first step's end, s for the whole process): the
            child reads the same monotonic clock (CLOCK_MONOTONIC, one per machine) after
            its first step; the whole process adds the interpreter's teardown."""
            t0 = time.monotonic()
            proc = subprocess.run(
                [sys.executable, "-c", code],
                cwd=ROOT,
                env=env,
                capture_output=True,
                text=True,
                timeout=600,
            )
            elapsed = time.monotonic() - t0
            if proc.returncode != 0:
                raise RuntimeError((proc.stderr or "").strip().splitlines()[-1:])
            done = [ln for ln in proc.stdout.splitlines() if ln.startswith("first step done")]
            return float(done[-1].split()[-1]) - t0, elapsed

        try:
            with tempfile.TemporaryDirectory(prefix="isaac-numba-") as cache:
                env = subprocess_env(NUMBA_CACHE_DIR=cache)
                first = once(env)[0] if engine.startswith("isaac") else None
                cached = [once(env) for _ in range(reps)]
            out.append(
                dict(
                    kind="startup",
                    engine=engine,
                    first_run_s=first,
                    cached_s=statistics.median(c[0] for c in cached),
                    cached_runs_s=[c[0] for c in cached],
                    cached_process_s=statistics.median(c[1] for c in cached),
                    what="python -c: import, build pyramid-10, first step: from the process's "
                    "start (interpreter start-up included) to the first step's end; "
                    "cached_process_s: the whole process (its teardown too)",
                )
            )
        except Exception as exc:  # noqa: BLE001 - report, go on
            out.append(dict(kind="startup", engine=engine, error=str(exc)))
        log(f"  startup {engine}: {out[-1]}")
    return out


FIRST_RUN_CLI = "isaac run scenes/default.yaml"  # the first-run row a new user meets
FIRST_RUN_LIMIT_S = 15.0  # the fused-stepping issue's first-run compile, to the first step


def first_cli_run(reps: int) -> dict:
    """`isaac run scenes/default.yaml --verbose`, each time in a fresh, empty NUMBA_CACHE_DIR:
    the command's own start-up to its first step (its --verbose line: from the command's start,
    which steps on the staged path while a helper compiles the driver), and the whole process
    (which waits for that helper at its end)."""
    first, whole = [], []
    isaac = str(Path(sys.executable).parent / "isaac")
    try:
        for _ in range(reps):
            with tempfile.TemporaryDirectory(prefix="isaac-numba-") as cache:
                t0 = time.monotonic()
                proc = subprocess.run(
                    [isaac, "run", "scenes/default.yaml", "--verbose", "--quiet"],
                    cwd=ROOT,
                    env=subprocess_env(NUMBA_CACHE_DIR=cache),
                    capture_output=True,
                    text=True,
                    timeout=600,
                )
                whole.append(time.monotonic() - t0)
            if proc.returncode != 0:
                raise RuntimeError((proc.stderr or "").strip().splitlines()[-1:])
            line = next(ln for ln in proc.stdout.splitlines() if "start-up to first step" in ln)
            first.append(float(line.split("start-up to first step")[1].split()[0]))
    except Exception as exc:  # noqa: BLE001 - report, go on
        return dict(kind="first_cli_run", command=FIRST_RUN_CLI, error=str(exc))
    return dict(
        kind="first_cli_run",
        command=FIRST_RUN_CLI,
        first_step_s=statistics.median(first),
        first_step_runs_s=first,
        whole_s=statistics.median(whole),
        whole_runs_s=whole,
        what="empty NUMBA_CACHE_DIR each time; first step: the command's --verbose start-up to "
        "first step; whole: the process, which waits for the driver's compile helper at its end",
    )


# ---- recording ------------------------------------------------------------------------------

# the recording issue's scenes: the 500-body and the 2,000-body pile (steps timed)
RECORDING_SCENES = (("pile-500", 400), ("pile-2000", 200))


def recording(preset: str, reps: int, steps: int, scene: str) -> dict:
    with tempfile.TemporaryDirectory(prefix="isaac-bench-rec-") as tmp:
        cmd = python_cmd(
            "bench.recording",
            "--scene",
            scene,
            "--preset",
            preset,
            "--out",
            tmp,
            "--reps",
            str(reps),
            "--steps",
            str(steps),
        )
        proc = subprocess.run(
            cmd, capture_output=True, text=True, cwd=ROOT, env=subprocess_env(), timeout=900
        )
    if proc.returncode != 0:
        tail = (proc.stderr or "").strip().splitlines()[-1:] or [f"exit {proc.returncode}"]
        return dict(kind="recording", engine=f"isaac-{preset}", scene=scene, error=tail[0])
    return json.loads(proc.stdout.strip().splitlines()[-1])


# ---- targets --------------------------------------------------------------------------------


def _mode_target(rows, engine, mode, scene, limit, over) -> list[dict]:
    """The target line of row `engine`/`mode` on `scene` against `limit`, or none when that
    mode or scene was not run."""
    name = f"{engine}/{mode}"
    row = next((r for r in rows if r.get("engine_arg") == name and r["scene"] == scene), None)
    if row is None:
        return []
    value = row.get("ratio_to_pymunk")
    met = None if value is None else bool(value <= limit)
    what = f"ms/step {name}{over}, {scene}"
    return [dict(kind="target", engine=name, what=what, limit=limit, value=value, met=met)]


def check_targets(
    rows, growth_rows, startup_rows, isaac_engines, recordings=(), first_cli=None
) -> list[dict]:
    out = []
    if first_cli is not None and "error" not in first_cli:
        value = first_cli["first_step_s"]
        out.append(
            dict(
                kind="target",
                engine="isaac run",
                what=f"first-run compile, `{FIRST_RUN_CLI}` to its first step (s)",
                limit=FIRST_RUN_LIMIT_S,
                value=value,
                met=bool(value <= FIRST_RUN_LIMIT_S),
            )
        )
    for engine in isaac_engines:
        for what, scene, limit in TARGETS:
            value = None
            if what == "ratio":
                value = next(
                    (
                        r.get("ratio_to_pymunk")
                        for r in rows
                        if r.get("engine_arg") == engine and r["scene"] == scene
                    ),
                    None,
                )
                label = f"ms/step {engine}/pymunk, {scene}"
            elif what == "growth":
                value = next((g["exponent"] for g in growth_rows if g["engine"] == engine), None)
                label = "growth exponent (piles)"
            else:
                key = "cached_s" if what == "startup_cached_s" else "first_run_s"
                value = next((s.get(key) for s in startup_rows if s["engine"] == engine), None)
                label = (
                    "cached start-up to first step (s)"
                    if key == "cached_s"
                    else "first-run compile, start-up to first step (s)"
                )
            out.append(
                dict(
                    kind="target",
                    engine=engine,
                    what=label,
                    limit=limit,
                    value=value,
                    met=None if value is None else bool(value <= limit),
                )
            )
            if what == "ratio" and scene in FUSED_SCENES:
                # the same limit through the fused paths, where they were timed
                for mode in FUSED_MODES:
                    out += _mode_target(rows, engine, mode, scene, limit, "/pymunk")
        for mode, scene, limit in MODE_TARGETS:
            out += _mode_target(rows, engine, mode, scene, limit, " over pymunk")
    for rec in recordings:
        if "error" in rec:
            continue
        frac = rec.get("overhead_fraction", {})
        checks = [
            (
                f"{mode.upper() if mode == 'mcap' else 'Rerun'} recording overhead, "
                f"{rec['scene']} (fraction)",
                limit,
                frac.get(mode),
            )
            for mode, limit in RECORDING_TARGETS
        ]
        checks.append(
            (
                f"replay time / original run's (isaac run --mcap), {rec['scene']}",
                REPLAY_TARGET,
                rec.get("replay", {}).get("time_ratio"),
            )
        )
        for label, limit, value in checks:
            out.append(
                dict(
                    kind="target",
                    engine=rec["engine"],
                    what=label,
                    limit=limit,
                    value=value,
                    met=None if value is None else bool(value <= limit),
                )
            )
    return out


# ---- output ---------------------------------------------------------------------------------


def fmt(x, digits: int = 3) -> str:
    if x is None:
        return "–"
    if isinstance(x, float):
        return f"{x:.{digits}g}" if x == 0 or abs(x) >= 0.001 else f"{x:.2e}"
    return str(x)


def provenance(meta: dict) -> str:
    """When, on what and from which commit a result was measured (`meta_info`'s fields): the
    opening of every results file."""
    return (
        f"{meta['date_utc']} on {meta['cpu']} ({meta['cpus']} CPUs, {meta['machine']}), "
        f"Python {meta['python']}, {meta['versions']}; git {meta['git']}"
    )


def markdown(meta, rows, growth_rows, startup_rows, recs, targets, first_cli=None) -> str:
    lines = [
        f"Benchmark of {provenance(meta)}. "
        f"dt = 1/60 s, no sleeping, friction on (except head-on and tunneling); "
        f"{meta['reps']} repetitions per engine, interleaved, each in its own process; "
        "medians. Ratio = median over repetitions of (engine / pymunk, engine / Box2D v3 when "
        "it ran) from the same repetition. Memory per body = (RSS after build and warm-up - "
        "RSS before build) / bodies.",
        "",
    ]
    # the Box2D v3 column only in a run that has its rows
    v3 = any(r.get("ratio_to_box2d_v3") is not None for r in rows)
    lines += [
        "| scene | bodies | engine | settings | ms/step | steps/s | ratio to pymunk | "
        + ("ratio to Box2D v3 | " if v3 else "")
        + "memory/body | quality |",
        "|---|---|---|---|---|---|---|" + ("---|" if v3 else "") + "---|---|",
    ]
    for r in rows:
        if "error" in r:
            cells = "| | | | |" + (" |" if v3 else "")
            lines.append(f"| {r['scene']} | | {r['engine']} | | error: {r['error']} {cells}")
            continue
        spread = f" ({fmt(r['ms_per_step_min'])}–{fmt(r['ms_per_step_max'])})"
        mem = r["memory_per_body_bytes"]
        mem_text = f"{mem / 1024:.2f} kB" if r["n_bodies"] >= 500 else "–"
        lines.append(
            f"| {r['scene']} | {r['n_bodies']} | {r['engine']} | {r['settings']} | "
            f"{fmt(r['ms_per_step'])}{spread} | {r['steps_per_s']:.0f} | "
            f"{fmt(r['ratio_to_pymunk'])} | "
            + (f"{fmt(r.get('ratio_to_box2d_v3'))} | " if v3 else "")
            + f"{mem_text} | {r['quality_text']} |"
        )
    steps = {}
    for r in rows:
        steps.setdefault((r.get("warmup_steps"), r.get("timed_steps")), []).append(r["scene"])
    steps_text = "; ".join(
        f"{', '.join(dict.fromkeys(names))}: {w} + {t}"
        for (w, t), names in steps.items()
        if w is not None
    )
    lines += [
        "",
        f"Steps (warm-up + timed): {steps_text}. ms/step is the timed block's mean; "
        "quality is measured on the final poses. Pile overlap is "
        "the deepest SAT penetration over all touching pairs (bench/quality.py, the same "
        "code for every engine); Box2D 2.3 rests polygons on a 1 cm skin, so it shows little "
        "overlap. A pyramid stands while no box has moved half a box sideways or down nor "
        "turned 0.1 rad. Memory per body is shown from 500 bodies up (page-size noise "
        "below).",
        "",
    ]
    if growth_rows:
        lines += [
            "| engine | growth exponent (ms/step vs bodies, piles) | points |",
            "|---|---|---|",
        ]
        for g in growth_rows:
            pts = ", ".join(
                f"{n}: {fmt(m)}" for n, m in zip(g["bodies"], g["ms_per_step"], strict=True)
            )
            lines.append(f"| {g['engine']} | {g['exponent']:.3f} | {pts} |")
        lines.append("")
    if startup_rows:
        lines += [
            "| engine | first run (compile), s | cached start-up to first step, s "
            "| cached, whole process, s |",
            "|---|---|---|---|",
        ]
        for s in startup_rows:
            if "error" in s:
                lines.append(f"| {s['engine']} | error: {s['error']} | | |")
            else:
                lines.append(
                    f"| {s['engine']} | {fmt(s['first_run_s'])} | {fmt(s['cached_s'])} "
                    f"| {fmt(s['cached_process_s'])} |"
                )
        lines += [
            "",
            "Start-up: a `python -c` process (import, build pyramid-10, first step), from its "
            "start to the first step's end; the last column, the whole process (its teardown "
            "too); first run with an empty NUMBA_CACHE_DIR.",
            "",
        ]
    if first_cli is not None:
        if "error" in first_cli:
            lines += [f"First `{FIRST_RUN_CLI}`: error: {first_cli['error']}", ""]
        else:
            runs = ", ".join(
                f"{a:.1f} / {b:.1f}"
                for a, b in zip(first_cli["first_step_runs_s"], first_cli["whole_runs_s"])
            )
            lines += [
                f"First `{FIRST_RUN_CLI}` in an empty NUMBA_CACHE_DIR: first step "
                f"{first_cli['first_step_s']:.1f} s after the command started, "
                f"{first_cli['whole_s']:.1f} s for the whole process (medians; each run, first "
                f"step / whole: {runs} s). It steps on the staged path while a helper compiles "
                "the driver, and waits for that helper at its end.",
                "",
            ]
    for rec in recs:
        if "error" in rec:
            lines += [f"Recording ({rec.get('scene')}): error: {rec['error']}", ""]
        else:
            ms = rec.get("ms_per_step", {})
            over = rec.get("overhead_ms_per_step", {})
            frac = rec.get("overhead_fraction", {})
            opened, closed = rec.get("open_s", {}), rec.get("close_s", {})
            lines += [
                f"Recording overhead, {rec['engine']} on {rec['scene']} ({rec['steps']} "
                "steps; each mode's repetition against the plain run interleaved with it, "
                "median; targets: MCAP <= 25 %, Rerun <= 50 % on top of the simulation "
                "alone). ms/step is the steady cost (steps, writes, and the wait until the "
                "writers have taken every step); opening and closing the files are one-off "
                "costs, shown apart:",
                "",
                "| mode | ms/step | steps/s | overhead ms/step | overhead | bytes/step "
                "| bytes/body-step | open, s | close, s |",
                "|---|---|---|---|---|---|---|---|---|",
            ]
            for mode, v in ms.items():
                size = rec.get(f"{mode}_bytes_per_step")
                extra = over.get(mode)
                share = f"{100 * frac[mode]:.0f} %" if mode in frac else "–"
                rate = f"{1000 / v:.0f}" if v else "–"
                per_body = size / rec["bodies"] if size and rec.get("bodies") else None
                lines.append(
                    f"| {mode} | {fmt(v)} | {rate} | {fmt(extra)} | {share} | "
                    f"{fmt(size) if size else '–'} | {fmt(per_body)} | "
                    f"{fmt(opened.get(mode))} | "
                    f"{fmt(closed.get(mode))} |"
                )
            rp = rec.get("replay", {})
            if "time_ratio" in rp:
                plain = (
                    f"; {rp['time_ratio_to_plain']:.2f}x the plain simulation's ms/step above"
                    if rp.get("time_ratio_to_plain")
                    else ""
                )
                lines.append(
                    f"\nReplay ({rp['command']}; medians): run "
                    f"{rp['median_run_with_finish_steps_per_s']:.0f} steps/s with its files "
                    f"finished ({rp['median_run_steps_per_s']:.0f} steps/s in its loop, then "
                    f"{rp['median_run_finish_s']:.2f} s to finish the files), replay "
                    f"{rp['median_replay_steps_per_s']:.0f} steps/s (loop rates after the first "
                    f"step): replay time per step {rp['time_ratio']:.2f}x the original run's "
                    f"(target <= {REPLAY_TARGET}; {rp['loop_time_ratio']:.2f}x its loop alone), "
                    f"whole process {rp['wall_time_ratio']:.2f}x{plain}; identical."
                )
            elif rp.get("note"):
                lines.append(f"\n{rp['note']}")
            for note in rec.get("notes", []):
                lines.append(f"\nNote: {note}")
            lines.append("")
    if targets:
        lines += ["| target | engine | limit | measured | met |", "|---|---|---|---|---|"]
        for t in targets:
            met = "–" if t["met"] is None else ("yes" if t["met"] else "**no**")
            lines.append(
                f"| {t['what']} | {t['engine']} | <= {t['limit']} | {fmt(t['value'])} | {met} |"
            )
        lines.append("")
    if meta.get("skipped"):
        lines += [*meta["skipped"], ""]
    return "\n".join(lines)


def update_readme(text: str, path: Path) -> bool:
    """Put `text` between the marker lines of `path` (each marker alone on its line: the prose
    that names them is left alone); False, and nothing written, without both of them."""
    if not path.exists():
        return False
    readme = path.read_text()
    start = re.search(rf"^{re.escape(README_START)}$", readme, re.M)
    end = start and re.search(rf"^{re.escape(README_END)}$", readme[start.end() :], re.M)
    if not end:
        return False
    head, tail = readme[: start.start()], readme[start.end() + end.end() :]
    path.write_text(f"{head}{README_START}\n{text}\n{README_END}{tail}")
    return True


def cpu_model(cpuinfo: Path = Path("/proc/cpuinfo")) -> str:
    """The CPU's model name (Linux: /proc/cpuinfo's first `model name`), else what
    `platform.processor()` says, else "unknown CPU": every result file names the CPU it ran on."""
    try:
        for line in cpuinfo.read_text(errors="replace").splitlines():
            key, _, value = line.partition(":")
            if key.strip() == "model name" and value.strip():
                return value.strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def write_results(out: Path, stem: str, objs: list[dict], text: str) -> tuple[Path, Path]:
    """Write `objs` (the `meta` object first) as OUT/STEM.jsonl, one JSON object a line, and
    `text` (the tables, opening with the date, CPU and commit) as OUT/STEM.md."""
    out.mkdir(parents=True, exist_ok=True)
    jsonl, md = out / f"{stem}.jsonl", out / f"{stem}.md"
    with open(jsonl, "w") as f:
        for obj in objs:
            f.write(json.dumps(obj, default=_json_default) + "\n")
    md.write_text(text + "\n")
    return jsonl, md


def meta_info(reps: int, skipped: list[str]) -> dict:
    from importlib.metadata import PackageNotFoundError, version

    versions = []
    for pkg in ("pymunk", "box2d", "numpy", "numba"):
        try:
            versions.append(f"{pkg} {version(pkg)}")
        except PackageNotFoundError:
            pass
    try:
        git = (
            subprocess.run(
                ["git", "rev-parse", "--short", "HEAD"],
                cwd=ROOT,
                check=False,
                capture_output=True,
                text=True,
            ).stdout.strip()
            or "?"
        )
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=ROOT,
            check=False,
            capture_output=True,
            text=True,
        ).stdout
        if dirty.strip():
            git += " + uncommitted changes"
    except OSError:
        git = "?"
    return dict(
        kind="meta",
        date_utc=_dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        cpu=cpu_model(),
        machine=f"{platform.machine()} {platform.system()}",
        cpus=os.cpu_count(),
        python=platform.python_version(),
        versions=", ".join(versions),
        git=git,
        reps=reps,
        skipped=skipped,
    )


# ---- main -----------------------------------------------------------------------------------


def parse_args(argv):
    p = argparse.ArgumentParser(prog="python -m bench", description=__doc__.split("\n")[0])
    p.add_argument(
        "--quick",
        action="store_true",
        help=f"a fast subset: {', '.join(QUICK_SCENES)}; 2 repetitions; no extras",
    )
    p.add_argument("--scenes", help=f"comma-separated, from: {', '.join(ALL_SCENES)}")
    p.add_argument(
        "--engines",
        help="comma-separated: pymunk, box2d, box2d-v3, isaac (default: all four; box2d-v3 runs "
        "when --box2d-v3 or ISAAC_BOX2D_V3 names its source)",
    )
    p.add_argument(
        "--box2d-v3",
        metavar="SRC",
        help="a Box2D v3 source tree or its .tar.gz: built once into $XDG_CACHE_HOME/isaac/"
        "box2d-v3 (bench/peers/box2d_v3.py) and run as the box2d-v3 row "
        "(default: $ISAAC_BOX2D_V3)",
    )
    p.add_argument(
        "--isaac-modes",
        default="step",
        help="how each ISAAC row steps, one row per mode: step (Simulation.step, a record per "
        "step), run (the records of Simulation.run, computed in batches by the compiled driver), "
        "advance (Simulation.advance: no records) (default: %(default)s)",
    )
    p.add_argument(
        "--presets",
        default=",".join(DEFAULT_PRESETS),
        help="ISAAC presets, one row each (default: %(default)s)",
    )
    p.add_argument("--reps", type=int, help="repetitions per engine (default 5, quick 2)")
    p.add_argument("--no-startup", action="store_true", help="skip compile / start-up timing")
    p.add_argument("--no-recording", action="store_true", help="skip recording and replay")
    p.add_argument("--no-sweep", action="store_true", help="skip the sweep throughput")
    p.add_argument("--out", default=str(RESULTS), help="results directory (default: %(default)s)")
    p.add_argument(
        "--no-readme",
        action="store_true",
        help="do not write the tables into bench/README.md between the bench markers",
    )
    p.add_argument("--timeout", type=float, default=600.0, help="per-process limit (s)")
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    scenes = (
        args.scenes.split(",") if args.scenes else list(QUICK_SCENES if args.quick else ALL_SCENES)
    )
    unknown = [s for s in scenes if s not in ALL_SCENES]
    if unknown:
        print(
            f"bench: unknown scene(s) {', '.join(unknown)}; known: {', '.join(ALL_SCENES)}",
            file=sys.stderr,
        )
        return 2
    reps = args.reps or (2 if args.quick else 5)
    wanted = args.engines.split(",") if args.engines else [*PEERS, "isaac"]
    try:
        v3_source = box2d_v3.source_from(args.box2d_v3)
    except box2d_v3.SourceError as exc:
        print(f"bench: {exc}", file=sys.stderr)
        return 2
    v3_build, worker_env = None, {}
    presets = [p for p in args.presets.split(",") if p]
    modes = [m for m in args.isaac_modes.split(",") if m]
    if not modes or any(m not in ISAAC_MODES for m in modes):
        print(f"bench: --isaac-modes takes {', '.join(ISAAC_MODES)}", file=sys.stderr)
        return 2
    engines, skipped = [], []
    for name in wanted:
        if name == BOX2D_V3:
            # built here, once, so that no repetition times a build and a failure is one line
            try:
                if v3_source is None:
                    raise LookupError(box2d_v3.NO_SOURCE_NOTE)
                log(f"bench: Box2D v3 from {v3_source} (cache: {box2d_v3.cache_root()})")
                v3_build = box2d_v3.ensure_built(v3_source)
            except (LookupError, box2d_v3.BuildError) as exc:
                skipped.append(str(exc))
                log(f"bench: {exc}")
                continue
            engines.append(name)
            worker_env[box2d_v3.ENV] = str(v3_source)
            continue
        names = (
            [f"isaac-{p}" + ("" if m == "step" else f"/{m}") for p in presets for m in modes]
            if name == "isaac"
            else [name]
        )
        ok, why = engine_available(names[0])
        if ok:
            engines += names
        else:
            skipped.append(f"{name}: not run (not available: {why})")
            log(f"bench: skipping {name}: {why}")
    if not engines:
        print("bench: no engine available", file=sys.stderr)
        return 2
    if BASELINE not in engines:
        log("bench: pymunk not in the run: no ratios")

    fused = fused_engines(engines, modes)
    t_start = time.perf_counter()
    runs: list[dict] = []
    for scene in scenes:
        # the 10,000 pile: fewer repetitions keep the whole run near 15 minutes
        scene_reps = min(reps, 3) if scene == "pile-10000" else reps
        scene_engines = engines + (fused if scene in FUSED_SCENES else [])
        for rep in range(scene_reps):
            for engine in scene_engines:
                r = run_worker(scene, engine, args.timeout, worker_env)
                r.update(kind="run", rep=rep, engine_arg=engine)
                runs.append(r)
                ms = r.get("ms_per_step")
                log(
                    f"  {scene:12s} rep {rep} {engine:15s} "
                    + (f"{ms:9.4f} ms/step" if ms is not None else f"error: {r['error']}")
                )
    rows = aggregate(runs, scenes, engines + fused)
    growth_rows = growth(rows)

    # start-up, recording and the targets are measured on the step-by-step rows
    isaac_engines = [e for e in engines if e.startswith("isaac") and "/" not in e]
    startup_rows = []
    first_cli = None
    if not args.no_startup and not args.quick:
        startup_rows = startup([e for e in engines if e not in OWN_PROCESS], reps=3)
        first_cli = first_cli_run(reps=2)
        log(f"  first {FIRST_RUN_CLI}: {first_cli}")
    recs = []
    if not args.no_recording and not args.quick and isaac_engines:
        preset = "balanced" if "isaac-balanced" in isaac_engines else isaac_engines[0][6:]
        for scene, steps in RECORDING_SCENES:
            recs.append(recording(preset, reps=5, steps=steps, scene=scene))
            log(f"  recording: {recs[-1]}")
    targets = check_targets(rows, growth_rows, startup_rows, isaac_engines, recs, first_cli)
    sweeps = []
    if not args.no_sweep and not args.quick:
        from bench import sweep as sweep_bench

        sweeps.append(sweep_bench.run_subprocess(subprocess_env()))
        log(f"  sweep: {sweeps[-1].get('error') or 'done'}")

    meta = meta_info(reps, skipped)
    if v3_build is not None:
        meta["versions"] += f", Box2D v3 {v3_build.version} ({v3_build.source.name})"
    meta["elapsed_s"] = time.perf_counter() - t_start
    meta["scenes"], meta["engines"] = scenes, engines
    text = markdown(meta, rows, growth_rows, startup_rows, recs, targets, first_cli)
    if sweeps:
        text += "\n" + sweep_bench.markdown(sweeps[0])

    # only a full run replaces the published results; a subset goes to partial.*
    full = not (
        args.quick
        or args.scenes
        or args.engines
        or args.reps
        or args.no_startup
        or args.no_recording
        or args.no_sweep
        or args.presets != ",".join(DEFAULT_PRESETS)
    )
    stem = "latest" if full else "partial"
    sweep_targets = [t for s in sweeps for t in s.get("targets", [])]
    objs = [meta, *runs, *rows, *growth_rows, *startup_rows, *recs, *targets]
    objs += [first_cli] if first_cli is not None else []
    jsonl, md = write_results(Path(args.out), stem, [*objs, *sweeps, *sweep_targets], text)
    print(text)
    if full and not args.no_readme and update_readme(text, ROOT / "bench" / "README.md"):
        log("bench: bench/README.md table updated")
    log(f"bench: {meta['elapsed_s']:.0f} s; wrote {jsonl} and {md}")
    return 0


def _json_default(x):
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return str(x)
    raise TypeError(f"not JSON serialisable: {type(x).__name__}")
