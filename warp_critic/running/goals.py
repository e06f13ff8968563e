"""New goals around the training goals (the paper's Table 1 sampling), clipped inside the joint
limits; meta-test (:mod:`warp_critic.running.metatest_setup`) samples its goals with it."""

from __future__ import annotations

import torch

from warp_critic.core.errors import FieldError
from warp_critic.running.task_inputs import inside_limits

#: the two readings of the paper's "at a distance of N(0, std)" (see :func:`sample_goals`)
GOAL_NOISE: tuple[str, ...] = ("per-joint", "distance")


def sample_goals(
    train_goals: torch.Tensor,
    num: int,
    std: float,
    around: list[int] | None,
    lower: torch.Tensor,
    upper: torch.Tensor,
    gen: torch.Generator,
    noise: str = "per-joint",
) -> torch.Tensor:
    """``num`` goals around training goals (cycled), clipped into the middle 98% of the limits.

    The paper (Table 1) samples new goals "at a distance of N(0, std)" around the training goals,
    which reads two ways: ``per-joint`` (default) draws ``N(g_i, std^2 I)``, so a 7-dof goal moves by
    ``std * sqrt(7)`` on average; ``distance`` moves it by ``d ~ N(0, std^2)`` along a uniformly random
    direction, so the expected squared offset is ``std^2`` whatever the number of joints.
    """
    if noise not in GOAL_NOISE:
        raise FieldError("goal_noise", f"must be one of {', '.join(GOAL_NOISE)} (got {noise!r})")
    idx = around if around else list(range(train_goals.shape[0]))
    for i in idx:
        if not 0 <= i < train_goals.shape[0]:
            raise FieldError("around", f"{i}: the run has {train_goals.shape[0]} training goals")
    centres = train_goals[[idx[k % len(idx)] for k in range(num)]]
    offset = torch.randn(num, train_goals.shape[1], generator=gen)
    if noise == "per-joint":
        offset = offset * std
    else:
        offset = (
            offset / offset.norm(dim=1, keepdim=True) * (torch.randn(num, 1, generator=gen) * std)
        )
    lo, hi = inside_limits(lower, upper, 0.98)
    return torch.clamp(centres + offset, lo, hi)
