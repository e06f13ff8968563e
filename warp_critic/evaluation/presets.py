"""Named settings behind the reported numbers (README.md, RESULTS.md).

:data:`PRESETS` maps a name to config values keyed by config **field names** (of
:class:`warp_critic.methods.ours.TrainConfig` for meta-training presets, of
:class:`warp_critic.methods.baseline_config.BaselineConfig` for the baselines); everything not named is the
scene default. A meta-training preset is a :class:`FromScene`: it names the settings of a reported
run, and their values are the ones its scene (:data:`SCENES`) authors, so the numbers live in one
place (``tools/make_scenes.py``, written into ``scenes/*.usda``). :data:`DESCRIPTIONS` says in one
line what each preset is and what it scored.

:data:`EVALUATIONS` holds the meta-test protocol each preset's numbers were reported with, keyed by
:class:`warp_critic.evaluation.protocol.ProtocolConfig` field names.

Why these settings: three inner critic-gradient steps with a 3x smaller step reach a much lower error
than one step (one step from a random initialisation leaves an error floor set by the random
network's Jacobian). KUKA: the goal-relative critic with random starts around home covers goals far
from the four training goals, while some worlds per goal keep starting at home (as at meta-test).
The measurements behind both are in RESULTS.md.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any

from warp_critic.core.errors import FieldError
from warp_critic.methods import methods


@dataclass(frozen=True)
class FromScene:
    """Settings (config field names) whose values are the ones the preset's scene authors."""

    keys: tuple[str, ...]


PRESETS: dict[str, FromScene | dict[str, Any]] = {
    # meta-training (TrainConfig fields), values from the scene
    "reacher": FromScene(("iterations", "inner_steps", "alpha")),
    "kuka-table1": FromScene(
        ("critic_input", "start_std", "home_starts", "iterations", "inner_steps", "alpha", "lr")
    ),
    # baselines (their config's fields): each registered method's preset (the published settings)
    **{m.name: m.preset for m in methods() if m.preset is not None},
}

DESCRIPTIONS: dict[str, str] = {
    "reacher": "reacher benchmark: 3 inner steps at alpha 3e-4, 400 iterations "
    "(meta-train 0.0083 rad^2, meta-test 0.033 summed at std 0.3)",
    "kuka-table1": "KUKA against the paper's Table 1: goal-relative critic, random starts 0.4 rad with 2 of 4 "
    "worlds per goal at home, 3 inner steps at alpha 3e-4, lr 3e-3, 3000 iterations "
    "(MSE 0.019 / 0.056 at std 0.1 / 0.4 per-joint)",
    **{m.name: m.preset_description for m in methods() if m.preset is not None},
}

#: The scene (file stem under ``scenes/``) each preset was measured on; ``None``: reported on several.
SCENES: dict[str, str | None] = {
    "reacher": "reacher",
    "kuka-table1": "kuka",
    **{m.name: None for m in methods() if m.preset is not None},
}

# every baseline is reported with the same protocol
_BASELINE_EVALUATION: dict[str, Any] = {
    "stds": [0.1, 0.3, 0.4],
    "goal_noise": ["per-joint"],
    "around": [0, 1],
    "num_goals": 10,
    "inits": 5,
    "seed": 1,
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
    **{m.name: _BASELINE_EVALUATION for m in methods() if m.preset is not None},
}


def _lookup(table: dict[str, Any], name: str) -> Any:
    if name not in table:
        raise FieldError("preset", f"unknown preset {name!r}; known: {', '.join(sorted(table))}")
    return copy.deepcopy(table[name])


def preset(name: str) -> dict[str, Any]:
    """A copy of preset ``name``'s settings (config field -> value); unknown names raise ``FieldError``.

    A :class:`FromScene` preset reads its values from ``scenes/<SCENES[name]>.usda``; a scene that
    lacks one of them raises ``FieldError`` naming the setting.
    """
    entry = _lookup(PRESETS, name)
    if not isinstance(entry, FromScene):
        return entry
    from warp_critic.physics.load import load_scene
    from warp_critic.physics.scene import scenes_dir

    scene = load_scene(scenes_dir() / f"{SCENES[name]}.usda")
    defaults = scene.defaults
    missing = [key for key in entry.keys if key not in defaults]
    if missing:
        raise FieldError(
            "preset", f"{name}: the scene {scene.path} authors no {', '.join(missing)}"
        )
    return {key: defaults[key] for key in entry.keys}


def evaluation(name: str) -> dict[str, Any]:
    """A copy of the meta-test protocol preset ``name`` was reported with (ProtocolConfig field -> value)."""
    return _lookup(EVALUATIONS, name)
