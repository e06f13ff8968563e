"""``S`` critics of one architecture (one per seed) as one module, and one seed's slice of them.

Batched seeds (``--seeds``) train their critics at once: :class:`StackedCritic` evaluates them with
one batched matmul per layer, and one Adam over its stacked parameters is exactly one Adam per
critic. A seed's slice is read and written by :func:`slice_norm` and :func:`clip_slice_` (its
gradient) and :func:`optimizer_slice` / :func:`load_optimizer_slice` (its Adam state), so each seed
clips, saves and resumes as a single-seed run does.
"""

from __future__ import annotations

import math

import torch
from torch import nn

from warp_critic.learning.critic import Critic
from warp_critic.learning.critic_inputs import RolloutData


def _linear(module: nn.Module) -> nn.Linear:
    if not isinstance(module, nn.Linear):
        raise TypeError(f"expected a Linear layer, got {type(module).__name__}")
    return module


class StackedCritic(nn.Module):
    """``S`` critics of one architecture (one per seed) evaluated as one module.

    The worlds axis (``-2`` of every input) is seed-major: worlds ``s*W .. (s+1)*W - 1`` belong to critic
    ``s``. Each layer is one batched matmul over the seeds, so ``S`` critics cost about one critic's
    overhead; their parameters are stacked ``(S, ...)`` tensors, and an optimiser over them that acts
    elementwise (Adam) is exactly ``S`` independent optimisers. :meth:`critic_state` /
    :meth:`load_critic_state` convert to and from ordinary :class:`Critic` state dicts.
    """

    _LAYERS = (0, 2, 4)  # indices of the Linear layers in Critic.net

    def __init__(self, critics: list[Critic]):
        super().__init__()
        first = critics[0]
        self.template: list[Critic] = [
            first
        ]  # a list: not a registered submodule (its parameters are not ours)
        self.seeds = len(critics)
        self.weights = nn.ParameterList()
        self.biases = nn.ParameterList()
        for i in self._LAYERS:
            layers = [_linear(c.net[i]) for c in critics]
            self.weights.append(nn.Parameter(torch.stack([x.weight.detach() for x in layers])))
            self.biases.append(nn.Parameter(torch.stack([x.bias.detach() for x in layers])))

    @property
    def rollout_data(self) -> tuple[RolloutData, ...]:
        """:attr:`Critic.rollout_data` (one layout for every seed)."""
        return self.template[0].rollout_data

    def torque_metric(self, q: torch.Tensor) -> torch.Tensor | None:
        """:meth:`Critic.torque_metric` (one scene for every seed)."""
        return self.template[0].torque_metric(q)

    def forward(
        self,
        q: torch.Tensor,
        qd: torch.Tensor,
        tau: torch.Tensor,
        goal: torch.Tensor,
        **data: torch.Tensor | None,
    ) -> torch.Tensor:
        """All ``(..., S*W, dof)`` (``data``: the rollout data, as for :meth:`Critic.features`) ->
        ``(..., S*W)``."""
        x = self.template[0].features(q, qd, tau, goal, **data)  # (..., S*W, n_in)
        lead, sw, n_in = x.shape[:-2], x.shape[-2], x.shape[-1]
        S = self.seeds
        x = x.reshape(-1, S, sw // S, n_in).permute(1, 0, 2, 3).reshape(S, -1, n_in)  # (S, M, n_in)
        for k, (w, b) in enumerate(zip(self.weights, self.biases)):
            x = torch.baddbmm(b.unsqueeze(1), x, w.transpose(1, 2))
            if k < len(self.weights) - 1:
                x = torch.nn.functional.elu(x)
        x = x.reshape(S, -1, sw // S).permute(1, 0, 2).reshape(*lead, sw)
        return x

    def critic_state(self, s: int) -> dict:
        """Critic ``s`` as an ordinary :class:`Critic` state dict."""
        state = {k: v.clone() for k, v in self.template[0].state_dict().items()}
        for i, w, b in zip(self._LAYERS, self.weights, self.biases):
            state[f"net.{i}.weight"] = w[s].detach().clone()
            state[f"net.{i}.bias"] = b[s].detach().clone()
        return state

    def load_critic_state(self, s: int, state: dict) -> None:
        with torch.no_grad():
            for i, w, b in zip(self._LAYERS, self.weights, self.biases):
                w[s].copy_(state[f"net.{i}.weight"])
                b[s].copy_(state[f"net.{i}.bias"])

    def critic(self, s: int) -> Critic:
        c = self.template[0]
        out = Critic(c.dof, c.norm, hidden=c.hidden, inputs=c.inputs).to(c.q_centre.device)
        out.load_state_dict(self.critic_state(s))
        return out

    def ordered(self) -> list[nn.Parameter]:
        """The stacked parameters in :meth:`Critic.parameters` order."""
        return [t for w, b in zip(self.weights, self.biases) for t in (w, b)]


# ------------------------------------------------------------------------------------------------
# one seed's slice: gradient norm, clipping, optimiser state
# ------------------------------------------------------------------------------------------------


def slice_norm(critic: StackedCritic, i: int) -> float:
    """The gradient norm of critic ``i``: ``sqrt(sum of its squared gradients)``."""
    total = 0.0
    for p in critic.ordered():
        if p.grad is not None:
            total += float(p.grad[i].detach().pow(2).sum())
    return math.sqrt(total)


def clip_slice_(critic: StackedCritic, i: int, max_norm: float) -> None:
    """``torch.nn.utils.clip_grad_norm_`` on critic ``i``'s gradient alone."""
    grads = [p.grad[i] for p in critic.ordered() if p.grad is not None]
    total = torch.linalg.vector_norm(torch.stack([torch.linalg.vector_norm(g) for g in grads]))
    coef = torch.clamp(max_norm / (total + 1e-6), max=1.0)
    for g in grads:
        g.mul_(coef)


def optimizer_slice(opt: torch.optim.Optimizer, critic: StackedCritic, i: int) -> dict:
    """Critic ``i``'s Adam state as the state dict of an Adam over one :class:`Critic`."""
    full = opt.state_dict()
    state = {
        k: {
            name: (v[i].clone() if torch.is_tensor(v) and v.dim() > 0 else v)
            for name, v in st.items()
        }
        for k, st in full["state"].items()
    }
    return {"state": state, "param_groups": full["param_groups"]}


def load_optimizer_slice(
    opt: torch.optim.Optimizer, critic: StackedCritic, i: int, single: dict
) -> None:
    """Inverse of :func:`optimizer_slice`: put one critic's Adam state into slice ``i``."""
    params = critic.ordered()
    for k, st in single["state"].items():
        p = params[int(k)]
        mine = opt.state[p]
        for name, v in st.items():
            if torch.is_tensor(v) and v.dim() > 0:
                if name not in mine:
                    mine[name] = torch.zeros_like(p)
                mine[name][i].copy_(v)
            else:
                mine[name] = v.clone() if torch.is_tensor(v) else v
    for group, saved in zip(opt.param_groups, single["param_groups"]):
        for key, value in saved.items():
            if key != "params":
                group[key] = value
