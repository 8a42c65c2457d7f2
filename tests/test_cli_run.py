"""`isaac run` and `isaac check` end to end, through the command line."""

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def isaac(*args, cwd=REPO):
    return subprocess.run(
        [sys.executable, "-m", "isaac", *map(str, args)],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_run_prints_a_summary_with_the_physics_it_saw():
    result = isaac("run", "scenes/head_on.yaml", "--quiet", "--verbose")
    assert result.returncode == 0, result.stderr
    out = result.stdout
    # the shipped head-on hit (e = 1, no gravity) keeps its energy exactly
    assert "200 steps of 0.01 s, 2 bodies, fidelity seed" in out
    assert "contacts seen 1," in out
    start = float(out.split("energy (kinetic + potential) start ")[1].split(" J")[0])
    end = float(out.split(", end ")[1].split(" J")[0])
    assert start == end > 0
    assert "start-up to first step" in out


def test_run_steps_option_sets_the_length():
    result = isaac("run", "scenes/bounce.yaml", "--quiet", "--steps", "7")
    assert result.returncode == 0, result.stderr
    assert "7 steps of" in result.stdout


def test_run_refuses_a_negative_step_count_in_one_line():
    result = isaac("run", "scenes/bounce.yaml", "--quiet", "--steps", "-3")
    assert result.returncode == 2
    assert result.stderr.count("\n") == 1 and "--steps" in result.stderr
    assert "Traceback" not in result.stderr


def test_check_prints_the_expanded_body_count():
    result = isaac("check", "scenes/pyramid.yaml")
    assert result.returncode == 0, result.stderr
    # 20 rows: 210 boxes and the ground
    assert "211 bodies (1 concrete)" in result.stdout


def test_profile_lists_every_stage():
    result = isaac("run", "scenes/pile.yaml", "--quiet", "--steps", "20", "--profile")
    assert result.returncode == 0, result.stderr
    for stage in ("broad phase", "narrow phase", "push-out", "impulses", "integration", "geometry"):
        assert stage in result.stdout
