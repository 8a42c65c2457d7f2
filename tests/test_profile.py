"""`isaac run --profile` times the stages inside the compiled driver: the timed driver gives the
same bits as the plain one, and its stage times are non-negative parts of its measured total,
which is itself part of the wall time around the calls."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from isaac.engine.driver import STAGES
from isaac.engine.records import CONTACT_FIELDS
from isaac.engine.simulation import Simulation
from isaac.scene import load_scene

ROOT = Path(__file__).resolve().parents[1]
STEPS = 30

# contacts under the sequential solver with sub-steps (pile: accurate is 4 sub-steps), bodies
# entering and leaving, the seed's solver (head_on), joints
SCENES = ("pile.yaml", "spawn.yaml", "head_on.yaml", "chain.yaml")


def _records(sim: Simulation, steps: int) -> list:
    return [batch.record(s) for batch in sim.batches(steps, size=8) for s in range(batch.steps)]


@pytest.mark.parametrize("name", SCENES)
def test_the_timed_driver_gives_the_plain_drivers_bits(name):
    scene = load_scene(ROOT / "scenes" / name)
    plain = _records(Simulation(scene, compile_ahead=False), STEPS)
    timed = _records(Simulation(scene, compile_ahead=False, profile=True), STEPS)
    assert len(plain) == len(timed) == STEPS
    for x, y in zip(plain, timed):
        for f in ("position", "angle", "velocity", "angular_velocity", "exists"):
            assert np.array_equal(getattr(x, f), getattr(y, f)), (x.step, f)
        for f in CONTACT_FIELDS:
            a, b = getattr(x.contacts, f), getattr(y.contacts, f)
            assert np.array_equal(a, b, equal_nan=True), (x.step, f)


def test_stage_times_are_parts_of_the_measured_total():
    scene = load_scene(ROOT / "scenes" / "pile.yaml")
    sim = Simulation(scene, compile_ahead=False, profile=True)
    sim.advance(1)  # (loads or compiles the timed driver)
    before = sim.stage_times()["total"]
    started = time.perf_counter()
    for _ in sim.batches(STEPS, size=8):
        pass
    wall = time.perf_counter() - started
    times = sim.stage_times()
    assert set(times) == {*STAGES, "total"}
    stages = [times[s] for s in STAGES]
    assert all(t >= 0.0 for t in stages)
    # every step transforms, sweeps, touches (the pile rests) and integrates
    for stage in ("geometry", "broad phase", "narrow phase", "impulses", "integration"):
        assert times[stage] > 0.0, stage
    # disjoint intervals inside the calls: their sum never exceeds the calls' total, and the
    # batches' calls took part of the wall time around them
    assert sum(stages) <= times["total"]
    assert 0.0 < times["total"] - before <= wall


def test_an_unprofiled_simulation_reports_no_time():
    sim = Simulation(load_scene(ROOT / "scenes" / "bounce.yaml"), compile_ahead=False)
    sim.advance(5)
    assert set(sim.stage_times().values()) == {0.0}


def _run(*args: str, jit: bool = True) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    if jit:
        env.pop("NUMBA_DISABLE_JIT", None)
    else:
        env["NUMBA_DISABLE_JIT"] = "1"
    return subprocess.run(
        [sys.executable, "-m", "isaac", "run", *args],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )


def _table(stdout: str) -> dict[str, float]:
    """The profile's rows: stage -> ms/step."""
    rows = {}
    lines = stdout.split("inside the compiled driver")[1].splitlines()[1:]
    for line in lines:
        if not line.startswith("    "):
            break
        label = line[4:17].strip()
        rows[label] = float(line[17:].split()[0])
    return rows


@pytest.mark.parametrize("jit", [True, False], ids=["jit", "no-jit"])
def test_cli_profile_prints_each_stage_and_the_drivers_total(jit):
    # (without the JIT a few steps of a small scene: pure Python)
    scene, steps = ("scenes/pile.yaml", "20") if jit else ("scenes/bounce.yaml", "4")
    result = _run(scene, "--quiet", "--steps", steps, "--profile", jit=jit)
    assert result.returncode == 0, result.stderr
    out = result.stdout
    rows = _table(out)
    assert set(rows) == {*STAGES, "clock reads"}
    assert all(v >= 0.0 for v in rows.values())
    total = float(out.split("driver total ")[1].split(" ms/step")[0])
    # the table's rows (rounded to 0.1 us) add up to the total
    assert abs(sum(rows.values()) - total) <= 1e-4 * (len(rows) + 1)


def test_cli_profile_keeps_the_runs_physics():
    plain = _run("scenes/pile.yaml", "--quiet", "--steps", "20")
    timed = _run("scenes/pile.yaml", "--quiet", "--steps", "20", "--profile")
    assert plain.returncode == timed.returncode == 0, plain.stderr + timed.stderr

    def physics(out: str) -> tuple:
        energy = out.split("energy (kinetic + potential) ")[1].splitlines()[0]
        contacts = out.split("contacts seen ")[1].split(", ")[:2]
        return energy, contacts

    assert physics(plain.stdout) == physics(timed.stdout)
