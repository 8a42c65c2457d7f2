"""Writer processes (recorder.writer_process): same bytes as in-process writing, frames that
round-trip exactly, NaN refused before anything is sent, a dead or failing child reported in
one line."""

from __future__ import annotations

import dataclasses
import os
import signal
import sys
from pathlib import Path

import numpy as np
import pytest

from isaac.engine.records import Contacts, StepRecord, state_hash
from isaac.errors import LogError, SimulationError
from recorder import Recorder
from recorder import frames as F
from recorder import writer_process as W
from recorder.pack import model_bundle
from recorder.reader import LogReader
from recorder.stats import compute_stats

sys.path.insert(0, str(Path(__file__).parent))
from recorder_synth import SCENE_TEXT, SynthSim  # noqa: E402


def _records(n=12, contacts=6, steps=120, leave_at=None):
    sim = SynthSim(n, contacts, leave_at=leave_at)
    return sim, [sim.record()] + [sim.step() for _ in range(steps)]


def _assert_same_record(a: StepRecord, b: StepRecord):
    assert (a.step, a.time) == (b.step, b.time)
    for name in ("position", "angle", "velocity", "angular_velocity", "exists"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    for f in dataclasses.fields(Contacts):
        x, y = getattr(a.contacts, f.name), getattr(b.contacts, f.name)
        assert x.shape == y.shape and x.dtype.kind == y.dtype.kind
        np.testing.assert_array_equal(x, y)


def _with_value(r: StepRecord, field: str, value: float) -> StepRecord:
    """`r` with one value of `field` (a body field: its last; a contact field: its first)
    replaced by `value`."""
    if hasattr(r, field):
        arr = getattr(r, field).copy()
        arr.flat[arr.size - 1] = value
        return dataclasses.replace(r, **{field: arr})
    arr = getattr(r.contacts, field).copy()
    arr.flat[0] = value
    return dataclasses.replace(r, contacts=dataclasses.replace(r.contacts, **{field: arr}))


def _packer(ring, sim):
    """A WriterProcess's packing half, without a child."""
    proc = W.WriterProcess.__new__(W.WriterProcess)
    proc._view = memoryview(ring)
    proc._ring_u8 = ring
    proc._stats_model = W._Namespace(
        mass=np.asarray(sim.model.mass, dtype=float),
        inertia=np.asarray(sim.model.inertia, dtype=float),
        concrete=np.asarray(sim.model.concrete, dtype=bool),
    )
    proc._gravity = (0.0, -9.81)
    proc._masses = model_bundle(proc._stats_model)
    return proc


def test_the_compiled_frame_head_has_the_size_the_reader_expects():
    from recorder.pack import HEAD_BYTES

    assert F.FRAME_HEAD.size == HEAD_BYTES  # pack_frame writes the head that Frame unpacks


def test_the_compiled_encoder_writes_the_reference_encoders_bytes_and_stats():
    from recorder.mcap_writer import encode_bodies, encode_contacts
    from recorder.pack import HEAD_BYTES

    sim, records = _records(steps=30, leave_at=20)
    ring = np.zeros(1 << 20, dtype=np.uint8)
    proc = _packer(ring, sim)
    assert any(len(r.contacts) == 0 for r in records)  # step 0: empty fields left out
    for r in records:
        stats = compute_stats(sim.model, (0.0, -9.81), r, with_hash=False)
        size = F.frame_size(r)
        assert proc._compiled_pack(8, r, None)
        frame = bytes(ring[8 : 8 + size])
        assert F.FRAME_HEAD.size == HEAD_BYTES
        assert frame == F.pack(r, stats)  # compiled and reference encoding agree byte for byte
        got = F.Frame(frame)
        assert bytes(got.bodies) == encode_bodies(r)
        assert bytes(got.contacts) == encode_contacts(r)
        assert got.stats == stats  # the same kernel, the same sums
        assert got.state_hash() == state_hash(r)
        np.testing.assert_array_equal(got.exists(), r.exists)
        _assert_same_record(got.record(), r)


@pytest.mark.parametrize(
    "field", ["position", "angular_velocity", "normal", "pair_depth", "impulse", "restitution"]
)
@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_the_compiled_encoder_refuses_a_nan_or_infinity_in_any_float_field(field, bad):
    from recorder.pack import (
        BODY_FIELDS,
        CONTACT_FIELDS,
        manifold_counts,
        model_bundle,
        pack_layout,
        record_bundles,
    )

    sim, records = _records(steps=3)
    r = _with_value(records[-1], field, bad)
    ring = np.zeros(1 << 20, dtype=np.uint8)
    assert not _packer(ring, sim)._compiled_pack(0, r, None)
    c = r.contacts
    state, rows = record_bundles(r)
    bad_field = pack_layout(
        ring,
        64,
        3,
        0.05,
        len(r.angle),
        len(c),
        *manifold_counts(c.slot, c.push_a, c.push_b),
        4096,
        state,
        rows,
        model_bundle(sim.model),
        (0.0, -9.81),
    )[0]
    assert bad_field == (BODY_FIELDS + CONTACT_FIELDS).index(field)


def _rerun_packer(ring, sim):
    """A Rerun WriterProcess's packing half, without a child."""
    from recorder.pack import pack_rerun, record_bundles, rerun_offsets

    proc = _packer(ring, sim)
    proc.kind, proc.capacity, proc.head, proc.released = "rerun", ring.size, 0, 0
    proc._pending = bytearray()
    proc._pack_rerun, proc._rerun_offsets = pack_rerun, rerun_offsets
    proc._record_bundles = record_bundles
    return proc


_RERUN_FIELDS = ("position", "angle", "exists", "point", "normal", "impulse", "push_a", "push_b")


def test_the_rerun_frame_round_trips_every_field_bit_for_bit():
    from recorder.pack import model_bundle, pack_rerun, record_bundles

    sim, records = _records(n=13, steps=30, leave_at=20)  # 13: exists bytes end mid-word
    assert len(records[0].contacts) == 0  # step 0: no contact arrays
    r = records[7]
    position = r.position.copy()
    position[2] = (-0.0, 5e-324)  # the sign of zero and a subnormal survive
    records[7] = dataclasses.replace(r, position=position)
    ring = np.full(1 << 16, 0xAB, dtype=np.uint8)  # leftover bytes must not leak into values
    model = model_bundle(_packer(ring, sim)._stats_model)
    for r in records:
        c = r.contacts
        state, rows = record_bundles(r)
        assert pack_rerun(ring, 24, r.step, r.time, state, rows, model, (0.0, -9.81)) == -1
        frame = F.read_rerun_frame(ring, 24)
        assert (frame.step, frame.time) == (r.step, r.time)
        for name in _RERUN_FIELDS:
            want = getattr(r, name) if hasattr(r, name) else getattr(c, name)
            got = getattr(frame, name)
            assert got.shape == want.shape and got.dtype == want.dtype, name
            assert got.tobytes() == np.ascontiguousarray(want).tobytes(), name
        stats = compute_stats(sim.model, (0.0, -9.81), r, with_hash=False)
        assert dict(zip(F.STAT_KEYS, frame.stats.tolist())) == stats  # the same sums
        assert F.rerun_frame_size(r) % 8 == 0


_FLOAT_FIELDS = (
    "position",
    "angle",
    "velocity",
    "angular_velocity",
    "point",
    "normal",
    "depth",
    "pair_depth",
    "push_a",
    "push_b",
    "impulse",
    "tangent_impulse",
    "restitution",
)


@pytest.mark.parametrize("field", _FLOAT_FIELDS)
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_the_rerun_frame_refuses_a_nan_or_infinity_in_any_float_field(field, bad):
    from recorder.pack import BODY_FIELDS, CONTACT_FIELDS, record_bundles

    sim, records = _records(steps=3)
    r = _with_value(records[-1], field, bad)
    ring = np.zeros(1 << 16, dtype=np.uint8)
    proc = _rerun_packer(ring, sim)
    assert proc.write(records[1]) is True  # a good step is handed out ...
    head, pending = proc.head, bytes(proc._pending)
    assert proc.write(r) is False  # ... a bad one is not: nothing more announced
    assert (proc.head, bytes(proc._pending)) == (head, pending)
    state, rows = record_bundles(r)
    got = proc._pack_rerun(ring, 0, r.step, r.time, state, rows, proc._masses, (0.0, -9.81))
    assert got == (BODY_FIELDS + CONTACT_FIELDS).index(field)


def _rrd_content(path):
    """The rows of every entity, per set of columns, without row ids and wall-clock times
    (how Rerun's batcher cuts rows into chunks depends on timing)."""
    import pyarrow as pa
    from rerun.chunk import RrdReader

    out = {}
    for chunk in RrdReader(str(path)).stream():
        batch = chunk.to_record_batch()
        cols = {}
        for name in batch.schema.names:
            if "rowid" in name.lower().replace("_", "") or name in (
                "log_time",
                "RecordingInfo:start_time",
            ):
                continue
            col = batch.column(name)
            cols[name] = col.cast(pa.int64()) if pa.types.is_duration(col.type) else col
        out.setdefault((chunk.entity_path, tuple(sorted(cols))), []).append(cols)
    return {
        key: {name: pa.concat_arrays([c[name] for c in chunks]) for name in chunks[0]}
        for key, chunks in out.items()
    }


# 5,424-byte frames (40 bodies, 60 contact rows): 8 KiB holds one at a time (every step
# waits for the child and wraps), 4 KiB none (every step but step 0 goes inline)
@pytest.mark.parametrize("ring_bytes", [None, 8192, 4096])
def test_the_rerun_writer_process_writes_what_writing_in_process_does(tmp_path, ring_bytes):
    sim, records = _records(n=40, contacts=60, steps=150, leave_at=70)
    assert F.rerun_frame_size(records[5]) == 5424
    paths = {}
    for offload in ("none", "process"):
        path = tmp_path / f"{offload}.rrd"
        rec = Recorder(sim, rrd_path=str(path), scene_text=SCENE_TEXT, offload=offload)
        if offload == "process" and ring_bytes is not None:
            config = {
                "model": F.model_table(rec.model),
                "gravity": rec.gravity,
                "scene": {"name": str(rec.scene.name), "dt": float(rec.scene.world.dt)},
                "impulse_scale": None,
            }
            rec.rerun.close()
            rec.rerun = W.WriterProcess("rerun", str(path), config, ring_bytes=ring_bytes)
        for r in records:
            rec.write(r)
        rec.close()
        paths[offload] = path
    a, b = _rrd_content(paths["none"]), _rrd_content(paths["process"])
    assert sorted(a) == sorted(b)
    for key, columns in a.items():
        assert all(values.equals(b[key][name]) for name, values in columns.items()), key


@pytest.mark.parametrize("ring_bytes", [None, 64 * 1024])  # the second forces wraps and waits
def test_writer_processes_write_the_same_bytes_as_writing_in_process(tmp_path, ring_bytes):
    sim, records = _records(n=30, contacts=20, steps=160, leave_at=70)
    paths = {}
    for offload in ("none", "process"):
        path = tmp_path / f"{offload}.mcap"
        rec = Recorder(
            sim, mcap_path=str(path), scene_text=SCENE_TEXT, compression="none", offload=offload
        )  # uncompressed: `_mcap_config` says so for the writer it swaps in
        if offload == "process" and ring_bytes is not None:
            # a ring a few frames long: every wrap and every wait for the child is exercised
            rec.mcap.close()
            rec.mcap = W.WriterProcess("mcap", str(path), _mcap_config(rec), ring_bytes=ring_bytes)
        for r in records:
            rec.write(r)
        rec.close()
        paths[offload] = path
    assert paths["none"].read_bytes() == paths["process"].read_bytes()


def test_writer_processes_started_before_the_recorder_write_the_same_files(tmp_path):
    """`isaac run` starts the writer processes before it builds the simulation
    (recorder.spawn); the recorder then adopts them: the Rerun one here, the MCAP log by the
    thread `offload` names. Same MCAP bytes and Rerun content as writing in-process."""
    from recorder.spawn import start_writer_child

    sim, records = _records(n=30, contacts=20, steps=90, leave_at=40)
    out = {}
    for label in ("in-process", "started"):
        mcap, rrd = tmp_path / f"{label}.mcap", tmp_path / f"{label}.rrd"
        children = {"rrd": start_writer_child("rerun")} if label == "started" else {}
        rec = Recorder(
            sim,
            mcap_path=str(mcap),
            rrd_path=str(rrd),
            scene_text=SCENE_TEXT,
            compression="none",
            offload="thread" if children else "none",
            children=children,
        )
        assert rec.offload == ("rrd process, mcap thread" if children else "none")
        assert isinstance(rec.rerun, W.WriterProcess) == bool(children)
        for r in records:
            rec.write(r)
        rec.close()
        out[label] = (mcap.read_bytes(), _rrd_content(rrd))
    assert out["started"][0] == out["in-process"][0]
    a, b = out["in-process"][1], out["started"][1]
    assert sorted(a) == sorted(b)
    for key, columns in a.items():
        assert all(values.equals(b[key][name]) for name, values in columns.items()), key


def test_a_started_writer_process_the_recorder_cannot_use_exits_and_writes_nothing(tmp_path):
    """An error before the recorder takes its started processes (here: the two outputs are
    the same file) stops them: no process is left behind and no file is written."""
    from recorder.spawn import start_writer_child

    sim, _ = _records(n=4, contacts=2, steps=1)
    children = {"mcap": start_writer_child("mcap"), "rrd": start_writer_child("rerun")}
    procs = [c.proc for c in children.values()]
    same = str(tmp_path / "same")
    with pytest.raises(LogError):
        Recorder(sim, mcap_path=same, rrd_path=same, scene_text=SCENE_TEXT, children=children)
    assert [p.poll() for p in procs] == [0, 0]  # exited, cleanly
    assert list(tmp_path.iterdir()) == []


def _mcap_config(rec):
    from recorder.mcap_writer import build_metadata

    return {
        "model": F.model_table(rec.model),
        "gravity": rec.gravity,
        "scene": {"name": str(rec.scene.name), "dt": float(rec.scene.world.dt)},
        "scene_text": rec.scene_text,
        "metadata": build_metadata(rec.scene, rec.scene_text, len(rec.model.names)),
        "flush_every": 100,
        "compression": "none",
        "foxglove": None,
    }


def test_a_frame_larger_than_the_ring_goes_inline_and_arrives_whole(tmp_path):
    sim, records = _records(n=40, contacts=30, steps=20)
    rec = Recorder(
        sim, mcap_path=str(tmp_path / "a.mcap"), scene_text=SCENE_TEXT, offload="process"
    )
    rec.mcap.close()
    rec.mcap = W.WriterProcess("mcap", str(tmp_path / "a.mcap"), _mcap_config(rec), ring_bytes=4096)
    assert F.frame_size(records[5]) > 4096
    for r in records:
        rec.write(r)
    rec.close()
    got = list(LogReader(str(tmp_path / "a.mcap")).steps())
    assert [s.step for s in got] == [r.step for r in records]
    for s, r in zip(got, records):
        _assert_same_record(s.record, r)


def test_nan_through_a_writer_process_names_step_and_body_and_keeps_earlier_steps(tmp_path):
    sim, records = _records(steps=40)
    bad = records[30]
    pos = bad.position.copy()
    pos[3, 1] = np.nan
    records[30] = dataclasses.replace(bad, position=pos)
    path = tmp_path / "nan.mcap"
    rec = Recorder(sim, mcap_path=str(path), scene_text=SCENE_TEXT, offload="process")
    with pytest.raises(SimulationError, match=r"step 30: body 'body3'"):
        with rec:
            for r in records:
                rec.write(r)
    assert [s.step for s in LogReader(str(path)).steps()] == list(range(30))


def test_nan_through_the_rerun_writer_process_names_step_and_contact(tmp_path):
    sim, records = _records(steps=40)
    bad = records[25]
    depth = bad.contacts.depth.copy()  # a field the Rerun frame leaves out, checked all the same
    depth[2] = np.inf
    records[25] = dataclasses.replace(bad, contacts=dataclasses.replace(bad.contacts, depth=depth))
    rec = Recorder(
        sim, rrd_path=str(tmp_path / "nan.rrd"), scene_text=SCENE_TEXT, offload="process"
    )
    c = bad.contacts
    name_a, name_b = sim.model.names[c.a[2]], sim.model.names[c.b[2]]
    with pytest.raises(
        SimulationError,
        match=rf"step 25: contact between '{name_a}' and "
        rf"'{name_b}' has a non-finite depth",
    ):
        with rec:
            for r in records:
                rec.write(r)
    assert (tmp_path / "nan.rrd").exists()  # closed, with the steps before


def test_an_unwritable_output_fails_at_once_in_one_line(tmp_path):
    sim, _ = _records(steps=1)
    with pytest.raises(LogError, match="cannot write .*missing"):
        Recorder(
            sim,
            mcap_path=str(tmp_path / "missing" / "x.mcap"),
            scene_text=SCENE_TEXT,
            offload="process",
        )


def test_a_writer_process_that_dies_is_reported_with_the_file_name(tmp_path):
    sim, records = _records(steps=200)
    path = tmp_path / "dead.mcap"
    rec = Recorder(sim, mcap_path=str(path), scene_text=SCENE_TEXT, offload="process")
    rec.wait_ready()
    os.kill(rec.mcap.proc.pid, signal.SIGKILL)
    rec.mcap.proc.wait()
    with pytest.raises(
        LogError,
        match=r"writing .*dead\.mcap\.partial failed: the writer "
        r"process stopped \(exit code -9\)",
    ):
        for r in records:
            rec.write(r)
        rec.close()
    rec._abandon()


def test_a_failure_inside_the_writer_process_comes_back_as_its_message(tmp_path):
    sim, records = _records(steps=5)
    path = tmp_path / "bad.mcap"
    rec = Recorder(sim, mcap_path=str(path), scene_text=SCENE_TEXT, offload="none")
    config = _mcap_config(rec)
    rec.close()
    config["compression"] = "brotli"  # refused by the MCAP writer, in the child
    proc = W.WriterProcess("mcap", str(path), config)
    with pytest.raises(LogError, match="compression must be one of"):
        proc.wait_ready()
    proc.abandon()


def test_drain_returns_once_every_step_is_written(tmp_path):
    sim, records = _records(steps=50)
    path = tmp_path / "d.mcap"
    rec = Recorder(
        sim, mcap_path=str(path), scene_text=SCENE_TEXT, flush_every=10, offload="process"
    )
    for r in records[:41]:
        rec.write(r)
    rec.drain()  # no waiting after this: the flushed steps are in the file now
    steps = [s.step for s in LogReader(str(path) + ".partial").steps()]
    assert steps == list(range(40))  # chunks closed after steps 0, 9, ..., 39
    rec.close()


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="needs two CPUs")
def test_writer_processes_get_cpus_of_their_own_until_the_recorder_closes(tmp_path):
    sim, records = _records(steps=5)
    before = os.sched_getaffinity(0)
    rec = Recorder(
        sim,
        mcap_path=str(tmp_path / "a.mcap"),
        rrd_path=str(tmp_path / "a.rrd"),
        scene_text=SCENE_TEXT,
        offload="process",
    )
    mine = os.sched_getaffinity(0)
    theirs = [os.sched_getaffinity(w.proc.pid) for w in (rec.mcap, rec.rerun)]
    assert all(t and not (t & mine) for t in theirs)  # apart from the simulation's CPUs
    assert mine | set().union(*theirs) == before
    for r in records:
        rec.write(r)
    rec.close()
    assert os.sched_getaffinity(0) == before


def test_a_failure_in_the_rerun_sender_thread_is_raised_by_the_next_call(tmp_path):
    from recorder.rerun_writer import RerunLogWriter

    sim, records = _records(steps=30)
    w = RerunLogWriter(str(tmp_path / "t.rrd"), sim.model, sim.scene, batch=10, background=True)

    def fail(*args):
        raise RuntimeError("disk on fire")

    w._send_batch = fail
    for r in records[:10]:  # the first batch goes to the thread, which fails
        w.write(r, compute_stats(sim.model, (0.0, -9.81), r, with_hash=False))
    with pytest.raises(LogError, match="t.rrd.partial failed: disk on fire"):
        w.settle()
    with pytest.raises(LogError, match="disk on fire"):
        w.close()
    assert w._thread is None  # stopped, not left waiting


def test_rerun_batches_grow_for_bodies_entering_and_more_contact_rows(tmp_path):
    """A body entering mid-batch (more outline points than the batch was sized for) and 30
    contact rows per step on 5 bodies (the first buffers hold 2,000 rows): every step's
    outlines and contact points are still those of its record."""
    from rerun.chunk import RrdReader

    sim, records = _records(n=5, contacts=30, steps=120)  # 3,000 rows in the first batch
    for k in range(0, 25):  # body 3 enters at step 25
        exists = records[k].exists.copy()
        exists[3] = False
        records[k] = dataclasses.replace(records[k], exists=exists)
    path = tmp_path / "grow.rrd"
    rec = Recorder(sim, rrd_path=str(path), scene_text=SCENE_TEXT, offload="process")
    for r in records:
        rec.write(r)
    rec.close()
    strips, points = {}, {}
    for chunk in RrdReader(str(path)).stream():
        batch = chunk.to_record_batch()
        for out, entity, name in (
            (strips, "/world/bodies/moving", "LineStrips2D:strips"),
            (points, "/world/contacts", "Points2D:positions"),
        ):
            if chunk.entity_path == entity and name in batch.schema.names:
                out.update(zip(batch.column("step").to_pylist(), batch.column(name).to_pylist()))
    local, counts = sim.model.vertices_local, sim.model.vertex_count
    for r in records:
        moving = np.flatnonzero(r.exists & ~sim.model.concrete)
        assert len(strips[r.step]) == moving.size
        for body, strip in zip(moving, strips[r.step]):
            c, s = np.cos(r.angle[body]), np.sin(r.angle[body])
            v = local[body, : counts[body]]
            want = r.position[body] + np.stack(
                [v[:, 0] * c - v[:, 1] * s, v[:, 0] * s + v[:, 1] * c], axis=1
            )
            np.testing.assert_allclose(
                np.array(strip), np.vstack([want, want[:1]]), rtol=1e-6, atol=1e-5
            )
        np.testing.assert_array_equal(
            np.array(points[r.step], dtype=np.float32).reshape(-1, 2),
            r.contacts.point.astype(np.float32).reshape(-1, 2),
        )


@pytest.mark.parametrize("field", ["slot", "a", "normal", "pair_depth", "push_b"])
def test_rows_that_are_not_manifolds_are_refused_not_stored_with_a_loss(field):
    """Format 2 stores a manifold's fields once: rows whose second point disagrees with its
    first (or sits at a slot out of turn, or carries a push) would lose a bit, so both encoders
    refuse them, naming the row."""
    from recorder.mcap_writer import encode_contacts

    sim, records = _records(steps=20)
    r = next(r for r in records if (r.contacts.slot == 1).any())
    c = r.contacts
    row = int(np.flatnonzero(c.slot == 1)[0])
    arr = np.array(getattr(c, field))
    if field == "slot":
        arr[row] = 2
    elif field == "a":
        arr[row] = arr[row] - 1 if arr[row] > 0 else arr[row] + 1
    else:
        arr.reshape(len(c), -1)[row, 0] = np.nextafter(arr.reshape(len(c), -1)[row, 0], 1.0)
    bad = dataclasses.replace(r, contacts=dataclasses.replace(c, **{field: arr}))
    with pytest.raises(ValueError, match=f"row {row} "):
        encode_contacts(bad)
    ring = np.zeros(1 << 20, dtype=np.uint8)
    with pytest.raises(ValueError, match=f"row {row} "):
        _packer(ring, sim)._compiled_pack(0, bad, None)
    assert _packer(ring, sim)._compiled_pack(0, r, None)  # the rows as they were: packed
