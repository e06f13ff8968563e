"""The names of the critic's input layouts: the one list that the layers below ``learning/`` know.

A scene may name its critic's layout (:mod:`warp_critic.physics.schema` checks the name), and
:mod:`warp_critic.learning.critic_inputs` registers one class per name: its width, its features and
the rollout data it reads. That module checks on import that it has a class for exactly these
names, in this order (the order of the ``--critic-input`` help and of the scene format's rule).
A new layout is its class there and its name here.
"""

from __future__ import annotations

__all__ = ["CRITIC_INPUT_NAMES"]

CRITIC_INPUT_NAMES: tuple[str, ...] = (
    "full",
    "relative",
    "history",
    "pose",
    "pose-trig",
    "inertial",
    "pose-dynamics",
    "relative-dynamics",
)
