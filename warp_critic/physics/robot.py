"""Robot files people already have (URDF, MJCF, USD without our attributes) as a :class:`Scene`.

Newton's own importers read the file (``ModelBuilder.add_urdf`` / ``add_mjcf`` / ``add_usd``); this
module only checks that the result is a robot warp-critic can train, and fills in what a robot
file cannot say:

* the end effector: ``ee_body`` (default: for an arm with a hand, the hand; else the last body of
  the longest chain of the file's kinematic tree, counting fixed joints too; ties go to the body
  that comes first in the file) and ``tip_offset`` ``(3,)`` m in that body's frame (default
  ``(0, 0, 0)``). A body that is welded to its parent by a fixed joint is merged into it; naming it
  puts the tip at its origin;
* ``joints``: train only these joints; the others are locked at the home pose (fixed joints).
  Without it, the joints the file actuates (:mod:`warp_critic.physics.actuation`: MJCF
  ``<actuator>``, URDF ``<transmission>`` or non-zero effort) are trained; an unactuated joint of
  the robot is refused ("underactuated"); an MJCF's bodies outside the actuated robot (targets,
  objects) are dropped with one note line; an arm with a hand trains the arm chain (one note line
  says which and how to pick others); a hand (several chains on a fixed palm) trains them all;
* the model a robot file rarely says and the training defaults (armature, damping, limit gains,
  goals, home pose, torque bounds, ``dt``/substeps, ...), derived from the robot by
  :mod:`warp_critic.physics.derive`; an MJCF actuator's bound (gear x ctrlrange, capped by
  forcerange) caps the joint's effort limit.

Refused, with one line naming the reason (:class:`~warp_critic.core.errors.SceneError`): a floating
base (a free joint to the world: an MJCF ``<freejoint>`` on the robot, a URDF ``floating`` joint; a
root link without a joint to the world is fixed, as pinocchio and pybullet read it), a closed
kinematic loop, a trained or locked joint that is not revolute or prismatic, an unactuated joint
of the robot, no movable joint, a body without mass.

Mesh files are not needed for dynamics: a URDF is imported without its ``<visual>``/``<collision>``
meshes (masses and inertias come from ``<inertial>``), and a missing mesh file gives one warning
naming the first one. A continuous joint (no limits) keeps Newton's ``+-1e10`` limits; the networks
see its angle wrapped to ``[-pi, pi)`` (:class:`warp_critic.learning.networks.Normalizer`).
"""

from __future__ import annotations

import copy
import hashlib
import json
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from warp_critic.core.errors import SceneError, warn
from warp_critic.physics import derive
from warp_critic.physics.balance import upright_note
from warp_critic.physics.file_format import USD_SUFFIXES, file_format
from warp_critic.physics.importers import (
    check_topology,
    collapse,
    depths,
    fail,
    import_builder,
    lock,
    moved_bodies,
    short,
)
from warp_critic.physics.inertia_checks import TOLERATED
from warp_critic.physics.joint_choice import check_loops, trained_joints
from warp_critic.physics.robot_checks import check_robot, given_home
from warp_critic.physics.robot_meshes import link_frames
from warp_critic.physics.scene import Scene

__all__ = ["RobotOptions", "ROBOT_SUFFIXES", "is_robot_file", "load_robot"]

ROBOT_SUFFIXES = (".urdf", ".xml", ".mjcf")
CONTINUOUS_LIMIT = 1e9  # |limit| at or beyond this: a joint without limits (newton writes 1e10)


@dataclass(frozen=True)
class RobotOptions:
    """What a robot file cannot say.

    Attributes:
        ee_body: end-effector body name (None: the last body of the longest chain).
        tip_offset: ``(3,)`` tip in the end-effector body frame [m] (None: ``(0, 0, 0)``).
        joints: names of the joints to train (None: every movable joint); the rest are locked.
        lock_mimic, repair_inertia: the repairs :mod:`warp_critic.physics.robot_checks` may make.
        home: ``(joint name, value)`` pairs [rad or m] that replace the derived home pose of those
            joints (None: the file's own pose inside the limits, else mid-range); the goals, the
            bounds and the model's derived values are then derived around it.
    """

    ee_body: str | None = None
    tip_offset: tuple[float, float, float] | None = None
    joints: tuple[str, ...] | None = None
    lock_mimic: bool = False
    repair_inertia: bool = False
    home: tuple[tuple[str, float], ...] | None = None

    def any(self) -> bool:
        return any(v is not None for v in (self.ee_body, self.tip_offset, self.joints, self.home))


def is_robot_file(path: str | Path) -> bool:
    """A URDF/MJCF file, or a USD file with no ``warp_critic:*`` attribute at all (a scene file that
    lacks one of ours is a broken scene, reported as such by :func:`warp_critic.physics.load.load_scene`)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in ROBOT_SUFFIXES or suffix == ".xacro":
        return True
    if not path.is_file():
        return False
    try:  # the format is read from the content: a URDF saved as .txt is a URDF
        return file_format(path) in (("usd",) if suffix in USD_SUFFIXES else ("urdf", "mjcf"))
    except SceneError:  # an unreadable file: load_scene says why
        return False


_CACHE: dict[tuple, Scene] = {}
_CACHE_LOCK = threading.Lock()


def load_robot(path: str | Path, options: RobotOptions = RobotOptions()) -> Scene:
    """Import a robot file into a :class:`Scene` with derived training defaults (cached per file
    version and options). Raises :class:`SceneError` with one line naming the reason."""
    path = Path(path).expanduser()
    if not path.exists():
        raise SceneError(f"{path}: no such robot file")
    if path.is_dir():
        raise SceneError(f"{path}: is a directory, not a robot file")
    path = path.resolve()
    stat = path.stat()
    key = (str(path), stat.st_mtime_ns, stat.st_size, options)
    with _CACHE_LOCK:
        scene = _CACHE.get(key)
        if scene is None:
            scene = _load(path, options)
            _CACHE[key] = scene
    return scene


def _load(path: Path, options: RobotOptions) -> Scene:
    import newton

    fmt = file_format(path)
    builder, actuation, notes = import_builder(path, fmt)
    if builder.body_count == 0:
        raise fail(path, "no bodies: not a robot")
    check_topology(path, builder)

    names = [short(label) for label in builder.joint_label]
    fixed = int(newton.JointType.FIXED)
    jointed = [j for j, t in enumerate(builder.joint_type) if int(t) != fixed]
    if not jointed:
        raise fail(path, "no movable joint (every joint is fixed): nothing to train")
    trained, branch, note = trained_joints(path, builder, names, jointed, actuation, options)
    check_loops(path, builder, actuation.loops, trained)
    # the file's validity on the joints chosen for training (a coupling between two locked joints,
    # such as an arm's gripper fingers, is no concern): refused in one line, or repaired on the
    # options' flags (robot_checks); --lock-mimic welds followers, which then leave the trained set
    o = options
    chosen = sorted(names[j] for j in trained)
    repairs = check_robot(
        path,
        builder,
        fmt,
        chosen,
        o.lock_mimic,
        o.repair_inertia,
        home=dict(o.home or ()),
        root=actuation.root,
    )
    jointed = [j for j, t in enumerate(builder.joint_type) if int(t) != fixed]
    trained = {j for j in trained if j in jointed}
    notes += [f"{path}: {r}" for r in repairs if TOLERATED in r]  # rounding-size repairs
    for line in [*notes, note] if note else notes:  # said once the file passed its checks: a
        warn(line)  # refused file gets its one line only
    home = _home(path, builder, names, jointed, trained, actuation, options)
    ee_label = _end_effector(path, builder, trained, branch, options)
    return _finish(path, builder, fmt, options, ee_label, home, repairs, actuation)


def _home(
    path: Path, builder, names: list[str], jointed: list[int], trained: set[int], actuation, o
) -> dict[int, float]:
    """Each movable joint's home (``--home``, else the file's ``home`` keyframe, else
    derive.home_value); the joints not trained locked there, the trained ones given the MJCF
    actuators' bounds as effort limits."""
    import newton

    movable = {int(newton.JointType.REVOLUTE), int(newton.JointType.PRISMATIC)}
    for j in jointed:  # after --joints: a joint that is neither trained nor lockable is refused
        if int(builder.joint_type[j]) not in movable:
            kind = newton.JointType(int(builder.joint_type[j])).name.lower()
            raise fail(
                path,
                f"joint {names[j]!r} is a {kind} joint; only revolute and prismatic joints (and "
                "fixed ones) are supported"
                + ("" if j in trained else " (--joints locks revolute and prismatic ones only)"),
            )
    dof_of = {j: builder.joint_qd_start[j] for j in jointed}
    lower = {j: float(builder.joint_limit_lower[dof_of[j]]) for j in jointed}
    upper = {j: float(builder.joint_limit_upper[dof_of[j]]) for j in jointed}
    file_home = {j: float(builder.joint_q[builder.joint_q_start[j]]) for j in jointed}
    home = {
        j: derive.home_value(lower[j], upper[j], file_home[j], CONTINUOUS_LIMIT) for j in jointed
    }
    for j in jointed:  # the file's home keyframe, inside the limits
        if names[j] in actuation.home:
            home[j] = min(max(actuation.home[names[j]], lower[j]), upper[j])
    home.update(given_home(path, o.home or (), names, jointed, lower, upper, CONTINUOUS_LIMIT))
    lock(builder, [j for j in jointed if j not in trained], home)
    for j in trained:  # an MJCF actuator's bound caps the joint's effort limit
        bound = (actuation.actuated or {}).get(names[j])
        if bound is not None:
            old = float(builder.joint_effort_limit[dof_of[j]])
            builder.joint_effort_limit[dof_of[j]] = min(old, bound) if old > 0 else bound
    return home


def _end_effector(path: Path, builder, trained: set[int], branch: int | None, options) -> str:
    """The end-effector body's label, chosen on the file's tree (fixed links included):
    ``--ee-body``, else the hand of an arm with a hand, else the first deepest body that a trained
    joint moves."""
    labels = list(builder.body_label)
    if options.ee_body is not None:
        matches = [i for i, lb in enumerate(labels) if lb == options.ee_body]
        matches = matches or [i for i, lb in enumerate(labels) if short(lb) == options.ee_body]
        if len(matches) != 1:
            raise fail(
                path,
                f"ee_body {options.ee_body!r} names {len(matches)} of the bodies "
                f"{[short(lb) for lb in labels]}",
            )
        return labels[matches[0]]
    if branch is not None:
        return labels[branch]  # an arm with a hand: the hand
    depth, _ = depths(builder)
    moved = moved_bodies(builder, trained)
    return labels[max(moved, key=lambda b: (depth[b], -b))]


def _finish(
    path: Path, builder, fmt: str, options, ee_label: str, home: dict, repairs, actuation
) -> Scene:
    """Fixed joints merged, the checks on the merged model, and the model a file does not say
    (armature, damping, limit gains: derive's rules) -> the scene."""
    names = [short(label) for label in builder.joint_label]
    labels = list(builder.body_label)
    ee = labels.index(ee_label)
    info = collapse(builder)
    frames = link_frames(labels, info)  # where each file link ended up: to draw its meshes
    tip = np.array(options.tip_offset or (0.0, 0.0, 0.0), dtype=np.float64)
    if ee in info["body_merged_parent"]:
        parent = info["body_merged_parent"][ee]
        if parent < 0:
            who = "--ee-body " if options.ee_body is not None else "the end-effector body "
            raise fail(
                path, f"{who}{short(ee_label)!r} is welded to the world: no trained joint moves it"
            )
        xf = info["body_merged_transform"][ee]
        import warp as wp

        tip = np.array(wp.transform_point(xf, wp.vec3(*tip)), dtype=np.float64)
        ee = info["body_remap"][parent]
    else:
        ee = info["body_remap"][ee]

    for b, m in enumerate(builder.body_mass):
        if not m > 0.0:
            raise fail(path, f"body {short(builder.body_label[b])!r} has no mass ({m} kg)")
    if builder.joint_dof_count == 0:
        raise fail(path, "no movable joint left to train")
    if not builder.joint_count == builder.joint_dof_count == builder.joint_coord_count:
        raise fail(path, "joints other than revolute/prismatic remain after merging fixed joints")

    effort = np.array(builder.joint_effort_limit, dtype=np.float64)
    effort = np.where(np.isfinite(effort) & (effort > 0), effort, derive.NO_EFFORT_LIMIT)
    builder.joint_effort_limit = [float(v) for v in effort]
    kept = [names.index(short(label)) for label in builder.joint_label]
    home_q = np.array([home[j] for j in kept], dtype=np.float64)
    digest = _content_hash(path, options)

    def make() -> RobotScene:  # the scene copies the builder's arrays: made again after each rule
        scene = RobotScene(path, builder, ee, tip, effort, home=home_q, content_hash=digest)
        scene.import_repairs = repairs
        scene.link_frames = frames
        scene.drawn_meshes = list(actuation.drawn)
        scene.bound_sources = {
            str(n): "file" for n, v in (actuation.actuated or {}).items() if v is not None
        }
        return scene

    # armature and damping where the file gives none (import_builder marks them UNSET), then the
    # limit gains on the joints' inertia with that armature (derive's rules)
    armature = np.array(builder.joint_armature, dtype=np.float64)
    damping = np.array(builder.joint_damping, dtype=np.float64)
    builder.joint_armature = [float(v) for v in np.maximum(armature, 0.0)]
    builder.joint_damping = [float(v) for v in np.maximum(damping, 0.0)]
    armature, damping = derive.armature_damping(make(), armature, damping)
    builder.joint_armature = [float(f"{v:.6g}") for v in armature]
    builder.joint_damping = [float(f"{v:.6g}") for v in damping]
    if fmt != "usd":  # a URDF/MJCF authors no limit springs
        ke, kd = derive.limit_gains(make())
        builder.joint_limit_ke = [float(f"{v:.6g}") for v in ke]
        builder.joint_limit_kd = [float(f"{v:.6g}") for v in kd]
    return make()


def _content_hash(path: Path, options: RobotOptions) -> str:
    """The file and the options shape the model; the derived defaults do not enter (a run resolves
    them into its own config, as the training-default attributes of a scene file)."""
    return hashlib.sha256(
        path.read_bytes()
        + json.dumps(
            {
                "options": [options.ee_body, options.tip_offset, options.joints]
                + [name for name in ("lock_mimic", "repair_inertia") if getattr(options, name)],
                "rules": derive.MODEL_RULES,
            },
            sort_keys=True,
        ).encode()
    ).hexdigest()


class RobotScene(Scene):
    """A :class:`Scene` imported from a robot file; its training defaults are derived from the
    robot (:mod:`warp_critic.physics.derive`) on first use, so loading alone stays cheap."""

    derived = True
    import_repairs: tuple[str, ...] = ()  # what robot_checks repaired on request, one line each
    link_frames: dict[str, tuple[int, tuple[float, ...]]]  # robot_meshes.link_frames
    drawn_meshes: list = []  # an MJCF's mesh geoms, for drawing (mjcf_file.DrawnMesh)
    bound_sources: dict[str, str] = {}  # joint -> "file" where the file gives its torque bound
    _derived_values: dict[str, Any] | None  # None until first use (set by the setter below)
    _derive_lock: threading.Lock

    @property
    def _defaults(self) -> dict[str, Any]:
        if self._derived_values is None:
            with self._derive_lock:
                if self._derived_values is None:
                    self._derived_values = _derive(self, derive.GRAVITY)
        return self._derived_values

    @_defaults.setter
    def _defaults(self, value: dict[str, Any]) -> None:  # Scene.__init__ sets {}: derive instead
        self._derived_values = value or None
        self._derive_lock = threading.Lock()
        self._at_gravity: dict[float, dict[str, Any]] = {}

    def defaults_at(self, gravity: float) -> dict[str, Any]:
        """The derived defaults (a copy) for a run under ``gravity`` [m/s^2] instead of the rules'
        9.81: the torque bounds and the time step depend on it (``derive.derive_defaults``)."""
        if float(gravity) == derive.GRAVITY:
            return self.defaults
        with self._derive_lock:
            if float(gravity) not in self._at_gravity:
                self._at_gravity[float(gravity)] = _derive(self, float(gravity))
        return copy.deepcopy(self._at_gravity[float(gravity)])


def _derive(scene: RobotScene, gravity: float) -> dict[str, Any]:
    """The robot's derived defaults under ``gravity`` [m/s^2], after one warning line where its
    home pose balances it upright (:mod:`warp_critic.physics.balance`)."""
    note = upright_note(scene, gravity)
    if note:
        warn(note)
    values = derive.derive_defaults(scene, gravity)
    note = derived_bound_note(scene, values["max_torque"], gravity)
    if note:
        warn(note)
    return values


def derived_bound_note(scene, max_torque, gravity: float) -> str | None:
    """One line naming the joints whose torque bound the file does not give (no effort limit, no
    actuator force range): their bound is derived, not a motor's limit. None where the file bounds
    every joint."""
    unbounded = np.flatnonzero(scene.effort_limit >= derive.NO_EFFORT_LIMIT)
    if not len(unbounded):
        return None
    values = ", ".join(
        f"{scene.joint_names[i]} {float(max_torque[i]):.3g}" for i in unbounded[:6]
    ) + (", .." if len(unbounded) > 6 else "")
    return (
        f"{scene.path}: the file gives no torque bound for {len(unbounded)} of {scene.dof} joints: "
        f"their max_torque ({values} N m or N) is derived from the robot under gravity "
        f"{gravity:g} m/s^2 (--help: max_torque), not a motor's limit; set the motors' own with "
        "--max-torque"
    )
