"""The packed-record path (`recorder.mcap_pack` + `recorder.mcap_chunks`): whole batches of
steps packed as Message records by one compiled call and entered into the chunk a stretch at a
time give the bytes of the reference, the Python encoders feeding mcap's own
`Writer.add_message` one message at a time."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

import recorder.mcap_chunks as MC
import recorder.mcap_pack as MP
from isaac import Simulation, load_scene
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
    """Every step's messages made by the Python encoders (`McapLogWriter.write`), each through
    mcap's own `Writer.add_message` (the packed chunk builder not installed)."""
    sim = Simulation(load_scene(scene))
    original = MC.install
    MC.install = lambda writer: "reference: mcap's own ChunkBuilder"
    try:
        w = _writer(path, sim, compression, **kw)
    finally:
        MC.install = original
    assert not w._sink.fast
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
    assert w._sink.fast, w._sink.reason
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


def test_the_sink_without_its_chunk_builder_feeds_add_message_the_same_bytes(tmp_path):
    # the fallback when mcap's Writer is not what install expects: every packed message goes
    # through add_message, and the file is the same
    reference = _packed(tmp_path / "fast.mcap", "scenes/default.yaml", 60, "zstd", 16)
    original = MC.install
    MC.install = lambda writer: "mcap changed"
    try:
        sim = Simulation(load_scene("scenes/default.yaml"))
        w = _writer(tmp_path / "slow.mcap", sim, "zstd")
        assert not w._sink.fast and w._sink.reason == "mcap changed"
        w.write(sim.record(), compute_stats(sim.model, sim.scene.world.gravity, sim.record()))
        for batch in sim.batches(60, size=16):
            w.write_batch(batch)
        w.close()
    finally:
        MC.install = original
    assert (tmp_path / "slow.mcap").read_bytes() == reference


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
