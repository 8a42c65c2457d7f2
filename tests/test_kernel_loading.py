"""Cached kernels load without numba's compiler registries (isaac/kernel_loading.py), and that
changes nothing but what is imported: the same bits as numba's own eager loading, and a kernel
compiled afterwards still compiles and runs."""

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
from isaac.engine.diagnostics import state_hash
from isaac.engine.simulation import Simulation
from isaac.scene import load_scene

scene = load_scene({scene!r})
sim = Simulation(scene)
hashes = [state_hash(sim.step()) for _ in range(5)]  # one compiled call per stage
hashes += [state_hash(r) for r in sim.run(40)]  # the compiled driver
loaded = [m for m in {modules!r} if m in sys.modules]
import numba  # a kernel compiled now, after the cached loads: the compiler refreshes itself

@numba.njit
def weighted(x, w):
    return (x * w).sum()

compiled = weighted(np.arange(4.0), np.arange(4.0))
from isaac import kernel_loading
print(json.dumps({{"hashes": hashes, "loaded": loaded, "compiled": compiled,
                   "lazy": kernel_loading.LAZY}}))
"""


def _run(scene: str, **env) -> dict:
    code = _RUN.format(scene=str(ROOT / "scenes" / scene), modules=REGISTRY_ONLY)
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
