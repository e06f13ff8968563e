"""Publish a finished report into a folder to commit (``docs/paper``), with the stages it read.

:func:`publish` copies a finished report (``REPORT.md``, ``results.json``, the ledger and the
figures) into a folder to commit, such as ``docs/paper``, and saves the stages it read into that
folder's ``stages/`` archive (:mod:`~warp_critic.reproduce.engine.carry`), so every number in the
report traces to a record there. A published folder is part of every clone for ever, so it keeps
less than a carried archive:

* a recipe's stage the rules name (:attr:`~.carry.CarryRules.record_only`) is published as its
  record alone;
* of another meta-training, only the checkpoints :attr:`~.carry.CarryRules.published_checkpoint`
  names; a note (:data:`~warp_critic.running.rundir.OMITTED`) stands in for each other one;
* its ledger names the output folder as the report's command did, never a machine's absolute path
  (:func:`portable_ledger`).
"""

from __future__ import annotations

import json
import shutil
from dataclasses import dataclass
from pathlib import Path

from warp_critic.core.errors import UserError
from warp_critic.reproduce.engine.carry import (
    ARCHIVE_STARTED,
    CarryRules,
    complete_stages,
    copy_stages,
)
from warp_critic.reproduce.engine.ledger import LEDGER
from warp_critic.reproduce.engine.ledger_text import out_as_shown, portable_ledger
from warp_critic.reproduce.engine.stages import MARKER, PACKED, STAGE_FILE


def _published_record(d: Path) -> bool:
    """Whether ``d`` is a stage record that :func:`publish` wrote beside the report before the
    records moved into ``stages/``: a ``stage.json`` and nothing but ``.json`` / ``.png`` files
    (never a carried stage, which holds its runs)."""
    if not (d / STAGE_FILE).is_file():
        return False
    return all(p.is_dir() or p.suffix in (".json", ".png") for p in d.rglob("*"))


#: the folder of a published report that holds the archive of the stages it read
ARCHIVE = "stages"


@dataclass(frozen=True)
class Published:
    """What :func:`publish` did."""

    stages: list[str]  # the stages the report read, archived in ``dest/stages``
    pruned: list[str]  # the stage records an earlier version wrote beside the report, removed
    omitted: list[str]  # the run directories (``STAGE/run/seedN``) published without checkpoint


def publish(out: Path, dest: Path, rules: CarryRules, replace: bool = False) -> Published:
    """Copy the report of ``out`` into ``dest``, for committing: ``REPORT.md``, ``results.json``,
    ``ledger.jsonl`` (where there is one) and ``figures/*.png``; and save each stage the report
    read (``results.json``'s ``stages``) into the archive ``dest/stages`` as
    :func:`~warp_critic.reproduce.engine.carry.save` does, so
    every number in the report traces to a record there (``tables-*/errors.json`` named in the
    report is ``dest/stages/tables-*/errors.json.xz``). A recipe's meta-training is archived as its
    record alone (``rules.record_only``; also one an earlier call archived whole), and another
    meta-training keeps the checkpoints ``rules.published_checkpoint`` names, each other one replaced
    by a note that says why (its record and config stay: the report reads no checkpoint).

    ``dest``'s figures that this report did not draw are removed, and so are the stage records an
    earlier version of this function wrote beside the report; anything else in ``dest`` (a README,
    the archive's other stages, search rows) is left alone. ``replace``: ``dest``'s ``stages/``
    and ``figures/`` go first, once ``out`` is checked (a republished report replaces the one
    before it, whose files the history keeps)."""
    from warp_critic.running.files import atomic_write_bytes

    out, dest = Path(out), Path(dest)
    if not (out / MARKER).is_file():
        raise UserError(f"{out}: not a reproduce output (no {MARKER})")
    try:
        results = json.loads((out / "results.json").read_text())
        stages = sorted(v["dir"] for v in results["stages"].values())
        report = (out / "REPORT.md").read_bytes()
    except FileNotFoundError as e:
        raise UserError(f"{e.filename}: missing; run reproduce to write its report first") from None
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        raise UserError(f"{out / 'results.json'}: not a reproduce report's results") from None
    for name in stages:
        if Path(name).name != name or not (out / name / STAGE_FILE).is_file():
            raise UserError(f"{out / 'results.json'}: names stage {name!r}, which {out} lacks")
    complete_stages(out, rules.check)  # an edited stage.json is refused before anything is written
    try:
        for replaced in (ARCHIVE, "figures") if replace else ():
            shutil.rmtree(dest / replaced, ignore_errors=True)
        (dest / ARCHIVE).mkdir(parents=True, exist_ok=True)
        archive = dest / ARCHIVE
        copy_stages(
            out, archive, rules, slim=True, pack=True, started=ARCHIVE_STARTED, only=set(stages)
        )
        omitted = []
        for name, data in complete_stages(archive, rules.check).items():  # now or earlier
            if name not in stages or data["group"] != rules.slim_group:
                continue
            if rules.record_only(data):
                for extra in sorted((archive / name).iterdir()):
                    if extra.name not in (STAGE_FILE, STAGE_FILE + PACKED):
                        shutil.rmtree(extra) if extra.is_dir() else extra.unlink()
            else:
                omitted += _omit_checkpoints(archive / name, data, rules)
        figures = sorted((out / "figures").glob("*.png"))
        (dest / "figures").mkdir(exist_ok=True)
        keep = {p.name for p in figures}
        for old in (dest / "figures").glob("*.png"):
            if old.name not in keep:
                old.unlink()
        for png in figures:
            atomic_write_bytes(dest / "figures" / png.name, png.read_bytes())
        pruned = [d.name for d in sorted(dest.iterdir()) if d.is_dir() and _published_record(d)]
        for name in pruned:
            shutil.rmtree(dest / name)
        if (out / LEDGER).is_file():  # the calls that made the report, and their times
            shown = out_as_shown(str(results.get("command", "")), out)
            ledger = portable_ledger((out / LEDGER).read_text(), out, shown)
            atomic_write_bytes(dest / LEDGER, ledger.encode())
        atomic_write_bytes(dest / "results.json", (out / "results.json").read_bytes())
        atomic_write_bytes(dest / "REPORT.md", report)  # last: a report only beside its files
    except OSError as e:
        raise UserError(f"{dest}: cannot write ({e.strerror or e})") from None
    return Published(stages, pruned, omitted)


def _omit_checkpoints(stage: Path, data: dict, rules: CarryRules) -> list[str]:
    """Drop the checkpoints of ``stage`` that ``rules.published_checkpoint`` does not keep, each
    replaced by the note :data:`~warp_critic.running.rundir.OMITTED` (written first: an interrupted
    call never leaves a run with neither); the run directories, relative to the archive."""
    from warp_critic.running.files import atomic_write_text
    from warp_critic.running.rundir import OMITTED

    dropped = []
    for ckpt in sorted(stage.rglob("checkpoint.pt")):
        run = ckpt.parent.relative_to(stage).as_posix()
        if rules.published_checkpoint(data, run):
            continue
        atomic_write_text(ckpt.with_name(OMITTED), rules.omitted_note.strip() + "\n")
        ckpt.unlink()
        dropped.append(f"{stage.name}/{run}")
    return dropped


__all__ = ["ARCHIVE", "Published", "portable_ledger", "publish"]
