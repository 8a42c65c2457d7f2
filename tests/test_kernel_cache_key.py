"""numba's cache of ISAAC's kernels goes stale when any engine source changes (a cached driver
holds the code of every stage it calls, and numba checks only the kernel's own file)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from isaac.engine import driver
from isaac.engine import kernel_cache as engine

ROOT = Path(__file__).resolve().parents[1]


def test_an_engine_kernels_cache_stamp_carries_the_sources_key():
    locator = driver.run_steps_sequential._cache._impl.locator
    assert type(locator).__name__.startswith("IsaacSources")
    assert locator.get_source_stamp()[1] == engine.SOURCES_KEY


def test_the_sources_key_changes_with_any_engine_file(tmp_path):
    copy = tmp_path / "isaac"
    shutil.copytree(ROOT / "isaac", copy, ignore=shutil.ignore_patterns("__pycache__"))
    assert engine._sources_key(copy) == engine.SOURCES_KEY
    geometry = copy / "engine" / "geometry.py"
    geometry.write_text(geometry.read_text() + "\n# an edit\n")
    assert engine._sources_key(copy) != engine.SOURCES_KEY


def test_a_kernel_outside_isaac_keeps_numbas_own_cache(tmp_path):
    module = tmp_path / "outside.py"
    module.write_text("import numba\n@numba.njit(cache=True)\ndef f(x):\n    return x + 1\n")
    sys.path.insert(0, str(tmp_path))
    try:
        import outside

        assert outside.f(1) == 2
        assert not type(outside.f._cache._impl.locator).__name__.startswith("IsaacSources")
    finally:
        sys.path.remove(str(tmp_path))


PROBE = """
import json
from isaac import Simulation, load_scene
from isaac.engine import driver
sim = Simulation(load_scene("{scene}"), compile_ahead=False)
sim.advance(3)
print(json.dumps(sum(driver.run_steps_seed.stats.cache_hits.values())))
"""


@pytest.mark.slow
def test_an_edit_to_geometry_alone_recompiles_the_cached_driver(tmp_path):
    tree = tmp_path / "tree"
    shutil.copytree(ROOT / "isaac", tree / "isaac", ignore=shutil.ignore_patterns("__pycache__"))
    env = {**os.environ, "PYTHONPATH": str(tree), "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    env.pop("NUMBA_DISABLE_JIT", None)
    scene = ROOT / "scenes" / "head_on.yaml"  # the seed preset: run_steps_seed

    def hits() -> int:
        out = subprocess.run(
            [sys.executable, "-c", PROBE.format(scene=scene)],
            env=env, cwd=tmp_path, capture_output=True, text=True, timeout=900, check=True,
        )  # fmt: skip
        return json.loads(out.stdout.strip().splitlines()[-1])

    assert hits() == 0  # compiled
    assert hits() == 1  # from the cache
    geometry = tree / "isaac" / "engine" / "geometry.py"
    geometry.write_text(geometry.read_text() + "\n# an edit that changes no code\n")
    assert hits() == 0  # the driver's cache is stale: compiled again


def test_a_recorder_kernels_cache_stamp_carries_the_recorders_key():
    from recorder import kernel_cache as recorder_key
    from recorder import mcap_pack

    kernel = next(
        k for k in vars(mcap_pack).values() if hasattr(getattr(k, "_cache", None), "_impl")
    )
    locator = kernel._cache._impl.locator
    assert type(locator).__name__.startswith("RecorderSources")
    assert locator.get_source_stamp()[1] == recorder_key.SOURCES_KEY


def test_the_recorders_key_changes_with_any_recorder_file_and_with_the_engine(tmp_path):
    from recorder import kernel_cache as recorder_key

    copy = tmp_path / "recorder"
    shutil.copytree(ROOT / "recorder", copy, ignore=shutil.ignore_patterns("__pycache__"))

    def key(seed=engine.SOURCES_KEY):
        return engine.files_key(copy, copy.glob("*.py"), seed=seed)

    assert key() == recorder_key.SOURCES_KEY
    assert key(seed="another engine") != recorder_key.SOURCES_KEY
    pack = copy / "pack.py"
    pack.write_text(pack.read_text() + "\n# an edit\n")
    assert key() != recorder_key.SOURCES_KEY


class TypeAnOlderEngineHad:
    """A kernel argument type of an older engine (removed below once pickled)."""


def _stale_index(cache_path: Path, stamp):
    """numba's index file of a kernel at `cache_path`, as an older engine wrote it: its
    signatures name a type this engine does not define."""
    import pickle

    from numba.core import caching

    cache_path.mkdir()
    index = caching.IndexDataCacheFile(str(cache_path), "driver.run_steps-1", stamp)
    with open(index._index_path, "wb") as f:
        pickle.dump(index._version, f, protocol=-1)
        f.write(pickle.dumps((stamp, {(TypeAnOlderEngineHad(),): "data"}), protocol=-1))
    return index


def test_an_index_naming_a_type_this_engine_lacks_is_a_miss_not_a_crash(tmp_path, monkeypatch):
    keyed = _stale_index(tmp_path / "engine", ((0.0, 1), engine.SOURCES_KEY))
    other = _stale_index(tmp_path / "other", (0.0, 1))  # another library's kernel
    monkeypatch.delattr(sys.modules[__name__], "TypeAnOlderEngineHad")
    assert keyed._load_index() == {}  # a miss: compiled again, and the index written anew
    with pytest.raises(AttributeError):  # numba's own behaviour, elsewhere
        other._load_index()
