"""Carry the finished batches of a stage that is part way, so that a stage longer than a sitting goes
on from an archive on a fresh machine.

A long meta-test keeps, in its stage's :data:`~warp_critic.reproduce.engine.stage.PROGRESS` folder,
one ``batch-B.pt`` per finished batch of worlds (a few kB: its errors and step sizes) and the
policies of the batch it is in (``batch-B-partial.pt``, megabytes, rewritten every few minutes;
:mod:`~warp_critic.reproduce.experiments.descent`). An archive
(:mod:`~warp_critic.reproduce.engine.carry`) keeps the finished batches of each stage that is part
way, in ``<archive>/<stage dir>/progress/``, and never a partial one: a sitting that ends loses at
most the batch it was in. Every batch file names the fingerprint of its batch's inputs, so one of
other inputs is never used (the descent checks, and starts that batch again).
"""

from __future__ import annotations

import re
from pathlib import Path

from warp_critic.core.errors import UserError
from warp_critic.reproduce.engine.stage import PROGRESS

#: a finished batch's file (a running batch's is ``batch-B-partial.pt``, never carried)
FINISHED = re.compile(r"batch-[0-9]+\.pt")


def finished_batches(stage: Path) -> list[Path]:
    """The finished batch files of the stage directory ``stage``, by name."""
    folder = Path(stage) / PROGRESS
    if not folder.is_dir():
        return []
    return sorted(p for p in folder.iterdir() if p.is_file() and FINISHED.fullmatch(p.name))


def progress_only(stage: Path) -> bool:
    """Whether ``stage`` is what :func:`copy_batches` writes into an archive: a folder that holds
    nothing but finished batches (no record: the stage is not complete)."""
    stage = Path(stage)
    if not stage.is_dir():
        return False
    inside = [p for p in stage.rglob("*") if p.is_file()]
    return all(p.parent == stage / PROGRESS and FINISHED.fullmatch(p.name) for p in inside)


def copy_batches(src: Path, dst: Path, names: list[str], replace: bool) -> list[str]:
    """Copy the finished batches of each stage ``src/NAME`` (``NAME`` in ``names``) that
    ``dst/NAME/progress`` lacks; ``replace``: also those it holds with other bytes (into an
    archive: the output replaced a batch of other inputs; never out of one, where the output's
    own file is the newer). Returns the names of the stages something was copied for. Each file
    is written atomically: an interrupted call leaves no torn batch."""
    from warp_critic.running.files import atomic_write_bytes

    copied = []
    for name in names:
        new = False
        for path in finished_batches(Path(src) / name):
            target = Path(dst) / name / PROGRESS / path.name
            data = path.read_bytes()
            if target.is_file() and (not replace or target.read_bytes() == data):
                continue
            try:
                target.parent.mkdir(parents=True, exist_ok=True)
                atomic_write_bytes(target, data)
            except OSError as e:
                raise UserError(f"{target}: cannot write ({e.strerror or e})") from None
            new = True
        if new:
            copied.append(name)
    return copied


def partway_stages(folder: Path, complete: set[str]) -> list[str]:
    """The stage directories of ``folder`` that are not in ``complete`` and hold finished
    batches."""
    folder = Path(folder)
    if not folder.is_dir():
        return []
    return [
        d.name
        for d in sorted(folder.iterdir())
        if d.is_dir() and d.name not in complete and finished_batches(d)
    ]


__all__ = ["FINISHED", "copy_batches", "finished_batches", "partway_stages", "progress_only"]
