"""numba's cache of the engine's kernels, keyed by the engine's sources.

Imported by every engine module that defines a cached kernel, before its kernels: numba checks
a cached kernel against its own source file alone, but the compiled driver holds the code of
every stage it calls. After an edit to geometry.py only, a cached driver went on running the
old physics (compiled and pure-Python runs disagreed at step 16 until the cache was deleted).
The locators installed here are numba's own (NUMBA_CACHE_DIR, then the in-tree __pycache__),
for isaac's files only, with `SOURCES_KEY` added to the source stamp numba compares.
(Not in isaac/engine/__init__: importing the records alone must not load numba.)

A cache index keyed here that no longer loads is a miss, not a crash
(`isaac.kernel_loading.tolerate_stale_indexes`).
"""

from __future__ import annotations

from isaac import kernel_loading  # (first: cached kernels load without numba's compiler)


def files_key(root, paths, seed: str = "") -> str:
    """sha256 (hex, 16 digits) of `seed` and of `paths` (below `root`) by relative path and
    content, in sorted order: the stamp a cached kernel compiled from those sources carries."""
    import hashlib
    from pathlib import Path

    root = Path(root)
    h = hashlib.sha256(seed.encode())
    for path in sorted(paths):
        h.update(Path(path).relative_to(root).as_posix().encode())
        h.update(b"\0")
        h.update(Path(path).read_bytes())
    return h.hexdigest()[:16]


def _sources_key(package_root) -> str:
    """The engine's key: the files of isaac/engine, isaac/trig.py and isaac/collision_filter.py,
    the sources every engine kernel may compile in, and isaac/kernel_loading.py, whose
    functions a cached kernel's data may name (an engine that had lazy environments pickled
    its own `_rebuild_env` into every kernel it saved)."""
    from pathlib import Path

    root = Path(package_root)
    shared = [root / "trig.py", root / "collision_filter.py", root / "kernel_loading.py"]
    return files_key(root, [*(root / "engine").rglob("*.py"), *shared])


def key_kernel_caches(root, key: str, label: str) -> str:
    """Key numba's cache of every kernel defined in a file below `root` by `key` (once a
    process per label): numba's own locators (NUMBA_CACHE_DIR, then the in-tree __pycache__),
    with `key` added to the source stamp numba compares. Files elsewhere keep numba's own
    cache. Returns `key`."""
    import os
    from pathlib import Path

    from numba.core import caching

    inside = str(Path(root).resolve()) + os.sep

    def keyed(base):
        class Keyed(base):
            @classmethod
            def from_function(cls, py_func, py_file):
                if not os.path.abspath(py_file).startswith(inside):
                    return None
                return super().from_function(py_func, py_file)

            def get_source_stamp(self):
                return (super().get_source_stamp(), key)

        Keyed.__name__ = Keyed.__qualname__ = f"{label}{base.__name__}"
        return Keyed

    classes = caching.CacheImpl._locator_classes  # shared by numba's cache implementations
    if not any(c.__name__.startswith(label) for c in classes):
        classes[:0] = [
            keyed(caching.UserProvidedCacheLocator),
            keyed(caching.InTreeCacheLocator),
        ]
    _KEYS.add(key)
    kernel_loading.tolerate_stale_indexes(_KEYS)
    return key


_KEYS: set[str] = set()  # the keys of the caches keyed here (`key_kernel_caches`)


def _key_kernel_caches() -> str:
    """Install the engine's keyed locators (once a process); returns the key."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    return key_kernel_caches(root, _sources_key(root), "IsaacSources")


SOURCES_KEY = _key_kernel_caches()
