"""What `make bench` writes under bench/results/: every results file names the CPU model, the
commit and the date it was measured on (no timing is run here)."""

from __future__ import annotations

import datetime as dt
import json
import subprocess
from pathlib import Path

from bench.suite import aggregate, cpu_model, markdown, meta_info, write_results

ROOT = Path(__file__).resolve().parent.parent


def test_the_cpu_model_is_read_from_cpuinfo(tmp_path):
    cpuinfo = tmp_path / "cpuinfo"
    cpuinfo.write_text(
        "processor\t: 0\nvendor_id\t: AuthenticAMD\nmodel name\t: AMD EPYC 7B13 64-Core\n"
        "processor\t: 1\nmodel name\t: AMD EPYC 7B13 64-Core\n"
    )
    assert cpu_model(cpuinfo) == "AMD EPYC 7B13 64-Core"


def test_the_results_files_name_the_cpu_model_the_commit_and_the_date(tmp_path):
    meta = meta_info(reps=1, skipped=[])
    meta["cpu"] = "Fake CPU 9000"  # a name no real machine gives, so the test sees it pass through
    run = dict(
        kind="run", scene="head-on", engine="pymunk", engine_arg="pymunk", rep=0, settings="s",
        n_bodies=2, ms_per_step=0.002, memory_per_body_bytes=0, timed_steps=10, warmup_steps=5,
        quality=None,
    )  # fmt: skip
    (row,) = aggregate([run], ["head-on"], ["pymunk"])
    text = markdown(meta, [row], [], [], [], [])
    jsonl, md = write_results(tmp_path / "results", "latest", [meta, run, row], text)

    first_line = md.read_text().splitlines()[0]
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True
    ).stdout.strip()
    today = dt.datetime.now(dt.UTC).strftime("%Y-%m-%d")
    assert "Fake CPU 9000" in first_line
    assert f"git {commit}" in first_line
    assert today in first_line
    written = [json.loads(line) for line in jsonl.read_text().splitlines()]
    assert written[0]["kind"] == "meta" and written[0]["cpu"] == "Fake CPU 9000"
    assert written[1:] == [run, row]


def _run(engine: str, rep: int, ms: float) -> dict:
    return dict(
        kind="run", scene="pile-100", engine=engine, engine_arg=engine, rep=rep, settings="s",
        n_bodies=103, ms_per_step=ms, memory_per_body_bytes=0, timed_steps=10, warmup_steps=5,
        quality=None,
    )  # fmt: skip


def test_the_ratio_to_box2d_v3_is_taken_within_each_repetition():
    # repetition 0: isaac 2 / box2d-v3 1 = 2; repetition 1: 6 / 2 = 3; median 2.5, while the
    # ratio of the medians (4 / 1.5) would differ
    runs = [_run("box2d-v3", 0, 1.0), _run("isaac-balanced", 0, 2.0)]
    runs += [_run("box2d-v3", 1, 2.0), _run("isaac-balanced", 1, 6.0)]
    rows = aggregate(runs, ["pile-100"], ["box2d-v3", "isaac-balanced"])
    isaac = next(r for r in rows if r["engine_arg"] == "isaac-balanced")
    assert isaac["ratio_to_box2d_v3"] == 2.5
    assert isaac["ratio_to_pymunk"] is None
    meta = meta_info(reps=2, skipped=[])
    header = markdown(meta, rows, [], [], [], []).splitlines()[2]
    assert "| ratio to pymunk | ratio to Box2D v3 |" in header


def test_without_box2d_v3_the_table_has_no_column_for_it():
    rows = aggregate([_run("pymunk", 0, 1.0)], ["pile-100"], ["pymunk"])
    assert rows[0]["ratio_to_box2d_v3"] is None
    text = markdown(meta_info(reps=1, skipped=[]), rows, [], [], [], [])
    assert "Box2D v3 |" not in text
