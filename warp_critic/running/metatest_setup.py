"""Meta-test's set-up (the paper's Algorithm 3): a run's critic, its task with the test's goals and
dynamics, a gradient-free simulator and fresh policies. :mod:`warp_critic.evaluation.metatest` runs
it; ``identify`` (``methods/``) reuses it. The critic comes from the loader that the run's method
registered (:mod:`warp_critic.running.methods`): ours, or ``L = -Q`` of a baseline's Q function.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import torch

from warp_critic.core.errors import FieldError, UserError
from warp_critic.core.memory import check_fits
from warp_critic.core.runtime import check_seed
from warp_critic.learning.inner import MAX_POLICY_STEPS, inner_update
from warp_critic.learning.networks import MLPPolicy, Normalizer
from warp_critic.physics.scene import Scene
from warp_critic.physics.schema import STANDARD_GRAVITY
from warp_critic.running.config import SerializableConfig, check_fields, spec
from warp_critic.running.goals import GOAL_NOISE, sample_goals
from warp_critic.running.methods import method, names
from warp_critic.running.rundir import RunDir
from warp_critic.running.scenefile import find_run_scene
from warp_critic.running.task import TaskConfig, build_task, task_variant
from warp_critic.running.task_inputs import estimate_memory, goals_tensor

if TYPE_CHECKING:  # a type only: the simulator module loads Newton (seconds)
    from warp_critic.physics.simulator import Simulator


@dataclass
class MetaTestConfig(SerializableConfig):
    """Meta-test settings; ``None`` = the value the run was trained with."""

    run_dir: str = spec("", "run directory written by meta-train or baseline")
    goals: list[list[float]] | None = spec(
        None,
        "explicit goals, inline 'a,b;c,d' or a file; default: sampled around the training goals",
    )
    num_goals: int = spec(10, "number of sampled goals", gt=0, cap=10**6)
    goal_std: float = spec(
        0.3, "std (rad) of the Gaussian around the training goals", ge=0, cap=100
    )
    goal_noise: str = spec(
        "per-joint",
        "per-joint: N(g, std^2) on every joint; distance: a random direction at a distance N(0, std^2) (the paper's 'at a distance of N(0, std)' reads both ways)",
        choices=GOAL_NOISE,
    )
    around: list[int] | None = spec(
        None, "indices of the training goals to sample around (default: all, cycled)", ge=0
    )
    inits: int = spec(5, "fresh policy initialisations per goal", gt=0, cap=10**6)
    policy_steps: int | None = spec(
        None,
        "critic-gradient steps per fresh policy (default: the run's inner steps x its policy "
        f"lifetime; at most {MAX_POLICY_STEPS})",
        gt=0,
        cap=MAX_POLICY_STEPS,
    )
    alpha: float | None = spec(
        None, "policy learning rate (default: the run's inner learning rate)", gt=0, cap=1e6
    )
    horizon: int | None = spec(None, "rollout length (default: the run's)", gt=0, cap=10**6)
    ee_mass: float = spec(0.0, "mass added at the end-effector (kg)", ge=0, cap=1e4)
    link_length: float | None = spec(None, "set the end-effector link length (m)", gt=0, cap=100)
    link_scale: float = spec(1.0, "scale the end-effector link length", gt=0, cap=100)
    variant: str | None = spec(
        None,
        "dynamics changes of any link at test, ';'-separated LINK.WHAT=V, +=V or *=V (WHAT: mass[:keep|:scale] at the COM, point-mass+=KG@x,y,z|@tip, offset (kinematic length, no mass change), stretch (stretched link)), e.g. 'iiwa_link_7.mass=5; ee.offset+=0.4'; applied after --ee-mass/--link-length/--link-scale (default: none)",
    )
    seed: int = spec(1, "random seed", ge=0, le=2**32 - 1)
    device: str = spec("auto", "cpu, cuda or auto")
    out: str | None = spec(None, "results JSON (default RUN_DIR/metatest.json)")


def build_test_critic(ckpt: dict, norm: Normalizer) -> tuple[torch.nn.Module, dict]:
    """The loss ``L(q, qd, tau, g)`` a fresh policy descends and the run's defaults, for any method:
    the critic loader of the run's method in the registry (:mod:`warp_critic.running.methods`)."""
    name = ckpt.get("method", "ours")
    if name not in names():
        raise UserError(f"checkpoint of method {name!r}: meta-test knows {', '.join(names())}")
    try:
        return method(name).critic_loader(ckpt, norm)
    except (KeyError, RuntimeError, TypeError, ValueError) as e:
        if isinstance(e, UserError):
            raise
        raise UserError(
            f"{name} checkpoint has no usable critic ({type(e).__name__}: "
            f"{str(e).splitlines()[0] if str(e) else ''})"
        ) from None


@dataclass
class MetaTestSetup:
    """Everything a model-free meta-test needs: ``W = G x K`` worlds (goal-major), fresh policies."""

    ckpt: dict
    cfg: TaskConfig  # the run's task
    scene: Scene
    goals: torch.Tensor  # (G, dof) rad, on the CPU
    goal: torch.Tensor  # (W, dof) rad, each world's goal
    sim: Simulator  # built without gradient buffers
    norm: Normalizer
    critic: torch.nn.Module  # frozen
    policy: MLPPolicy
    params: dict  # fresh policy parameters, (W, ...) each
    q0: torch.Tensor
    qd0: torch.Tensor
    inits: int
    steps: int
    horizon: int
    alpha: float

    def update(self, params: dict, **kw) -> tuple[dict, list]:
        """Meta-test's policy update of ``params`` (:func:`~warp_critic.learning.inner.inner_update`
        with this setup's critic, model, starts, goals, horizon, rate and steps; ``kw`` as there):
        the updated parameters and the rollout each step evaluated."""
        return inner_update(
            self.critic,
            self.policy,
            params,
            self.sim,
            self.q0,
            self.qd0,
            self.goal,
            horizon=self.horizon,
            alpha=self.alpha,
            steps=self.steps,
            **kw,
        )


def setup_meta_test(tc: MetaTestConfig, gen: torch.Generator | None = None) -> MetaTestSetup:
    """Load the run, check ``tc``, sample the goals and build the gradient-free model and fresh policies.

    ``gen`` draws the goals and the policy initialisations (default: a new generator seeded with
    ``tc.seed``); no global random state is read or changed.
    """
    check_fields(tc)
    test_variant = task_variant(tc)  # a bad --variant text fails before the run is read
    ckpt, cfg, scene = _load_run(tc, test_variant)
    horizon = tc.horizon if tc.horizon is not None else cfg.horizon

    if gen is None:
        gen = torch.Generator().manual_seed(check_seed(tc.seed))
    goals = _test_goals(tc, cfg, scene, gen)
    G, K = goals.shape[0], tc.inits
    W = G * K
    check_fits(
        "inits",
        f"{G} goals x {K} inits = {W} worlds, horizon {horizon}",
        estimate_memory(W, scene.dof, horizon, cfg.substeps),
    )
    # the run's task with the test's goals, inits and dynamics variant, as training laid it out; built
    # without gradient buffers (differentiable=False): a taped rollout through it is impossible
    test_task = replace(
        cfg,
        goals=goals.tolist(),
        worlds_per_goal=K,
        ee_mass=tc.ee_mass,
        link_length=tc.link_length,
        link_scale=tc.link_scale,
        variant=tc.variant,
        device=tc.device,
        horizon=horizon,
        gravity=cfg.gravity if cfg.gravity is not None else STANDARD_GRAVITY,
    )
    task = build_task(test_task, scene, differentiable=False)
    sim, norm, dev, goal = task.sim, task.norm, task.device, task.goal
    critic, defaults = build_test_critic(ckpt, norm)
    critic = critic.to(dev)
    for p in critic.parameters():
        p.requires_grad_(False)
    alpha, steps = _policy_step_settings(tc, defaults)
    q0, qd0 = task.home, torch.zeros_like(task.home)
    policy = MLPPolicy(norm)
    params = {
        k: v.requires_grad_(True) for k, v in policy.init(W, generator=gen, device=dev).items()
    }
    return MetaTestSetup(
        ckpt=ckpt,
        cfg=cfg,
        scene=scene,
        goals=goals,
        goal=goal,
        sim=sim,
        norm=norm,
        critic=critic,
        policy=policy,
        params=params,
        q0=q0,
        qd0=qd0,
        inits=K,
        steps=steps,
        horizon=horizon,
        alpha=alpha,
    )


def _load_run(tc: MetaTestConfig, test_variant) -> tuple[dict, Any, Scene]:
    """The run's checkpoint, its task config (a :class:`TaskConfig` as training filled it in: no
    ``None`` left) and its scene (found by content), checked against each other and against the
    test's dynamics variant."""
    ckpt = RunDir.open(tc.run_dir).load_checkpoint(require=("config", "dof", "scene", "method"))
    try:
        cfg = TaskConfig.from_dict(ckpt["config"])
        check_fields(cfg)
    except (TypeError, UserError) as e:
        raise UserError(f"{tc.run_dir}: checkpoint holds an unusable config ({e})") from None
    scene = find_run_scene(ckpt, tc.run_dir)  # by its content, wherever it is now
    if scene.name != ckpt["scene"] or scene.dof != ckpt["dof"]:
        raise UserError(
            f"{tc.run_dir}: checkpoint is for scene {ckpt['scene']} ({ckpt['dof']} dof), "
            f"but {cfg.scene} is {scene.name} ({scene.dof} dof)"
        )
    if ckpt.get("scene_hash") and getattr(scene, "content_hash", None) not in (
        None,
        ckpt["scene_hash"],
    ):
        raise UserError(
            f"{tc.run_dir}: the scene file {cfg.scene} has changed since the run was trained"
        )
    if test_variant.changes:  # its link names, masses and lengths against the run's scene
        scene.world_builder(test_variant)
    return ckpt, cfg, scene


def _test_goals(
    tc: MetaTestConfig, cfg: TaskConfig, scene: Scene, gen: torch.Generator
) -> torch.Tensor:
    """The test's goals (G, dof) in rad (or m): ``tc.goals`` as given, else drawn around the run's
    training goals within the joint limits."""
    train_goals = torch.tensor(cfg.goals, dtype=torch.float32)
    lo = torch.as_tensor(scene.q_lower, dtype=torch.float32)
    hi = torch.as_tensor(scene.q_upper, dtype=torch.float32)
    if tc.goals is not None:
        return goals_tensor(tc.goals, scene)
    return sample_goals(
        train_goals, tc.num_goals, tc.goal_std, tc.around, lo, hi, gen, tc.goal_noise
    )


def _policy_step_settings(tc: MetaTestConfig, defaults: dict) -> tuple[float, int]:
    """The policy learning rate ``alpha`` and the critic-gradient steps per policy: the test's, else
    the run's defaults, checked."""
    alpha = tc.alpha if tc.alpha is not None else defaults.get("alpha")
    steps = tc.policy_steps if tc.policy_steps is not None else defaults.get("steps", 1)
    if tc.policy_steps is None and int(steps) > MAX_POLICY_STEPS:
        raise FieldError(
            "policy_steps",
            f"{tc.run_dir}: the run's default of {steps} critic-gradient steps per policy (inner "
            f"steps x policy lifetime) is over the limit of {MAX_POLICY_STEPS}: give at most "
            f"{MAX_POLICY_STEPS}",
        )
    if not (isinstance(alpha, (int, float)) and alpha > 0):
        raise UserError(
            f"{tc.run_dir}: the run stores no usable policy learning rate (alpha {alpha!r}); give one"
        )
    return alpha, steps
