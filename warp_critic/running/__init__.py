"""Running: the task config and its worlds, the one run harness, run directories and recordings."""

# ruff: noqa: F401  (the TYPE_CHECKING imports name the lazy exports)

from typing import TYPE_CHECKING

from warp_critic.core.exports import lazy_exports

if TYPE_CHECKING:  # the names for IDEs and type checkers (Newton's pattern); at run time
    # they load lazily, on first use
    from warp_critic.running.config import check_fields, spec
    from warp_critic.running.loop import Interrupted, IterationInfo, Session, TrainResult
    from warp_critic.running.recording import Recorder, TrainingRecorder
    from warp_critic.running.rundir import RunDir, RunExistsError
    from warp_critic.running.task import Task, TaskConfig, build_task, load_task_scene

__all__, __getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "warp_critic.running.task": (
            "TaskConfig",
            "Task",
            "build_task",
            "load_task_scene",
        ),
        "warp_critic.running.config": ("check_fields", "spec"),
        "warp_critic.running.loop": ("Session", "TrainResult", "IterationInfo", "Interrupted"),
        "warp_critic.running.rundir": ("RunDir", "RunExistsError"),
        "warp_critic.running.recording": ("Recorder", "TrainingRecorder"),
    },
)
