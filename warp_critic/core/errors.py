"""User-facing errors.

Every mistake a user can make (a bad path, a bad setting, an incompatible checkpoint) is raised as
:class:`UserError`. The CLI catches it, prints ``warp-critic: error: <message>`` on one line and exits
with code 2 -- never a traceback. Library users get an ordinary exception they can catch.

Library code never names a command-line flag: a bad setting raises :class:`FieldError` with the
config field's name (``worlds_per_goal``); the CLI maps it to the flag (``--worlds-per-goal``).
"""

from __future__ import annotations


class UserError(ValueError):
    """A mistake in the user's input; the message names the file/setting and the problem."""


class FieldError(UserError):
    """A bad value of one config field: ``field`` is its name, ``problem`` says what is wrong."""

    def __init__(self, field: str, problem: str):
        super().__init__(f"{field}: {problem}")
        self.field, self.problem = field, problem

    def __reduce__(self):  # a worker process's error reaches the driver whole (Ray, --jobs)
        return (type(self), (self.field, self.problem))


class SceneError(UserError):
    """A scene file that cannot be used (missing, not USD, no articulation, bad joint, ...)."""


class DivergenceError(RuntimeError):
    """A non-finite state or loss appeared during simulation or training.

    Attributes name where it happened so that the caller can report it and keep the last good
    checkpoint.
    """

    def __init__(self, message: str, *, world: int | None = None, step: int | None = None):
        super().__init__(message)
        self.world = world
        self.step = step
        self.checkpoint: int | None = None  # the last good checkpoint's iteration, where known


def warn(message: str) -> None:
    """One line ``warp-critic: warning: ...`` on stderr (something the user should know; work goes on)."""
    import sys

    sys.stderr.write(f"warp-critic: warning: {' '.join(message.split())}\n")
    sys.stderr.flush()
