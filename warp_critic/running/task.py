"""The training task every method shares: its config fields and the worlds it runs.

:class:`TaskConfig` holds the fields common to meta-training and both baselines (scene, goals,
horizon, time step, torque bounds, training distribution, run settings). Each method's config
subclasses it and adds its own hyperparameters, so the three methods train on exactly the same
task and take the same flags for it.

Defaults that depend on the robot (goals, horizon, ``dt``, torque bounds, ...) are ``None`` here and
come from the scene's content (:attr:`warp_critic.physics.scene.Scene.defaults`, authored by
``tools/make_scenes.py``), never from its file name. A scene that does not carry one must be given
it explicitly (:class:`~warp_critic.core.errors.FieldError` names the field).

:func:`build_task` lays out ``W = G x K`` worlds goal-major (world ``w`` pursues goal ``w // K``) in
one :class:`~warp_critic.physics.simulator.Simulator` and draws the training start states.
"""

from __future__ import annotations

import copy
import logging
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, TypeVar

import torch

from warp_critic.core.errors import FieldError
from warp_critic.core.runtime import MAX_SEED, MAX_SEEDS, check_threads
from warp_critic.learning.networks import Normalizer
from warp_critic.physics import schema
from warp_critic.physics.inertia import NominalInertia
from warp_critic.physics.link_changes import parse_changes
from warp_critic.physics.scene import Scene, Variant
from warp_critic.running.config import SerializableConfig, check_fields, filled, spec
from warp_critic.running.task_inputs import (
    check_memory,
    goals_tensor,
    inside_limits,
    max_torque_tensor,
)

if TYPE_CHECKING:
    from typing_extensions import Self

log = logging.getLogger(__name__)

# Used for a field that neither the user nor the scene sets (the scene schema's defaults).
GENERIC_DEFAULTS: dict[str, Any] = schema.fallbacks()
DEVICES = ("auto", "cpu", "cuda")
# Fields that say where/how a run executes, not what it computes: they may change on --resume.
RUNTIME_FIELDS = (
    "out",
    "device",
    "resume",
    "cpu_threads",
    "checkpoint_every",
    "record_every",
    "iterations",
    "seeds",
)


@dataclass
class TaskConfig(SerializableConfig):
    """The task and run settings every method shares. ``None`` = the scene's default."""

    scene: str = spec(
        "scenes/kuka.usda",
        "USD scene file, or a robot file (.urdf, MJCF .xml, .usd/.usda without warp_critic attributes)",
    )
    ee_body: str | None = spec(
        None,
        "robot files: the end-effector body (default: the last body of the longest chain)",
    )
    tip_offset: list[float] | None = spec(
        None, "robot files: the tip x,y,z (m) in the end-effector body frame (default: 0,0,0)"
    )
    joints: str | None = spec(
        None,
        "robot files: train only these joints (comma-separated names); the others are locked at the home pose (default: every movable joint)",
    )
    goals: list[list[float]] | None = spec(
        None,
        "training goals in joint space: inline '0.1,0.2;0.3,0.4' or a .json/.txt file (one goal per line); default: the scene's",
    )
    iterations: int = spec(300, "outer iterations (critic updates)", gt=0, cap=10**8)
    horizon: int | None = spec(None, "control steps per rollout", gt=0, cap=10**6)
    dt: float | None = spec(None, "physics time step (s)", gt=0, cap=1.0)
    substeps: int | None = spec(None, "physics steps per control step", gt=0, cap=10**4)
    worlds_per_goal: int = spec(4, "policy initialisations per goal (parallel worlds)", gt=0)
    start_std: float | None = spec(
        None,
        "std (rad) of random initial joint positions around the home pose, drawn per world and iteration (0 = always start at home, as at meta-test); default: the scene's, else "
        + schema.fallback_text("start_std"),
        ge=0,
        cap=100,
    )
    home_starts: int | None = spec(
        None,
        "with a start std: this many of each goal's worlds still start at the home pose (as at meta-test) every iteration; default: the scene's, else "
        + schema.fallback_text("home_starts"),
        ge=0,
    )
    max_torque: list[float] | None = spec(
        None, "per-joint torque bound of the policy (N·m), comma-separated or one value", gt=0
    )
    qd_scale: float | None = spec(None, "velocity normalisation (rad/s)", gt=0)
    gravity: float | None = spec(
        None,
        "gravity along -z (m/s^2); 0 = a perfectly gravity-compensated robot (the iiwa's torque mode, the kuka default)",
        ge=0,
        cap=1000,
    )
    ee_mass: float = spec(0.0, "mass added at the end-effector during training (kg)", ge=0, cap=1e4)
    link_length: float | None = spec(
        None, "set the end-effector link length during training (m)", gt=0, cap=100
    )
    link_scale: float = spec(
        1.0, "scale the end-effector link length during training", gt=0, cap=100
    )
    variant: str | None = spec(
        None,
        "dynamics changes of any link during training, ';'-separated LINK.WHAT=V, +=V or *=V (WHAT: mass[:keep|:scale] at the COM, point-mass+=KG@x,y,z|@tip, offset (kinematic length, no mass change), stretch (stretched link)), e.g. 'iiwa_link_7.mass=5; ee.offset+=0.4'; applied after --ee-mass/--link-length/--link-scale (default: none)",
    )
    seed: int = spec(0, "random seed (fixes everything on CPU)", ge=0, le=MAX_SEED)
    seeds: list[int] | None = spec(
        None,
        "train these seeds at once in one process and one simulator (comma-separated, e.g. 0,1,2,3,4); each seed gets its own run directory OUT/seed<k> with exactly the results of a single-seed run; "
        f"at most {MAX_SEEDS} seeds",
        ge=0,
        le=MAX_SEED,
    )
    device: str = spec("auto", "cpu, cuda or auto (the CPU until CUDA is measured faster)")
    cpu_threads: int | None = spec(
        None,
        "torch CPU threads while training (0 = torch's default; default: $WARP_CRITIC_TORCH_THREADS or 1: small networks run fastest on one)",
    )
    out: str | None = spec(None, "run directory (default runs/<scene>-<method>)")
    checkpoint_every: int = spec(10, "write a checkpoint every N iterations", gt=0)
    record_every: int = spec(50, "record rollouts every N iterations", gt=0)
    resume: bool = spec(
        False,
        "continue the run in the run directory from its last checkpoint (the run's saved settings hold; only the iterations may grow)",
    )

    method = "task"  # overridden by each method's config
    # fields a scene's content may set (a method adds its own, e.g. ours the inner/outer learning rates)
    scene_fields: ClassVar[tuple[str, ...]] = schema.keys("task")

    def __post_init__(self) -> None:
        # Set here, not annotated in the class body (that would make it a field: a flag, a range
        # check, a setting compared on --resume): the defaults load_task_scene derived from a robot
        # file, ``{name: {"value", "rule"}}``; a record of the run, not a setting.
        self.derived_defaults: dict[str, dict[str, Any]] = {}

    # -- defaults and checks -------------------------------------------------------------------
    def to_dict(self) -> dict:
        d = asdict(self)
        if self.derived_defaults:  # the defaults derived from a robot file, each with its rule
            d["derived_defaults"] = copy.deepcopy(self.derived_defaults)
        return d

    def default_out(self) -> str:
        return f"runs/{Path(self.scene).stem}-{self.method}"

    def fill_defaults(self, scene: Scene) -> Self:
        """A copy with the ``None`` fields filled from the scene's content, then the generic defaults."""
        gravity = getattr(self, "gravity", None)
        # a robot file's derived torque bounds and dt follow the run's gravity (Scene.defaults_at)
        authored = scene.defaults if gravity is None else scene.defaults_at(gravity)
        filled: dict[str, Any] = {}
        for name in self.scene_fields:
            if getattr(self, name) is not None:
                continue
            if name in authored:
                filled[name] = copy.deepcopy(authored[name])
            elif name in GENERIC_DEFAULTS:
                filled[name] = GENERIC_DEFAULTS[name]
        if filled.get("goals", self.goals) is None:
            raise FieldError(
                "goals",
                f"the scene {scene.path} carries no training goals "
                "(warp_critic:goals); give them explicitly",
            )
        if self.max_torque is None and "max_torque" not in filled:  # the joints' own effort limits
            filled["max_torque"] = [float(x) for x in scene.effort_limit]
        if self.out is None:
            filled["out"] = self.default_out()
        return replace(self, **filled)

    def check(self, scene: Scene | None = None) -> None:
        """Check every field (types, finiteness, ranges, cross-field rules); with ``scene``, against it."""
        check_fields(self)
        if self.device not in DEVICES and not str(self.device).startswith("cuda:"):
            raise FieldError("device", f"must be one of {', '.join(DEVICES)} (got {self.device!r})")
        if self.cpu_threads is not None:
            check_threads(self.cpu_threads)
        if self.home_starts is not None and self.home_starts > self.worlds_per_goal:
            raise FieldError(
                "home_starts",
                f"must be at most worlds_per_goal {self.worlds_per_goal} (got {self.home_starts})",
            )
        variant = task_variant(self)
        if scene is not None:
            if variant.changes:  # link names and resulting masses/lengths, against the scene
                scene.world_builder(variant)
            dof = scene.dof
            if self.max_torque is not None and len(self.max_torque) not in (1, dof):
                raise FieldError(
                    "max_torque",
                    f"needs 1 or {dof} values for {scene.name} (got {len(self.max_torque)})",
                )
            if self.max_torque is not None and len(self.max_torque) in (1, dof):
                max_torque_tensor(self.max_torque, scene)
            if self.goals is not None:
                goals_tensor(self.goals, scene)
            check_memory(self, dof)


TaskConfigT = TypeVar("TaskConfigT", bound=TaskConfig)


@dataclass
class Task:
    """``S`` copies (one per seed) of ``G x K`` worlds of one scene, seed-major then goal-major, with
    their goals and normaliser. ``W = S x Wc`` worlds in all, ``Wc = G x K`` per copy."""

    cfg: TaskConfig
    scene: Scene
    goals: torch.Tensor  # (G, dof) rad, on the CPU
    sim: Any  # warp_critic.physics.simulator.Simulator
    goal_index: torch.Tensor  # (W,) goal of each world
    slot: torch.Tensor  # (W,) index of each world among its goal's worlds
    goal: torch.Tensor  # (W, dof) each world's goal
    norm: Normalizer
    home: torch.Tensor  # (W, dof) the home pose
    S: int = 1  # copies (seeds)

    @property
    def G(self) -> int:
        return self.goals.shape[0]

    @property
    def K(self) -> int:
        return self.cfg.worlds_per_goal

    @property
    def W(self) -> int:
        return self.goal.shape[0]

    @property
    def Wc(self) -> int:
        return self.W // self.S

    @property
    def device(self) -> torch.device:
        return self.sim.torch_device

    def copy(self, i: int) -> slice:
        """The worlds of copy (seed) ``i``."""
        return slice(i * self.Wc, (i + 1) * self.Wc)

    def goal_index_of(self, i: int) -> torch.Tensor:
        """``(W,)``: the goal of each world of copy ``i``, -1 for the other copies' worlds."""
        out = torch.full_like(self.goal_index, -1)
        out[self.copy(i)] = self.goal_index[self.copy(i)]
        return out

    def start_states(self, gen: torch.Generator, i: int = 0) -> torch.Tensor:
        """``(Wc, dof)`` initial joint positions of copy ``i``: home, plus ``N(0, start_std^2)`` inside
        the middle 95% of the limits for all but the first ``home_starts`` worlds of each goal."""
        home, slot = self.home[self.copy(i)], self.slot[self.copy(i)]
        if not self.cfg.start_std:
            return home
        away = (slot >= (self.cfg.home_starts or 0)).float().unsqueeze(1)
        noise = (
            torch.randn(self.Wc, self.scene.dof, generator=gen).to(self.device)
            * self.cfg.start_std
            * away
        )
        lo, hi = inside_limits(self.sim.q_lower, self.sim.q_upper, 0.95)
        return torch.clamp(home + noise, lo, hi)

    def per_goal(self, per_world: torch.Tensor, keep: torch.Tensor | None = None) -> torch.Tensor:
        """``(Wc,) -> (G,)`` mean over each goal's worlds (one copy's worlds); with ``keep (Wc,)``
        bool, over its kept worlds only (``nan`` for a goal with none)."""
        idx = self.goal_index[: per_world.shape[0]]
        zeros = torch.zeros(self.G, device=per_world.device)
        if keep is None:
            return zeros.index_add(0, idx, per_world) / self.K
        total = zeros.index_add(0, idx, torch.where(keep, per_world, torch.zeros_like(per_world)))
        return total / zeros.index_add(0, idx, keep.to(zeros.dtype))


def scene_of(cfg) -> Scene:
    """The config's scene: a scene file, or a robot file with the config's robot options."""
    from warp_critic.physics.load import load_any

    joints = getattr(cfg, "joints", None)
    if joints is not None:
        joints = [n.strip() for n in str(joints).split(",") if n.strip()]
    return load_any(
        cfg.scene,
        ee_body=getattr(cfg, "ee_body", None),
        tip_offset=getattr(cfg, "tip_offset", None),
        joints=joints,
    )


def load_task_scene(cfg: TaskConfigT, announce: bool = True) -> tuple[TaskConfigT, Scene]:
    """Load the scene, check the config and fill its defaults from the scene: returns ``(the filled
    config, a new object; the scene)``, ``cfg`` itself is left as it was.

    For a robot file, the defaults derived from the robot that the run uses are kept in the config
    (``derived_defaults``: value and rule) and, with ``announce``, stated in one INFO record on this
    module's logger (the command line prints it as one line at the start of a run).
    """
    check_fields(cfg)  # finite numbers before anything is built
    if cfg.tip_offset is not None and len(cfg.tip_offset) != 3:
        raise FieldError("tip_offset", f"needs 3 values x,y,z (got {len(cfg.tip_offset)})")
    scene = scene_of(cfg)
    unset = {name for name in cfg.scene_fields if getattr(cfg, name) is None}
    filled = cfg.fill_defaults(scene)
    filled.check(scene)
    if getattr(scene, "derived", False):
        from warp_critic.physics import derive

        used = unset & set(scene.defaults)
        values = {name: getattr(filled, name) for name in used}
        derived = {
            "home": {"value": scene.home.tolist(), "rule": derive.RULES["home"]},
            **{n: {"value": values[n], "rule": derive.RULES[n]} for n in sorted(used)},
        }
        filled.derived_defaults = derived  # on the new config, kept by to_dict
        if announce:
            log.info("%s", derive.summary(scene, values, used))
    return filled, scene


def task_variant(cfg) -> Variant:
    """The dynamics :class:`Variant` of a task or test config (its ``ee_mass``, ``link_length``,
    ``link_scale`` and ``variant`` fields; a bad ``variant`` text raises :class:`FieldError`)."""
    return Variant(
        ee_mass=cfg.ee_mass,
        link_length=cfg.link_length,
        link_scale=cfg.link_scale,
        changes=parse_changes(getattr(cfg, "variant", None)),
    )


def build_task(cfg: TaskConfig, scene: Scene, *, differentiable: bool, copies: int = 1) -> Task:
    """The simulator with ``copies x G x K`` worlds (all with the config's dynamics variant)."""
    from warp_critic.physics.simulator import Simulator

    variant = task_variant(cfg)
    goals = goals_tensor(cfg.goals, scene)
    G, K = goals.shape[0], cfg.worlds_per_goal
    sim = Simulator(
        scene,
        [variant] * (copies * G * K),
        dt=filled(cfg.dt, "dt"),
        substeps=filled(cfg.substeps, "substeps"),
        device=cfg.device,
        differentiable=differentiable,
        gravity=filled(cfg.gravity, "gravity"),
    )
    dev = sim.torch_device
    goal_index = torch.arange(G, device=dev).repeat_interleave(K).repeat(copies)
    slot = torch.arange(K, device=dev).repeat(G * copies)
    norm = Normalizer.from_limits(
        sim.q_lower,
        sim.q_upper,
        max_torque_tensor(filled(cfg.max_torque, "max_torque"), scene, dev),
        filled(cfg.qd_scale, "qd_scale"),
        NominalInertia(scene, cfg.device),
        sim.dynamics_size,
    )
    home = torch.as_tensor(
        getattr(scene, "home", [0.0] * scene.dof), dtype=torch.float32, device=dev
    )
    return Task(
        cfg=cfg,
        scene=scene,
        goals=goals,
        sim=sim,
        goal_index=goal_index,
        slot=slot,
        goal=goals.to(dev)[goal_index],
        norm=norm,
        home=home.expand(copies * G * K, -1).clone(),
        S=copies,
    )
