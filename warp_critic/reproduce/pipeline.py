"""``reproduce``: run the stages a call needs (:mod:`~warp_critic.reproduce.experiments.plan`),
each once its inputs are complete, skipping complete ones, then write the report.

The top of ``reproduce/``: it joins the engine (stage directories, executors, ledger), the
experiments (the plan, each stage's function) and the report.
"""

from __future__ import annotations

import time
from pathlib import Path

from warp_critic.core.errors import UserError
from warp_critic.reproduce.engine.stages import Runner, claim_out, read_complete
from warp_critic.reproduce.experiments.plan import ReproduceConfig, needed, plan
from warp_critic.reproduce.experiments.records import stage_problem


def reproduce(rc: ReproduceConfig, executor=None) -> dict:
    """Run the stages of ``rc`` (with ``executor``; default: in this process) and write the report.

    Returns ``{"report": path, "records": ..., "out": ..., "plan": ...}``.
    """
    from warp_critic.reproduce.engine.executors import InProcess

    settings = rc.validate()
    out, lock = claim_out(Path(rc.out))
    try:
        return _reproduce(rc, settings, out, executor or InProcess())
    finally:
        lock.release()


def _reproduce(rc: ReproduceConfig, settings: dict, out: Path, executor) -> dict:
    from warp_critic.physics.simulator import resolve_device
    from warp_critic.reproduce.engine.executors import jobs_hint
    from warp_critic.reproduce.engine.ledger import Call
    from warp_critic.reproduce.experiments.units import make_unit

    device = resolve_device(rc.device)
    runner = Runner(out, stage_problem)
    t0 = time.perf_counter()
    stages = plan(settings, beyond=rc.plans_beyond, extra=rc.extra)
    call = Call(out, rc.command, rc.selected(), device)  # the folder's ledger
    waves = needed(rc, stages)
    todo = [  # reads every stage record first: a damaged one refuses the call here
        [
            n
            for n in wave
            if read_complete(
                runner.stage_dir(n, stages[n]["hash"]), stages[n]["group"], stage_problem
            )
            is None
        ]
        for wave in waves
    ]
    runner.total = sum(len(wave) for wave in todo)
    with call:

        def done(unit, result, seconds):
            st = stages[unit.name]
            runner.finish(
                st["group"],
                unit.name,
                st["hash"],
                st["settings"],
                result,
                seconds,
                depends=st["depends"],
            )
            call.stage(unit.name, seconds, unit.dir_name)

        runner.log(
            f"reproduce: {runner.total} stage(s) to run ({executor.name}); complete ones are skipped"
        )
        hint = jobs_hint(executor, [len(wave) for wave in todo])
        if hint:
            runner.log(hint)
        waiting = [  # the complete ones are recorded (and said skipped) here
            n
            for n in dict.fromkeys(n for wave in waves for n in wave)
            if runner.complete(stages[n]["group"], n, stages[n]["hash"]) is None
        ]

        def ready() -> list:
            """The units of the waiting stages whose every input stage is now complete: a maps or
            tables stage starts as soon as its robot's meta-trainings are done, not after all."""
            units = []
            for n in list(waiting):
                if all(dep in runner.records for dep in stages[n]["depends"]):
                    waiting.remove(n)
                    units.append(make_unit(n, stages[n], settings, device, rc.progress, out))
            return units

        try:
            executor.run(ready(), out, done, runner.log, more=ready)
        finally:
            executor.close()
        if waiting:  # an input that this call neither found complete nor ran
            raise UserError(f"reproduce: {', '.join(waiting)}: an input stage did not complete")
        runner.log(
            f"reproduce: writing the report, {(time.perf_counter() - t0) / 60:.1f} min elapsed"
        )
        from warp_critic.reproduce.report.write import write_report

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
