"""The library's INFO log records as ``warp-critic: ...`` lines on stderr, while a command runs.

Library modules never print; they log on their module logger (``logging.getLogger(__name__)``,
below ``warp_critic``), e.g. the derived defaults of a robot file at the start of a run. The command
line is what the user reads, so it states those records, one line each.
"""

from __future__ import annotations

import contextlib
import logging
import sys
from collections.abc import Iterator

LIBRARY = "warp_critic"


class _StderrLines(logging.Handler):
    """One ``warp-critic: <message>`` line per record on the stderr of the moment of the record."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            sys.stderr.write(f"warp-critic: {self.format(record)}\n")
            sys.stderr.flush()
        except Exception:  # logging's contract: a failing handler reports, it does not raise
            self.handleError(record)


@contextlib.contextmanager
def library_messages() -> Iterator[None]:
    """While inside: the library's INFO (and higher) records are printed; restored on exit (the
    command can run in-process, e.g. ``main([...])`` from a test, more than once)."""
    logger = logging.getLogger(LIBRARY)
    handler = _StderrLines(logging.INFO)
    previous = logger.level
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    try:
        yield
    finally:
        logger.removeHandler(handler)
        logger.setLevel(previous)
