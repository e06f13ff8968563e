"""Named settings behind the reported numbers (README.md, RESULTS.md).

:data:`PRESETS` maps a name to config values keyed by config **field names** (of
:class:`warp_critic.config.TrainConfig` for meta-training presets, of
:class:`warp_critic.methods.baseline.BaselineConfig` for the baselines); everything not named is the
scene default. :data:`DESCRIPTIONS` says in one line what each preset is and what it scored,
:data:`SCENES` which scene it was measured on (``None``: any scene).

:data:`EVALUATIONS` holds the meta-test protocol each preset's numbers were reported with, keyed by
:class:`warp_critic.evaluation.protocol.ProtocolConfig` field names.

Why these settings: three inner critic-gradient steps with a 3x smaller step reach a much lower error
than one step (one step from a random initialisation leaves an error floor set by the random
network's Jacobian: reacher 0.023 after 1000 iterations with one step vs 0.0076 after 400 with
three). KUKA: the goal-relative critic with random starts 0.4 rad around home covers goals far from
the four training goals, while two of the four worlds per goal keep starting at home (as at
meta-test), and 3000 iterations sharpen it near them (RESULTS.md, "KUKA against the paper's Table 1").
"""

from __future__ import annotations

import copy
from typing import Any

from warp_critic.core.errors import FieldError

PRESETS: dict[str, dict[str, Any]] = {
    # meta-training (TrainConfig fields)
    "reacher": {"iterations": 400, "inner_steps": 3, "alpha": 3e-4},
    "kuka-table1": {
        "critic_input": "relative",
        "start_std": 0.4,
        "home_starts": 2,
        "iterations": 3000,
        "inner_steps": 3,
        "alpha": 3e-4,
        "lr": 3e-3,
    },
    # baselines (BaselineConfig fields): the published DDPG / Meta-Critic settings, 300 iterations
    "ddpg": {"method": "ddpg", "iterations": 300},
    "meta-critic": {"method": "meta-critic", "iterations": 300},
}

DESCRIPTIONS: dict[str, str] = {
    "reacher": "reacher benchmark: 3 inner steps at alpha 3e-4, 400 iterations "
    "(meta-train 0.0083 rad^2, meta-test 0.033 summed at std 0.3)",
    "kuka-table1": "KUKA against the paper's Table 1: goal-relative critic, random starts 0.4 rad with 2 of 4 "
    "worlds per goal at home, 3 inner steps at alpha 3e-4, lr 3e-3, 3000 iterations "
    "(MSE 0.019 / 0.056 at std 0.1 / 0.4 per-joint)",
    "ddpg": "DDPG baseline: the published settings (BaselineConfig defaults), 300 iterations",
    "meta-critic": "Meta-Critic baseline: Zhou et al.'s settings (BaselineConfig defaults), 300 iterations",
}

#: The scene (file stem under ``scenes/``) each preset was measured on; ``None``: reported on several.
SCENES: dict[str, str | None] = {
    "reacher": "reacher",
    "kuka-table1": "kuka",
    "ddpg": None,
    "meta-critic": None,
}

#: The meta-test protocol each preset's numbers were reported with (ProtocolConfig fields).
EVALUATIONS: dict[str, dict[str, Any]] = {
    "reacher": {
        "stds": [0.3],
        "goal_noise": ["per-joint"],
        "around": None,
        "num_goals": 10,
        "inits": 5,
        "seed": 1,
    },
    "kuka-table1": {
        "stds": [0.1, 0.4],
        "goal_noise": ["per-joint", "distance"],
        "around": [0, 1],
        "num_goals": 10,
        "inits": 5,
        "seed": 1,
    },
    "ddpg": {
        "stds": [0.1, 0.3, 0.4],
        "goal_noise": ["per-joint"],
        "around": [0, 1],
        "num_goals": 10,
        "inits": 5,
        "seed": 1,
    },
    "meta-critic": {
        "stds": [0.1, 0.3, 0.4],
        "goal_noise": ["per-joint"],
        "around": [0, 1],
        "num_goals": 10,
        "inits": 5,
        "seed": 1,
    },
}


def _lookup(table: dict[str, dict[str, Any]], name: str) -> dict[str, Any]:
    if name not in table:
        raise FieldError("preset", f"unknown preset {name!r}; known: {', '.join(sorted(table))}")
    return copy.deepcopy(table[name])


def preset(name: str) -> dict[str, Any]:
    """A copy of preset ``name``'s settings (config field -> value); unknown names raise ``FieldError``."""
    return _lookup(PRESETS, name)


def evaluation(name: str) -> dict[str, Any]:
    """A copy of the meta-test protocol preset ``name`` was reported with (ProtocolConfig field -> value)."""
    return _lookup(EVALUATIONS, name)
