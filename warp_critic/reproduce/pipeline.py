"""``reproduce``: run the stages a call needs (:mod:`~warp_critic.reproduce.experiments.plan`),
each once its inputs are complete, skipping complete ones, then write the report.

The top of ``reproduce/``: it joins the engine (stage directories, executors, ledger), the
experiments (the plan, each stage's function) and the report.
"""

from __future__ import annotations

import time
from pathlib import Path

from warp_critic.reproduce.engine.stages import Runner, claim_out
from warp_critic.reproduce.experiments.plan import ReproduceConfig, needed, plan
from warp_critic.reproduce.experiments.records import stage_problem


def reproduce(rc: ReproduceConfig, executor=None, hours: float | None = None) -> dict:
    """Run the stages of ``rc`` (with ``executor``; default: in this process) and write the report;
    ``hours``: this call's time limit (:mod:`~warp_critic.reproduce.engine.timelimit`: it raises
    ``TimeLimitReached`` when it stops the call before the report).

    Returns ``{"report": path, "records": ..., "out": ..., "plan": ...}``.
    """
    from warp_critic.reproduce.engine.executors import InProcess

    settings = rc.validate()
    out, lock = claim_out(Path(rc.out))
    try:
        return _reproduce(rc, settings, out, executor or InProcess(), hours)
    finally:
        lock.release()


def _reproduce(
    rc: ReproduceConfig, settings: dict, out: Path, executor, hours: float | None
) -> dict:
    from warp_critic.physics.simulator import resolve_device
    from warp_critic.reproduce.engine.ledger import Call
    from warp_critic.reproduce.engine.scheduler import pending, run_stages
    from warp_critic.reproduce.engine.timelimit import TimeLimit
    from warp_critic.reproduce.experiments.units import make_unit
    from warp_critic.reproduce.report.write import write_report

    device = resolve_device(rc.device)
    runner = Runner(out, stage_problem)
    t0 = time.perf_counter()
    stages = plan(settings, rc.plans_beyond, rc.extra, rc.plans_budget)
    limit = None
    if hours is not None:  # counted from here: the plan is built, no stage has started
        from warp_critic.reproduce.status import estimator, published_archive

        limit = TimeLimit(hours, estimator(out, stages, published_archive()))
    call = Call(out, rc.command, rc.selected(), device)  # the folder's ledger
    waves = needed(rc, stages)
    todo = pending(stages, waves, runner)  # a damaged stage record refuses the call here
    with call:
        run_stages(
            stages,
            waves,
            todo,
            runner,
            executor,
            call,
            lambda st: make_unit(st, settings, device, rc.progress, out),
            limit,
        )
        runner.log(
            f"reproduce: writing the report, {(time.perf_counter() - t0) / 60:.1f} min elapsed"
        )
        report = write_report(
            out,
            stages,
            runner.records,
            config=rc,
            device=device,
            wall=time.perf_counter() - t0,
            call=call.id,
        )
    runner.log(f"reproduce: done in {(time.perf_counter() - t0):.1f} s; report {report}")
    return {"report": report, "records": runner.records, "out": out, "plan": stages}
