"""Critic loaders for meta-test: a run's method -> the loss a fresh policy descends, and the run's
meta-test defaults (its learning rate and number of policy steps).

A loader takes ``(checkpoint, normaliser)`` and returns ``(L, defaults)`` with ``L(q, qd, tau, g)``
and ``defaults = {"alpha": ..., "steps": ...}``; :func:`build_test_critic` picks the run's.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable

import torch

from warp_critic.core.errors import UserError
from warp_critic.learning.critic import Critic
from warp_critic.learning.networks import Normalizer


def load_our_critic(ckpt: dict, norm: Normalizer) -> tuple[torch.nn.Module, dict]:
    """Our meta-learned critic; meta-test defaults: its inner lr, inner steps x policy lifetime."""
    cfg = ckpt["config"]
    critic: torch.nn.Module = Critic(
        ckpt["dof"],
        norm,
        hidden=ckpt.get("critic_hidden", 400),
        inputs=ckpt.get("critic_input", "full"),
    )
    critic.load_state_dict(ckpt["critic_state"])
    from warp_critic.learning.identify import IdentifiedCritic, identifier_from_checkpoint

    identifier = identifier_from_checkpoint(ckpt)
    if identifier is not None:  # a told critic fed the model identified from its rollouts
        critic = IdentifiedCritic(critic, identifier)
    # a critic trained on policies of every age up to the policy lifetime keeps improving them that long
    steps = int(cfg.get("inner_steps", 1)) * int(cfg.get("policy_lifetime", 1))
    return critic, {"alpha": cfg.get("alpha"), "steps": steps}


# Registry by name ("module:function"), so meta-test imports no method's code until a run of that
# method is tested. A loader takes ``(checkpoint, normaliser)`` and returns ``(L, defaults)`` with
# ``L(q, qd, tau, g)`` and ``defaults = {"alpha": ..., "steps": ...}``.
CRITIC_LOADERS: dict[str, str | Callable] = {
    "ours": load_our_critic,
    "ddpg": "warp_critic.methods.q_networks:test_critic_from_checkpoint",
    "meta-critic": "warp_critic.methods.q_networks:test_critic_from_checkpoint",
}


def register_critic_loader(method: str, loader: str | Callable) -> None:
    """Make ``meta-test`` understand run directories of another method."""
    CRITIC_LOADERS[method] = loader


def build_test_critic(ckpt: dict, norm: Normalizer) -> tuple[torch.nn.Module, dict]:
    """The loss ``L(q, qd, tau, g)`` a fresh policy descends and the run's defaults, for any method."""
    method = ckpt.get("method", "ours")
    loader = CRITIC_LOADERS.get(method)
    if loader is None:
        raise UserError(
            f"checkpoint of method {method!r}: meta-test knows {', '.join(CRITIC_LOADERS)}"
        )
    if isinstance(loader, str):
        module, name = loader.split(":")
        loader = getattr(importlib.import_module(module), name)
    try:
        return loader(ckpt, norm)
    except (KeyError, RuntimeError, TypeError, ValueError) as e:
        if isinstance(e, UserError):
            raise
        raise UserError(
            f"{method} checkpoint has no usable critic ({type(e).__name__}: "
            f"{str(e).splitlines()[0] if str(e) else ''})"
        ) from None
