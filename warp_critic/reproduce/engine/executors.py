"""Where ``reproduce`` runs its units of work: in this process, in local processes, or on Ray.

A **unit** is one stage (sub-stage) of the plan -- the toy, the landscape, one method x robot
meta-training with all its seeds, the reacher maps, the KUKA tables -- described by plain data
(:class:`Unit`: the function to call by its import path, its keyword arguments, the stage
directories it reads), so any executor can run it anywhere. Whatever runs it, the driver alone
writes ``stage.json`` (last, atomically), so a unit that did not finish is never taken for a
complete one, and a restarted driver skips exactly the units that finished.

* :class:`InProcess` (the default): one after the other, here, with progress bars.

Every executor takes the units that can start and, after each stage it hands back, asks the driver
for the ones that stage made ready (``more``): a maps or tables stage starts when its own inputs are
complete, while other meta-trainings still run.
* :class:`LocalProcesses` (``--jobs N``): ``N`` fresh processes on this machine writing into the
  output folder directly; a process that dies costs only its unit, which is run again (up to
  ``retries`` times). Its units show no progress bars; every ``progress_every`` seconds (10 min)
  the driver logs a line per running unit from its runs' ``metrics.jsonl`` (:func:`unit_progress`).
* :class:`RayExecutor` (``--ray [ADDRESS]``): one Ray task per unit with its resource request (one
  GPU for a CUDA run, one CPU otherwise). No shared filesystem is assumed: a task gets the files of
  the stage directories it reads (and of its own unfinished stage directory, to resume) and returns
  the files of its stage directory, which the driver writes into ``--out``. Ray retries a task whose
  worker died (``max_retries``), each try from the files the driver holds, so a partial run never
  reaches a table.
"""

from __future__ import annotations

import contextlib
import importlib
import json
import os
import signal
import sys
import time
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from pathlib import Path

from warp_critic.core import interrupts
from warp_critic.core.errors import FieldError, UserError

UNIT_FAULT_ENV = "WARP_CRITIC_UNIT_FAULT"  # tests: "<unit name>:<marker file>" kills its first try
MAX_JOBS = 1024
WORKER_GRACE = 5.0  # s a worker whose driver died has to close its run before it exits


@dataclass(frozen=True)
class Unit:
    """One unit of work: ``fn(OUT/dir_name, **kwargs)`` with ``runs`` (method -> run directories,
    relative to OUT) resolved against the folder it runs in."""

    name: str  # e.g. metatrain-kuka-ours
    dir_name: str  # its stage directory, e.g. metatrain-kuka-ours-4b66f80b24
    fn: str  # "module:function"
    kwargs: dict = field(default_factory=dict)
    reads: tuple[str, ...] = ()  # stage directories (under OUT) it reads


def call_unit(unit: Unit, root: Path) -> dict:
    """Run ``unit`` with its stage directory under ``root``; returns its result (for ``stage.json``)."""
    _maybe_fail(unit)
    module, name = unit.fn.split(":")
    fn = getattr(importlib.import_module(module), name)
    kwargs = dict(unit.kwargs)
    if "runs" in kwargs:
        kwargs["runs"] = {m: [root / p for p in paths] for m, paths in kwargs["runs"].items()}
    d = root / unit.dir_name
    d.mkdir(parents=True, exist_ok=True)
    return fn(d, **kwargs)


def _maybe_fail(unit: Unit) -> None:
    """Fault injection for the tests: the first try of the named unit dies as a killed worker does."""
    spec = os.environ.get(UNIT_FAULT_ENV, "")
    name, _, marker = spec.partition(":")
    if name == unit.name and marker and not os.path.exists(marker):
        Path(marker).write_text(str(os.getpid()))
        os.kill(os.getpid(), signal.SIGKILL)


def unit_progress(unit: Unit, root: Path) -> str:
    """One line on how far ``unit`` has come, read from the ``metrics.jsonl`` of its runs under
    ``root/unit.dir_name`` (one row per finished iteration): the iteration every seed has reached,
    of the unit's ``values["iterations"]`` where it names them, the mean seconds per iteration of
    the last 20 rows and the time left at that rate. A unit without metrics (an evaluation) is
    "running"."""
    files = sorted((Path(root) / unit.dir_name).rglob("metrics.jsonl"))
    rows: list[list[str]] = []
    for f in files:
        try:
            rows.append(f.read_text(encoding="utf-8").splitlines())
        except OSError:
            continue
    if not rows:
        return f"reproduce: {unit.name}: running"
    if not min(len(r) for r in rows):
        return f"reproduce: {unit.name}: running, no iteration finished yet"
    done = min(len(r) for r in rows)
    values = unit.kwargs.get("values")
    total = values.get("iterations") if isinstance(values, dict) else None
    seconds = []
    for line in rows[0][max(0, done - 20) : done]:
        try:
            seconds.append(float(json.loads(line)["seconds"]))
        except (ValueError, KeyError, TypeError):
            continue
    runs = f"{len(rows)} run(s)"
    if not isinstance(total, int) or isinstance(total, bool):
        return f"reproduce: {unit.name}: iteration {done} ({runs})"
    line = f"reproduce: {unit.name}: iteration {done} of {total} ({runs})"
    if seconds and done < total:
        rate = sum(seconds) / len(seconds)
        line += (
            f", {rate:.2f} s/iteration, about {(total - done) * rate / 60:.0f} min of training left"
        )
    return line


# ------------------------------------------------------------------------------------------------
# executors
# ------------------------------------------------------------------------------------------------

Done = Callable[[Unit, dict, float], None]  # (unit, result, seconds): the driver records the stage
Log = Callable[[str], None]  # one line for the user
#: after each recorded stage, the units that it made ready (their input stages are now complete)
More = Callable[[], list[Unit]]
#: asked when a unit would start (a worker is free for it): may it? One refused is not run by this
#: call (``reproduce --hours``: it would not end in time)
Admit = Callable[[Unit], bool]


def no_units() -> list[Unit]:
    """No unit made ready (an executor's ``more`` where the driver gives none)."""
    return []


def admit_all(unit: Unit) -> bool:
    """Every unit may start (an executor's ``admit`` where the driver sets no limit)."""
    return True


class InProcess:
    """Run the units here, one after the other (progress bars on stderr)."""

    name = "in-process"

    def run(
        self,
        units: list[Unit],
        root: Path,
        done: Done,
        log: Log,
        more: More = no_units,
        admit: Admit = admit_all,
    ) -> None:
        queue = list(units)
        while queue:
            u = queue.pop(0)
            if not admit(u):
                continue
            log(f"reproduce: {u.name}: running ({u.dir_name})")
            t = time.perf_counter()
            result = call_unit(u, root)
            done(u, result, time.perf_counter() - t)
            queue += more()

    def close(self) -> None:
        pass


_IN_UNIT = False  # a worker process: is a unit running (set around it by _process_unit)?
_STOPPING = False  # a worker process: SIGTERM came; start no further unit


def _worker_stop(signum, frame) -> None:
    """SIGTERM in a worker (the driver stopping, or dying: PDEATHSIG). Mid-unit it stops the unit the way
    Ctrl-C stops a CLI run: the run's ``finally`` blocks close its recording and release its lock, so the
    next call resumes without a stale lock. An idle worker just exits."""
    global _STOPPING
    _STOPPING = True
    if _IN_UNIT:
        interrupts.request()  # raised again at the unit's next step if this raise is swallowed
        raise KeyboardInterrupt
    os._exit(128 + signum)


def _watch_parent(sentinel: int) -> None:
    """A worker's watchdog thread: when the driver dies by any cause (its end of the spawn pipe
    closes; SIGKILL included), stop the unit as SIGTERM does and exit after a grace period even if
    the pool's loop is blocked on its pipe."""
    from multiprocessing.connection import wait

    wait([sentinel])
    with contextlib.suppress(OSError):
        os.kill(os.getpid(), signal.SIGTERM)
    time.sleep(WORKER_GRACE)
    os._exit(128 + signal.SIGTERM)


def _process_init() -> None:
    """A worker process: stop with the driver (its death is watched on the spawn pipe, and on Linux
    also signalled by PDEATHSIG), then start as the CLI starts."""
    import multiprocessing
    import threading

    parent = multiprocessing.parent_process()
    if parent is not None and getattr(parent, "sentinel", None) is not None:
        threading.Thread(target=_watch_parent, args=(parent.sentinel,), daemon=True).start()
    signal.signal(signal.SIGTERM, _worker_stop)
    signal.signal(
        signal.SIGINT, signal.SIG_IGN
    )  # a terminal's Ctrl-C reaches the driver, which stops us
    if sys.platform.startswith("linux"):
        import ctypes

        try:
            ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
        except OSError:
            pass
    from warp_critic.core.runtime import init

    init()


def _quiet(unit: Unit) -> Unit:
    """The unit without progress bars (a worker's stderr is no terminal; the driver logs each unit)."""
    if "progress" not in unit.kwargs:
        return unit
    return Unit(unit.name, unit.dir_name, unit.fn, {**unit.kwargs, "progress": False}, unit.reads)


def _process_unit(unit: Unit, root: str) -> tuple[dict, float]:
    global _IN_UNIT
    if _STOPPING:  # the driver is stopping: a unit the pool had queued must not start
        os._exit(128 + signal.SIGTERM)
    t = time.perf_counter()
    _IN_UNIT = True
    try:
        return call_unit(_quiet(unit), Path(root)), time.perf_counter() - t
    finally:
        _IN_UNIT = False
        if _STOPPING:  # its run is closed (the finally blocks above ran): leave, take no next unit
            os._exit(128 + signal.SIGTERM)


def check_jobs(jobs) -> int:
    if isinstance(jobs, bool) or not isinstance(jobs, int) or not 1 <= jobs <= MAX_JOBS:
        raise FieldError("jobs", f"must be an integer in 1..{MAX_JOBS} (got {jobs!r})")
    return jobs


class LocalProcesses:
    """``jobs`` worker processes on this machine (spawned fresh: no state shared with the driver)."""

    name = "local processes"

    def __init__(self, jobs: int, retries: int = 2, progress_every: float = 600.0):
        check_jobs(jobs)
        self.jobs, self.retries = jobs, retries
        self.progress_every = progress_every  # s between the driver's progress lines
        self._pool_now: ProcessPoolExecutor | None = None
        # stopping workers mid-unit (Ctrl-C) leaves the pool's queue semaphores to the tracker process,
        # which would warn about them on its own stderr: that is expected here, not a leak
        os.environ.setdefault(
            "PYTHONWARNINGS", "ignore::UserWarning:multiprocessing.resource_tracker"
        )

    def _pool(self) -> ProcessPoolExecutor:
        import multiprocessing

        return ProcessPoolExecutor(
            max_workers=self.jobs,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=_process_init,
        )

    def run(
        self,
        units: list[Unit],
        root: Path,
        done: Done,
        log: Log,
        more: More = no_units,
        admit: Admit = admit_all,
    ) -> None:
        try:
            self._run(units, root, done, log, more, admit)
        except BaseException:
            # a unit failed for good, or Ctrl-C / SIGTERM: stop the other units' processes too (each
            # resumes from its checkpoints next time) instead of waiting for them to finish
            import multiprocessing

            children = multiprocessing.active_children()
            for child in children:
                child.terminate()
            # A stopped worker hands its unit's end back through the pool's result queue, whose
            # lock a terminated sibling can hold forever (seen: the driver hung at exit after one
            # unit diverged while another trained). Each has WORKER_GRACE to close its run and
            # exit; what is still there after that is killed, so the driver always returns.
            deadline = time.monotonic() + WORKER_GRACE
            for child in children:
                child.join(max(0.0, deadline - time.monotonic()))
                if child.is_alive():
                    child.kill()
                    child.join(WORKER_GRACE)
            if self._pool_now is not None:
                self._pool_now.shutdown(wait=True, cancel_futures=True)
            raise

    def _run(
        self, units: list[Unit], root: Path, done: Done, log: Log, more: More, admit: Admit
    ) -> None:
        # Units are handed to the pool one per free worker (never queued inside it), so a unit
        # counts as running once it is submitted, and one that a finished stage made ready waits
        # only for the next free worker.
        tries = {u.name: 0 for u in units}
        queue = list(units)  # ready, not yet submitted

        def fill(pool: ProcessPoolExecutor, futures: dict, lost: list[Unit]) -> None:
            while queue and len(futures) < self.jobs and not lost:
                u = queue.pop(0)
                if not admit(u):  # asked when a worker is free for it, not when it became ready
                    continue
                log(f"reproduce: {u.name}: started in a local process ({u.dir_name})")
                tries.setdefault(u.name, 0)
                futures[pool.submit(_process_unit, u, str(root))] = u

        while queue:
            pool = self._pool_now = self._pool()
            futures: dict = {}
            lost: list[Unit] = []  # units whose worker died (the pool is broken then)
            fill(pool, futures, lost)
            next_progress = time.monotonic() + self.progress_every
            while futures:
                finished, _ = wait(
                    futures,
                    timeout=max(0.0, next_progress - time.monotonic()),
                    return_when=FIRST_COMPLETED,
                )
                if time.monotonic() >= next_progress:
                    for f, u in futures.items():
                        if not f.done():
                            log(unit_progress(u, root))
                    next_progress = time.monotonic() + self.progress_every
                for f in finished:
                    u = futures.pop(f)
                    try:
                        result, seconds = f.result()
                    except BrokenProcessPool:
                        lost.append(u)
                        continue
                    except BaseException:
                        pool.shutdown(wait=False, cancel_futures=True)
                        raise
                    done(u, result, seconds)
                    queue.extend(more())
                fill(pool, futures, lost)
            pool.shutdown(wait=True, cancel_futures=True)
            for u in lost:
                tries[u.name] += 1
                if tries[u.name] > self.retries:
                    raise UserError(
                        f"reproduce: unit {u.name} lost its worker process {tries[u.name]} times; "
                        "its stage directory is left unfinished (run again to resume)"
                    )
                log(
                    f"reproduce: {u.name}: a worker process died; running it again "
                    f"(try {tries[u.name] + 1} of {self.retries + 1})"
                )
            queue[:0] = lost

    def close(self) -> None:
        pass


__all__ = [
    "Admit",
    "Unit",
    "admit_all",
    "call_unit",
    "InProcess",
    "LocalProcesses",
    "check_jobs",
    "unit_progress",
]
