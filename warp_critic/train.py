"""Model-based meta-learning of the critic (the paper's Algorithm 2): the config and one outer step.

Reads top to bottom: the critic and its optimiser -> for each outer iteration: fresh policies,
inner update with the critic, rollout of the updated policies through the differentiable Newton
model, critic update. Everything around the step (run directory, resume, metrics, progress,
recording, checkpoints) is the shared harness :class:`warp_critic.loop.Session`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from .errors import DivergenceError, FieldError
from .loop import Callback, Session, TrainResult, grad_norm
from .networks import CRITIC_INPUTS, POLICY_INIT_SCHEMES, Critic, MLPPolicy, detach_params
from .outer import meta_loss
from .task import TaskConfig, spec


@dataclass
class TrainConfig(TaskConfig):
    """Model-based meta-training of the critic (Algorithm 2). ``None`` = the scene's default."""

    alpha: float | None = spec(None, "inner learning rate (policy update with the critic)", gt=0, cap=1e6)
    lr: float | None = spec(None, "outer learning rate (Adam on the critic)", gt=0, cap=1e3)
    lr_schedule: str = spec("cosine", "outer learning-rate schedule: constant, or cosine decay to 10%% over the iterations", choices=("constant", "cosine"))
    inner_steps: int = spec(1, "inner critic-gradient steps per outer iteration", gt=0)
    policy_init: str = spec("fresh", "fresh: new random policies every iteration (paper); fixed: the same initial policies every iteration; persistent: continue from the updated policies", choices=POLICY_INIT_SCHEMES)
    policy_lifetime: int = spec(1, "with policy-init fresh: outer iterations a policy lives before a fresh random one replaces it; 1 = new policies every iteration (paper). N > 1 staggers the worlds so policies of every age 0..N-1 are trained on at once: the critic learns to keep improving a policy, and meta-test takes N x inner-steps steps", gt=0, cap=10**6)
    critic_input: str = spec("full", "critic input layout: full = [q, qd, a, g, q-g]; relative = [q-g, qd, a] (goal-equivariant)", choices=CRITIC_INPUTS)
    critic_hidden: int = spec(400, "critic hidden units (2 ELU layers)", gt=0, cap=65536)
    running_weight: float = spec(0.0, "weight of the running term mean_t ||q_t-g||^2 added to the task loss", ge=0)
    velocity_weight: float = spec(0.0, "weight (s^2) of the final-velocity term ||qd_T||^2 added to the task loss", ge=0)
    clip_grad: float = spec(10.0, "clip the critic's gradient norm (0 = off)", ge=0)

    method = "ours"
    scene_fields = TaskConfig.scene_fields + ("alpha", "lr")

    def default_out(self) -> str:
        return f"runs/{self.scene_stem()}-meta"

    def scene_stem(self) -> str:
        from pathlib import Path

        return Path(self.scene).stem

    def check(self, scene=None) -> None:
        super().check(scene)
        if self.policy_lifetime > 1 and self.policy_init != "fresh":
            raise FieldError("policy_lifetime", f"{self.policy_lifetime} needs policy_init fresh (got {self.policy_init})")

    def lr_at(self, it: int) -> float:
        """Cosine decay to 10% of ``lr`` at the last iteration, or constant."""
        if self.lr_schedule == "cosine":
            return self.lr * (0.1 + 0.9 * 0.5 * (1 + math.cos(math.pi * it / max(self.iterations - 1, 1))))
        return self.lr


def meta_train(cfg: TrainConfig, callbacks: list[Callback] | None = None, progress: bool = True,
               record: bool = True, given: set[str] | None = None) -> TrainResult:
    """Run (or resume) meta-training; returns the run directory, metrics and critic.

    ``callbacks`` get an :class:`~warp_critic.loop.IterationInfo` after every iteration; ``given``
    names the fields the user set (for the resume rule; see :class:`~warp_critic.loop.Session`).
    """
    with Session(cfg, differentiable=True, given=given) as session:
        cfg, task, gen = session.cfg, session.task, session.gen
        critic = Critic(task.scene.dof, task.norm, hidden=cfg.critic_hidden, inputs=cfg.critic_input).to(task.device)
        opt = torch.optim.Adam(critic.parameters(), lr=cfg.lr)
        policy = MLPPolicy(task.norm)
        params = policy.init(task.W, generator=gen, device=task.device)
        q0, qd0 = task.home, torch.zeros_like(task.home)
        ckpt = session.restore()
        if ckpt is not None:
            critic.load_state_dict(ckpt["critic_state"])
            opt.load_state_dict(ckpt["optimizer_state"])
            params = {k: v.to(task.device) for k, v in ckpt["policy_params"].items()}

        def step(it: int):
            nonlocal params, q0
            if cfg.policy_init == "fresh":  # Algorithm 2: new random policies every iteration ...
                fresh = policy.init(task.W, generator=gen, device=task.device)
                if cfg.policy_lifetime == 1:
                    params = fresh
                else:  # ... or, staggered, in the worlds whose policy has reached its lifetime
                    reset = (it + task.slot) % cfg.policy_lifetime == 0  # (W,)
                    params = {k: torch.where(reset.view(-1, *[1] * (v.dim() - 1)), fresh[k], v)
                              for k, v in params.items()}
            if cfg.start_std:
                q0 = task.start_states(gen)
            res = meta_loss(critic, policy, detach_params(params), task.sim, q0, qd0, task.goal,
                            horizon=cfg.horizon, alpha=cfg.alpha, inner_steps=cfg.inner_steps,
                            running_weight=cfg.running_weight, velocity_weight=cfg.velocity_weight)
            opt.zero_grad(set_to_none=True)
            res.loss.backward()
            norm = grad_norm(critic)
            if not (math.isfinite(res.loss.item()) and math.isfinite(norm)):
                raise DivergenceError("non-finite task loss or critic gradient")
            if cfg.clip_grad:
                torch.nn.utils.clip_grad_norm_(critic.parameters(), cfg.clip_grad)
            for group in opt.param_groups:
                group["lr"] = cfg.lr_at(it)
            opt.step()
            if cfg.policy_init == "persistent" or cfg.policy_lifetime > 1:  # lifetime > 1 implies fresh
                params = res.params_new
            before = ((res.before.q[-1] - task.goal) ** 2).sum(-1)
            row = {"task_loss": res.per_world.mean().item(), "task_loss_before": before.mean().item(),
                   "task_loss_per_goal": task.per_goal(res.per_world).tolist(), "grad_norm": norm}
            return row, res

        def state() -> dict:
            return {"critic_state": critic.state_dict(), "critic_hidden": cfg.critic_hidden,
                    "critic_input": cfg.critic_input, "optimizer_state": opt.state_dict(),
                    "policy_params": {k: v.cpu() for k, v in params.items()}}

        result = session.run(step, state, callbacks=callbacks, progress=progress, record=record,
                             describe=lambda r: f"task {r['task_loss']:.4f} (before {r['task_loss_before']:.3f})")
    result.model = critic
    return result
