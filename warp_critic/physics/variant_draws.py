"""Variant distributions for dynamics-randomised training (``--train-variants``).

Text form: link changes (:mod:`warp_critic.physics.link_changes`) whose value may be a range
``LO..HI``, joined by ``;``. Examples::

    ee.point-mass+=0..9                     # 0-9 kg added at the end-effector tip
    arm1.mass=0.5..6; arm2.mass=0.5..6      # both reacher links' masses, independently
    iiwa_link_7.stretch=0.2..2              # link 7 stretched to 0.2-2 m
    iiwa_link_7.mass=0..9:keep              # link 7's mass set, its inertia about the COM kept

Each range is drawn **uniformly and independently per world and per iteration**; a plain value is a
fixed change. The drawn changes follow the world's own variant (``--variant`` and friends), in the
order written.

Groups joined by ``|`` are alternatives: at iteration ``it`` world ``w`` takes only the changes of
group ``(w + it) mod G`` (``G`` groups), so every world and every goal sees each group in turn, and
the others' values are not drawn into it (NaN in :func:`draw`, ``null`` in the metrics). One factor
at a time, as the generalisation grids test them::

    arm1.mass=0.25..6; arm2.mass=0.25..6 | arm1.stretch=0.5..2; arm2.stretch=0.5..2

(all four at once put 6 kg on 2 m links next to 0.25 kg on 0.5 m ones, where the reacher's dt
diverged, measured).

The draws are a function of ``(seed, iteration)`` alone (a ``numpy`` PCG64 generator seeded with
``SeedSequence([seed, iteration, TAG])``), not of a generator's history: a resumed run redraws exactly
the variants the uninterrupted run drew, and the draws do not shift any other random stream.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace

import numpy as np

from warp_critic.core.errors import FieldError
from warp_critic.physics.link_changes import LinkChange, parse_changes
from warp_critic.physics.variants import Variant, is_finite

FIELD = "train_variants"
#: separates these draws from every other use of the seed
TAG = 0x5EED_DA7A
_ITEM = re.compile(
    r"^(?P<head>[^=]*?(?:\+=|\*=|=))\s*(?P<value>[^@:]+?)\s*(?P<tail>(?:@[^:]*)?(?::.*)?)$"
)


@dataclass(frozen=True)
class ChangeRange:
    """One link change whose value is drawn from ``U(lo, hi)`` (``lo == hi``: fixed)."""

    change: LinkChange  # with value lo
    lo: float
    hi: float
    group: int = 0  # alternatives joined by '|' (module docstring)

    def at(self, value: float) -> LinkChange:
        return replace(self.change, value=float(value))

    def text(self) -> str:
        """The text form (round-trips through :func:`parse_ranges`)."""
        if self.lo == self.hi:
            return self.change.text()
        c = self.change
        point = "" if c.point is None else "@" + ",".join(f"{x:g}" for x in c.point)
        mode = f":{c.mode}" if c.mode else ""
        return f"{c.link}.{c.what}{c.op}{self.lo:g}..{self.hi:g}{point}{mode}"


def _number(text: str, item: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise FieldError(FIELD, f"{item!r}: {text!r} is not a number or a range LO..HI") from None
    if not is_finite(value):
        raise FieldError(FIELD, f"{item!r}: {text!r} must be finite")
    return value


def parse_ranges(text: str | None) -> tuple[ChangeRange, ...]:
    """``'LINK.WHAT OP LO..HI[@POINT][:MODE]; ...'`` -> ranges (``()`` for ``None`` or blank).

    Raises:
        FieldError: on ``train_variants``, one line naming the item and the problem (a bad change at
            either end of its range, ``LO > HI``, not a number).
    """
    if text is None or not str(text).strip():
        return ()
    out = []
    for group, part in enumerate(str(text).split("|")):
        if not part.strip():
            raise FieldError(FIELD, f"{text!r}: an empty group between '|'")
        out += [replace(r, group=group) for r in _parse_group(part, text)]
    return tuple(out)


def _parse_group(part: str, text: str) -> list[ChangeRange]:
    out = []
    for item in (s.strip() for s in part.split(";")):
        if not item:
            raise FieldError(FIELD, f"{text!r}: an empty item between ';'")
        m = _ITEM.match(item)
        if m is None:
            raise FieldError(FIELD, f"{item!r}: expected LINK.WHAT=LO..HI, +=LO..HI or *=LO..HI")
        value = m["value"]
        if ".." in value:
            lo_text, _, hi_text = value.partition("..")
            lo, hi = _number(lo_text.strip(), item), _number(hi_text.strip(), item)
        else:
            lo = hi = _number(value, item)
        if lo > hi:
            raise FieldError(FIELD, f"{item!r}: the range {lo:g}..{hi:g} is empty (LO > HI)")
        ends = []
        for v in (lo, hi):
            try:
                (change,) = parse_changes(f"{m['head']}{v!r}{m['tail']}")
            except FieldError as e:  # its problem names the change at this end of the range
                raise FieldError(FIELD, e.problem) from None
            ends.append(change)
        out.append(ChangeRange(ends[0], lo, hi))
    return out


def groups(ranges: tuple[ChangeRange, ...]) -> int:
    """The number of alternative groups (1 without ``|``; 0 for no ranges)."""
    return 1 + max(r.group for r in ranges) if ranges else 0


def format_ranges(ranges: tuple[ChangeRange, ...]) -> str:
    parts = ["; ".join(r.text() for r in ranges if r.group == g) for g in range(groups(ranges))]
    return " | ".join(parts)


def draw(ranges: tuple[ChangeRange, ...], worlds: int, seed: int, iteration: int) -> np.ndarray:
    """``(worlds, len(ranges))`` values drawn for ``iteration`` of ``seed`` (module docstring); NaN
    where a range's group is not the world's at this iteration."""
    rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed, iteration, TAG])))
    u = rng.random((worlds, len(ranges)))
    lo = np.array([r.lo for r in ranges], dtype=np.float64)
    hi = np.array([r.hi for r in ranges], dtype=np.float64)
    values = lo + (hi - lo) * u
    if groups(ranges) > 1:
        world_group = (np.arange(worlds) + iteration) % groups(ranges)
        member = world_group[:, None] == np.array([r.group for r in ranges])[None, :]
        values = np.where(member, values, np.nan)
    return values


def with_draws(base: Variant, ranges: tuple[ChangeRange, ...], values) -> Variant:
    """``base`` followed by ``ranges`` at ``values`` (one value per range; a NaN value, a range of
    another group, is left out)."""
    drawn = tuple(r.at(v) for r, v in zip(ranges, values) if not np.isnan(v))
    return replace(base, changes=tuple(base.changes) + drawn)


def check_on_scene(scene, base: Variant, ranges: tuple[ChangeRange, ...]) -> None:
    """Apply both ends of every range, one group at a time, to one robot copy (unknown links,
    lengths without an end, negative masses): a :class:`FieldError` on ``train_variants`` for what
    does not apply."""
    for g in range(groups(ranges)):
        for end in ("lo", "hi"):
            values = [getattr(r, end) if r.group == g else np.nan for r in ranges]
            try:
                scene.world_builder(with_draws(base, ranges, values))
            except FieldError as e:
                if e.field != "variant":
                    raise
                raise FieldError(FIELD, e.problem) from None


def ranges_on_scene(scene, base: Variant, text: str) -> tuple[ChangeRange, ...]:
    """``text`` (the ``train_variants`` form) parsed and checked on ``scene`` from ``base``
    (:func:`check_on_scene`): a :class:`FieldError` on ``train_variants`` for text that names no
    range or does not apply."""
    ranges = parse_ranges(text)
    if not ranges:
        raise FieldError(FIELD, f"{text!r}: no range to draw")
    check_on_scene(scene, base, ranges)
    return ranges


__all__ = [
    "ChangeRange",
    "ranges_on_scene",
    "parse_ranges",
    "format_ranges",
    "groups",
    "draw",
    "with_draws",
    "check_on_scene",
    "FIELD",
]
