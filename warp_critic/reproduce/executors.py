"""Where ``reproduce`` runs its units of work: in this process, in local processes, or on Ray.

A **unit** is one stage (sub-stage) of the plan -- the toy, the landscape, one method x robot
meta-training with all its seeds, the reacher maps, the KUKA tables -- described by plain data
(:class:`Unit`: the function to call by its import path, its keyword arguments, the stage
directories it reads), so any executor can run it anywhere. Whatever runs it, the driver alone
writes ``stage.json`` (last, atomically), so a unit that did not finish is never taken for a
complete one, and a restarted driver skips exactly the units that finished.

* :class:`InProcess` (the default): one after the other, here, with progress bars.
* :class:`LocalProcesses` (``--jobs N``): ``N`` fresh processes on this machine writing into the
  output folder directly; a process that dies costs only its unit, which is run again (up to
  ``retries`` times).
* :class:`RayExecutor` (``--ray [ADDRESS]``): one Ray task per unit with its resource request (one
  GPU for a CUDA run, one CPU otherwise). No shared filesystem is assumed: a task gets the files of
  the stage directories it reads (and of its own unfinished stage directory, to resume) and returns
  the files of its stage directory, which the driver writes into ``--out``. Ray retries a task whose
  worker died (``max_retries``), each try from the files the driver holds, so a partial run never
  reaches a table.
"""

from __future__ import annotations

import importlib
import os
import signal
import socket
import sys
import tempfile
import time
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from pathlib import Path

from warp_critic.core.errors import FieldError, UserError

UNIT_FAULT_ENV = "WARP_CRITIC_UNIT_FAULT"  # tests: "<unit name>:<marker file>" kills its first try


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


# ------------------------------------------------------------------------------------------------
# executors
# ------------------------------------------------------------------------------------------------

Done = Callable[[Unit, dict, float], None]  # (unit, result, seconds): the driver records the stage


class InProcess:
    """Run the units here, one after the other (progress bars on stderr)."""

    name = "in-process"

    def run(self, units: list[Unit], root: Path, done: Done, log: Callable[[str], None]) -> None:
        for u in units:
            log(f"reproduce: {u.name}: running ({u.dir_name})")
            t = time.perf_counter()
            result = call_unit(u, root)
            done(u, result, time.perf_counter() - t)

    def close(self) -> None:
        pass


_IN_UNIT = False  # a worker process: is a unit running (set around it by _process_unit)?


def _worker_stop(signum, frame) -> None:
    """SIGTERM in a worker (the driver stopping, or dying: PDEATHSIG). Mid-unit it stops the unit the way
    Ctrl-C stops a CLI run: the run's ``finally`` blocks close its recording and release its lock, so the
    next call resumes without a stale lock. An idle worker just exits."""
    if _IN_UNIT:
        raise KeyboardInterrupt
    os._exit(128 + signum)


def _process_init() -> None:
    """A worker process: stop with the driver (Linux: even when the driver is SIGKILLed), then start as
    the CLI starts."""
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
    t = time.perf_counter()
    _IN_UNIT = True
    try:
        return call_unit(_quiet(unit), Path(root)), time.perf_counter() - t
    finally:
        _IN_UNIT = False


class LocalProcesses:
    """``jobs`` worker processes on this machine (spawned fresh: no state shared with the driver)."""

    name = "local processes"

    def __init__(self, jobs: int, retries: int = 2):
        if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
            raise FieldError("jobs", f"must be an integer >= 1 (got {jobs!r})")
        self.jobs, self.retries = jobs, retries
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

    def run(self, units: list[Unit], root: Path, done: Done, log: Callable[[str], None]) -> None:
        try:
            self._run(units, root, done, log)
        except BaseException:
            # a unit failed for good, or Ctrl-C / SIGTERM: stop the other units' processes too (each
            # resumes from its checkpoints next time) instead of waiting for them to finish
            import multiprocessing

            for child in multiprocessing.active_children():
                child.terminate()
            if self._pool_now is not None:
                self._pool_now.shutdown(wait=True, cancel_futures=True)
            raise

    def _run(self, units: list[Unit], root: Path, done: Done, log: Callable[[str], None]) -> None:
        tries = {u.name: 0 for u in units}
        pending = list(units)
        while pending:
            pool = self._pool_now = self._pool()
            futures = {}
            for u in pending:
                log(f"reproduce: {u.name}: submitted to a local process ({u.dir_name})")
                futures[pool.submit(_process_unit, u, str(root))] = u
            pending = []
            broken = False
            while futures:
                finished, _ = wait(futures, return_when=FIRST_COMPLETED)
                for f in finished:
                    u = futures.pop(f)
                    try:
                        result, seconds = f.result()
                    except BrokenProcessPool:
                        broken = True
                        pending.append(u)
                        continue
                    except BaseException:
                        pool.shutdown(wait=False, cancel_futures=True)
                        raise
                    done(u, result, seconds)
            pool.shutdown(wait=True, cancel_futures=True)
            if broken:
                for u in pending:
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

    def close(self) -> None:
        pass


# -- Ray -------------------------------------------------------------------------------------------


def _read_tree(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder``, keyed by its path relative to ``folder.parent``."""
    out = {}
    if folder.is_dir():
        for p in sorted(folder.rglob("*")):
            if p.is_file() and not p.name.endswith(".tmp") and p.name != ".lock":
                out[str(p.relative_to(folder.parent))] = p.read_bytes()
    return out


def _write_tree(root: Path, files: dict[str, bytes]) -> None:
    from warp_critic.running.rundir import atomic_write_bytes

    for rel, data in files.items():
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(path, data)


def _ray_unit(
    unit: Unit, inputs: dict[str, bytes], env: dict[str, str]
) -> tuple[dict[str, bytes], dict, float]:
    """A Ray task: run ``unit`` in a private folder holding ``inputs``; return its stage directory's files."""
    os.environ.update(env)
    from warp_critic.core.runtime import init

    init()
    with tempfile.TemporaryDirectory(prefix="warp-critic-unit-") as tmp:
        root = Path(tmp)
        for rel, data in inputs.items():
            (root / rel).parent.mkdir(parents=True, exist_ok=True)
            (root / rel).write_bytes(data)
        t = time.perf_counter()
        result = call_unit(_quiet(unit), root)
        seconds = time.perf_counter() - t
        return _read_tree(root / unit.dir_name), result, seconds


def check_ray_address(address: str | None) -> None:
    """A reachable ``HOST:PORT`` (or ``auto``, or none for a local cluster), checked before anything starts."""
    if address in (None, "", "auto", "local"):
        return
    host, sep, port = address.removeprefix("ray://").rpartition(":")
    if not sep or not host or not port.isdigit():
        raise FieldError(
            "ray",
            f"{address!r}: expected auto, or HOST:PORT of the cluster's head (e.g. 10.0.0.1:6379)",
        )
    try:
        with socket.create_connection((host, int(port)), timeout=3.0):
            pass
    except (OSError, ValueError) as e:
        raise FieldError("ray", f"{address}: cannot reach the Ray cluster's head ({e})") from None


class RayExecutor:
    """One Ray task per unit (``address``: ``None`` starts a local cluster, ``auto`` joins the running
    one, ``HOST:PORT`` the head at that address)."""

    name = "ray"

    def __init__(
        self, address: str | None, device: str, num_cpus: int | None = None, retries: int = 3
    ):
        try:
            import ray
        except ImportError:
            raise UserError('--ray needs Ray: pip install -e ".[ray]"') from None
        check_ray_address(address)
        self.ray, self.retries = ray, retries
        kwargs = dict(include_dashboard=False, log_to_driver=False, configure_logging=False)
        try:
            if address in (None, "", "local"):  # a cluster of this machine alone, on loopback
                ray.init(
                    num_cpus=num_cpus or os.cpu_count(), _node_ip_address="127.0.0.1", **kwargs
                )
            else:
                ray.init(address=address, **kwargs)
        except Exception as e:  # ConnectionError and Ray's own
            raise FieldError(
                "ray",
                f"{address or 'local'}: cannot start or join a Ray cluster "
                f"({type(e).__name__}: {' '.join(str(e).split())[:160]})",
            ) from None
        self.gpu = str(device).startswith("cuda")
        if self.gpu and not ray.cluster_resources().get("GPU", 0):
            ray.shutdown()
            raise FieldError("device", f"{device}: the Ray cluster has no GPU")

    def run(self, units: list[Unit], root: Path, done: Done, log: Callable[[str], None]) -> None:
        ray = self.ray
        env = {
            k: v
            for k, v in os.environ.items()
            if k in (UNIT_FAULT_ENV, "WARP_CRITIC_TORCH_THREADS")
        }
        task = ray.remote(_ray_unit).options(
            max_retries=self.retries,
            retry_exceptions=False,
            num_cpus=0 if self.gpu else 1,
            num_gpus=1 if self.gpu else 0,
        )
        refs = {}
        for u in units:
            inputs = _read_tree(root / u.dir_name)  # an unfinished stage directory resumes
            for d in u.reads:
                inputs.update(_read_tree(root / d))
            log(f"reproduce: {u.name}: submitted to Ray ({u.dir_name}, {len(inputs)} input files)")
            refs[task.remote(u, inputs, env)] = u
        while refs:
            ready, _ = ray.wait(list(refs), num_returns=1)
            u = refs.pop(ready[0])
            try:
                files, result, seconds = ray.get(ready[0])
            except Exception as e:  # the unit failed for good (after Ray's retries)
                raise UserError(
                    f"reproduce: unit {u.name} failed on Ray ({type(e).__name__}: "
                    f"{' '.join(str(e).split())[:200]}); run again to resume"
                ) from None
            stage = root / u.dir_name
            _write_tree(root, files)
            for p in sorted(
                stage.rglob("*"), reverse=True
            ):  # the task returned the whole directory:
                rel = str(
                    p.relative_to(root)
                )  # what it removed (unstarted seeds, merged segments) goes
                if p.is_file() and rel not in files and p.name != ".lock":
                    p.unlink()
            done(u, result, seconds)

    def close(self) -> None:
        self.ray.shutdown()


def make_executor(jobs: int | None, ray: str | None, device: str):
    """The executor the flags ask for (checked before any work)."""
    if jobs is not None and ray is not None:
        raise FieldError("jobs", "and --ray exclude each other")
    if ray is not None:
        return RayExecutor(None if ray == "local" else ray, device)
    if jobs is not None:
        local = LocalProcesses(jobs)  # checks jobs
        return local if jobs > 1 else InProcess()
    return InProcess()


__all__ = [
    "Unit",
    "call_unit",
    "InProcess",
    "LocalProcesses",
    "RayExecutor",
    "make_executor",
    "check_ray_address",
]
