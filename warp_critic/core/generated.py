"""Generated blocks in hand-written files: the lines between a begin and an end marker, which a
tool writes from the project's own data (``--write``) and compares (``--check``).

The README's claims table, its scene-attribute table, ``docs/design.md``'s module table and
``docs/paper/README.md``'s verdicts are such blocks; everything around them is prose.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["check_or_write", "emit", "replace_block"]


def replace_block(text: str, begin: str, end: str, body: str, where: str) -> str:
    """``text`` with what lies between the marker ``begin`` and the marker ``end`` replaced by
    ``body`` (each marker then on a line of its own). Raises :class:`ValueError` naming ``where``
    (the file) unless ``text`` holds ``begin`` once and ``end`` once after it."""
    if text.count(begin) != 1 or text.count(end) != 1 or text.index(begin) > text.index(end):
        raise ValueError(f"{where}: needs one {begin} line and one {end} line after it")
    head, rest = text.split(begin)
    _, tail = rest.split(end)
    return f"{head}{begin}\n{body}\n{end}{tail}"


def check_or_write(path: Path, text: str, new: str, *, check: bool, prog: str, what: str) -> int:
    """A tool's ``--check`` / ``--write`` of the file ``path`` (``text`` now, ``new`` with its block
    written): ``--check`` prints whether ``what`` (the block) is current and returns 0, or 1 when
    it is stale; ``--write`` writes ``new`` and returns 0. One line either way."""
    import sys

    if check:
        if new != text:
            print(f"{prog}: {path}: {what} is not current: run {prog} --write", file=sys.stderr)
            return 1
        print(f"{prog}: {path}: {what} is current")
        return 0
    path.write_text(new, encoding="utf-8")
    print(f"{prog}: {path}: wrote {what}")
    return 0


def emit(
    prog: str,
    body: str,
    begin: str,
    end: str,
    *,
    write: Path | None = None,
    check: Path | None = None,
    what: str = "the block",
) -> int:
    """A block tool's output: ``body`` printed (neither ``write`` nor ``check``), or put between
    ``begin`` and ``end`` of the file ``write`` / compared with ``check``'s (:func:`check_or_write`).
    A file that cannot be read or lacks its markers is one line and exit 2."""
    import sys

    target = write or check
    if target is None:
        print(body)
        return 0
    try:
        text = target.read_text(encoding="utf-8")
        new = replace_block(text, begin, end, body, str(target))
    except (OSError, UnicodeDecodeError, ValueError) as e:
        print(f"{prog}: error: {getattr(e, 'strerror', None) or e}", file=sys.stderr)
        return 2
    return check_or_write(target, text, new, check=check is not None, prog=prog, what=what)
