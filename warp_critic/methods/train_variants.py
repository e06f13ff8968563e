"""``--train-variants`` in meta-training: its checks before any work, and the per-iteration redraw.

:func:`check_train_variants` (called by ``TrainConfig.check``): blank text is refused, every range
must apply to the robot (:func:`~warp_critic.physics.variant_draws.check_on_scene`), and, for a new
run that stops on divergence, the run's own step must hold the models at the ranges' ends under
saturated torques (:mod:`warp_critic.physics.stability`): a range that would diverge at iteration 0
is refused up front, naming the value from which the model holds. The probe runs once per process
for the same scene and settings (a batched run checks one config per seed).
"""

from __future__ import annotations

from typing import Any

from warp_critic.core.errors import FieldError
from warp_critic.physics.variant_draws import FIELD, check_on_scene, parse_ranges
from warp_critic.running.task import task_variant

_probed: dict[tuple, str | None] = {}


def check_train_variants(cfg: Any, scene=None) -> None:
    """The ``train_variants`` checks of a meta-training config (module docstring); a
    :class:`FieldError` on ``train_variants``."""
    text = cfg.train_variants
    if text is not None and not str(text).strip():
        raise FieldError(FIELD, "is blank: give ranges such as 'arm1.mass=0.5..2', or leave it out")
    ranges = parse_ranges(text)
    if scene is None or not ranges:
        return
    base = task_variant(cfg)
    check_on_scene(scene, base, ranges)
    if cfg.resume or cfg.on_divergence != "stop":
        return  # a resumed run trained on them already; dropped worlds are the user's choice
    check_held(cfg, scene, ranges, text)


def check_held(cfg: Any, scene, ranges, text: str) -> None:
    """Refuse (:class:`FieldError` on ``train_variants``) ranges whose ends the step of ``cfg`` (a
    filled task config: ``dt``, ``substeps``, ``gravity``, ``max_torque``, ``horizon``) cannot hold
    under saturated torques; a config not yet filled is not probed."""
    filled = (cfg.dt, cfg.substeps, cfg.gravity, cfg.max_torque, cfg.horizon)
    if any(v is None for v in filled):
        return
    from warp_critic.learning.rollout import DIVERGED
    from warp_critic.physics.stability import Probe, check_ranges
    from warp_critic.running.task_inputs import max_torque_tensor

    base = task_variant(cfg)
    bound = [float(x) for x in max_torque_tensor(cfg.max_torque, scene)]
    probe = Probe(
        dt=float(cfg.dt),
        substeps=int(cfg.substeps),
        gravity=float(cfg.gravity),
        bound=tuple(bound),
        steps=int(cfg.horizon),
        limit=DIVERGED,
    )
    key = (getattr(scene, "content_hash", None) or str(scene.path), base, ranges, probe)
    if key not in _probed:
        _probed[key] = check_ranges(scene, base, ranges, probe)
    problem = _probed[key]
    if problem is not None:
        raise FieldError(FIELD, f"{text!r}: {problem}")


class VariantRedraw:
    """``--train-variants``: every iteration, a new variant for every world of the task's simulator.

    Seed ``i``'s worlds draw from ``(seed_i, iteration)`` alone
    (:func:`~warp_critic.physics.variant_draws.draw`), so batched seeds draw what single-seed runs
    draw, and a resumed run draws what the uninterrupted one did. Calling it with iteration ``it``
    sets the variants in place (:func:`~warp_critic.physics.redraw.set_variants`) and returns the
    values, ``(S, Wc, ranges)``.
    """

    def __init__(self, cfg: Any, task, seeds: list[int]):
        self.ranges = parse_ranges(cfg.train_variants)
        self.base = task_variant(cfg)
        self.seeds = seeds  # of the task's copies, in order
        self.task = task

    def __call__(self, it: int):
        import numpy as np

        from warp_critic.physics.redraw import set_variants
        from warp_critic.physics.variant_draws import draw, with_draws

        values = np.stack([draw(self.ranges, self.task.Wc, s, it) for s in self.seeds])
        worlds = [
            with_draws(self.base, self.ranges, v) for v in values.reshape(-1, len(self.ranges))
        ]
        set_variants(self.task.sim, worlds)
        return values


__all__ = ["check_train_variants", "VariantRedraw"]
