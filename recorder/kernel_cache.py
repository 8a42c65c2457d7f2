"""numba's cache of the recorder's kernels, keyed by the recorder's and the engine's sources.

Imported by every recorder module that defines a cached kernel, before its kernels. numba checks
a cached kernel against its own source file alone, but the recorder's packers call kernels of
other files (`recorder.mcap_pack` calls `recorder.pack`'s, both call
`isaac.engine.diagnostics._sums`): after an edit to recorder/pack.py alone, mcap_pack's cached
kernels went on running the old code until the cache was deleted. The key covers every
recorder source and the engine's key (`isaac.engine.kernel_cache`), so any such edit recompiles
them; an edit to the recorder leaves the engine's kernels cached.
"""

from __future__ import annotations

from pathlib import Path

from isaac.engine import kernel_cache as engine

ROOT = Path(__file__).resolve().parent

SOURCES_KEY = engine.key_kernel_caches(
    ROOT, engine.files_key(ROOT, ROOT.glob("*.py"), seed=engine.SOURCES_KEY), "RecorderSources"
)
