"""The process's environment, checked before any work: text arguments that are not UTF-8, an ASCII
locale given UTF-8 names (``LC_ALL=C PYTHONUTF8=0``), a working directory that was deleted.

Standard library only (called before torch and Warp are imported).
"""

from __future__ import annotations

import argparse
import os
import sys

from warp_critic.core.errors import FieldError


def check_utf8(args: argparse.Namespace) -> None:
    """Every text argument must be valid UTF-8: a name with a stray byte cannot be written into
    config.json or printed, so it is refused before anything is made."""
    for name, value in vars(args).items():
        for v in value if isinstance(value, list) else [value]:
            if isinstance(v, (str, os.PathLike)):
                try:
                    str(v).encode("utf-8")
                except UnicodeEncodeError as e:
                    raise FieldError(
                        name,
                        f"{str(v).encode('utf-8', 'backslashreplace').decode()}: not valid UTF-8 "
                        f"(byte {e.object[e.start : e.end].encode('utf-8', 'surrogateescape')!r})",
                    ) from None


def utf8_mode() -> None:
    """The console script under an ASCII locale (``LC_ALL=C PYTHONUTF8=0``) given a valid UTF-8 name:
    the same command again in Python's UTF-8 mode, so that the name is text (for config.json and
    USD) and a path (for the file system) at once. Other bytes are refused by :func:`check_utf8`."""
    if sys.flags.utf8_mode or sys.getfilesystemencoding().lower().replace("-", "") == "utf8":
        return
    utf8 = False
    for arg in sys.argv[1:]:
        try:
            arg.encode("utf-8")
            continue
        except UnicodeEncodeError:
            pass
        try:
            os.fsencode(arg).decode("utf-8")
            utf8 = True
        except (UnicodeEncodeError, UnicodeDecodeError):
            pass  # not UTF-8 in either mode: check_utf8 names it
    if utf8 and getattr(sys, "orig_argv", None):
        os.execv(sys.executable, [sys.executable, "-X", "utf8", *sys.orig_argv[1:]])


def console_never_fails() -> None:
    """A console that cannot show every character (``PYTHONIOENCODING=ascii``, an ASCII locale)
    shows the others as ``\\xNN`` escapes: a file name printed after the work is done (the result's
    path) must not end the command in a ``UnicodeEncodeError``."""
    for stream in (sys.stdout, sys.stderr):
        reconfigure = getattr(stream, "reconfigure", None)
        if reconfigure is not None and getattr(stream, "errors", None) == "strict":
            reconfigure(errors="backslashreplace")


def cwd_gone() -> str | None:
    """The one-line problem when the working directory no longer exists (deleted under the shell),
    else ``None``."""
    try:
        os.getcwd()
    except OSError:
        where = os.environ.get("PWD") or "the working directory"
        return f"{where}: the working directory no longer exists; change to a folder that does"
    return None


__all__ = ["check_utf8", "console_never_fails", "utf8_mode", "cwd_gone"]
