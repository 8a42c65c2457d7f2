"""`isaac sweep`: a sweep file's runs over a local Dask cluster, one results table.

Claims: the table and the log bytes do not depend on the number of workers, the chunking or a
resume; the metrics agree with closed forms (free fall, tunneling through a thin wall with and
without continuous collision); random draws depend on (seed, sample, key) alone; a diverging run
is a failed row and the others complete; bad sweep files exit 2 in one line naming the file, the
line and the key. Slow cases: a worker killed mid-sweep, Ctrl-C then resume, no JIT.
"""

from __future__ import annotations

import hashlib
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from cluster_helpers import local_cluster

from isaac.app.cli import main
from isaac.app.sweep import SweepError, execute, load_sweep
from isaac.app.sweep.spec import check_runs, stream
from isaac.app.sweep.table import TIMING_COLUMNS

ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT / "scenes"
# Dask's worker processes start with this process's sys.path; under `pytest` (not `python -m
# pytest`) it holds tests/ but not the repository, and tests/recorder/ (no __init__.py) then
# shadows the recorder package in the workers of an editable install
if str(ROOT) not in sys.path:
    sys.path.append(str(ROOT))

BOUNCE_SWEEP = """\
scene: {scene}
runs:
  grid:
    bodies.box.restitution: [0.2, 0.8]
    world.dt: [0.01, 0.005]
  random:
    n: 10
    seed: 7
    bodies.box.velocity.x: {{uniform: [-5.0, 5.0]}}
    bodies.box.angle: {{normal: [0.0, 0.1]}}
steps: {steps}
record: {record}
"""


def _write(tmp_path: Path, text: str, name: str = "s.sweep.yaml") -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


@pytest.fixture(scope="module")
def cluster():
    """One local 2-worker cluster for the module (bound to 127.0.0.1, no dashboard)."""
    with local_cluster(2) as both:
        yield both


def _rows_written(rows: Path) -> int:
    """Rows the workers have written so far (one line each in rows/chunk-*.jsonl)."""
    if not rows.is_dir():
        return 0
    return sum(p.read_text().count("\n") for p in rows.glob("chunk-*.jsonl"))


def _comparable(table) -> list[dict]:
    return [{k: v for k, v in r.items() if k not in TIMING_COLUMNS} for r in table.to_pylist()]


def _log_bytes(out: str) -> dict[str, str]:
    logs = Path(out) / "logs"
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(logs.glob("run-*"))}


def test_table_and_logs_are_the_same_with_one_and_two_workers_and_any_chunking(tmp_path, cluster):
    sweep = _write(
        tmp_path, BOUNCE_SWEEP.format(scene=SCENES / "bounce.yaml", steps=40, record="mcap")
    )
    import dask

    _, client = cluster
    two = execute(str(sweep), str(tmp_path / "two"), client=client, chunk=3)
    # every task of the second sweep on one worker process
    first_worker = sorted(client.scheduler_info()["workers"])[0]
    with dask.annotate(workers=[first_worker], allow_other_workers=False):
        one = execute(str(sweep), str(tmp_path / "one"), client=client, chunk=7, plots=False)
    # the default: rounds of chunks that shrink towards the end (_round_chunks)
    guided = execute(str(sweep), str(tmp_path / "guided"), client=client, plots=False)
    assert _comparable(guided.table) == _comparable(two.table)
    assert _log_bytes(guided.out) == _log_bytes(two.out)
    assert two.table.num_rows == one.table.num_rows == 40
    assert two.table.column("index").to_pylist() == list(range(40))
    assert _comparable(two.table) == _comparable(one.table)
    assert set(one.table.column("worker").to_pylist()) == {first_worker}
    assert len(set(two.table.column("worker").to_pylist())) == 2
    assert all(s == "ok" for s in two.table.column("status").to_pylist())
    logs = _log_bytes(two.out)
    assert len(logs) == 40 and logs == _log_bytes(one.out)
    # the table's sha256 is the file's
    for row in two.table.to_pylist():
        assert logs[os.path.basename(row["log_path"])] == row["log_sha256"]
    # the same table read back from runs.parquet
    assert _comparable(pq.read_table(Path(two.out) / "runs.parquet")) == _comparable(two.table)
    # 4 grid points x 10 samples: sample i has the same drawn values at every grid point
    rows = two.table.to_pylist()
    for i in range(10):
        xs = {rows[g * 10 + i]["bodies.box.velocity.x"] for g in range(4)}
        assert len(xs) == 1
    assert len({r["bodies.box.velocity.x"] for r in rows}) == 10
    # a histogram of each varying metric and each against each parameter
    names = {Path(p).name for p in two.plots}
    assert "hist-final_com_x.png" in names and "hist-energy_drift.png" in names
    assert "final_com_x-vs-bodies.box.velocity.x.png" in names
    assert "hist-tunneled.png" not in names  # 0 in every run: no plot of a constant


@pytest.mark.parametrize(
    "key, label",
    [
        ("bodies.box.velocity.x", "bodies.box.velocity.x (m/s)"),
        ("bodies.velocity.restitution", "bodies.velocity.restitution"),  # a body's name
        ("world.dt", "world.dt (s)"),
        ("generators.0.pile.container.width", "generators.0.pile.container.width (m)"),
        ("generators.0.pile.seed", "generators.0.pile.seed"),
        ("bodies.box.angle", "bodies.box.angle (rad)"),
    ],
)
def test_a_plotted_parameter_is_labelled_with_its_unit(key, label):
    from isaac.app.sweep.plots import param_label

    assert param_label(key) == label


@pytest.mark.parametrize(
    "runs, workers, least",
    [(1000, 2, 20), (1000, 1, 20), (100, 2, 1), (5, 4, 1), (3, 2, 1), (1, 2, 20), (997, 3, 20)],
)
def test_chunks_come_in_rounds_of_one_equal_chunk_per_worker_and_end_evenly(runs, workers, least):
    from isaac.app.sweep.command import MAX_CHUNK, TASKS_PER_WORKER, _round_chunks

    todo = list(range(3, 3 + runs))
    chunks = _round_chunks(todo, workers, least)
    assert chunks == _round_chunks(list(todo), workers, least)  # a function of its inputs
    assert [i for c in chunks for i in c] == todo  # every run once, in order
    sizes = [len(c) for c in chunks]
    assert min(sizes) >= 1 and max(sizes) <= MAX_CHUNK
    # the last round: the runs left split evenly over the workers (no lone tail chunk)
    last = min(workers, runs)
    tail, rounds = sizes[-last:], sizes[:-last]
    assert max(tail) - min(tail) <= 1
    # before it, whole rounds of equal chunks, shrinking, each the runs left over
    # TASKS_PER_WORKER x workers (over the least: else it would have been the last round)
    assert len(rounds) % workers == 0
    left = runs
    previous = MAX_CHUNK
    for k in range(0, len(rounds), workers):
        size = rounds[k]
        assert rounds[k : k + workers] == [size] * workers
        assert least < size == min(MAX_CHUNK, -(-left // (TASKS_PER_WORKER * workers)))
        assert size <= previous
        previous = size
        left -= size * workers
    assert sum(tail) == left
    assert min(MAX_CHUNK, -(-left // (TASKS_PER_WORKER * workers))) <= least


def test_resume_keeps_complete_runs_and_redoes_the_others(tmp_path, cluster):
    _, client = cluster
    sweep = _write(
        tmp_path, BOUNCE_SWEEP.format(scene=SCENES / "bounce.yaml", steps=20, record="mcap")
    )
    out = tmp_path / "out"
    first = execute(str(sweep), str(out), client=client, plots=False)
    logs = _log_bytes(str(out))
    # a lost log, a truncated one and a log of the right size but other bytes
    (out / "logs" / "run-000003.mcap").unlink()
    cut = out / "logs" / "run-000017.mcap"
    cut.write_bytes(cut.read_bytes()[:1000])
    other = out / "logs" / "run-000030.mcap"
    data = bytearray(other.read_bytes())
    data[-20] ^= 1
    other.write_bytes(bytes(data))
    again = execute(str(sweep), str(out), client=client, plots=False)
    assert again.kept == 37 and again.ran == 3
    assert _comparable(again.table) == _comparable(first.table)
    assert _log_bytes(str(out)) == logs
    # nothing left to do: every row kept
    third = execute(str(sweep), str(out), client=client, plots=False)
    assert third.kept == 40 and third.ran == 0


def test_resume_refuses_a_folder_of_another_sweep(tmp_path, cluster, capsys):
    _, client = cluster
    sweep = _write(
        tmp_path, BOUNCE_SWEEP.format(scene=SCENES / "bounce.yaml", steps=5, record="none")
    )
    out = tmp_path / "out"
    execute(str(sweep), str(out), client=client, plots=False)
    sweep.write_text(sweep.read_text().replace("seed: 7", "seed: 8"))
    status = main(["sweep", str(sweep), "--out", str(out)])
    err = capsys.readouterr().err
    assert status == 2 and "holds a sweep of another sweep file" in err


def _free_fall_y(y0: float, v0: float, g: float, dt: float, k: int) -> float:
    """Semi-implicit Euler after k steps: v_j = v0 + j g dt, y_k = y0 + dt sum_{j=1..k} v_j."""
    return y0 + k * dt * v0 + g * dt * dt * k * (k + 1) / 2


def test_final_state_and_energy_of_a_free_fall_match_the_closed_form(tmp_path, cluster):
    _, client = cluster
    _write(
        tmp_path,
        """\
        world: {gravity: [0.0, -9.81], dt: 0.01, steps: 50, fidelity: balanced}
        bodies:
          - name: ball
            shape: {box: [0.5, 0.5]}
            position: [0.0, 100.0]
        """,
        "fall.yaml",
    )
    sweep = _write(
        tmp_path,
        """\
        scene: fall.yaml
        runs:
          grid:
            bodies.ball.velocity.y: [0.0, 3.0, -2.5]
            world.dt: [0.01, 0.02]
        record: none
        """,
    )
    table = execute(str(sweep), str(tmp_path / "out"), client=client, plots=False).table
    for row in table.to_pylist():
        v0, dt = row["bodies.ball.velocity.y"], row["world.dt"]
        y = _free_fall_y(100.0, v0, -9.81, dt, 50)
        assert row["final.ball.y"] == pytest.approx(y, rel=1e-12)
        assert row["final.ball.vy"] == pytest.approx(v0 - 9.81 * dt * 50, rel=1e-12, abs=1e-12)
        assert row["final_com_y"] == row["final.ball.y"]
        mass = 0.25  # box 0.5 x 0.5 at density 1
        e0 = 0.5 * mass * v0 * v0 + mass * 9.81 * 100.0
        vy = v0 - 9.81 * dt * 50
        e1 = 0.5 * mass * vy * vy + mass * 9.81 * y
        assert row["energy_change"] == pytest.approx(e1 - e0, rel=1e-9, abs=1e-12)
        assert row["energy_drift"] == pytest.approx((e1 - e0) / e0, rel=1e-9, abs=1e-15)
        assert row["contacts"] == 0 and row["max_depth"] == 0.0 and row["tunneled"] == 0
        assert row["final_step"] == 50 and row["status"] == "ok"


def test_tunneling_is_counted_without_ccd_and_not_with_it(tmp_path, cluster):
    _, client = cluster
    sweep = _write(
        tmp_path,
        f"""\
        scene: {SCENES / "tunnel.yaml"}
        runs:
          grid:
            world.ccd: ["off", speculative]
        record: none
        metrics: [tunneled, contacts, max_depth]
        """,
    )
    rows = execute(str(sweep), str(tmp_path / "out"), client=client, plots=False).table.to_pylist()
    by_ccd = {r["world.ccd"]: r for r in rows}
    assert by_ccd["off"]["tunneled"] == 1 and by_ccd["off"]["tunneled_bodies"] == "bullet"
    assert by_ccd["off"]["contacts"] == 0
    assert by_ccd["speculative"]["tunneled"] == 0 and by_ccd["speculative"]["contacts"] > 0


@pytest.mark.parametrize("prefilter", [True, False], ids=["bounding boxes first", "every path"])
def test_the_tunneling_metric_clips_only_paths_near_a_concrete_body_and_agrees_with_all(
    prefilter, monkeypatch
):
    from types import SimpleNamespace

    from isaac.app.sweep import metrics
    from isaac.app.sweep.metrics import Measure
    from isaac.app.tradeoff.trajectory import _crossed_concrete
    from isaac.engine.simulation import Simulation
    from isaac.scene import load_scene_text

    movers = "".join(
        f"  - {{name: b{i}, shape: {{box: [0.1, 0.1]}}, position: [{i - 4}, 5]}}\n"
        for i in range(8)
    )
    scene = load_scene_text(
        "world: {steps: 1}\n"
        "bodies:\n"
        "  - {name: wall, shape: {box: [0.1, 3.0]}, position: [2.0, 1.0], angle: 0.7,"
        " concrete: true}\n"
        "  - {name: floor, shape: {polygon: [[-5, -1], [5, -1], [4, 0], [-4, 0]]},"
        " concrete: true}\n" + movers
    )
    monkeypatch.setattr(metrics, "PREFILTER_PATHS", 0 if prefilter else 10**9)
    m = Measure(Simulation(scene), ["tunneled"], [])
    rng = np.random.default_rng(5)
    n = len(scene.bodies)
    hits = misses = 0
    for _ in range(300):
        # one step of paths of every length and place: through, into, past or far from the two
        start = rng.uniform(-6.0, 6.0, (n, 2))
        end = start + rng.uniform(-3.0, 3.0, (n, 2)) * rng.uniform(0.0, 1.0, (n, 1))
        m.tunneled[:] = False
        m.last = SimpleNamespace(position=start, exists=np.ones(n, dtype=bool))
        m._tunneling(SimpleNamespace(position=end[None], exists=np.ones((1, n), dtype=bool)))
        want = _crossed_concrete(m.planes, start, end) & np.asarray(m.movable)
        assert (m.tunneled == want).all()
        hits += int(want.sum())
        misses += int((~want & np.asarray(m.movable)).sum())
    assert hits > 100 and misses > 100
    assert (m._boxes is not None) == prefilter


def test_a_diverging_run_is_a_failed_row_and_the_others_complete(tmp_path, cluster, capsys):
    _, client = cluster
    scene = _write(
        tmp_path,
        """\
        world: {gravity: [0.0, -10000.0], dt: 0.01, steps: 15000}
        bodies:
          - name: anvil
            shape: {box: [1.0, 1.0]}
        """,
        "absurd.yaml",
    )
    del scene
    sweep = _write(
        tmp_path,
        """\
        scene: absurd.yaml
        runs:
          grid:
            world.dt: [0.001, 1.0, 0.002]
        record: none
        """,
    )
    out = tmp_path / "out"
    # closed form of the first step past 1e12 m at dt = 1 s (isaac.engine.integrate)
    y, v, k = 0.0, 0.0, 0
    while abs(y) <= 1e12:
        k, v = k + 1, v - 10000.0
        y += v
    os.environ["DASK_SCHEDULER_ADDRESS"] = client.scheduler.address
    try:
        status = main(["sweep", str(sweep), "--out", str(out), "--quiet", "--no-plots"])
    finally:
        del os.environ["DASK_SCHEDULER_ADDRESS"]
    printed = capsys.readouterr().out
    assert status == 1
    rows = pq.read_table(out / "runs.parquet").to_pylist()
    assert [r["status"] for r in rows] == ["ok", "failed", "ok"]
    assert f"step {k}" in rows[1]["error"] and "'anvil'" in rows[1]["error"]
    assert rows[1]["final_step"] == k - 1  # the last good state
    assert f"failed: run 1: step {k}" in printed


def test_the_base_scenes_warnings_are_said_once_for_the_sweeps_steps(tmp_path, cluster, capsys):
    _, client = cluster
    _write(
        tmp_path,
        """\
        world: {steps: 100, dt: 0.01}
        bodies:
          - {name: ground, shape: {box: [10, 1]}, position: [0, -0.5], concrete: true}
          - {name: box, shape: {box: [1, 1]}, position: [0, 0.5], friction: 0.9}
          - {name: late, shape: {box: [1, 1]}, position: [-3, 3], enters_at: 0.5}
        """,
        "traps.yaml",
    )
    sweep = _write(
        tmp_path,
        """\
        scene: traps.yaml
        runs:
          grid:
            bodies.box.restitution: [0.1, 0.2, 0.3]
        steps: 10
        record: none
        """,
    )
    os.environ["DASK_SCHEDULER_ADDRESS"] = client.scheduler.address
    try:
        status = main(["sweep", str(sweep), "--out", str(tmp_path / "out"), "--no-plots"])
    finally:
        del os.environ["DASK_SCHEDULER_ADDRESS"]
    assert status == 0
    said = [line for line in capsys.readouterr().err.splitlines() if "warning:" in line]
    scene = tmp_path / "traps.yaml"
    # once for the sweep, not once per run; 'late' enters at 0.5 s, after the sweep's 10 steps
    # of 0.01 s (the scene's own 100 steps would let it in)
    assert len(said) == 2, said
    assert said[0].startswith(f"isaac sweep: warning: {scene}:4: bodies[1].friction: ")
    assert said[1].startswith(f"isaac sweep: warning: {scene}:5: bodies[2]: ")
    assert "'late'" in said[1] and "never exists" in said[1]


BAD = [
    ("unknown key path", "bodies.box.restitutio: [0.5]", 4, "runs.grid.bodies.box.restitutio"),
    ("no such body", "bodies.crate.restitution: [0.5]", 4, "runs.grid.bodies.crate.restitution"),
    ("made by nothing", "planets.0.mass: [1.0]", 4, "runs.grid.planets.0.mass"),
    (
        "out of range",
        "bodies.box.restitution:\n      - 0.5\n      - 1.5",
        6,
        "runs.grid.bodies.box.restitution",
    ),
    ("list index", "bodies.box.position.z: [1.0]", 4, "runs.grid.bodies.box.position.z"),
]


@pytest.mark.parametrize("what, grid, line, key", BAD, ids=[b[0] for b in BAD])
def test_bad_grid_exits_2_naming_file_line_and_key(tmp_path, capsys, what, grid, line, key):
    sweep = _write(
        tmp_path,
        f"scene: {SCENES / 'bounce.yaml'}\nruns:\n  grid:\n    {grid}\nrecord: none\n",
    )
    status = main(["sweep", str(sweep), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert status == 2
    assert err.count("\n") == 1 and "Traceback" not in err
    assert f"{sweep}:{line}: {key}:" in err, err
    if what == "unknown key path":  # the key's fault, not a value's
        assert "no such key in a scene: unknown key 'restitutio'" in err, err
        assert "did you mean 'restitution'" in err and "value" not in err, err
    assert not (tmp_path / "out").exists()  # refused before anything was written


def test_out_of_range_value_names_the_run_and_the_scene_rule(tmp_path, capsys):
    sweep = _write(
        tmp_path,
        f"""\
        scene: {SCENES / "bounce.yaml"}
        runs:
          random:
            n: 200
            seed: 3
            bodies.box.restitution: {{uniform: [0.5, 1.2]}}
        """,
    )
    status = main(["sweep", str(sweep)])
    err = capsys.readouterr().err
    assert status == 2
    assert f"{sweep}:6: runs.random.bodies.box.restitution: run " in err
    assert "is out of range (must be >= 0.0 and <= 1.0)" in err
    assert "(scene bodies[1].restitution)" in err
    # the run it names is the first whose draw is above 1 (recomputed from the stream)
    first = next(
        i for i in range(200) if stream(3, i, "bodies.box.restitution").uniform(0.5, 1.2) > 1.0
    )
    assert f": run {first}: drawn value" in err


def test_a_refusal_found_on_the_cluster_is_the_same_and_comes_before_anything(tmp_path, cluster):
    # run 40 is past the runs checked in this process (PRE_CHECK): the cluster finds it
    from isaac.app.sweep.command import PRE_CHECK
    from isaac.app.sweep.spec import SweepError

    _, client = cluster
    values = [round(0.01 * i, 2) for i in range(60)]
    values[40], values[50] = 1.5, 2.5
    assert PRE_CHECK <= 40
    sweep = _write(
        tmp_path,
        f"scene: {SCENES / 'bounce.yaml'}\nruns:\n  grid:\n"
        f"    bodies.box.restitution: {values}\nrecord: none\n",
    )
    with pytest.raises(SweepError) as refused:
        execute(str(sweep), str(tmp_path / "out"), client=client)
    said = str(refused.value)
    assert said.startswith(f"{sweep}:4: runs.grid.bodies.box.restitution: run 40: value 1.5 ")
    assert "is out of range (must be >= 0.0 and <= 1.0) (scene bodies[1].restitution)" in said
    assert not (tmp_path / "out").exists()  # nothing ran or was written


def test_an_output_folder_that_cannot_be_made_is_said_in_one_line_and_nothing_runs(
    tmp_path, cluster
):
    # OUT is made on the cluster, by the task between the check and the runs: its error comes
    # back as the sweep's own (exit 2), and no run starts
    from isaac.app.sweep.spec import SweepError

    _, client = cluster
    sweep = _write(
        tmp_path,
        f"scene: {SCENES / 'bounce.yaml'}\nruns:\n  grid:\n"
        "    bodies.box.restitution: [0.2, 0.4]\nrecord: none\n",
    )
    (tmp_path / "file").write_text("not a folder")
    out = tmp_path / "file" / "out"
    with pytest.raises(SweepError) as refused:
        execute(str(sweep), str(out), client=client)
    assert str(refused.value).startswith(f"{sweep}: cannot write --out {out}: ")
    assert (tmp_path / "file").read_text() == "not a folder"


RANDOM_BAD = [
    (
        "bad distribution",
        "bodies.box.restitution: {gauss: [0, 1]}",
        6,
        "runs.random.bodies.box.restitution.gauss",
        30,
    ),
    ("n = 0", None, 5, "runs.random.n", 0),
    (
        "low above high",
        "bodies.box.restitution: {uniform: [0.9, 0.1]}",
        6,
        "runs.random.bodies.box.restitution.uniform",
        30,
    ),
]


@pytest.mark.parametrize("what, dist, line, key, n", RANDOM_BAD, ids=[b[0] for b in RANDOM_BAD])
def test_bad_random_exits_2_naming_file_line_and_key(tmp_path, capsys, what, dist, line, key, n):
    dist = dist or "bodies.box.restitution: {uniform: [0.1, 0.9]}"
    sweep = _write(
        tmp_path,
        f"scene: {SCENES / 'bounce.yaml'}\nruns:\n  random:\n    seed: 1\n    n: {n}\n    {dist}\n",
    )
    # lines: scene 1, runs 2, random 3, seed 4, n 5, the key and its distribution 6
    status = main(["sweep", str(sweep)])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1
    assert f"{sweep}:{line}: {key}" in err, err


def test_a_missing_scene_file_exits_2_naming_the_sweep_line(tmp_path, capsys):
    sweep = _write(tmp_path, "runs:\n  grid:\n    world.dt: [0.01]\nscene: nowhere.yaml\n")
    status = main(["sweep", str(sweep)])
    err = capsys.readouterr().err
    assert status == 2 and f"{sweep}:4: scene: no such file" in err, err


def test_a_remote_scheduler_needs_an_absolute_output_folder(tmp_path, capsys):
    sweep = _write(
        tmp_path, f"scene: {SCENES / 'bounce.yaml'}\nruns:\n  grid:\n    world.dt: [0.01]\n"
    )
    status = main(["sweep", str(sweep), "--out", "rel/out", "--scheduler", "tcp://127.0.0.1:1"])
    err = capsys.readouterr().err
    assert status == 2 and "absolute path" in err


def test_a_client_of_a_scheduler_reached_by_address_needs_an_absolute_output_folder(
    tmp_path, cluster, monkeypatch
):
    """Through the Python API too: a client made from the address (as for a remote scheduler)
    is refused a relative `out`; a client of a LocalCluster made here is not."""
    from dask.distributed import Client

    c, local = cluster
    sweep = _write(
        tmp_path, BOUNCE_SWEEP.format(scene=SCENES / "bounce.yaml", steps=5, record="none")
    )
    monkeypatch.chdir(tmp_path)
    with Client(c.scheduler_address) as by_address:
        with pytest.raises(SweepError, match="absolute path"):
            execute(str(sweep), "rel/out", client=by_address, plots=False)
    assert not (tmp_path / "rel").exists()
    result = execute(str(sweep), "rel/here", client=local, plots=False)
    assert result.table.num_rows == 40 and result.out == str(tmp_path / "rel" / "here")


def test_a_slow_start_of_the_runs_is_said_once(tmp_path, cluster, monkeypatch):
    """A first sweep compiles the kernels before any run starts: `note` says what the wait
    is (here any start is slow: the limit is 0 s)."""
    from isaac.app.sweep import cluster as clusters

    _, client = cluster
    monkeypatch.setattr(clusters, "SLOW_START_S", 0.0)
    sweep = _write(
        tmp_path, BOUNCE_SWEEP.format(scene=SCENES / "bounce.yaml", steps=5, record="none")
    )
    notes: list[str] = []
    execute(str(sweep), str(tmp_path / "out"), client=client, plots=False, note=notes.append)
    assert len(notes) == 1 and "compiles the engine's kernels" in notes[0]


def test_an_ignored_ctrl_c_stays_ignored_while_the_cluster_starts():
    """A sweep started with SIGINT ignored (a shell script's background job) ignores it
    throughout, the cluster's start included, instead of stopping only then."""
    from isaac.app.sweep.cluster import _interrupt_held

    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with _interrupt_held() as caught:
            assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
            os.kill(os.getpid(), signal.SIGINT)
        assert caught == []
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, previous)


def test_random_draws_depend_on_seed_sample_and_key_alone(tmp_path):
    text = """\
        scene: {scene}
        runs:
          random:
            n: 5
            seed: 11
            {a}
            {b}
        record: none
        """
    a = "bodies.box.velocity.x: {uniform: [-5.0, 5.0]}"
    b = "bodies.box.restitution: {integers: [0, 1]}"
    s1 = load_sweep(_write(tmp_path, text.format(scene=SCENES / "bounce.yaml", a=a, b=b), "1.yaml"))
    s2 = load_sweep(_write(tmp_path, text.format(scene=SCENES / "bounce.yaml", a=b, b=a), "2.yaml"))
    for i in range(5):
        assert s1.params(i) == s2.params(i)
        rng = np.random.Generator(
            np.random.PCG64(
                np.random.SeedSequence(
                    [
                        11,
                        i,
                        *np.frombuffer(
                            hashlib.sha256(b"bodies.box.velocity.x").digest()[:16], "<u4"
                        ).tolist(),
                    ]
                )
            )
        )
        assert s1.params(i)["bodies.box.velocity.x"] == rng.uniform(-5.0, 5.0)
    # every run's scene loads, and holds the drawn value
    check_runs(s1)
    from isaac.scene import load_scene_text

    run3 = load_scene_text(s1.run_scene_text(3))
    assert run3.bodies[1].velocity == (s1.params(3)["bodies.box.velocity.x"], 0.0)


@pytest.mark.slow
def test_no_jit_sweep_runs_and_records(tmp_path):
    sweep = _write(
        tmp_path,
        f"""\
        scene: {SCENES / "bounce.yaml"}
        runs:
          grid:
            bodies.box.restitution: [0.3, 0.6]
        steps: 5
        record: mcap
        """,
    )
    env = dict(os.environ, NUMBA_DISABLE_JIT="1")
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "isaac",
            "sweep",
            str(sweep),
            "--out",
            str(tmp_path / "o"),
            "--workers",
            "1",
        ],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr
    rows = pq.read_table(tmp_path / "o" / "runs.parquet").to_pylist()
    assert [r["status"] for r in rows] == ["ok", "ok"]
    assert all((tmp_path / "o" / r["log_path"]).stat().st_size > 0 for r in rows)


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def _children(pid: int) -> list[int]:
    out = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                stat = Path(f"/proc/{entry}/stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                out.append(int(entry))
    return out


@pytest.mark.slow
def test_ctrl_c_stops_cleanly_and_the_same_command_resumes(tmp_path, cluster):
    # runs long enough (1,500 steps, recorded) that the 40 cannot all finish between the third
    # row seen here (polled every 0.2 s) and the interrupt
    sweep = _write(
        tmp_path, BOUNCE_SWEEP.format(scene=SCENES / "bounce.yaml", steps=1500, record="mcap")
    )
    out = tmp_path / "out"
    cmd = [
        sys.executable,
        "-m",
        "isaac",
        "sweep",
        str(sweep),
        "--out",
        str(out),
        "--workers",
        "2",
        "--chunk",
        "1",
    ]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    rows = out / "rows"
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and _rows_written(rows) < 3:
        time.sleep(0.2)
    workers = _children(proc.pid)
    assert workers
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "run the same command again to resume" in err
    # the workers and multiprocessing's resource tracker end with the sweep (the tracker a
    # moment after: it waits for its pipe to close)
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline and [p for p in workers if _alive(p)]:
        time.sleep(0.2)
    assert [p for p in workers if _alive(p)] == []
    # every log under its final name is a finished run's (its row names its sha256)
    table = pq.read_table(out / "runs.parquet").to_pylist()
    assert 3 <= len(table) < 40
    finals = {p.name for p in (out / "logs").glob("run-*.mcap")}
    named = {os.path.basename(r["log_path"]) for r in table}
    assert finals <= named | {p.name for p in (out / "logs").glob("*.partial")}
    resumed = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert resumed.returncode == 0, resumed.stderr
    _, client = cluster
    whole = execute(str(sweep), str(tmp_path / "whole"), client=client, plots=False)
    assert _comparable(pq.read_table(out / "runs.parquet")) == _comparable(whole.table)
    assert _log_bytes(str(out)) == _log_bytes(whole.out)


@pytest.mark.slow
def test_a_killed_worker_costs_only_its_run(tmp_path, cluster):
    c, client = cluster
    # runs of 6,000 steps: a chunk of 10 takes about half a second, so the kill lands inside one
    sweep = _write(
        tmp_path, BOUNCE_SWEEP.format(scene=SCENES / "bounce.yaml", steps=6000, record="mcap")
    )
    out = tmp_path / "out"
    import threading

    result = {}
    thread = threading.Thread(
        target=lambda: result.update(
            r=execute(str(sweep), str(out), client=client, chunk=10, plots=False)
        )
    )
    thread.start()
    rows = out / "rows"
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and _rows_written(rows) < 2:
        time.sleep(0.02)
    pids = client.run(os.getpid)
    busy = {w: keys for w, keys in client.processing().items() if keys}
    victim = sorted(busy)[0]
    killed_tasks = list(busy[victim])
    os.kill(pids[victim], signal.SIGKILL)
    thread.join(timeout=600)
    # the victim was running a chunk when it died, and the scheduler ran that chunk again
    for key in killed_tasks:
        sent = client.run_on_scheduler(
            lambda dask_scheduler, key=key: len(
                [t for t in dask_scheduler.story(key) if t[2] == "processing"]
            )
        )
        assert sent >= 2, (key, sent)
    table = result["r"].table
    assert table.column("index").to_pylist() == list(range(40))
    assert all(s == "ok" for s in table.column("status").to_pylist())
    whole = execute(str(sweep), str(tmp_path / "whole"), client=client, plots=False)
    assert _comparable(table) == _comparable(whole.table)
    assert _log_bytes(str(out)) == _log_bytes(whole.out)
    assert not list((out / "logs").glob("*.partial"))


def test_verify_replays_every_log_and_names_the_run_and_step_of_a_one_ulp_edit(tmp_path, cluster):
    sys.path.insert(0, str(ROOT / "tests" / "replay"))
    from logtools import bodies_with, rewrite

    from isaac.app.sweep.verify import verify

    _, client = cluster
    sweep = _write(
        tmp_path,
        f"""\
        scene: {SCENES / "bounce.yaml"}
        runs:
          grid:
            bodies.box.velocity.x: [0.0, 0.5, 1.0, 1.5]
        steps: 20
        """,
    )
    out = tmp_path / "out"
    execute(str(sweep), str(out), client=client, plots=False)
    clean = verify(str(out), client=client).to_pylist()
    assert [r["verdict"] for r in clean] == ["identical"] * 4
    assert all(r["steps_compared"] > 0 for r in clean)

    def one_ulp(topic, step, data):
        if topic != "/bodies" or step != 12:
            return data

        def change(a):
            a["position"][3] = np.nextafter(a["position"][3], np.inf)  # box's y

        return bodies_with(data, change)

    log = out / "logs" / "run-000002.mcap"
    rewrite(log, tmp_path / "edited.mcap", message=one_ulp)
    os.replace(tmp_path / "edited.mcap", log)
    rows = verify(str(out), client=client).to_pylist()
    # not the file its row names (sha256), and replayed all the same
    assert [r["verdict"] for r in rows] == ["identical", "identical", "wrong log", "identical"]
    assert "the replay: diverged" in rows[2]["detail"] and rows[2]["first_divergent_step"] == 12
    # an edit the table was made to agree with: the replay alone finds it
    table = pq.read_table(out / "runs.parquet")
    shas = table.column("log_sha256").to_pylist()
    shas[2] = hashlib.sha256(log.read_bytes()).hexdigest()
    table = table.set_column(table.schema.get_field_index("log_sha256"), "log_sha256", [shas])
    pq.write_table(table, out / "runs.parquet")
    rows = verify(str(out), client=client).to_pylist()
    assert [r["verdict"] for r in rows] == ["identical", "identical", "diverged", "identical"]
    bad = rows[2]
    assert bad["first_divergent_step"] == 12 and bad["ulps"] == 1
    assert "'box'" in bad["where"] and bad["field"].startswith("position")
    assert pq.read_table(out / "verify.parquet").to_pylist() == rows


def test_verify_replays_one_log_alone_before_the_others_and_says_a_slow_start(
    tmp_path, cluster, monkeypatch
):
    """On a cold numba cache one worker compiles the replay's kernels (the first log, alone)
    and the others load them; a slow first replay is said (here any: the limit is 0 s)."""
    from dask.distributed import get_task_stream

    from isaac.app.sweep import cluster as clusters
    from isaac.app.sweep.verify import verify

    _, client = cluster
    sweep = _write(
        tmp_path, BOUNCE_SWEEP.format(scene=SCENES / "bounce.yaml", steps=10, record="mcap")
    )
    out = tmp_path / "out"
    execute(str(sweep), str(out), client=client, plots=False)
    monkeypatch.setattr(clusters, "SLOW_START_S", 0.0)
    notes: list[str] = []
    with get_task_stream(client) as stream:
        rows = verify(str(out), client=client, note=notes.append).to_pylist()
    assert [r["index"] for r in rows] == list(range(40))
    assert all(r["verdict"] == "identical" for r in rows)
    assert len(notes) == 1 and "replaying the first log" in notes[0]
    tasks = [t for t in stream.data if t["key"].startswith("verify_chunk")]
    starts = sorted(
        (min(s["start"] for s in t["startstops"]), max(s["stop"] for s in t["startstops"]))
        for t in tasks
    )
    lead, others = starts[0], starts[1:]
    assert len(others) >= 2 and all(start >= lead[1] for start, _ in others)


def test_a_generator_option_is_swept_by_index_and_equal_seeds_give_equal_runs(tmp_path, cluster):
    _, client = cluster
    _write(
        tmp_path,
        """\
        world: {dt: 0.01, steps: 10}
        generators:
          - pile: {count: 6, seed: 1, container: {width: 4.0}}
        """,
        "pile.yaml",
    )
    sweep = _write(
        tmp_path,
        """\
        scene: pile.yaml
        runs:
          random:
            n: 8
            seed: 2
            generators.0.pile.seed: {integers: [10, 12]}
        record: none
        metrics: [final_state]
        """,
    )
    rows = execute(str(sweep), str(tmp_path / "out"), client=client, plots=False).table.to_pylist()
    seeds = [r["generators.0.pile.seed"] for r in rows]
    assert set(seeds) <= {10, 11, 12} and len(set(seeds)) > 1
    for a in rows:
        for b in rows:
            same = a["generators.0.pile.seed"] == b["generators.0.pile.seed"]
            assert (a["final_state_hash"] == b["final_state_hash"]) == same
    # 6 moving polygons (at most 8: each gets final-state columns), the concrete container none
    bodies = {k.split(".")[1] for k in rows[0] if k.startswith("final.")}
    assert bodies == {f"pile/{i}" for i in range(1, 7)}


def test_a_chunk_stopped_before_its_logs_were_moved_into_place_keeps_its_runs_on_resume(tmp_path):
    # a chunk's logs are closed without an fsync and moved to their final names only after one
    # sync at the chunk's end (worker.publish_logs); a chunk stopped before that (worker
    # killed, Ctrl-C) left its rows and its finished logs in logs/.tmp: they are kept
    import json

    from isaac.app.sweep import table as results
    from isaac.app.sweep import worker as work
    from isaac.app.sweep.command import _tasks

    path = _write(
        tmp_path, BOUNCE_SWEEP.format(scene=SCENES / "bounce.yaml", steps=20, record="mcap")
    )
    sweep = load_sweep(str(path))
    out = str(tmp_path / "o")
    work.prepare_out(sweep, out)
    task = _tasks(sweep, [[0, 1, 2]], out)[0]
    moves: list = []
    rows = [work.run_one(task, sweep, i, moves=moves) for i in task["runs"]]
    Path(work.rows_path(out, 0)).write_text("".join(json.dumps(r) + "\n" for r in rows))
    assert [r["log_path"] for r in rows] == [f"logs/run-00000{i}.mcap" for i in range(3)]
    assert len(moves) == 3 and not any(os.path.exists(final) for _, final in moves)
    kept = results.kept_rows(out, sweep.n_runs, results.schema(sweep))
    assert sorted(kept) == [0, 1, 2]
    for r in rows:
        final = Path(out) / r["log_path"]
        assert hashlib.sha256(final.read_bytes()).hexdigest() == r["log_sha256"]
    assert not any(os.path.exists(tmp) for tmp, _ in moves)
    # a chunk that runs to its end moves its logs itself: the same bytes as run one by one
    done = work.run_chunk(_tasks(sweep, [[3, 4]], out)[0], sweep)
    alone = str(tmp_path / "alone")
    work.prepare_out(sweep, alone)
    for r in done:
        assert r["status"] == "ok"
        again = work.run_one(_tasks(sweep, [[r["index"]]], alone)[0], sweep, r["index"])
        assert again["log_sha256"] == r["log_sha256"]
        final = Path(out) / r["log_path"]
        assert hashlib.sha256(final.read_bytes()).hexdigest() == r["log_sha256"]
    assert sorted(os.listdir(Path(out) / "logs" / ".tmp")) == []


@pytest.mark.slow
def test_ctrl_c_while_the_local_cluster_starts_stops_cleanly_without_a_traceback(tmp_path):
    # Ctrl-C reaches every process of the terminal's group: here once the workers have started
    # and before they are told to leave it to the client (the plugin), the moment a traceback
    # came from (the workers', and the client's, which left the cluster running)
    sweep = _write(
        tmp_path, BOUNCE_SWEEP.format(scene=SCENES / "bounce.yaml", steps=20, record="none")
    )
    code = textwrap.dedent(
        f"""\
        import os, signal, sys, time
        sys.argv[0] = "/usr/bin/isaac"
        from isaac.app.cli import main
        import distributed

        register = distributed.Client.register_plugin

        def interrupted(self, *args, **kwargs):
            os.killpg(os.getpgrp(), signal.SIGINT)
            time.sleep(2.0)  # the workers and this process have had it
            return register(self, *args, **kwargs)

        distributed.Client.register_plugin = interrupted
        sys.exit(main(["sweep", {str(sweep)!r}, "--out", {str(tmp_path / "o")!r},
                       "--workers", "2", "--quiet", "--no-plots"]))
        """
    )
    proc = subprocess.run(
        [sys.executable, "-c", code],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
        start_new_session=True,  # its own process group: the signal stays in it
    )
    assert proc.returncode == 130, proc.stderr
    assert "Traceback" not in proc.stderr, proc.stderr
    assert proc.stderr.strip().splitlines()[-1].startswith("isaac sweep: interrupted")
    assert not (tmp_path / "o" / "runs.parquet").exists()
