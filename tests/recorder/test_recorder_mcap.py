"""The MCAP log: read back with generic readers, deterministic, crash-safe, NaN-safe.

These tests use synthetic step records (tests/recorder/recorder_synth.py) so they check the log
format itself; tests/recorder/test_recorder_physics.py checks logs of real runs.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.reader import make_reader

from isaac.engine.records import StepRecord
from isaac.errors import LogError, SimulationError
from recorder import Recorder
from recorder.reader import LogReader

sys.path.insert(0, str(Path(__file__).parent))
from recorder_synth import SCENE_TEXT, SynthSim  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
PYTHON = sys.executable


def record_run(path, *, n=20, contacts=8, steps=250, rrd=None, leave_at=None, **kwargs):
    sim = SynthSim(n, contacts, leave_at=leave_at)
    records = [sim.record()] + [sim.step() for _ in range(steps)]
    with Recorder(
        sim,
        mcap_path=str(path),
        rrd_path=None if rrd is None else str(rrd),
        scene_text=SCENE_TEXT,
        **kwargs,
    ) as rec:
        for r in records:
            rec.write(r)
    return sim, records


def generic_messages(path):
    """Decode every message with google.protobuf from the FileDescriptorSet stored in the file."""
    out = []
    classes = {}
    with open(path, "rb") as f:
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages():
            if schema.id not in classes:
                fds = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
                pool = descriptor_pool.DescriptorPool()
                for fd in fds.file:
                    pool.Add(fd)
                classes[schema.id] = message_factory.GetMessageClass(
                    pool.FindMessageTypeByName(schema.name)
                )
            assert schema.encoding == "protobuf" and channel.message_encoding == "protobuf"
            out.append((channel.topic, message, classes[schema.id].FromString(message.data)))
    return out


def test_generic_protobuf_reader_gets_every_float_bit_exact(tmp_path):
    path = tmp_path / "run.mcap"
    sim, records = record_run(path, leave_at=100)
    msgs = generic_messages(path)
    bodies = [m for t, _, m in msgs if t == "/bodies"]
    contacts = [m for t, _, m in msgs if t == "/contacts"]
    stats = [m for t, _, m in msgs if t == "/stats"]
    worlds = [(raw, m) for t, raw, m in msgs if t == "/world"]
    assert len(bodies) == len(contacts) == len(stats) == len(records)
    for r, b, c, s in zip(records, bodies, contacts, stats):
        assert b.step == c.step == s.step == r.step
        assert b.time == r.time
        np.testing.assert_array_equal(np.array(b.position).reshape(-1, 2), r.position)
        np.testing.assert_array_equal(np.array(b.angle), r.angle)
        np.testing.assert_array_equal(np.array(b.velocity).reshape(-1, 2), r.velocity)
        np.testing.assert_array_equal(np.array(b.angular_velocity), r.angular_velocity)
        np.testing.assert_array_equal(np.array(b.exists, dtype=bool), r.exists)
        rc = r.contacts
        # format 2: the pair fields once per manifold, the point fields per point; expanded
        # here with plain numpy, each row gets its manifold's values
        points = np.array(c.points, dtype=np.int64)
        assert points.sum() == len(rc) and (points >= 1).all()
        of_row = np.repeat(np.arange(points.size), points)
        first = np.cumsum(points) - points
        np.testing.assert_array_equal(np.arange(len(rc)) - first[of_row], rc.slot)
        for name in ("substep", "a", "b", "feature", "pair_depth"):
            np.testing.assert_array_equal(np.array(getattr(c, name))[of_row], getattr(rc, name))
        np.testing.assert_array_equal(np.array(c.normal).reshape(-1, 2)[of_row], rc.normal)
        for name in ("push_a", "push_b"):  # stored for the manifolds in `pushed` only
            per_row = np.zeros((len(rc), 2))
            per_row[first[np.array(c.pushed, dtype=np.int64)]] = np.array(getattr(c, name)).reshape(
                -1, 2
            )
            np.testing.assert_array_equal(per_row, getattr(rc, name))
        np.testing.assert_array_equal(np.array(c.point_depth), rc.depth)
        for name in ("impulse", "tangent_impulse", "restitution"):
            np.testing.assert_array_equal(np.array(getattr(c, name)), getattr(rc, name))
        np.testing.assert_array_equal(np.array(c.point).reshape(-1, 2), rc.point)
        assert s.contact_count == len(rc)
        assert len(s.state_hash) == 64
    # /world at step 0 and when the last body leaves at step 100, with everything per body
    assert [m.step for _, m in worlds] == [0, 100]
    first = worlds[0][1]
    model = sim.model
    assert [b.name for b in first.bodies] == model.names
    for k, b in enumerate(first.bodies):
        assert b.index == k
        c = int(model.vertex_count[k])
        np.testing.assert_array_equal(
            np.array(b.vertices_local).reshape(-1, 2), model.vertices_local[k, :c]
        )
        assert (b.mass, b.inertia, b.restitution) == (
            model.mass[k],
            model.inertia[k],
            model.restitution[k],
        )
        assert b.concrete == bool(model.concrete[k]) and b.exists
    assert not worlds[1][1].bodies[-1].exists


def test_log_time_is_step_times_dt_in_integer_nanoseconds(tmp_path):
    path = tmp_path / "run.mcap"
    record_run(path, steps=30)
    for _topic, raw, decoded in generic_messages(path):
        assert raw.sequence == decoded.step
        assert raw.log_time == raw.publish_time == round(decoded.step * (1 / 60) * 1e9)


def test_metadata_and_scene_attachment_come_before_any_chunk(tmp_path):
    path = tmp_path / "run.mcap"
    record_run(path, steps=5)
    with open(path, "rb") as f:
        reader = make_reader(f)
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
        attachments = {a.name: a for a in reader.iter_attachments()}
        summary = reader.get_summary()
    isaac = meta["isaac"]
    for key in (
        "engine_version",
        "python_version",
        "numpy_version",
        "numba_version",
        "platform",
        "cpu",
        "scene_sha256",
        "settings",
        "world.dt",
        "world.gravity",
        "world.fidelity",
        "world.solver",
    ):
        assert key in isaac, key
    import platform

    assert isaac["platform"] == platform.platform()  # the same name, without `uname -p`
    assert attachments["scene.yaml"].data.decode() == SCENE_TEXT
    import hashlib

    assert isaac["scene_sha256"] == hashlib.sha256(SCENE_TEXT.encode()).hexdigest()
    first_chunk = min(c.chunk_start_offset for c in summary.chunk_indexes)
    assert all(i.offset < first_chunk for i in summary.metadata_indexes if i.name == "isaac")
    assert all(i.offset < first_chunk for i in summary.attachment_indexes)
    assert meta["isaac.end"]["complete"] == "true"


def test_two_runs_give_byte_identical_files(tmp_path):
    record_run(tmp_path / "one.mcap", steps=120)
    record_run(tmp_path / "two.mcap", steps=120)
    assert (tmp_path / "one.mcap").read_bytes() == (tmp_path / "two.mcap").read_bytes()
    one = [raw.data for _, raw, _ in generic_messages(tmp_path / "one.mcap")]
    two = [raw.data for _, raw, _ in generic_messages(tmp_path / "two.mcap")]
    assert one == two


def test_reader_returns_the_records_that_were_written(tmp_path):
    path = tmp_path / "run.mcap"
    sim, records = record_run(path, leave_at=50)
    log = LogReader(str(path))
    assert log.closed_cleanly and log.complete
    assert log.scene_text == SCENE_TEXT
    assert log.world.names == sim.model.names
    got = list(log.steps())
    assert [s.step for s in got] == [r.step for r in records]
    for s, r in zip(got, records):
        for name in ("position", "angle", "velocity", "angular_velocity", "exists"):
            np.testing.assert_array_equal(getattr(s.record, name), getattr(r, name))
        np.testing.assert_array_equal(s.record.contacts.feature, r.contacts.feature)
        np.testing.assert_array_equal(s.record.contacts.push_b, r.contacts.push_b)
        assert s.world.exists[-1] == (r.step < 50)
    assert log.step(7).record.step == 7
    with pytest.raises(LogError):
        log.step(10_000)


def test_no_file_without_partial_suffix_until_closed(tmp_path):
    sim = SynthSim(5, 2)
    rec = Recorder(sim, mcap_path=str(tmp_path / "r.mcap"), scene_text=SCENE_TEXT)
    rec.write(sim.record())
    assert (tmp_path / "r.mcap.partial").exists() and not (tmp_path / "r.mcap").exists()
    rec.close(complete=False, stopped_at=1, reason="interrupted")
    assert (tmp_path / "r.mcap").exists() and not (tmp_path / "r.mcap.partial").exists()
    log = LogReader(str(tmp_path / "r.mcap"))
    assert log.closed_cleanly and not log.complete
    assert log.end["stopped_at"] == "1" and log.end["reason"] == "interrupted"


def test_nan_stops_the_run_naming_step_and_body_and_keeps_earlier_steps(tmp_path):
    sim = SynthSim(6, 3)
    path = tmp_path / "nan.mcap"
    written = []
    with pytest.raises(SimulationError) as info:
        with Recorder(sim, mcap_path=str(path), scene_text=SCENE_TEXT) as rec:
            rec.write(sim.record())
            for _ in range(10):
                r = sim.step()
                if r.step == 6:
                    pos = r.position.copy()
                    pos[3, 1] = np.nan
                    r = StepRecord(
                        r.step,
                        r.time,
                        pos,
                        r.angle,
                        r.velocity,
                        r.angular_velocity,
                        r.exists,
                        r.contacts,
                    )
                rec.write(r)
                written.append(r.step)
    assert info.value.step == 6 and info.value.body == "body3"
    assert "step 6" in str(info.value) and "body3" in str(info.value)
    log = LogReader(str(path))
    assert [s.step for s in log.steps()] == [0, 1, 2, 3, 4, 5]
    # stopped at the last step in the log (the failing step 6 is in the reason)
    assert log.end["complete"] == "false" and log.end["stopped_at"] == "5"
    for s in log.steps():
        assert np.isfinite(s.record.position).all()


def _flushed_steps(clean_path, cut):
    """Steps whose chunks lie wholly before byte ``cut`` (what must survive a cut there)."""
    with open(clean_path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        steps = set()
        for ci in summary.chunk_indexes:
            if ci.chunk_start_offset + ci.chunk_length <= cut:
                for _, _, m in reader.iter_messages(
                    starting_at=ci.message_start_time, ending_at=ci.message_end_time
                ):
                    steps.add(m.sequence)
    return steps


def test_file_cut_at_60_percent_is_inspected_and_recovered_without_losing_flushed_steps(tmp_path):
    clean = tmp_path / "clean.mcap"
    _, records = record_run(clean, n=30, contacts=12, steps=450)
    data = clean.read_bytes()
    cut = int(len(data) * 0.6)
    partial = tmp_path / "cut.mcap.partial"
    partial.write_bytes(data[:cut])
    expected = sorted(_flushed_steps(clean, cut))
    assert len(expected) >= 100  # at least one full flush interval lies before the cut
    log = LogReader(str(partial))
    assert not log.closed_cleanly and log.end is None
    got = [s.step for s in log.steps()]
    assert got[: len(expected)] == expected
    assert got == list(range(len(got)))

    out = run_cli("inspect", str(partial))
    assert out.returncode == 0, out.stderr
    assert "NOT closed" in out.stdout

    fixed = tmp_path / "fixed.mcap"
    out = run_cli("recover", str(partial), str(fixed))
    assert out.returncode == 0, out.stderr
    with open(fixed, "rb") as f:
        summary = make_reader(f).get_summary()  # indexed, readable by the seeking reader
    assert summary is not None and summary.chunk_indexes
    rlog = LogReader(str(fixed))
    assert rlog.closed_cleanly and not rlog.complete
    steps = list(rlog.steps())
    assert [s.step for s in steps] == got
    for s in steps:
        np.testing.assert_array_equal(s.record.position, records[s.step].position)


_KILLED_WRITER = r"""
import sys, time
sys.path.insert(0, {synth_dir!r})
from recorder_synth import SynthSim, SCENE_TEXT
from recorder import Recorder
sim = SynthSim(40, 10)
rec = Recorder(sim, mcap_path={path!r}, scene_text=SCENE_TEXT, offload="process")
rec.write(sim.record())
while True:
    r = sim.step()
    rec.write(r)
    print(r.step, flush=True)
    time.sleep(0.002)
"""


def test_sigkilled_writer_leaves_a_partial_file_with_every_flushed_step(tmp_path):
    path = tmp_path / "killed.mcap"
    script = _KILLED_WRITER.format(synth_dir=str(Path(__file__).parent), path=str(path))
    proc = subprocess.Popen([PYTHON, "-c", script], stdout=subprocess.PIPE, text=True, cwd=REPO)
    last = 0
    try:
        for line in proc.stdout:
            last = int(line)
            if last >= 350:
                break
        # the writer thread has flushed step 299 once the file holds the chunk; wait for it
        deadline = time.time() + 20
        partial = Path(str(path) + ".partial")
        while time.time() < deadline:
            try:
                if len([s for s in LogReader(str(partial)).steps()]) >= 300:
                    break
            except LogError:
                pass
            time.sleep(0.05)
    finally:
        writers = _children(proc.pid)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    # the writer process outlives the killed run: it writes out the steps it was handed and
    # exits (the command pipe ended); read the file once it is done
    deadline = time.time() + 30
    while any(Path(f"/proc/{c}").exists() for c in writers) and time.time() < deadline:
        time.sleep(0.05)
    partial = Path(str(path) + ".partial")
    log = LogReader(str(partial))
    assert not log.closed_cleanly
    steps = [s.step for s in log.steps()]
    # every step up to the last flush (flushes after steps 0, 99, 199, 299, ...), none missing
    assert steps == list(range(len(steps)))
    assert len(steps) >= 300
    assert run_cli("inspect", str(partial)).returncode == 0
    out = run_cli("recover", str(partial), str(path))
    assert out.returncode == 0, out.stderr
    assert [s.step for s in LogReader(str(path)).steps()] == steps


def _children(pid: int) -> list[int]:
    """Processes whose parent is `pid` (Linux /proc; empty elsewhere)."""
    out = []
    for entry in Path("/proc").glob("[0-9]*"):
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
            out.append(int(entry.name))
    return out


def run_cli(*args):
    return subprocess.run(
        [PYTHON, "-m", "isaac", *args], capture_output=True, text=True, cwd=REPO, timeout=300
    )


@pytest.mark.parametrize("content", [b"", os.urandom(4096), b"\x89MCAP0\r\n" + b"\0" * 100])
def test_inspect_rejects_bad_files_in_one_line(tmp_path, content):
    path = tmp_path / "bad.mcap"
    path.write_bytes(content)
    out = run_cli("inspect", str(path))
    assert out.returncode == 2
    assert out.stderr.count("\n") == 1 and "Traceback" not in out.stderr
    assert out.stderr.startswith("isaac inspect: error:")


def test_inspect_rejects_an_mcap_that_is_not_an_isaac_log(tmp_path):
    from mcap.writer import Writer

    path = tmp_path / "other.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        sid = w.register_schema("x", "jsonschema", b"{}")
        cid = w.register_channel("/x", "json", sid)
        w.add_message(cid, 0, b"{}", 0)
        w.finish()
    out = run_cli("inspect", str(path))
    assert out.returncode == 2 and "not an ISAAC log" in out.stderr
    assert out.stderr.count("\n") == 1
    out = run_cli("inspect", str(tmp_path / "missing.mcap"))
    assert out.returncode == 2 and out.stderr.count("\n") == 1


def test_inspect_prints_summary_and_step_table(tmp_path):
    path = tmp_path / "run.mcap"
    _, records = record_run(path, steps=40)
    out = run_cli("inspect", str(path))
    assert out.returncode == 0, out.stderr
    text = out.stdout
    assert "synthetic" in text and "numpy" in text and "closed cleanly" in text
    assert "steps    41" in text
    total = sum(len(r.contacts) for r in records)
    assert f"contacts {total} in all" in text
    out = run_cli("inspect", str(path), "--step", "3")
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert lines[0].startswith("step 3") and f"{len(records[3].contacts)} contact" in lines[0]
    header = [ln for ln in lines if ln.split() and ln.split()[0] == "row"]
    assert header and "impulse" in header[0]
    out = run_cli("inspect", str(path), "--step", "999")
    assert out.returncode == 2 and "step 999" in out.stderr


def test_foreground_and_background_writers_write_the_same_bytes(tmp_path):
    from recorder.mcap_writer import McapLogWriter
    from recorder.stats import compute_stats

    sim = SynthSim(10, 4)
    records = [sim.record()] + [sim.step() for _ in range(150)]
    for bg, name in ((False, "fg.mcap"), (True, "bg.mcap")):
        w = McapLogWriter(str(tmp_path / name), sim.model, sim.scene, SCENE_TEXT, background=bg)
        for r in records:
            w.write(r, compute_stats(sim.model, (0.0, -9.81), r))
        w.close()
    assert (tmp_path / "fg.mcap").read_bytes() == (tmp_path / "bg.mcap").read_bytes()


@pytest.mark.parametrize("compression", ["lz4", "zstd"])
def test_compressed_logs_read_back_and_recover(tmp_path, compression):
    path = tmp_path / "c.mcap"
    _, records = record_run(path, steps=230, compression=compression)
    assert [s.step for s in LogReader(str(path)).steps()] == [r.step for r in records]
    data = path.read_bytes()
    cut = tmp_path / "c.mcap.partial"
    cut.write_bytes(data[: int(len(data) * 0.6)])
    expected = sorted(_flushed_steps(path, int(len(data) * 0.6)))
    out = run_cli("recover", str(cut), str(tmp_path / "fixed.mcap"))
    assert out.returncode == 0, out.stderr
    got = [s.step for s in LogReader(str(tmp_path / "fixed.mcap")).steps()]
    assert got[: len(expected)] == expected and got == list(range(len(got)))


def test_an_empty_packed_scalar_is_a_wire_error_not_an_index_error():
    # a crafted message may give a scalar double field as an empty length-delimited value
    from recorder import schema as S

    for message, fields in S.MESSAGES.items():
        for _name, number, typ, repeated in fields:
            if typ == "double" and not repeated:
                with pytest.raises(S.WireError, match="empty value"):
                    S.decode(message, bytes([(number << 3) | 2, 0]))


@pytest.mark.parametrize("preset", ["balanced", "accurate"])  # accurate: 4 sub-steps a step
def test_per_manifold_contacts_round_trip_byte_for_byte(tmp_path, preset):
    """A real run's contact rows, written per manifold (format 2) by the writer process's
    batch encoder, read back as the very rows the engine made (every bit, slot and push
    included), and the rows read back encode to the logged bytes again."""
    from isaac.engine.records import CONTACT_FIELDS
    from isaac.engine.simulation import Simulation
    from isaac.scene import load_scene_text
    from recorder import schema as S
    from recorder.mcap_writer import encode_contacts
    from replay.reader import RawLog

    root = Path(__file__).resolve().parents[2]
    text = (root / "scenes" / "default.yaml").read_text().replace("balanced", preset, 1)
    sim = Simulation(load_scene_text(text, "<default>"))
    path = tmp_path / "default.mcap"
    made = [sim.record()]
    with Recorder(sim, mcap_path=str(path), offload="process") as rec:
        rec.write(made[0])
        for batch in sim.batches(150, size=50):
            rec.write_batch(batch)
            made += [batch.record(s) for s in range(batch.steps)]
    assert LogReader(str(path)).metadata["format_version"] == "2"
    raw = {s.step: s.messages["/contacts"] for s in RawLog(str(path)).steps()}
    two_point = substeps = 0
    for want, got in zip(made, LogReader(str(path)).steps()):
        c, d = want.contacts, got.record.contacts
        assert len(c) == len(d)
        for f in CONTACT_FIELDS:
            x, y = np.asarray(getattr(c, f)), getattr(d, f)
            assert np.ascontiguousarray(x).astype(y.dtype).tobytes() == y.tobytes(), f
        assert encode_contacts(got.record) == raw[want.step]
        two_point += int((c.slot == 1).sum())
        substeps = max(substeps, int(c.substep.max()) if len(c) else 0)
        m = S.decode("Contacts", raw[want.step])
        assert m["a"].size == int((c.slot == 0).sum())  # one entry per manifold
    assert two_point > 100
    assert substeps == (3 if preset == "accurate" else 0)
