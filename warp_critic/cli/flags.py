"""Config dataclasses as command-line flags, and user input files (goals) as values.

One typed ``--flag`` per dataclass field, documented from the field's ``help`` metadata; lists are
comma-separated (``--max-torque 20,150``, ``--around 0,1``). Library code raises
:class:`~warp_critic.core.errors.FieldError` with a field name; :func:`flag_of` gives the flag that
sets it, so the CLI's message names what the user typed.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import re
import typing
from pathlib import Path

from warp_critic.core.errors import FieldError, UserError

_NUMBER = r"-?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"
#: A negative number, or a list of numbers (``,``/``;``-separated) whose first is negative.
NEGATIVE_VALUE = re.compile(rf"^-(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?(?:\s*[,;]\s*{_NUMBER})*$")


class Parser(argparse.ArgumentParser):
    """argparse, but errors are a single line ``warp-critic: error: [COMMAND: ]...`` and exit code 2
    (the same start as every other user error, whichever subcommand's parser found it).

    A value that starts with a negative number (``--max-torque -1,1``, ``--tip-offset -0.1,0,0``) is
    a value, not an unknown flag: argparse takes only a lone ``-1`` or ``-.5`` for a number.

    :attr:`refused` maps a flag this parser does not take to why (``--aux-lr``: "is a Meta-Critic
    setting; ddpg does not use it"): given anyway, it is that one line rather than argparse's
    "unrecognized arguments"."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = NEGATIVE_VALUE
        self.refused: dict[str, str] = {}

    def parse_known_args(self, args=None, namespace=None):
        # a subcommand's parser is called through this too (argparse's _SubParsersAction), so
        # its refused flags are named before the top parser reports them as unrecognized
        namespace, extras = super().parse_known_args(args, namespace)
        for arg in extras:
            flag = arg.split("=", 1)[0]
            if flag in self.refused:
                self.error(f"{flag} {self.refused[flag]}")
        return namespace, extras

    def error(self, message: str) -> typing.NoReturn:  # noqa: D401
        root, *command = self.prog.split()
        where = f"{' '.join(command)}: " if command else ""
        self.exit(2, f"{root}: error: {where}{' '.join(message.split())}\n")


class ToolParser(argparse.ArgumentParser):
    """argparse for the scripts in ``tools/``: ``PROG: error: ...`` on one line, exit code 2."""

    def error(self, message: str) -> typing.NoReturn:  # noqa: D401
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())}\n")


RUN_SETS_HELP = "NAME=RUN_DIR[,RUN_DIR...]: a named set of run directories (one recipe's seeds)"


def run_sets(parser: argparse.ArgumentParser, items: list[str]) -> dict[str, list[str]]:
    """A tool's ``NAME=RUN_DIR[,RUN_DIR...]`` arguments as ``{name: run dirs}`` in order; a bad
    item (no name, a name twice, a folder without ``checkpoint.pt``) is ``parser.error`` (exit 2)."""
    sets: dict[str, list[str]] = {}
    for item in items:
        name, sep, dirs = item.partition("=")
        if not sep or not name or not dirs:
            parser.error(f"{item!r}: expected NAME=RUN_DIR[,RUN_DIR...]")
        if name in sets:
            parser.error(f"{name!r}: named twice")
        sets[name] = [d for d in dirs.split(",") if d]
        for d in sets[name]:
            if not (Path(d) / "checkpoint.pt").is_file():
                parser.error(f"{d}: not a run directory (no checkpoint.pt)")
    return sets


def stage_on_sets(parser, stage, settings: dict, sets: dict[str, list[str]], device: str) -> dict:
    """A ``reproduce`` evaluation stage (``run_maps_stage``, ``run_tables_stage``) of ``settings``
    on a tool's run sets, in a scratch folder; the first set is the stage's ``ours`` (it sets the
    scene and goals). A user mistake it finds is ``parser.exit(2)`` with its one line."""
    import tempfile

    first = next(iter(sets))
    runs = {"ours": sets[first], **{k: v for k, v in sets.items() if k != first}}
    try:
        with tempfile.TemporaryDirectory() as tmp:
            return stage(Path(tmp), settings, runs, device, progress=False)
    except UserError as e:
        parser.exit(2, f"{parser.prog}: error: {user_message(e)}\n")
        raise  # unreachable: exit raises SystemExit


def comma_list(kind):
    """An argparse type: comma-separated values of ``kind`` (``int``, ``float`` or ``str``); ``''`` is
    the empty list (a tool's "all")."""
    one = str if kind is str else _number(kind)

    def parse(text: str) -> list:
        return [one(x.strip()) for x in text.split(",") if x.strip()]

    return parse


def _number(kind):
    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"invalid {kind.__name__} value: {text!r}") from None
        if kind is float and not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"must be a finite number (got {text!r})")
        return value

    parse.__name__ = kind.__name__
    return parse


def _number_list(kind):
    """:func:`comma_list` of numbers that must not be empty (a config field's list)."""
    values_of = comma_list(kind)

    def parse(text: str):
        values = values_of(text)
        if not values:
            raise argparse.ArgumentTypeError(
                f"expected comma-separated {kind.__name__}s, got {text!r}"
            )
        return values

    return parse


def flag_of(field: str) -> str:
    return "--" + field.replace("_", "-")


def add_dataclass_arguments(
    parser: argparse.ArgumentParser, cls, skip: tuple[str, ...] = ()
) -> None:
    """One typed ``--flag`` per field of ``cls``; the default shown is the field's."""
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        if f.name in skip:
            continue
        hint = hints[f.name]
        help_text = f.metadata.get("help", "")
        default = f.default if f.default is not dataclasses.MISSING else None
        if default is None:
            suffix = "" if "default" in help_text.lower() else " (default: the scene's)"
        else:
            suffix = f" (default: {default})"
        kwargs: dict[str, typing.Any] = dict(
            dest=f.name, default=argparse.SUPPRESS, help=f"{help_text}{suffix}"
        )
        if hint is bool:
            parser.add_argument(flag_of(f.name), action="store_true", **kwargs)
            continue
        args = typing.get_args(hint)
        base = next((a for a in args if a is not type(None)), hint) if args else hint
        if f.name == "goals":
            parser.add_argument(flag_of(f.name), type=str, metavar="GOALS", **kwargs)
        elif typing.get_origin(base) is list:
            inner = typing.get_args(base)[0]
            parser.add_argument(
                flag_of(f.name),
                type=_number_list(int if inner is int else float),
                metavar="A,B,..",
                **kwargs,
            )
        elif base in (int, float):
            parser.add_argument(
                flag_of(f.name), type=_number(base), metavar=base.__name__.upper(), **kwargs
            )
        elif base is str:
            choices = f.metadata.get("choices")
            parser.add_argument(
                flag_of(f.name), type=str, metavar="|".join(choices) if choices else "STR", **kwargs
            )
        else:  # pragma: no cover - programming error
            raise TypeError(f"unsupported field type {hint} for {f.name}")


def dataclass_from_args(cls, args: argparse.Namespace, **overrides):
    """``(config, given)``: the config from the parsed flags, and the names of the fields the user set."""
    names = {f.name for f in dataclasses.fields(cls)}
    values = {k: v for k, v in vars(args).items() if k in names}
    given = set(values) | set(overrides)
    values.update(overrides)
    if isinstance(values.get("goals"), str):
        values["goals"] = parse_goals(values["goals"])
    return cls(**values), given


def _is_existing_path(path: Path) -> bool:
    """``path.exists()``, False for a string the OS cannot take as a name (e.g. a long inline goal list)."""
    try:
        return path.exists()
    except (OSError, ValueError):
        return False


def parse_goals(spec: str | list | None, name: str = "goals") -> list[list[float]] | None:
    """Goals from an inline string ``'a,b;c,d'`` or a file (JSON list of lists, or one goal per line)."""
    if spec is None or isinstance(spec, list):
        return spec
    if not spec.strip():
        raise FieldError(
            name, "no goals given (expected inline '0.1,0.2;0.3,0.4' or a .json/.txt file)"
        )
    path = Path(spec)
    if path.suffix in (".json", ".txt", ".csv") or _is_existing_path(path):
        if path.is_dir():
            raise FieldError(name, f"{spec}: is a directory, not a goals file")
        if not path.is_file():
            raise FieldError(name, f"{spec}: file not found")
        try:
            text = path.read_text()
        except (OSError, UnicodeDecodeError) as e:
            raise FieldError(name, f"{spec}: not a text file ({type(e).__name__})") from None
        try:
            if path.suffix == ".json":
                goals = json.loads(text)
            else:
                goals = [
                    [float(x) for x in line.replace(",", " ").split()]
                    for line in text.splitlines()
                    if line.strip() and not line.lstrip().startswith("#")
                ]
        except (ValueError, RecursionError) as e:
            raise FieldError(
                name, f"{spec}: cannot parse goals ({' '.join(str(e).split())[:120]})"
            ) from None
        where = f"{spec}: "
    else:
        try:
            goals = [[float(x) for x in g.split(",")] for g in spec.split(";") if g.strip()]
        except ValueError:
            raise FieldError(name, f"{spec!r}: expected numbers like '0.1,0.2;0.3,0.4'") from None
        where = ""
    if (
        not isinstance(goals, list)
        or not goals
        or not all(isinstance(g, list) and g for g in goals)
    ):
        raise FieldError(
            name, f"{where}no goals given (expected a list of goals, each a list of numbers)"
        )
    if any(
        isinstance(x, (bool, list, dict, str)) or not isinstance(x, (int, float))
        for g in goals
        for x in g
    ):
        raise FieldError(name, f"{where}every goal value must be a number")
    try:
        goals = [[float(x) for x in g] for g in goals]
    except OverflowError:
        raise FieldError(
            name,
            f"{where}goal values must be finite numbers (got an integer too large for a float)",
        ) from None
    if len({len(g) for g in goals}) != 1:
        raise FieldError(
            name, f"{where}goals of different lengths {sorted({len(g) for g in goals})}"
        )
    bad = next(
        ((i, j, x) for i, g in enumerate(goals) for j, x in enumerate(g) if not math.isfinite(x)),
        None,
    )
    if bad is not None:
        i, j, x = bad
        raise FieldError(
            name, f"{where}goal values must be finite numbers (goal {i} joint {j} is {x!r})"
        )
    return goals


def user_message(
    e: UserError, positional: tuple[str, ...] = (), rename: dict[str, str] | None = None
) -> str:
    """The one-line message for the CLI: a field error names the flag (or the positional argument;
    ``rename`` maps a field to what the user typed instead)."""
    if isinstance(e, FieldError):
        who = (rename or {}).get(e.field) or (
            e.field if e.field in positional else flag_of(e.field)
        )
        return (
            f"{who} {e.problem}"
            if e.problem.startswith(("must", "needs", "may"))
            else f"{who}: {e.problem}"
        )
    return str(e)
