"""`isaac replay` / `isaac diff`: clean logs replay identically, a 1-ULP change is found exactly,
bad files give one line and exit status 2, truncated logs replay up to their last step."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from isaac.app.cli import main
from isaac.engine.diagnostics import state_hash
from isaac.engine.simulation import Simulation
from isaac.errors import LogError, SceneError
from recorder import Recorder
from replay.compare import diff_logs, replay_log
from replay.divergence import ulp_distance, ulp_distances
from replay.reader import RawLog

sys.path.insert(0, str(Path(__file__).parent))
from logtools import (
    COMINGS_AND_GOINGS,
    SMALL_PILE,
    STACK,
    bodies_changed,
    bodies_with,  # noqa: E402
    contacts_with,
    record,
    rewrite,
    scene_from,
)


def isaac(capsys, *argv) -> tuple[int, str, str]:
    status = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return status, out, err


@pytest.fixture(scope="module")
def stack_log(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("stack") / "stack.mcap"
    record(path, STACK)
    return path


# --- ULP distance ----------------------------------------------------------------------------


def test_ulp_distance_counts_representable_doubles_between_two_values():
    x = 1.2345
    assert ulp_distance(x, x) == 0
    assert ulp_distance(x, float(np.nextafter(x, np.inf))) == 1
    assert ulp_distance(x, float(np.nextafter(np.nextafter(x, -np.inf), -np.inf))) == 2
    # across zero: the smallest subnormals on either side are 2 apart; -0.0 and 0.0 are 0 apart
    tiny = 5e-324
    assert ulp_distance(-tiny, tiny) == 2
    assert ulp_distance(-0.0, 0.0) == 0
    assert ulp_distance(-1.0, 1.0) == 2 * ulp_distance(0.0, 1.0)
    assert ulp_distance(float("nan"), 1.0) is None


def test_vectorised_ulp_distances_agree_with_the_scalar_one():
    rng = np.random.default_rng(4)
    a = rng.normal(size=500) * 10.0 ** rng.integers(-300, 300, 500)
    b = np.where(rng.random(500) < 0.5, -a, np.nextafter(a, np.inf))
    b[:5] = a[:5]
    got = ulp_distances(a, b)
    assert [int(g) for g in got] == [ulp_distance(float(x), float(y)) for x, y in zip(a, b)]


# --- clean runs ------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "scene, steps",
    [
        (STACK, None),
        (COMINGS_AND_GOINGS, None),  # bodies enter and leave: /world is logged 3 more times
        (SMALL_PILE, None),
        ("pile", 40),  # the 500-body pile, first 40 steps
        ("spawn", 330),  # bodies enter at 0.5, 1.0, 1.5 s and one leaves at 2.5 s
        ("head_on", None),
    ],
)
def test_a_clean_log_replays_identically(tmp_path, capsys, scene, steps):
    path = tmp_path / "run.mcap"
    hashes = record(path, scene, steps=steps)
    status, out, err = isaac(capsys, "replay", path)
    assert status == 0, out + err
    assert out.startswith(f"identical: replayed {len(hashes)} steps (steps 0..{len(hashes) - 1})")
    assert "steps/s" in out and err == ""


def test_resuming_inside_the_replay_matches_a_fresh_simulation_from_the_same_record():
    scene, _ = scene_from(STACK)
    through = Simulation(scene)
    records = [through.step() for _ in range(50)]
    resumed = Simulation(scene)
    resumed.resume(records[19])
    fresh = Simulation(scene, start=records[19])
    for expected in records[20:]:
        a, b = resumed.step(), fresh.step()
        assert state_hash(a) == state_hash(b) == state_hash(expected)
        assert np.array_equal(a.contacts.impulse, expected.contacts.impulse)


def test_from_step_and_to_step_check_a_window_of_the_run(stack_log, capsys):
    status, out, _ = isaac(capsys, "replay", stack_log, "--from-step", 60, "--to-step", 90)
    assert status == 0
    assert out.startswith("identical: replayed 30 steps (steps 61..90)")
    report = replay_log(str(stack_log), from_step=119)
    assert report.identical and report.steps_compared == 1 and report.first_step == 120


def test_from_step_past_the_end_is_a_bad_request(stack_log, capsys):
    status, _, err = isaac(capsys, "replay", stack_log, "--from-step", 500)
    assert status == 2
    assert "step 500 is not in the log" in err and err.count("\n") == 1


# --- divergences -----------------------------------------------------------------------------


def test_one_ulp_in_one_body_at_step_k_is_reported_at_k_that_body_that_field(
    stack_log, tmp_path, capsys
):
    k, body = 37, 2  # "high"
    original = {}

    def bump(arrays):
        v = arrays["velocity"]
        original["value"] = float(v[2 * body + 1])
        v[2 * body + 1] = np.nextafter(v[2 * body + 1], np.inf)

    bad = tmp_path / "bad.mcap"
    rewrite(
        stack_log,
        bad,
        message=lambda topic, step, data: (
            bodies_with(data, bump) if topic == "/bodies" and step == k else data
        ),
    )
    out_json = tmp_path / "report.json"
    status, out, err = isaac(capsys, "replay", bad, "--json", out_json)
    assert status == 1, out + err
    assert out.startswith(f"DIVERGED at step {k}:")
    assert f"step {k}, /bodies, body 'high' (index {body}), velocity.y" in out
    assert "1 ULP" in out
    report = json.loads(out_json.read_text())
    first = report["divergences"][0]
    assert (first["step"], first["channel"], first["body"], first["body_name"], first["field"]) == (
        k,
        "/bodies",
        body,
        "high",
        "velocity.y",
    )
    assert first["ulps"] == 1 and first["differing_values"] == 1
    assert first["replayed"] == original["value"]
    assert first["logged"] == float(np.nextafter(original["value"], np.inf))
    assert report["exit_status"] == 1 and report["stopped_early"] is True
    # steps before k are untouched: a window that ends before k is identical
    assert replay_log(str(bad), to_step=k - 1).identical
    # a keyframe after k starts from the logged (changed) state, so it is consistent again
    assert replay_log(str(bad), from_step=k + 1).identical


def test_all_lists_every_differing_step(stack_log, tmp_path, capsys):
    changed = {20, 80}

    def bump(arrays):
        arrays["angle"][1] = np.nextafter(arrays["angle"][1], -np.inf)

    bad = tmp_path / "bad.mcap"
    bodies_changed(stack_log, bad, changed, bump)
    report = replay_log(str(bad), all_steps=True)
    steps = report.divergent_steps()
    # each changed step differs; the step after it does not follow from the changed state
    assert {20, 80} <= set(steps) and steps[0] == 20
    assert all(s in changed or s - 1 in changed for s in steps)
    assert report.steps_compared == 121 and not report.stopped_early
    status, out, _ = isaac(capsys, "replay", bad, "--all")
    assert status == 1
    assert "step 20, /bodies, body 'low' (index 1), angle" in out
    assert "step 80, /bodies, body 'low' (index 1), angle" in out


def test_one_ulp_in_a_contact_impulse_names_the_contact_row(stack_log, tmp_path):
    k = 60
    bad = tmp_path / "bad.mcap"

    def bump(fields):
        fields["impulse"][1] = np.nextafter(fields["impulse"][1], np.inf)

    rewrite(
        stack_log,
        bad,
        message=lambda topic, step, data: (
            contacts_with(data, bump) if topic == "/contacts" and step == k else data
        ),
    )
    report = replay_log(str(bad))
    d = report.divergences[0]
    assert (d.step, d.channel, d.field, d.ulps) == (k, "/contacts", "impulse", 1)
    assert d.contact["row"] == 1 and d.contact["a"] < d.contact["b"]


def test_a_missing_contact_row_is_a_count_mismatch_not_a_crash(stack_log, tmp_path, capsys):
    k = 50
    bad = tmp_path / "bad.mcap"

    def drop_last(fields):
        m = fields["a"].size
        for name, arr in fields.items():
            fields[name] = arr[: (m - 1) * (arr.size // m)]

    rewrite(
        stack_log,
        bad,
        message=lambda topic, step, data: (
            contacts_with(data, drop_last) if topic == "/contacts" and step == k else data
        ),
    )
    status, out, _ = isaac(capsys, "replay", bad)
    assert status == 1
    assert f"step {k}, /contacts" in out and "contacts count differs" in out


def test_a_log_with_different_bodies_reports_a_count_mismatch(stack_log, tmp_path, capsys):
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    record(b, "head_on", steps=10)  # 2 bodies against the stack's 4
    status, _, err = isaac(capsys, "diff", stack_log, b)
    assert status == 2 and "are logs of different scenes" in err  # unless forced:
    status, out, _ = isaac(capsys, "diff", stack_log, b, "--force")
    assert status == 1
    assert "step 0, /world: bodies count differs: A 4, B 2" in out
    assert "step 0, /bodies: bodies count differs: A 4, B 2" in out

    def drop_last(arrays):
        for name in arrays:
            arrays[name] = arrays[name][: arrays[name].size * 3 // 4]

    rewrite(
        stack_log,
        a,
        message=lambda topic, step, data: (
            bodies_with(data, drop_last) if topic == "/bodies" and step == 5 else data
        ),
    )
    status, out, _ = isaac(capsys, "replay", a)
    assert status == 1
    assert "step 5, /bodies: bodies count differs: logged 3, replayed 4" in out


def test_a_dropped_world_message_is_reported_where_the_body_set_changes(tmp_path):
    log, bad = tmp_path / "run.mcap", tmp_path / "bad.mcap"
    record(log, COMINGS_AND_GOINGS)
    worlds = [raw.step for raw in RawLog(str(log)).steps() if "/world" in raw.messages]
    assert worlds == [0, 30, 60, 100]  # start; enters at 0.3 s and 0.6 s; leaves at 1.0 s
    rewrite(
        log,
        bad,
        message=lambda topic, step, data: None if topic == "/world" and step == 60 else data,
    )
    report = replay_log(str(bad))
    d = report.divergences[0]
    assert (d.step, d.channel, d.kind) == (60, "/world", "missing")
    assert "replayed only" in d.detail


# --- bad files -------------------------------------------------------------------------------


def test_an_empty_file_is_a_one_line_error(tmp_path, capsys):
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    status, out, err = isaac(capsys, "replay", empty)
    assert (status, out) == (2, "")
    assert err.strip().endswith("empty file") and err.count("\n") == 1


def test_random_bytes_are_not_an_isaac_log(tmp_path, capsys):
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(np.random.default_rng(1).bytes(5000))
    status, _, err = isaac(capsys, "replay", junk)
    assert status == 2 and "not an MCAP file" in err and err.count("\n") == 1
    # MCAP magic followed by garbage: no readable ISAAC header
    junk.write_bytes(b"\x89MCAP0\r\n" + np.random.default_rng(2).bytes(5000))
    status, _, err = isaac(capsys, "replay", junk)
    assert status == 2 and "not an ISAAC log" in err and err.count("\n") == 1


def test_a_missing_file_is_a_one_line_error(tmp_path, capsys):
    status, _, err = isaac(capsys, "replay", tmp_path / "nope.mcap")
    assert status == 2 and "No such file" in err and err.count("\n") == 1


@pytest.mark.parametrize("where", ["header", "metadata", "format_version"])
def test_a_corrupt_header_is_a_one_line_error(stack_log, tmp_path, capsys, where):
    bad = tmp_path / "bad.mcap"
    if where == "format_version":
        rewrite(stack_log, bad, metadata=lambda m: {**m, "format_version": "99"})
        expected = "log format version '99' is not supported"
    else:
        data = bytearray(stack_log.read_bytes())
        start = 9 if where == "header" else data.index(b"isaac-log")
        data[start : start + 12] = b"\xff" * 12
        bad.write_bytes(bytes(data))
        expected = "not an ISAAC log"
    status, out, err = isaac(capsys, "replay", bad)
    assert (status, out) == (2, "")
    assert expected in err and err.count("\n") == 1


def test_an_embedded_scene_that_fails_validation_exits_2(stack_log, tmp_path, capsys):
    bad = tmp_path / "bad.mcap"
    rewrite(stack_log, bad, scene=lambda text: text.replace("dt: 0.01", "dt: -0.01"))
    status, out, err = isaac(capsys, "replay", bad)
    assert status == 2 and out == ""
    assert "scene.yaml" in err and "dt" in err and err.count("\n") == 1
    with pytest.raises(SceneError):
        replay_log(str(bad))


def test_an_embedded_scene_altered_behind_its_hash_exits_2(stack_log, tmp_path, capsys):
    bad = tmp_path / "bad.mcap"
    rewrite(
        stack_log,
        bad,
        scene=lambda text: text.replace("restitution: 0.3", "restitution: 0.4"),
        fix_scene_hash=False,
    )
    status, _, err = isaac(capsys, "replay", bad)
    assert status == 2 and "does not match its recorded sha256" in err
    with pytest.raises(LogError):
        replay_log(str(bad))


def test_a_consistently_altered_scene_replays_differently(stack_log, tmp_path, capsys):
    # a valid scene with its hash updated: the physics differs, so the replay diverges
    bad = tmp_path / "bad.mcap"
    rewrite(stack_log, bad, scene=lambda text: text.replace("restitution: 0.3", "restitution: 0.4"))
    status, out, _ = isaac(capsys, "replay", bad)
    assert status == 1 and "DIVERGED at step" in out


def test_a_truncated_log_fails_unless_partial_is_asked_for(tmp_path, capsys):
    path = tmp_path / "long.mcap"
    record(path, STACK, steps=400)  # 4 chunks of 100 steps
    data = path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: int(len(data) * 0.6)])
    # the steps that were read are identical, but the log cannot prove the rest: a failure
    status, out, err = isaac(capsys, "replay", cut)
    assert status == 1, out + err
    report = replay_log(str(cut))
    assert not report.identical and report.verdict == "damaged"
    assert 0 < report.last_step < 400 and report.damage_step == report.last_step + 1
    assert out.startswith(f"DAMAGED at step {report.damage_step}: ")
    assert "damaged: " in out and "cut short" in out
    # asked for, the complete steps before the cut are checked, and the verdict says so
    status, out, err = isaac(capsys, "replay", cut, "--partial")
    assert status == 0, out + err
    n = report.last_step + 1
    assert out.startswith(f"partial: {n:,} of {n:,} steps checked, identical up to step {n - 1}")


def test_the_partial_log_of_an_abandoned_run_is_incomplete_unless_partial(tmp_path):
    scene, _ = scene_from(STACK)
    sim = Simulation(scene)
    path = tmp_path / "killed.mcap"
    rec = Recorder(sim, mcap_path=str(path), flush_every=50, compression="none")
    rec.write(sim.record())
    for r in sim.run(170):
        rec.write(r)
    # what a SIGKILL leaves: flushed chunks, no summary, no footer (and, unlike a killed
    # process, this one gets its CPUs back: later tests must not run pinned to one)
    rec._abandon()
    partial = Path(str(path) + ".partial")
    assert partial.exists() and not path.exists()
    # every chunk is intact, but without a summary the log cannot prove it is complete
    report = replay_log(str(partial))
    assert not report.identical and report.verdict == "incomplete" and report.exit_status == 1
    assert (report.first_step, report.last_step) == (0, 170)  # abandon() flushed the last chunk
    assert "was not closed" in report.truncated_detail
    report = replay_log(str(partial), partial=True)
    assert report.verdict == "partial" and report.exit_status == 0
    assert (report.steps_compared, report.claimed_steps) == (171, 171)


def test_a_corrupt_chunk_in_a_closed_log_is_reported_as_damage(tmp_path):
    path = tmp_path / "run.mcap"
    record(path, STACK, steps=400, compression="none")
    data = bytearray(path.read_bytes())
    # flip one byte inside a float of the third chunk (steps 200..299): its CRC no longer holds
    data[int(len(data) * 0.6)] ^= 0x01
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    report = replay_log(str(bad))
    assert not report.identical and report.verdict == "damaged" and report.exit_status == 1
    assert (report.last_step, report.damage_step) == (199, 200)
    assert "CRC" in report.damage and report.claimed_steps == 401


# --- tolerance and versions ------------------------------------------------------------------


def test_tolerance_accepts_small_differences_and_reports_large_ones(stack_log, tmp_path, capsys):
    small, large = tmp_path / "small.mcap", tmp_path / "large.mcap"

    def nudge(factor):
        def change(arrays):
            arrays["position"][3] *= factor  # body "low", y ~ 0.5 m

        return change

    for path, factor in ((small, 1 + 1e-13), (large, 1 + 1e-6)):
        rewrite(
            stack_log,
            path,
            message=lambda topic, step, data, f=factor: (
                bodies_with(data, nudge(f)) if topic == "/bodies" and step in (30, 31) else data
            ),
        )
    assert isaac(capsys, "replay", small)[0] == 1
    status, out, _ = isaac(capsys, "replay", small, "--tolerance", "1e-9")
    assert status == 0 and out.startswith("equal within tolerance 1e-09: replayed 121 steps")
    assert "not bit-identical" in out
    status, out, _ = isaac(capsys, "replay", large, "--tolerance", "1e-9")
    assert status == 1 and "DIVERGED at step 30" in out


def test_a_log_from_other_versions_says_so_and_suggests_tolerance(stack_log, tmp_path, capsys):
    other = tmp_path / "other.mcap"
    rewrite(
        stack_log,
        other,
        metadata=lambda m: {**m, "numpy_version": "1.24.0", "cpu": "Some Other CPU"},
    )
    status, out, _ = isaac(capsys, "replay", other)
    assert status == 0
    assert "numpy 1.24.0 in the log" in out and "--tolerance" in out


# --- diff ------------------------------------------------------------------------------------


def test_diff_of_two_runs_of_one_scene_is_identical(stack_log, tmp_path, capsys):
    again = tmp_path / "again.mcap"
    record(again, STACK)
    status, out, _ = isaac(capsys, "diff", stack_log, again)
    assert status == 0 and out.startswith("identical: compared 121 steps (steps 0..120)")


def test_diff_reports_the_first_step_where_two_logs_part(stack_log, tmp_path, capsys):
    other = tmp_path / "other.mcap"
    record(other, STACK.replace("restitution: 0.3", "restitution: 0.35"))
    status, out, _ = isaac(capsys, "diff", stack_log, other, "--json", "-")
    assert status == 1
    report = json.loads(out)
    assert report["mode"] == "diff" and report["divergences"]
    # one scene under another material: compared, and what differs is listed
    assert any(s.endswith("restitution 0.3, 0.35") for s in report["settings_differ"])
    # the scenes differ in one body's restitution: /world says so at step 0
    first = report["divergences"][0]
    assert (first["step"], first["channel"], first["body_name"], first["field"]) == (
        0,
        "/world",
        "falling",
        "restitution",
    )
    assert (first["logged"], first["replayed"]) == (0.3, 0.35)
    # and the motion parts later, when the falling body bounces
    later = diff_logs(str(stack_log), str(other), all_steps=True)
    assert any(d.channel == "/bodies" and d.step > 0 for d in later.divergences)


def test_diff_against_a_truncated_log_fails_unless_partial(tmp_path, capsys):
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    record(a, STACK, steps=300)
    data = a.read_bytes()
    b.write_bytes(data[: len(data) // 2])
    status, out, _ = isaac(capsys, "diff", a, b)
    assert status == 1, out
    assert out.startswith("DAMAGED at step ") and "log B: " in out
    status, out, _ = isaac(capsys, "diff", a, b, "--partial")
    assert status == 0, out
    assert out.startswith("partial: ") and "steps compared, identical up to step" in out


# groups of 1, of 7 (the end falls inside a group), and groups cut short by their weight
GROUPINGS = [{}, {"group": 7}, {"group": 64, "weigh": lambda k: k, "budget": 40}]


@pytest.mark.parametrize("grouping", GROUPINGS)
def test_reading_ahead_keeps_the_order_and_raises_where_the_source_raised(grouping):
    from replay.reader import Prefetch

    assert list(Prefetch(iter(range(100)), depth=3, **grouping)) == list(range(100))

    def failing():
        yield from range(12)
        raise LogError("step 12 is out of order")

    got = []
    ahead = Prefetch(failing(), depth=2, **grouping)
    with pytest.raises(LogError, match="step 12 is out of order"):
        for item in ahead:
            got.append(item)
    assert got == list(range(12))
    with pytest.raises(StopIteration):  # raised once, then the end
        next(ahead)


def test_weighed_groups_are_handed_over_once_they_reach_their_budget():
    import threading

    from replay.reader import Prefetch

    read = []
    go_on = threading.Event()

    def items():
        for k in range(10):
            read.append(k)
            if k == 5:
                go_on.wait(10)
            yield k

    ahead = Prefetch(items(), group=64, weigh=lambda k: 10, budget=30)
    # the first group (0, 1, 2: 30 bytes) is there while the reader waits inside item 5
    assert [next(ahead) for _ in range(3)] == [0, 1, 2]
    go_on.set()
    assert list(ahead) == list(range(3, 10))


def test_closing_a_read_ahead_stops_its_thread_and_closes_the_source():
    from replay.reader import Prefetch

    closed = []

    def endless():
        try:
            k = 0
            while True:
                yield k
                k += 1
        finally:
            closed.append(True)

    ahead = Prefetch(endless(), depth=4)
    assert [next(ahead) for _ in range(10)] == list(range(10))
    ahead.close()
    assert not ahead._thread.is_alive() and closed == [True]
    with pytest.raises(StopIteration):
        next(ahead)


@pytest.mark.parametrize("scene", [COMINGS_AND_GOINGS, "pile"])
def test_the_replay_encoder_writes_the_reference_encoders_bytes(scene):
    import dataclasses

    from recorder.mcap_writer import encode_bodies, encode_contacts, encode_stats
    from recorder.stats import compute_stats
    from replay.compare import StepEncoder

    scene, _ = scene_from(scene, steps=None)
    sim = Simulation(scene)
    gravity = tuple(float(g) for g in scene.world.gravity)
    encoder = StepEncoder(sim.model, gravity)

    def reference(r):
        return {
            "/bodies": encode_bodies(r),
            "/contacts": encode_contacts(r),
            "/stats": encode_stats(r.step, r.time, compute_stats(sim.model, gravity, r)),
        }

    records = [sim.record()] + [sim.step() for _ in range(40)]
    assert any(len(r.contacts) for r in records) and not len(records[0].contacts)
    for r in records:
        assert encoder.encode(r) == reference(r)
    # a record the compiled path refuses (NaN) is still encoded, by the reference encoders
    bad = records[-1].velocity.copy()
    bad[0, 0] = np.nan
    r = dataclasses.replace(records[-1], velocity=bad)
    assert encoder.encode(r) == reference(r)
