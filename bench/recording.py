"""Recording overhead (MCAP, Rerun) and replay speed, in a process of their own.

`python -m bench.recording --scene pyramid-20 --preset balanced --out DIR` prints one JSON line:
ms/step of ISAAC alone, with the MCAP log, with the Rerun recording and with both (interleaved
repetitions, medians), the overhead of each (per repetition against the plain run beside it,
then the median), the one-off seconds to open and to close the files, and, when the
`isaac replay` command is there, the replay speed against the original run (`replay_speed`).

Each part is skipped with a note when what it needs (the recorder, a writer, the replay command)
is not importable yet, so the suite lights up as those land.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

from bench.scenes import build, with_preset

BLOCK = 100  # steps per timed block


def _time_paired(scene, steps: int, mcap_path=None, rrd_path=None, batches=False) -> dict:
    """Two simulations of `scene` in lockstep, one plain and one recorded, timed in alternating
    blocks of BLOCK steps; the overhead is (recorded time) / (plain time) over all blocks - 1.
    Steps are taken one `step()` at a time and written with `Recorder.write`; with ``batches``,
    as `isaac run` takes them: `Simulation.batches` (its batch size), `Recorder.write_batch`.

    This machine's speed drifts by up to 1.6x from second to second (shared host), which made
    separate timings of plain and recorded runs, even interleaved ones, differ by more than the
    overhead itself. Blocks a few milliseconds apart see the same machine. A recorded block
    ends with `Recorder.drain` (every step taken by its writer processes), so their Python
    work is charged to it even when they lag; Rerun's own encoder threads run on as they would
    in a run, and the last block waits for them too (``settle``). Sums, not medians, so that
    the Rerun writer's batch every 100 steps counts. Opening (writer processes started, step 0
    written) and closing the files are one-off costs, timed apart in seconds.
    """
    from isaac.engine.simulation import Simulation

    plain, recorded = Simulation(scene), Simulation(scene)
    if batches:
        from isaac.app.run import batch_size

        size = batch_size(len(scene.bodies))
    else:
        for _ in range(20):  # load the compiled kernels outside the clock
            plain.step()
            recorded.step()
    from recorder import Recorder

    t_open = time.perf_counter()
    rec = Recorder(recorded, mcap_path=mcap_path, rrd_path=rrd_path)
    if not batches:
        rec.write(recorded.record())
    rec.wait_ready()
    rec.drain()
    opened = time.perf_counter() - t_open
    if batches:  # (a fresh simulation's step 0 is written by the recorder itself)
        for sim in (plain, recorded):  # the kernels (the writer's too) loaded off the clock
            for batch in sim.batches(20 + size, size=size):
                if sim is recorded:
                    rec.write_batch(batch)
        rec.drain(settle=True)
    t_plain = t_rec = 0.0
    done = 0
    while done < steps:
        n = min(BLOCK, steps - done)
        t0 = time.perf_counter()
        if batches:
            for _ in plain.batches(n, size=size):
                pass
        else:
            for _ in range(n):
                plain.step()
        t1 = time.perf_counter()
        if batches:
            for batch in recorded.batches(n, size=size):
                rec.write_batch(batch)
        else:
            for _ in range(n):
                rec.write(recorded.step())
        rec.drain(settle=done + n >= steps)
        t2 = time.perf_counter()
        t_plain += t1 - t0
        t_rec += t2 - t1
        done += n
    t0 = time.perf_counter()
    rec.close()
    return {
        "plain_ms_per_step": 1000.0 * t_plain / steps,
        "ms_per_step": 1000.0 * t_rec / steps,
        "overhead": t_rec / t_plain - 1.0,
        "open_s": opened,
        "close_s": time.perf_counter() - t0,
    }


def _time_in_process(scene_name: str, preset: str, steps: int, paths: dict) -> dict:
    """`_time_paired` in a process of its own (`--one`)."""
    cmd = [
        sys.executable,
        "-m",
        "bench.recording",
        "--scene",
        scene_name,
        "--preset",
        preset,
        "--steps",
        str(steps),
        "--one",
        json.dumps(paths),
    ]
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False, timeout=900)
    if proc.returncode != 0:
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or [f"exit {proc.returncode}"]
        raise RuntimeError(tail[0])
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _available(module: str) -> str | None:
    """None if `module` imports, else the reason."""
    import importlib

    try:
        importlib.import_module(module)
    except Exception as exc:  # noqa: BLE001 - any failure means "not there yet"
        return f"{module}: {type(exc).__name__}: {exc}"
    return None


def run(scene_name: str, preset: str, out_dir: str, reps: int, steps: int) -> dict:
    bench = build(scene_name)
    scene = with_preset(bench.scene, preset)
    result: dict = {
        "kind": "recording",
        "scene": scene_name,
        "engine": f"isaac-{preset}",
        "bodies": len(scene.bodies),
        "steps": steps,
        "reps": reps,
        "notes": [],
    }
    modes = {"plain": {}}
    missing = _available("recorder")
    if missing:
        result["notes"].append(f"recording skipped: {missing}")
    else:
        for mode, module, key in (
            ("mcap", "recorder.mcap_writer", "mcap_path"),
            ("rerun", "recorder.rerun_send", "rrd_path"),
        ):
            why = _available(module)
            if why:
                result["notes"].append(f"{mode} skipped: {why}")
            else:
                ext = "mcap" if mode == "mcap" else "rrd"
                modes[mode] = {key: os.path.join(out_dir, f"bench-{scene_name}.{ext}")}
        if "mcap" in modes and "rerun" in modes:
            modes["both"] = {**modes["mcap"], **modes["rerun"]}
    # each (repetition, mode) in a fresh process, modes interleaved: no run inherits another's
    # heap, caches or finished writer processes
    modes.pop("plain")
    runs: dict[str, list[dict]] = {m: [] for m in modes}
    errors: dict[str, str] = {}
    for _ in range(reps):
        for mode, paths in modes.items():
            if mode in errors:
                continue
            try:
                runs[mode].append(_time_in_process(scene_name, preset, steps, paths))
            except Exception as exc:  # noqa: BLE001 - a writer in progress: note it, go on
                errors[mode] = f"{type(exc).__name__}: {exc}"
    for mode, why in errors.items():
        result["notes"].append(f"{mode} failed: {why}")
    done = {m: rs for m, rs in runs.items() if rs}
    medians = {}
    if done:
        medians["plain"] = statistics.median(
            r["plain_ms_per_step"] for rs in done.values() for r in rs
        )
    medians.update({m: statistics.median(r["ms_per_step"] for r in rs) for m, rs in done.items()})
    result["ms_per_step"] = medians
    result["method"] = (
        f"plain and recorded simulations in lockstep, alternating blocks of "
        f"{BLOCK} steps in one process, {reps} processes per mode"
    )
    result["overhead_fraction"] = {
        m: statistics.median(r["overhead"] for r in rs) for m, rs in done.items()
    }
    result["overhead_reps"] = {m: [r["overhead"] for r in rs] for m, rs in done.items()}
    if "plain" in medians:
        result["overhead_ms_per_step"] = {
            m: medians["plain"] * f for m, f in result["overhead_fraction"].items()
        }
    for key in ("open_s", "close_s"):
        result[key] = {m: statistics.median(r[key] for r in rs) for m, rs in done.items()}
    for mode in ("mcap", "rerun"):
        if mode in medians and mode in modes:
            path = next(iter(modes[mode].values()))
            if os.path.exists(path):
                result[f"{mode}_bytes_per_step"] = os.path.getsize(path) / (steps + 1)
    if "mcap" in done:
        result["replay"] = replay_speed(scene, out_dir, steps, medians.get("plain"))
    else:
        result["replay"] = {"note": "replay skipped: no MCAP log was written"}
    return result


REPLAY_REPS = 3


def replay_speed(scene, out_dir: str, steps: int, plain_ms: float | None) -> dict:
    """The replay issue's comparison, replay against the original run: `isaac run SCENE --mcap`
    and `isaac replay` of its log as whole processes, REPLAY_REPS interleaved repetitions, each
    command's own loop rate (after its first step) and wall time (bench.replay_speed.compare).
    ``time_ratio`` is the replay's ms/step over the run's, the run's file finishing included
    (target <= 1.2); ``loop_time_ratio`` leaves that out."""
    why = _available("isaac.app.verify")
    if why:
        return {"note": f"replay skipped: {why}"}
    from pathlib import Path

    from bench.replay_speed import compare
    from isaac.scene import scene_to_yaml

    scene_path = Path(out_dir) / f"replay-{scene.name}.yaml"
    scene_path.write_text(scene_to_yaml(scene))
    try:
        out = compare(str(scene_path), REPLAY_REPS, Path(out_dir) / "replay", steps=steps)
    except RuntimeError as exc:
        return {"note": f"replay failed: {exc}", "identical": False}
    out["command"] = (
        f"isaac run SCENE --mcap LOG --steps {steps} against isaac replay LOG, "
        f"{REPLAY_REPS} interleaved repetitions of each, whole processes"
    )
    out["identical"] = True  # compare raises when a replay diverges
    if plain_ms:
        out["time_ratio_to_plain"] = (1000.0 / out["median_replay_steps_per_s"]) / plain_ms
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench.recording")
    parser.add_argument("--scene", default="pyramid-20")
    parser.add_argument("--preset", default="balanced")
    parser.add_argument("--out", default="bench/results")
    parser.add_argument("--reps", type=int, default=5)
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--one", metavar="JSON", help=argparse.SUPPRESS)  # one timed run
    args = parser.parse_args(argv)
    # the process-level tuning `isaac run` and the Recorder apply (isaac.tuning), applied up
    # front so the plain runs and the recorded runs of this process share it
    from isaac.tuning import reuse_large_buffers

    reuse_large_buffers()
    if args.one is not None:
        scene = with_preset(build(args.scene).scene, args.preset)
        sys.stdout.write(json.dumps(_time_paired(scene, args.steps, **json.loads(args.one))) + "\n")
        return 0
    os.makedirs(args.out, exist_ok=True)
    result = run(args.scene, args.preset, args.out, args.reps, args.steps)
    sys.stdout.write(json.dumps(result) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
