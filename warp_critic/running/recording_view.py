"""What a recording shows in the viewer: its layout and the robot per goal.

:func:`training_blueprint` is the layout a run's recording opens with, :func:`metatest_blueprint`
a meta-test's. :class:`GoalStage` lays out the 3-D view: one copy of the robot per goal, drawn by
:class:`~warp_critic.running.robot_drawing.RobotDrawing` (the model's own shapes and meshes, line
strips without them).
"""

from __future__ import annotations

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from warp_critic.physics.robot_meshes import link_meshes
from warp_critic.running.robot_drawing import (  # also recording_view.<name>, as before
    BASE_COLOR,
    BEFORE_COLOR,
    CAPSULE,
    CYLINDER,
    MAX_GOALS_DRAWN,
    SPHERE,
    RobotDrawing,
    camera_for,
    goal_color,
    grid_offsets,
    quat_mul,
    quat_rotate,
)

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


def metatest_blueprint(camera: rrb.EyeControls3D | None = None) -> rrb.Blueprint:
    """The layout a meta-test's recording opens with: the ``policy_step`` timeline; on the left the
    final error per goal (bars) and the error over the policy steps (mean, per goal); on the right
    the robot per goal before and after its critic-gradient steps, framed by ``camera``."""
    bars = rrb.BarChartView(
        origin="/metatest/final_error", name="final error ||q_T - g||^2 per goal (mean over inits)"
    )
    curve = rrb.TimeSeriesView(
        origin="/metatest/error", name="error ||q_T - g||^2 over the policy steps"
    )
    robot = rrb.Spatial3DView(
        origin="/robot",
        name="fresh policy per goal: goal (wireframe), before training (grey), after (colour)",
        eye_controls=camera,
    )
    return rrb.Blueprint(
        rrb.Horizontal(rrb.Vertical(bars, curve), robot, column_shares=[1, 1]),
        rrb.TimePanel(timeline="policy_step", state="collapsed", play_state="following"),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
    )


class GoalStage:
    """The 3-D view of a recording: one copy of the robot per goal drawn (the first ``shown``), laid
    side by side under ``robot/goal<i>``: ``target`` (the goal pose as a wireframe ghost, its tip
    labelled), ``base``, and rollouts' final poses and tip paths (:meth:`log_rollout`).

    Args:
        sim: the :class:`~warp_critic.physics.simulator.Simulator` (for forward kinematics).
        goals: ``(G, dof)`` goals; ``shown`` of them are drawn.
        world_offset: the first world of ``sim`` to use for the goals' poses.
    """

    def __init__(self, sim, goals, shown: int, world_offset: int = 0):
        self.sim, self.shown = sim, shown
        self.drawing = RobotDrawing.from_model(
            sim.model,
            sim.worlds,
            sim.scene.ee_body,
            sim.scene.tip_offset_of(sim.variants[world_offset]),
            link_meshes(sim.scene),
        )
        q = sim.zeros()
        for g in range(shown):
            q[world_offset + g] = goals[g]
        self.goal_poses = sim.body_poses(q)[world_offset : world_offset + shown]
        reach = self._reach(self.goal_poses[0])
        self.offsets = grid_offsets(shown, max(2.2 * reach, 0.5))
        # the camera frames the goal poses and room around each base to move in; a planar robot
        # (its goal poses flat in z) is seen from above
        d = self.drawing
        robot = np.concatenate([d.points(p) for p in self.goal_poses])
        flat = np.ptp(robot[:, 2]) < 0.1 * max(float(np.ptp(robot[:, :2], 0).max()), 1e-6)
        room = np.array([[-0.6 * reach, -0.6 * reach, 0.0], [0.6 * reach, 0.6 * reach, 0.0]])
        frame = [d.points(p) + o for p, o in zip(self.goal_poses, self.offsets)]
        frame += [o + room for o in self.offsets]
        self.camera = camera_for(np.concatenate(frame), bool(flat))

    def _reach(self, poses: np.ndarray) -> float:
        """The robot's length: its links and the tip, end to end (m)."""
        d = self.drawing
        links = sum(float(np.linalg.norm(poses[c, :3] - poses[p, :3])) for p, c in d.links)
        tip = float(np.linalg.norm(d.tip_of(poses) - poses[d.ee_body, :3]))
        return links + tip + float(np.linalg.norm(poses[0, :3]))

    def log_static(self, s: rr.RecordingStream) -> None:
        """Each goal's place, base and goal pose, once."""
        for g in range(self.shown):
            root = f"robot/goal{g}"
            s.log(root, rr.Transform3D(translation=self.offsets[g].astype(np.float32)), static=True)
            self.drawing.log_static(s, f"{root}/base", BASE_COLOR)
            self.drawing.log_arm(
                s, f"{root}/target", self.goal_poses[g], goal_color(g), solid=False, static=True
            )
            s.log(
                f"{root}/target/tip",
                rr.Points3D(
                    [self.drawing.tip_of(self.goal_poses[g])],
                    colors=[goal_color(g)],
                    radii=0.03,
                    labels=[f"goal {g}"],
                ),
                static=True,
            )

    def log_rollout(
        self, s: rr.RecordingStream, label: str, q, worlds, static: bool = False
    ) -> None:
        """The final pose and the tip path of ``worlds`` (one per goal drawn) along a trajectory
        ``q (T+1, W, dof)`` under ``robot/goal<i>/<label>`` (``after``: the goal's colour, else
        grey), at the current time."""
        final = self.sim.body_poses(q[-1])  # (W, B, 7)
        tips = np.stack([self.sim.tip_positions(q[t]) for t in range(q.shape[0])])  # (T+1, W, 3)
        for gi, w in enumerate(worlds):
            color = goal_color(gi) if label == "after" else BEFORE_COLOR
            entity = f"robot/goal{gi}/{label}"
            self.drawing.log_arm(s, entity, final[w], color, static=static)
            s.log(
                f"{entity}/tip_path",
                rr.LineStrips3D([tips[:, w]], colors=[color], radii=0.006),
                static=static,
            )


__all__ = [
    "BASE_COLOR",
    "BEFORE_COLOR",
    "CAPSULE",
    "CYLINDER",
    "SPHERE",
    "GoalStage",
    "MAX_GOALS_DRAWN",
    "RobotDrawing",
    "camera_for",
    "goal_color",
    "grid_offsets",
    "metatest_blueprint",
    "quat_mul",
    "quat_rotate",
    "training_blueprint",
]
