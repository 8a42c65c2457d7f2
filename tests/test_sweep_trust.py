"""A sweep trusts no file it did not check: `isaac sweep verify` checks every log against the
sha256 its row in runs.parquet names (a swapped or replaced log replays identical, being a true
log of some run) and keeps the replay's notes; the `tunneled` metric counts only the concrete
bodies a body could have collided with (not one a joint connects it to, nor one its collision
filter keeps it from).

Small sweeps (2-3 runs, few steps) on one 1-worker local cluster for the module.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from cluster_helpers import local_cluster
from physics_helpers import LEDGE, ROTOR

from isaac.app.cli import main
from isaac.app.sweep import execute
from isaac.app.sweep.worker import sha256_of

ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT / "scenes"
if str(ROOT) not in sys.path:  # the workers import the repository (see tests/test_sweep.py)
    sys.path.append(str(ROOT))

# three runs that differ only in the box's restitution: in 10 steps the box does not reach the
# ground, so the three logs differ in their embedded scenes alone
THREE_RUNS = """\
scene: {scene}
runs:
  grid:
    bodies.box.restitution: [0.2, 0.5, 0.8]
steps: 10
record: mcap
"""


@pytest.fixture(scope="module")
def cluster():
    with local_cluster(1) as both:
        yield both


@pytest.fixture(scope="module")
def recorded(tmp_path_factory, cluster):
    """A 3-run recorded sweep's folder, kept pristine: each test works on a copy."""
    import shutil

    _, client = cluster
    tmp = tmp_path_factory.mktemp("recorded")
    sweep = tmp / "three.sweep.yaml"
    sweep.write_text(THREE_RUNS.format(scene=SCENES / "bounce.yaml"))
    execute(str(sweep), str(tmp / "out"), client=client, plots=False)

    def copy(dst: Path) -> Path:
        shutil.copytree(tmp / "out", dst)
        return dst

    return copy


def _verify(capsys, cluster, out: Path) -> tuple[int, str, list[dict]]:
    """`isaac sweep verify OUT` on the module's cluster: (exit status, stdout, verify rows)."""
    c, _ = cluster
    capsys.readouterr()
    status = main(["sweep", "verify", str(out), "--scheduler", c.scheduler_address, "--quiet"])
    return status, capsys.readouterr().out, pq.read_table(out / "verify.parquet").to_pylist()


def test_two_swapped_logs_are_each_a_wrong_log_naming_whose_log_it_is(
    recorded, cluster, capsys, tmp_path
):
    out = recorded(tmp_path / "out")
    logs = out / "logs"
    os.replace(logs / "run-000000.mcap", tmp_path / "zero.mcap")
    os.replace(logs / "run-000001.mcap", logs / "run-000000.mcap")
    os.replace(tmp_path / "zero.mcap", logs / "run-000001.mcap")
    status, text, rows = _verify(capsys, cluster, out)
    assert status == 1
    assert [r["verdict"] for r in rows] == ["wrong log", "wrong log", "identical"]
    assert "(it is run 1's log)" in rows[0]["detail"]
    assert "the replay: identical" in rows[0]["detail"]
    assert "(it is run 0's log)" in rows[1]["detail"]
    assert "run 0 (logs/run-000000.mcap): wrong log" in text
    assert "run 1 (logs/run-000001.mcap): wrong log" in text and "run 2 (" not in text


def test_a_log_replaced_by_another_runs_log_is_a_wrong_log(recorded, cluster, capsys, tmp_path):
    out = recorded(tmp_path / "out")
    logs = out / "logs"
    (logs / "run-000002.mcap").write_bytes((logs / "run-000000.mcap").read_bytes())
    status, text, rows = _verify(capsys, cluster, out)
    assert status == 1
    assert [r["verdict"] for r in rows] == ["identical", "identical", "wrong log"]
    want = pq.read_table(out / "runs.parquet").column("log_sha256").to_pylist()[2]
    assert f"the row names {want[:12]}..." in rows[2]["detail"]
    assert "(it is run 0's log)" in rows[2]["detail"]
    assert "run 2 (logs/run-000002.mcap): wrong log" in text


def test_the_replays_notes_are_kept_in_detail_and_said(recorded, cluster, capsys, tmp_path):
    """A log recorded under another Python (here: its python_version rewritten, with the
    table's sha256 updated to match) replays identical with `isaac replay`'s note."""
    sys.path.insert(0, str(ROOT / "tests" / "replay"))
    from logtools import rewrite

    out = recorded(tmp_path / "out")
    log = out / "logs" / "run-000001.mcap"

    def python(meta):
        return {**meta, "python_version": "3.0.1"}

    rewrite(log, tmp_path / "noted.mcap", metadata=python)
    os.replace(tmp_path / "noted.mcap", log)
    table = pq.read_table(out / "runs.parquet")
    shas = table.column("log_sha256").to_pylist()
    shas[1] = sha256_of(str(log))
    table = table.set_column(table.schema.get_field_index("log_sha256"), "log_sha256", [shas])
    pq.write_table(table, out / "runs.parquet")
    status, text, rows = _verify(capsys, cluster, out)
    assert status == 0
    assert [r["verdict"] for r in rows] == ["identical"] * 3
    assert rows[0]["detail"] is None and rows[2]["detail"] is None
    assert "versions or platform differ" in rows[1]["detail"]
    assert "python 3.0.1 in the log" in rows[1]["detail"]
    assert "note (1 identical log): " in text and "python 3.0.1 in the log" in text


def _tunneled(tmp_path: Path, cluster, name: str, scene: str, grid: dict) -> list[tuple]:
    """(tunneled, tunneled_bodies, contacts) of each run of a sweep of `scene` (inline YAML, or
    a path) over `grid` {key: [values]}."""
    _, client = cluster
    scene_path = tmp_path / f"{name}.yaml"
    if "\n" in scene:
        scene_path.write_text(scene)
    else:
        scene_path = Path(scene)
    keys = "".join(f"    {k}: {json.dumps(v)}\n" for k, v in grid.items())
    sweep = tmp_path / f"{name}.sweep.yaml"
    sweep.write_text(
        f"scene: {scene_path}\nruns:\n  grid:\n{keys}record: none\nmetrics: [tunneled, contacts]\n"
    )
    table = execute(str(sweep), str(tmp_path / name), client=client, plots=False).table
    return [(r["tunneled"], r["tunneled_bodies"], r["contacts"]) for r in table.to_pylist()]


def test_a_body_on_an_axle_through_a_concrete_hub_has_not_tunneled(tmp_path, cluster):
    rows = _tunneled(
        tmp_path, cluster, "rotor", ROTOR, {"bodies.blade.angular_velocity": [1.0, 3.0]}
    )
    assert rows == [(0, "", 0), (0, "", 0)]


def test_a_body_its_filter_keeps_from_a_concrete_ledge_falls_through_it_untunneled(
    tmp_path, cluster
):
    rows = _tunneled(tmp_path, cluster, "ledge", LEDGE, {"bodies.ghost.position.x": [0.0, 0.5]})
    assert rows == [(0, "", 0), (0, "", 0)]
    # the same fall through a ledge it may collide with, where no contact stops it (its
    # mask is the default): the centre crosses the ledge, as in scenes/tunnel.yaml
    thin = LEDGE.replace(", mask: 0x1", ", velocity: [0.0, -100.0]").replace(
        "[4.0, 0.2]", "[4.0, 0.02]"
    )
    rows = _tunneled(
        tmp_path, cluster, "thin", thin.replace("steps: 60", "steps: 5"), {"world.ccd": ["off"]}
    )
    assert rows[0][:2] == (1, "ghost")


def test_a_bullet_through_a_wall_still_tunnels(tmp_path, cluster):
    tunnel = str(SCENES / "tunnel.yaml")
    rows = _tunneled(tmp_path, cluster, "tunnel", tunnel, {"world.ccd": ["off", "speculative"]})
    assert rows[0] == (1, "bullet", 0)
    assert rows[1][:2] == (0, "") and rows[1][2] > 0


def test_a_bullet_through_the_place_of_a_wall_not_there_yet_has_not_tunneled(tmp_path, cluster):
    """The bullet crosses x = 0 at 0.01 s: through the wall when it is there from the start,
    through its empty place when it enters at 0.5 s (the broad phase pairs no absent body)."""
    tunnel = str(SCENES / "tunnel.yaml")
    grid = {"world.ccd": ["off"], "bodies.wall.enters_at": [0.0, 0.5]}
    rows = _tunneled(tmp_path, cluster, "late", tunnel, grid)
    assert [r[:2] for r in rows] == [(1, "bullet"), (0, "")]


@pytest.mark.parametrize("prefilter", [True, False], ids=["bounding boxes first", "every path"])
def test_paths_through_a_body_kept_apart_are_left_out_with_or_without_bounding_boxes(
    prefilter, monkeypatch
):
    """Random one-step paths against a wall and a floor (the oracle: every path clipped
    against each polygon on its own, `_crossed_concrete`), where b0 hangs from the wall by a
    joint and b1's mask leaves out the floor's category: b0 never counts for the wall, b1
    never for the floor, every other pair as before."""
    from types import SimpleNamespace

    import numpy as np

    from isaac.app.sweep import metrics
    from isaac.app.sweep.metrics import Measure
    from isaac.app.tradeoff.trajectory import _crossed_concrete
    from isaac.engine.simulation import Simulation
    from isaac.scene import load_scene_text

    movers = "".join(
        f"  - {{name: b{i}, shape: {{box: [0.1, 0.1]}}, position: [{i - 4}, 5]"
        + (", mask: 0x1" if i == 1 else "")
        + "}\n"
        for i in range(8)
    )
    scene = load_scene_text(
        "world: {steps: 1}\n"
        "bodies:\n"
        "  - {name: wall, shape: {box: [0.1, 3.0]}, position: [2.0, 1.0], angle: 0.7,"
        " concrete: true}\n"
        "  - {name: floor, shape: {polygon: [[-5, -1], [5, -1], [4, 0], [-4, 0]]},"
        " concrete: true, category: 0x2}\n" + movers + "joints:\n"
        "  - {type: distance, bodies: [wall, b0], anchor_a: [2.0, 1.0], anchor_b: [-4.0, 5.0]}\n"
    )
    monkeypatch.setattr(metrics, "PREFILTER_PATHS", 0 if prefilter else 10**9)
    m = Measure(Simulation(scene), ["tunneled"], [])
    n = len(scene.bodies)
    wall_apart = np.arange(n) == 2  # b0
    floor_apart = np.arange(n) == 3  # b1
    rng = np.random.default_rng(5)
    hits = kept_apart = 0
    for _ in range(300):
        start = rng.uniform(-6.0, 6.0, (n, 2))
        end = start + rng.uniform(-3.0, 3.0, (n, 2)) * rng.uniform(0.0, 1.0, (n, 1))
        m.tunneled[:] = False
        m.last = SimpleNamespace(position=start, exists=np.ones(n, dtype=bool))
        m._tunneling(SimpleNamespace(position=end[None], exists=np.ones((1, n), dtype=bool)))
        wall, floor = (_crossed_concrete([p], start, end) for p in m.planes)
        want = ((wall & ~wall_apart) | (floor & ~floor_apart)) & np.asarray(m.movable)
        assert (m.tunneled == want).all()
        hits += int(want.sum())
        kept_apart += int((wall & wall_apart).sum() + (floor & floor_apart).sum())
    assert hits > 100 and kept_apart > 20
    assert (m._boxes is not None) == prefilter


def test_a_table_without_the_log_columns_is_refused_in_one_line(tmp_path, capsys):
    import pyarrow as pa

    pq.write_table(pa.table({"log_path": ["logs/run-000000.mcap"]}), tmp_path / "runs.parquet")
    status = main(["sweep", "verify", str(tmp_path), "--workers", "1"])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1, err
    assert "runs.parquet" in err and "no column index, log_sha256" in err
