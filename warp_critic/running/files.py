"""A run's files on disk: atomic writes (a temporary file in the same folder, then ``os.replace``; a
full disk is one :class:`DiskFullError` line), bounded reads of user-named files, and the one rule
for every writer: a result replaces only a file of its own kind written for the same run(s)
(:func:`check_replaceable`). :mod:`.rundir` builds the run directory on these."""

from __future__ import annotations

import contextlib
import errno
import io
import json
import os
import stat
import tempfile
from collections.abc import Callable
from pathlib import Path

import torch

from warp_critic.core.errors import FieldError, UserError

#: a run directory's marker file, and the files a run owns (never an output another command names)
MARKER = ".warp-critic-run"
RUN_FILES = ("config.json", "checkpoint.pt", "metrics.jsonl", "recording.rrd", MARKER)


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


#: the first bytes of every PNG file
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def check_figure_file(path: str | Path, what: str = "--figure") -> Path:
    """Check, before any work, that ``path`` is a place for a figure: a ``.png`` that is not a
    folder, in a folder we can write, and, where a file is there already, a PNG (a user's other file
    is never overwritten by a picture)."""
    path = Path(path)
    if path.suffix.lower() != ".png":
        raise UserError(f"{what} {path}: must be a .png file")
    if path.is_dir():
        raise UserError(f"{what} {path}: is a directory")
    if not path.parent.is_dir():
        raise UserError(f"{what} {path}: {path.parent} is not a folder")
    _writable_dir(path.parent, what)
    if path.exists() or path.is_symlink():
        try:
            head = read_head(path, len(PNG_SIGNATURE))
        except UserError as e:
            raise UserError(f"{what} {e}") from None
        if head != PNG_SIGNATURE:
            raise UserError(f"{what} {path}: exists and is not a PNG image; not overwriting it")
    return path


#: A file read back to decide whether it may be replaced is at most this big (bytes): every result
#: this package writes is far smaller, and a device such as ``/dev/zero`` never ends.
MAX_RESULT_BYTES = 64 * 2**20


def _regular_size(path: Path) -> int:
    """The size of the user-named regular file ``path`` (bytes); a device, a FIFO, a socket or a
    file that cannot be read is one :class:`UserError` line (nothing is read from it)."""
    try:
        st = os.stat(path)  # through a symbolic link: what the link names is what would be read
    except OSError as e:
        raise UserError(f"{path}: cannot be read ({e.strerror or e})") from None
    if not stat.S_ISREG(st.st_mode):
        kind = next((name for test, name in _NOT_REGULAR if test(st.st_mode)), "not a regular file")
        raise UserError(f"{path}: is {kind}, not a regular file")
    return st.st_size


def _read_at_most(path: Path, n: int) -> bytes:
    try:
        with open(path, "rb") as f:
            return f.read(n)
    except OSError as e:
        raise UserError(f"{path}: cannot be read ({e.strerror or e})") from None


def read_bounded(path: str | Path, cap: int = MAX_RESULT_BYTES) -> bytes:
    """The bytes of the user-named regular file ``path``, at most ``cap`` of them; a device, a FIFO,
    a socket or a larger file is one :class:`UserError` line (nothing is read from it)."""
    path = Path(path)
    size = _regular_size(path)
    if size > cap:
        raise UserError(f"{path}: {size:,} bytes, more than the {cap:,} a result file can be")
    data = _read_at_most(path, cap + 1)
    if len(data) > cap:  # grew since the stat
        raise UserError(f"{path}: more than the {cap:,} bytes a result file can be")
    return data


def read_head(path: str | Path, n: int) -> bytes:
    """The first ``n`` bytes (fewer where the file is shorter) of the user-named regular file
    ``path``, whatever its size; not a regular file is one :class:`UserError` line."""
    path = Path(path)
    _regular_size(path)
    return _read_at_most(path, n)


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
