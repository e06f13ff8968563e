#!/usr/bin/env python
"""Kept for old command lines: ``warp-critic score`` (``warp-critic score --help``) runs the
paper's Table 1 protocol.

Usage::

    python tools/paper_table.py RUN_DIR... [flags]   # = warp-critic score RUN_DIR... [flags]
"""

from __future__ import annotations

import sys

from warp_critic.cli.main import main as warp_critic


def main(argv: list[str] | None = None) -> int:
    return warp_critic(["score", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":
    sys.exit(main())
