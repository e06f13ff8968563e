"""Rollout: run batched policies through the simulator for a fixed horizon.

A trajectory holds joint positions/velocities at ``T + 1`` instants and the ``T`` actions between
them, for all ``W`` worlds at once. With ``differentiable=True`` the states are torch functions of
the actions and the initial state (through :mod:`warp_critic.physics.bridge`); otherwise they are data.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch

from warp_critic.core.errors import DivergenceError
from warp_critic.physics.simulator import Simulator

PolicyFn = Callable[[torch.Tensor, torch.Tensor], torch.Tensor]  # (q, qd) -> tau, all (W, dof)


@dataclass
class Trajectory:
    q: torch.Tensor  # (T+1, W, dof) rad or m
    qd: torch.Tensor  # (T+1, W, dof) rad/s or m/s
    tau: torch.Tensor  # (T, W, dof) N·m or N

    @property
    def horizon(self) -> int:
        return self.tau.shape[0]

    def states(self) -> torch.Tensor:
        """``(T, W, 2*dof)``: the states at which the actions were taken."""
        return torch.cat([self.q[:-1], self.qd[:-1]], dim=-1)


def check_finite(traj: Trajectory, what: str = "rollout") -> None:
    """Raise :class:`DivergenceError` naming the first world and step with a non-finite state."""
    bad = ~(torch.isfinite(traj.q).all(-1) & torch.isfinite(traj.qd).all(-1))  # (T+1, W)
    if bool(bad.any()):
        steps, worlds = torch.nonzero(bad, as_tuple=True)
        first = int(torch.argmin(steps))
        step, world = int(steps[first]), int(worlds[first])
        raise DivergenceError(
            f"{what}: non-finite state in world {world} at step {step} "
            f"(unstable dynamics: lower dt, raise substeps or reduce the torque scale)",
            world=world,
            step=step,
        )


def rollout(
    sim: Simulator,
    policy: PolicyFn,
    q0: torch.Tensor,
    qd0: torch.Tensor,
    horizon: int,
    *,
    differentiable: bool = False,
    check: bool = True,
) -> Trajectory:
    """Roll ``policy`` out for ``horizon`` control steps from ``(q0, qd0)`` in every world.

    With ``differentiable=False`` the simulator runs forward only (no tape) and the actions are
    detached data. With ``differentiable=True`` gradients flow from the states back into the actions,
    the policy parameters and the initial state. ``check``: raise :class:`DivergenceError` on a
    non-finite state (``False``: leave it in the trajectory, for a caller that marks such worlds;
    the worlds are independent, so the others are unaffected).
    """
    qs, qds, taus = [q0], [qd0], []
    q, qd = q0, qd0
    if differentiable:
        with sim.begin_rollout() as ro:
            for _ in range(horizon):
                tau = policy(q, qd)
                q, qd = ro.step(q, qd, tau)
                qs.append(q)
                qds.append(qd)
                taus.append(tau)
    else:
        with torch.no_grad():
            for _ in range(horizon):
                tau = policy(q, qd)
                q, qd = sim.step(q, qd, tau)
                qs.append(q)
                qds.append(qd)
                taus.append(tau)
    traj = Trajectory(torch.stack(qs), torch.stack(qds), torch.stack(taus))
    if check:
        check_finite(traj)
    return traj


def finite_worlds(traj: Trajectory) -> torch.Tensor:
    """``(W,)`` bool: the worlds whose states stayed finite over the whole trajectory."""
    return (torch.isfinite(traj.q).all(-1) & torch.isfinite(traj.qd).all(-1)).all(0)
