"""Which goal seeds chose what, and which scored the report: a seed that chose a setting is not a
held-out test of it.

A *goal seed* draws the new goals and the fresh policy initialisations of the Table 1 protocol
(:class:`~warp_critic.evaluation.protocol.ProtocolConfig` ``seed``, the ``tables`` and ``maps``
stages' ``seed``). The ``tables`` and ``maps`` stages score on goal seed 1, the seed that also chose
the KUKA's and the reacher's settings; the ``tables-heldout`` and ``maps-heldout`` stages score them
again on each of :data:`HELD_OUT_SEEDS`, which chose nothing (:func:`chose`), and the report judges
the claims on those.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class SeedUse:
    seed: int
    use: str  # "chose" (selected a setting) or "scored" (a number in the report)
    what: str
    where: str


#: the goal seed that chooses each method's meta-test budget (:mod:`warp_critic.reproduce.budget`)
CHOOSE_BUDGET_SEED = 2000
#: the goal seed that scores every method's tuning candidates (the repository's ``bench/tune.py``)
TUNE_SEED = 3000

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
        CHOOSE_BUDGET_SEED,
        "chose",
        "each method's meta-test budget (step size and number of critic-gradient steps): the "
        "initialisations of the fresh policies on the run's training goals",
        "warp-critic budget --choose-seed (its default); reproduce/budget.py",
    ),
    SeedUse(
        TUNE_SEED,
        "chose",
        "every method's hyper-parameters (one tuning procedure for all): the initialisations of "
        "the fresh policies that score each candidate on its run's training goals",
        'the tuning search of docs/paper/README.md ("The tuning searches"); seed_uses.TUNE_SEED',
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
    *(
        SeedUse(
            seed,
            "scored",
            "the report's held-out KUKA Tables 1-3 and reacher maps, and the verdicts on them "
            "(stages tables-heldout and maps-heldout)",
            "evaluation/seed_uses.py HELD_OUT_SEEDS; reproduce/experiments/heldout.py",
        )
        for seed in (1000, 1010, 1020)
    ),
)

#: goal seeds that chose nothing: Tables 1-3 and the maps scored on them are a held-out test. Ten
#: apart, as Table 1 draws column ``c``'s goals from ``seed + c`` (10 columns): no goal is drawn twice
HELD_OUT_SEEDS = (1000, 1010, 1020)
#: the first of them (the only one before there were three; its stages keep their names)
HELD_OUT_SEED = HELD_OUT_SEEDS[0]
#: the ``tables-heldout`` stages: the ``tables`` settings with these replaced, and ``seed`` (Tables
#: 1-3 in full; the stress tables cut to one column each and no reachability floors, to save time)
HELDOUT_TABLES = {
    "seed": HELD_OUT_SEED,
    "stress_masses": [9.0],
    "stress_lengths": [2.0],
    "reach_iterations": 0,
}
#: the ``maps-heldout`` stages: the ``maps`` settings with these replaced, and ``seed`` (the
#: reachability floors depend on no seed and no critic: the ``maps`` stage's are read)
HELDOUT_MAPS = {"reach_iterations": 0}


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
