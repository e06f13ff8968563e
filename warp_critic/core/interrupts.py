"""A stop request that survives a swallowed ``KeyboardInterrupt``.

A signal handler raises ``KeyboardInterrupt`` wherever the main thread happens to be. If that is a
finaliser, a weakref callback or a C extension's callback, Python prints "Exception ignored in ..."
and carries on: the run would go on forever with the handler already in its "stopping" phase (seen
in CI: a SIGTERM'd meta-train printed its KeyboardInterrupt as ignored and kept training).
So a handler also records the request here, and the long loops (:mod:`warp_critic.running.loop`,
the evaluation) call :func:`check` at each step boundary, which raises again.

Standard library only (the CLI's signal handlers import it before torch and Warp).
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

_requested = False
_deferring = 0  # depth of deferred() sections


@contextlib.contextmanager
def deferred() -> Iterator[None]:
    """A section a signal does not cut short (writing every seed's files of one iteration): the
    handler only records its request (:func:`deferring`), and :func:`check` raises right after."""
    global _deferring
    _deferring += 1
    try:
        yield
    finally:
        _deferring -= 1
    check()


def deferring() -> bool:
    """Whether a :func:`deferred` section runs (a signal handler then only calls :func:`request`)."""
    return _deferring > 0


def request() -> None:
    """A signal asked the process to stop (called by a signal handler)."""
    global _requested
    _requested = True


def clear() -> None:
    """Forget a request (a new in-process command starts)."""
    global _requested, _deferring
    _requested, _deferring = False, 0


def check() -> None:
    """Raise ``KeyboardInterrupt`` if a stop was requested; a no-op otherwise."""
    if _requested:
        raise KeyboardInterrupt


__all__ = ["request", "clear", "check", "deferred", "deferring"]
