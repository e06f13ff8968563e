"""The scheduler: run a plan's stages with an executor, each as soon as the stages it reads are complete.

Complete stages are skipped (their records read first: a damaged one refuses the call before any
work); every other stage is handed to the executor once each stage it ``depends`` on is complete,
whichever wave it is in; each finished stage is recorded (``stage.json``, written last) and entered
in the folder's ledger. With a time limit (:class:`~warp_critic.reproduce.engine.timelimit.TimeLimit`)
a stage starts only if it is expected to end in time, and the call stops at the limit.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

from warp_critic.core.errors import UserError
from warp_critic.reproduce.engine.choose_executor import jobs_hint
from warp_critic.reproduce.engine.executors import Unit
from warp_critic.reproduce.engine.ledger import Call
from warp_critic.reproduce.engine.stage import Stage
from warp_critic.reproduce.engine.stages import Runner, read_complete
from warp_critic.reproduce.engine.timelimit import TimeLimit


def pending(stages: Mapping[str, Stage], waves: list[list[str]], runner: Runner) -> list[list[str]]:
    """The stages of each wave that are not complete yet; sets ``runner.total``. Reads every stage
    record first: a damaged one refuses the call here, before any work."""
    todo = [
        [
            n
            for n in wave
            if read_complete(runner.stage_dir(n, stages[n].hash), stages[n].kind, runner.check)
            is None
        ]
        for wave in waves
    ]
    runner.total = sum(len(wave) for wave in todo)
    return todo


def run_stages(
    stages: Mapping[str, Stage],
    waves: list[list[str]],
    todo: list[list[str]],
    runner: Runner,
    executor,
    call: Call,
    make_unit: Callable[[Stage], Unit],
    limit: TimeLimit | None = None,
) -> None:
    """Run the stages of ``waves`` that are not complete (``todo``, from :func:`pending`) with
    ``executor``, recording each in ``runner`` and ``call``; the complete ones are recorded as
    skipped. Raises a one-line :class:`UserError` if a stage's input never completed. With
    ``limit``: a ready stage that it says will not end in time is not started (nor the stages that
    read it), and at the limit the running ones are stopped; either way the call then ends with
    :class:`~warp_critic.reproduce.engine.timelimit.TimeLimitReached`."""

    def done(unit: Unit, result: dict, seconds: float) -> None:
        st = stages[unit.name]
        runner.finish(st.kind, unit.name, st.hash, st.settings, result, seconds, st.depends)
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
        if runner.complete(stages[n].kind, n, stages[n].hash) is None
    ]

    def ready() -> list[Unit]:
        """The units of the waiting stages whose every input stage is now complete: a stage starts
        as soon as the stages it reads are done, not after all of an earlier wave."""
        units = []
        for n in list(waiting):
            if all(dep in runner.records for dep in stages[n].depends):
                waiting.remove(n)
                units.append(make_unit(stages[n]))
        return units

    def admit(unit: Unit) -> bool:
        """Asked when a worker is free for ``unit``: with a limit, whether it can end in time (one
        that cannot is left for the next call, and so are the stages that read it)."""
        if limit is None or limit.fits(unit.name):
            return True
        runner.log(f"reproduce: {unit.name}: left for the next call: {limit.held[unit.name]}")
        return False

    def left() -> list[str]:
        return [
            n for n in dict.fromkeys(n for wave in todo for n in wave) if n not in runner.records
        ]

    if limit is not None:
        limit.start()
    try:
        executor.run(ready(), runner.out, done, runner.log, more=ready, admit=admit)
    except KeyboardInterrupt as e:
        if limit is not None and limit.reached:
            raise limit.outcome(left(), kept=str(e)) from None
        raise
    finally:
        if limit is not None:
            limit.cancel()
        executor.close()
    if left() and limit is not None and limit.held:
        raise limit.outcome(left())
    if waiting:  # an input that this call neither found complete nor ran
        raise UserError(f"reproduce: {', '.join(waiting)}: an input stage did not complete")


__all__ = ["pending", "run_stages"]
