"""The paper's stages by name (:func:`stage_name`, the one place a stage name is built) and what each
produces (:class:`Outputs`, the ``outputs`` of its :class:`~warp_critic.reproduce.engine.stage.Stage`).

Names: ``toy``, ``landscape``, ``maps``, ``tables``; one meta-training per robot and method,
``metatrain-<robot>-<method>``; an extra baseline's evaluations ``<method>-maps`` /
``<method>-tables``; beyond the paper, one meta-training per robot and recipe,
``beyond-metatrain-<robot>-<recipe>``, and ``beyond-maps`` / ``beyond-tables``. On the held-out goal
seeds (:data:`~warp_critic.evaluation.seed_uses.HELD_OUT_SEEDS`): ``tables-heldout`` and
``maps-heldout`` on the first, ``tables-heldout-<seed>`` / ``maps-heldout-<seed>`` on the others,
each also ``by`` an extra baseline (``td3-tables-heldout-1010``) or by ours at the baselines'
environment steps (:data:`EQUAL_STEPS`: ``metatrain-kuka-ours-equal-steps``,
``equal-steps-tables-heldout``). Each method's own meta-test budget (:data:`BUDGET`,
:mod:`~warp_critic.reproduce.experiments.budget`): chosen by ``budget-<robot>-<method>``, reported
by ``budget-<method>-tables-heldout[-<seed>]`` / ``budget-<method>-maps-heldout[-<seed>]``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

#: the recipes beyond the paper (``--beyond``): kept apart, never part of the paper's stages
BEYOND = "beyond"
#: the goal seeds that chose nothing: Tables 1-3 and the maps again (``tables-heldout``)
HELDOUT = "heldout"
#: ours meta-trained on the baselines' environment steps (the equal-budget rows)
EQUAL_STEPS = "equal-steps"
#: each method's own meta-test budget: its choice, and the held-out tables and maps at it
BUDGET = "budget"


def stage_name(
    kind: str,
    scene: str | None = None,
    method: str | None = None,
    *,
    recipe: str | None = None,
    by: str | None = None,
    heldout: bool | int = False,
    equal_steps: bool = False,
    budget: bool = False,
) -> str:
    """The name of a stage of ``kind`` (toy, landscape, metatrain, maps, tables).

    ``metatrain`` names one robot (``scene``) and either a ``method`` or a ``recipe`` beyond the
    paper (``equal_steps``: ours at the baselines' environment steps); an evaluation (maps, tables) is
    the paper's, or ``by`` an extra baseline, :data:`BEYOND` or :data:`EQUAL_STEPS`; ``heldout``: on
    a held-out goal seed (``True``: the first; a seed: that one, named by it unless the first).
    ``kind`` :data:`BUDGET` names a robot and a method (the choice of its meta-test budget);
    ``budget``: an evaluation at the meta-test budget of the method ``by`` (no ``by``: the
    ``--only`` group of them all).
    """
    if kind == BUDGET:
        if scene is None or method is None:
            raise ValueError("a budget stage names a robot and a method")
        return "-".join((kind, scene, method))
    if kind == "metatrain":
        if scene is None or (method is None) == (recipe is None):
            raise ValueError("a meta-training stage names a robot and a method or a recipe")
        if recipe is not None:
            return "-".join((BEYOND, kind, scene, recipe))
        return "-".join((kind, scene, str(method)) + ((EQUAL_STEPS,) if equal_steps else ()))
    parts = ([BUDGET] if budget else []) + ([by] if by else []) + [kind]
    if heldout is not False:
        from warp_critic.evaluation.seed_uses import HELD_OUT_SEEDS

        parts.append(HELDOUT)
        # the first seed's stages keep the names they had before there were three seeds
        if heldout is not True and int(heldout) != HELD_OUT_SEEDS[0]:
            parts.append(str(int(heldout)))
    return "-".join(parts)


def is_beyond(name: str) -> bool:
    """Whether ``name`` is the group ``beyond`` or one of its stages."""
    return name == BEYOND or name.startswith(BEYOND + "-")


@dataclass(frozen=True)
class Outputs:
    """What a paper stage produces. A meta-training: the runs of ``method`` on ``scene`` (with
    ``recipe``: ours under a recipe beyond the paper). An evaluation (maps, tables) on ``scene``:
    rows for the runs of each stage it depends on, labelled by its method, or by ``labels``
    (dependency -> row, the recipes beyond the paper); ``rows``: only these methods' (an extra
    baseline's, ours' runs the reference), which the report adds to the paper stage ``adds_to``."""

    scene: str | None = None
    method: str | None = None
    recipe: str | None = None
    rows: tuple[str, ...] | None = None
    adds_to: str | None = None
    labels: Mapping[str, str] | None = None
    #: the ``--only`` group it runs with besides its own name (the held-out seeds after the first)
    part_of: str | None = None
    #: an evaluation at this method's chosen meta-test budget (its ``budget-*`` stage read at run time)
    budget_of: str | None = None


__all__ = ["BEYOND", "BUDGET", "EQUAL_STEPS", "HELDOUT", "Outputs", "is_beyond", "stage_name"]
