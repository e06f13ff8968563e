"""Model-based meta-learning of the critic (the paper's Algorithm 2): the config and one outer step.

Reads top to bottom: the critic and its optimiser -> for each outer iteration: fresh policies,
inner update with the critic, rollout of the updated policies through the differentiable Newton
model, critic update. Everything around the step (run directory, resume, metrics, progress,
recording, checkpoints) is the shared harness :class:`warp_critic.running.loop.Session`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import torch

from warp_critic.core.errors import DivergenceError, FieldError, UserError
from warp_critic.learning.critic import Critic
from warp_critic.learning.critic_inputs import CRITIC_INPUTS, critic_input_help
from warp_critic.learning.identify import IdentifiedCritic, identifier_from_checkpoint
from warp_critic.learning.inner import MAX_POLICY_STEPS, check_policy_steps
from warp_critic.learning.networks import (
    POLICY_INIT_SCHEMES,
    MLPPolicy,
    PolicyParams,
    detach_params,
)
from warp_critic.learning.outer import meta_loss
from warp_critic.learning.stacked import (
    StackedCritic,
    clip_slice_,
    load_optimizer_slice,
    optimizer_slice,
    slice_norm,
)
from warp_critic.methods.train_variants import VariantRedraw, check_train_variants
from warp_critic.physics import schema
from warp_critic.running.config import filled, spec
from warp_critic.running.loop import Callback, Session, TrainResult
from warp_critic.running.methods import Method, register
from warp_critic.running.task import TaskConfig


@dataclass
class TrainConfig(TaskConfig):
    """Model-based meta-training of the critic (Algorithm 2). ``None`` = the scene's default."""

    # None: the scene's count; Session hands the method the filled config (an int)
    iterations: int | None = spec(  # type: ignore[assignment]
        None,
        "outer iterations (critic updates); default: the scene's (the reported runs), else "
        + schema.fallback_text("iterations"),
        gt=0,
        cap=10**8,
    )
    alpha: float | None = spec(
        None, "inner learning rate (policy update with the critic)", gt=0, cap=1e6
    )
    lr: float | None = spec(None, "outer learning rate (Adam on the critic)", gt=0, cap=1e3)
    lr_schedule: str = spec(
        "cosine",
        "outer learning-rate schedule: constant, or cosine decay to 10%% over the iterations",
        choices=("constant", "cosine"),
    )
    inner_steps: int | None = spec(
        None,
        "inner critic-gradient steps per outer iteration; default: the scene's, else "
        + schema.fallback_text("inner_steps")
        + " (the paper's Algorithm 2)",
        gt=0,
        cap=10**4,
    )
    policy_init: str = spec(
        "fresh",
        "fresh: new random policies every iteration (paper); fixed: the same initial policies every iteration; persistent: continue from the updated policies",
        choices=POLICY_INIT_SCHEMES,
    )
    policy_lifetime: int = spec(
        1,
        "with policy-init fresh: outer iterations a policy lives before a fresh random one replaces it; 1 = new policies every iteration (paper). N > 1 staggers the worlds so policies of every age 0..N-1 are trained on at once: the critic learns to keep improving a policy, and meta-test takes N x inner-steps steps "
        f"(at most {MAX_POLICY_STEPS} in all)",
        gt=0,
        cap=MAX_POLICY_STEPS,
    )
    critic_input: str | None = spec(
        None,
        "critic input layout: "
        + critic_input_help()
        + "; default: the scene's, else "
        + schema.fallback_text("critic_input"),
        choices=tuple(CRITIC_INPUTS),
    )
    critic_hidden: int = spec(400, "critic hidden units (2 ELU layers)", gt=0, cap=8192)
    running_weight: float = spec(
        0.0, "weight of the running term mean_t ||q_t-g||^2 added to the task loss", ge=0
    )
    velocity_weight: float = spec(
        0.0, "weight (s^2) of the final-velocity term ||qd_T||^2 added to the task loss", ge=0
    )
    clip_grad: float = spec(10.0, "clip the critic's gradient norm (0 = off)", ge=0)
    on_divergence: str = spec(
        "stop",
        "a world whose state goes non-finite (or beyond 1e4 rad, rad/s) in training: stop = stop "
        "the run naming world and step, keeping the last checkpoint; drop = leave that world out "
        "of this iteration's task loss and gradient (exactly zero) and go on, counting it in the "
        "metrics as diverged_worlds (a seed whose worlds all diverge still stops). For "
        "--train-variants over models that an integrator step cannot always hold",
        choices=("stop", "drop"),
    )
    train_variants: str | None = spec(
        None,
        "dynamics-randomised meta-training: ';'-separated link changes (as --variant) whose values "
        "may be ranges LO..HI, drawn uniformly for every world at every iteration (seeded by the "
        "seed and the iteration, so a resumed run draws the same; the draws are in the metrics as "
        "train_variant_values), applied after --variant; e.g. 'ee.point-mass+=0..9' or "
        "'arm1.mass=0.5..6; arm2.mass=0.5..6'. Groups joined by '|' are alternatives: at "
        "iteration i world w takes group (w + i) mod (number of groups) only, one factor at a time, "
        "e.g. 'ee.stretch=0.2..2 | ee.point-mass+=0..9' (default: none, the nominal model)",
    )

    method = "ours"
    scene_fields = TaskConfig.scene_fields + schema.keys("meta-train")

    def default_out(self) -> str:
        return f"runs/{Path(self.scene).stem}-meta"

    def check(self, scene=None) -> None:
        super().check(scene)
        check_policy_steps(self.policy_lifetime, self.inner_steps or 1)
        check_train_variants(self, scene)
        if self.policy_lifetime > 1 and self.policy_init != "fresh":
            raise FieldError(
                "policy_lifetime",
                f"{self.policy_lifetime} needs policy_init fresh (got {self.policy_init})",
            )

    def lr_at(self, it: int) -> float:
        """Cosine decay to 10% of ``lr`` at the last iteration, or constant."""
        lr = filled(self.lr, "lr")
        if self.lr_schedule == "cosine":
            iterations = filled(self.iterations, "iterations")
            return lr * (0.1 + 0.9 * 0.5 * (1 + math.cos(math.pi * it / max(iterations - 1, 1))))
        return lr


def meta_train(
    cfg: TrainConfig,
    callbacks: list[Callback] | None = None,
    progress: bool = True,
    record: bool = True,
    given: set[str] | None = None,
) -> TrainResult:
    """Run (or resume) meta-training; returns the run directory, metrics and critic.

    With ``cfg.seeds`` the seeds train at once: their worlds share one simulator, their critics are
    one :class:`~warp_critic.learning.stacked.StackedCritic` under one Adam (elementwise, so exactly one Adam
    per critic), and each seed's gradient is clipped on its own; every seed writes the run directory
    a single-seed run would (``result.seeds``). ``callbacks`` get an
    :class:`~warp_critic.running.loop.IterationInfo` (of the first seed) after every iteration; ``given``
    names the fields the user set (for the resume rule; see :class:`~warp_critic.running.loop.Session`).
    """
    with Session(
        cfg,
        differentiable=True,
        given=given,
        require=("critic_state", "optimizer_state", "policy_params"),
    ) as session:
        run = _MetaTrainRun(session)  # set-up, then the checkpoint's states (resume)
        result = session.run(
            run.step,
            run.state,
            callbacks=callbacks,
            progress=progress,
            record=record,
            describe=lambda r: f"task {r['task_loss']:.4f} (before {r['task_loss_before']:.3f})",
        )
    for i, r in enumerate(result.seeds):
        r.model = run.critic.critic(i)
    return result


class _MetaTrainRun:
    """One meta-training's critics (one per seed, stacked), optimiser, policies and iteration."""

    IDENTIFIED = ("identifier", "identifier_state")  # an identified run's checkpoint entries

    def __init__(self, session: Session):
        cfg, task = session.cfg, session.task  # the scene's defaults filled in
        assert isinstance(cfg, TrainConfig)
        self.cfg, self.task = cfg, task
        self.critic_input = filled(cfg.critic_input, "critic_input")
        S, dev, dof, hidden = task.S, task.device, task.scene.dof, cfg.critic_hidden
        self.policy = MLPPolicy(task.norm)
        self.gens: list[torch.Generator] = []
        critics: list[Critic] = []
        seed_params: list[PolicyParams] = []
        for i in range(S):  # each seed's draws in the order of a single-seed run
            self.gens.append(session.seed(i))
            critics.append(Critic(dof, task.norm, hidden, inputs=self.critic_input).to(dev))
            seed_params.append(self.policy.init(task.Wc, generator=self.gens[-1], device=dev))
            session.seeded(i)
        self.critic = StackedCritic(critics)
        self.opt = torch.optim.Adam(self.critic.ordered(), lr=filled(cfg.lr, "lr"))
        # an identified run's identifiers (warp-critic identify), and their checkpoint entries, kept
        identifiers: list = []
        self.identified: list[dict] = []
        for i in range(S):
            ckpt = session.restore(i)
            if ckpt is not None:
                with session.loading(i):
                    self.critic.load_critic_state(i, ckpt["critic_state"])
                    load_optimizer_slice(self.opt, self.critic, i, ckpt["optimizer_state"])
                    seed_params[i] = {
                        k: ckpt["policy_params"][k].to(dev).reshape(v.shape)
                        for k, v in seed_params[i].items()
                    }
                    ident = identifier_from_checkpoint(ckpt)
                    if ident is not None:
                        identifiers.append(ident.to(dev).requires_grad_(False))
                        self.identified.append({k: ckpt[k] for k in self.IDENTIFIED})
        # the critic the inner loop descends: an identified run trains on its identifiers'
        # estimates from every rollout, as at meta-test, never on the told model
        self.inner_critic: torch.nn.Module = self.critic
        if self.identified:
            if len(self.identified) != S:
                raise UserError(
                    "identified and told runs cannot resume together: resume the identified ones "
                    "(warp-critic identify's outputs) apart"
                )
            self.inner_critic = IdentifiedCritic(self.critic, identifiers)
        self.params = _cat(seed_params)
        self.q0, self.qd0 = task.home, torch.zeros_like(task.home)
        self.seeds = [r.cfg.seed for r in session.runs]  # of the task's copies, in order
        self.redraw = VariantRedraw(cfg, task, self.seeds) if cfg.train_variants else None
        self.drop = cfg.on_divergence == "drop"

    def step(self, it: int):
        """Policies, the inner update and rollout through the model, one critic step; a row per seed."""
        cfg, task = self.cfg, self.task
        drawn = self.redraw(it) if self.redraw is not None else None
        self.new_policies(it)
        if cfg.start_std:
            self.q0 = torch.cat([task.start_states(g, i) for i, g in enumerate(self.gens)])
        res = meta_loss(
            self.inner_critic,
            self.policy,
            detach_params(self.params),
            task.sim,
            self.q0,
            self.qd0,
            task.goal,
            horizon=filled(cfg.horizon, "horizon"),
            alpha=filled(cfg.alpha, "alpha"),
            inner_steps=filled(cfg.inner_steps, "inner_steps"),
            running_weight=cfg.running_weight,
            velocity_weight=cfg.velocity_weight,
            drop_diverged=self.drop,
        )
        settled = res.settled.view(task.S, -1)
        norms = self.update_critic(it, res, settled)
        if cfg.policy_init == "persistent" or cfg.policy_lifetime > 1:  # lifetime > 1: fresh
            self.params = res.params_new
        return self.rows(res, settled, norms, drawn), res

    def new_policies(self, it: int) -> None:
        """Algorithm 2: new random policies every iteration, or (staggered) in the worlds whose
        policy has reached its lifetime; persistent policies carry on."""
        cfg, task = self.cfg, self.task
        if cfg.policy_init != "fresh":
            return
        fresh = _cat(
            [self.policy.init(task.Wc, generator=g, device=task.device) for g in self.gens]
        )
        if cfg.policy_lifetime == 1:
            self.params = fresh
            return
        reset = (it + task.slot) % cfg.policy_lifetime == 0  # (W,)
        self.params = {
            k: torch.where(reset.view(-1, *[1] * (v.dim() - 1)), fresh[k], v)
            for k, v in self.params.items()
        }

    def update_critic(self, it: int, res, settled: torch.Tensor) -> list[float]:
        """One Adam step on each seed's task loss (its mean over the settled worlds with
        ``on_divergence`` drop); returns each seed's gradient norm (before clipping)."""
        S, seeds, critic = self.task.S, self.seeds, self.critic
        if self.drop:  # each seed's mean over its settled worlds
            kept = settled.sum(1)
            if bool((kept == 0).any()):
                gone = [str(seeds[i]) for i in range(S) if int(kept[i]) == 0]
                raise DivergenceError(f"every world diverged (seed {', '.join(gone)})")
            loss = res.losses.view(S, -1).sum(1) / kept
        else:
            loss = res.losses.view(S, -1).mean(1)  # (S,) each seed's task loss
        self.opt.zero_grad(set_to_none=True)
        loss.sum().backward()  # seeds share no parameter: each gets its own gradient
        norms = [slice_norm(critic, i) for i in range(S)]
        finite = [math.isfinite(loss[i].item()) and math.isfinite(norms[i]) for i in range(S)]
        bad = [seeds[i] for i in range(S) if not finite[i]]
        if bad:
            raise DivergenceError(
                f"non-finite task loss or critic gradient (seed {', '.join(map(str, bad))})"
            )
        if self.cfg.clip_grad:
            for i in range(S):
                clip_slice_(critic, i, self.cfg.clip_grad)
        for group in self.opt.param_groups:
            group["lr"] = self.cfg.lr_at(it)
        self.opt.step()
        return norms

    def rows(self, res, settled: torch.Tensor, norms: list[float], drawn) -> list[dict]:
        """Each seed's metrics row (with ``on_divergence`` drop: means over its settled worlds)."""
        task = self.task
        before = ((res.before.q[-1] - task.goal) ** 2).sum(-1)
        rows: list[dict] = []
        for i in range(task.S):
            sl = task.copy(i)
            after_i, before_i = res.per_world[sl], before[sl]
            keep = settled[i] if self.drop else None
            mean_after, mean_before = (
                (x if keep is None else x[keep]).mean().item() for x in (after_i, before_i)
            )
            row = {
                "task_loss": mean_after,
                "task_loss_before": mean_before,
                "task_loss_per_goal": [  # null: a goal whose worlds all diverged
                    None if v != v else v for v in task.per_goal(after_i, keep).tolist()
                ],
                "grad_norm": norms[i],
            }
            if self.drop:
                row["diverged_worlds"] = int((~settled[i]).sum())
            if self.identified:  # the critic learned on its identifier's estimates, not the model
                row["critic_fed"] = "identified"
            if drawn is not None:
                # null: a range of another '|' group than the world's at this iteration
                row["train_variant_values"] = [
                    [None if v != v else v for v in world] for world in drawn[i].tolist()
                ]
            rows.append(row)
        return rows

    def state(self, i: int) -> dict:
        sl = self.task.copy(i)
        return {
            "critic_state": self.critic.critic_state(i),
            "critic_hidden": self.cfg.critic_hidden,
            "critic_input": self.critic_input,
            "optimizer_state": optimizer_slice(self.opt, self.critic, i),
            "policy_params": {
                k: v[sl].cpu().clone() for k, v in self.params.items()
            },  # own storage
            **(self.identified[i] if self.identified else {}),
        }


def _cat(per_seed: list[PolicyParams]) -> PolicyParams:
    return (
        {k: torch.cat([p[k] for p in per_seed]) for k in per_seed[0]}
        if len(per_seed) > 1
        else per_seed[0]
    )


def load_our_critic(ckpt: dict, norm) -> tuple[torch.nn.Module, dict]:
    """Our meta-learned critic; meta-test defaults: its inner lr, inner steps x policy lifetime."""
    cfg = ckpt["config"]
    critic: torch.nn.Module = Critic(
        ckpt["dof"],
        norm,
        hidden=ckpt.get("critic_hidden", 400),
        inputs=ckpt.get("critic_input", "full"),
    )
    critic.load_state_dict(ckpt["critic_state"])
    identifier = identifier_from_checkpoint(ckpt)
    if identifier is not None:  # a told critic fed the model identified from its rollouts
        critic = IdentifiedCritic(critic, identifier)
    # a critic trained on policies of every age up to the policy lifetime keeps improving them that long
    steps = int(cfg.get("inner_steps", 1)) * int(cfg.get("policy_lifetime", 1))
    return critic, {"alpha": cfg.get("alpha"), "steps": steps}


register(
    Method(
        name="ours",
        order=0,
        label="L_critic (ours)",
        colour="tab:blue",
        config=TrainConfig,
        train=meta_train,
        critic_loader=load_our_critic,
        samples_per_iteration=lambda cfg: filled(cfg.inner_steps, "inner_steps") + 1,
        samples_text="(inner_steps + 1) x worlds x horizon per iteration: the inner-loop rollouts "
        "and the rollout of the updated policies",
        baseline=False,
        paper_label="paper (Table 1)",
        table_label="paper: L_critic (ours)",
    )
)
