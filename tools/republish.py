#!/usr/bin/env python
"""Republish the paper-setting report from a finished reproduce output, in one command.

    python tools/republish.py runs/paper                   # into docs/paper, against HEAD's report
    python tools/republish.py runs/paper --allow-carried   # a run with stages carried in

The steps, each the project's own tool:

1. refuse an output whose report names stages no call of its ledger completed (carried in with
   ``carry_stages.py restore``), unless ``--allow-carried``: a republished report is one run;
2. remove the destination's ``stages/`` and ``figures/`` (the replaced report's are in the history)
   and :func:`~warp_critic.reproduce.engine.publish.publish` the report and the stages it read;
3. write the generated blocks: the README's claims table (``readme_claims.py``), and in the
   destination's ``README.md`` the verdicts against the replaced report (``verdict_changes.py``;
   ``--before``, default ``HEAD:docs/paper/results.json``), what the folder keeps
   (``paper_contents.py``) and the ledger's calls (``ledger_calls.py``), each where its markers are;
4. print what to measure before committing: the folder's size and the clone's growth.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import sys
from pathlib import Path

PROG = "republish"
ROOT = Path(__file__).resolve().parents[1]
HERE = Path(__file__).resolve().parent


def _tool(name: str):
    """The module of ``tools/NAME.py`` (the generated blocks' writers)."""
    spec = importlib.util.spec_from_file_location(f"_republish_{name}", HERE / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def carried(out: Path) -> list[str]:
    """The stages ``out``'s report read that no call of its ledger completed."""
    try:
        ledger = json.loads((out / "results.json").read_text())["ledger"]
    except FileNotFoundError:
        raise ValueError(
            f"{out}: no results.json; run reproduce to write its report first"
        ) from None
    except (OSError, ValueError, KeyError, TypeError):
        raise ValueError(f"{out / 'results.json'}: not a reproduce report's results") from None
    return list(ledger.get("stages_before_ledger") or [])


def check_dest(dest: Path) -> None:
    """``dest`` is new, empty, or holds a published report (its ``results.json``): the replaced
    report's ``stages/`` and ``figures/`` are removed there, so a folder of other files is refused."""
    if dest.exists() and not dest.is_dir():
        raise ValueError(f"--dest {dest}: not a folder")
    if dest.is_dir() and any(dest.iterdir()) and not (dest / "results.json").is_file():
        raise ValueError(
            f"--dest {dest}: holds files but no published report (results.json); a republish "
            "replaces a report's stages/ and figures/, so give the report's folder or a new one"
        )


def check_full(out: Path, allow_quick: bool) -> None:
    """A ``--quick`` run's report is plumbing, not the paper's setting (its columns and seeds are
    not the paper's): refused unless ``allow_quick``."""
    try:
        quick = bool(json.loads((out / "results.json").read_text()).get("quick"))
    except (OSError, ValueError, AttributeError):
        return  # carried() says what is wrong with it
    if quick and not allow_quick:
        raise ValueError(
            f"{out}: a --quick run's report (plumbing, not the paper's setting); republish a full "
            "run (--allow-quick publishes it anyway)"
        )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n")[0])
    ap.add_argument("out", type=Path, help="a finished reproduce output folder")
    ap.add_argument(
        "--dest", type=Path, default=ROOT / "docs" / "paper", help="the folder to commit"
    )
    ap.add_argument(
        "--before",
        default="HEAD:docs/paper/results.json",
        help="the replaced report's results.json (a file, or REV:PATH from git)",
    )
    ap.add_argument("--readme", type=Path, default=ROOT / "README.md", help="its claims table")
    ap.add_argument(
        "--allow-carried", action="store_true", help="publish a run with carried stages"
    )
    ap.add_argument(
        "--allow-quick", action="store_true", help="publish a --quick run (plumbing checks)"
    )
    args = ap.parse_args(argv)
    from warp_critic.core.errors import UserError
    from warp_critic.core.generated import replace_block
    from warp_critic.reproduce.engine.publish import publish
    from warp_critic.reproduce.experiments.records import CARRY

    verdicts, contents, calls = (
        _tool(n) for n in ("verdict_changes", "paper_contents", "ledger_calls")
    )
    try:
        before = verdicts.load(args.before)  # read first: the destination is about to change
        extra = carried(args.out)
        check_full(args.out, args.allow_quick)
        check_dest(args.dest)
        if extra and not args.allow_carried:
            raise ValueError(
                f"{args.out}: {len(extra)} stage(s) of its report were carried in, not run by a "
                f"call of its ledger ({', '.join(sorted(extra))}); a republished report is one "
                "run (--allow-carried publishes it anyway)"
            )
        done = publish(args.out, args.dest, CARRY, replace=True)
    except (ValueError, UserError) as e:
        print(f"{PROG}: error: {e}", file=sys.stderr)
        return 2
    print(
        f"{PROG}: {args.dest}: the report and its {len(done.stages)} stages; "
        f"{len(done.omitted)} run(s) without their checkpoint"
    )
    page = args.dest / "README.md"
    text = page.read_text(encoding="utf-8") if page.is_file() else ""
    after = args.dest / "results.json"
    if verdicts.BEGIN in text:  # the replaced report as read before it was replaced
        shown = after.resolve().relative_to(ROOT) if after.resolve().is_relative_to(ROOT) else after
        body = verdicts.block(before, (str(shown), verdicts.load(str(after))[1]))
        page.write_text(replace_block(text, verdicts.BEGIN, verdicts.END, body, str(page)))
        print(f"{PROG}: {page}: the verdicts against {before[0]}")
    steps = []
    if calls.BEGIN in text:
        steps.append(("ledger_calls", calls, [str(args.dest), "--write", str(page)]))
    if contents.BEGIN in text:  # after the others: they change the page, not the folder's files
        steps.append(
            ("paper_contents", contents, ["--folder", str(args.dest), "--write", str(page)])
        )
    if args.readme.is_file():
        claims = ["--write", "--results", str(after), "--readme", str(args.readme)]
        steps.append(("readme_claims", _tool("readme_claims"), claims))
    for name, tool, tool_args in steps:
        if tool.main(tool_args) != 0:
            print(f"{PROG}: error: {name} failed (above); the report is published", file=sys.stderr)
            return 2
    size = sum(f.stat().st_size for f in args.dest.rglob("*") if f.is_file())
    print(
        f"{PROG}: {args.dest} is {size / 1e6:.1f} MB; after committing, the clone's growth: "
        "git rev-list --objects OLD..HEAD | git pack-objects --stdout -q | wc -c"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
