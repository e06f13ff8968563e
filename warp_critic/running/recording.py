"""Recording: the one module that writes rerun ``.rrd`` files (and nothing else does).

Everything is written headlessly through an explicit :class:`rerun.RecordingStream` saved to a file:
no viewer is spawned and no port is opened. Close the recorder (or use it as a context manager) so
that the file gets its footer; ``rerun path/to/recording.rrd`` then opens it.

Timelines: ``iteration`` (outer/training iterations), ``step`` (simulation steps inside a rollout).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr
import rerun.blueprint as rrb


class Recorder:
    """A headless rerun recording written to ``path``.

    Args:
        path: output ``.rrd`` file; parent folders are created.
        application_id: shown in the viewer's title.
        blueprint: optional layout sent with the recording.
    """

    def __init__(
        self,
        path: str | Path,
        application_id: str = "warp-critic",
        blueprint=None,
        recording_id: str | None = None,
    ):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        # segments of one run (a resumed run records each segment) share the run's recording id, so
        # merged or opened together they are one recording
        self.stream = rr.RecordingStream(application_id, recording_id=recording_id)
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
            self.stream.disconnect()
            self._closed = True

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def read_entity_paths(path: str | Path) -> set[str]:
    """Entity paths stored in an ``.rrd`` file (used by tests and tools to check recordings)."""
    from rerun.chunk import RrdReader  # local: only needed for reading back

    schema = RrdReader(Path(path)).store().schema()
    return {str(p) for p in schema.entity_paths()}


_GOAL_COLORS = [
    (230, 25, 75),
    (60, 180, 75),
    (0, 130, 200),
    (245, 130, 48),
    (145, 30, 180),
    (70, 240, 240),
    (240, 50, 230),
    (210, 245, 60),
    (128, 128, 0),
    (0, 0, 128),
]


class TrainingRecorder:
    """Records a training run (any method) into ``recording.rrd``; used as a training callback.

    Logs, on the ``iteration`` timeline: the task loss per goal and its mean, the task loss of the
    untrained policies, and a policy-parameter trace (the first parameters and the norm of the
    updated policy of world 0). Every ``record_every`` iterations (and the first and last ones) it
    logs the rollout of one world per goal *before* and *after* the inner update as 3-D link
    transforms on the ``step`` timeline under ``rollout/<before|after>/it<k>/goal<i>/body<j>``.

    Args:
        path: output ``.rrd``.
        sim: the training :class:`~warp_critic.physics.simulator.Simulator` (for forward kinematics).
        goals: ``(G, dof)`` training goals.
        history: metrics rows of earlier iterations (a resumed run re-logs them so the recording is complete).
        record_every: rollout recording period (iterations).
        last_iteration: index of the final iteration (always recorded).
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
        self.world_offset = (
            world_offset  # this run's first world in ``sim`` (runs of several seeds share one)
        )
        G = goals.shape[0]
        blueprint = rrb.Blueprint(
            rrb.Horizontal(
                rrb.Vertical(
                    rrb.TimeSeriesView(origin="/train/task_loss", name="task loss per goal"),
                    rrb.TimeSeriesView(origin="/train/policy", name="policy parameters"),
                ),
                rrb.Spatial3DView(
                    origin="/rollout", name="rollouts (before / after the inner update)"
                ),
            ),
            collapse_panels=True,
        )
        self.rec = Recorder(
            path,
            application_id=f"warp-critic {method} {sim.scene.name}",
            blueprint=blueprint,
            recording_id=recording_id,
        )
        for i in range(G):
            self.rec.series_style(
                f"train/task_loss/goal{i}", f"goal {i}", _GOAL_COLORS[i % len(_GOAL_COLORS)]
            )
        self.rec.series_style("train/task_loss/mean", "mean")
        self.rec.series_style("train/task_loss_before/mean", "untrained policies")
        for row in history:
            self._log_row(row)

    def _log_row(self, row: dict) -> None:
        self.rec.set_time("iteration", row["iteration"])
        self.rec.scalar("train/task_loss/mean", row["task_loss"])
        if "task_loss_before" in row:
            self.rec.scalar("train/task_loss_before/mean", row["task_loss_before"])
        for i, v in enumerate(row.get("task_loss_per_goal", [])):
            self.rec.scalar(f"train/task_loss/goal{i}", v)
        for name in ("grad_norm", "seconds"):
            if name in row:
                self.rec.scalar(f"train/{name}", row[name])

    def __call__(self, info) -> None:
        self._log_row(info.metrics)
        res = info.result
        params = getattr(res, "params_new", None)
        if params is not None:
            from warp_critic.learning.networks import flat_params

            flat = flat_params(params)[self.world_offset].detach().cpu().numpy()
            self.rec.scalar("train/policy/norm", float(np.linalg.norm(flat)))
            for j in range(min(4, flat.size)):
                self.rec.scalar(f"train/policy/theta{j}", float(flat[j]))
        it = info.iteration
        if it == 0 or (it + 1) % self.record_every == 0 or it == self.last_iteration:
            worlds = [
                int(np.nonzero(info.goal_index.cpu().numpy() == g)[0][0])
                for g in range(self.goals.shape[0])
            ]
            for label, traj in (
                ("before", getattr(res, "before", None)),
                ("after", getattr(res, "after", None)),
            ):
                if traj is not None:
                    self.log_rollout(f"rollout/{label}/it{it}", traj.q, worlds)

    def log_rollout(self, prefix: str, q, worlds) -> None:
        """Link transforms of ``worlds`` along a trajectory ``q (T+1, W, dof)``."""
        T1 = q.shape[0]
        poses = np.stack([self.sim.body_poses(q[t]) for t in range(T1)])  # (T+1, W, B, 7)
        tips = np.stack([self.sim.tip_positions(q[t]) for t in range(T1)])  # (T+1, W, 3)
        for gi, w in enumerate(worlds):
            self.stream_static_strip(
                f"{prefix}/goal{gi}/tip_path", tips[:, w], _GOAL_COLORS[gi % len(_GOAL_COLORS)]
            )
        for gi, w in enumerate(worlds):
            color = _GOAL_COLORS[gi % len(_GOAL_COLORS)]
            for b in range(poses.shape[2]):
                self.rec.static_box(f"{prefix}/goal{gi}/body{b}", (0.03, 0.03, 0.03), color=color)
            for t in range(T1):
                self.rec.set_time("step", t)
                for b in range(poses.shape[2]):
                    self.rec.transform(
                        f"{prefix}/goal{gi}/body{b}", poses[t, w, b, :3], poses[t, w, b, 3:]
                    )
                self.rec.line_strips3d(
                    f"{prefix}/goal{gi}/skeleton", [poses[t, w, :, :3]], colors=[color]
                )
        self.rec.reset_time()

    def flush(self) -> None:
        """Wait until everything logged so far is written to the file."""
        self.rec.stream.flush()

    def stream_static_strip(self, entity: str, points: np.ndarray, color) -> None:
        self.rec.stream.log(entity, rr.LineStrips3D([points], colors=[color]), static=True)

    def close(self) -> None:
        self.rec.close()


__all__ = ["Recorder", "TrainingRecorder", "read_entity_paths", "rrb"]
