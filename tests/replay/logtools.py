"""Helpers for the replay tests: record small scenes, and rewrite a log with one thing changed."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from isaac.engine.diagnostics import state_hash
from isaac.engine.records import Contacts, StepRecord
from isaac.engine.simulation import Simulation
from isaac.scene import load_scene, load_scene_text
from recorder import Recorder
from recorder import schema as S
from recorder.mcap_writer import encode_bodies, encode_contacts

REPO = Path(__file__).resolve().parents[2]
SCENES = REPO / "scenes"

# two boxes resting on a ground, a third dropped on them; friction on (3 bodies move)
STACK = """\
name: stack
world:
  dt: 0.01
  steps: 120
  friction: true
bodies:
  - name: ground
    shape: {box: [10.0, 1.0]}
    position: [0.0, -0.5]
    concrete: true
  - name: low
    shape: {box: [1.0, 1.0]}
    position: [0.0, 0.5]
  - name: high
    shape: {box: [1.0, 1.0]}
    position: [0.2, 1.6]
    angle: 0.1
  - name: falling
    shape: {regular: {sides: 5, radius: 0.5}}
    position: [-0.1, 4.0]
    restitution: 0.3
"""

# bodies enter and leave while others rest on the ground (the set of bodies changes 3 times)
COMINGS_AND_GOINGS = """\
name: comings_and_goings
world:
  dt: 0.01
  steps: 150
bodies:
  - name: ground
    shape: {box: [8.0, 1.0]}
    position: [0.0, -0.5]
    concrete: true
  - name: resting
    shape: {box: [1.0, 1.0]}
    position: [0.0, 0.5]
    leaves_at: 1.0
  - name: late
    shape: {box: [0.8, 0.8]}
    position: [0.1, 2.5]
    enters_at: 0.3
  - name: later
    shape: {polygon: [[-0.5, 0.0], [0.5, 0.0], [0.0, 0.7]]}
    position: [-0.2, 4.0]
    enters_at: 0.6
"""

# a small pile from the generator, with the seed's algorithm (one-point contacts, full push-out)
SMALL_PILE = """\
name: small_pile
world:
  dt: 0.016666666666666666
  steps: 60
  fidelity: seed
generators:
  - pile: {count: 25, seed: 7, container: {width: 5.0}}
"""


def scene_from(text_or_name: str, *, steps: int | None = None):
    """A scene from inline YAML text, or from scenes/NAME.yaml when given a bare name."""
    if "\n" in text_or_name:
        scene = load_scene_text(text_or_name, source="<test>")
    else:
        scene = load_scene(SCENES / f"{text_or_name}.yaml")
    return scene, (scene.world.steps if steps is None else steps)


def record(
    path: Path, scene_text_or_name: str, *, steps: int | None = None, compression: str = "lz4"
) -> list[str]:
    """Run a scene with the Recorder writing ``path``; returns the state hash of every step."""
    scene, steps = scene_from(scene_text_or_name, steps=steps)
    sim = Simulation(scene)
    hashes = []
    with Recorder(sim, mcap_path=str(path), compression=compression) as rec:
        first = sim.record()
        rec.write(first)
        hashes.append(state_hash(first))
        for r in sim.run(steps):
            rec.write(r)
            hashes.append(state_hash(r))
    return hashes


def run_hashes(scene_text_or_name: str, *, steps: int | None = None) -> list[str]:
    """State hashes of a run without any recording."""
    scene, steps = scene_from(scene_text_or_name, steps=steps)
    sim = Simulation(scene)
    return [state_hash(sim.record())] + [state_hash(r) for r in sim.run(steps)]


def rewrite(
    src: Path, dst: Path, *, message=None, scene=None, metadata=None, fix_scene_hash: bool = True
) -> None:
    """Copy the clean log ``src`` to ``dst`` with the same layout, changing one thing.

    message(topic, step, data) -> bytes | None: new payload (None drops the message).
    scene(text) -> text: new embedded scene; its sha256 in the metadata is updated unless
        ``fix_scene_hash`` is False. metadata(dict) -> dict: new ``isaac`` metadata.
    """
    with open(src, "rb") as f:
        reader = make_reader(f)
        metas = [(m.name, dict(m.metadata)) for m in reader.iter_metadata()]
        attachments = list(reader.iter_attachments())
        messages = [(ch.topic, sc, ch, m) for sc, ch, m in reader.iter_messages()]
    with open(dst, "wb") as out:
        w = Writer(out, compression=CompressionType.LZ4)
        w.start(profile="isaac", library="isaac-recorder")
        for name, meta in metas:
            if name != "isaac":
                continue
            for a in attachments:
                if a.name == "scene.yaml" and scene is not None:
                    text = scene(a.data.decode("utf-8"))
                    if fix_scene_hash:
                        meta["scene_sha256"] = hashlib.sha256(text.encode()).hexdigest()
            if metadata is not None:
                meta = metadata(meta)
            w.add_metadata(name, meta)
        for a in attachments:
            data = a.data
            if a.name == "scene.yaml" and scene is not None:
                data = scene(data.decode("utf-8")).encode("utf-8")
            w.add_attachment(a.create_time, a.log_time, a.name, a.media_type, data)
        schema_ids, channel_ids = {}, {}
        for topic, sc, ch, m in messages:
            if sc.id not in schema_ids:
                schema_ids[sc.id] = w.register_schema(sc.name, sc.encoding, sc.data)
            if ch.id not in channel_ids:
                channel_ids[ch.id] = w.register_channel(
                    topic, ch.message_encoding, schema_ids[sc.id], dict(ch.metadata)
                )
            data = m.data if message is None else message(topic, m.sequence, m.data)
            if data is not None:
                w.add_message(channel_ids[ch.id], m.log_time, data, m.publish_time, m.sequence)
        for name, meta in metas:
            if name != "isaac":
                w.add_metadata(name, meta)
        w.finish()


def bodies_with(data: bytes, change) -> bytes:
    """Re-encode a ``/bodies`` payload after ``change(arrays)`` edits a dict of writable arrays."""
    d = S.decode("Bodies", data)
    arrays = {
        k: np.array(d[k]) for k in ("position", "angle", "velocity", "angular_velocity", "exists")
    }
    change(arrays)
    n = arrays["angle"].size
    rec = StepRecord(
        step=d["step"],
        time=d["time"],
        position=arrays["position"].reshape(n, 2),
        angle=arrays["angle"],
        velocity=arrays["velocity"].reshape(n, 2),
        angular_velocity=arrays["angular_velocity"],
        exists=arrays["exists"],
        contacts=Contacts.empty(),
    )
    return encode_bodies(rec)


def contacts_with(data: bytes, change) -> bytes:
    """Re-encode a ``/contacts`` payload after ``change(fields)`` edits a dict of its arrays
    (flat, as in the message); rows can be dropped by slicing every array."""
    from recorder.reader import contacts_from_message

    d = S.decode("Contacts", data)
    fields = {k: np.array(v) for k, v in d.items() if isinstance(v, np.ndarray)}
    change(fields)
    d.update(fields)
    rec = StepRecord(
        step=d["step"],
        time=d["time"],
        position=np.zeros((0, 2)),
        angle=np.zeros(0),
        velocity=np.zeros((0, 2)),
        angular_velocity=np.zeros(0),
        exists=np.zeros(0, bool),
        contacts=contacts_from_message(d),
    )
    return encode_contacts(rec)


def bodies_changed(src: Path, dst: Path, steps, change) -> None:
    """Copy the log ``src`` to ``dst`` with the ``/bodies`` payload of each step in ``steps``
    edited by ``change(arrays)`` (`bodies_with`)."""
    rewrite(
        src,
        dst,
        message=lambda topic, step, data: (
            bodies_with(data, change) if topic == "/bodies" and step in steps else data
        ),
    )
