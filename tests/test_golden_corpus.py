"""The golden corpus (tests/fixtures/golden/, recorded by scripts/make_golden.sh with physics
version 2) replays bit for bit under every configuration a log may meet on another machine:

- the host CPU, with the on-disk numba cache as it is;
- NUMBA_CPU_NAME=generic with a fresh NUMBA_CACHE_DIR (code for a baseline x86-64 / aarch64 CPU:
  no AVX, no FMA available to LLVM at all; compiled from scratch);
- NUMBA_DISABLE_JIT=1 (the pure-Python reference path).

Emulated arm64: scripts/arm64_replay.sh (`make test-arm64`, docs/replay.md).

The generic-CPU case compiles every kernel from scratch (50-70 s on the loaded 2-core machine,
one process for the whole corpus); the no-JIT case takes about 3 s.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from isaac.engine import PHYSICS_VERSION
from replay.compare import replay_log

ROOT = Path(__file__).resolve().parents[1]
GOLDEN = ROOT / "tests" / "fixtures" / "golden"
LOGS = sorted(GOLDEN.glob("*.mcap"))
NAMES = [p.stem for p in LOGS]

_REPLAY_ALL = """
import json, sys
from replay.compare import replay_log
out = {}
for path in sys.argv[1:]:
    r = replay_log(path)
    out[path] = [r.verdict, r.steps_compared, r.claimed_steps]
print(json.dumps(out))
"""


def _replay_elsewhere(names: list[str], env_extra: dict[str, str]) -> dict[str, list]:
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_DISABLE_JIT", "NUMBA_CPU_NAME")}
    env.update(env_extra)
    paths = [str(GOLDEN / f"{n}.mcap") for n in names]
    done = subprocess.run(
        [sys.executable, "-c", _REPLAY_ALL, *paths],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=1800,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def _assert_identical(results: dict[str, list]) -> None:
    for path, (verdict, compared, claimed) in results.items():
        assert verdict == "identical", path
        assert compared == claimed and compared > 10, path


def test_the_corpus_covers_what_it_says():
    from isaac.scene import load_scene

    assert NAMES == ["ccd", "head_on", "off_centre", "pile", "pyramid", "spawn"]
    scenes = [load_scene(str(GOLDEN / f"{n}.yaml")) for n in NAMES]
    assert {s.world.fidelity for s in scenes} == {"seed", "fast", "balanced", "accurate"}
    assert {s.world.friction for s in scenes} == {True, False}
    assert {s.world.ccd for s in scenes} == {"off", "speculative"}
    assert any(b.enters_at > 0 for s in scenes for b in s.bodies)
    # each log is its scene's recording, by the current physics
    from replay.reader import RawLog

    for name, scene in zip(NAMES, scenes):
        meta = RawLog(str(GOLDEN / f"{name}.mcap")).metadata
        assert meta["scene_name"] == scene.name
        assert meta["physics_version"] == str(PHYSICS_VERSION)


@pytest.mark.parametrize("name", NAMES)
def test_replays_identical_on_the_host_cpu(name):
    report = replay_log(str(GOLDEN / f"{name}.mcap"))
    assert report.verdict == "identical"
    assert report.steps_compared == report.claimed_steps


def test_replays_identical_on_a_generic_cpu_from_a_fresh_cache(tmp_path):
    # about 50-70 s, nearly all of it compiling every kernel from scratch (one process for all)
    env = {"NUMBA_CPU_NAME": "generic", "NUMBA_CACHE_DIR": str(tmp_path / "numba-cache")}
    _assert_identical(_replay_elsewhere(NAMES, env))


def test_replays_identical_without_the_jit():
    # the pure-Python reference path: about 3 s for the whole corpus
    _assert_identical(_replay_elsewhere(NAMES, {"NUMBA_DISABLE_JIT": "1"}))
