"""Recording ISAAC runs: MCAP (the exact, self-contained log) and Rerun (for looking).

`Recorder` is what the run loop uses; `LogReader` (recorder.reader) reads a log back.
docs/log-format.md describes the MCAP layout.

May import: the engine (`isaac.engine`), the scene contract (`isaac.scene`), `isaac.errors`,
`isaac.tuning` and the I/O libraries (mcap, protobuf, rerun-sdk, pyarrow). Never `replay` or
the app; the engine never imports this package.
"""

__all__ = ["Recorder", "LogReader", "check_finite", "compute_stats"]

# imported lazily, so that `import recorder.spawn` (which `isaac run` does before it imports
# the engine) and `import recorder` stay light
_LAZY = {
    "Recorder": "recorder.recording",
    "LogReader": "recorder.reader",
    "check_finite": "recorder.stats",
    "compute_stats": "recorder.stats",
}


def __getattr__(name):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(name)
    import importlib

    return getattr(importlib.import_module(module), name)
