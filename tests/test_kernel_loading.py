"""Cached kernels load without numba's compiler registries and without parsing their bitcode
(isaac/kernel_loading.py), and that changes nothing but what is imported and when: the same bits
as numba's own eager loading, a kernel compiled afterwards still compiles and runs (also against
a lazily loaded kernel), and a stale cache still recompiles. On a numba version it was not
tested with, numba's own loading is left in place."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# modules that only numba's target refresh imports (numba.core.cpu.load_additional_registries),
# never the environments of the engine's kernels
REGISTRY_ONLY = ("numba.cpython.printimpl", "numba.misc.cffiimpl", "numba.typed.typedset")

_RUN = r"""
import json, sys
import numpy as np
import numba
from numba.core import caching, codegen, environment

def replaced():  # numba's internals the lazy loading may replace
    return (caching.Cache.load_overload, codegen.CPUCodeLibrary.__dict__["_unserialize"],
            environment._rebuild_env)

numbas_own = replaced()
{prelude}
from isaac.engine.diagnostics import state_hash
from isaac.engine.simulation import Simulation
from isaac.scene import load_scene

scene = load_scene({scene!r})
sim = Simulation(scene)
hashes = [state_hash(sim.step()) for _ in range(5)]  # one compiled call per stage
hashes += [state_hash(r) for r in sim.run(40)]  # the compiled driver
loaded = [m for m in {modules!r} if m in sys.modules]
own = [a is b for a, b in zip(numbas_own, replaced())]
from isaac.engine.geometry import sin_cos
from isaac.trig import sin_cos as sin_cos_python
direct = sin_cos(0.3)  # loaded from the cache
# a kernel compiled now, after the cached loads: the compiler refreshes itself

@numba.njit
def through(a):  # compiled against the loaded kernel (lazily: its bitcode parsed now)
    return sin_cos(a)

linked = through(0.3)

@numba.njit
def weighted(x, w):
    return (x * w).sum()

compiled = weighted(np.arange(4.0), np.arange(4.0))
from isaac import kernel_loading
same_sin_cos = list(direct) == list(linked) == list(sin_cos_python(0.3))
print(json.dumps({{"hashes": hashes, "loaded": loaded, "compiled": compiled, "own": own,
                   "lazy": kernel_loading.LAZY, "loading": kernel_loading.LOADING,
                   "same_sin_cos": same_sin_cos}}))
"""

# isaac.kernel_loading imported under another numba version (put back before any kernel's
# cache is made: numba's cache index records the version and would miss)
_UNTESTED_NUMBA = """
real_version, numba.__version__ = numba.__version__, "0.0.0"
import isaac.kernel_loading
numba.__version__ = real_version
"""


def _run(scene: str, prelude: str = "", **env) -> dict:
    code = _RUN.format(scene=str(ROOT / "scenes" / scene), modules=REGISTRY_ONLY, prelude=prelude)
    proc = subprocess.run(
        [sys.executable, "-c", code],
        cwd=ROOT,
        env={**os.environ, **env},
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.mark.skipif(
    os.environ.get("NUMBA_DISABLE_JIT") == "1", reason="no kernel is loaded without the JIT"
)
def test_cached_kernels_load_without_the_compiler_registries_and_give_the_same_bits():
    _run("car.yaml")  # fills the cache if this checkout's kernels are not in it yet
    lazy = _run("car.yaml")
    eager = _run("car.yaml", ISAAC_EAGER_KERNEL_LOADING="1")
    assert lazy["lazy"] and not eager["lazy"]
    assert lazy["loaded"] == [] and eager["loaded"] == list(REGISTRY_ONLY)
    assert lazy["hashes"] == eager["hashes"] and len(set(lazy["hashes"])) == 45
    assert lazy["compiled"] == eager["compiled"] == 14.0  # 0 + 1 + 4 + 9
    assert lazy["same_sin_cos"] and eager["same_sin_cos"]
    assert lazy["own"] == [False, False, True] and eager["own"] == [True, True, True]


@pytest.mark.skipif(
    os.environ.get("NUMBA_DISABLE_JIT") == "1", reason="no kernel is loaded without the JIT"
)
def test_on_an_untested_numba_version_numba_loads_its_own_way_with_the_same_bits():
    _run("car.yaml")  # fills the cache if this checkout's kernels are not in it yet
    lazy = _run("car.yaml")
    untested = _run("car.yaml", prelude=_UNTESTED_NUMBA)
    assert lazy["lazy"] and lazy["loading"] == "lazy"
    assert not untested["lazy"] and "numba 0.0.0 is not one of" in untested["loading"]
    assert untested["own"] == [True, True, True]  # numba's own, by identity
    assert untested["loaded"] == list(REGISTRY_ONLY)  # numba refreshed its target to load
    assert untested["hashes"] == lazy["hashes"] and untested["compiled"] == lazy["compiled"]
    assert untested["same_sin_cos"]


_KERNEL = """
import numba
import numpy as np

@numba.njit(cache=True)
def total(x):
    return np.sum(x) * SCALE  # (np.sum: an environment in numba.np.arraymath)
"""

_USE = r"""
import json, sys
sys.path.insert(0, {folder!r})
import numpy as np
from isaac import kernel_loading
import kernel
value = kernel.total(np.arange(4.0))
import numba

@numba.njit
def plus_one(x):
    return kernel.total(x) + 1.0

print(json.dumps({{"value": value, "plus_one": plus_one(np.arange(4.0)),
                   "lazy": kernel_loading.LAZY,
                   "hits": sum(kernel.total.stats.cache_hits.values())}}))
"""


@pytest.mark.skipif(
    os.environ.get("NUMBA_DISABLE_JIT") == "1", reason="no kernel is loaded without the JIT"
)
def test_a_stale_or_missing_cache_recompiles_and_a_lazy_load_links_like_an_eager_one(tmp_path):
    source = tmp_path / "kernel.py"

    def use(scale: float, **env) -> dict:
        source.write_text(f"SCALE = {scale!r}\n" + _KERNEL)
        stamp = 1e9 + scale  # (numba tells a stale source by its time stamp and size)
        os.utime(source, (stamp, stamp))
        proc = subprocess.run(
            [sys.executable, "-c", _USE.format(folder=str(tmp_path))],
            env={**os.environ, **env},
            capture_output=True,
            text=True,
            timeout=600,
        )
        assert proc.returncode == 0, proc.stderr[-3000:]
        return json.loads(proc.stdout.strip().splitlines()[-1])

    missing = use(2.0)  # no cache yet: compiled and saved
    lazy = use(2.0)
    eager = use(2.0, ISAAC_EAGER_KERNEL_LOADING="1")
    assert (missing["hits"], lazy["hits"], eager["hits"]) == (0, 1, 1)
    assert lazy["lazy"] and not eager["lazy"]
    assert missing["value"] == lazy["value"] == eager["value"] == 12.0
    assert missing["plus_one"] == lazy["plus_one"] == eager["plus_one"] == 13.0
    stale = use(3.0)  # a new source: the cached kernel is stale
    assert stale["hits"] == 0 and (stale["value"], stale["plus_one"]) == (18.0, 19.0)
    again = use(3.0)
    assert again["hits"] == 1 and (again["value"], again["plus_one"]) == (18.0, 19.0)
