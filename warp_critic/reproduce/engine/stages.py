"""The stage runner: one sub-directory per stage keyed by the hash of its settings, ``stage.json`` last.

A stage directory ``OUT/<name>-<hash>`` is complete when it holds ``stage.json`` (written atomically,
after everything else): a complete stage is skipped. An incomplete one is re-entered: training stages
resume their run directories (``resume=True``), the meta-tests go on from the batches kept in their
:data:`~warp_critic.reproduce.engine.stage.PROGRESS` folder (removed once the stage is complete), the
others recompute their files. A changed setting
changes the hash, so only the stages that depend on it run again, into new directories; old
directories are never touched.

The output folder carries :data:`MARKER`; a non-empty folder without it is refused (it is not ours).
One driver at a time: the folder's OS lock (``.lock``) is held while a driver works in it.
"""

from __future__ import annotations

import json
import lzma
import shutil
import sys
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from warp_critic.core.errors import FieldError, UserError
from warp_critic.reproduce.engine.stage import PROGRESS, dir_name
from warp_critic.running.files import atomic_write_text, check_output_dir
from warp_critic.running.locks import LOCK, REPRODUCE_MARKER, FolderLock, check_not_owned

MARKER = REPRODUCE_MARKER
STAGE_FILE = "stage.json"
STAGE_KIND = "warp-critic/reproduce-stage-v1"
#: the suffix of an xz-compressed text file in a carried archive (``stage.json.xz``)
PACKED = ".xz"


def prepare_out(out: Path) -> Path:
    """Check ``out`` (before any work) and mark it as a reproduce output; returns it."""
    out, lock = claim_out(out)
    lock.release()
    return out


def claim_out(out: Path) -> tuple[Path, FolderLock]:
    """Check ``out`` (before any work), lock it (one reproduce driver per output folder: a second
    one is refused while the first lives) and mark it as a reproduce output."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise FieldError("out", f"{out}: is a file, not a directory")
    try:
        check_not_owned(out, "", reproduce_ok=True)  # not inside a live run or another output
    except UserError as e:
        raise FieldError("out", str(e).strip()) from None
    _check_ours(out)
    try:
        check_output_dir(out, "")
    except UserError as e:
        raise FieldError("out", str(e).strip()) from None
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise FieldError("out", f"{out}: cannot create ({e.strerror or e})") from None
    lock = FolderLock(out, "reproduce output")
    try:
        lock.acquire()
    except UserError as e:
        raise FieldError("out", str(e).removeprefix("reproduce output ")) from None
    try:
        _check_ours(out)  # again, under the lock
        if not (out / MARKER).is_file():
            atomic_write_text(
                out / MARKER, json.dumps({"kind": "warp-critic/reproduce-output-v1"}) + "\n"
            )
    except BaseException:
        lock.release()
        raise
    return out, lock


def _check_ours(out: Path) -> None:
    if out.is_dir() and not (out / MARKER).is_file():
        if any(p.name != LOCK for p in out.iterdir()):
            raise FieldError(
                "out",
                f"{out}: is not empty and not a reproduce output (no {MARKER}); not writing into it",
            )


def read_stage(d: Path) -> dict | None:
    """The ``stage.json`` of a complete stage directory, or ``None``; in a carried archive
    (:mod:`~warp_critic.reproduce.engine.carry`) the record is xz-compressed, ``stage.json.xz``."""
    try:
        packed = Path(d) / (STAGE_FILE + PACKED)
        text = (
            lzma.decompress(packed.read_bytes()).decode()
            if packed.is_file()
            else (Path(d) / STAGE_FILE).read_text()
        )
        data = json.loads(text)
    except (OSError, ValueError, UnicodeDecodeError, lzma.LZMAError):
        return None
    return data if isinstance(data, dict) and data.get("kind") == STAGE_KIND else None


#: what makes a complete stage's record unusable, told by the stages' owner: ``(group, stage.json)
#: -> why, or None`` (the engine itself checks only what every record holds: seconds, a result)
Check = Callable[[str, dict], str | None]


def read_complete(d: Path, group: str, check: Check) -> dict | None:
    """The ``stage.json`` of a complete stage of ``group``, ``None`` when the stage is not complete;
    a ``stage.json`` edited or damaged so that it cannot be used (:func:`record_problem`, then
    ``check``) is a one-line :class:`UserError`."""
    data = read_stage(d)
    problem = None if data is None else record_problem(data) or check(group, data)
    if problem is not None:
        packed = Path(d) / (STAGE_FILE + PACKED)
        raise UserError(
            f"{packed if packed.is_file() else Path(d) / STAGE_FILE}: edited or damaged "
            f"({problem}); remove it to run the stage again"
        )
    return data


def record_problem(data: dict) -> str | None:
    """What makes any complete stage's ``stage.json`` unusable: no seconds, no result."""
    if not isinstance(data.get("seconds"), (int, float)):
        return "no number of seconds"
    if not isinstance(data.get("result"), dict):
        return "no result"
    return None


@dataclass
class StageRecord:
    """What the report needs to know about one stage (sub-stage) of this call."""

    group: str  # toy, landscape, metatrain, maps, tables
    name: str  # e.g. metatrain-kuka-ours
    dir: Path
    data: dict  # stage.json
    ran: bool = False  # ran (or resumed) in this call; False: skipped as complete
    seconds_this_call: float = 0.0


def _to_stderr(line: str) -> None:
    sys.stderr.write(line + "\n")
    sys.stderr.flush()


@dataclass
class Runner:
    """Records the stages of one call in ``out``; ``log`` gets one line per stage (stderr by default)."""

    out: Path
    check: Check  # what makes a complete record unusable (:func:`read_complete`)
    total: int = 0  # stages to run in this call (set once the complete ones are known)
    log: Callable[[str], None] = field(default=_to_stderr)
    records: dict[str, StageRecord] = field(default_factory=dict)
    t0: float = field(default_factory=time.perf_counter)
    done: int = 0  # stages that ran to completion in this call

    def stage_dir(self, name: str, h: str) -> Path:
        return self.out / dir_name(name, h)

    def complete(self, group: str, name: str, h: str) -> StageRecord | None:
        """The record of a stage already complete in ``out`` (skipped), or ``None``."""
        d = self.stage_dir(name, h)
        data = read_complete(d, group, self.check)
        if data is None:
            return None
        self.log(f"reproduce: {name}: complete, skipped ({d.name})")
        rec = StageRecord(group, name, d, data, ran=False)
        self.records[name] = rec
        return rec

    def finish(
        self,
        group: str,
        name: str,
        h: str,
        settings: Any,
        result: dict,
        seconds: float,
        depends: Mapping[str, str] | None = None,
    ) -> StageRecord:
        """Record a stage that ran: ``stage.json`` is written last, atomically (then it is complete)."""
        d = self.stage_dir(name, h)
        data = {
            "kind": STAGE_KIND,
            "stage": name,
            "group": group,
            "hash": h,
            "settings": settings,
            "depends": dict(depends or {}),
            "seconds": seconds,
            "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            "result": result,
        }
        atomic_write_text(d / STAGE_FILE, json.dumps(data, indent=1, default=_jsonable) + "\n")
        shutil.rmtree(d / PROGRESS, ignore_errors=True)  # complete: its progress is the record now
        rec = StageRecord(group, name, d, data, ran=True, seconds_this_call=seconds)
        self.records[name] = rec
        self.done += 1
        minutes = (time.perf_counter() - self.t0) / 60
        self.log(
            f"reproduce: {name} done in {seconds / 60:.1f} min ({self.done} of {self.total} stages of this "
            f"call, {minutes:.1f} min elapsed)"
        )
        return rec


def _jsonable(x):
    import numpy as np

    if isinstance(x, Path):
        return str(x)
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, tuple):
        return list(x)
    raise TypeError(f"not JSON serialisable: {type(x).__name__}")
