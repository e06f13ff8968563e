"""The contract of a report section: a pure ``compute`` from the stage records to a JSON-able part
of ``results.json``, and a pure ``render`` from that part to the markdown of ``REPORT.md``.

A section is a :class:`Section` ``(name, compute, render)``:

* ``compute(inputs: Inputs) -> dict``: reads the stage records in ``inputs.recs`` (and the files
  they name), writes the section's figures into ``inputs.figures_dir`` (the only side effect), and
  returns :func:`part`'s dict: ``view`` (what ``render`` needs: numbers, verdicts, labels; stored in
  ``results.json`` under ``sections.<name>``), ``results`` (top-level ``results.json`` keys it
  sets), ``claims`` (rows of the claims table) and ``figures`` (``{"title", "file", "sentence"}``,
  ``file`` relative to the output folder).
* ``render(view) -> list[str]``: the section's markdown lines from ``view`` as read back from
  ``results.json`` (keys strings, tuples lists); it reads no file and no record.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

from warp_critic.reproduce.engine.stages import StageRecord


@dataclass(frozen=True)
class Inputs:
    """What a section's ``compute`` reads. ``recs``: stage name -> its record (None: not
    complete); ``solved``: robot -> baseline -> per seed, whether it solved the training task;
    ``quick``: the plumbing-check settings; ``out``: the output folder; ``figures_dir``: where the
    section writes its figures (inside ``out``)."""

    recs: Mapping[str, StageRecord | None]
    solved: dict[str, dict[str, list[bool]]]
    quick: bool
    out: Path
    figures_dir: Path

    def figure(self, title: str, png: Path, sentence: str) -> dict:
        """A figures entry of ``results.json``: ``png`` relative to the output folder."""
        return {"title": title, "file": rel(png, self.out), "sentence": sentence}


class Section(NamedTuple):
    """One section of the report: its name (its key under ``results.json``'s ``sections``), its
    ``compute(Inputs) -> dict`` (:func:`part`) and its ``render(view) -> list[str]``."""

    name: str
    compute: Callable[[Inputs], dict]
    render: Callable[[Any], list[str]]


def part(
    view: Any,
    *,
    results: dict | None = None,
    claims: list[dict] | None = None,
    figures: list[dict] | None = None,
) -> dict:
    """A section's computed part (module docstring)."""
    return {
        "view": view,
        "results": results or {},
        "claims": claims or [],
        "figures": figures or [],
    }


def fmt(x: float) -> str:
    return f"{x:.3g}"


def rel(p: Path, out: Path) -> str:
    try:
        return str(Path(p).resolve().relative_to(out.resolve()))
    except ValueError:
        return str(p)
