"""The ``warp-critic`` command line (nothing below this package imports it).

In the ``warp-critic`` process itself (the console script), importing this package installs the
Ctrl-C / SIGTERM handlers (:mod:`warp_critic.cli.signals`, standard library only) before anything
else is imported, so that a signal at any moment of start-up is one line and exit code 130.
"""

# ruff: noqa: F401  (the TYPE_CHECKING imports name the lazy exports)

import os as _os
import sys as _sys

if _sys.argv and _os.path.basename(_sys.argv[0]) == "warp-critic":
    from warp_critic.cli import signals as _signals

    _signals.install()

from typing import TYPE_CHECKING  # noqa: E402

from warp_critic.core.exports import lazy_exports  # noqa: E402

if TYPE_CHECKING:  # the names for IDEs and type checkers (Newton's pattern); at run time
    # they load lazily, on first use
    from warp_critic.cli.main import main

__all__, __getattr__, __dir__ = lazy_exports(__name__, {"warp_critic.cli.main": ("main",)})
