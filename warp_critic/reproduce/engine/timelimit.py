"""A reproduce call's time limit (``reproduce --hours H``): a sitting-sized call that wastes no stage.

A paper-setting reproduction takes tens of hours and is run in sittings: a batch job's wall-time
limit, a workday, a machine lent for a few hours and perhaps fresh the next time. A meta-training
that a sitting cuts off resumes from its checkpoints on the same machine, but on a fresh one (its
output folder carried by an archive of complete stages: ``tools/carry_stages.py``) it starts again:
its hours were lost. A meta-test loses at most the batch of worlds it was in (its finished batches
are kept and carried). So a call with a limit

* **starts a stage only if it is expected to end in time**, where an estimate exists: a
  meta-training by its time in a reference run (scaled by this folder's pace), or, part way, by its
  iterations left at its recent speed (:func:`~warp_critic.reproduce.status.estimator`). A
  meta-training without an estimate (no reference ran it with the same work per iteration) starts
  only while half the limit is left, so the second half goes to stages known to end in time. A
  meta-test, which keeps its finished batches, starts while time is left. A stage held back waits
  for the next call, and so do the stages that read it;
* **at the limit, stops what still runs** the way Ctrl-C does (each run closes its files; the
  same command goes on from there), and ends early when nothing more can start in time.

Either way the call raises :class:`TimeLimitReached` (a ``KeyboardInterrupt``: the ledger records
the call as interrupted); the command exits with :data:`EXIT_TIME_LIMIT`.
"""

from __future__ import annotations

import math
import os
import signal
import threading
import time
from collections.abc import Callable

__all__ = ["EXIT_TIME_LIMIT", "Estimate", "TimeLimit", "TimeLimitReached", "check_hours"]

#: the exit status of a call that its limit stopped (EX_TEMPFAIL: "try again later": the same
#: command goes on from where it stopped)
EXIT_TIME_LIMIT = 75

#: a stage's expected seconds and how they were reckoned (words); seconds ``nan``: a stage that
#: loses its work when cut off on a fresh machine but has no estimate; ``None``: one that keeps it
Estimate = Callable[[str], "tuple[float, str] | None"]


class TimeLimitReached(KeyboardInterrupt):
    """The call stopped at its limit, or ended early because no stage left could end in time."""


def check_hours(hours) -> float:
    """``hours`` as a positive finite number of hours; a one-line ``FieldError`` otherwise."""
    from warp_critic.core.errors import FieldError

    if isinstance(hours, bool) or not isinstance(hours, (int, float)):
        raise FieldError("hours", f"must be a number of hours (got {hours!r})")
    if not math.isfinite(hours) or hours <= 0:
        raise FieldError("hours", f"must be a positive, finite number of hours (got {hours!r})")
    return float(hours)


class TimeLimit:
    """``hours`` of wall time from construction; ``estimate(name)`` gives a stage's expected
    seconds (``None``: unknown, so not held back). ``clock`` and ``stop`` are for tests (``stop``:
    what happens at the limit; default: SIGINT to this process, which stops the running stages as
    Ctrl-C does)."""

    def __init__(
        self,
        hours: float,
        estimate: Estimate,
        clock: Callable[[], float] = time.monotonic,
        stop: Callable[[], None] | None = None,
    ):
        self.hours = check_hours(hours)
        self.estimate, self.clock = estimate, clock
        self.end = clock() + 3600.0 * self.hours
        self.held: dict[str, str] = {}  # stage -> why it was not started
        self.reached = False  # the limit came while stages ran
        self._stop = stop or _interrupt_self
        self._timer: threading.Timer | None = None

    def left(self) -> float:
        """Seconds left (never below 0)."""
        return max(0.0, self.end - self.clock())

    def fits(self, name: str) -> bool:
        """Whether stage ``name`` may start now: time is left and its expected time (where known)
        is no more than that. A stage that does not fit is entered in :attr:`held`."""
        left = self.left()
        if left <= 0:
            self.held[name] = "no time left"
            return False
        guess = self.estimate(name)
        whole = 3600.0 * self.hours
        if guess is not None and math.isnan(guess[0]):  # a meta-training of unknown length
            if left >= 0.5 * whole:
                self.held.pop(name, None)
                return True
            self.held[name] = f"{guess[1]}, and less than half of --hours {self.hours:g} is left"
            return False
        if guess is None or guess[0] <= left:
            self.held.pop(name, None)
            return True
        self.held[name] = f"expected {guess[0] / 60:.0f} min ({guess[1]}), " + (
            f"more than the whole --hours {self.hours:g}"
            if guess[0] > whole
            else f"{left / 60:.0f} min left"
        )
        return False

    def _fire(self) -> None:
        self.reached = True
        self._stop()

    def start(self) -> None:
        """Arm the stop at the limit (a daemon timer thread)."""
        self._timer = threading.Timer(self.left(), self._fire)
        self._timer.daemon = True
        self._timer.start()

    def cancel(self) -> None:
        """Disarm it (the stages ended first)."""
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def outcome(self, left: list[str], kept: str = "") -> TimeLimitReached:
        """The exception that ends a call it stopped, with ``left``, the stages not complete, and
        ``kept``, what a stopped run said it kept."""
        why = (
            f"the --hours {self.hours:g} limit was reached"
            if self.reached
            else f"no stage left could end within --hours {self.hours:g}"
        )
        held = "".join(f"; {n} not started: {w}" for n, w in self.held.items() if n in left)
        kept = kept.removeprefix("interrupted").lstrip("; ")
        return TimeLimitReached(
            f"{why}, {len(left)} stage(s) left{held}" + (f"; {kept}" if kept else "")
        )


def _interrupt_self() -> None:
    os.kill(os.getpid(), signal.SIGINT)
