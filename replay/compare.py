"""Replay a log against a re-simulation (`replay_log`) or compare two logs (`diff_logs`).

How a replay works (docs/replay.md):
1. the scene is the one embedded in the log (never a file on disk), checked against the sha256
   recorded beside it; the versions and machine recorded in the log are compared with this one;
2. the simulation starts from the scene's initial state (step 0), or from the state logged at
   ``from_step`` (every logged step is a keyframe: state + the contacts that warm-start the next
   step);
3. for every logged step the re-simulated record is encoded with the recorder's own encoders and
   the bytes are compared with the logged payloads (``/world`` when the set of bodies changed,
   ``/bodies``, ``/contacts``, ``/stats``). Equal bytes are the common case and cost one memcmp;
   only when they differ are both sides decoded to find the field, the body or contact row, the
   two values and their distance in ULPs;
4. the first divergence ends a bitwise replay. With ``all_steps`` or a ``tolerance`` the replay
   goes on, restarting from the logged state of the step that differed, so each later step is
   checked against its own logged predecessor and one difference is not counted a thousand times.

`diff_logs` walks two logs step by step and compares their payloads the same way.
A divergence is a result (`replay.report.Report`), never an exception; a bad file raises
LogError / SceneError (exit status 2).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import fields

import numpy as np

from isaac.engine import PHYSICS_VERSION
from isaac.engine.records import StepRecord
from isaac.errors import LogError, SimulationError, StateError
from isaac.scene import Scene
from recorder import schema as S
from recorder.mcap_writer import (
    FORMAT_VERSION,
    build_metadata,
    encode_bodies,
    encode_contacts,
    encode_contacts_v1,
    encode_joints,
    encode_stats,
    joint_table_rows,
)
from recorder.reader import DECODE_ERRORS, record_from_messages
from recorder.stats import compute_stats
from replay.divergence import MalformedMessage, check_payload, locate
from replay.reader import Prefetch, RawLog, RawStep
from replay.replayed import ReplayedSteps
from replay.report import DEFAULT_MAX_REPORTED, Divergence, Report

# metadata keys whose difference voids the promise of bit-identical results
VERSION_KEYS = (
    "engine_version",
    "python_version",
    "python_implementation",
    "numpy_version",
    "numba_version",
    "machine",
    "cpu",
    "byteorder",
)
SUGGESTED_TOLERANCE = 1e-9
# steps the reading thread hands over at once (`replay.reader.Prefetch`), or fewer once they
# hold this many bytes: one hand-over costs a few microseconds, as much as reading a small
# scene's step (the bounce log replayed in-process: 34,900 -> 44,600 steps/s, medians of 5)
READ_GROUP = 64
READ_GROUP_BYTES = 1 << 20


class PhysicsVersionDiffers(LogError):
    """The log was recorded by another physics version (CHANGELOG.md): a bit-for-bit replay
    cannot match, so it is refused before anything is simulated (exit status 1, not 2: the file
    is fine, the verdict is that it does not replay)."""

    exit_status = 1


def check_tolerance(tolerance: float | None) -> None:
    """A tolerance is None (bit for bit) or a finite number >= 0, else LogError (exit 2): with
    an infinite one, ``X * (1 + |a|)`` is NaN where a value is 0 (``inf * 0``), and equal values
    were reported as diverged; a NaN one compared nothing as equal."""
    if tolerance is not None and not (np.isfinite(tolerance) and tolerance >= 0):
        raise LogError(f"--tolerance must be a finite number >= 0, got {tolerance!r}")


def physics_version(metadata: dict) -> str:
    """The physics version a log's metadata records ("1" for logs from before it was recorded)."""
    return metadata.get("physics_version") or "1"


def physics_note(logged: dict, here: dict, *, what: str = "here") -> str | None:
    """One line when the physics versions differ (None when they agree)."""
    a, b = physics_version(logged), physics_version(here)
    if a == b:
        return None
    return f"physics version {a} in the log, {b} {what} (CHANGELOG.md lists what changed)"


_CHANNEL_ORDER = ("/world", "/contacts", "/bodies", "/joints", "/stats")


def versions_note(
    logged: dict, here: dict, *, what: str = "here", suggest: bool = True, physics: bool = True
) -> str | None:
    """A note when the versions or the machine differ (None when they all agree); the physics
    version among them unless ``physics`` is False (a replay says it on its own line)."""
    diffs = []
    a, b = physics_version(logged), physics_version(here)
    if physics and a != b:
        diffs.append(f"physics {a} in the log, {b} {what}")
    for key in VERSION_KEYS:
        a, b = logged.get(key), here.get(key)
        if a != b:
            diffs.append(f"{key.replace('_version', '')} {a or '?'} in the log, {b or '?'} {what}")
    os_a = (logged.get("platform") or "?").split("-")[0]
    os_b = (here.get("platform") or "?").split("-")[0]
    if os_a != os_b:
        diffs.append(f"system {os_a} in the log, {os_b} {what}")
    if not diffs:
        return None
    text = "versions or platform differ (" + "; ".join(diffs) + ")"
    if suggest:
        text += (
            ": bit-identical results are promised for the same versions of ISAAC, Python, numpy "
            "and numba, on any machine (docs/physics.md); if this replay diverges, compare with "
            f"--tolerance {SUGGESTED_TOLERANCE:g}"
        )
    return text


def load_embedded_scene(log: RawLog) -> tuple[Scene, list[str]]:
    """The log's embedded scene, validated and checked against its recorded sha256
    (`recorder.reader.LogReader.scene`).

    Returns (scene, notes). Raises LogError if the scene text was altered (its sha256 does not
    match the metadata) and SceneError if it fails validation. A metadata value that disagrees
    with the scene is damage (``log.damage`` after the steps), not an error: the steps are
    still compared.
    """
    scene = log.header.scene()
    return scene, list(log.header.header_notes)


def _completeness(
    log: RawLog, report: Report, *, to_step: int | None, label: str = "", partial: bool
) -> None:
    """Whether every step the log claims (or the ``--to-step`` window) was read whole: sets
    ``complete``, ``damage``, ``claimed_steps`` and the explaining note (``truncated_detail``)."""
    report.partial = partial
    damage = log.damage
    name = f"log {label}: " if label else ""
    if report.claimed_steps is None or (log.claimed_steps or 0) > report.claimed_steps:
        report.claimed_steps = log.claimed_steps
    if damage is not None and to_step is not None and (damage.step or -1) > to_step:
        # beyond the window asked for: the window itself was read whole
        report.notes.append(f"{name}the log is damaged after --to-step {to_step}: {damage}")
        return
    if not log.read_through and damage is None:
        return  # stopped at --to-step: the window was read whole
    if damage is not None:
        complete = False
        why = f"{name}the log is damaged from {damage.at()} on"
        if damage is log.header.header_damage:
            why = (
                f"{name}its metadata does not say what its embedded scene says (the scene, "
                f"checked against its sha256, is what was replayed)"
            )
        text = name + str(damage)
        report.damage = text if not report.damage else f"{report.damage}; {text}"
        if damage.step is not None and (
            report.damage_step is None or damage.step < report.damage_step
        ):
            report.damage_step = damage.step
        if report.damage_offset is None:
            report.damage_offset = damage.offset
    elif not log.complete:
        complete = False
        why = (
            f"{name}the log was not closed (the run crashed or was killed, or the file was "
            f"cut): without its summary it cannot prove that nothing follows its last step"
        )
        if log.incomplete_tail is not None:
            why += f" (step {log.incomplete_tail} was only partly written)"
    else:
        complete = True
        end = log.end or {}
        if end.get("complete") != "true":
            reason = end.get("reason") or "no reason given"
            report.notes.append(
                f"{name}the logged run did not finish: stopped at step "
                f"{end.get('stopped_at') or '?'} ({reason})"
            )
    if complete:
        return
    report.complete = False
    report.truncated = True
    hint = (
        "--partial accepted the complete steps before that"
        if partial
        else "--partial checks the complete steps before that; `isaac recover` writes them "
        "as a clean log"
    )
    detail = f"{why}; {hint}"
    report.truncated_detail = (
        detail if not report.truncated_detail else f"{report.truncated_detail}; {detail}"
    )


# ---------------------------------------------------------------------------------------------
# replay


def _logged_record(raw: RawStep, path: str, n_bodies: int) -> StepRecord:
    """The logged state of a step, to go on from (LogError if it does not decode, does not
    fit together or is not a state of this scene's ``n_bodies`` bodies)."""
    try:
        bodies = S.decode("Bodies", raw.messages["/bodies"])
        contacts = S.decode("Contacts", raw.messages["/contacts"])
        # the logged joints carry the warm-start impulses the engine goes on from
        joints = raw.messages.get("/joints")
        joints = None if joints is None else S.decode("Joints", joints)
        record = record_from_messages(bodies, contacts, joints)
    except DECODE_ERRORS as exc:
        raise LogError(
            f"{path}: damaged log: step {raw.step}: the logged state does not decode ({exc})"
        ) from None
    if record.position.shape[0] != n_bodies or record.step != raw.step:
        raise LogError(
            f"{path}: damaged log: step {raw.step}: the logged state is step {record.step} of "
            f"{record.position.shape[0]} bodies; the scene has {n_bodies}"
        )
    return record


def _compare_step(
    raw: RawStep,
    ours: dict,
    names: list,
    tolerance: float | None,
    report: Report,
    *,
    path: str,
    paths: tuple[str, str] | None = None,
    sides: tuple[str, str] = ("logged", "replayed"),
    joint_names: list | None = None,
) -> tuple[bool, bool]:
    """Compare one step's payloads. Returns (bytes all equal, beyond tolerance somewhere).

    LogError ("damaged log", naming ``path``, or ``paths[side]`` for a diff) if a payload that
    differs does not decode or its arrays do not fit together."""
    found = []
    equal = True
    for topic in _CHANNEL_ORDER:
        mine = ours.get(topic)
        theirs = raw.messages.get(topic)
        if mine is None and theirs is None:
            continue
        if mine is None or theirs is None:
            equal = False
            side = f"{sides[0]} only" if mine is None else f"{sides[1]} only"
            found.append(
                Divergence(
                    raw.step,
                    topic,
                    "missing",
                    detail=(
                        f"a {topic} message is {side} (the set of existing bodies changed on one "
                        f"side only)"
                        if topic == "/world"
                        else f"a {topic} message is {side}"
                    ),
                )
            )
            continue
        if mine == theirs:
            continue
        equal = False
        try:
            d, max_ulps = locate(
                topic, raw.step, theirs, mine, names, tolerance, joint_names=joint_names
            )
        except MalformedMessage as exc:
            where = paths[exc.side] if paths else path
            raise LogError(
                f"{where}: damaged log: step {raw.step}: the {topic} message {exc}"
            ) from None
        if max_ulps is not None:
            report.max_ulps_seen = (
                max_ulps if report.max_ulps_seen is None else max(report.max_ulps_seen, max_ulps)
            )
        if d is not None:
            found.append(d)
    report.add(found)
    if not equal and not found:
        report.within_tolerance_steps += 1
    return equal, bool(found)


class StepEncoder:
    """A replayed step's ``/bodies``, ``/contacts`` and ``/stats`` payloads, the bytes the
    recorder writes for it.

    On little-endian machines one compiled call encodes the step into a reused buffer (the
    writer processes' `recorder.frames.pack_into`, tested byte for byte against the
    reference encoders; about 20 us on the 500-body pile against 70 us for `encode_bodies`,
    `encode_contacts` and `compute_stats`); elsewhere, and for a record holding a NaN or an
    infinity (which the compiled path refuses), the reference encoders. For a log of format 1
    (``contacts_format="1"``) ``/contacts`` is encoded as that format wrote it
    (`recorder.mcap_writer.encode_contacts_v1`).
    """

    def __init__(self, model, gravity: tuple[float, float], contacts_format: str = "2") -> None:
        from recorder.pack import model_bundle

        self.model = model
        self.gravity = tuple(float(g) for g in gravity)
        self._masses = model_bundle(model)  # (mass, inertia, concrete) for the /stats sums
        self._compiled = sys.byteorder == "little"
        self._buf = np.zeros(0, dtype=np.uint8)
        self._v1 = contacts_format == "1"

    def encode(self, record: StepRecord) -> dict[str, bytes]:
        out = self._encode(record)
        if self._v1:
            out["/contacts"] = encode_contacts_v1(record)
        if record.joints is not None:
            out["/joints"] = encode_joints(record.step, record.time, record.joints)
        return out

    def _encode(self, record: StepRecord) -> dict[str, bytes]:
        from recorder.frames import Frame, frame_size, pack_into

        if self._compiled:
            size = frame_size(record)
            if self._buf.size < size:
                self._buf = np.zeros(max(size, 2 * self._buf.size), dtype=np.uint8)
            if pack_into(self._buf, 0, record, self._masses, self.gravity):
                frame = Frame(self._buf[:size])
                stats = {**frame.stats, "state_hash": frame.state_hash()}
                # bytes, not views of the buffer: the next step overwrites it, and
                # memoryview == bytes compares item by item (30x slower)
                return {
                    "/bodies": bytes(frame.bodies),
                    "/contacts": bytes(frame.contacts),
                    "/stats": encode_stats(record.step, record.time, stats),
                }
        return {
            "/bodies": encode_bodies(record),
            "/contacts": encode_contacts(record),
            "/stats": encode_stats(
                record.step, record.time, compute_stats(self.model, self.gravity, record)
            ),
        }


def _resume(sim, replayed: ReplayedSteps, logged: StepRecord) -> str | None:
    """Go on from a logged state; why the engine refuses it (`isaac.engine.guards`: a value
    that is not finite, ...) instead of raising, or None once it has taken it."""
    try:
        sim.resume(logged)
    except StateError as exc:
        return str(exc)
    replayed.restart(logged.exists)
    return None


def _went_on(sim, replayed: ReplayedSteps, logged: StepRecord, report: Report) -> bool:
    """Restart from the logged state after a difference at its step; True (lost) when the
    engine refuses that state, which is then reported at its step as the replay's error."""
    why = _resume(sim, replayed, logged)
    if why is None:
        return False
    detail = f"the replay cannot go on from the logged state: {why}"
    report.add([Divergence(logged.step, "simulation", "error", detail=detail)])
    return True


def replay_log(
    path: str,
    *,
    from_step: int | None = None,
    to_step: int | None = None,
    tolerance: float | None = None,
    all_steps: bool = False,
    max_reported: int = DEFAULT_MAX_REPORTED,
    on_step: Callable[[int], None] | None = None,
    partial: bool = False,
) -> Report:
    """Re-simulate the log at ``path`` from its embedded scene and compare every step.

    from_step: start from the state logged at this step (default: the scene's step 0).
    to_step: last step to compare (default: the log's last complete step).
    tolerance: None for bit-for-bit; else values count as equal when
        ``|logged - replayed| <= tolerance * (1 + |logged|)`` (integers and counts stay exact).
    all_steps: go on after a divergence (from the logged state) and list every differing step,
        at most ``max_reported`` of them. on_step: called with each step index (progress).
    partial: accept a damaged or never-closed log checked up to its last complete step before
        the damage (verdict ``partial``, exit status 0); without it such a log is ``damaged``
        or ``incomplete`` (exit status 1), never ``identical``.
    Raises LogError / SceneError for a file that is not a readable ISAAC log or whose scene is
    invalid, whose messages are malformed, or that holds no step to compare (exit status 2); a
    divergence or damage found while comparing is reported, not raised.
    """
    from isaac.engine.simulation import Simulation  # loads the compiled kernels

    check_tolerance(tolerance)
    if from_step is not None and from_step < 0:
        raise LogError(f"--from-step must be >= 0, got {from_step}")
    if to_step is not None and from_step is not None and to_step < from_step:
        raise LogError(f"--to-step {to_step} is before --from-step {from_step}")
    log = RawLog(path)
    # before anything is simulated or compiled: a log of another physics version never matches
    physics = physics_note(
        log.metadata, {"physics_version": str(PHYSICS_VERSION)}, what="in this engine"
    )
    if physics and tolerance is None:
        raise PhysicsVersionDiffers(
            f"{path}: not replayed: {physics}; results differ on purpose, so a bit-for-bit "
            f"replay cannot match (--tolerance X compares within X * (1 + |value|))"
        )
    scene, notes = load_embedded_scene(log)
    if physics:
        notes.insert(0, f"{physics}; compared within --tolerance {tolerance:g}")
    sim = Simulation(scene)
    model = sim.model
    names = list(model.names)
    gravity = tuple(float(g) for g in scene.world.gravity)
    encoder = StepEncoder(model, gravity, log.format_version)
    joint_rows = joint_table_rows(scene.joints)
    joint_names = [j.name for j in scene.joints]
    report = Report(mode="replay", logs=[str(path)], tolerance=tolerance, max_reported=max_reported)
    report.notes.extend(notes)
    here = build_metadata(scene, "", len(names))
    note = versions_note(log.metadata, here, suggest=tolerance is None, physics=False)
    if note:
        report.notes.append(note)

    # the replayed steps, a batch per compiled call, packed as the recorder packs them
    replayed = ReplayedSteps(
        sim, encoder, joint_rows, batched=log.format_version == FORMAT_VERSION, stop=to_step
    )
    started = time.perf_counter()
    timed_from: float | None = None
    timed_after = 0  # steps from this one on count towards the rate
    timed_steps = 0
    last_step: int | None = None
    go_on = all_steps or tolerance is not None
    lost = False  # the last logged state was refused: steps are skipped until one is taken
    # read ahead in a thread while the engine steps (replay.reader.Prefetch)
    steps = Prefetch(
        log.steps(start=from_step or 0, stop=to_step),
        group=READ_GROUP,
        weigh=_payload_bytes,
        budget=READ_GROUP_BYTES,
    )
    try:
        for raw in steps:
            last_step = raw.step
            if report.first_step is None and (from_step is not None or raw.step != 0):
                # a keyframe: start from the logged state (nothing to compare at this step)
                if from_step is not None and raw.step != from_step:
                    raise LogError(
                        f"{path}: step {from_step} is not in the log (the next "
                        f"complete step is {raw.step})"
                    )
                if from_step is None:
                    report.notes.append(
                        f"the log starts at step {raw.step}: replayed from its state"
                    )
                why = _resume(sim, replayed, _logged_record(raw, path, len(names)))
                if why is not None:
                    raise LogError(
                        f"{path}: the log's step {raw.step} cannot be replayed from: {why}"
                    )
                report.first_step = raw.step + 1
                continue
            if lost:
                # determinism: a state the engine refused is never stepped; the next logged
                # state the engine takes is a new start, compared from the step after it
                lost = _resume(sim, replayed, _logged_record(raw, path, len(names))) is not None
                continue
            if report.first_step is None:
                report.first_step = raw.step
            if replayed.next > raw.step:
                raise LogError(f"{path}: step {raw.step} is out of order")
            try:
                while replayed.next < raw.step:
                    replayed.payloads(replayed.next)
                ours = replayed.payloads(raw.step)
            except SimulationError as exc:
                report.steps_compared += 1
                report.add(
                    [
                        Divergence(
                            raw.step, "simulation", "error", detail=f"the replay stopped: {exc}"
                        )
                    ]
                )
                if not go_on:
                    report.stopped_early = True
                    break
                lost = _went_on(sim, replayed, _logged_record(raw, path, len(names)), report)
                continue
            if timed_from is None and replayed.batches:
                # the first batch also loads the kernels: the rate is measured after it
                timed_from = time.perf_counter()
                timed_after = replayed.next_batch
            elif timed_from is not None and raw.step >= timed_after:
                timed_steps += 1
            report.steps_compared += 1
            equal, beyond = _compare_step(
                raw, ours, names, tolerance, report, path=path, joint_names=joint_names
            )
            if on_step is not None:
                on_step(raw.step)
            if equal:
                continue
            if beyond and not go_on:
                report.stopped_early = True
                break
            # restart from the logged state so the next step is checked on its own
            lost = _went_on(sim, replayed, _logged_record(raw, path, len(names)), report)
    finally:
        steps.close()
    finished = time.perf_counter()
    report.elapsed_s = finished - started
    if timed_from is not None and timed_steps > 0 and finished > timed_from:
        report.steps_per_s = timed_steps / (finished - timed_from)
    elif report.elapsed_s > 0:
        report.steps_per_s = report.steps_compared / report.elapsed_s
    if report.first_step is not None and report.steps_compared:
        report.last_step = last_step
    elif report.first_step is not None:
        report.first_step = None
    if not report.stopped_early:
        _completeness(log, report, to_step=to_step, partial=partial)
        if (
            to_step is not None
            and last_step is not None
            and last_step < to_step
            and report.complete
        ):
            report.notes.append(f"the log ends at step {last_step}, before --to-step {to_step}")
    if report.steps_compared == 0 and not report.diverged:
        raise LogError(f"{path}: {_nothing_compared(log, from_step, last_step)}")
    return report


def _payload_bytes(raw: RawStep) -> int:
    return sum(len(p) for p in raw.messages.values())


def _nothing_compared(log: RawLog, from_step: int | None, last_step: int | None) -> str:
    """Why a replay or diff compared no step (a zero-step comparison is never identical)."""
    damage = f" (the log is damaged: {log.damage})" if log.damage else ""
    if from_step is not None and last_step is None:
        return f"step {from_step} is not in the log{damage}"
    if last_step is not None:
        return f"nothing to compare after step {last_step}, the last complete step{damage}"
    if log.damage is not None:
        return f"damaged log, no complete step: {log.damage}"
    return "the log holds no complete step (nothing to compare)"


# ---------------------------------------------------------------------------------------------
# diff


def same_bodies(scene_a: Scene, scene_b: Scene) -> bool:
    """Whether two scenes have the same bodies by name and shape (in order): one scene, perhaps
    under other settings."""
    return [(b.name, b.vertices) for b in scene_a.bodies] == [
        (b.name, b.vertices) for b in scene_b.bodies
    ]


MAX_LISTED_SETTINGS = 8


def settings_differ(scene_a: Scene, scene_b: Scene) -> list[str]:
    """``"key A, B"`` for each world setting and each body field (material, starting state)
    that differs between two scenes with the same bodies; at most MAX_LISTED_SETTINGS, then a
    count of the rest."""
    out = []
    for f in fields(scene_a.world):
        va, vb = getattr(scene_a.world, f.name), getattr(scene_b.world, f.name)
        if va != vb:
            out.append(f"{f.name} {va!r}, {vb!r}")
    if same_bodies(scene_a, scene_b):
        for a, b in zip(scene_a.bodies, scene_b.bodies):
            for f in fields(a):
                va, vb = getattr(a, f.name), getattr(b, f.name)
                if va != vb:
                    out.append(f"{a.name}.{f.name} {va!r}, {vb!r}")
    if len(out) > MAX_LISTED_SETTINGS:
        out = out[:MAX_LISTED_SETTINGS] + [f"and {len(out) - MAX_LISTED_SETTINGS} more"]
    return out


def _pairs(a: Iterator[RawStep], b: Iterator[RawStep]):
    """Merge two step streams by step index: (step, raw_a or None, raw_b or None)."""
    sa, sb = next(a, None), next(b, None)
    while sa is not None or sb is not None:
        if sb is None or (sa is not None and sa.step < sb.step):
            yield sa.step, sa, None
            sa = next(a, None)
        elif sa is None or sb.step < sa.step:
            yield sb.step, None, sb
            sb = next(b, None)
        else:
            yield sa.step, sa, sb
            sa, sb = next(a, None), next(b, None)


def diff_logs(
    path_a: str,
    path_b: str,
    *,
    from_step: int | None = None,
    to_step: int | None = None,
    tolerance: float | None = None,
    all_steps: bool = False,
    max_reported: int = DEFAULT_MAX_REPORTED,
    partial: bool = False,
    force: bool = False,
) -> Report:
    """Compare two logs of the same scene step by step, channel by channel, like `replay_log`.

    Logs of different scenes (other body names or shapes) are a LogError unless `force`; logs of
    one scene under other settings (world settings, or a body's material or starting state) are
    compared, and the report lists what differs (`Report.settings_differ`).

    In the report, "logged" is log A and "replayed" is log B. Steps present in one complete log
    only are a divergence. Both logs must be whole (every step they claim, intact) for the
    verdict ``identical``; when one is damaged or was never closed the comparison stops at its
    end and the verdict is ``damaged`` or ``incomplete`` (``partial`` with ``partial=True``).
    """
    check_tolerance(tolerance)
    log_a, log_b = RawLog(path_a), RawLog(path_b)
    scene_a, _ = load_embedded_scene(log_a)
    scene_b, _ = load_embedded_scene(log_b)
    names = [b.name for b in scene_a.bodies]
    report = Report(
        mode="diff", logs=[str(path_a), str(path_b)], tolerance=tolerance, max_reported=max_reported
    )
    if not same_bodies(scene_a, scene_b):
        if not force:
            raise LogError(
                f"{path_a} and {path_b} are logs of different scenes ({scene_a.name!r}, "
                f"{len(scene_a.bodies)} bodies; {scene_b.name!r}, {len(scene_b.bodies)} bodies): "
                f"pass --force to compare them anyway"
            )
        report.notes.append("the two logs embed different scenes")
    report.settings_differ = settings_differ(scene_a, scene_b)
    note = versions_note(log_a.metadata, log_b.metadata, what="in B", suggest=tolerance is None)
    if note:
        report.notes.append(note.replace("in the log", "in A"))
    started = time.perf_counter()
    go_on = all_steps or tolerance is not None
    steps_a = log_a.steps(start=from_step or 0, stop=to_step)
    steps_b = log_b.steps(start=from_step or 0, stop=to_step)
    last_step = None
    try:
        for step, ra, rb in _pairs(steps_a, steps_b):
            if ra is None or rb is None:
                # one log ends (or skips) here: read the other through to learn whether it
                # was cut or damaged, or really holds fewer steps
                for it in (steps_a, steps_b):
                    for _ in it:
                        pass
                short, other = (log_a, "A") if ra is None else (log_b, "B")
                if short.complete or (short.damage is None and not short.read_through):
                    report.add(
                        [
                            Divergence(
                                step,
                                "steps",
                                "missing",
                                detail=(
                                    f"step {step} is in {'B' if ra is None else 'A'} only "
                                    f"(log {other} ends at step {last_step})"
                                ),
                            )
                        ]
                    )
                break
            if report.first_step is None:
                report.first_step = step
            last_step = step
            report.steps_compared += 1
            _equal, beyond = _compare_step(
                ra,
                rb.messages,
                names,
                tolerance,
                report,
                path=path_a,
                paths=(path_a, path_b),
                sides=("in A", "in B"),
                joint_names=[j.name for j in scene_a.joints],
            )
            # payloads equal in both logs were not decoded: check them once (two copies of a
            # damaged log are not identical logs)
            for topic, data in ra.messages.items():
                if rb.messages.get(topic) == data:
                    try:
                        check_payload(topic, data, len(names))
                    except MalformedMessage as exc:
                        raise LogError(
                            f"{path_a}: damaged log: step {step}: the {topic} message {exc}"
                        ) from None
            if beyond and not go_on:
                report.stopped_early = True
                break
    finally:
        steps_a.close()
        steps_b.close()
    report.elapsed_s = time.perf_counter() - started
    report.last_step = last_step
    if report.elapsed_s > 0:
        report.steps_per_s = report.steps_compared / report.elapsed_s
    if not report.stopped_early:
        for label, log in (("A", log_a), ("B", log_b)):
            _completeness(log, report, to_step=to_step, label=label, partial=partial)
    if report.steps_compared == 0 and not report.diverged:
        short = log_a if log_a.damage is not None or log_b.damage is None else log_b
        raise LogError(f"{short.path}: {_nothing_compared(short, from_step, last_step)}")
    return report
