"""Rollout: run batched policies through the simulator for a fixed horizon.

A trajectory holds joint positions/velocities at ``T + 1`` instants and the ``T`` actions between
them, for all ``W`` worlds at once. With ``differentiable=True`` the states are torch functions of
the actions and the initial state (through :mod:`warp_critic.physics.bridge`); otherwise they are data.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import torch

from warp_critic.core.errors import DivergenceError

if TYPE_CHECKING:  # a type only: importing the simulator loads Newton (seconds), which a
    # module that merely names a Trajectory (the command line's method configs) does not need
    from warp_critic.physics.simulator import Simulator

PolicyFn = Callable[[torch.Tensor, torch.Tensor], torch.Tensor]  # (q, qd) -> tau, all (W, dof)

# rad or m, rad/s or m/s: a guarded rollout counts a world whose state leaves this bound in any
# joint as diverged, as a non-finite one (an arm swinging at 10^4 rad/s has left the model's range)
DIVERGED = 1e4


@dataclass
class Trajectory:
    q: torch.Tensor  # (T+1, W, dof) rad or m
    qd: torch.Tensor  # (T+1, W, dof) rad/s or m/s
    tau: torch.Tensor  # (T, W, dof) N·m or N
    # (W, K): each world's dynamics relative to the nominal model (Simulator.dynamics), data; for
    # critics told the model (``pose-dynamics``)
    dynamics: torch.Tensor | None = None

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
    guard: bool = False,
) -> Trajectory:
    """Roll ``policy`` out for ``horizon`` control steps from ``(q0, qd0)`` in every world.

    With ``differentiable=False`` the simulator runs forward only (no tape) and the actions are
    detached data. With ``differentiable=True`` gradients flow from the states back into the actions,
    the policy parameters and the initial state. ``check``: raise :class:`DivergenceError` on a
    non-finite state (``False``: leave it in the trajectory, for a caller that marks such worlds;
    the worlds are independent, so the others are unaffected).

    ``guard`` (with ``differentiable=True`` and ``check=False``): a world that diverges (not
    :func:`settled_worlds`) gets exactly zero gradient, so that a backward pass through the rollout
    stays finite in every other world. The policy sees its states clamped to finite values, and the
    gradient rows of its states and actions are zeroed on the way back (a diverged state's Jacobian
    is non-finite, and ``0 * nan`` is ``nan``). The settled worlds' values and gradients are those of
    the unguarded rollout, bitwise.
    """
    qs, qds, taus = [q0], [qd0], []
    q, qd = q0, qd0
    if differentiable:
        diverged = torch.zeros(q0.shape[0], dtype=torch.bool, device=q0.device)  # set below

        def zero_diverged(g: torch.Tensor | None) -> torch.Tensor | None:
            return None if g is None else g.masked_fill(diverged.unsqueeze(-1), 0.0)

        seen = _finite if guard else (lambda x: x)
        with sim.begin_rollout() as ro:
            for _ in range(horizon):
                tau = policy(seen(q), seen(qd))
                q, qd = ro.step(q, qd, tau)
                if guard:
                    for x in (tau, q, qd):
                        if x.requires_grad:
                            x.register_hook(zero_diverged)
                qs.append(q)
                qds.append(qd)
                taus.append(tau)
        if guard:  # the hooks run in the backward pass, after this
            with torch.no_grad():
                diverged |= ~_settled(torch.stack(qs), torch.stack(qds))
    else:
        with torch.no_grad():
            for _ in range(horizon):
                tau = policy(q, qd)
                q, qd = sim.step(q, qd, tau)
                qs.append(q)
                qds.append(qd)
                taus.append(tau)
    describe = getattr(sim, "dynamics", None)  # a stand-in simulator may not describe its worlds
    traj = Trajectory(
        torch.stack(qs), torch.stack(qds), torch.stack(taus), describe() if describe else None
    )
    if check:
        check_finite(traj)
    return traj


def _finite(x: torch.Tensor) -> torch.Tensor:
    """``x`` with non-finite entries and entries beyond :data:`DIVERGED` clamped into the bound
    (the identity, value and gradient, on every other entry)."""
    return torch.nan_to_num(x, nan=0.0, posinf=DIVERGED, neginf=-DIVERGED).clamp(
        -DIVERGED, DIVERGED
    )


def _settled(q: torch.Tensor, qd: torch.Tensor) -> torch.Tensor:
    x = torch.cat([q, qd], dim=-1)  # (T+1, W, 2*dof)
    return (torch.isfinite(x) & (x.abs() <= DIVERGED)).all(-1).all(0)


def settled_worlds(traj: Trajectory) -> torch.Tensor:
    """``(W,)`` bool: the worlds whose states stayed finite and within :data:`DIVERGED` throughout."""
    return _settled(traj.q.detach(), traj.qd.detach())


def hold_diverged(traj: Trajectory, settled: torch.Tensor) -> Trajectory:
    """``traj`` (data) with each world not ``settled (W,)`` replaced by its start state (clamped
    finite) held still under zero torque: finite inputs for a critic, whose gradient for such a world
    is then unused."""
    if bool(settled.all()):
        return traj
    keep = settled.view(1, -1, 1)
    return Trajectory(
        torch.where(keep, traj.q, _finite(traj.q[:1])),
        torch.where(keep, traj.qd, _finite(traj.qd[:1])),
        torch.where(keep, traj.tau, torch.zeros_like(traj.tau)),
        traj.dynamics,
    )


def finite_worlds(traj: Trajectory) -> torch.Tensor:
    """``(W,)`` bool: the worlds whose states stayed finite over the whole trajectory."""
    return (torch.isfinite(traj.q).all(-1) & torch.isfinite(traj.qd).all(-1)).all(0)
