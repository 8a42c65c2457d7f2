"""The engine's own sub-commands: `isaac run` and `isaac check`."""

from __future__ import annotations

import argparse
import os
import signal
import sys
import time
from itertools import chain

from isaac.app.options import integer
from isaac.errors import LogError, SimulationError
from isaac.sizes import byte_size


def _steps(text: str) -> int:
    """--steps: 0 to a scene's own bound on world.steps (isaac.scene.limits.MAX_STEPS)."""
    from isaac.scene.limits import MAX_STEPS  # numpy: imported once --steps is given

    return integer(minimum=0, maximum=MAX_STEPS)(text)


def register(subparsers) -> None:
    run = subparsers.add_parser("run", help="run a scene (optionally recording it)")
    run.add_argument("scene", help="scene YAML file")
    run.add_argument(
        "--steps",
        type=_steps,
        default=None,
        help="number of steps (default: the scene's world.steps; at most 100000000, as there)",
    )
    run.add_argument("--mcap", metavar="OUT.mcap", help="record the run to this MCAP log")
    run.add_argument("--rrd", metavar="OUT.rrd", help="record the run to this Rerun recording")
    run.add_argument("--quiet", action="store_true", help="no progress bar")
    run.add_argument("--verbose", action="store_true", help="also print start-up and compile time")
    run.add_argument(
        "--profile", action="store_true", help="print time spent in each stage of the step"
    )
    run.add_argument(
        "--compression",
        choices=("zstd", "lz4", "none"),
        default="lz4",
        help="MCAP chunk compression (default: lz4, about a third smaller for a few percent of "
        "the run's time; docs/log-format.md has the measured cost and size of each)",
    )
    run.add_argument(
        "--offload",
        choices=("auto", "process", "thread", "none"),
        default="auto",
        help="where the files are written: writer processes, a thread, or this process "
        "(default auto: processes when the machine has an idle CPU for each, else a thread); "
        "with auto or thread, a Rerun recording is sent by a process of its own",
    )
    run.add_argument(
        "--force",
        action="store_true",
        help="replace an OUT.partial file left by an earlier run (default: refuse, so that "
        "`isaac recover` can save its steps)",
    )
    run.set_defaults(func=cmd_run)

    check = subparsers.add_parser("check", help="validate a scene and print its expanded size")
    check.add_argument("scene", help="scene YAML file")
    check.set_defaults(func=cmd_check)


def _warn(command: str, scene, steps: int | None = None) -> None:
    """The scene's warnings (isaac.scene.warnings) for a run of `steps` steps (default the
    scene's), one line each on stderr; not errors."""
    from isaac.scene.warnings import scene_warnings

    for line in scene_warnings(scene, steps):
        print(f"isaac {command}: warning: {line}", file=sys.stderr)


def cmd_check(args: argparse.Namespace) -> int:
    from isaac.scene import load_scene

    scene = load_scene(args.scene)
    _warn("check", scene)
    concrete = sum(b.concrete for b in scene.bodies)
    w = scene.world
    written = dict(scene.as_written).get("world.dt")  # `dt: 1/120`, as the scene says it
    dt = f"{written} s ({w.dt!r})" if written else f"{w.dt} s"
    joints = f", {len(scene.joints)} joints" if scene.joints else ""
    print(
        f"{args.scene}: ok: scene {scene.name!r}, {len(scene.bodies)} bodies "
        f"({concrete} concrete){joints}, dt {dt}, {w.steps} steps, fidelity {w.fidelity}"
    )
    return 0


# Ctrl-C, SIGTERM, and SIGHUP (the terminal closed): each stops the run between steps and lets
# the files be finished
_STOP_SIGNALS = (signal.SIGTERM, signal.SIGINT, signal.SIGHUP)


class _StopRequest:
    """Ctrl-C, SIGTERM or SIGHUP, noted by the handler and acted on between steps, so a step and its
    records (MCAP and Rerun alike) are always written whole before the files are closed.

    The handler stays until the files are closed: a signal while they are being finished is
    noted too and only reported once they are (a default handler would kill the run with the
    files half-written, or raise KeyboardInterrupt inside the close)."""

    def __init__(self) -> None:
        self.signal: int | None = None

    def __call__(self, signum, frame) -> None:  # pragma: no cover - exercised via a subprocess
        if self.signal is None:
            self.signal = signum


def _claim_outputs(args: argparse.Namespace) -> tuple[dict, list]:
    """Check and claim the output files before anything is computed: ({"mcap": OutputClaim,
    "rrd": OutputClaim} for those given, the directories made for them, for `_unmake`).
    Raises LogError (one line, exit 2) for an output that is the scene or the other output,
    whose directory cannot be made, that is not a file, that another run is writing, or whose
    .partial holds an earlier run's steps (without --force); the directories it made are then
    removed again."""
    outputs = {label: out for label, out in (("--mcap", args.mcap), ("--rrd", args.rrd)) if out}
    if not outputs:
        return {}, []
    from recorder.outputs import check_distinct, claim

    check_distinct(outputs, {"scene file": args.scene})
    made = []
    claims = {}
    try:
        for out in outputs.values():
            made += _make_parent(out)
        for kind, label in (("mcap", "--mcap"), ("rrd", "--rrd")):
            if label in outputs:
                claims[kind] = claim(
                    outputs[label],
                    kind,
                    replace_partial=args.force,
                    force_hint="pass --force to replace it",
                )
    except BaseException:
        for c in claims.values():
            c.release(discard=True)
        _unmake(made)
        raise
    return claims, made


def _make_parent(out: str) -> list[str]:
    """Create the directory of output ``out`` (and its parents); LogError in one line if not.
    Returns the directories it created, deepest first."""
    parent = os.path.dirname(os.path.abspath(out))
    existing = parent
    missing = []
    while not os.path.lexists(existing):
        missing.append(existing)
        existing = os.path.dirname(existing)
    if not os.path.isdir(existing):
        raise LogError(f"cannot write {out}: {existing} is not a directory")
    try:
        os.makedirs(parent, exist_ok=True)
    except OSError as exc:
        raise LogError(f"cannot write {out}: cannot create {parent}: {exc.strerror}") from exc
    return missing


def _unmake(made: list[str]) -> None:
    """Remove the directories `_make_parent` created, where still empty: a run
    that stopped before its files were opened leaves nothing behind."""
    for directory in sorted(made, key=len, reverse=True):  # a child before its parent
        try:
            os.rmdir(directory)
        except OSError:  # not empty (something else wrote there), or already gone
            pass


def _plan_recording(args: argparse.Namespace, claims: dict, scene, steps: int) -> str:
    """Where the files are written (``--offload``; ``auto``: `choose_offload` on the log's
    expected size), saying first what a long run will write.

    A run whose log is surely small (`simple_log_bound` under LONG_RUN_BYTES) skips the
    estimate, which loads a compiled kernel (`recorder.pack.message_sizes`) before the engine
    is imported: there is nothing to announce, and `choose_offload` picks "thread" for any log
    under SMALL_RUN_BYTES (> LONG_RUN_BYTES)."""
    if simple_log_bound(len(scene.bodies), steps) < LONG_RUN_BYTES:
        return "thread" if args.offload == "auto" else args.offload
    from recorder.frames import ROWS_PER_MOVING_BODY as ROWS_PER_MOVING
    from recorder.frames import expected_log_bytes
    from recorder.writer_process import choose_offload

    moving = sum(not b.concrete for b in scene.bodies)
    per_step, total = expected_log_bytes(len(scene.bodies), moving, steps)
    if args.mcap and total >= LONG_RUN_BYTES:  # a long run says first what it will write
        share = COMPRESSED_SHARE.get(args.compression)
        packed = f"; {args.compression} measured {share[0]:g}-{share[1]:g} of that" if share else ""
        print(
            f"expected MCAP log size: about {byte_size(total)} ({byte_size(per_step)} a step x "
            f"{steps + 1} steps, uncompressed{packed}; contacts estimated at "
            f"{ROWS_PER_MOVING:g} points per moving body)",
            file=sys.stderr,
        )
    if args.offload != "auto":
        return args.offload
    # a short run does not wait for writer processes to start
    return choose_offload(len(claims), log_bytes=total)


def _start_sender(offload: str, claims: dict) -> dict:
    """{"rrd": the Rerun sender process} when a Rerun recording is asked for and ``--offload``
    is auto or thread, started at once (`recorder.spawn.start_sender_child`), before the scene
    is read: it imports rerun-sdk (0.4-0.5 s of CPU) while this process imports numpy, numba
    and the engine and runs, and sends what this process draws
    (`recorder.writer_process.RerunSendProcess`). {} otherwise: with ``--offload process`` the
    Rerun writer process draws and sends, with ``none`` this process does both."""
    if "rrd" not in claims or offload not in ("auto", "thread"):
        return {}
    from recorder.spawn import start_sender_child

    return {"rrd": start_sender_child(claims["rrd"].fd)}


def _prepare_sender(children: dict, claims: dict, scene) -> None:
    """Tell the Rerun sender, if started, what the scene says of the recording
    (`recorder.spawn.WriterChild.prepare`)."""
    if "rrd" in children:
        children["rrd"].prepare(
            partial_path=claims["rrd"].partial_path,
            recording_id=f"isaac-{scene.name}",
            joints=bool(scene.joints),
            moving=sum(not b.concrete for b in scene.bodies),
        )


def _start_writers(offload: str, claims: dict) -> dict:
    """With offload "process", the writer processes started now, before the simulation is
    built, so that their start-up (importing mcap or rerun-sdk, opening the file) overlaps the
    building and the kernels' loading (`recorder.spawn`); {} otherwise."""
    if offload != "process":
        return {}
    from recorder.spawn import start_writer_child

    children = {}
    try:
        for k in ("mcap", "rrd"):
            if k in claims:
                children[k] = start_writer_child("rerun" if k == "rrd" else "mcap", claims[k].fd)
    except BaseException:
        for child in children.values():
            child.discard()
        raise
    return children


def _compiling(scene, *, say: bool) -> bool:
    """Whether numba's cache lacks the step's kernels (the first run on a machine, or after
    the engine changed): the run then compiles the stages before its first step (8.2-10.4 s to
    it on the idle 2-core machine), steps on them while a helper compiles the driver, and waits
    for that helper at its end (15.7-20.5 s in all; bench/README.md). say: one line on stderr
    then, where a new user would otherwise see nothing."""
    from isaac.engine.compile_ahead import is_cold, solver_kernel
    from isaac.engine.step import StepSettings

    cold = is_cold(solver_kernel(StepSettings.of(scene.world)))
    if cold and say:
        print(
            "compiling the engine's kernels into numba's cache (once: the first steps come "
            "after about 10 s, and a first run takes 15-40 s in all; later runs load them in "
            "under a second)",
            file=sys.stderr,
        )
    return cold


def _start_recorder_helper(claims: dict, offload: str, scene, *, say: bool):
    """With an empty numba cache for the recorder's kernels, the helper process that compiles
    them beside this one (`recorder.compile_ahead`), or None. Not with writer processes
    (``--offload process``), which pack and draw in kernels of their own. say: one line on
    stderr when it starts (a run whose engine compiles says so already)."""
    mcap = "mcap" in claims and offload != "process"
    rrd = "rrd" in claims and offload != "process"
    if not (mcap or rrd):
        return None
    from recorder import compile_ahead

    if not compile_ahead.cold(mcap, rrd):
        return None
    if say:
        print(
            "compiling the recorder's kernels into numba's cache before the first step (once; "
            "later runs load them)",
            file=sys.stderr,
        )
    return compile_ahead.start(scene.world, mcap=mcap, rrd=rrd, joints=bool(scene.joints))


def _finish_recorder_helper(helper, sim, *, profile: bool) -> None:
    """The driver compiled (or loaded) while the recorder's helper still runs, unless a helper
    of the engine's compiles it (`Simulation(tiered=True)`), then the recorder's helper waited
    for: the recorder loads its kernels from the cache it filled. The driver would otherwise
    compile at the first step, after the wait, with one core idle (2-core machine: the
    helper's 24 s of compiling are longer than the engine's 17-20 s)."""
    from isaac.engine.compile_ahead import compile_driver
    from recorder.compile_ahead import finish

    if not sim.compiling_driver:
        scene = sim.scene
        compile_driver(scene.world, joints=bool(scene.joints), timed=profile)
    finish(helper)


def _finish_compiling(sim, *, say: bool, interrupted: bool) -> None:
    """At the end of a run on a cold cache whose driver's helper still compiles: wait for it, so
    that the next run loads the driver (no process is left behind); or, when the run was
    interrupted, stop it (the user asked to stop, not to wait). say: one line on stderr before
    the wait, since the run's output is complete."""
    if interrupted:
        sim.finish_compiling(stop=True)
        return
    if say and sim.compiling_driver:
        sys.stdout.flush()  # (the summary first)
        print(
            "finishing the compiled driver in numba's cache for later runs (once)",
            file=sys.stderr,
            flush=True,
        )
    sim.finish_compiling()


def _pause_collector(args: argparse.Namespace) -> bool:
    """As the `isaac` command (``args.owns_process``): pause Python's cyclic collector until
    `_settle_collector`. Why: importing numpy, numba and the engine and loading the kernels
    makes some 500,000 objects that live as long as the process, and the collector walked them
    all, to free nothing, 40-60 ms of a 0.45 s start (2-core machine). Returns whether it was
    running (False when not paused)."""
    if not getattr(args, "owns_process", False):
        return False
    import gc

    running = gc.isenabled()
    gc.disable()
    return running


def _settle_collector(running: bool) -> bool:
    """Once the run is set up (or before kernels are compiled, which makes garbage the
    collector must free): what start-up made is frozen out of every later collection
    (`gc.freeze`: never walked, never freed by the collector; a command's process ends with
    its run), and the collector runs again if `_pause_collector` paused it. Returns False (so
    a second call does nothing)."""
    if running:
        import gc

        gc.freeze()
        gc.enable()
    return False


def cmd_run(args: argparse.Namespace) -> int:
    started = time.perf_counter()
    collector_running = _pause_collector(args)
    # the outputs are claimed and the Rerun sender started before the scene is read (which
    # imports numpy and numba): the sender's import of rerun-sdk, the longest part of a short
    # recorded run, starts 0.15-0.2 s sooner
    claims, made = _claim_outputs(args)
    children = {}
    helper = None
    try:
        children = _start_sender(args.offload, claims)
        from isaac.scene import load_scene

        scene = load_scene(args.scene)
        steps = scene.world.steps if args.steps is None else args.steps
        _warn("run", scene, steps)
        _prepare_sender(children, claims, scene)
        offload = _plan_recording(args, claims, scene, steps) if claims else args.offload
        children.update(
            _start_writers(offload, {k: c for k, c in claims.items() if k not in children})
        )
        # imported here, after the writers started: compiling kernels is not needed for --help
        from isaac.engine.simulation import Simulation

        compiling = _compiling(scene, say=not args.quiet)
        helper = _start_recorder_helper(claims, offload, scene, say=not (args.quiet or compiling))
        if compiling or helper is not None:
            collector_running = _settle_collector(collector_running)
        # --profile: the timed driver; tiered: with a cold cache, the run steps on the staged
        # path while a helper compiles the driver (`Simulation`)
        sim = Simulation(scene, profile=args.profile, tiered=True)
        if helper is not None:
            _finish_recorder_helper(helper, sim, profile=args.profile)
            helper = None
    except BaseException:
        if helper is not None:
            from isaac.engine.compile_ahead import stop_helper

            stop_helper(helper)
        for child in children.values():
            child.discard()
        for c in claims.values():
            c.release(discard=True)
        _unmake(made)
        raise
    recorder = None
    first = last = sim.record()
    energy_start = _energy(sim, first)
    energy = _energy_check(sim, first, energy_start)
    contacts_seen = 0
    max_depth = 0.0
    progress = None
    stop = _StopRequest()
    # handled from before the files are opened until they are closed (see _StopRequest)
    previous = {sig: signal.signal(sig, stop) for sig in _STOP_SIGNALS}
    stopped = None
    signal_in_close = None
    finished = False
    first_step_at = None
    loop_start = loop_end = time.perf_counter()
    try:
        if claims:
            from recorder import Recorder

            recorder = Recorder(
                sim,
                mcap_path=claims.get("mcap"),
                rrd_path=claims.get("rrd"),
                offload=offload,
                compression=args.compression,
                children=children,
            )
            claims = children = {}  # the recorder owns them now
            recorder.write(first)
        if not args.quiet and sys.stderr.isatty():
            from tqdm import tqdm

            progress = tqdm(total=steps, unit="step", desc=scene.name, leave=False)
        collector_running = _settle_collector(collector_running)
        loop_start = time.perf_counter()
        # whole batches of steps per compiled call (`Simulation.batches`); a stop request is
        # acted on between batches, which are small enough to keep that prompt
        size = batch_size(sim.n_bodies)
        # (the first step alone: it also loads or compiles the kernels, and the rate is
        # measured after it)
        batches = chain(
            sim.batches(min(1, steps), size=1), sim.batches(max(steps - 1, 0), size=size)
        )
        for batch in batches:
            if recorder:
                recorder.write_batch(batch)
            if first_step_at is None:  # (its recording loads or compiles the packer too)
                first_step_at = time.perf_counter()
            energy.add(*_batch_energies(sim, last, batch))
            last = batch.record(batch.steps - 1)
            depth = batch.all_contacts().depth
            if len(depth):
                contacts_seen += len(depth)
                max_depth = max(max_depth, float(depth.max()))
            if progress:
                progress.update(batch.steps)
            if stop.signal is not None and sim.step_index < first.step + steps:
                name = signal.Signals(stop.signal).name
                stopped = ("interrupted", f"interrupted by {name}")
                break
        finished = stopped is None
    except SimulationError as exc:
        stopped = ("error", str(exc))
    finally:
        loop_end = time.perf_counter()
        try:
            if progress:
                progress.close()
            for child in children.values():  # the recorder never started
                child.discard()
            for c in claims.values():
                c.release(discard=True)
            if recorder:
                if finished:
                    recorder.close(complete=True)
                else:
                    reason = stopped[1] if stopped else "the run failed"
                    # stopped at the last step the recorder took (its default), as the summary says
                    recorder.close(complete=False, reason=reason)
                if stopped is None:  # a signal the loop did not act on: during the close
                    signal_in_close = stop.signal
        finally:
            for sig, handler in previous.items():
                signal.signal(sig, handler)
    finished_files = time.perf_counter() - loop_end
    taken = last.step - first.step
    # the first step also loads (or compiles) the kernels: the rate is measured after it, up to
    # the last step handed to the recorder; finishing the files is a one-off, reported apart
    timed_steps = taken - 1
    elapsed = loop_end - (first_step_at or loop_start)
    rate = timed_steps / elapsed if timed_steps > 0 and elapsed > 0 else 0.0
    energy_end = _energy(sim, last)
    # "stopped at step K" means one thing everywhere (run, inspect, recover): K is the last step
    # whose state the run completed and, with files, the last step in them
    files = " and ".join(out for out in (args.mcap, args.rrd) if out)
    where = f"the last step in {files}" if files else "the last step simulated"
    # with files: the recorder's last step (a NaN it found mid-batch stops the log before it)
    recorded = recorder.last_step if recorder is not None else None
    stopped_at = f"stopped at step {last.step if recorded is None else recorded}, {where}"
    ran = f"{taken} steps"
    if stopped is not None:  # the error itself is the last line, on stderr
        ran = f"{'failed' if stopped[0] == 'error' else stopped[1]}: {taken} of {steps} steps"
    print(
        f"scene {scene.name!r}: {ran} of {scene.world.dt} s, {sim.n_bodies} bodies, "
        f"fidelity {scene.world.fidelity}" + ("" if stopped is None else f"; {stopped_at}")
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
    print(f"  {energy.summary()}")
    if recorder:
        print(
            f"  recording: files finished {finished_files:.2f} s after the last step (the "
            f"writers' last steps, summary, index); written by offload {recorder.offload}"
        )
    if args.verbose and first_step_at is not None:
        print(
            f"  start-up to first step {first_step_at - started:.3f} s "
            f"(includes loading or compiling the kernels)"
        )
    if args.profile:
        from isaac.app.profile import report

        print(report(sim.stage_times(), taken, 1e3 / rate if rate else None))
    for label, out in (("MCAP log", args.mcap), ("Rerun recording", args.rrd)):
        if out:
            print(f"  {label}: {out}")
    if energy.flagged:  # a result, not an error: the run's exit status is unchanged
        sys.stdout.flush()
        print(f"isaac run: warning: {energy.warning()}", file=sys.stderr)
    interrupted = (stopped is not None and stopped[0] != "error") or signal_in_close is not None
    _finish_compiling(sim, say=not args.quiet, interrupted=interrupted)
    if stopped is None and signal_in_close is not None:
        files = ", ".join(out for out in (args.mcap, args.rrd) if out)
        print(
            f"isaac run: interrupted ({signal.Signals(signal_in_close).name}) while finishing "
            f"the files; they were finished first and are complete: {files}",
            file=sys.stderr,
        )
        return 130
    if stopped:
        kind, message = stopped
        print(
            f"isaac run: {'error: ' if kind == 'error' else ''}{message}; {stopped_at}",
            file=sys.stderr,
        )
        return 3 if kind == "error" else 130
    return 0


# a recording expected to take this much (MCAP, uncompressed) is announced with its size first
LONG_RUN_BYTES = 50_000_000
# `simple_log_bound`: bytes a step at most besides the bodies' (varints, heads, the /stats
# message and the records' overhead), and a body's at most (its /bodies row, 49 bytes, and the
# /contacts rows `expected_log_bytes` assumes for a moving body, 205 bytes; 254 in all)
BOUND_STEP_BYTES = 1024
BOUND_BODY_BYTES = 256


def simple_log_bound(n_bodies: int, steps: int) -> int:
    """An upper bound of `recorder.frames.expected_log_bytes` (uncompressed MCAP bytes of a run
    of ``steps`` steps after step 0), by arithmetic alone: no kernel is loaded."""
    return (BOUND_STEP_BYTES + BOUND_BODY_BYTES * n_bodies) * (steps + 1)


# compressed size / uncompressed size of the log, measured on scenes/default.yaml and
# scenes/pile.yaml (log format 2, docs/log-format.md): what the expected size says beside it
COMPRESSED_SHARE = {"lz4": (0.68, 0.82), "zstd": (0.61, 0.71)}


def batch_size(n_bodies: int) -> int:
    """Steps per compiled call of a run: 64 for small scenes, fewer as they grow (about 4,096
    body-steps a batch), so that a stop request waits for at most a few steps of a large scene."""
    return max(1, min(64, 4096 // max(1, n_bodies)))


def _energy(sim, record) -> float:
    from isaac.engine import diagnostics  # compiled kernels: `isaac check` does without them

    totals = diagnostics.summary(sim.model, record, sim.scene.world.gravity)
    return totals.kinetic_energy + totals.potential_energy


def _energy_check(sim, first, start_energy: float):
    """The run's energy check (`isaac.engine.energy_check`) from its first record."""
    from isaac.engine.energy_check import EnergyCheck

    model = sim.model
    motors = bool(model.joints.has_motor.any())
    return EnergyCheck.of(model, first, sim.scene.world.gravity, start_energy, motors=motors)


def _batch_energies(sim, before, batch):
    """(total, entered) energies (J) of each step of a batch (`diagnostics.batch_energies`)."""
    from isaac.engine import diagnostics

    return diagnostics.batch_energies(sim.model, before, batch, sim.scene.world.gravity)
