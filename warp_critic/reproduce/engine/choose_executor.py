"""The executor ``warp-critic reproduce``'s flags ask for: in this process (none), ``--jobs N`` local
processes, or ``--ray [ADDRESS]`` (:mod:`warp_critic.reproduce.engine.executors`,
:mod:`warp_critic.reproduce.engine.on_ray`; Ray itself is imported only when asked for), and the
line that names ``--jobs`` to a call that would gain from it."""

from __future__ import annotations

import os

from warp_critic.core.errors import FieldError
from warp_critic.reproduce.engine.executors import InProcess, LocalProcesses, check_jobs
from warp_critic.reproduce.engine.on_ray import RayExecutor


def check_executor_flags(jobs: int | None, ray: str | None) -> None:
    """``--jobs`` and ``--ray`` as :func:`make_executor` checks them, starting nothing (``--status``
    refuses what the call it answers for would refuse)."""
    if jobs is not None and ray is not None:
        raise FieldError("jobs", "and --ray exclude each other")
    if jobs is not None:
        check_jobs(jobs)


def make_executor(jobs: int | None, ray: str | None, device: str):
    """The executor the flags ask for (checked before any work)."""
    check_executor_flags(jobs, ray)
    if ray is not None:
        return RayExecutor(None if ray == "local" else ray, device)
    if jobs is not None:
        local = LocalProcesses(jobs)  # checks jobs
        return local if jobs > 1 else InProcess()
    return InProcess()


def jobs_hint(executor, widths: list[int]) -> str | None:
    """A line for a call that runs its stages one after the other in this process although the
    machine has more cores and stages that could run at once (``widths``: how many stages each wave
    has left to run); ``None`` otherwise. A paper-setting stage takes hours."""
    cores = os.cpu_count() or 1
    widest = max(widths, default=0)
    if not isinstance(executor, InProcess) or cores < 2 or widest < 2:
        return None
    n = min(cores, widest)
    return (
        f"reproduce: the stages run one after the other in this process; this machine has {cores} "
        f"cores, and --jobs {n} would run up to {n} independent stages at once (the same numbers; "
        "a baseline stage takes about 3 GB of memory)"
    )


__all__ = ["check_executor_flags", "jobs_hint", "make_executor"]
