"""User-facing errors.

Every mistake a user can make (a bad path, a bad flag value, an incompatible checkpoint) is raised
as :class:`UserError`. The CLI catches it, prints ``warp-critic: error: <message>`` on one line and
exits with code 2 -- never a traceback. Library users get an ordinary exception they can catch.
"""

from __future__ import annotations


class UserError(ValueError):
    """A mistake in the user's input; the message names the file/flag and the problem."""


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
