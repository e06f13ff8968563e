"""Ctrl-C and SIGTERM at any moment of a command: one line, exit code 130.

The handlers are installed first thing in :func:`warp_critic.cli.main.main`, before the heavy imports
(torch, Warp, USD), and stay installed until the process ends. What a signal does depends on the phase:

* ``starting`` (imports, Warp start-up; nothing written yet): exit at once. Raising into an import
  that runs inside C++ (torch's, pybind11) would abort the process instead;
* ``running`` (the command): raise ``KeyboardInterrupt``, so that a run closes its files, releases its
  lock and says what it kept (the command's own one line); a second signal meanwhile is ignored.
  The request is also recorded (:mod:`warp_critic.core.interrupts`): a raise that lands in a callback
  which swallows it is raised again at the run's next step;
* ``exiting`` (after the command, while the interpreter shuts down): exit at once.

This module imports only the standard library (and the stdlib-only ``core.interrupts``).
"""

from __future__ import annotations

import atexit
import os
import signal
import sys
import typing

from warp_critic.core import interrupts

EXIT_INTERRUPTED = 130
SIGNALS = (signal.SIGINT, signal.SIGTERM)

_phase = "off"
_said = False  # the command already wrote its line about the interruption
_note = ""  # what is true if a signal stops the command from now on (said in its line)


def _handler(signum, frame) -> None:
    global _phase
    if _phase == "running":
        _phase = "stopping"
        interrupts.request()  # the loops raise again at their next step if this raise is swallowed
        if interrupts.deferring():
            return  # a section that must not be cut short raises when it ends
        raise KeyboardInterrupt
    if _phase == "stopping":
        return  # the first signal's clean-up is under way
    stop_now()


def stop_now() -> None:
    """Write the one line (unless the command wrote it) and exit 130 without clean-up."""
    # stderr is silenced while Warp starts (core/runtime.py keeps a copy); not imported: not started
    runtime = sys.modules.get("warp_critic.core.runtime")
    fd = runtime.stderr_fd() if runtime is not None else 2
    if not _said:
        try:
            os.write(fd, f"warp-critic: interrupted{noted()}\n".encode(errors="replace"))
        except OSError:
            pass
    os._exit(EXIT_INTERRUPTED)


def note(text: str) -> None:
    """From now on a signal's line also says ``text`` (e.g. that an output was written whole)."""
    global _note
    _note = text


def noted() -> str:
    """``"; <note>"`` for the interruption line, or ``""``."""
    return f"; {_note}" if _note else ""


def install() -> dict:
    """Install the handlers (phase ``starting``); returns the previous ones for :func:`restore`
    (none when they were installed already, first thing in the process)."""
    global _phase, _said
    if _phase in ("starting", "running", "stopping") and signal.getsignal(SIGNALS[0]) is _handler:
        return {}
    _phase, _said = "starting", False
    note("")
    interrupts.clear()
    return {s: signal.signal(s, _handler) for s in SIGNALS}


def running() -> None:
    """The command starts: a signal now raises ``KeyboardInterrupt``."""
    global _phase
    _phase = "running"


def exiting(said: bool) -> None:
    """The command is over (``said``: it wrote its line about an interruption): a signal while the
    exit handlers run still ends the process with one line (:func:`stop_now`)."""
    global _phase, _said
    _phase, _said = "exiting", _said or said


def finish(code: int) -> typing.NoReturn:
    """End the console script with ``code`` once the command is over (:func:`exiting`): the exit
    handlers run now, while a signal still ends the process with its one line; then the process
    leaves without Python's teardown, which puts the default handlers back first, so a signal during
    it would kill the process without a line (exit 143). What the command wrote is closed already
    (every result is written atomically); the console streams are flushed here."""
    atexit._run_exitfuncs()
    for s in SIGNALS:
        signal.signal(s, signal.SIG_IGN)
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(code)


def restore(previous: dict) -> None:
    """Put the previous handlers back (an in-process call of ``main`` leaves nothing behind)."""
    global _phase
    _phase = "off"
    note("")
    interrupts.clear()
    for s, h in previous.items():
        signal.signal(s, h)


__all__ = [
    "EXIT_INTERRUPTED",
    "install",
    "running",
    "exiting",
    "finish",
    "restore",
    "stop_now",
    "note",
    "noted",
]
