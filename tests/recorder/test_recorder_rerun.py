"""The Rerun recording, read back with Rerun's own reader, agrees with the MCAP log."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from rerun.chunk import RrdReader

from recorder.reader import LogReader

sys.path.insert(0, str(Path(__file__).parent))
from test_recorder_mcap import PYTHON, REPO, record_run, run_cli  # noqa: E402


def rrd_rows(path, entity, component):
    """{step: list of values} for one component of one entity, from the .rrd file."""
    out = {}
    for chunk in RrdReader(str(path)).stream():
        if chunk.entity_path != entity:
            continue
        batch = chunk.to_record_batch()
        if component not in batch.schema.names or "step" not in batch.schema.names:
            continue
        steps = batch.column("step").to_pylist()
        values = batch.column(component).to_pylist()
        for s, v in zip(steps, values):
            if v is not None:
                out[s] = v
    return out


def test_rerun_holds_as_many_contact_points_per_step_as_the_mcap_log(tmp_path):
    mcap, rrd = tmp_path / "run.mcap", tmp_path / "run.rrd"
    _, records = record_run(mcap, n=25, contacts=9, steps=230, rrd=rrd, leave_at=120)
    points = rrd_rows(rrd, "/world/contacts", "Points2D:positions")
    log_counts = {s.step: len(s.record.contacts) for s in LogReader(str(mcap)).steps()}
    assert sorted(points) == sorted(log_counts)
    assert {k: len(v) for k, v in points.items()} == log_counts
    # positions agree to float32
    r = records[17]
    np.testing.assert_allclose(np.array(points[17]), r.contacts.point, rtol=1e-6, atol=1e-5)
    impulses = rrd_rows(rrd, "/world/impulses", "Arrows2D:vectors")
    assert {k: len(v) for k, v in impulses.items()} == log_counts


def test_rerun_bodies_are_closed_outlines_and_stats_are_series(tmp_path):
    mcap, rrd = tmp_path / "run.mcap", tmp_path / "run.rrd"
    sim, records = record_run(mcap, n=12, contacts=3, steps=60, rrd=rrd, leave_at=30)
    strips = rrd_rows(rrd, "/world/bodies/moving", "LineStrips2D:strips")
    moving = ~sim.model.concrete
    assert len(strips[0]) == int(moving.sum())
    assert len(strips[40]) == int(moving.sum()) - 1  # the last body left at step 30
    first = np.array(strips[5][0])
    np.testing.assert_allclose(first[0], first[-1])  # closed
    energy = rrd_rows(rrd, "/stats/kinetic_energy", "Scalars:scalars")
    assert len(energy) == len(records)
    names = {c.entity_path for c in RrdReader(str(rrd)).stream()}
    assert {"/world", "/world/bodies/concrete", "/world/normals", "/world/push", "/info"} <= names


def test_view_converts_an_mcap_log_on_the_fly(tmp_path):
    mcap = tmp_path / "run.mcap"
    record_run(mcap, steps=20)
    out = run_cli("view", str(mcap), "--dry-run")
    assert out.returncode == 0, out.stderr
    assert "rerun" in out.stdout
    out = run_cli("view", str(mcap), "--web", "--dry-run")
    assert "--serve-web" in out.stdout and "127.0.0.1" in out.stdout


def test_mcap_to_rrd_conversion_keeps_every_step(tmp_path):
    from recorder.rerun_writer import mcap_to_rrd

    mcap = tmp_path / "run.mcap"
    _, records = record_run(mcap, steps=40)
    rrd = mcap_to_rrd(str(mcap), str(tmp_path / "conv.rrd"))
    points = rrd_rows(rrd, "/world/contacts", "Points2D:positions")
    assert {k: len(v) for k, v in points.items()} == {r.step: len(r.contacts) for r in records}


def _wait_for_the_writer(partial: Path, timeout: float = 120.0) -> None:
    """Until the writer process that outlived its run has written out the steps it was handed:
    it holds the .partial's flock until it exits (recorder/outputs.py)."""
    import fcntl

    deadline = time.time() + timeout
    with open(partial, "rb") as f:
        while True:
            try:
                fcntl.flock(f.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
                return
            except BlockingIOError:
                assert time.time() < deadline, "the writer process never let the file go"
                time.sleep(0.1)


def test_isaac_run_killed_with_sigkill_leaves_a_recoverable_log(tmp_path):
    pytest.importorskip("isaac.engine.simulation")
    out = tmp_path / "pile.mcap"
    proc = subprocess.Popen(
        [
            PYTHON,
            "-m",
            "isaac",
            "run",
            "scenes/pile.yaml",
            "--steps",
            "100000",
            "--mcap",
            str(out),
            "--quiet",
        ],
        cwd=REPO,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    partial = Path(str(out) + ".partial")
    try:
        deadline = time.time() + 240
        steps = 0
        while time.time() < deadline and steps < 250:
            time.sleep(1.0)
            if partial.exists():
                try:
                    steps = sum(1 for _ in LogReader(str(partial)).steps())
                except Exception:  # noqa: BLE001 - the header may not be written yet
                    steps = 0
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    _wait_for_the_writer(partial)
    log = LogReader(str(partial))
    got = [s.step for s in log.steps()]
    # every step up to the last flush (after steps 0, 99, 199, ...; 256 KiB chunks may add more)
    assert len(got) >= 200 and got == list(range(len(got)))
    inspect = run_cli("inspect", str(partial))
    assert inspect.returncode == 0 and "NOT closed" in inspect.stdout
    fixed = tmp_path / "fixed.mcap"
    assert run_cli("recover", str(partial), str(fixed)).returncode == 0
    assert [s.step for s in LogReader(str(fixed)).steps()] == got


def test_isaac_run_stopped_with_sigterm_finishes_both_files_and_says_where(tmp_path):
    pytest.importorskip("isaac.engine.simulation")
    mcap, rrd = tmp_path / "pile.mcap", tmp_path / "pile.rrd"
    proc = subprocess.Popen(
        [
            PYTHON,
            "-m",
            "isaac",
            "run",
            "scenes/pile.yaml",
            "--steps",
            "100000",
            "--mcap",
            str(mcap),
            "--rrd",
            str(rrd),
            "--quiet",
        ],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    partial = Path(str(mcap) + ".partial")
    try:
        deadline = time.time() + 240
        steps = 0
        while time.time() < deadline and steps < 120:
            time.sleep(0.5)
            if partial.exists():
                try:
                    steps = sum(1 for _ in LogReader(str(partial)).steps())
                except Exception:  # noqa: BLE001 - the header may not be written yet
                    steps = 0
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait()
    assert "stopped at step" in err, err
    log = LogReader(str(mcap))
    assert log.closed_cleanly and not log.complete
    got = [s.step for s in log.steps()]
    assert got == list(range(len(got))) and len(got) >= 120
    # the signal lands either between steps or inside one (whose record was never made)
    assert int(log.end["stopped_at"]) in (got[-1], got[-1] + 1), log.end
    assert rrd.exists() and not Path(str(rrd) + ".partial").exists()
    points = rrd_rows(rrd, "/world/contacts", "Points2D:positions")
    assert max(points) == got[-1]
    counts = {s.step: len(s.record.contacts) for s in log.steps()}
    assert {k: len(v) for k, v in points.items()} == counts


def test_arrow_scales_use_numpys_median_bit_for_bit():
    """The drawing scales' median (written without `np.median`, whose first call imports
    numpy.ma) is numpy's, to the bit, for odd and even counts and ties."""
    from recorder.rerun_writer import _median

    rng = np.random.default_rng(7)
    for n in (1, 2, 3, 4, 5, 10, 66, 101):
        values = rng.uniform(0.01, 50.0, n)
        assert _median(values) == float(np.median(values))
        ties = np.round(values, 1)
        assert _median(ties) == float(np.median(ties))
