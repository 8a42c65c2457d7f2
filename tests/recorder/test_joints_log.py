"""Joints in the MCAP log: `/world` carries the joint table and `/joints` every step's joint rows
(docs/log-format.md). Checked against the engine's own records bit for bit on every path that
writes steps (one record at a time and whole batches; in this process, in a thread and in a
writer process), decoded both by the project's reader and by google.protobuf from the schema
stored in the file; replay compares `/joints` bit for bit and names a 1-ULP edit; `isaac
inspect --step K` lists the joints; a scene without joints keeps the bytes it had."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.reader import make_reader

from isaac.engine.records import JOINT_FIELDS
from isaac.engine.simulation import Simulation
from isaac.scene import load_scene
from recorder import Recorder
from recorder import schema as S
from recorder.reader import LogReader

ROOT = Path(__file__).resolve().parents[2]
SCENES = ROOT / "scenes"
STEPS = 120


def _bits(a) -> np.ndarray:
    return np.ascontiguousarray(a, dtype="<f8").view(np.uint64)


def _record(path: Path, name: str, *, offload: str, batches: bool, steps: int = STEPS) -> list:
    """Record scenes/NAME.yaml for ``steps`` steps; returns the engine's records, step 0 first."""
    sim = Simulation(load_scene(SCENES / f"{name}.yaml"))
    records = [sim.record()]
    with Recorder(sim, str(path), offload=offload, compression="none") as rec:
        if batches:
            for batch in sim.batches(steps):
                rec.write_batch(batch)
                records += [batch.record(s) for s in range(batch.steps)]
        else:
            for r in sim.run(steps):
                rec.write(r)
                records.append(r)
    assert len(records) == steps + 1
    return records


@pytest.fixture(scope="module")
def logs(tmp_path_factory) -> dict:
    """(scene, offload, batches) -> (log path, the engine's records)."""
    folder = tmp_path_factory.mktemp("joints_log")
    out = {}
    for name in ("pendulum", "double_pendulum"):
        for offload in ("none", "thread", "process"):
            for batches in (False, True):
                path = folder / f"{name}_{offload}_{batches}.mcap"
                out[name, offload, batches] = (
                    path,
                    _record(path, name, offload=offload, batches=batches),
                )
    return out


def _generic_messages(path: Path, topic: str) -> list:
    """The messages of ``topic`` decoded by google.protobuf from the file's own schema."""
    out = []
    with open(path, "rb") as f:
        for schema, _channel, message in make_reader(f).iter_messages(topics=[topic]):
            fds = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
            pool = descriptor_pool.DescriptorPool()
            for fd in fds.file:
                pool.Add(fd)
            cls = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))
            out.append((message.sequence, cls.FromString(message.data)))
    return out


@pytest.mark.parametrize("name", ["pendulum", "double_pendulum"])
def test_every_path_logs_the_engines_joint_rows_bit_for_bit(logs, name):
    scene = load_scene(SCENES / f"{name}.yaml")
    reference = logs[name, "none", False][0].read_bytes()
    for (scene_name, offload, batches), (path, records) in logs.items():
        if scene_name != name:
            continue
        where = f"{name}, offload {offload}, batches {batches}"
        # every path writes the same file
        assert path.read_bytes() == reference, where
        steps = list(LogReader(str(path)).steps())
        assert [s.step for s in steps] == [r.step for r in records], where
        for logged, r in zip(steps, records):
            assert r.joints is not None and len(r.joints) == len(scene.joints)
            for field in JOINT_FIELDS:
                mine, theirs = getattr(logged.record.joints, field), getattr(r.joints, field)
                assert mine.shape == np.asarray(theirs).shape, (where, logged.step, field)
                assert np.array_equal(_bits(mine), _bits(theirs)), (where, logged.step, field)
    # and a generic protobuf reader sees the same doubles, one /joints message a step
    path, records = logs[name, "none", False]
    generic = _generic_messages(path, "/joints")
    assert [seq for seq, _m in generic] == [r.step for r in records]
    widths = {"impulses": 6, "angular_impulse": 1, "motor_impulse": 1, "limit_impulse": 1}
    for (seq, msg), r in zip(generic, records):
        assert msg.step == seq and _bits([msg.time]) == _bits([r.time])
        for field in JOINT_FIELDS:
            got = np.array(getattr(msg, field), dtype=np.float64)
            want = np.asarray(getattr(r.joints, field), dtype=np.float64).reshape(-1)
            assert got.size == widths.get(field, 2) * len(scene.joints)
            assert np.array_equal(_bits(got), _bits(want)), (seq, field)


@pytest.mark.parametrize("name", ["pendulum", "double_pendulum"])
def test_world_carries_the_scenes_joint_table(logs, name):
    scene = load_scene(SCENES / f"{name}.yaml")
    path = logs[name, "none", False][0]
    worlds = _generic_messages(path, "/world")
    assert len(worlds) == 1  # no body enters or leaves
    table = list(worlds[0][1].joints)
    assert len(table) == len(scene.joints) > 0
    for i, (logged, spec) in enumerate(zip(table, scene.joints)):
        assert (logged.index, logged.name, logged.type) == (i, spec.name, spec.kind)
        assert (logged.a, logged.b) == (spec.a, spec.b)
        for field in ("local_a", "local_b", "axis"):
            assert np.array_equal(_bits(list(getattr(logged, field))), _bits(getattr(spec, field)))
        for field in ("reference_angle", "length", "damping_ratio", "max_motor"):
            assert _bits([getattr(logged, field)]) == _bits([getattr(spec, field)]), field
        # a value the scene leaves out is an infinite limit, or a flag that is false
        for field, none in (
            ("min_length", -np.inf),
            ("max_length", np.inf),
            ("lower", -np.inf),
            ("upper", np.inf),
        ):
            want = none if getattr(spec, field) is None else getattr(spec, field)
            assert getattr(logged, field) == want, field
        assert logged.spring == (spec.stiffness is not None)
        assert logged.motor == (spec.motor_speed is not None)
        assert logged.collide_connected == spec.collide_connected
    # the project's reader gives the same table
    world = LogReader(str(path)).world
    assert [j["name"] for j in world.joints] == [j.name for j in scene.joints]
    assert [j["type"] for j in world.joints] == [j.kind for j in scene.joints]


def test_a_scene_without_joints_has_no_joint_schema_nor_channel(tmp_path):
    sim = Simulation(load_scene(SCENES / "stack.yaml"))
    path = tmp_path / "stack.mcap"
    with Recorder(sim, str(path), offload="none", compression="none") as rec:
        for r in sim.run(5):
            rec.write(r)
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    topics = sorted(c.topic for c in summary.channels.values())
    assert topics == ["/bodies", "/contacts", "/stats", "/world"]
    for schema in summary.schemas.values():
        assert schema.data == S.schema_bytes()  # the schema of the logs before joints
        fds = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
        names = [m.name for m in fds.file[0].message_type]
        assert "Joint" not in names and "Joints" not in names
    assert S.schema_bytes() != S.schema_bytes(joints=True)


@pytest.mark.parametrize("name", ["pendulum", "double_pendulum"])
def test_replay_says_identical(logs, name):
    from replay.compare import replay_log

    path = logs[name, "none", True][0]
    report = replay_log(str(path))
    assert report.verdict == "identical", report.divergences[:1]
    assert report.steps_compared == STEPS + 1
    # from a keyframe: the logged joints carry the warm-start impulses the replay goes on from
    report = replay_log(str(path), from_step=STEPS // 2)
    assert report.verdict == "identical", report.divergences[:1]
    assert report.steps_compared == STEPS - STEPS // 2


def test_one_ulp_in_a_joint_impulse_is_named(logs, tmp_path):
    from replay.compare import diff_logs, replay_log

    sys.path.insert(0, str(ROOT / "tests" / "replay"))
    from mcap_surgery import crafted, rewrite

    src = logs["double_pendulum", "none", False][0]
    step, joint, column = 40, 1, 1  # the second joint's point impulse along y
    names = [j.name for j in load_scene(SCENES / "double_pendulum.yaml").joints]
    original = S.decode("Joints", _message(src, "/joints", step))["impulses"].reshape(-1, 6)
    value = float(original[joint, column])
    assert value != 0.0  # a value the step really holds
    bumped = float(np.nextafter(value, np.inf))

    def change(d):
        v = d["impulses"].copy().reshape(-1, 6)
        v[joint, column] = bumped
        d["impulses"] = v.reshape(-1)

    edited = rewrite(src, tmp_path / "edited.mcap", crafted("/joints", step, change))
    assert _message(edited, "/bodies", step) == _message(src, "/bodies", step)
    report = replay_log(str(edited))
    assert report.verdict != "identical"
    first = report.divergences[0]
    assert (first.step, first.channel, first.field) == (step, "/joints", "impulses")
    assert first.joint == {"index": joint, "name": names[joint], "component": f"J{column}"}
    assert first.ulps == 1 and (first.logged, first.replayed) == (bumped, value)
    assert names[joint] in first.where()
    # log against log: the same place
    report = diff_logs(str(src), str(edited))
    first = report.divergences[0]
    assert (first.step, first.channel, first.field, first.ulps) == (step, "/joints", "impulses", 1)
    assert first.joint["name"] == names[joint]


def _message(path: Path, topic: str, step: int) -> bytes:
    with open(path, "rb") as f:
        for _s, _c, message in make_reader(f).iter_messages(topics=[topic]):
            if message.sequence == step:
                return message.data
    raise AssertionError(f"no {topic} at step {step}")


def _isaac(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "isaac", *args], cwd=ROOT, capture_output=True, text=True,
        timeout=300,
    )  # fmt: skip


def test_inspect_lists_the_joints(logs):
    from isaac.app.logs import _g

    path = logs["double_pendulum", "none", False][0]
    scene = load_scene(SCENES / "double_pendulum.yaml")
    step = 50
    joints = LogReader(str(path)).step(step).record.joints
    done = _isaac("inspect", str(path), "--step", str(step))
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    at = lines.index(f"{len(scene.joints)} joint(s):")
    head = lines[at + 1].split()
    assert head[:4] == ["joint", "type", "a", "b"]
    rows = [line.split() for line in lines[at + 2 : at + 2 + len(scene.joints)]]
    names = [b.name for b in scene.bodies]
    for i, (row, spec) in enumerate(zip(rows, scene.joints)):
        cell = dict(zip(head, row))
        assert (cell["joint"], cell["type"]) == (spec.name, spec.kind)
        assert (cell["a"], cell["b"]) == (f"{spec.a}:{names[spec.a]}", f"{spec.b}:{names[spec.b]}")
        assert cell["anchor_b_x"] == _g(joints.anchor_b[i, 0])
        assert cell["lin_imp_y"] == _g(joints.linear_impulse[i, 1])
        assert cell["error_m"] == _g(joints.error[i, 0])
    # JSON: the exact doubles
    done = _isaac("inspect", str(path), "--step", str(step), "--format", "json")
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout)["joints"]
    assert out["name"] == [j.name for j in scene.joints]
    assert np.array_equal(_bits(out["anchor_a_m"]), _bits(joints.anchor_a))
    assert np.array_equal(_bits(out["impulses"]), _bits(joints.impulses))


def test_one_ulp_in_the_joint_table_is_named(logs, tmp_path):
    from replay.compare import replay_log

    sys.path.insert(0, str(ROOT / "tests" / "replay"))
    from mcap_surgery import crafted, rewrite

    src = logs["pendulum", "none", False][0]
    name = load_scene(SCENES / "pendulum.yaml").joints[0].name

    def change(d):
        d["joints"][0]["length"] = float(np.nextafter(d["joints"][0]["length"], np.inf))

    edited = rewrite(src, tmp_path / "edited.mcap", crafted("/world", 0, change))
    first = replay_log(str(edited)).divergences[0]
    assert (first.step, first.channel, first.field, first.ulps) == (0, "/world", "joints.length", 1)
    assert first.joint == {"index": 0, "name": name}


@pytest.mark.parametrize("offload", ["none", "process"])
@pytest.mark.parametrize("batches", [False, True])
def test_a_non_finite_joint_value_stops_the_run_and_keeps_the_steps_before(
    tmp_path, offload, batches
):
    import dataclasses

    from isaac.engine.records import JointRows, StepBatch, StepRecord
    from isaac.errors import SimulationError

    sim = Simulation(load_scene(SCENES / "double_pendulum.yaml"))
    records = list(sim.run(20))
    bad_step = records[12].step
    j = records[12].joints
    error = np.array(j.error)
    error[1, 0] = np.nan
    fields = {f: getattr(records[12], f) for f in StepRecord.__dataclass_fields__}
    records[12] = StepRecord(**{**fields, "joints": dataclasses.replace(j, error=error)})
    assert isinstance(records[12].joints, JointRows)
    path = tmp_path / "nan.mcap"
    fresh = Simulation(load_scene(SCENES / "double_pendulum.yaml"))
    with pytest.raises(SimulationError, match=f"step {bad_step}: joint 1 has a non-finite error"):
        with Recorder(fresh, str(path), offload=offload, compression="none") as rec:
            if batches:
                rec.write_batch(StepBatch.of_records(records, fresh.scene.world.dt))
            else:
                for r in records:
                    rec.write(r)
    steps = list(LogReader(str(path)).steps())
    assert [s.step for s in steps] == list(range(bad_step))
    assert all(np.isfinite(s.record.joints.error).all() for s in steps)


def test_inspect_summary_names_the_largest_joint_error(logs):
    from isaac.app.logs import _g

    path = logs["double_pendulum", "none", False][0]
    scene = load_scene(SCENES / "double_pendulum.yaml")
    errors = np.array([s.record.joints.error[:, 0] for s in LogReader(str(path)).steps()])
    step, joint = np.unravel_index(int(np.argmax(errors)), errors.shape)
    assert errors.max() > 0.0
    done = _isaac("inspect", str(path))
    assert done.returncode == 0, done.stderr
    line = next(x for x in done.stdout.splitlines() if x.startswith("joints "))
    kinds = sorted({j.kind for j in scene.joints})
    assert line.startswith(f"joints   {len(scene.joints)} (")
    assert all(kind in line for kind in kinds)
    want = f"largest error {_g(errors.max())} m ({scene.joints[joint].name!r}, step {step})"
    assert line.endswith(want), line
