#!/usr/bin/env python
"""Kept for old command lines: ``warp-critic identify`` (``warp-critic identify --help``) does it.

Usage::

    python tools/identify.py RUN --out RUN2 ...   # = warp-critic identify RUN --out RUN2 ...
"""

from __future__ import annotations

import sys

from warp_critic.cli.main import main as warp_critic


def main(argv: list[str] | None = None) -> int:
    return warp_critic(["identify", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":
    sys.exit(main())
