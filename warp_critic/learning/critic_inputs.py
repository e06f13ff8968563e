"""The critic's input layouts: one small class each, and the one registry of them.

A layout (:class:`CriticInput`) is what the critic ``L_critic(s, a, g)`` sees of a state, an action
and a goal: its name (the ``critic_input`` setting, :data:`CRITIC_INPUTS`), its width for a robot
(:meth:`CriticInput.width`: the robot's DoF and, for a layout told the model, the length ``K`` of its
dynamics descriptor), the normalised features it computes (:meth:`CriticInput.features`, with the
scene's fixed :class:`~warp_critic.learning.networks.Normalizer`), and the rollout data it reads
beside ``(s, a, g)`` (:attr:`CriticInput.rollout_data`: :data:`HISTORY`, :data:`DYNAMICS`). The
critic (:class:`~warp_critic.learning.critic.Critic`) builds its first layer and its input from its
layout; the losses hand a critic the rollout data it names (:func:`rollout_data_of`); the scene
format knows the names only (:mod:`warp_critic.core.critic_input_names`, checked against this
registry on import). A new layout is a class here and its name there.

Normalisation (:class:`~warp_critic.learning.networks.Normalizer`): joint positions, goals and
their differences by the joint limits (continuous joints wrapped), velocities by ``qd_scale``,
torques by ``max_torque``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import torch

from warp_critic.core.critic_input_names import CRITIC_INPUT_NAMES
from warp_critic.learning.networks import Normalizer

if TYPE_CHECKING:
    from warp_critic.learning.rollout import Trajectory

Data = Mapping[str, torch.Tensor | None]


# ------------------------------------------------------------------------------------------------
# rollout data a critic may read beside (s, a, g), passed to it by keyword
# ------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RolloutData:
    """One kind of data a critic reads from a trajectory beside ``(s, a, g)``: passed to the critic
    as the keyword ``key``, computed from the trajectory by ``of``."""

    key: str
    of: Callable[[Trajectory], torch.Tensor]
    doc: str


def history_features(qd: torch.Tensor, tau: torch.Tensor) -> torch.Tensor:
    """``(T, W, 2*dof)``: at each step ``t`` of a trajectory, ``[qd_t - qd_{t-1}, tau_{t-1}]``
    (zeros at ``t = 0``), detached. ``qd``: ``(T+1, W, dof)`` or ``(T, W, dof)``; ``tau``:
    ``(T, W, dof)``, the applied torques."""
    qd, tau = qd[: tau.shape[0]].detach(), tau.detach()
    dqd = torch.cat([torch.zeros_like(qd[:1]), qd[1:] - qd[:-1]])
    prev = torch.cat([torch.zeros_like(tau[:1]), tau[:-1]])
    return torch.cat([dqd, prev], dim=-1)


def _told_dynamics(traj: Trajectory) -> torch.Tensor:
    if traj.dynamics is None:
        raise ValueError("this critic reads the worlds' dynamics; the trajectory carries none")
    return traj.dynamics  # (W, K), the same at every step


HISTORY = RolloutData(
    "history",
    lambda traj: history_features(traj.qd, traj.tau),
    "(T, W, 2*dof): the last control step's velocity change and torque (observed, data)",
)
DYNAMICS = RolloutData(
    "dynamics",
    _told_dynamics,
    "(W, K): each world's dynamics descriptor (told: privileged data)",
)


def rollout_data_of(critic: object) -> tuple[RolloutData, ...]:
    """The rollout data ``critic`` reads (its ``rollout_data``; none for a plain callable)."""
    return tuple(getattr(critic, "rollout_data", ()))


def rollout_kwargs(critic: object, traj: Trajectory) -> dict[str, torch.Tensor]:
    """The keywords to call ``critic`` with on ``traj``'s steps: the rollout data it reads."""
    return {d.key: d.of(traj) for d in rollout_data_of(critic)}


# ------------------------------------------------------------------------------------------------
# the layouts
# ------------------------------------------------------------------------------------------------


class CriticInput(ABC):
    """One input layout of the critic (module docstring). Subclasses set the class attributes and
    :meth:`parts`; the features are the parts concatenated along the last dim."""

    name: str = ""
    help: str = ""  # one phrase for the ``--critic-input`` help: what the critic sees
    per_dof: int = 0  # features per joint (the told dynamics come on top)
    rollout_data: tuple[RolloutData, ...] = ()
    needs_inertia: bool = False  # reads the nominal model's M(q) (Normalizer.inertia)

    @property
    def told(self) -> bool:
        """Whether the layout reads each world's model (:data:`DYNAMICS`, privileged)."""
        return DYNAMICS in self.rollout_data

    def width(self, dof: int, dynamics_size: int = 0) -> int:
        """The critic's input width for a robot of ``dof`` joints (``dynamics_size``: ``K``)."""
        return self.per_dof * dof + (dynamics_size if self.told else 0)

    def check(self, norm: Normalizer) -> None:
        """Raise ``ValueError`` where ``norm`` lacks what the layout reads."""
        if self.needs_inertia and norm.inertia is None:
            raise ValueError(
                f"an {self.name} critic needs the scene's nominal inertia (norm.inertia)"
            )
        if self.told and norm.dynamics_size <= 0:
            raise ValueError(
                f"a {self.name} critic needs the worlds' descriptor size (norm.dynamics_size)"
            )

    @abstractmethod
    def parts(
        self,
        norm: Normalizer,
        q: torch.Tensor,
        qd: torch.Tensor,
        tau: torch.Tensor,
        goal: torch.Tensor,
        data: Data,
    ) -> list[torch.Tensor]:
        """The feature blocks ``(..., n_i)`` the layout concatenates (normalised)."""

    def features(
        self,
        norm: Normalizer,
        q: torch.Tensor,
        qd: torch.Tensor,
        tau: torch.Tensor,
        goal: torch.Tensor,
        data: Data,
    ) -> torch.Tensor:
        """The normalised input ``(..., width)``: ``q, qd, tau, goal`` ``(..., dof)``; ``data``:
        the rollout data by key (``history`` ``(..., 2*dof)``, ``dynamics`` ``(..., K)``)."""
        return torch.cat(self.parts(norm, q, qd, tau, goal, data), dim=-1)

    def torque_metric(self, norm: Normalizer, q: torch.Tensor) -> torch.Tensor | None:
        """The metric ``P(q) (..., dof, dof)`` the inner update steps torques in, or ``None``: the
        identity, the paper's plain gradient."""
        return None


class Full(CriticInput):
    """``[q, qd, a, g, q - g]``: everything. The goal-relative position ``q - g`` is a fixed feature
    of ``(s, g)`` that adds no information but makes goal generalisation easier to learn."""

    name, per_dof = "full", 5
    help = "[q, qd, a, g, q-g]"

    def parts(self, norm, q, qd, tau, goal, data):
        return [norm.q(q), qd / norm.qd_scale, norm.action(tau), norm.q(goal), norm.dq(q, goal)]


class Relative(CriticInput):
    """``[q - g, qd, a]``: the state seen from the goal. The critic is then equivariant to shifting
    the goal and the state together, so it cannot memorise the few training goals and has to describe
    how to move towards *a* goal. It suits robots whose dynamics change little with ``q`` over the
    goal region, e.g. a gravity-compensated arm. On its own it generalises on the KUKA about as well
    as ``full``; with random start states (``--start-std``), which it reads as goal offsets, it
    reaches the paper's Table 1 (RESULTS.md has the measurements)."""

    name, per_dof = "relative", 3
    help = "[q-g, qd, a] (goal-equivariant)"

    def parts(self, norm, q, qd, tau, goal, data):
        return [norm.dq(q, goal), qd / norm.qd_scale, norm.action(tau)]


class History(Relative):
    """``[q - g, qd, a, qd_t - qd_{t-1}, a_{t-1}]``: ``relative`` plus the last control step's
    response, the torque applied there and the velocity change it produced (zeros at the first step),
    observed data like the states. Under ``qd_t - qd_{t-1} ~ dt M^-1 (a_{t-1} - bias)`` the pair tells
    the critic about the inertia it acts on, so one critic can tell models apart (for
    dynamics-randomised training); :func:`history_features` builds it from a trajectory."""

    name, per_dof = "history", 5
    help = (
        "relative + the last step's velocity change and torque (tells models apart, for "
        "--train-variants)"
    )
    rollout_data = (HISTORY,)

    def parts(self, norm, q, qd, tau, goal, data):
        history = data.get("history")
        if history is None:
            raise ValueError("a history critic needs history (history_features)")
        dqd, tau_prev = history.split(q.shape[-1], dim=-1)
        return [
            *super().parts(norm, q, qd, tau, goal, data),
            dqd / norm.qd_scale,
            norm.action(tau_prev),
        ]


class Pose(Relative):
    """``[q - g, qd, a, q]``: ``relative`` plus the arm's own configuration. The goal still enters
    through ``q - g`` only, but the critic sees the joint angles the dynamics depend on: an arm's
    inertia ``M(q)`` changes with every joint but the first (the reacher's elbow), which a
    ``relative`` critic cannot see, so it applies near far goals the field it learned near the
    training goals (RESULTS.md, "Why the far goals miss")."""

    name, per_dof = "pose", 4
    help = "relative + the joint angles q"

    def parts(self, norm, q, qd, tau, goal, data):
        return [*super().parts(norm, q, qd, tau, goal, data), norm.q(q)]


class PoseTrig(Relative):
    """``[q - g, qd, a, sin q, cos q]``: ``pose`` with the joint angles encoded by their sine and
    cosine. A rigid arm's inertia and gravity terms are sums of products of ``sin q_i`` and
    ``cos q_i``, so the critic sees the pose in the coordinates its dynamics are simple in (the
    reacher's ``M(q)`` is affine in ``cos q2``). ``q - g`` stays an angle difference: the joint
    limits let it exceed ``pi``, where its sine and cosine would alias."""

    name, per_dof = "pose-trig", 5
    help = "relative + sin q and cos q"

    def parts(self, norm, q, qd, tau, goal, data):
        return [*super().parts(norm, q, qd, tau, goal, data), torch.sin(q), torch.cos(q)]


class Inertial(Relative):
    """``[q - g, qd, M(q_h) M(q)^-1 a]``: ``relative`` with the torque seen as the torque that gives
    the same joint acceleration at the home pose ``q_h`` (``M``: the nominal model's inertia,
    :class:`~warp_critic.physics.inertia.NominalInertia`, evaluated as data). Its inner update steps
    the torques in the metric ``P(q) = M(q) M(q_h)^-2 M(q)`` (:meth:`torque_metric`), so that one
    critic gradient changes the joint acceleration by the same amount in every pose: ``M(q)^-1 P(q)
    d/dtau = M(q_h)^-1 d/dx`` with ``x`` the home-equivalent torque. Where the dynamics depend on the
    pose only through ``M(q)`` (the reacher: its joint axes are parallel to gravity), the inner loop
    is then the same at every goal and a field learned near the training goals holds at all of them.
    At the home pose it is the ``relative`` critic with the paper's update."""

    name, per_dof = "inertial", 3
    help = (
        "relative with the torque in home-pose acceleration units, M(q_h) M(q)^-1 a, and inner "
        "steps in that metric"
    )
    needs_inertia = True

    def parts(self, norm, q, qd, tau, goal, data):
        assert norm.inertia is not None  # check()
        acc = torch.linalg.solve(norm.inertia(q), tau.unsqueeze(-1))
        home_equivalent = (norm.inertia.home() @ acc).squeeze(-1)
        return super().parts(norm, q, qd, home_equivalent, goal, data)

    def torque_metric(self, norm, q):
        """``M(q) M(q_h)^-2 M(q)`` at the states ``q (..., dof)`` (data)."""
        assert norm.inertia is not None  # check()
        M = norm.inertia(q)
        left = torch.linalg.solve(norm.inertia.home(), M)  # M(q_h)^-1 M(q)
        return left.transpose(-1, -2) @ left


def _told(layout: CriticInput, q: torch.Tensor, data: Data, K: int) -> torch.Tensor:
    """The worlds' descriptors ``(..., K)`` for a told layout, broadcast over ``q``'s steps."""
    dynamics = data.get("dynamics")
    if dynamics is None or dynamics.shape[-1] != K:
        raise ValueError(f"a {layout.name} critic needs the worlds' dynamics (..., {K})")
    return dynamics.expand(*q.shape[:-1], -1)


class PoseDynamics(Pose):
    """``[q - g, qd, a, q, d]``: ``pose`` plus the world's dynamics ``d (K,)`` relative to the
    scene's nominal model (:class:`~warp_critic.physics.descriptor.DynamicsDescriptor`: masses,
    centres of mass, inertias, joint offsets). Privileged: the critic is told the model instead of
    identifying it, at training and at meta-test alike (the trajectory carries ``d``,
    :attr:`~warp_critic.learning.rollout.Trajectory.dynamics`). It measures how far identifying the
    model alone takes one critic across dynamics-randomised training's range."""

    name = "pose-dynamics"
    help = (
        "pose + each world's masses, inertias and link offsets relative to the nominal model "
        "(privileged: the critic is told the model, at meta-test too)"
    )
    rollout_data = (DYNAMICS,)

    def parts(self, norm, q, qd, tau, goal, data):
        told = _told(self, q, data, norm.dynamics_size)
        return [*super().parts(norm, q, qd, tau, goal, data), told]


class RelativeDynamics(Relative):
    """``[q - g, qd, a, d]``: ``pose-dynamics``'s told model for the ``relative`` layout (the
    KUKA's)."""

    name = "relative-dynamics"
    help = "relative + the same"
    rollout_data = (DYNAMICS,)

    def parts(self, norm, q, qd, tau, goal, data):
        told = _told(self, q, data, norm.dynamics_size)
        return [*super().parts(norm, q, qd, tau, goal, data), told]


#: every layout by name, in the order of :data:`~warp_critic.core.critic_input_names.CRITIC_INPUT_NAMES`
CRITIC_INPUTS: dict[str, CriticInput] = {
    layout.name: layout
    for layout in (
        Full(),
        Relative(),
        History(),
        Pose(),
        PoseTrig(),
        Inertial(),
        PoseDynamics(),
        RelativeDynamics(),
    )
}
if tuple(CRITIC_INPUTS) != CRITIC_INPUT_NAMES:  # the names the lower layers know
    raise ImportError(
        f"critic input layouts {tuple(CRITIC_INPUTS)} differ from the names the scene format "
        f"knows {CRITIC_INPUT_NAMES} (warp_critic.core.critic_input_names)"
    )

#: the layouts told each world's model (privileged: ``warp-critic identify`` estimates it instead)
TOLD_INPUTS: tuple[str, ...] = tuple(n for n, layout in CRITIC_INPUTS.items() if layout.told)


def critic_input(name: str) -> CriticInput:
    """The layout called ``name`` (``ValueError`` for an unknown one)."""
    if name not in CRITIC_INPUTS:
        raise ValueError(f"critic inputs must be one of {CRITIC_INPUT_NAMES} (got {name!r})")
    return CRITIC_INPUTS[name]


def critic_input_help() -> str:
    """``name = what it sees; ...`` for every layout, in registry order (the flag's help)."""
    return "; ".join(f"{name} = {layout.help}" for name, layout in CRITIC_INPUTS.items())


__all__ = [
    "CRITIC_INPUTS",
    "DYNAMICS",
    "HISTORY",
    "TOLD_INPUTS",
    "CriticInput",
    "RolloutData",
    "critic_input",
    "critic_input_help",
    "history_features",
    "rollout_data_of",
    "rollout_kwargs",
]
