"""Running: the task config and its worlds, the one run harness, run directories and recordings."""

from warp_critic.core.exports import lazy_exports

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
