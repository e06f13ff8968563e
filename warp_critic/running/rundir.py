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
import errno
import io
import json
import os
import stat
import tempfile
import uuid
from collections.abc import Callable, Iterable
from pathlib import Path

import torch

from warp_critic.core.errors import FieldError, UserError, warn
from warp_critic.running.locks import FolderLock

MARKER = ".warp-critic-run"
RUN_KIND = "warp-critic/run-v1"
CHECKPOINT_KIND = "warp-critic/checkpoint-v1"
RUN_FILES = ("config.json", "checkpoint.pt", "metrics.jsonl", "recording.rrd", MARKER)
RECORDING = "recording.rrd"
SEGMENT = "recording.segment.rrd"


class RunExistsError(UserError):
    """A new run was asked for in a directory that holds one (the CLI suggests resuming it)."""


class DiskFullError(UserError):
    """A write failed because the device is full (or the quota is used up): not the user's input,
    but one line all the same (the CLI exits 1)."""


FULL = (errno.ENOSPC, getattr(errno, "EDQUOT", errno.ENOSPC))


# ------------------------------------------------------------------------------------------------
# atomic writes
# ------------------------------------------------------------------------------------------------

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
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def _write_bytes(path: Path, data: bytes) -> None:
    """The one place a result file's bytes reach the disk (the full-disk tests fail it here)."""
    with open(path, "wb") as f:
        f.write(data)


def _write_atomically(path: Path, data: bytes) -> None:
    """``data`` into a temporary file that then replaces ``path``; a failure is one line."""
    try:
        with _atomic(path) as tmp:
            _write_bytes(tmp, data)
    except OSError as e:
        cls = DiskFullError if e.errno in FULL else UserError
        raise cls(f"{path}: cannot write ({e.strerror or e})") from None


def atomic_write_text(path: Path, text: str) -> None:
    _write_atomically(path, text.encode())


def atomic_write_bytes(path: Path, data: bytes) -> None:
    _write_atomically(path, data)


def atomic_torch_save(obj, path: Path) -> None:
    """``torch.save`` to memory, then to disk atomically (a full disk is an ``OSError`` here, where
    ``torch.save`` to a path would hide it in a ``RuntimeError``)."""
    buf = io.BytesIO()
    torch.save(obj, buf)
    _write_atomically(path, buf.getvalue())


def save_figure(fig, path: Path, **kwargs) -> None:
    """A matplotlib figure as PNG at ``path``, atomically (``kwargs`` go to ``savefig``)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", **kwargs)
    _write_atomically(Path(path), buf.getvalue())


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
    """Check, before any work, that ``path`` is a place for a result file: a ``.json`` other than a
    run's own files, not a folder, in a folder we can write. Whether what is there may be replaced is
    :func:`check_replaceable`'s question (it needs the run being written for)."""
    path = Path(path)
    if path.name in RUN_FILES or path.suffix != ".json":
        raise UserError(f"{what} {path}: must be a .json file other than a run's own files")
    if path.is_dir():
        raise UserError(f"{what} {path}: is a directory")
    _writable_dir(path.parent, what)
    return path


#: A file read back to decide whether it may be replaced is at most this big (bytes): every result
#: this package writes is far smaller, and a device such as ``/dev/zero`` never ends.
MAX_RESULT_BYTES = 64 * 2**20


def read_bounded(path: str | Path, cap: int = MAX_RESULT_BYTES) -> bytes:
    """The bytes of the user-named regular file ``path``, at most ``cap`` of them; a device, a FIFO,
    a socket or a larger file is one :class:`UserError` line (nothing is read from it)."""
    path = Path(path)
    try:
        st = os.stat(path)  # through a symbolic link: what the link names is what would be read
    except OSError as e:
        raise UserError(f"{path}: cannot be read ({e.strerror or e})") from None
    if not stat.S_ISREG(st.st_mode):
        kind = next((name for test, name in _NOT_REGULAR if test(st.st_mode)), "not a regular file")
        raise UserError(f"{path}: is {kind}, not a regular file")
    if st.st_size > cap:
        raise UserError(f"{path}: {st.st_size:,} bytes, more than the {cap:,} a result file can be")
    try:
        with open(path, "rb") as f:
            data = f.read(cap + 1)
    except OSError as e:
        raise UserError(f"{path}: cannot be read ({e.strerror or e})") from None
    if len(data) > cap:  # grew since the stat
        raise UserError(f"{path}: more than the {cap:,} bytes a result file can be")
    return data


_NOT_REGULAR = (
    (stat.S_ISDIR, "a directory"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISFIFO, "a FIFO (named pipe)"),
    (stat.S_ISSOCK, "a socket"),
)


def check_replaceable(
    path: str | Path, field: str, kind: str, same: Callable[[dict], str | None]
) -> bool:
    """The one rule of every writer: ``path`` may be written when nothing is there, or when what is
    there is a result of the same purpose (``kind``) written for the same run(s): ``same(old)``
    returns ``None`` for such an ``old`` result, else the words naming whose it is ("of the run X").
    Anything else (a user's file, another command's result, another run's) is one
    :class:`FieldError` naming ``field`` (the flag that chose ``path``); nothing beyond
    :data:`MAX_RESULT_BYTES` is read. Returns whether an earlier result of this run is there (and
    will be replaced)."""
    path = Path(path)
    if not path.exists() and not path.is_symlink():
        return False
    try:
        data = read_bounded(path)
    except UserError as e:
        raise FieldError(field, str(e)) from None
    try:
        old = json.loads(data)
    except (ValueError, UnicodeDecodeError, RecursionError):
        old = None
    if not (isinstance(old, dict) and str(old.get("kind", "")).startswith("warp-critic/")):
        raise FieldError(
            field, f"{path}: exists and is not a warp-critic result; not overwriting it"
        )
    whose = f"of kind {old.get('kind')!r}" if old.get("kind") != kind else same(old)
    if whose is not None:
        raise FieldError(
            field, f"{path}: holds a result {whose}; not replacing it (choose another file)"
        )
    return True


#: The first bytes of a rerun recording (``.rrd``).
RRD_MAGIC = b"RRF2"


def check_recording_replaceable(path: str | Path, field: str, result_is_ours: bool) -> None:
    """A recording written beside a result file (``X.json`` -> ``X.rrd``) may replace only the
    recording of the result it replaces: an existing ``path`` is refused unless the result beside it
    is this run's earlier result (``result_is_ours``, from :func:`check_replaceable`) and ``path`` is
    a rerun recording."""
    path = Path(path)
    if not path.exists() and not path.is_symlink():
        return
    if path.is_dir():
        raise FieldError(field, f"{path}: the recording's place is a directory")
    ours = False
    if result_is_ours and path.is_file() and not path.is_symlink():
        try:
            with open(path, "rb") as f:
                ours = f.read(len(RRD_MAGIC)) == RRD_MAGIC
        except OSError:
            ours = False
    if not ours:
        raise FieldError(
            field,
            f"{path}: exists and is not the recording of the result it would sit beside; "
            "not replacing it (choose another file, or give --no-recording)",
        )


def write_result(path: Path, result: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, json.dumps(result, indent=2))


# ------------------------------------------------------------------------------------------------
# the run directory
# ------------------------------------------------------------------------------------------------


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
