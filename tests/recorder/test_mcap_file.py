"""`recorder.mcap_file.McapFile`, ISAAC's own MCAP writer: its files equal byte for byte those
of the mcap library's public `Writer` for the same calls, mcap's own reader (CRCs checked) and
`recorder.mcap_records` read them; and whole batches of steps packed as Message records by one
compiled call (`recorder.mcap_pack`) and entered a stretch at a time give the bytes of the
Python encoders entering one message at a time."""

from __future__ import annotations

import hashlib
import io

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.records import Attachment, Channel, DataEnd, Header, Message, Metadata, Schema
from mcap.stream_reader import CRCValidationError, StreamReader
from mcap.writer import CompressionType, Writer

import recorder.mcap_pack as MP
from isaac import Simulation, load_scene
from recorder.integrity import StepReader
from recorder.mcap_file import McapFile
from recorder.mcap_records import OP_CHUNK, OP_CHUNK_INDEX, OP_MESSAGE_INDEX, McapScan, open_log
from recorder.mcap_writer import McapLogWriter
from recorder.stats import compute_stats

CHUNK = 4096  # bytes: a chunk closes every few steps, inside batches of 7 and 64


def _writer(path, sim, compression, *, chunk_size=CHUNK, flush_every=100):
    return McapLogWriter(
        str(path),
        sim.model,
        sim.scene,
        "scene text\n",
        compression=compression,
        chunk_size=chunk_size,
        flush_every=flush_every,
    )


def _reference(path, scene, steps, compression, **kw) -> bytes:
    """Every step's messages made by the Python encoders (`McapLogWriter.write`), entered one
    by one (`McapFile.add`)."""
    sim = Simulation(load_scene(scene))
    w = _writer(path, sim, compression, **kw)
    gravity = sim.scene.world.gravity
    w.write(sim.record(), compute_stats(sim.model, gravity, sim.record()))
    for record in sim.run(steps):
        w.write(record, compute_stats(sim.model, gravity, record))
    w.close()
    return path.read_bytes()


def _packed(path, scene, steps, compression, size, **kw) -> bytes:
    """Step 0 as a record, then batches of ``size`` steps through `write_batch`."""
    sim = Simulation(load_scene(scene))
    w = _writer(path, sim, compression, **kw)
    w.write(sim.record(), compute_stats(sim.model, sim.scene.world.gravity, sim.record()))
    for batch in sim.batches(steps, size=size):
        assert w.write_batch(batch) == batch.steps
    w.close()
    return path.read_bytes()


@pytest.mark.parametrize("compression", ["none", "lz4", "zstd"])
@pytest.mark.parametrize("size", [1, 7, 64])
def test_packed_batches_give_the_bytes_of_add_message_one_by_one(tmp_path, compression, size):
    # head_on: chunks of 4 kB close every ~12 steps, so inside the batches of 7 and 64
    reference = _reference(tmp_path / "ref.mcap", "scenes/head_on.yaml", 150, compression)
    got = _packed(tmp_path / "got.mcap", "scenes/head_on.yaml", 150, compression, size)
    assert got == reference


@pytest.mark.parametrize(
    "scene",
    [
        "scenes/pendulum.yaml",  # a circle on a distance joint: /joints, World.joints
        "scenes/car.yaml",  # circles, revolute joints with motors, contacts
        "scenes/spawn.yaml",  # bodies entering and leaving: /world mid-run
        "scenes/default.yaml",  # manifolds of one and two points, pushes
    ],
)
def test_packed_batches_of_joints_circles_and_contacts_give_the_same_bytes(tmp_path, scene):
    steps = 400 if "spawn" in scene else 120
    reference = _reference(tmp_path / "ref.mcap", scene, steps, "lz4", flush_every=25)
    got = _packed(tmp_path / "got.mcap", scene, steps, "lz4", 16, flush_every=25)
    assert got == reference


def test_hashes_written_by_hashlib_when_openssl_is_not_found(tmp_path, monkeypatch):
    reference = _packed(tmp_path / "openssl.mcap", "scenes/default.yaml", 40, "none", 16)
    monkeypatch.setattr(MP, "hash_function", lambda: 0)
    assert _packed(tmp_path / "hashlib.mcap", "scenes/default.yaml", 40, "none", 16) == reference


def test_the_compiled_sha256_is_hashlibs():
    digest = np.empty(32, dtype=np.uint8)
    fn = MP.hash_function()
    for data in (b"", b"abc", bytes(range(256)) * 37):
        MP.sha256_digest(fn, np.frombuffer(data, dtype=np.uint8).copy(), digest)
        assert digest.tobytes() == hashlib.sha256(data).digest()


def test_the_scan_reads_back_each_records_channel_sequence_and_time():
    records = [
        MP.message_record(3, 7, 70_000, b"abc"),
        MP.message_record(1, 8, 2**40 + 5, b""),
        MP.message_record(65535, 2**32 - 1, 2**63 - 1, bytes(300)),
    ]
    buf = np.frombuffer(b"xx" + b"".join(records), dtype=np.uint8)
    starts, ends, channel, sequence, log_time = MP.scan_records(buf, 2, len(buf))
    assert list(channel) == [3, 1, 65535]
    assert list(sequence) == [7, 8, 2**32 - 1]
    assert list(log_time) == [70_000, 2**40 + 5, 2**63 - 1]
    assert list(ends - starts) == [len(r) for r in records]
    with pytest.raises(ValueError):
        MP.scan_records(buf, 2, len(buf) - 1)  # the last record cut short


def test_log_times_of_a_batch_are_the_clocks_one_by_one():
    from recorder.mcap_writer import LogClock

    for dt in (1 / 120, 0.01, 1e-7, 0.1 + 0.2):
        clock = LogClock(dt)
        first = 10**9 - 3
        assert list(clock.times(first, 50)) == [clock(first + k) for k in range(50)]


@pytest.mark.parametrize("openssl", [True, False])
def test_hashes_written_where_the_records_are_entered_are_the_packers(monkeypatch, openssl):
    # a writer process's parent packs without the hashes; the child writes them from the
    # /bodies records (recorder.mcap_pack.put_hashes): the same bytes as packing them
    from recorder.mcap_writer import encode_world, joint_table_rows, record_channels

    sim = Simulation(load_scene("scenes/car.yaml"))  # joints: /joints between /contacts, /stats
    batch = next(iter(sim.batches(40, size=40)))
    channels = record_channels(True)
    out = []
    for hashes in (True, False):
        packer = MP.BatchPacker(sim.model, sim.scene.world.gravity, batch.dt, channels,
                                joint_table_rows(sim.scene.joints), encode_world=encode_world,
                                hashes=hashes)  # fmt: skip
        plan = packer.plan(batch, None)
        buf = np.zeros(int(plan.sizes.sum()), dtype=np.uint8)
        done, end, _ = packer.pack(buf, 0, 0, batch.steps, batch, plan)
        assert (done, end) == (batch.steps, len(buf))
        out.append(buf)
    assert not np.array_equal(out[0], out[1])  # the digits left out
    if not openssl:
        monkeypatch.setattr(MP, "hash_function", lambda: 0)
    MP.put_hashes(out[1], 0, len(out[1]), channels)
    assert out[1].tobytes() == out[0].tobytes()


MCAP_COMPRESSION = {
    "none": CompressionType.NONE,
    "lz4": CompressionType.LZ4,
    "zstd": CompressionType.ZSTD,
}


def _calls(rng):
    """A log's worth of writer calls: metadata, attachment, two schemas, three channels, then
    messages of random sizes and channels at non-decreasing times, flushes between them."""
    calls = [
        ("metadata", "isaac", {"a": "1", "b": "two"}),
        ("attachment", 5, 7, "scene.yaml", "application/yaml", b"bodies: []\n" * 30),
        ("schema", "s.One", "protobuf", bytes(rng.integers(0, 256, 300, dtype=np.uint8))),
        ("schema", "s.Two", "protobuf", b"\x01\x02"),
        ("channel", "/a", "protobuf", 1),
        ("channel", "/b", "protobuf", 2),
        ("channel", "/c", "protobuf", 1),
    ]
    t = 1000
    for seq in range(400):
        t += int(rng.integers(0, 3))
        channel = int(rng.choice([1, 2, 3], p=[0.5, 0.3, 0.2]))
        data = bytes(rng.integers(0, 256, int(rng.integers(0, 600)), dtype=np.uint8))
        calls.append(("message", channel, t, data, seq))
        if rng.random() < 0.05:
            calls.append(("flush",))
    calls.append(("flush",))
    calls.append(("metadata", "isaac.end", {"complete": "true"}))
    return calls


def _with_mcap(calls, compression: str, chunk_size: int) -> bytes:
    out = io.BytesIO()
    w = Writer(out, chunk_size=chunk_size, compression=MCAP_COMPRESSION[compression])
    w.start(profile="isaac", library="isaac test")
    for call in calls:
        kind, args = call[0], call[1:]
        if kind == "metadata":
            w.add_metadata(*args)
        elif kind == "attachment":
            c, lt, name, media, data = args
            w.add_attachment(create_time=c, log_time=lt, name=name, media_type=media, data=data)
        elif kind == "schema":
            w.register_schema(name=args[0], encoding=args[1], data=args[2])
        elif kind == "channel":
            w.register_channel(topic=args[0], message_encoding=args[1], schema_id=args[2])
        elif kind == "message":
            channel, t, data, seq = args
            w.add_message(channel, t, data, t, seq)
        else:
            w.flush()
    w.finish()
    return out.getvalue()


def _with_mcap_file(calls, compression: str, chunk_size: int) -> bytes:
    out = io.BytesIO()
    w = McapFile(
        out,
        chunk_size=chunk_size,
        compression=compression,
        flush_every=1,
        profile="isaac",
        library="isaac test",
    )
    for call in calls:
        kind, args = call[0], call[1:]
        if kind == "metadata":
            w.add_metadata(*args)
        elif kind == "attachment":
            c, lt, name, media, data = args
            w.add_attachment(create_time=c, log_time=lt, name=name, media_type=media, data=data)
        elif kind == "schema":
            w.register_schema(name=args[0], encoding=args[1], data=args[2])
        elif kind == "channel":
            w.register_channel(topic=args[0], message_encoding=args[1], schema_id=args[2])
        elif kind == "message":
            w.add(*args)
        else:
            w.flush()
    w.finish()
    return out.getvalue()


@pytest.mark.parametrize("compression", ["none", "lz4", "zstd"])
@pytest.mark.parametrize("chunk_size", [1, 3000, 1 << 20])
def test_the_file_is_mcaps_writer_byte_for_byte(compression, chunk_size):
    calls = _calls(np.random.default_rng(37))
    assert _with_mcap_file(calls, compression, chunk_size) == _with_mcap(
        calls, compression, chunk_size
    )


@pytest.mark.parametrize("compression", ["none", "lz4", "zstd"])
def test_mcaps_reader_and_mcap_records_read_the_file(compression):
    calls = _calls(np.random.default_rng(5))
    data = _with_mcap_file(calls, compression, 3000)
    sent = [c[1:] for c in calls if c[0] == "message"]

    reader = make_reader(io.BytesIO(data), validate_crcs=True)
    got = [(c.id, m.log_time, m.data, m.sequence) for _, c, m in reader.iter_messages()]
    assert got == sent
    summary = reader.get_summary()
    assert summary.statistics.message_count == len(sent)
    assert summary.statistics.channel_message_counts == {
        k: sum(1 for s in sent if s[0] == k) for k in (1, 2, 3)
    }
    assert [c.topic for c in summary.channels.values()] == ["/a", "/b", "/c"]
    assert len(summary.chunk_indexes) == summary.statistics.chunk_count > 1

    scan = McapScan(io.BytesIO(data), len(data))
    msgs = list(scan.messages())
    assert [(m.channel_id, m.log_time, bytes(m.data), m.sequence) for m in msgs] == sent
    assert scan.index_error is None
    assert scan.summary_crc_ok() is True
    assert [m.name for _, m in scan.metadata] == ["isaac", "isaac.end"]


def _log(path, scene: str, steps: int, compression: str, flush_every: int):
    """An ISAAC log as `isaac run` writes it: step 0 as a record, then packed batches."""
    sim = Simulation(load_scene(scene))
    w = McapLogWriter(str(path), sim.model, sim.scene, "scene text\n", compression=compression,
                      flush_every=flush_every, chunk_size=CHUNK)  # fmt: skip
    w.write(sim.record())
    for batch in sim.batches(steps, size=16):
        assert w.write_batch(batch) == batch.steps
    w.close()
    return path


def _rewritten_by_mcap(path, compression: str, flush_every: int) -> bytes:
    """The log's records, in file order (mcap's `StreamReader`, CRCs checked), given to mcap's
    public `Writer` as the recorder makes its calls: every message through `add_message`, the
    file flushed after the first step and every flush_every-th, the end metadata after a
    flush."""
    out = io.BytesIO()
    w = Writer(out, chunk_size=CHUNK, compression=MCAP_COMPRESSION[compression])
    topics, steps, messages = {}, 0, 0
    with open(path, "rb") as f:
        for r in StreamReader(f, validate_crcs=True).records:
            if isinstance(r, Header):
                w.start(profile=r.profile, library=r.library)
            elif isinstance(r, Metadata):
                if messages:
                    w.flush()
                w.add_metadata(r.name, r.metadata)
            elif isinstance(r, Attachment):
                w.add_attachment(r.create_time, r.log_time, r.name, r.media_type, r.data)
            elif isinstance(r, Schema) and not messages:
                w.register_schema(r.name, r.encoding, r.data)
            elif isinstance(r, Channel) and not messages:
                topics[w.register_channel(r.topic, r.message_encoding, r.schema_id)] = r.topic
            elif isinstance(r, Message):
                messages += 1
                w.add_message(r.channel_id, r.log_time, r.data, r.publish_time, r.sequence)
                if topics[r.channel_id] == "/stats":
                    steps += 1
                    if steps == 1 or steps % flush_every == 0:
                        w.flush()
            elif isinstance(r, DataEnd):
                w.finish()
                return out.getvalue()
    raise AssertionError("no DataEnd")


@pytest.mark.parametrize(
    "scene,compression",
    [
        ("scenes/default.yaml", "none"),
        ("scenes/default.yaml", "lz4"),
        ("scenes/default.yaml", "zstd"),
        ("scenes/car.yaml", "zstd"),  # joints
        ("scenes/spawn.yaml", "lz4"),  # /world mid-run
    ],
)
def test_a_log_is_what_mcaps_writer_makes_of_its_messages(tmp_path, scene, compression):
    path = _log(tmp_path / "log.mcap", scene, 130, compression, 25)
    assert path.read_bytes() == _rewritten_by_mcap(path, compression, 25)
    reader = make_reader(open(path, "rb"), validate_crcs=True)
    assert sum(1 for _ in reader.iter_messages()) == reader.get_summary().statistics.message_count
    steps = StepReader(str(path), closed=True)
    assert sum(1 for _ in steps.steps()) == 131 and steps.complete, steps.damage


def _flipped(path, out, where) -> str:
    """``path`` copied to ``out`` with one byte flipped at ``where(records)``, records being
    (offset, opcode, body length) of every record."""
    data = bytearray(path.read_bytes())
    f, size = open_log(str(path))
    with f:
        records = [(o, op, len(b)) for o, op, b in McapScan(f, size).records()]
    data[where(records)] ^= 0x40
    out.write_bytes(data)
    return str(out)


@pytest.mark.parametrize(
    "what,where",
    [
        # the last byte of the first chunk's records: its CRC no longer matches
        ("chunk", lambda rs: next(o + 9 + n - 1 for o, op, n in rs if op == OP_CHUNK)),
        # the first MessageIndex entry's offset
        ("index", lambda rs: next(o + 9 + 6 + 8 for o, op, n in rs if op == OP_MESSAGE_INDEX)),
        # a ChunkIndex in the summary: the footer's summary CRC no longer matches
        ("summary", lambda rs: next(o + 9 + 16 for o, op, n in rs if op == OP_CHUNK_INDEX)),
    ],
)
def test_a_flipped_byte_in_a_chunk_or_an_index_is_caught(tmp_path, what, where):
    path = _log(tmp_path / "log.mcap", "scenes/default.yaml", 40, "none", 25)
    bad = _flipped(path, tmp_path / "bad.mcap", where)
    steps = StepReader(bad, closed=True)
    list(steps.steps())
    assert steps.damage is not None
    if what == "chunk":  # mcap's reader checks the chunk CRC too
        with pytest.raises(CRCValidationError), open(bad, "rb") as f:
            list(make_reader(f, validate_crcs=True).iter_messages())
