"""Range checks of the analyses' settings, run before any work.

Each check raises :class:`~warp_critic.core.errors.FieldError` naming the setting; :func:`flag_errors`
turns that into a one-line :class:`~warp_critic.core.errors.UserError` naming the command-line flag.
"""

from __future__ import annotations

import math
import numbers
from contextlib import contextmanager
from pathlib import Path

from warp_critic.core.errors import FieldError, UserError
from warp_critic.core.memory import available_memory


def number(
    field: str,
    value,
    *,
    lo: float | None = None,
    hi: float | None = None,
    positive: bool = False,
    max_abs: float | None = None,
) -> float:
    """A finite float, optionally ``> 0``, within ``[lo, hi]`` and with ``|value| <= max_abs``."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise FieldError(field, f"must be a number, got {value!r}") from None
    if not math.isfinite(x):
        raise FieldError(field, f"must be a finite number, got {value!r}")
    if positive and x <= 0:
        raise FieldError(field, f"must be > 0, got {value!r}")
    if lo is not None and x < lo:
        raise FieldError(field, f"must be >= {lo:g}, got {value!r}")
    if hi is not None and x > hi:
        raise FieldError(field, f"must be <= {hi:g}, got {value!r}")
    if max_abs is not None and abs(x) > max_abs:
        raise FieldError(field, f"must be within +-{max_abs:g}, got {value!r}")
    return x


def integer(field: str, value, lo: int, hi: int | None = None) -> int:
    """An integer in ``[lo, hi]``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise FieldError(field, f"must be an integer, got {value!r}")
    n = int(value)
    if n < lo or (hi is not None and n > hi):
        raise FieldError(
            field,
            f"must be an integer >= {lo}"
            + (f" and <= {hi}" if hi is not None else "")
            + f", got {value!r}",
        )
    return n


def out_dir(field: str, path) -> Path:
    """An output folder that is a folder (or can be made one) we can write into."""
    from warp_critic.core.errors import UserError
    from warp_critic.running.files import check_output_dir

    try:
        return check_output_dir(path)
    except UserError as e:
        raise FieldError(field, str(e).removeprefix("output ")) from None


def not_owned(field: str, path) -> None:
    """For the ``analyze`` commands: ``path`` is not inside a reproduce output or a locked run."""
    from warp_critic.core.errors import UserError
    from warp_critic.running.locks import check_not_owned

    try:
        check_not_owned(path, "output")
    except UserError as e:
        raise FieldError(field, str(e).removeprefix("output ")) from None


def _size(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if n < 1024 or unit == "PiB":
            return f"{n:.3g} {unit}"
        n /= 1024
    return f"{n:.3g} PiB"  # pragma: no cover


def memory(field: str, value, need: float, device: str = "cpu", what: str = "") -> None:
    """Refuse a size setting whose estimated memory ``need`` (bytes) exceeds the free memory."""
    free = available_memory(device)
    if free is not None and need > free:
        raise FieldError(
            field,
            f"{value!r} needs about {_size(need)} of memory{what}, more than the "
            f"{_size(free)} available on {device}",
        )


def flag(field: str) -> str:
    """The command-line flag of a setting: ``plain_lr`` -> ``--plain-lr``."""
    return "--" + field.replace("_", "-")


@contextmanager
def flag_errors(flags: dict[str, str] | None = None):
    """Re-raise a :class:`FieldError` as a one-line :class:`UserError` naming the flag
    (``flags`` maps field names whose flag is not :func:`flag` of the name)."""
    try:
        yield
    except FieldError as e:
        name = (flags or {}).get(e.field, flag(e.field))
        raise UserError(f"{name}: {e.problem}") from None
