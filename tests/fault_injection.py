"""Fault injection for the kill-at-a-point tests (``test_faults.py``); nothing in the package loads it.

    python tests/fault_injection.py POINT:N ARGS...

runs ``warp-critic ARGS...`` in this process and kills it with SIGKILL (as a crash, an OOM kill or a
lost node would) at the ``N``-th occurrence of ``POINT``:

* ``<file name>`` (``checkpoint.pt``, ``config.json``, ...): an atomic write of that run-directory
  file, written to its temporary file but not yet moved into place (the worst moment to die);
* ``metrics-row``: a row of ``metrics.jsonl`` written and flushed, before that iteration's checkpoint.

It wraps ``os.replace`` (the last step of every atomic write in ``warp_critic.running.rundir``) and
the file ``RunDir.open_metrics`` returns, so the production write path carries no test hook.
"""

from __future__ import annotations

import os
import signal
import sys
from collections import Counter

METRICS_ROW = "metrics-row"


def install(point: str) -> None:
    """Arrange for this process to die at ``point`` (``NAME:N``, see the module docstring)."""
    target, _, n = point.rpartition(":")
    if not target or not n.isdigit():
        raise SystemExit(f"fault_injection: expected POINT:N, got {point!r}")
    count, seen = int(n), Counter()

    def reached(name: str) -> None:
        seen[name] += 1
        if name == target and seen[name] == count:
            os.kill(os.getpid(), signal.SIGKILL)

    real_replace = os.replace

    def replace(src, dst, *args, **kwargs):
        reached(os.path.basename(os.fspath(dst)))
        return real_replace(src, dst, *args, **kwargs)

    os.replace = replace

    from warp_critic.running.rundir import RunDir

    real_open_metrics = RunDir.open_metrics

    class _Metrics:
        """The metrics file, whose every flush (one row) is a fault point."""

        def __init__(self, f):
            self._f = f

        def flush(self) -> None:
            self._f.flush()
            reached(METRICS_ROW)

        def __getattr__(self, name):
            return getattr(self._f, name)

    def open_metrics(self, history):
        return _Metrics(real_open_metrics(self, history))

    RunDir.open_metrics = open_metrics


if __name__ == "__main__":
    install(sys.argv[1])
    from warp_critic.cli.main import main

    sys.exit(main(sys.argv[2:]))
