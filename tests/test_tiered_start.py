"""A first run while a helper still compiles the driver (`Simulation(tiered=True)`, which
`isaac run` uses): `run`, `advance` and `batches` take the staged path until the helper is done,
then the driver, and the bits are those of the driver all along; the helper is waited for at
the end, and the next run loads the driver from the cache."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from test_fused_stepping import _pile, _same_record

from isaac.engine.diagnostics import state_hash
from isaac.engine.records import StepBatch
from isaac.engine.simulation import Simulation
from isaac.scene import load_scene

SCENES = Path(__file__).resolve().parents[1] / "scenes"


class _Compiling:
    """Stands in for the driver's helper process: running for `polls` polls, then exited."""

    stdin = stdout = None

    def __init__(self, polls: int) -> None:
        self.polls = polls

    def poll(self):
        self.polls -= 1
        return None if self.polls >= 0 else 0

    def wait(self, timeout=None):
        self.polls = -1
        return 0

    def kill(self):
        self.killed = True


def _compiling(sim: Simulation, polls: int) -> Simulation:
    sim._compiling = _Compiling(polls)
    return sim


@pytest.mark.parametrize("size", [1, 7, 16])
def test_batches_switching_from_the_staged_path_to_the_driver_keep_the_drivers_bits(
    size, monkeypatch
):
    scene = _pile("balanced")
    expected = [r for b in Simulation(scene).batches(40, size=size) for r in b_records(b)]
    paths = []
    for path in ("_staged_batch", "_driven_batch"):
        real = getattr(Simulation, path)

        def spy(self, k, real=real, path=path):
            paths.append(path)
            return real(self, k)

        monkeypatch.setattr(Simulation, path, spy)
    sim = _compiling(Simulation(scene), polls=2)  # two staged batches, then the driver
    got = [r for b in sim.batches(40, size=size) for r in b_records(b)]
    assert paths == ["_staged_batch"] * 2 + ["_driven_batch"] * (-(-40 // size) - 2)
    assert len(got) == len(expected) == 40
    for x, y in zip(got, expected):
        _same_record(x, y)
    assert not sim.compiling_driver


def b_records(batch: StepBatch) -> list:
    return [batch.record(s) for s in range(batch.steps)]


def test_advance_while_the_driver_compiles_steps_staged_then_drives_with_the_same_bits():
    scene = load_scene(SCENES / "spawn.yaml")  # bodies entering and leaving on the way
    expected = Simulation(scene, staged=True)
    for _ in range(30):
        expected.step()
    sim = _compiling(Simulation(scene), polls=12)  # 12 staged steps, then one driver call
    sim.advance(30)
    assert sim._stepper.carried is not None and sim._contacts is None  # (the driver's last)
    _same_record(sim.record(), expected.record())


def test_finish_compiling_waits_for_the_helper_and_says_whether_there_was_one():
    sim = _compiling(Simulation(_pile("balanced")), polls=100)
    assert sim.compiling_driver
    assert sim.finish_compiling() is True
    assert not sim.compiling_driver and sim.finish_compiling() is False


def test_finish_compiling_with_stop_kills_a_running_helper_instead_of_waiting():
    sim = _compiling(Simulation(_pile("balanced")), polls=100)
    helper = sim._compiling
    assert sim.finish_compiling(stop=True) is True
    assert getattr(helper, "killed", False) and not sim.compiling_driver


def test_a_one_record_batch_of_the_staged_path_leaves_the_records_rows_writable():
    # its rows are what the next staged step reads: a read-only array is another type to numba,
    # and three kernels compiled again for it (6.7 s on a first run)
    sim = Simulation(_pile("balanced"), staged=True)
    while not len(sim.record().contacts):  # (the pile settles onto its floor)
        sim.step()
    record = sim.record()
    assert len(record.contacts)
    batch = StepBatch.of_records([record], sim.scene.world.dt)
    assert not batch.contacts_of(0).depth.flags.writeable
    assert all(getattr(record.contacts, f).flags.writeable for f in ("depth", "a", "point"))
    assert np.array_equal(batch.contacts_of(0).depth, record.contacts.depth)


_COLD = r"""
import json, sys
from isaac.engine import driver, narrow_phase
from isaac.engine.compile_ahead import driver_kernel, is_cold
from isaac.engine.diagnostics import state_hash
from isaac.engine.simulation import Simulation
from isaac.scene import load_scene

scene = load_scene(sys.argv[1])
sim = Simulation(scene, tiered=True)
kernel = driver_kernel(sim.settings)
compiling_at_start = sim.compiling_driver
hashes, paths = [], []
for batch in sim.batches(size=16):
    paths.append("staged" if sim.compiling_driver else "driver")
    hashes += [state_hash(batch.record(s)) for s in range(batch.steps)]
sim.finish_compiling()
cold_after = is_cold(kernel)
print(json.dumps({"compiling_at_start": compiling_at_start, "paths": paths, "hashes": hashes,
                  "cold_after": cold_after,
                  "driver_signatures": len(kernel.signatures),
                  "collide_signatures": len(narrow_phase.collide_pairs.signatures)}))
"""

_WARM = r"""
import json, sys
from isaac.engine.compile_ahead import driver_kernel
from isaac.engine.simulation import Simulation
from isaac.scene import load_scene

sim = Simulation(load_scene(sys.argv[1]), tiered=True)
kernel = driver_kernel(sim.settings)
helper = sim.compiling_driver
sim.advance(5)
print(json.dumps({"helper": helper, "hits": sum(kernel.stats.cache_hits.values()),
                  "misses": sum(kernel.stats.cache_misses.values())}))
"""


def _python(code: str, scene: Path, cache: Path) -> dict:
    proc = subprocess.run(
        [sys.executable, "-c", code, str(scene)],
        capture_output=True,
        text=True,
        env={**os.environ, "NUMBA_CACHE_DIR": str(cache)},
        timeout=600,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.mark.skipif(os.environ.get("NUMBA_DISABLE_JIT") == "1", reason="compiles kernels")
def test_a_cold_first_run_steps_before_the_driver_compiles_then_the_next_run_loads_it(tmp_path):
    scene = SCENES / "default.yaml"
    cache = tmp_path / "numba-cache"
    got = _python(_COLD, scene, cache)
    # the helper was compiling the driver when the simulation was built (the driver takes
    # 7-10 s alone), and the run's first batch came from the staged path meanwhile
    assert got["compiling_at_start"] is True
    assert got["paths"][0] == "staged"
    # this process never compiled the driver, and each stage once (a staged batch hands the
    # next step writable rows)
    assert got["driver_signatures"] == 0 and got["collide_signatures"] == 1
    assert got["cold_after"] is False  # the helper, waited for, left the driver in the cache
    assert got["hashes"] == [state_hash(r) for r in Simulation(load_scene(scene)).run()]
    # the next run: no helper, the driver loaded from the cache the helper filled
    again = _python(_WARM, scene, cache)
    assert again == {"helper": False, "hits": 1, "misses": 0}


@pytest.mark.slow
def test_a_first_isaac_run_finishes_its_output_then_waits_for_the_driver_leaving_nothing(
    tmp_path,
):
    """`isaac run` in an empty cache (about 18 s on 2 cores): its summary is printed, then it
    says it finishes the driver, which is in the cache when it exits, and no helper outlives
    it."""
    cache = tmp_path / "cache"
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    env.pop("NUMBA_DISABLE_JIT", None)
    isaac = str(Path(sys.executable).parent / "isaac")
    done = subprocess.run(
        [isaac, "run", str(SCENES / "default.yaml")],
        capture_output=True, text=True, env=env, timeout=600,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "scene 'default': 600 steps" in done.stdout
    assert "finishing the compiled driver in numba's cache for later runs" in done.stderr
    assert list(cache.rglob("driver.run_steps_sequential-*.nbi"))
    assert not _processes_using(cache)


def _processes_using(cache: Path) -> list[int]:
    """Processes whose environment names this numba cache (a helper left behind)."""
    found = []
    for environ in Path("/proc").glob("[0-9]*/environ"):
        try:
            if str(cache).encode() in environ.read_bytes():
                found.append(int(environ.parent.name))
        except OSError:  # (gone, or not ours)
            continue
    return found
