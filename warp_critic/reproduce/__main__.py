"""``python -m warp_critic.reproduce ...``: the ``reproduce`` command on its own (until ``warp-critic reproduce``
is registered in ``warp_critic/cli.py``); the same one-line errors and exit codes as ``warp-critic``."""

from __future__ import annotations

import sys


def main(argv: list[str] | None = None) -> int:
    from ..errors import UserError
    from ..flags import Parser
    from ..rundir import RunExistsError
    from . import cli

    parser = Parser(prog="warp-critic reproduce", description=cli.DESCRIPTION)
    cli.add_arguments(parser)
    args = parser.parse_args(argv)
    try:
        return cli.run_from_args(args)
    except RunExistsError as e:
        sys.stderr.write(f"warp-critic: error: {e}\n")
        return 2
    except UserError as e:
        sys.stderr.write(f"warp-critic: error: {' '.join(str(e).split())}\n")
        return 2
    except KeyboardInterrupt:
        sys.stderr.write("warp-critic: interrupted (run the same command again to resume)\n")
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
