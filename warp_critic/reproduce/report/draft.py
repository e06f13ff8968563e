"""The report being written: its markdown lines, ``results.json`` dict, figures and claims,
shared by the report's sections (:mod:`~warp_critic.reproduce.report.write`, which renders them)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from warp_critic.reproduce.engine.stages import StageRecord


@dataclass
class Draft:
    """One report in the making. ``recs``: stage name -> its record (None: not complete);
    ``solved``: robot -> baseline -> per seed, whether it solved the training task."""

    out: Path
    figs: Path  # where the figures go
    recs: dict[str, StageRecord | None]
    config: Any  # the reproduce config (``command``, ``quick``)
    solved: dict[str, dict[str, list[bool]]]
    md: list[str] = field(default_factory=list)
    results: dict = field(default_factory=dict)
    figures: list[tuple[str, Path, str]] = field(default_factory=list)  # (title, png, sentence)
    claims: list[dict] = field(default_factory=list)  # rendered at the top of REPORT.md


def fmt(x: float) -> str:
    return f"{x:.3g}"


def rel(p: Path, out: Path) -> str:
    try:
        return str(Path(p).resolve().relative_to(out.resolve()))
    except ValueError:
        return str(p)
