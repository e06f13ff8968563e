"""The task's tensors from its config and scene (goals, torque bounds, interior joint ranges) and the
memory check of its worlds."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Protocol

import torch

from warp_critic.core.errors import FieldError
from warp_critic.core.memory import check_fits

if TYPE_CHECKING:
    from warp_critic.physics.scene import Scene


class TaskSize(Protocol):
    """What :func:`check_memory` reads of a run's config (a ``TaskConfig``; this module sits below
    ``running.task``, which imports it)."""

    @property
    def goals(self) -> Sequence | None: ...
    @property
    def horizon(self) -> int | None: ...
    @property
    def substeps(self) -> int | None: ...
    @property
    def worlds_per_goal(self) -> int: ...


__all__ = ["check_memory", "estimate_memory", "goals_tensor", "inside_limits", "max_torque_tensor"]


def goals_tensor(goals, scene: Scene, device="cpu", name: str = "goals") -> torch.Tensor:
    """Validate goals against the scene (shape, finiteness, joint limits) -> ``(G, dof)`` rad."""
    try:
        g = torch.tensor(goals, dtype=torch.float32)
    except (TypeError, ValueError):
        raise FieldError(
            name, "expected a list of goals, each a list of numbers (rows of equal length)"
        ) from None
    if g.ndim != 2 or g.shape[0] == 0 or g.shape[1] != scene.dof:
        got = list(g.shape)[-1] if g.ndim == 2 else list(g.shape)
        raise FieldError(
            name, f"each goal needs {scene.dof} joint values for {scene.name} (got {got})"
        )
    if not bool(torch.isfinite(g).all()):
        raise FieldError(name, "goals must be finite numbers")
    lo = torch.as_tensor(scene.q_lower, dtype=torch.float32)
    hi = torch.as_tensor(scene.q_upper, dtype=torch.float32)
    outside = (g < lo) | (g > hi)
    if bool(outside.any()):
        i, j = (int(x) for x in torch.nonzero(outside)[0])
        raise FieldError(
            name,
            f"goal {i} joint {j} = {g[i, j]:.3f} is outside the joint limits "
            f"[{lo[j]:.3f}, {hi[j]:.3f}] of {scene.name}",
        )
    return g.to(device)


def inside_limits(lower, upper, fraction: float):
    """The bounds of the middle ``fraction`` of each joint's range ``[lower, upper]``:
    ``mid -/+ fraction * half``, inside the limits whatever their signs (for limits symmetric about 0
    exactly ``fraction * lower`` and ``fraction * upper``)."""
    mid, half = (upper + lower) / 2, (upper - lower) / 2
    return mid - fraction * half, mid + fraction * half


def max_torque_tensor(max_torque: list[float], scene: Scene, device="cpu") -> torch.Tensor:
    """Per-joint torque bound ``(dof,)``; a bound above a joint's effort limit is refused (the
    policy could not apply it, and the run would record a number it did not use)."""
    t = torch.tensor(max_torque, dtype=torch.float32)
    if t.numel() == 1:
        t = t.expand(scene.dof).clone()
    if t.numel() != scene.dof:
        raise FieldError(
            "max_torque", f"needs 1 or {scene.dof} values for {scene.name} (got {t.numel()})"
        )
    limit = torch.as_tensor(scene.effort_limit, dtype=torch.float32)
    over = torch.nonzero(t > limit).flatten()
    if over.numel():
        j = int(over[0])
        raise FieldError(
            "max_torque",
            f"{float(t[j]):g} N·m for joint {j} is above its effort limit {float(limit[j]):g} N·m "
            f"in {scene.name} (give at most the effort limits)",
        )
    return torch.minimum(t, limit).to(device)


def estimate_memory(
    worlds: int, dof: int, horizon: int, substeps: int, graph_steps: int = 1
) -> int:
    """A coarse upper estimate (bytes) of a run's peak memory.

    Per world and physics step the differentiable model keeps its own state and Featherstone scratch
    (mass matrix, Jacobians; ~``(6 dof)^2`` floats) for the backward pass; per control step torch keeps
    the policy activations of every rollout in the graph (``graph_steps`` of them).
    """
    per_physics_step = 4 * (6 * dof) ** 2 + 4 * 64 * dof
    per_control_step = 4 * (3 * 64 + 8 * dof) * 4
    per_world = horizon * (substeps * per_physics_step + graph_steps * per_control_step)
    return int(worlds * per_world + 200 * 2**20)


def check_memory(cfg: TaskSize, dof: int, graph_steps: int = 1, copies: int = 1) -> None:
    """Refuse settings whose memory estimate cannot fit, with the estimate, before allocating."""
    horizon, substeps = cfg.horizon, cfg.substeps
    if not (isinstance(horizon, int) and isinstance(substeps, int)):
        return
    goals = (len(cfg.goals) if cfg.goals else 1) * copies
    need = estimate_memory(
        goals * cfg.worlds_per_goal,
        dof,
        horizon,
        substeps,
        max(graph_steps, getattr(cfg, "inner_steps", 1) + 1),
    )
    inner = getattr(cfg, "inner_steps", 1)
    culprit = max(
        (
            ("worlds_per_goal", cfg.worlds_per_goal / 64),
            ("horizon", horizon / 1000),
            ("substeps", substeps / 100),
            ("inner_steps", inner / 100),
        ),
        key=lambda kv: kv[1],
    )[0]
    check_fits(
        culprit,
        f"{goals} goals x {cfg.worlds_per_goal} worlds, horizon {cfg.horizon} x "
        f"{cfg.substeps} substeps, {inner} inner steps",
        need,
    )


# ------------------------------------------------------------------------------------------------
# the worlds
# ------------------------------------------------------------------------------------------------
