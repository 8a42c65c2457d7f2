"""The engine's own sub-commands: `isaac run` and `isaac check`."""

from __future__ import annotations

import argparse
import signal
import sys
import time
from pathlib import Path

from isaac.engine import diagnostics
from isaac.errors import IsaacError, SimulationError
from isaac.scene import load_scene


def register(subparsers) -> None:
    run = subparsers.add_parser("run", help="run a scene (optionally recording it)")
    run.add_argument("scene", help="scene YAML file")
    run.add_argument(
        "--steps", type=int, default=None, help="number of steps (default: the scene's world.steps)"
    )
    run.add_argument("--mcap", metavar="OUT.mcap", help="record the run to this MCAP log")
    run.add_argument("--rrd", metavar="OUT.rrd", help="record the run to this Rerun recording")
    run.add_argument("--quiet", action="store_true", help="no progress bar")
    run.add_argument("--verbose", action="store_true", help="also print start-up and compile time")
    run.add_argument(
        "--profile", action="store_true", help="print time spent in each stage of the step"
    )
    run.set_defaults(func=cmd_run)

    check = subparsers.add_parser("check", help="validate a scene and print its expanded size")
    check.add_argument("scene", help="scene YAML file")
    check.set_defaults(func=cmd_check)


def cmd_check(args: argparse.Namespace) -> int:
    scene = load_scene(args.scene)
    concrete = sum(b.concrete for b in scene.bodies)
    w = scene.world
    print(
        f"{args.scene}: ok: scene {scene.name!r}, {len(scene.bodies)} bodies "
        f"({concrete} concrete), dt {w.dt} s, {w.steps} steps, fidelity {w.fidelity}"
    )
    return 0


class _StopRequest:
    """Ctrl-C or SIGTERM, noted by the handler and acted on between steps, so a step and its
    records (MCAP and Rerun alike) are always written whole before the files are closed."""

    def __init__(self) -> None:
        self.signal: int | None = None

    def __call__(self, signum, frame) -> None:  # pragma: no cover - exercised via a subprocess
        self.signal = signum


def cmd_run(args: argparse.Namespace) -> int:
    from isaac.engine.simulation import (
        Simulation,
    )  # imported here: compiling kernels is not needed for --help

    started = time.perf_counter()
    scene = load_scene(args.scene)
    steps = scene.world.steps if args.steps is None else args.steps
    if steps < 0:
        raise IsaacError(f"--steps must be >= 0, got {steps}")
    sim = Simulation(scene)
    if args.profile:
        from isaac.app.profile import enable_profiling

        profiler = enable_profiling()
    recorder = None
    if args.mcap or args.rrd:
        from recorder import Recorder

        for out in (args.mcap, args.rrd):
            if out:
                Path(out).parent.mkdir(parents=True, exist_ok=True)
        recorder = Recorder(sim, mcap_path=args.mcap, rrd_path=args.rrd)

    first = sim.record()
    if recorder:
        recorder.write(first)
    energy_start = _energy(sim, first)
    contacts_seen = 0
    max_depth = 0.0
    last = first
    progress = None
    if not args.quiet and sys.stderr.isatty():
        from tqdm import tqdm

        progress = tqdm(total=steps, unit="step", desc=scene.name, leave=False)
    stop = _StopRequest()
    previous = {sig: signal.signal(sig, stop) for sig in (signal.SIGTERM, signal.SIGINT)}
    stopped = None
    finished = False
    first_step_at = None
    loop_start = time.perf_counter()
    try:
        for _ in range(steps):
            if stop.signal is not None:
                name = signal.Signals(stop.signal).name
                stopped = ("interrupted", f"{name} after step {sim.step_index}")
                break
            last = sim.step()
            if first_step_at is None:
                first_step_at = time.perf_counter()
            if recorder:
                recorder.write(last)
            n = len(last.contacts)
            if n:
                contacts_seen += n
                max_depth = max(max_depth, float(last.contacts.depth.max()))
            if progress:
                progress.update(1)
        finished = stopped is None
    except SimulationError as exc:
        stopped = ("error", str(exc))
    finally:
        loop_end = time.perf_counter()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        if progress:
            progress.close()
        if recorder:
            if finished:
                recorder.close(complete=True)
            else:
                reason = stopped[1] if stopped else "the run failed"
                recorder.close(complete=False, stopped_at=sim.step_index, reason=reason)
    finished_files = time.perf_counter() - loop_end
    taken = last.step - first.step
    # the first step also loads (or compiles) the kernels: the rate is measured after it, up to
    # the last step handed to the recorder; finishing the files is a one-off, reported apart
    timed_steps = taken - 1
    elapsed = loop_end - (first_step_at or loop_start)
    rate = timed_steps / elapsed if timed_steps > 0 and elapsed > 0 else 0.0
    energy_end = _energy(sim, last)
    print(
        f"scene {scene.name!r}: {taken} steps of {scene.world.dt} s, {sim.n_bodies} bodies, "
        f"fidelity {scene.world.fidelity}"
    )
    print(
        f"  contacts seen {contacts_seen}, max depth {max_depth:.6g} m, "
        + (
            f"{rate:.1f} steps/s ({1e3 / rate:.3f} ms/step, after the first step)"
            if rate
            else "too few steps to measure a rate"
        )
    )
    print(f"  energy (kinetic + potential) start {energy_start:.6g} J, end {energy_end:.6g} J")
    if recorder:
        print(
            f"  recording: files finished {finished_files:.2f} s after the last step (the "
            f"writers' last steps, summary, index)"
        )
    if args.verbose and first_step_at is not None:
        print(
            f"  start-up to first step {first_step_at - started:.3f} s "
            f"(includes loading or compiling the kernels)"
        )
    if args.profile:
        print(profiler.report(taken))
    for label, out in (("MCAP log", args.mcap), ("Rerun recording", args.rrd)):
        if out:
            print(f"  {label}: {out}")
    if stopped:
        kind, message = stopped
        print(
            f"isaac run: {'error: ' if kind == 'error' else ''}{message}; "
            f"stopped at step {sim.step_index}, the steps before it are recorded",
            file=sys.stderr,
        )
        return 3 if kind == "error" else 130
    return 0


def _energy(sim, record) -> float:
    totals = diagnostics.summary(sim.model, record, sim.scene.world.gravity)
    return totals.kinetic_energy + totals.potential_energy
