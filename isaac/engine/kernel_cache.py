"""numba's cache of the engine's kernels, keyed by the engine's sources.

Imported by every engine module that defines a cached kernel, before its kernels: numba checks
a cached kernel against its own source file alone, but the compiled driver holds the code of
every stage it calls. After an edit to geometry.py only, a cached driver went on running the
old physics (compiled and pure-Python runs disagreed at step 16 until the cache was deleted).
The locators installed here are numba's own (NUMBA_CACHE_DIR, then the in-tree __pycache__),
for isaac's files only, with `SOURCES_KEY` added to the source stamp numba compares.
(Not in isaac/engine/__init__: importing the records alone must not load numba.)
"""

from __future__ import annotations

from isaac import kernel_loading  # noqa: F401  (cached kernels load without numba's compiler)


def _sources_key(package_root) -> str:
    """sha256 (hex, 16 digits) of the sources every engine kernel may compile in: the files
    of isaac/engine, isaac/trig.py and isaac/collision_filter.py, by relative path and
    content."""
    import hashlib
    from pathlib import Path

    root = Path(package_root)
    h = hashlib.sha256()
    shared = [root / "trig.py", root / "collision_filter.py"]
    for path in sorted([*(root / "engine").rglob("*.py"), *shared]):
        h.update(path.relative_to(root).as_posix().encode())
        h.update(b"\0")
        h.update(path.read_bytes())
    return h.hexdigest()[:16]


def _key_kernel_caches() -> str:
    """Install the keyed locators (once a process); returns the key."""
    import os
    from pathlib import Path

    from numba.core import caching

    root = Path(__file__).resolve().parents[1]
    key = _sources_key(root)
    inside = str(root) + os.sep

    def keyed(base):
        class Keyed(base):
            @classmethod
            def from_function(cls, py_func, py_file):
                if not os.path.abspath(py_file).startswith(inside):
                    return None
                return super().from_function(py_func, py_file)

            def get_source_stamp(self):
                return (super().get_source_stamp(), key)

        Keyed.__name__ = Keyed.__qualname__ = f"IsaacSources{base.__name__}"
        return Keyed

    classes = caching.CacheImpl._locator_classes  # shared by numba's cache implementations
    if not any(c.__name__.startswith("IsaacSources") for c in classes):
        classes[:0] = [
            keyed(caching.UserProvidedCacheLocator),
            keyed(caching.InTreeCacheLocator),
        ]
    return key


SOURCES_KEY = _key_kernel_caches()
