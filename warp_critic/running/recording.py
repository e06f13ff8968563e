"""Recording: the one module that writes rerun ``.rrd`` files (``recording_view`` only draws the
robot into a stream opened here).

Everything is written headlessly through an explicit :class:`rerun.RecordingStream` saved to a file:
no viewer is spawned and no port is opened. Close the recorder (or use it as a context manager) so
that the file gets its footer; ``rerun path/to/recording.rrd`` then opens it.

A training run's recording is on one timeline, ``iteration`` (outer/training iterations), which its
layout opens on: the time cursor selects the iteration whose rollouts the 3-D view shows.
"""

from __future__ import annotations

from collections.abc import Sequence
from datetime import timedelta
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from warp_critic.running.recording_view import (
    ACTOR_SIGNALS,
    BEFORE_COLOR,
    CRITIC_SIGNALS,
    MAX_GOALS_DRAWN,
    MEAN_COLOR,
    POLICY_COLOR,
    GoalStage,
    goal_color,
    training_blueprint,
)


class Recorder:
    """A headless rerun recording written to ``path``.

    Args:
        path: output ``.rrd`` file; parent folders are created.
        application_id: shown in the viewer's title.
        blueprint: optional layout sent with the recording.
        flush_seconds: how long logged data may wait to be batched into larger chunks (smaller
            files; :meth:`flush` writes it at once); ``None``: rerun's default (a few ms).
        whole: keep the recording in memory and write it at :meth:`close`, atomically (a full
            disk is one :class:`~warp_critic.running.files.DiskFullError` and leaves no part of a
            file; rerun's own file writer fails in a thread, with a traceback and log lines). For
            recordings that fit in memory (a meta-test's).
    """

    def __init__(
        self,
        path: str | Path,
        application_id: str = "warp-critic",
        blueprint=None,
        recording_id: str | None = None,
        flush_seconds: float | None = None,
        whole: bool = False,
    ):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        # segments of one run (a resumed run records each segment) share the run's recording id, so
        # merged or opened together they are one recording
        batcher = None
        if flush_seconds is not None:
            batcher = rr.ChunkBatcherConfig(
                flush_tick=timedelta(seconds=flush_seconds), flush_num_bytes=1 << 20
            )
        self.stream = rr.RecordingStream(
            application_id, recording_id=recording_id, batcher_config=batcher
        )
        self._memory = None
        if whole:
            self._memory = self.stream.memory_recording()
            if blueprint is not None:
                self.stream.send_blueprint(blueprint, make_active=True, make_default=True)
        else:
            self.stream.save(str(self.path), default_blueprint=blueprint)
        self._closed = False

    # -- time ---------------------------------------------------------------------------------
    def set_time(self, timeline: str, value: int) -> None:
        """Set the current index on ``timeline`` for everything logged next."""
        self.stream.set_time(timeline, sequence=int(value))

    def reset_time(self) -> None:
        self.stream.reset_time()

    # -- primitives ---------------------------------------------------------------------------
    def scalar(self, entity: str, value: float) -> None:
        """One point of a time series at the current time."""
        self.stream.log(entity, rr.Scalars(float(value)))

    def scalars(self, entity_prefix: str, values: Sequence[float], names: Sequence[str]) -> None:
        """Several series, ``entity_prefix/name`` each, at the current time."""
        for name, value in zip(names, values):
            self.scalar(f"{entity_prefix}/{name}", value)

    def series_style(self, entity: str, name: str, color: Sequence[int] | None = None) -> None:
        """Name (and optionally colour) a series once, statically."""
        kwargs: dict[str, Any] = {"names": name}
        if color is not None:
            kwargs["colors"] = [list(color)]
        self.stream.log(entity, rr.SeriesLines(**kwargs), static=True)

    def image(self, entity: str, rgb: np.ndarray, static: bool = False) -> None:
        """An ``(H, W, 3|4)`` uint8 image."""
        self.stream.log(entity, rr.Image(np.asarray(rgb)), static=static)

    def tensor(
        self,
        entity: str,
        array: np.ndarray,
        dim_names: Sequence[str] | None = None,
        static: bool = False,
    ) -> None:
        self.stream.log(entity, rr.Tensor(np.asarray(array), dim_names=dim_names), static=static)

    def arrows2d(
        self,
        entity: str,
        origins: np.ndarray,
        vectors: np.ndarray,
        colors: np.ndarray | None = None,
        static: bool = False,
    ) -> None:
        self.stream.log(
            entity,
            rr.Arrows2D(origins=np.asarray(origins), vectors=np.asarray(vectors), colors=colors),
            static=static,
        )

    def points2d(
        self, entity: str, positions: np.ndarray, colors=None, radii=None, static: bool = False
    ) -> None:
        self.stream.log(
            entity, rr.Points2D(np.asarray(positions), colors=colors, radii=radii), static=static
        )

    def points3d(self, entity: str, positions: np.ndarray, colors=None, radii=None) -> None:
        self.stream.log(entity, rr.Points3D(np.asarray(positions), colors=colors, radii=radii))

    def line_strips3d(
        self, entity: str, strips: Sequence[np.ndarray], colors=None, radii=None
    ) -> None:
        self.stream.log(
            entity, rr.LineStrips3D([np.asarray(s) for s in strips], colors=colors, radii=radii)
        )

    def transform(self, entity: str, translation: np.ndarray, quat_xyzw: np.ndarray) -> None:
        """A rigid transform (metres, unit quaternion in x, y, z, w order)."""
        self.stream.log(
            entity,
            rr.Transform3D(
                translation=np.asarray(translation, dtype=np.float32),
                quaternion=rr.Quaternion(xyzw=np.asarray(quat_xyzw, dtype=np.float32)),
            ),
        )

    def static_box(
        self, entity: str, half_size: Sequence[float], center=(0.0, 0.0, 0.0), color=None
    ) -> None:
        self.stream.log(
            entity,
            rr.Boxes3D(
                half_sizes=[list(half_size)],
                centers=[list(center)],
                colors=None if color is None else [list(color)],
            ),
            static=True,
        )

    def text(self, entity: str, text: str, static: bool = True) -> None:
        self.stream.log(entity, rr.TextDocument(text, media_type="text/markdown"), static=static)

    # -- lifetime -----------------------------------------------------------------------------
    def close(self) -> None:
        """Flush and close so the file gets its footer. Idempotent."""
        if not self._closed:
            self.stream.flush()
            self._closed = True
            if self._memory is not None:
                from warp_critic.running.files import atomic_write_bytes

                data = self._memory.drain_as_bytes()
                self.stream.disconnect()
                atomic_write_bytes(self.path, data)
            else:
                self.stream.disconnect()

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def read_entity_paths(path: str | Path) -> set[str]:
    """Entity paths stored in an ``.rrd`` file (used by tests and tools to check recordings)."""
    from rerun.chunk import RrdReader  # local: only needed for reading back

    schema = RrdReader(Path(path)).store().schema()
    return {str(p) for p in schema.entity_paths()}


def recorded_iterations(path: str | Path) -> list[int]:
    """The iterations whose rollouts (``robot/goal<i>/after``) an ``.rrd`` file holds, sorted."""
    from rerun.chunk import RrdReader  # local: only needed for reading back

    its: set[int] = set()
    for chunk in RrdReader(Path(path)).store().stream().to_chunks():
        if "/after" in str(chunk.entity_path) and "iteration" in chunk.timeline_names:
            its.update(int(x) for x in chunk.to_record_batch().column("iteration").to_pylist())
    return sorted(its)


class TrainingRecorder:
    """Records a training run (any method) into ``recording.rrd``; used as a training callback.

    Everything is on the ``iteration`` timeline, which the recording opens on
    (:func:`training_blueprint`): ``train/task_loss/{mean,goal<i>}`` (the updated policies; a
    baseline's noise-free actor), ``train/task_loss_before/mean`` (ours: the untrained policies) or
    ``train/task_loss_explore/mean`` (a baseline's exploration), ``train/critic/<signal>``,
    ``train/actor/actor_loss`` (baselines), ``train/policy/update_norm`` (ours: the inner update's
    ``|theta' - theta|`` of the run's first world). The 3-D view holds one copy of the robot per goal (the
    first :data:`MAX_GOALS_DRAWN`), laid side by side under ``robot/goal<i>``: ``target`` (the goal
    pose as a wireframe ghost, its tip labelled), ``base``, and every ``record_every`` iterations
    (and the first and last) ``before`` and ``after`` (the final pose of one world of that goal and
    its tip path, before and after the inner update). Moving the time cursor selects an iteration.

    Args:
        path: output ``.rrd``.
        sim: the training :class:`~warp_critic.physics.simulator.Simulator` (for forward kinematics).
        goals: ``(G, dof)`` training goals.
        history: metrics rows of earlier iterations (a resumed run re-logs them so the recording is complete).
        record_every: rollout recording period (iterations).
        last_iteration: index of the final iteration (always recorded).
        world_offset: this run's first world in ``sim`` (runs of several seeds share one).
    """

    def __init__(
        self,
        path,
        sim,
        goals,
        history=(),
        record_every: int = 50,
        last_iteration: int | None = None,
        method: str = "ours",
        recording_id: str | None = None,
        world_offset: int = 0,
    ):
        self.sim, self.goals = sim, goals
        self.record_every, self.last_iteration = record_every, last_iteration
        self.world_offset = world_offset
        self.shown = min(goals.shape[0], MAX_GOALS_DRAWN)
        self.stage = GoalStage(sim, goals, self.shown, world_offset)
        self.drawing = self.stage.drawing
        self.rec = Recorder(
            path,
            application_id=f"warp-critic {method} {sim.scene.name}",
            blueprint=training_blueprint(method, self.stage.camera),
            recording_id=recording_id,
            flush_seconds=30.0,  # the harness flushes before every checkpoint
        )
        self._log_static()
        for row in history:
            self._log_row(row)

    def _log_static(self) -> None:
        for i in range(self.goals.shape[0]):
            self.rec.series_style(f"train/task_loss/goal{i}", f"goal {i}", goal_color(i))
        self.rec.series_style("train/task_loss/mean", "mean", MEAN_COLOR)
        self.rec.series_style("train/task_loss_before/mean", "untrained policies", BEFORE_COLOR)
        self.rec.series_style("train/task_loss_explore/mean", "exploration", BEFORE_COLOR)
        for key, (name, color) in {**CRITIC_SIGNALS, **ACTOR_SIGNALS}.items():
            group = "actor" if key in ACTOR_SIGNALS else "critic"
            self.rec.series_style(f"train/{group}/{key}", name, color)
        self.rec.series_style("train/policy/update_norm", "|theta' - theta|", POLICY_COLOR)
        self.stage.log_static(self.rec.stream)

    def _log_row(self, row: dict) -> None:
        self.rec.set_time("iteration", row["iteration"])
        for key, entity in (
            ("task_loss", "task_loss/mean"),
            ("task_loss_before", "task_loss_before/mean"),
            ("task_loss_explore", "task_loss_explore/mean"),
        ):
            if row.get(key) is not None:
                self.rec.scalar(f"train/{entity}", row[key])
        for i, v in enumerate(row.get("task_loss_per_goal", [])):
            if v is not None:
                self.rec.scalar(f"train/task_loss/goal{i}", v)
        for group, keys in (("critic", CRITIC_SIGNALS), ("actor", ACTOR_SIGNALS)):
            for key in keys:
                if row.get(key) is not None:
                    self.rec.scalar(f"train/{group}/{key}", row[key])

    def __call__(self, info) -> None:
        self._log_row(info.metrics)
        res = info.result
        params, params_new = getattr(res, "params", None), getattr(res, "params_new", None)
        if params_new is not None and params is not None:
            from warp_critic.learning.networks import flat_params

            w = self.world_offset
            step = flat_params(params_new)[w] - flat_params(params)[w]
            self.rec.scalar("train/policy/update_norm", float(step.norm()))
        it = info.iteration
        if it == 0 or (it + 1) % self.record_every == 0 or it == self.last_iteration:
            goal_index = info.goal_index.cpu().numpy()
            worlds = [int(np.nonzero(goal_index == g)[0][0]) for g in range(self.shown)]
            for label, traj in (
                ("before", getattr(res, "before", None)),
                ("after", getattr(res, "after", None)),
            ):
                if traj is not None:
                    self.log_rollout(label, traj.q, worlds)
        self.rec.reset_time()

    def log_rollout(self, label: str, q, worlds) -> None:
        """The final pose and the tip path of ``worlds`` (one per goal drawn) along a trajectory
        ``q (T+1, W, dof)`` under ``robot/goal<i>/<label>``, at the current iteration."""
        self.stage.log_rollout(self.rec.stream, label, q, worlds)

    def flush(self) -> None:
        """Wait until everything logged so far is written to the file."""
        self.rec.stream.flush()

    def close(self) -> None:
        self.rec.close()


def read_times(path: str | Path, entity_prefix: str, timeline: str = "iteration") -> set[int]:
    """The times on ``timeline`` at which anything under ``entity_prefix`` was logged in an ``.rrd``
    file (used by tests to check recordings)."""
    from rerun.chunk import RrdReader  # local: only needed for reading back

    times: set[int] = set()
    for chunk in RrdReader(Path(path)).store().stream():
        if chunk.entity_path.startswith(entity_prefix) and timeline in chunk.timeline_names:
            times.update(chunk.to_record_batch().column(timeline).to_pylist())
    return times


__all__ = [
    "Recorder",
    "TrainingRecorder",
    "read_entity_paths",
    "recorded_iterations",
    "read_times",
    "rrb",
    "training_blueprint",
]
