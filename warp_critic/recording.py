"""Recording: the one module that writes rerun ``.rrd`` files (and nothing else does).

Everything is written headlessly through an explicit :class:`rerun.RecordingStream` saved to a file:
no viewer is spawned and no port is opened. Close the recorder (or use it as a context manager) so
that the file gets its footer; ``rerun path/to/recording.rrd`` then opens it.

Timelines: ``iteration`` (outer/training iterations), ``step`` (simulation steps inside a rollout).
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

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

    def __init__(self, path: str | Path, application_id: str = "warp-critic", blueprint=None):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.stream = rr.RecordingStream(application_id)
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
        kwargs = {"names": name}
        if color is not None:
            kwargs["colors"] = [list(color)]
        self.stream.log(entity, rr.SeriesLines(**kwargs), static=True)

    def image(self, entity: str, rgb: np.ndarray, static: bool = False) -> None:
        """An ``(H, W, 3|4)`` uint8 image."""
        self.stream.log(entity, rr.Image(np.asarray(rgb)), static=static)

    def tensor(self, entity: str, array: np.ndarray, dim_names: Sequence[str] | None = None,
               static: bool = False) -> None:
        self.stream.log(entity, rr.Tensor(np.asarray(array), dim_names=dim_names), static=static)

    def arrows2d(self, entity: str, origins: np.ndarray, vectors: np.ndarray,
                 colors: np.ndarray | None = None, static: bool = False) -> None:
        self.stream.log(entity, rr.Arrows2D(origins=np.asarray(origins), vectors=np.asarray(vectors),
                                            colors=colors), static=static)

    def points2d(self, entity: str, positions: np.ndarray, colors=None, radii=None,
                 static: bool = False) -> None:
        self.stream.log(entity, rr.Points2D(np.asarray(positions), colors=colors, radii=radii),
                        static=static)

    def points3d(self, entity: str, positions: np.ndarray, colors=None, radii=None) -> None:
        self.stream.log(entity, rr.Points3D(np.asarray(positions), colors=colors, radii=radii))

    def line_strips3d(self, entity: str, strips: Sequence[np.ndarray], colors=None, radii=None) -> None:
        self.stream.log(entity, rr.LineStrips3D([np.asarray(s) for s in strips], colors=colors, radii=radii))

    def transform(self, entity: str, translation: np.ndarray, quat_xyzw: np.ndarray) -> None:
        """A rigid transform (metres, unit quaternion in x, y, z, w order)."""
        self.stream.log(entity, rr.Transform3D(translation=np.asarray(translation, dtype=np.float32),
                                               quaternion=rr.Quaternion(xyzw=np.asarray(quat_xyzw, dtype=np.float32))))

    def static_box(self, entity: str, half_size: Sequence[float], center=(0.0, 0.0, 0.0), color=None) -> None:
        self.stream.log(entity, rr.Boxes3D(half_sizes=[list(half_size)], centers=[list(center)],
                                           colors=None if color is None else [list(color)]), static=True)

    def text(self, entity: str, text: str, static: bool = True) -> None:
        self.stream.log(entity, rr.TextDocument(text, media_type="text/markdown"), static=static)

    # -- lifetime -----------------------------------------------------------------------------
    def close(self) -> None:
        """Flush and close so the file gets its footer. Idempotent."""
        if not self._closed:
            self.stream.flush()
            self.stream.disconnect()
            self._closed = True

    def __enter__(self) -> "Recorder":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def read_entity_paths(path: str | Path) -> set[str]:
    """Entity paths stored in an ``.rrd`` file (used by tests and tools to check recordings)."""
    from rerun.chunk import RrdReader  # local: only needed for reading back

    schema = RrdReader(Path(path)).store().schema()
    return {str(p) for p in schema.entity_paths()}


__all__ = ["Recorder", "read_entity_paths", "rrb"]
