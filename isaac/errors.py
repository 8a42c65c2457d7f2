"""One error hierarchy for the whole project.

User input is validated once, at the boundary (scene loading, log reading); the step trusts its
input. The command line turns any `IsaacError` into one line on stderr and a non-zero exit status
(2 for bad input), never a traceback.
"""

from __future__ import annotations


class IsaacError(Exception):
    """Base of every error this project raises on purpose."""

    exit_status = 2


class SceneError(IsaacError):
    """A scene file (or scene text) is invalid.

    The message is one line: ``FILE:LINE: KEY.PATH: what is wrong`` (the line where YAML gives one).
    """

    def __init__(
        self, what: str, *, source: str = "<scene>", line: int | None = None, path: str = ""
    ) -> None:
        self.what = what
        self.source = source
        self.line = line
        self.path = path
        where = source if line is None else f"{source}:{line}"
        key = f" {path}:" if path else ""
        super().__init__(f"{where}:{key} {what}")


class SimulationError(IsaacError):
    """The simulation cannot go on (e.g. a NaN or infinity appeared in the state).

    `step` is the step index at which it was detected and `body` the offending body's name.
    """

    exit_status = 3

    def __init__(self, message: str, *, step: int | None = None, body: str | None = None) -> None:
        self.step = step
        self.body = body
        super().__init__(message)


class LogError(IsaacError):
    """A log file (MCAP) is missing, unreadable, not an ISAAC log, or corrupt."""


class StateError(IsaacError, ValueError):
    """A record or a state array handed to a `Simulation` does not fit its scene (another body
    or joint count, another dt, a wrong shape or dtype, a value that is not finite).

    Raised before anything reaches compiled code; a ValueError too, for Python callers.
    """
