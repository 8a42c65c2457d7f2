"""The MCAP log decodes in Foxglove's TypeScript stack (@mcap/core + protobufjs, and
@mcap/support's lz4 and zstd decompressors, the ones Foxglove loads MCAP files with), bit for
bit, with each chunk compression.

Needs node and npm (on this project's machines); the three npm packages are installed once into
.venv/js-mcap-check. Without node, or with no npm registry to install from, the test is skipped
with the reason.
"""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from recorder.reader import LogReader

REPO = Path(__file__).resolve().parents[2]
JS = Path(__file__).resolve().parent / "js"
MODULES = REPO / ".venv" / "js-mcap-check"

SCENE = """
name: foxglove_check
world: {gravity: [0.0, -9.81], dt: 0.01, steps: 60}
bodies:
  - {name: ground, shape: {box: [10.0, 1.0]}, position: [0.0, -0.5], concrete: true}
  - {name: box, shape: {box: [1.0, 1.0]}, position: [0.0, 1.0], angular_velocity: 0.3}
  - {name: hex, shape: {regular: {sides: 6, radius: 0.4}}, position: [0.3, 2.5],
     velocity: [0.1, 0.0], enters_at: 0.2}
"""


def _node_modules() -> Path:
    node, npm = shutil.which("node"), shutil.which("npm")
    if node is None or npm is None:
        pytest.skip("node/npm not installed")
    if not all((MODULES / "node_modules" / "@mcap" / p).exists() for p in ("core", "support")):
        MODULES.mkdir(parents=True, exist_ok=True)
        shutil.copy(JS / "package.json", MODULES / "package.json")
        try:
            done = subprocess.run(
                [npm, "install", "--no-audit", "--no-fund", "--silent"],
                cwd=MODULES,
                capture_output=True,
                text=True,
                timeout=300,
            )
        except subprocess.TimeoutExpired:
            pytest.skip("npm install timed out (no registry?)")
        if done.returncode != 0:
            pytest.skip(f"npm install failed: {done.stderr.strip()[:200]}")
    shutil.copy(JS / "decode_mcap.mjs", MODULES / "decode_mcap.mjs")
    return MODULES


@pytest.mark.parametrize("compression", ["lz4", "zstd", "none"])  # lz4: the default
def test_every_channel_decodes_with_foxglove_typescript_stack_bit_for_bit(tmp_path, compression):
    modules = _node_modules()
    scene = tmp_path / "scene.yaml"
    scene.write_text(SCENE)
    log = tmp_path / "run.mcap"
    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "isaac",
            "run",
            str(scene),
            "--quiet",
            "--mcap",
            str(log),
            "--compression",
            compression,
        ],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stderr
    node = subprocess.run(
        [shutil.which("node"), str(modules / "decode_mcap.mjs"), str(log)],
        cwd=modules,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert node.returncode == 0, node.stderr
    decoded = json.loads(node.stdout)

    steps = list(LogReader(str(log)).steps())
    assert decoded["counts"]["/bodies"] == decoded["counts"]["/contacts"] == len(steps) == 61
    assert decoded["counts"]["/stats"] == len(steps)
    # /world at step 0 and when the hexagon enters
    assert decoded["counts"]["/world"] == 2
    for which, logged in (("first", steps[0].record), ("last", steps[-1].record)):
        js = decoded[which]
        assert js["step"] == logged.step
        assert np.array_equal(
            np.array(js["position"], dtype=np.float64), logged.position.reshape(-1)
        )
        assert np.array_equal(
            np.array(js["velocity"], dtype=np.float64), logged.velocity.reshape(-1)
        )
        assert np.array_equal(np.array(js["angle"], dtype=np.float64), logged.angle)
        assert np.array_equal(
            np.array(js["angularVelocity"], dtype=np.float64), logged.angular_velocity
        )
    # /contacts (format 2): the manifold fields once per manifold, the point fields per point
    js = decoded["contacts"]
    assert js is not None
    c = next(s.record.contacts for s in steps if s.record.step == js["step"])
    first = c.slot == 0
    assert np.array_equal(np.array(js["points"]), np.diff(np.append(np.flatnonzero(first), len(c))))
    assert (np.array(js["points"]) == 2).any()  # a two-point manifold among them
    for name in ("substep", "a", "b", "feature"):
        assert np.array_equal(np.array(js[name], dtype=np.int64), getattr(c, name)[first]), name
    for name in ("normal", "pair_depth"):
        want = getattr(c, name)[first].reshape(-1)
        assert np.array_equal(np.array(js[name], dtype=np.float64), want), name
    # the pushes of the manifolds the push-out moved, named by index
    moved = np.flatnonzero((c.push_a[first] != 0).any(axis=1) | (c.push_b[first] != 0).any(axis=1))
    assert np.array_equal(np.array(js["pushed"], dtype=np.int64), moved)
    for name in ("push_a", "push_b"):
        want = getattr(c, name)[first][moved].reshape(-1)
        assert np.array_equal(np.array(js[name], dtype=np.float64), want), name
    for name, ours in (
        ("point", "point"),
        ("point_depth", "depth"),
        ("impulse", "impulse"),
        ("tangent_impulse", "tangent_impulse"),
        ("restitution", "restitution"),
    ):
        want = getattr(c, ours).reshape(-1)
        assert np.array_equal(np.array(js[name], dtype=np.float64), want), name


@pytest.mark.parametrize("compression", ["lz4", "none"])
def test_joint_channels_decode_with_foxglove_typescript_stack_bit_for_bit(tmp_path, compression):
    """A scene with joints: /world's joint table and /joints decode in the same stack."""
    from isaac.engine.simulation import Simulation
    from isaac.scene import load_scene
    from recorder import Recorder

    modules = _node_modules()
    scene = load_scene(REPO / "scenes" / "double_pendulum.yaml")
    log = tmp_path / "joints.mcap"
    sim = Simulation(scene)
    with Recorder(sim, str(log), compression=compression, offload="none") as rec:
        for r in sim.run(30):
            rec.write(r)
    node = subprocess.run(
        [shutil.which("node"), str(modules / "decode_mcap.mjs"), str(log)],
        cwd=modules,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert node.returncode == 0, node.stderr
    decoded = json.loads(node.stdout)
    steps = list(LogReader(str(log)).steps())
    assert decoded["counts"]["/joints"] == len(steps) == 31
    last = steps[-1].record.joints
    js = decoded["joints"]
    assert js["step"] == steps[-1].step
    for name in ("anchor_a", "anchor_b", "linear_impulse", "error", "impulses"):
        assert np.array_equal(
            np.array(js[name], dtype=np.float64), getattr(last, name).reshape(-1)
        ), name
    for name in ("angular_impulse", "motor_impulse", "limit_impulse"):
        assert np.array_equal(np.array(js[name], dtype=np.float64), getattr(last, name)), name
    table = decoded["jointTable"]
    assert [j["name"] for j in table] == [j.name for j in scene.joints]
    assert [j["type"] for j in table] == [j.kind for j in scene.joints]
    for j, spec in zip(table, scene.joints):
        assert (int(j["a"]), int(j["b"])) == (spec.a, spec.b)
        assert tuple(j["local_a"]) == spec.local_a and tuple(j["local_b"]) == spec.local_b
        lower = -np.inf if spec.lower is None else spec.lower
        assert float(j["lower"]) == lower  # "-Infinity" for no limit
