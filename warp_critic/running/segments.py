"""Merging a recording segment into a run's ``recording.rrd`` without ever losing either.

``rerun rrd optimize`` (a merge that also compacts the chunks) keeps everything readable of a file
without footer, so a segment cut short by a killed process loses at most its last, unwritten
chunk. A ``recording.rrd`` that rerun cannot read
(edited, or garbage) is kept aside under a new name, with a one-line warning, and the recording goes
on from the segment; a segment that rerun cannot read is kept aside the same way. A segment is
deleted only once its content is in ``recording.rrd``.
"""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
from pathlib import Path

from warp_critic.core.errors import UserError, warn


def merge_segment(recording: Path, segment: Path) -> None:
    """Fold ``segment`` into ``recording`` (created when missing); see the module docstring."""
    if not segment.exists():
        return
    if segment.stat().st_size == 0:
        segment.unlink()
        return
    old = recording if recording.exists() and recording.stat().st_size > 0 else None
    cut = [p for p in (old, segment) if p is not None and not _whole(p)]
    if old is not None and _merge(recording, [old, segment]):
        segment.unlink()
        _say_kept(recording, cut)
        return
    if old is not None and _readable(segment):  # the segment is fine: the old recording is not
        aside = _aside(recording)
        os.replace(recording, aside)
        warn(
            f"{recording}: not a readable rerun recording; kept aside as {aside.name}, the "
            "recording continues from this run's segment"
        )
    if _merge(recording, [segment]):
        segment.unlink()
        _say_kept(recording, [p for p in cut if p == segment])
        return
    aside = _aside(segment)
    os.replace(segment, aside)
    warn(f"{segment}: not a readable rerun recording; kept aside as {aside.name}")


def _whole(path: Path) -> bool:
    """Whether ``path`` ends in rerun's footer (a file closed by its writer, not cut short)."""
    try:
        with open(path, "rb") as f:
            f.seek(0, os.SEEK_END)
            size = f.tell()
            f.seek(max(size - 12, 0))
            return size >= 12 and f.read(8) == b"RRF2FOOT"
    except OSError:
        return True  # nothing to say about a file that cannot be read here


def _say_kept(recording: Path, cut: list[Path]) -> None:
    """After a merge that read files cut short (a killed writer): one warning line saying what the
    recording holds now (the iterations whose rollouts it has)."""
    if not cut:
        return
    from warp_critic.running.recording import recorded_iterations

    try:
        its = recorded_iterations(recording)
    except Exception:  # noqa: BLE001 - the warning must not fail the run
        its = []
    held = (
        f"the rollouts of {len(its)} recorded iteration(s), {its[0]} to {its[-1]}"
        if its
        else "no rollouts"
    )
    names = " and ".join(p.name for p in cut)
    warn(
        f"{recording}: {names} had been cut short (a killed write); it now holds what rerun could "
        f"read: {held}"
    )


def _readable(path: Path) -> bool:
    probe = path.with_name(f".{path.name}.probe.tmp")
    try:
        return _run_merge([path], probe)
    finally:
        with contextlib.suppress(OSError):
            probe.unlink()


def _merge(recording: Path, sources: list[Path]) -> bool:
    """``rerun rrd optimize`` (merge and compact) of ``sources`` into ``recording`` (atomically); False, with ``recording``
    untouched, when rerun cannot read them."""
    tmp = recording.with_name(f".{recording.name}.{os.getpid()}.tmp")
    try:
        ok = _run_merge(sources, tmp)
        if ok:
            os.replace(tmp, recording)
        return ok
    finally:
        with contextlib.suppress(OSError):
            tmp.unlink()


def _run_merge(sources: list[Path], out: Path) -> bool:
    proc = subprocess.run(
        # optimize: merge and compact the many small chunks a run flushes (one per entity and
        # checkpoint) into few: a long run's recording shrinks several-fold
        [sys.executable, "-m", "rerun_cli", "rrd", "optimize", *map(str, sources), "-o", str(out)],
        capture_output=True,
        text=True,
        env={**os.environ, "RUST_LOG": "error"},
    )
    # rerun reports unreadable input on stderr but may still exit 0 with no (or an empty) output
    return (
        proc.returncode == 0
        and "Error" not in proc.stderr
        and out.is_file()
        and out.stat().st_size > 0
    )


def _aside(path: Path) -> Path:
    """A free name next to ``path`` for a file kept aside: ``recording.bad-1.rrd``, ..."""
    for k in range(1, 10_000):
        p = path.with_name(f"{path.stem}.bad-{k}{path.suffix}")
        if not p.exists():
            return p
    raise UserError(f"{path}: too many files kept aside next to it")


__all__ = ["merge_segment"]
