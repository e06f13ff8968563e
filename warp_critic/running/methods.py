"""The method registry: every method (ours and the baselines) is one :class:`Method` entry here.

The entries are registered by the methods themselves (``warp_critic/methods/``, a higher layer):
importing the package :mod:`warp_critic.methods` registers all of them, in :data:`Method.order`.
The command line, meta-test, the presets, the protocol, ``reproduce`` and its report read this
registry (through :func:`method` and :func:`methods`) instead of naming methods themselves, so a new
method is its module plus its entry.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from warp_critic.core.errors import UserError

#: ``(checkpoint, normaliser) -> (L, defaults)``: the loss ``L(q, qd, tau, g)`` a fresh policy
#: descends at meta-test and the run's meta-test defaults ``{"alpha": ..., "steps": ...}``
CriticLoader = Callable[[dict, Any], tuple[Any, dict]]


@dataclass(frozen=True)
class Method:
    """One method: what every layer above needs to train it, test its critic and report it."""

    name: str  # the CLI's and the checkpoint's name: "ours", "ddpg", ...
    order: int  # where it goes in tables, plots and stage lists (ours first)
    label: str  # in the report's tables and plots
    colour: str  # matplotlib colour of its curves
    config: type  # its config dataclass (a TaskConfig)
    train: Callable[..., Any]  # train(cfg, **kwargs) -> TrainResult
    critic_loader: CriticLoader  # what meta-test descends
    cite: str = ""  # the reference of its published settings, for help texts
    #: the named settings (config field -> value) of ``warp-critic``'s preset of this name, or None
    preset: dict[str, Any] | None = None
    preset_description: str = ""
    #: environment steps one training iteration takes, per world and control step
    #: (``samples_per_iteration(cfg) * worlds * horizon``); and how they are counted, in words
    samples_per_iteration: Callable[[Any], int] = field(default=lambda cfg: 1)
    samples_text: str = (
        "worlds x horizon per iteration: the exploration episodes (evaluation rollouts not counted)"
    )
    #: what a ``reproduce`` stage adds to each seed's summary from its metrics rows, or None
    run_summary: Callable[[list[dict]], dict] | None = None
    baseline: bool = True  # trained by ``warp-critic baseline NAME`` (else ``meta-train``)
    #: trained and reported by ``warp-critic reproduce`` unless selected otherwise
    reproduced_by_default: bool = True
    #: the paper's Table 1 row label (``paper (Table 1, DDPG)``), or None when the paper has none
    paper_label: str | None = None
    table_label: str | None = None  # the report's "paper: ..." row label


_REGISTRY: dict[str, Method] = {}


def register(entry: Method) -> Method:
    """Add ``entry`` (a method module calls this once, at import); a second name is a bug."""
    old = _REGISTRY.get(entry.name)
    if old is not None and old != entry:
        raise ValueError(f"method {entry.name!r} is registered twice")
    _REGISTRY[entry.name] = entry
    return entry


def methods(*, baseline: bool | None = None) -> tuple[Method, ...]:
    """Every registered method in :attr:`Method.order` (``baseline``: only those, or only not)."""
    found = sorted(_REGISTRY.values(), key=lambda m: m.order)
    return tuple(m for m in found if baseline is None or m.baseline == baseline)


def names(*, baseline: bool | None = None) -> tuple[str, ...]:
    """The names of :func:`methods`."""
    return tuple(m.name for m in methods(baseline=baseline))


def method(name: str) -> Method:
    """The entry of ``name``; an unknown name raises ``UserError`` naming the known ones."""
    entry = _REGISTRY.get(name)
    if entry is None:
        raise UserError(f"unknown method {name!r}; known: {', '.join(names()) or 'none'}")
    return entry
