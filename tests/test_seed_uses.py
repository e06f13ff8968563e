"""Which goal seeds chose what (warp_critic/evaluation/seed_uses.py), the held-out tables stage
planned from it, and the report's line on the settings that differ from the paper's text."""

from __future__ import annotations

from warp_critic.evaluation import seed_uses
from warp_critic.reproduce.report.departures import departures


def test_the_held_out_seed_chose_nothing_and_seed_1_is_not_held_out():
    assert seed_uses.chose(seed_uses.HELD_OUT_SEED) == []
    assert any("KUKA" in u.what for u in seed_uses.chose(1))
    assert "not a held-out test" in seed_uses.seed_note(1)
    assert "held out" in seed_uses.seed_note(seed_uses.HELD_OUT_SEED)
    scored = {u.seed for u in seed_uses.SEED_USES if u.use == "scored"}
    assert scored == {1, *seed_uses.HELD_OUT_SEEDS}
    assert all(seed_uses.chose(s) == [] for s in seed_uses.HELD_OUT_SEEDS)


def test_the_held_out_stage_keeps_the_tables_stage_and_its_hash():
    from warp_critic.reproduce.experiments.plan import plan
    from warp_critic.reproduce.experiments.settings import default_settings

    p = plan(default_settings(True, 2))
    held, tables = p["tables-heldout"], p["tables"]
    assert held.kind == "tables" and held.depends == tables.depends
    assert held.settings["seed"] == seed_uses.HELD_OUT_SEED != tables.settings["seed"]
    assert held.settings["stds"] == tables.settings["stds"]
    assert held.hash != tables.hash


def test_departures_name_what_differs_from_the_papers_text():
    kuka = departures(
        "kuka",
        {"critic_input": "relative", "start_std": 0.4, "home_starts": 2, "inner_steps": 3},
        0.0,
    )
    text = " ".join(kuka)
    assert "goal-relative critic" in text and "N(0, 0.4^2)" in text and "gravity 0" in text
    assert "3 inner steps per meta-training iteration" in text
    assert "take 3 critic-gradient step(s)" in text and "while not done" in text
    assert "final error ||q_T - g||^2" in text and "once per goal" in text
    one = " ".join(departures("kuka", {"inner_steps": 1, "running_weight": 1.0}, 0.0))
    assert "inner steps" not in one and "final error" not in one and "take 1 critic" in one
    reacher = departures("reacher", {"critic_input": "full"}, 9.81)
    assert not any("gravity" in x or "goal-relative" in x for x in reacher)
    from warp_critic.reproduce.experiments.settings import METHOD_LABELS, TUNED, TUNED_FROM

    for m, changed in TUNED.get("reacher", {}).items():  # each adopted setting, and its source
        ((key, value), *_) = changed.items()
        said = [x for x in reacher if x.startswith(f"{METHOD_LABELS[m]} with {key} {value:g}")]
        assert len(said) == 1 and TUNED_FROM in said[0], (m, reacher)
    assert "`warp-critic budget` or `reproduce --beyond` chooses" in text  # no budget stage: how
    own = " ".join(departures("kuka", {"inner_steps": 3}, 0.0, own_budgets=True))
    assert (
        "'Each method at its own meta-test budget' chooses" in own
        and "warp-critic budget" not in own
    )


def test_departures_point_at_the_budget_section_when_its_stages_are_in_the_report():
    from warp_critic.reproduce.report.departures import departures_of

    class _Rec:
        data: dict = {"settings": {"values": {"inner_steps": 3}}}

    with_budget = departures_of("kuka", {"metatrain-kuka-ours": _Rec(), "budget-kuka-ours": _Rec()})
    without = departures_of("kuka", {"metatrain-kuka-ours": _Rec()})
    assert any("own meta-test budget' chooses" in x for x in with_budget)
    assert not any("own meta-test budget' chooses" in x for x in without)


def test_departures_name_only_the_adoptions_the_reports_runs_trained_with():
    """A report without TD3 (``--baselines ddpg,meta-critic``) names no TD3 setting, and one whose
    meta-training record holds other values than ``TUNED`` (an older run) is not said to hold
    ``TUNED``'s."""
    from types import SimpleNamespace

    from warp_critic.reproduce.experiments.settings import METHOD_LABELS, TUNED
    from warp_critic.reproduce.report.departures import departures_of

    tuned = TUNED.get("reacher", {})
    assert tuned, "no adoption on the reacher to test with"

    def rec(values):
        return SimpleNamespace(data={"settings": {"values": values}})

    ours = {"metatrain-reacher-ours": rec({"critic_input": "full"})}
    assert not [x for x in departures_of("reacher", ours) if "tuning search" in x]
    ran = {f"metatrain-reacher-{m}": rec(dict(v)) for m, v in tuned.items()}
    said = [x for x in departures_of("reacher", {**ours, **ran}) if "tuning search" in x]
    assert len(said) == len(tuned)
    assert all(any(x.startswith(METHOD_LABELS[m]) for x in said) for m in tuned)
    other = {
        k: rec({key: v * 10 for key, v in r.data["settings"]["values"].items()})
        for k, r in ran.items()
    }
    assert not [x for x in departures_of("reacher", {**ours, **other}) if "tuning search" in x]
