"""Who owns a folder: OS file locks, and the rule that keeps every command out of another's folder.

* :class:`FolderLock`: ``FOLDER/.lock``, an OS file lock (``filelock``, ``flock(2)``) held while its
  process lives and released by the kernel when that process dies by any cause, SIGKILL included. The
  file's content (``{"pid", "host", "started"}``) only names the holder for messages; a ``.lock`` file
  that nobody holds is taken over (with a warning naming the process it names), except one written on
  another host, whose process this host cannot see.
* :func:`check_not_owned`: a folder that holds a live lock, or a reproduce output (its marker), belongs
  to its owner: another command may not write into it or below it.
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import time
from pathlib import Path
from typing import TYPE_CHECKING

from warp_critic.core.errors import UserError, warn

if TYPE_CHECKING:
    from filelock import BaseFileLock

LOCK = ".lock"
#: The marker of a ``warp-critic reproduce`` output folder (written by :mod:`warp_critic.reproduce.engine.stages`).
REPRODUCE_MARKER = ".warp-critic-reproduce"


def _info(path: Path) -> dict | None:
    """The holder a lock file names: a dict, ``{}`` for garbage, ``None`` for no file or no content."""
    try:
        text = path.read_bytes()
    except OSError:
        return None
    if not text.strip():
        return None
    try:
        info = json.loads(text)
    except (ValueError, UnicodeDecodeError):
        return {}
    return info if isinstance(info, dict) else {}


def _who(info: dict | None) -> str:
    if not info:
        return "another process"
    return f"process {info.get('pid')} on {info.get('host')}"


class FolderLock:
    """The OS lock of ``folder`` (``folder/.lock``); ``what`` names the folder in messages."""

    def __init__(self, folder: str | Path, what: str = "run directory"):
        self.folder, self.what = Path(folder), what
        self.path = self.folder / LOCK
        self._lock: BaseFileLock | None = None  # held while not None

    @property
    def held(self) -> bool:
        return self._lock is not None

    def acquire(self) -> None:
        """Take the lock or refuse at once with a one-line :class:`UserError` naming the holder."""
        from filelock import FileLock, Timeout

        me = {"pid": os.getpid(), "host": socket.gethostname(), "started": time.time()}
        for _ in range(3):
            fds: list[int] = []
            lock = FileLock(str(self.path), timeout=0, thread_local=False, on_acquired=fds.append)
            try:
                lock.acquire()
            except Timeout:
                raise UserError(
                    f"{self.what} {self.folder}: in use by {_who(_info(self.path))} (its {LOCK})"
                ) from None
            except OSError as e:
                raise UserError(
                    f"{self.what} {self.folder}: cannot lock ({e.strerror or e})"
                ) from None
            try:  # the file we locked is still the one at the path (not one a holder just removed)
                same = bool(fds) and os.fstat(fds[0]).st_ino == os.stat(self.path).st_ino
            except OSError:
                same = False
            if not same:
                lock.release()
                continue
            old = _info(self.path)
            if old and old.get("host") not in (None, me["host"]):
                lock.release()
                raise UserError(
                    f"{self.what} {self.folder}: in use by {_who(old)} (its {LOCK}, written on "
                    "another host; delete it if that process is gone)"
                )
            if old is not None and old.get("pid") != me["pid"]:
                warn(
                    f"{self.what} {self.folder}: taking over the lock file left by "
                    f"{_who(old) if old else 'a process'}, which no longer holds it"
                )
            try:
                with open(self.path, "w") as f:
                    f.write(json.dumps(me))
            except OSError as e:
                lock.release()
                raise UserError(
                    f"{self.what} {self.folder}: cannot lock ({e.strerror or e})"
                ) from None
            self._lock = lock
            return
        raise UserError(f"{self.what} {self.folder}: cannot take its lock (it keeps changing)")

    def release(self) -> None:
        """Remove the lock file, then let the lock go (removing it first: no one locks a dead file)."""
        if self._lock is None:
            return
        with contextlib.suppress(OSError):
            self.path.unlink()
        with contextlib.suppress(OSError):
            self._lock.release()
        self._lock = None


#: A lock held through this many tries, ``PROBE_WAIT_S`` s apart, has an owner: another process's
#: :func:`holder` holds it for microseconds (two commands checking one folder at once), an owner for
#: its whole run.
PROBE_TRIES, PROBE_WAIT_S = 10, 0.05


def holder(folder: str | Path) -> dict | None:
    """Who holds ``folder``'s lock now (the content of its lock file), or ``None`` when nobody does."""
    path = Path(folder) / LOCK
    if not path.is_file():
        return None
    from filelock import FileLock, Timeout

    probe = FileLock(str(path), timeout=0, thread_local=False)
    for _ in range(PROBE_TRIES):
        try:
            probe.acquire()
        except Timeout:
            time.sleep(PROBE_WAIT_S)
            continue
        except OSError:
            return None
        probe.release()
        return None
    return _info(path) or {}


def check_not_owned(path: str | Path, what: str, *, reproduce_ok: bool = False) -> None:
    """Refuse ``path`` when it, or a folder above it, is a reproduce output (unless ``reproduce_ok``,
    for reproduce's own ``--out``) or holds a live lock: that folder belongs to its owner."""
    p = Path(os.path.abspath(path))
    for d in (p, *p.parents):
        if not d.is_dir():
            continue
        if (d / REPRODUCE_MARKER).is_file() and not (reproduce_ok and d == p):
            raise UserError(
                f"{what} {path}: inside the reproduce output {d}, which belongs to reproduce; "
                "write elsewhere"
            )
        owner = holder(d)
        if owner is not None and not (owner.get("pid") == os.getpid() and d == p):
            raise UserError(
                f"{what} {path}: {d} is in use by {_who(owner)} (its {LOCK}); write elsewhere"
            )


__all__ = ["FolderLock", "LOCK", "REPRODUCE_MARKER", "check_not_owned", "holder"]
