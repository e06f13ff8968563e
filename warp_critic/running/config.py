"""Typed config fields: a dataclass field with its help text and valid range (:func:`spec`), the
range check over every field (:func:`check_fields`), JSON round-trips (:class:`SerializableConfig`),
and :func:`filled` for a field a scene default has set."""

from __future__ import annotations

import copy
import math
import typing
from dataclasses import asdict, field, fields
from typing import TYPE_CHECKING, Any, ClassVar, TypeVar

from warp_critic.core.errors import FieldError

if TYPE_CHECKING:
    pass

__all__ = ["SerializableConfig", "check_fields", "filled", "spec"]


def spec(default, help: str, *, gt=None, ge=None, le=None, lt=None, cap=None, choices=None):
    """A dataclass field with its help text and its valid range (checked by :func:`check_fields`).

    ``gt``/``ge``/``lt``/``le``: the range where the value means something; ``cap``: a sanity limit
    beyond which a value can only be a typo (it would not fit in memory or time).
    """
    meta = {"help": help}
    for key, value in (
        ("gt", gt),
        ("ge", ge),
        ("le", le),
        ("lt", lt),
        ("cap", cap),
        ("choices", choices),
    ):
        if value is not None:
            meta[key] = value
    if isinstance(default, list):
        return field(default_factory=lambda: copy.deepcopy(default), metadata=meta)
    return field(default=default, metadata=meta)


class SerializableConfig:
    """``to_dict`` / ``from_dict`` (unknown keys ignored) for config dataclasses."""

    __dataclass_fields__: ClassVar[dict[str, Any]]  # the subclasses are dataclasses

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict):
        names = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in d.items() if k in names})


def check_fields(cfg) -> None:
    """Check every field's type, finiteness and range from its :func:`spec`; raises :class:`FieldError`."""
    hints = typing.get_type_hints(type(cfg))
    for f in fields(cfg):
        value = getattr(cfg, f.name)
        if value is None:
            continue
        hint = hints[f.name]
        base = (
            next((a for a in typing.get_args(hint) if a is not type(None)), hint)
            if typing.get_args(hint)
            else hint
        )
        if typing.get_origin(base) is list:
            values = [x for g in value for x in (g if isinstance(g, list) else [g])]
        else:
            values = [value]
        for x in values:
            _check_value(f.name, x, f.metadata)


def _check_value(name: str, x, meta) -> None:
    if isinstance(x, bool) or isinstance(x, str):
        if "choices" in meta and x not in meta["choices"]:
            raise FieldError(name, f"must be one of {', '.join(meta['choices'])} (got {x!r})")
        return
    if not isinstance(x, (int, float)) or not math.isfinite(x):
        raise FieldError(name, f"must be a finite number (got {x!r})")
    if "cap" in meta and x > meta["cap"]:
        raise FieldError(
            name, f"must be <= {meta['cap']} (got {x!r}; larger values cannot be meant)"
        )
    lo = ("gt", meta["gt"]) if "gt" in meta else ("ge", meta["ge"]) if "ge" in meta else None
    hi = ("lt", meta["lt"]) if "lt" in meta else ("le", meta["le"]) if "le" in meta else None
    ok_lo = lo is None or (x > lo[1] if lo[0] == "gt" else x >= lo[1])
    ok_hi = hi is None or (x < hi[1] if hi[0] == "lt" else x <= hi[1])
    if ok_lo and ok_hi:
        return
    if lo and hi:
        raise FieldError(
            name,
            f"must be in {'(' if lo[0] == 'gt' else '['}{lo[1]}, {hi[1]}"
            f"{')' if hi[0] == 'lt' else ']'} (got {x!r})",
        )
    violated = lo if lo else hi
    assert violated is not None  # without bounds every value is in range
    key, bound = violated
    word = {"gt": ">", "ge": ">=", "lt": "<", "le": "<="}[key]
    raise FieldError(name, f"must be {word} {bound} (got {x!r})")


T = TypeVar("T")


def filled(value: T | None, name: str) -> T:
    """A field that :meth:`TaskConfig.fill_defaults` has set: ``None`` only before it (a scene default
    not yet read), which is a programming error here, named by the field."""
    if value is None:
        raise FieldError(name, "has no value: the config's defaults were not filled from its scene")
    return value


# ------------------------------------------------------------------------------------------------
# goals, torque bounds, memory
# ------------------------------------------------------------------------------------------------
