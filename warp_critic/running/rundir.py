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

* A new run claims a directory that does not exist, is empty, or is a finished/aborted run of ours
  started anew is refused: anything else (someone's files) is never overwritten.
* One process at a time: :meth:`RunDir.lock` refuses a directory locked by a live process at once; a
  lock left by a dead process on this host is taken over with a warning.
* Every write is atomic (temporary file in the same directory, then ``os.replace``); a failed
  write removes its temporary file.
* Checkpoints are loaded with ``torch.load(weights_only=True)``: a file that needs code to unpickle
  is refused, and its code never runs.
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import subprocess
import sys
import tempfile
import time
import uuid
from collections.abc import Iterable
from pathlib import Path

import torch

from warp_critic.core.errors import UserError, warn

MARKER = ".warp-critic-run"
LOCK = ".lock"
RUN_KIND = "warp-critic/run-v1"
CHECKPOINT_KIND = "warp-critic/checkpoint-v1"
RUN_FILES = ("config.json", "checkpoint.pt", "metrics.jsonl", "recording.rrd", MARKER)
RECORDING = "recording.rrd"
SEGMENT = "recording.segment.rrd"


class RunExistsError(UserError):
    """A new run was asked for in a directory that holds one (the CLI suggests resuming it)."""


# ------------------------------------------------------------------------------------------------
# atomic writes
# ------------------------------------------------------------------------------------------------

FAULT_ENV = "WARP_CRITIC_FAULT"  # fault injection for the tests: "<file name>:<n>"
_writes: dict[str, int] = {}


def _fault_point(name: str) -> None:
    """Kill this process (SIGKILL, as a crash or an OOM kill would) at the n-th write of ``name`` when
    ``$WARP_CRITIC_FAULT`` asks for it: how the fault tests interrupt a run at an exact point."""
    spec = os.environ.get(FAULT_ENV)
    if not spec:
        return
    _writes[name] = _writes.get(name, 0) + 1
    target, _, n = spec.rpartition(":")
    if target == name and n.isdigit() and _writes[name] == int(n):
        import signal

        os.kill(os.getpid(), signal.SIGKILL)


_UMASK = os.umask(0)
os.umask(_UMASK)


@contextlib.contextmanager
def _atomic(path: Path):
    """Yield a temporary path next to ``path``; on success it replaces ``path``, on failure it is removed."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    os.chmod(tmp, 0o666 & ~_UMASK)  # an ordinary file, not mkstemp's private 0600
    try:
        yield Path(tmp)
        _fault_point(path.name)  # written, not yet in place: the worst moment to die
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def _write_atomically(path: Path, write) -> None:
    """``write(tmp)`` fills a temporary file that then replaces ``path``; a failure is one line."""
    try:
        with _atomic(path) as tmp:
            write(tmp)
    except OSError as e:
        raise UserError(f"{path}: cannot write ({e.strerror or e})") from None


def atomic_write_text(path: Path, text: str) -> None:
    _write_atomically(path, lambda tmp: tmp.write_text(text))


def atomic_write_bytes(path: Path, data: bytes) -> None:
    _write_atomically(path, lambda tmp: tmp.write_bytes(data))


def atomic_torch_save(obj, path: Path) -> None:
    _write_atomically(path, lambda tmp: torch.save(obj, tmp))


# ------------------------------------------------------------------------------------------------
# output locations
# ------------------------------------------------------------------------------------------------


def _writable_dir(path: Path, what: str) -> None:
    """``path`` exists as a directory we can write into, or can be created."""
    probe = Path(path)
    while not probe.exists() and probe != probe.parent:
        probe = probe.parent
    if not probe.is_dir():
        raise UserError(f"{what} {path}: {probe} is a file, not a directory")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise UserError(f"{what} {path}: {probe} is not writable")


def check_output_dir(path: str | Path, what: str = "output") -> Path:
    """An output folder that is a folder (or can be made one) we can write into; checked before any work."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise UserError(f"{what} {path}: exists and is not a folder")
    _writable_dir(path, what)
    return path


def check_output_file(path: str | Path, what: str = "output") -> Path:
    """Check, before any work, that a result file can be written to ``path`` without overwriting
    anything that is not an earlier result of the same kind (a ``.json`` written by us)."""
    path = Path(path)
    if path.name in RUN_FILES or path.suffix != ".json":
        raise UserError(f"{what} {path}: must be a .json file other than a run's own files")
    if path.is_dir():
        raise UserError(f"{what} {path}: is a directory")
    if path.exists():
        try:
            old = json.loads(path.read_text())
        except (OSError, ValueError, UnicodeDecodeError):
            old = None
        if not (isinstance(old, dict) and old.get("kind", "").startswith("warp-critic/")):
            raise UserError(
                f"{what} {path}: exists and is not a warp-critic result; not overwriting it"
            )
    _writable_dir(path.parent, what)
    return path


def write_result(path: Path, result: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, json.dumps(result, indent=2))


# ------------------------------------------------------------------------------------------------
# the run directory
# ------------------------------------------------------------------------------------------------


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


class RunDir:
    """A run directory. Use :meth:`create` for a new run, :meth:`open` for an existing one."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self._locked = False
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
        """Take the directory's lock or refuse at once (a dead owner's lock is taken over)."""
        path = self.path / LOCK
        me = {"pid": os.getpid(), "host": socket.gethostname(), "started": time.time()}
        for _ in range(2):
            try:
                fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
            except FileExistsError:
                try:
                    owner = json.loads(path.read_text())
                except (OSError, ValueError, UnicodeDecodeError):
                    owner = {}
                pid, host = owner.get("pid"), owner.get("host")
                if isinstance(pid, int) and host == me["host"] and not _pid_alive(pid):
                    warn(
                        f"run directory {self.path}: taking over the lock of process {pid}, which is no longer running"
                    )
                    with contextlib.suppress(OSError):
                        path.unlink()
                    continue
                if not owner:  # unreadable: being written right now, or garbage
                    raise UserError(
                        f"run directory {self.path}: is locked ({LOCK} exists; delete it if no process uses the run)"
                    ) from None
                raise UserError(
                    f"run directory {self.path}: in use by process {pid} on {host} "
                    f"(its {LOCK}; delete it if that process is gone)"
                ) from None
            except OSError as e:
                raise UserError(
                    f"run directory {self.path}: cannot lock ({e.strerror or e})"
                ) from None
            with os.fdopen(fd, "w") as f:
                f.write(json.dumps(me))
            self._locked = True
            for stale in self.path.glob(".*.tmp"):  # half-written files of a killed process
                with contextlib.suppress(OSError):
                    stale.unlink()
            return
        raise UserError(f"run directory {self.path}: cannot take over its lock")

    def unlock(self) -> None:
        if self._locked:
            with contextlib.suppress(OSError):
                (self.path / LOCK).unlink()
            self._locked = False

    # -- config -----------------------------------------------------------------------------------
    def save_config(self, config: dict) -> None:
        atomic_write_text(self.path / "config.json", json.dumps(config, indent=2))

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
            if (
                isinstance(row, dict)
                and isinstance(row.get("iteration"), int)
                and row["iteration"] < upto
            ):
                rows.append(row)
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
        """Fold a segment (closed, or cut short by a killed process) into ``recording.rrd``.

        ``rerun rrd merge`` keeps everything readable of a file without footer, so a killed segment
        loses at most its last, unwritten chunk; the merged file always verifies.
        """
        seg = self.segment_path()
        if not seg.exists():
            return
        sources = [
            str(p) for p in (self.recording_path, seg) if p.exists() and p.stat().st_size > 0
        ]
        if sources:
            with _atomic(self.recording_path) as tmp:
                proc = subprocess.run(
                    [sys.executable, "-m", "rerun_cli", "rrd", "merge", *sources, "-o", str(tmp)],
                    capture_output=True,
                    text=True,
                    env={**os.environ, "RUST_LOG": "error"},
                )
                if proc.returncode != 0:
                    raise UserError(
                        f"{self.recording_path}: cannot merge the recording segment "
                        f"({(proc.stderr.strip().splitlines() or ['rerun rrd merge failed'])[-1]})"
                    )
        seg.unlink()


def load_checkpoint_file(path: str | Path, require: Iterable[str] = ()) -> dict:
    """Load a checkpoint without running code from it, or raise a one-line :class:`UserError`."""
    path = Path(path)
    if not path.is_file():
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
