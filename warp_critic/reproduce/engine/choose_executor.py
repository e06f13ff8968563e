"""The executor ``warp-critic reproduce``'s flags ask for: in this process (none), ``--jobs N`` local
processes, or ``--ray [ADDRESS]`` (:mod:`warp_critic.reproduce.engine.executors`,
:mod:`warp_critic.reproduce.engine.on_ray`; Ray itself is imported only when asked for)."""

from __future__ import annotations

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


__all__ = ["check_executor_flags", "make_executor"]
