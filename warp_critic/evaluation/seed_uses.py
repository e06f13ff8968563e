"""Which goal seeds chose what, and which scored the report: a seed that chose a setting is not a
held-out test of it.

A *goal seed* draws the new goals and the fresh policy initialisations of the Table 1 protocol
(:class:`~warp_critic.evaluation.protocol.ProtocolConfig` ``seed``, the ``tables`` and ``maps``
stages' ``seed``). The report's Tables 1-3 are scored on goal seed 1, the seed that also chose the
KUKA's setting; the ``tables-heldout`` stage scores them again on :data:`HELD_OUT_SEED`, which
chose nothing (:func:`chose`).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class SeedUse:
    seed: int
    use: str  # "chose" (selected a setting) or "scored" (a number in the report)
    what: str
    where: str


SEED_USES: tuple[SeedUse, ...] = (
    SeedUse(
        1,
        "chose",
        "the KUKA's setting (preset kuka-table1: goal-relative critic, random starts 0.4 rad with 2 "
        "home starts, gravity 0, 3 inner steps at alpha 3e-4, lr 3e-3, 3000 iterations): candidates "
        "scored with the Table 1 protocol",
        "warp-critic score --seed 1 (its default); docs/journal/paper-experiments.md 'Settings "
        "compared'; "
        "evaluation/presets.py EVALUATIONS['kuka-table1']",
    ),
    SeedUse(
        1,
        "chose",
        "the reacher's setting (preset reacher: 3 inner steps at alpha 3e-4, 400 iterations), "
        "meta-tested at std 0.3",
        "evaluation/presets.py EVALUATIONS['reacher']",
    ),
    SeedUse(
        1,
        "scored",
        "the report's KUKA Tables 1-3 and stress tables (stage tables)",
        "reproduce/experiments/settings.py tables.seed",
    ),
    SeedUse(
        1,
        "scored",
        "the policy initialisations of the report's reacher maps (Figures 4-6; the goal grid is "
        "fixed, not drawn)",
        "reproduce/experiments/settings.py maps.seed",
    ),
)

#: a goal seed that chose nothing: Tables 1-3 scored on it are a held-out test
HELD_OUT_SEED = 1000
#: the ``tables-heldout`` stage: the ``tables`` settings with these replaced (Tables 1-3 in full;
#: the stress tables cut to one column each and no reachability floors, to save time)
HELDOUT_TABLES = {
    "seed": HELD_OUT_SEED,
    "stress_masses": [9.0],
    "stress_lengths": [2.0],
    "reach_iterations": 0,
}


def chose(seed: int) -> list[SeedUse]:
    """The settings ``seed`` chose (empty: a held-out seed)."""
    return [u for u in SEED_USES if u.seed == seed and u.use == "chose"]


def seed_note(seed: int) -> str:
    """One sentence for the report: whether ``seed`` is held out, or what it chose."""
    picked = chose(seed)
    if not picked:
        return f"goal seed {seed} chose no setting (held out; warp_critic/evaluation/seed_uses.py)"
    return (
        f"goal seed {seed} also chose " + "; ".join(u.what.split(" (")[0] for u in picked) + " "
        "(warp_critic/evaluation/seed_uses.py), so these numbers are not a held-out test"
    )
