"""The run directory: the one module that reads and writes a run's files.

Layout (the same for every method, so ``warp-critic meta-test RUN_DIR`` works on all of them)::

    RUN_DIR/
      .warp-critic-run   marker: {"kind", "method", "run_id"}; a directory is ours only if it has it
      .lock              {"pid", "host", "started"} while a process works in it
      config.json        the run's resolved config (the truth on --resume)
      checkpoint.pt      atomic; kind, method, iteration, networks, optimisers, RNG state
      metrics.jsonl      one JSON row per finished iteration
      recording.rrd      rerun recording of the whole run (every resumed segment merged in)

Rules:

* A new run claims a directory that does not exist or is empty (:meth:`RunDir.create`). One that
  holds a run of ours is refused (continue it with ``--resume``); anything else (someone's files) is
  never written into.
* One process at a time: :meth:`RunDir.lock` takes the directory's OS file lock
  (:class:`~warp_critic.running.locks.FolderLock`), which dies with its process; a directory locked by a
  live process is refused at once.
* Every write is atomic (temporary file in the same directory, then ``os.replace``); a failed
  write removes its temporary file.
* Checkpoints are loaded with ``torch.load(weights_only=True)``: a file that needs code to unpickle
  is refused, and its code never runs.
"""

from __future__ import annotations

import contextlib
import json
import uuid
from collections.abc import Iterable
from pathlib import Path

import torch

from warp_critic.core.errors import UserError, warn
from warp_critic.running.files import (
    MARKER,
    _writable_dir,
    atomic_torch_save,
    atomic_write_text,
)
from warp_critic.running.locks import FolderLock

RUN_KIND = "warp-critic/run-v1"
CHECKPOINT_KIND = "warp-critic/checkpoint-v1"
RECORDING = "recording.rrd"
SEGMENT = "recording.segment.rrd"
#: the note that stands in for a checkpoint a published archive leaves out (one line of text: why,
#: and how to get the run's weights back); :func:`load_checkpoint_file` reports it
OMITTED = "checkpoint.omitted"


class RunExistsError(UserError):
    """A new run was asked for in a directory that holds one (the CLI suggests resuming it)."""


class RunDir:
    """A run directory. Use :meth:`create` for a new run, :meth:`open` for an existing one."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self._lock = FolderLock(self.path, "run directory")
        self._created: list[Path] = []

    # -- claiming ---------------------------------------------------------------------------------
    @classmethod
    def create(cls, path: str | Path, method: str) -> RunDir:
        """Claim ``path`` for a new run (it must not exist, or be empty). Locks it."""
        rd = cls(path)
        p = rd.path
        if p.exists() and not p.is_dir():
            raise UserError(f"run directory {p}: is a file")
        if p.is_dir() and any(p.iterdir()):
            if (p / MARKER).is_file() or (p / "checkpoint.pt").is_file():
                raise RunExistsError(f"run directory {p}: already holds a run")
            raise UserError(
                f"run directory {p}: is not empty and not a warp-critic run; not writing into it"
            )
        _writable_dir(p, "run directory")
        rd._created = []  # the folders this run made, deepest first (removed again if it fails early)
        probe = p
        while not probe.exists():
            rd._created.append(probe)
            probe = probe.parent
        try:
            p.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise UserError(f"run directory {p}: cannot create ({e.strerror or e})") from None
        rd.lock()
        atomic_write_text(
            p / MARKER, json.dumps({"kind": RUN_KIND, "method": method, "run_id": uuid.uuid4().hex})
        )
        return rd

    @classmethod
    def open(cls, path: str | Path) -> RunDir:
        """An existing run directory of ours (read-only until :meth:`lock`)."""
        rd = cls(path)
        p = rd.path
        if not p.is_dir():
            raise UserError(
                f"{p}: run directory not found"
                if not p.exists()
                else f"{p}: is a file, not a run directory"
            )
        if not (p / MARKER).is_file() and not (p / "checkpoint.pt").is_file():
            raise UserError(f"{p}: no checkpoint.pt: not a warp-critic run directory")
        return rd

    def marker(self) -> dict:
        try:
            m = json.loads((self.path / MARKER).read_text())
        except (OSError, ValueError, UnicodeDecodeError):
            m = {}
        if not isinstance(m, dict):
            m = {}
        return m

    def ensure_marker(self, method: str) -> dict:
        """The marker (written for a run made before markers existed)."""
        m = self.marker()
        if m.get("kind") != RUN_KIND:
            m = {"kind": RUN_KIND, "method": method, "run_id": uuid.uuid4().hex}
            atomic_write_text(self.path / MARKER, json.dumps(m))
        return m

    def abandon(self) -> None:
        """Undo :meth:`create` after an early failure: remove what it made if nothing else was written."""
        self.unlock()
        with contextlib.suppress(OSError):
            (self.path / MARKER).unlink()
        for folder in self._created:
            try:
                folder.rmdir()  # only succeeds when empty
            except OSError:
                break

    # -- locking ----------------------------------------------------------------------------------
    def lock(self) -> None:
        """Take the directory's OS lock or refuse at once (a lock file nobody holds is taken over)."""
        self._lock.acquire()
        for stale in self.path.glob(".*.tmp"):  # half-written files of a killed process
            with contextlib.suppress(OSError):
                stale.unlink()

    def unlock(self) -> None:
        self._lock.release()

    # -- config -----------------------------------------------------------------------------------
    def save_config(self, config: dict) -> None:
        atomic_write_text(self.path / "config.json", json.dumps(config, indent=2))

    def saved_config(self) -> dict:
        """``config.json`` as written by :meth:`save_config`, or ``{}`` (missing or unreadable)."""
        try:
            config = json.loads((self.path / "config.json").read_text())
        except (OSError, ValueError, UnicodeDecodeError):
            return {}
        return config if isinstance(config, dict) else {}

    # -- checkpoints ------------------------------------------------------------------------------
    @property
    def checkpoint_path(self) -> Path:
        return self.path / "checkpoint.pt"

    def save_checkpoint(self, ckpt: dict) -> None:
        atomic_torch_save({"kind": CHECKPOINT_KIND, **ckpt}, self.checkpoint_path)

    def load_checkpoint(self, require: Iterable[str] = ()) -> dict:
        return load_checkpoint_file(self.checkpoint_path, require)

    # -- metrics ----------------------------------------------------------------------------------
    def read_metrics(self, upto: int) -> list[dict]:
        """Rows with ``iteration < upto``; a truncated last line (a killed write) is dropped."""
        path = self.path / "metrics.jsonl"
        if not path.exists():
            if upto > 0:
                warn(f"{path}: missing; the resumed run's metrics start at iteration {upto}")
            return []
        rows = []
        lines = path.read_text(errors="replace").splitlines()
        for i, line in enumerate(lines):
            if not line.strip():
                continue
            try:
                row = json.loads(line)
            except ValueError:
                if i == len(lines) - 1:
                    break  # the last line of a killed run
                raise UserError(f"{path}: line {i + 1} is not JSON") from None
            if isinstance(row, dict) and isinstance(row.get("iteration"), int):
                if row["iteration"] < upto:
                    _check_row(row, f"{path}: line {i + 1}")
                    rows.append(row)
            else:
                raise UserError(f"{path}: line {i + 1} is not a metrics row (no integer iteration)")
        return rows

    def open_metrics(self, history: list[dict]):
        """(Re)write ``metrics.jsonl`` with ``history`` (atomically); returns the file open for appending."""
        path = self.path / "metrics.jsonl"
        atomic_write_text(path, "".join(json.dumps(r) + "\n" for r in history))
        return open(path, "a")

    # -- recording segments -----------------------------------------------------------------------
    @property
    def recording_path(self) -> Path:
        return self.path / RECORDING

    def segment_path(self) -> Path:
        """Where this process records; merged into ``recording.rrd`` by :meth:`merge_recording`."""
        return self.path / SEGMENT

    def merge_recording(self) -> None:
        """Fold a segment (closed, or cut short by a killed process) into ``recording.rrd``; nothing
        unmerged is ever deleted (:func:`warp_critic.running.segments.merge_segment`)."""
        from warp_critic.running.segments import merge_segment

        merge_segment(self.recording_path, self.segment_path())


def _check_row(row: dict, where: str) -> None:
    """A metrics row read back must hold a numeric ``task_loss`` (a resumed run reports and plots it)."""
    loss = row.get("task_loss")
    if isinstance(loss, bool) or not isinstance(loss, (int, float)):
        raise UserError(f"{where}: task_loss must be a number (got {loss!r})")
    for key, value in row.items():
        if key in ("seconds", "iteration") and (
            isinstance(value, bool) or not isinstance(value, (int, float))
        ):
            raise UserError(f"{where}: {key} must be a number (got {value!r})")


def load_checkpoint_file(path: str | Path, require: Iterable[str] = ()) -> dict:
    """Load a checkpoint without running code from it, or raise a one-line :class:`UserError`."""
    path = Path(path)
    if not path.is_file():
        note = path.with_name(OMITTED)
        if note.is_file():
            why = " ".join(note.read_text(errors="replace").split())
            raise UserError(f"{path}: not in this archive ({why})")
        raise UserError(f"{path}: no checkpoint")
    try:
        ckpt = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # corrupt, not a torch file, or objects that need code to load
        text = str(e).lower()
        reason = (
            "it holds objects that need code to load (refused)"
            if "unsupported global" in text
            else f"not a readable checkpoint ({type(e).__name__})"
        )
        raise UserError(f"{path}: {reason}") from None
    if not isinstance(ckpt, dict) or ckpt.get("kind") != CHECKPOINT_KIND:
        raise UserError(f"{path}: not a warp-critic checkpoint")
    missing = [k for k in require if k not in ckpt]
    if missing:
        raise UserError(f"{path}: incomplete checkpoint (no {', '.join(missing)})")
    return ckpt


def load_checkpoint(run_dir: str | Path, require: Iterable[str] = ()) -> dict:
    """``RUN_DIR/checkpoint.pt`` of a run directory (see :meth:`RunDir.load_checkpoint`)."""
    return RunDir.open(run_dir).load_checkpoint(require)
