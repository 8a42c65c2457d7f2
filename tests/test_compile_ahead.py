"""First run with an empty numba cache (isaac.engine.compile_ahead): the solver (and, for a scene
with joints, the joints' kernels) are compiled by helper processes into the cache, this process
loads them from there, and the run's bits do not change. A scene without joints never compiles
the joints' kernels: its driver and solver are specialisations without them."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
from test_determinism import pile_scene

from isaac.engine.compile_ahead import is_cold, solver_kernel
from isaac.engine.diagnostics import state_hash
from isaac.engine.simulation import Simulation
from isaac.engine.step import StepSettings
from isaac.scene import load_scene

_FIRST_RUN = r"""
import json, sys
sys.path.insert(0, {tests!r})
from isaac.engine.compile_ahead import WAITING, is_cold, joints_kernel, solver_kernel
from isaac.engine.diagnostics import state_hash
from isaac.engine.simulation import Simulation
from isaac.scene import load_scene
from test_determinism import pile_scene

scene = pile_scene("balanced") if {scene!r} is None else load_scene({scene!r})
sim = Simulation(scene)
kernel = solver_kernel(sim.settings)
cold_after_build = is_cold(kernel)
joints_helper = len(WAITING)
hashes = [state_hash(rec) for rec in sim.run()]  # the driver: after the joints' helper
joints = joints_kernel()
from isaac.engine.driver import keep_rows  # compiled by the solver's helper
print(json.dumps({{"cold_after_build": cold_after_build, "hashes": hashes,
                   "joints_helper": joints_helper, "waiting_after_run": len(WAITING),
                   "joints_cache_hits": sum(joints.stats.cache_hits.values()),
                   "joints_cache_misses": sum(joints.stats.cache_misses.values()),
                   "solver_cache_hits": sum(kernel.stats.cache_hits.values()),
                   "solver_cache_misses": sum(kernel.stats.cache_misses.values()),
                   "keep_rows_cache_hits": sum(keep_rows.stats.cache_hits.values()),
                   "keep_rows_cache_misses": sum(keep_rows.stats.cache_misses.values())}}))
"""


def _first_run(tmp_path, scene: str | None = None) -> dict:
    """The balanced pile (or the scene file `scene`) run in a fresh process with an empty numba
    cache."""
    tests = os.path.dirname(os.path.abspath(__file__))
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba-cache")}
    proc = subprocess.run(
        [sys.executable, "-c", _FIRST_RUN.format(tests=tests, scene=scene)],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_a_cold_cache_gets_the_solver_from_its_helper_never_the_joints_and_the_same_bits(tmp_path):
    # one first run (~8 s of compiling on 2 cores): the path every new machine and CI takes
    got = _first_run(tmp_path)
    assert got["cold_after_build"] is False  # the helper wrote the solver's cache index
    # the first step loaded the solver from that cache instead of compiling it
    assert (got["solver_cache_hits"], got["solver_cache_misses"]) == (1, 0)
    # ... and the driver's `keep_rows`, which the helper compiles too (its share of the work)
    assert (got["keep_rows_cache_hits"], got["keep_rows_cache_misses"]) == (1, 0)
    # no joints: no joints' helper, and neither it nor the driver compiled the joints' kernels
    assert (got["joints_helper"], got["waiting_after_run"]) == (0, 0)
    assert (got["joints_cache_hits"], got["joints_cache_misses"]) == (0, 0)
    expected = [state_hash(rec) for rec in Simulation(pile_scene("balanced")).run()]
    assert got["hashes"] == expected


def test_a_cold_cache_gets_a_joint_scenes_solver_and_joints_from_the_helpers_and_the_same_bits(
    tmp_path,
):
    scene = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scenes")
    scene = os.path.join(scene, "pendulum.yaml")
    got = _first_run(tmp_path, scene)
    assert got["cold_after_build"] is False
    # the solver's specialisation with joints came from its helper
    assert (got["solver_cache_hits"], got["solver_cache_misses"]) == (1, 0)
    # (the simulation compiled the joints' first kernels itself, for its step-0 joint rows,
    # before `prepare`: no joints' helper then, as before)
    assert got["waiting_after_run"] == 0
    expected = [state_hash(rec) for rec in Simulation(load_scene(scene)).run()]
    assert got["hashes"] == expected


def test_a_warm_cache_is_not_cold_and_a_kernel_without_cache_never_is():
    sim = Simulation(pile_scene("balanced"))
    sim.step()  # compiled or loaded in this process: the cache index exists now
    assert not is_cold(solver_kernel(sim.settings))
    assert not is_cold(lambda: None)  # NUMBA_DISABLE_JIT: plain functions, nothing to prepare


def test_the_seed_solver_is_the_kernel_prepared_for_the_seed_preset():
    from isaac.engine.solver import seed, sequential

    assert solver_kernel(StepSettings.of(pile_scene("seed").world)) is seed.solve_seed
    assert (
        solver_kernel(StepSettings.of(pile_scene("balanced").world)) is sequential.solve_sequential
    )


_DRIVER_AFTER_COMPILE_DRIVER = r"""
import json, sys
from isaac.engine import driver
from isaac.engine.compile_ahead import compile_driver
from isaac.engine.simulation import Simulation
from isaac.scene import load_scene

scene = load_scene(sys.argv[1])
timed = sys.argv[2] == "timed"
compile_driver(scene.world, joints=bool(scene.joints), timed=timed)
after_compile = {n: len(getattr(driver, n).signatures) for n in dir(driver)
                 if n.startswith("run_steps_") and getattr(driver, n).signatures}
Simulation(scene, profile=timed).advance(20)
after_run = {n: len(getattr(driver, n).signatures) for n in dir(driver)
             if n.startswith("run_steps_") and getattr(driver, n).signatures}
print(json.dumps([after_compile, after_run]))
"""


@pytest.mark.skipif(os.environ.get("NUMBA_DISABLE_JIT") == "1", reason="counts compiled drivers")
@pytest.mark.parametrize(
    "scene, timed, driver",
    [
        ("default.yaml", "plain", "run_steps_sequential"),
        ("pendulum.yaml", "plain", "run_steps_sequential_joints"),
        ("default.yaml", "timed", "run_steps_sequential_timed"),
    ],
)
def test_compile_driver_compiles_the_driver_a_simulation_then_calls(scene, timed, driver):
    """`compile_driver` (what `isaac run` calls before waiting for the recorder's helper) on the
    small world gives the driver of the scene's own run: the run adds no signature."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    out = subprocess.run(
        [sys.executable, "-c", _DRIVER_AFTER_COMPILE_DRIVER, f"scenes/{scene}", timed],
        capture_output=True, text=True, cwd=root, check=True,
    )  # fmt: skip
    after_compile, after_run = json.loads(out.stdout.splitlines()[-1])
    assert after_compile == {driver: 1}
    assert after_run == after_compile
