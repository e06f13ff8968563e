"""Meta-test (the paper's Algorithm 3): train fresh policies with a learned critic, model-free.

The simulator is built **without gradients** (``requires_grad=False``): it only produces rollouts,
and the policies follow ``-alpha * grad_theta sum_t L(s_t, pi_theta(s_t), g)`` of the saved critic.
Works for every method's run directory: our critic, and the Q functions of DDPG / Meta-Critic
(through :func:`test_critic_from_checkpoint`, which returns a module with the same signature
``L(q, qd, tau, g)`` -- for a Q function, ``L = -Q``).

Two aggregations of the final error are reported, for every goal and init:

* ``mean`` / ``std`` / ``final_error_*``: ``||q_T - g||^2``, the squared joint-space distance summed
  over the joints (rad^2), the task loss the critic was meta-trained on;
* ``mse_*``: ``mean_j (q_T,j - g_j)^2``, the *mean* squared error over the joints (rad^2), i.e. the
  sum divided by ``dof``. The paper's Tables 1-3 report "the mean squared error between last state
  and goal"; the authors' earlier ML3 code reports its reacher error the same way,
  ``torch.mean((states[-1, :2] - goal[:2]) ** 2)``. Compare with the paper in this column.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import torch

from warp_critic.core.errors import FieldError, UserError
from warp_critic.core.memory import check_fits
from warp_critic.core.runtime import check_seed
from warp_critic.evaluation.critic_loaders import (  # also metatest.<name>, as before
    CRITIC_LOADERS,
    build_test_critic,
    load_our_critic,
    register_critic_loader,
)
from warp_critic.evaluation.goals import sample_goals  # also metatest.sample_goals, as before
from warp_critic.evaluation.paper import GOAL_NOISE
from warp_critic.learning.inner import MAX_POLICY_STEPS, inner_update, policy_fn
from warp_critic.learning.losses import final_error
from warp_critic.learning.networks import MLPPolicy, Normalizer
from warp_critic.learning.rollout import rollout
from warp_critic.physics.scene import Scene
from warp_critic.physics.simulator import STANDARD_GRAVITY, Simulator
from warp_critic.running.config import SerializableConfig, check_fields, spec
from warp_critic.running.rundir import RunDir, check_output_file, write_result
from warp_critic.running.scenefile import find_run_scene
from warp_critic.running.task import TaskConfig, build_task, task_variant
from warp_critic.running.task_inputs import estimate_memory, goals_tensor

RESULT_KIND = "warp-critic/metatest-v1"


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
    horizon = tc.horizon if tc.horizon is not None else cfg.horizon

    if gen is None:
        gen = torch.Generator().manual_seed(check_seed(tc.seed))
    train_goals = torch.tensor(cfg.goals, dtype=torch.float32)
    lo = torch.as_tensor(scene.q_lower, dtype=torch.float32)
    hi = torch.as_tensor(scene.q_upper, dtype=torch.float32)
    if tc.goals is not None:
        goals = goals_tensor(tc.goals, scene)
    else:
        goals = sample_goals(
            train_goals, tc.num_goals, tc.goal_std, tc.around, lo, hi, gen, tc.goal_noise
        )
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


def meta_test(
    tc: MetaTestConfig, progress: Callable[[str], None] | None = None, record: bool = False
) -> dict:
    """Algorithm 3 on ``G x K`` fresh policies; writes and returns the results (see the module docstring).

    ``progress`` (the CLI passes ``print``) gets the summary, one line per call; nothing is printed.
    ``record``: also write a rerun recording beside the results
    (:mod:`warp_critic.running.recording_metatest`; its path in ``result["recording"]``).
    """
    out = check_output_file(Path(tc.out) if tc.out else Path(tc.run_dir) / "metatest.json", "out")
    if record:
        from warp_critic.running.recording_metatest import metatest_recording_path

        rrd = metatest_recording_path(out)
    m = setup_meta_test(tc)
    _not_anothers(out, tc, m.ckpt.get("run_id"))
    ckpt, scene, goals, goal, sim, policy = m.ckpt, m.scene, m.goals, m.goal, m.sim, m.policy
    params, q0, qd0, steps, horizon, alpha = m.params, m.q0, m.qd0, m.steps, m.horizon, m.alpha
    G, K = goals.shape[0], m.inits
    before = rollout(sim, policy_fn(policy, params), q0, qd0, horizon)
    params, trajs = m.update(params, create_graph=False)
    after = rollout(sim, policy_fn(policy, params), q0, qd0, horizon)
    err = final_error(after.q[-1], goal).view(G, K).cpu()
    err0 = final_error(before.q[-1], goal).view(G, K).cpu()
    per_goal = err.mean(1)
    mse, mse0 = err / scene.dof, err0 / scene.dof  # mean over the joints instead of the sum
    result = {
        "kind": RESULT_KIND,
        "run_dir": str(tc.run_dir),
        "run_id": ckpt.get("run_id"),
        "method": ckpt.get("method", "ours"),
        "scene": scene.name,
        "goals": goals.tolist(),
        "goal_std": tc.goal_std if tc.goals is None else None,
        "goal_noise": tc.goal_noise if tc.goals is None else None,
        "inits": K,
        "policy_steps": steps,
        "alpha": alpha,
        "horizon": horizon,
        "variant": {
            "ee_mass": tc.ee_mass,
            "link_length": tc.link_length,
            "link_scale": tc.link_scale,
            "changes": tc.variant,
        },
        "final_error_per_goal": per_goal.tolist(),
        "final_error_all": err.tolist(),
        "mean": float(err.mean()),
        "std": float(err.std(unbiased=False)),
        "mean_before": float(err0.mean()),
        # the same, averaged over the joints instead of summed (the paper's "mean squared error")
        "mse_per_goal": mse.mean(1).tolist(),
        "mse_mean": float(mse.mean()),
        "mse_std": float(mse.std(unbiased=False)),
        "mse_mean_before": float(mse0.mean()),
    }
    if progress:
        progress(
            f"meta-test {result['method']} on {scene.name}: {G} goals x {K} inits, "
            f"{steps} policy step(s), no model gradient"
        )
        progress(
            f"  final error per goal, mean over {K} inits: ||q_T - g||^2 summed over the joints, "
            f"and its mean over the {scene.dof} joints (MSE, the paper's tables)"
        )
        for i, e in enumerate(per_goal.tolist()):
            progress(
                f"  goal {i:2d} {np.array2string(goals[i].numpy(), precision=2)}  "
                f"final sq. error {e:.4f}  MSE {e / scene.dof:.4f}"
            )
        progress(
            f"  sq. error: mean {result['mean']:.4f}  std {result['std']:.4f}  "
            f"(untrained policies: {result['mean_before']:.4f})"
        )
        progress(
            f"  MSE:       mean {result['mse_mean']:.4f}  std {result['mse_std']:.4f}  "
            f"(untrained policies: {result['mse_mean_before']:.4f})"
        )
    write_result(out, result)
    result["output"] = str(out)
    if record:
        from warp_critic.running.recording_metatest import record_meta_test

        rollouts = [before, *trajs[1:], after]  # the policies at every step
        result["recording"] = str(
            record_meta_test(rrd, sim, goals, goal, K, rollouts, result["method"])
        )
    return result


def _not_anothers(out: Path, tc: MetaTestConfig, run_id: str | None) -> None:
    """An existing ``out`` is replaced only if it is a meta-test result of this run (the same run id,
    or, for a result without one, the same run directory): never another run's or command's."""
    import json

    try:
        old = json.loads(out.read_text()) if out.is_file() else None
    except (OSError, ValueError, UnicodeDecodeError):
        old = {}
    if old is None:
        return
    old = old if isinstance(old, dict) else {}
    if old.get("kind") == RESULT_KIND:
        same_dir = Path(str(old.get("run_dir"))).resolve() == Path(tc.run_dir).resolve()
        if (old.get("run_id") == run_id) if old.get("run_id") and run_id else same_dir:
            return
        whose = f"of the run {old.get('run_dir')}"
    else:
        whose = f"of kind {old.get('kind')!r}"
    raise FieldError(
        "out", f"{out}: holds a result {whose}; not replacing it (choose another file)"
    )


__all__ = [
    "CRITIC_LOADERS",
    "MetaTestConfig",
    "MetaTestSetup",
    "build_test_critic",
    "load_our_critic",
    "meta_test",
    "register_critic_loader",
    "sample_goals",
    "setup_meta_test",
]
