"""What a run's recording shows in the viewer: its layout and the robot.

:func:`training_blueprint` is the layout a run's recording opens with.
:class:`RobotDrawing` reads one world's shapes from the Newton model (capsules, spheres, boxes,
cylinders attached to the bodies, and the static base shapes); a robot whose bodies carry no such
shape (meshes only, or none) is drawn as line strips along its links (parent body to child body, and
the end-effector body to the tip). :func:`camera_for` frames a set of points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

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
BEFORE_COLOR = (150, 150, 150)  # the arm before the inner update (a baseline's exploration)
BASE_COLOR = (90, 90, 90)
MAX_GOALS_DRAWN = 6  # goals drawn in the 3-D view (every goal is plotted)

MEAN_COLOR = (255, 190, 0)
# metrics-row keys -> (series name, colour); a row logs the keys it has
CRITIC_SIGNALS = {
    "grad_norm": ("outer gradient norm |dL/dphi|", (230, 80, 160)),
    "critic_loss": ("TD loss", (230, 80, 160)),
    "q_mean": ("mean Q", (0, 170, 230)),
    "meta_loss": ("meta loss", (120, 200, 60)),
    "aux_loss": ("auxiliary loss", (245, 130, 48)),
}
ACTOR_SIGNALS = {"actor_loss": ("actor loss", (60, 200, 170))}
POLICY_COLOR = (60, 200, 170)


def goal_color(i: int) -> tuple[int, int, int]:
    return _GOAL_COLORS[i % len(_GOAL_COLORS)]


def training_blueprint(method: str, camera: rrb.EyeControls3D | None = None) -> rrb.Blueprint:
    """The layout a run's recording opens with: the ``iteration`` timeline; on the left the task
    loss (mean, per goal), the critic's training signals and the policy update (ours) or the actor
    loss (baselines); on the right the robot at the selected iteration, framed by ``camera``."""
    ours = method == "ours"
    mean = rrb.TimeSeriesView(
        origin="/train",
        contents=[
            "/train/task_loss/mean",
            "/train/task_loss_before/mean",
            "/train/task_loss_explore/mean",
        ],
        name="task loss |q_T - g|^2 (mean over worlds)",
    )
    per_goal = rrb.TimeSeriesView(
        origin="/train/task_loss",
        contents=["+ $origin/**", "- $origin/mean"],
        name="task loss per goal" + (" (after the inner update)" if ours else " (actor)"),
    )
    critic = rrb.TimeSeriesView(origin="/train/critic", name="critic training")
    last = (
        rrb.TimeSeriesView(origin="/train/policy", name="policy update |theta' - theta| (world 0)")
        if ours
        else rrb.TimeSeriesView(origin="/train/actor", name="actor training")
    )
    before, after = ("before the inner update", "after") if ours else ("exploration", "actor")
    robot = rrb.Spatial3DView(
        origin="/robot",
        name=f"robot per goal: goal (wireframe), {before} (grey), {after} (colour)",
        eye_controls=camera,
    )
    return rrb.Blueprint(
        rrb.Horizontal(rrb.Vertical(mean, per_goal, critic, last), robot, column_shares=[1, 1]),
        # following: the cursor at the last iteration, also while a long file is still loading
        rrb.TimePanel(timeline="iteration", state="collapsed", play_state="following"),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
    )


# newton.GeoType values (newton/_src/geometry/types.py); kept here so that reading a model's shapes
# needs no import of newton
SPHERE, CAPSULE, CYLINDER, BOX = 3, 4, 6, 7
DRAWN = (SPHERE, CAPSULE, CYLINDER, BOX)


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of quaternions in ``(x, y, z, w)`` order, broadcast over leading axes."""
    ax, ay, az, aw = np.moveaxis(a, -1, 0)
    bx, by, bz, bw = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ],
        -1,
    )


def quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``v`` rotated by the unit quaternion ``q`` ``(x, y, z, w)``, broadcast over leading axes."""
    u, w = q[..., :3], q[..., 3:4]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


@dataclass
class RobotDrawing:
    """One world's drawable shapes, in the frames of its bodies.

    ``kind[s]``, ``body[s]`` (index within the world), ``local[s]`` (7: position, quaternion xyzw of
    the shape in its body), ``scale[s]`` (newton's shape scale: radius, half height, ...);
    ``static``: the same for shapes fixed to the world (the base); ``links``: ``(parent, child)``
    body pairs for the line-strip fallback; ``ee_body``/``tip``: the end effector and its tip offset.
    """

    kind: np.ndarray
    body: np.ndarray
    local: np.ndarray
    scale: np.ndarray
    static_kind: np.ndarray
    static_local: np.ndarray
    static_scale: np.ndarray
    links: list[tuple[int, int]]
    ee_body: int
    tip: np.ndarray

    @classmethod
    def from_model(cls, model, worlds: int, ee_body: int, tip: np.ndarray) -> RobotDrawing:
        B = model.body_count // worlds
        body = model.shape_body.numpy()
        kind = model.shape_type.numpy()
        local = model.shape_transform.numpy().astype(np.float64)
        scale = model.shape_scale.numpy().astype(np.float64)
        mine = (body >= 0) & (body < B) & np.isin(kind, DRAWN)
        # static shapes repeat once per world at the same place: keep one of each
        static = np.nonzero((body < 0) & np.isin(kind, DRAWN))[0]
        seen, keep = set(), []
        for s in static:
            key = (int(kind[s]), *np.round(local[s], 5), *np.round(scale[s], 5))
            if key not in seen:
                seen.add(key)
                keep.append(s)
        parent, child = model.joint_parent.numpy(), model.joint_child.numpy()
        links = [(int(p), int(c)) for p, c in zip(parent, child) if 0 <= p < B and 0 <= c < B]
        return cls(
            kind[mine],
            body[mine],
            local[mine],
            scale[mine],
            kind[keep],
            local[keep],
            scale[keep],
            links,
            int(ee_body),
            np.asarray(tip, np.float64),
        )

    @property
    def has_shapes(self) -> bool:
        return len(self.kind) > 0

    def tip_of(self, poses: np.ndarray) -> np.ndarray:
        """The tip position for body poses ``(B, 7)``."""
        p = poses[self.ee_body]
        return p[:3] + quat_rotate(p[3:], self.tip)

    def points(self, poses: np.ndarray) -> np.ndarray:
        """Body origins and the tip: what the camera frames."""
        return np.concatenate([poses[:, :3], self.tip_of(poses)[None]])

    def log_static(self, stream: rr.RecordingStream, entity: str, color) -> None:
        """The shapes fixed to the world (the base), once."""
        if len(self.static_kind):
            ident = np.tile([0.0, 0, 0, 0, 0, 0, 1], (len(self.static_kind), 1))
            self._log_shapes(
                stream,
                entity,
                self.static_kind,
                ident,
                self.static_local,
                self.static_scale,
                color,
                True,
                True,
            )

    def log_arm(
        self,
        stream: rr.RecordingStream,
        entity: str,
        poses: np.ndarray,
        color,
        *,
        solid: bool = True,
        static: bool = False,
    ) -> None:
        """The robot at body poses ``(B, 7)`` under ``entity`` (solid, or as a wireframe ghost)."""
        if self.has_shapes:
            self._log_shapes(
                stream,
                entity,
                self.kind,
                poses[self.body],
                self.local,
                self.scale,
                color,
                solid,
                static,
            )
            return
        tip = self.tip_of(poses)
        strips = [np.stack([poses[p, :3], poses[c, :3]]) for p, c in self.links]
        strips.append(np.stack([poses[self.ee_body, :3], tip]))
        stream.log(
            f"{entity}/links",
            rr.LineStrips3D(strips, colors=[color], radii=0.02 if solid else 0.006),
            static=static,
        )

    @staticmethod
    def _log_shapes(stream, entity, kind, frames, local, scale, color, solid, static) -> None:
        pos = frames[:, :3] + quat_rotate(frames[:, 3:], local[:, :3])
        rot = quat_mul(frames[:, 3:], local[:, 3:])
        FillMode = rr.components.FillMode
        fill = FillMode.Solid if solid else FillMode.TransparentFillMajorWireframe
        quats = lambda m: rot[m].astype(np.float32)  # noqa: E731 (x, y, z, w)
        m = kind == CAPSULE
        if m.any():
            half = scale[m, 1:2]
            axis = quat_rotate(rot[m], np.tile([0.0, 0.0, 1.0], (int(m.sum()), 1)))
            stream.log(
                f"{entity}/capsules",
                rr.Capsules3D(
                    lengths=2 * half[:, 0],
                    radii=scale[m, 0],
                    translations=pos[m] - axis * half,
                    quaternions=quats(m),
                    colors=[color],
                    fill_mode=fill,
                ),
                static=static,
            )
        m = kind == CYLINDER
        if m.any():
            stream.log(
                f"{entity}/cylinders",
                rr.Cylinders3D(
                    lengths=2 * scale[m, 1],
                    radii=scale[m, 0],
                    centers=pos[m],
                    quaternions=quats(m),
                    colors=[color],
                    fill_mode=fill,
                ),
                static=static,
            )
        for k, name, half in (
            (SPHERE, "spheres", lambda s: np.repeat(s[:, :1], 3, 1)),
            (BOX, "boxes", lambda s: s),
        ):
            m = kind == k
            if m.any():
                cls = rr.Ellipsoids3D if k == SPHERE else rr.Boxes3D
                stream.log(
                    f"{entity}/{name}",
                    cls(
                        centers=pos[m],
                        half_sizes=half(scale[m]),
                        quaternions=quats(m),
                        colors=[color],
                        fill_mode=fill,
                    ),
                    static=static,
                )


def grid_offsets(n: int, spacing: float) -> np.ndarray:
    """``(n, 3)`` offsets that lay ``n`` copies of the robot out side by side in a near-square grid
    (rows along -y, columns along x)."""
    cols = int(np.ceil(np.sqrt(n)))
    return np.array([[(i % cols) * spacing, -(i // cols) * spacing, 0.0] for i in range(n)])


def camera_for(points: np.ndarray, planar: bool) -> rrb.EyeControls3D:
    """An orbit camera looking at the centre of ``points (N, 3)``, from above for a ``planar`` robot
    and from the front, above and to the side otherwise, just far enough back to see them all."""
    lo, hi = points.min(0), points.max(0)
    centre = (lo + hi) / 2
    radius = max(float(np.linalg.norm(hi - lo)) / 2, 0.25)
    direction = np.array([0.0, -0.45, 1.0]) if planar else np.array([0.6, -1.0, 0.55])
    direction /= np.linalg.norm(direction)
    return rrb.EyeControls3D(
        position=(centre + direction * radius * 2.2).tolist(),
        look_target=centre.tolist(),
        eye_up=[0.0, 0.0, 1.0],
    )


__all__ = [
    "RobotDrawing",
    "camera_for",
    "goal_color",
    "grid_offsets",
    "quat_mul",
    "quat_rotate",
    "training_blueprint",
]
