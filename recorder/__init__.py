"""Recording ISAAC runs: MCAP (the exact, self-contained log) and Rerun (for looking).

`Recorder` is what the run loop uses; `LogReader` (recorder.reader) reads a log back.
docs/log-format.md describes the MCAP layout.

May import: the engine (`isaac.engine`), the scene contract (`isaac.scene`), `isaac.errors`,
`isaac.tuning` and the I/O libraries (mcap, protobuf, rerun-sdk, pyarrow). Never `replay` or
the app; the engine never imports this package.
"""

from recorder.recording import Recorder
from recorder.stats import check_finite, compute_stats

__all__ = ["Recorder", "LogReader", "check_finite", "compute_stats"]


def __getattr__(name):
    # the reader is imported lazily so `import recorder` stays light for the run loop
    if name == "LogReader":
        from recorder.reader import LogReader

        return LogReader
    raise AttributeError(name)
