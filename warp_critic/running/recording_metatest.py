"""A meta-test's recording: the fresh policies per goal before and after their critic-gradient steps.

Written beside the results file (``metatest.json`` -> ``metatest.rrd``), through the same headless
:class:`~warp_critic.running.recording.Recorder` as a run's recording. It opens
(:func:`~warp_critic.running.recording_view.metatest_blueprint`) on the ``policy_step`` timeline
with ``metatest/final_error`` (a bar per goal: the final error ``||q_T - g||^2`` after the steps,
mean over the inits), ``metatest/error/{mean,goal<i>}`` (that error at every policy step, 0 = the
untrained policies) and the 3-D view: per goal drawn, ``robot/goal<i>/target`` (the goal pose),
``before`` (grey) and ``after`` (the goal's colour), the final pose and tip path of the goal's first
init.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr

from warp_critic.core.errors import FieldError
from warp_critic.learning.losses import final_error
from warp_critic.running.files import RUN_FILES
from warp_critic.running.recording import Recorder
from warp_critic.running.recording_view import (
    MAX_GOALS_DRAWN,
    MEAN_COLOR,
    GoalStage,
    goal_color,
    metatest_blueprint,
)


def metatest_recording_path(out: str | Path) -> Path:
    """Where the meta-test writing the results file ``out`` (``.json``) records: ``out`` with the
    suffix ``.rrd`` (``.metatest.rrd`` where that would be one of a run's own files); checked before
    any work."""
    out = Path(out)
    path = out.with_suffix(".rrd")
    if path.name in RUN_FILES:
        path = out.with_suffix(".metatest.rrd")
    if path.is_dir():
        raise FieldError("out", f"{path}: the recording's place is a directory")
    return path


def record_meta_test(
    path: str | Path, sim, goals, goal, inits: int, rollouts, method: str = "ours"
) -> Path:
    """Write the recording of a meta-test to ``path`` and return it.

    Args:
        sim: the meta-test's simulator, ``W = G x inits`` worlds, goal-major.
        goals: ``(G, dof)`` test goals; ``goal``: ``(W, dof)`` each world's goal.
        rollouts: the fresh policies' rollouts (``.q``: ``(T+1, W, dof)``) at every policy step,
            the untrained policies' first and the trained policies' last.
    """
    G = goals.shape[0]
    shown = min(G, MAX_GOALS_DRAWN)
    stage = GoalStage(sim, goals, shown)
    errors = [final_error(r.q[-1], goal).view(G, inits).mean(1).cpu().numpy() for r in rollouts]
    with Recorder(
        path,
        application_id=f"warp-critic meta-test {method} {sim.scene.name}",
        blueprint=metatest_blueprint(stage.camera),
        whole=True,
    ) as rec:
        stage.log_static(rec.stream)
        worlds = [g * inits for g in range(shown)]
        stage.log_rollout(rec.stream, "before", rollouts[0].q, worlds, static=True)
        stage.log_rollout(rec.stream, "after", rollouts[-1].q, worlds, static=True)
        rec.stream.log(
            "metatest/final_error",
            rr.BarChart(np.asarray(errors[-1], np.float64), color=list(MEAN_COLOR)),
            static=True,
        )
        rec.series_style("metatest/error/mean", "mean", MEAN_COLOR)
        for i in range(G):
            rec.series_style(f"metatest/error/goal{i}", f"goal {i}", goal_color(i))
        for k, e in enumerate(errors):
            rec.set_time("policy_step", k)
            rec.scalar("metatest/error/mean", float(e.mean()))
            rec.scalars("metatest/error", e.tolist(), [f"goal{i}" for i in range(G)])
    return Path(path)


__all__ = ["metatest_recording_path", "record_meta_test"]
