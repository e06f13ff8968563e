"""The settings of a robot's runs that differ from the paper's text, and why: one line the report
prints next to each table and figure of that robot (read from the stage records and the scene)."""

from __future__ import annotations

from collections.abc import Mapping

from warp_critic.reproduce.experiments.naming import BUDGET, stage_name
from warp_critic.reproduce.experiments.settings import METHOD_LABELS, TUNED, TUNED_FROM


def scene_gravity(scene: str) -> float | None:
    """The gravity the scene's runs use (m/s^2), ``None`` if the scene cannot be read."""
    try:
        from warp_critic.physics.load import load_scene
        from warp_critic.reproduce.experiments.metatrain import scene_file

        g = load_scene(scene_file(scene)).defaults.get("gravity")
    except Exception:  # the report states what it can
        return None
    return None if g is None else float(g)


def departures(
    scene: str,
    values: dict,
    gravity: float | None,
    own_budgets: bool = False,
    tuned: Mapping[str, Mapping[str, float]] | None = None,
) -> list[str]:
    """What differs from the paper's text in ``scene``'s runs: ``values`` are ours' meta-training
    settings (the stage record's), ``gravity`` the scene's; ``own_budgets``: the report also
    holds each method at its own meta-test budget (the budget stages ran); ``tuned``: method ->
    the adopted values its runs trained with (default: ``TUNED``'s for ``scene``)."""
    out = []
    inner = int(values.get("inner_steps", 1))
    if inner != 1:
        out.append(
            f"{inner} inner steps per meta-training iteration (Algorithm 2 takes one step of "
            "L_critic's gradient before the task loss)"
        )
    per_policy = inner * int(values.get("policy_lifetime", 1))
    where = (
        "the section 'Each method at its own meta-test budget' chooses every method's steps (1-300) "
        "and step size on its training goals and reports it there"
        if own_budgets
        else "`warp-critic budget` or `reproduce --beyond` chooses each method's steps (1-300) "
        "and step size on its training goals"
    )
    out.append(
        f"meta-test: every method's fresh policies take {per_policy} critic-gradient step(s) "
        f"(Algorithm 3 trains 'while not done'; {where})"
    )
    out.append(
        "one critic update per iteration on the mean task loss over all training goals at once "
        "(Algorithm 2 updates the critic once per goal, in turn)"
    )
    if not values.get("running_weight"):
        out.append(
            "the task loss is the final error ||q_T - g||^2 (the paper's L_task sums the cost "
            "along the trajectory)"
        )
    if values.get("critic_input") == "relative":
        out.append(
            "a goal-relative critic (input q - g, not the state and the goal) and the random starts "
            "below: in the paper's setting the critic does not generalise to unseen goals, with "
            "both it does (Figure 1's row)"
        )
    if values.get("start_std"):
        out.append(
            f"random starts (N(0, {values['start_std']:g}^2) rad per joint around home, "
            f"{values.get('home_starts', 0)} of each goal's 4 worlds at home; the baselines train "
            "on the same starts)"
        )
    if gravity == 0:
        out.append("gravity 0 (torque mode; the paper's text does not state the gravity)")
    for m, changed in (TUNED.get(scene, {}) if tuned is None else tuned).items():
        own = "its preset's" if m == "ours" else "its published"
        out.append(
            f"{METHOD_LABELS[m]} with "
            + ", ".join(f"{k} {v:g}" for k, v in changed.items())
            + f" from {TUNED_FROM}, not {own} value"
        )
    return out


def departures_of(scene: str, recs: Mapping) -> list[str]:
    """What differs from the paper's text in ``scene``'s runs (``recs``: the stage records by
    name), read from ours' meta-training record and the scene."""
    rec = recs.get(stage_name("metatrain", scene, "ours"))
    values = rec.data.get("settings", {}).get("values", {}) if rec is not None else {}
    own = stage_name(BUDGET, scene, "ours") in recs  # ours' choice: the budget section is there
    return departures(
        scene, values, scene_gravity(scene), own_budgets=own, tuned=_tuned(scene, recs)
    )


def _tuned(scene: str, recs: Mapping) -> dict[str, dict[str, float]]:
    """``TUNED``'s adoptions for ``scene`` that the report's meta-trainings trained with: a method
    the call did not run (``--baselines`` without it), or whose record holds other values, is not
    named."""
    out = {}
    for m, changed in TUNED.get(scene, {}).items():
        rec = recs.get(stage_name("metatrain", scene, m))
        ran = rec.data.get("settings", {}).get("values", {}) if rec is not None else {}
        if changed and all(ran.get(k) == v for k, v in changed.items()):
            out[m] = dict(changed)
    return out


def departures_line(scene: str, items: list[str]) -> str:
    """The report's sentence for ``scene`` from :func:`departures_of`'s ``items``."""
    if not items:
        return f"Settings that differ from the paper's text ({scene}): none stated."
    return f"Settings that differ from the paper's text ({scene}): " + "; ".join(items) + "."
