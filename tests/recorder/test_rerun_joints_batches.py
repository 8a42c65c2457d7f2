"""The Rerun recording's joints and its batch path, read back with Rerun's own reader.

Joints: each step's `/world/joints/lines` holds one 2-point strip per joint whose bodies exist,
from body a's world anchor to body b's, and `/world/joints/anchors` the same points; checked
against the engine's own `JointRows.anchor_a/_b` of every step (float32), on the in-process
writer, the Rerun writer process and `isaac view`'s MCAP conversion.
Batches: `RerunLogWriter.write_batch` (a `StepBatch` in two compiled calls) writes the same
content, value for value, as the same steps written one record at a time.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
from rerun.chunk import RrdReader

from isaac.engine.simulation import Simulation
from isaac.scene import load_scene, load_scene_text
from recorder import Recorder, blueprint
from recorder.rerun_writer import mcap_to_rrd

ROOT = Path(__file__).resolve().parents[2]
SCENES = ROOT / "scenes"


def rrd_content(path) -> dict:
    """{(entity, component): {step or "static": value}} of a .rrd (Rerun's row ids, the
    recording's properties and the wall-clock log times left out; durations as integer
    nanoseconds)."""
    out: dict = {}
    for chunk in RrdReader(str(path)).stream():
        if chunk.entity_path.startswith("/__properties"):  # its wall-clock start time
            continue
        batch = chunk.to_record_batch()
        names = batch.schema.names
        steps = batch.column("step").to_pylist() if "step" in names else None
        for name in names:
            if name.startswith("rerun.") or name == "step":
                continue
            column = batch.column(name)
            if pa.types.is_timestamp(column.type):
                continue
            if pa.types.is_duration(column.type):
                column = column.cast(pa.int64())
            values = column.to_pylist()
            keys = steps if steps is not None else ["static"] * len(values)
            slot = out.setdefault((chunk.entity_path, name), {})
            for key, value in zip(keys, values):
                if value is not None:
                    slot[key] = value
    return out


def _record(path: Path, scene, steps: int, *, batches: bool, offload: str = "none", **paths):
    """Run ``scene`` for ``steps`` steps into a Rerun recording at ``path``; returns the engine's
    records, step 0 first."""
    sim = Simulation(scene)
    records = [sim.record()]
    with Recorder(sim, rrd_path=str(path), offload=offload, **paths) as rec:
        for batch in sim.batches(steps, size=16):
            if batches:
                rec.write_batch(batch)
            else:
                for s in range(batch.steps):
                    rec.write(batch.record(s))
            records += [batch.record(s) for s in range(batch.steps)]
    return records


def _check_joints_drawn(rrd: Path, records: list) -> None:
    content = rrd_content(rrd)
    lines = content[("/world/joints/lines", "LineStrips2D:strips")]
    anchors = content[("/world/joints/anchors", "Points2D:positions")]
    assert sorted(lines) == [r.step for r in records] == sorted(anchors)
    for r in records:
        j = r.joints
        expected = np.stack([j.anchor_a, j.anchor_b], axis=1)  # (m, 2 ends, 2)
        drawn = np.array(lines[r.step], dtype=np.float64).reshape(-1, 2, 2)
        assert drawn.shape == expected.shape, r.step
        # float32 in Rerun: within a float32 rounding of the engine's float64 anchors
        np.testing.assert_allclose(
            drawn, expected, rtol=1e-6, atol=1e-6 * (1 + np.abs(expected).max())
        )
        points = np.array(anchors[r.step], dtype=np.float64)
        np.testing.assert_array_equal(points, drawn.reshape(-1, 2))


@pytest.mark.parametrize("name", ["pendulum", "car"])
@pytest.mark.parametrize("batches", [False, True])
def test_joint_lines_run_from_each_steps_anchor_on_a_to_its_anchor_on_b(tmp_path, name, batches):
    rrd = tmp_path / f"{name}.rrd"
    records = _record(rrd, load_scene(SCENES / f"{name}.yaml"), 40, batches=batches)
    _check_joints_drawn(rrd, records)
    # drawn in the joints' classes of the legend, labels off (they covered small bodies)
    content = rrd_content(rrd)
    ((text,),) = content[("/info", "TextDocument:text")].values()
    assert blueprint.JOINT.label in text and blueprint.ANCHOR.label in text  # in the legend
    for kind, archetype in ((blueprint.JOINT, "LineStrips2D"), (blueprint.ANCHOR, "Points2D")):
        style = f"/world/{kind.entity}"
        assert content[(style, f"{archetype}:class_ids")] == {"static": [kind.class_id]}
        assert content[(style, f"{archetype}:show_labels")] == {"static": [False]}
    if name == "car":  # revolute: the two anchors of each joint meet (the drawn pivot)
        last = np.array(rrd_content(rrd)[("/world/joints/lines", "LineStrips2D:strips")][40])
        assert np.abs(last[:, 0] - last[:, 1]).max() < 1e-3


def test_the_rerun_writer_process_and_the_mcap_conversion_draw_the_joints(tmp_path):
    scene = load_scene(SCENES / "double_pendulum.yaml")
    rrd, mcap = tmp_path / "run.rrd", tmp_path / "run.mcap"
    records = _record(rrd, scene, 30, batches=True, offload="process", mcap_path=str(mcap))
    _check_joints_drawn(rrd, records)
    converted = mcap_to_rrd(str(mcap), str(tmp_path / "converted.rrd"))
    _check_joints_drawn(converted, records)


LEAVING = """
name: leaving
world: {gravity: [0.0, -9.81], dt: 1/120, steps: 60}
bodies:
  - {name: post, shape: {box: [0.2, 0.2]}, position: [0.0, 0.0], concrete: true}
  - {name: bob, shape: {circle: {radius: 0.1}}, position: [1.0, 0.0], leaves_at: 0.2}
  - {name: bar, shape: {box: [1.0, 0.1]}, position: [0.5, 2.0]}
joints:
  - {name: rod, type: distance, bodies: [post, bob], anchor_a: [0.0, 0.0], anchor_b: [1.0, 0.0]}
  - {name: pin, type: revolute, bodies: [post, bar], anchor: [0.0, 2.0]}
"""


def test_a_joint_whose_body_left_is_not_drawn(tmp_path):
    scene = load_scene_text(LEAVING)
    rrd = tmp_path / "leaving.rrd"
    records = _record(rrd, scene, 50, batches=True)
    lines = rrd_content(rrd)[("/world/joints/lines", "LineStrips2D:strips")]
    for r in records:
        drawn = np.array(lines[r.step], dtype=np.float64).reshape(-1, 2, 2)
        kept = [k for k in range(2) if r.exists[scene_index(scene, ("bob", "bar")[k])]]
        expected = np.stack([r.joints.anchor_a, r.joints.anchor_b], axis=1)[kept]
        np.testing.assert_allclose(drawn, expected, rtol=1e-6, atol=1e-5)
    assert len(lines[0]) == 2 and len(lines[50]) == 1  # the bob left at t = 0.2 s (step 24)


def scene_index(scene, name: str) -> int:
    return [b.name for b in scene.bodies].index(name)


@pytest.mark.parametrize("name, steps", [("default", 130), ("car", 60), ("spawn", 150)])
def test_whole_batches_write_what_the_records_one_by_one_write(tmp_path, name, steps):
    scene = load_scene(SCENES / f"{name}.yaml")
    one, whole = tmp_path / "one.rrd", tmp_path / "whole.rrd"
    _record(one, scene, steps, batches=False)
    _record(whole, scene, steps, batches=True)
    a, b = rrd_content(one), rrd_content(whole)
    assert sorted(a) == sorted(b)
    for key in a:
        assert a[key] == b[key], key
    # the content is there: every step's outlines and stats
    assert len(a[("/world/bodies/moving", "LineStrips2D:strips")]) == steps + 1
    assert len(a[("/stats/total_energy", "Scalars:scalars")]) == steps + 1
    # sim_time: the record's time, step * dt, in nanoseconds rounded as rr.set_time rounds it
    dt = scene.world.dt
    for entity in ("/world/bodies/moving", "/world/contacts", "/stats/max_depth"):
        times = a[(entity, "sim_time")]
        assert times == {k: round(1e9 * (k * dt)) for k in times} and len(times) > steps
