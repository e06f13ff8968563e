"""bench/tune.py: one tuning procedure for ours, DDPG, Meta-Critic and TD3 -- the same candidate
count and knobs, the same environment steps, the same score and the same adoption rule."""

from __future__ import annotations

import json

import pytest
from conftest import ROOT
from helpers import load_tool

METHODS = ("ours", "ddpg", "meta-critic", "td3")
TUNING = ROOT / "docs" / "paper" / "tuning"


@pytest.fixture(scope="module")
def tool():
    return load_tool("tune", "bench")


def _tiny_argv(tmp, jobs: int = 1) -> list[str]:
    """A tiny search of ours on the reacher (7 candidates, 2 seeds, a few iterations each)."""
    return ["--tiny", "--train-steps", "400", "--scenes", "reacher", "--methods", "ours",
            "--inits", "1", "--jobs", str(jobs), "--out", str(tmp / "tune.json"),
            "--runs", str(tmp / "runs")]  # fmt: skip


@pytest.fixture(scope="module")
def tiny_search(tool, tmp_path_factory):
    """``(argv, out)`` of one complete tiny search, made once for the tests that read it."""
    tmp = tmp_path_factory.mktemp("tiny-search")
    argv = _tiny_argv(tmp)
    assert tool.main(argv) == 0
    return argv, tmp / "tune.json"


@pytest.mark.parametrize("scene", ["reacher", "kuka"])
def test_every_method_gets_seven_candidates_on_the_same_three_knobs(tool, scene):
    for m in METHODS:
        cands = tool.candidates(scene, m)
        own = tool.knob_values(scene, m)
        assert cands[0] == {} and len(cands) == 7, (m, cands)
        assert all(len(c) == 1 for c in cands[1:])
        kind = "ours" if m == "ours" else "baseline"
        for knob in tool.KNOBS.values():  # each knob down and up once, by its factors
            name = knob[kind]
            got = sorted(c[name] / own[name] for c in cands[1:] if name in c)
            assert got == pytest.approx(sorted(knob["factors"]), rel=2e-3), (m, name)


def test_the_own_setting_undoes_earlier_adoptions(tool, monkeypatch):
    """The search starts from the published settings, not from an earlier search's pick: whatever
    ``settings.TUNED`` holds (here the committed one, and a stand-in that adopts a change of every
    kind), the own setting is reproduce's setting without it."""
    import warp_critic.reproduce.experiments.settings as settings

    def check():
        for scene in ("reacher", "kuka"):
            for m in METHODS:
                own = tool.own_setting(scene, m)
                plain = settings.default_settings(False, 1, extra=tool._extra(m))["metatrain"][
                    scene
                ][m]
                changed = settings.TUNED.get(scene, {}).get(m, {})
                assert {k: v for k, v in plain.items() if k not in changed} == {
                    k: v for k, v in own.items() if k not in changed
                }, (scene, m)
                for key, value in changed.items():
                    assert plain[key] == value and own.get(key) != value, (scene, m, key)

    check()
    stand_in = {
        "reacher": {"ddpg": {"actor_lr": 3.16e-5}, "meta-critic": {"updates_per_iteration": 100}},
        "kuka": {"ours": {"lr": 0.00948}, "td3": {"critic_hidden": 800}},
    }
    monkeypatch.setattr(settings, "TUNED", stand_in)
    check()
    assert "updates_per_iteration" not in tool.own_setting("reacher", "meta-critic")
    assert tool.own_setting("reacher", "ddpg").get("actor_lr", 1e-4) == 1e-4  # the config's
    assert tool.knob_values("reacher", "ddpg")["actor_lr"] == 1e-4
    assert tool.own_setting("kuka", "ours")["lr"] != 0.00948


@pytest.mark.parametrize("scene", ["reacher", "kuka"])
def test_every_method_trains_for_the_same_environment_steps(tool, scene):
    its = {
        m: tool.iterations_for(scene, m, tool.own_setting(scene, m), tool.TRAIN_STEPS)
        for m in METHODS
    }
    # ours counts (3 inner + 1) rollouts of 16 worlds x 50 steps per iteration, a baseline one
    assert its == {"ours": 100, "ddpg": 400, "meta-critic": 400, "td3": 400}


def test_the_score_is_the_best_step_size_and_a_diverged_seed_rules_its_step_size_out(tool):
    got = tool.pick({"0.1": [0.3, 0.5], "1": [0.2, float("inf")], "10": [0.35, 0.25]})
    assert (
        got["scale"] == 10.0
        and got["score"] == pytest.approx(0.3)
        and got["per_seed"] == [0.35, 0.25]
    )
    tie = tool.pick({"0.1": [0.2, 0.2], "1": [0.2, 0.2]})
    assert tie["scale"] == 0.1


def test_one_adoption_rule_for_every_method(tool):
    own = {"change": {}, "score": 0.9, "per_seed": [1.0, 0.8]}
    better = {"change": {"lr": 1e-3}, "score": 0.79}
    assert tool.adopted(better, own)  # 0.11 below, more than half the 0.2 spread
    assert not tool.adopted({**better, "score": 0.81}, own)
    assert not tool.adopted({**own, "score": 0.1}, own)  # the own setting itself
    assert not tool.adopted({**better, "score": float("inf")}, own)


def test_a_complete_search_proposes_and_only_full_length_confirms(tool):
    rows = [
        {
            "scene": "reacher",
            "method": "td3",
            "change": c,
            "score": 0.5 - 0.01 * k,
            "per_seed": [0.5, 0.5],
        }
        for k, c in enumerate(tool.candidates("reacher", "td3"))
    ]
    best = rows[-1]["change"]
    a = tool.adoption(rows, "reacher", "td3")
    assert a["complete"] and a["proposed"] and a["best"] is rows[-1]
    assert a["confirm"] is None and a["adopt"] == {}  # proposed, not yet confirmed
    part = tool.adoption(rows[:-1], "reacher", "td3")
    assert not part["complete"] and not part["proposed"] and part["adopt"] == {}
    assert tool.adoption(rows[1:], "reacher", "td3") is None  # the own setting not scored yet

    def full(change, score):
        return {"scene": "reacher", "method": "td3", "change": change, "length": "full",
                "score": score, "per_seed": [score - 0.01, score + 0.01]}  # fmt: skip

    kept = tool.adoption([*rows, full({}, 0.2), full(best, 0.195)], "reacher", "td3")
    assert kept["confirm"] is False and kept["adopt"] == {}  # 0.005 < half the 0.02 spread
    won = tool.adoption([*rows, full({}, 0.2), full(best, 0.1)], "reacher", "td3")
    assert won["confirm"] is True and won["adopt"] == best
    # full-length rows never enter the truncated search's ranking
    assert tool.adoption([*rows, full({}, 0.0)], "reacher", "td3")["best"] is rows[-1]


@pytest.mark.slow
def test_a_tiny_search_scores_every_candidate_and_resumes_without_retraining(
    tool, tiny_search, tmp_path, capsys
):
    argv, out = tiny_search
    rows = json.loads(out.read_text())["rows"]
    search = [r for r in rows if r["length"] == "truncated"]
    assert [r["change"] for r in search] == tool.candidates("reacher", "ours")
    a = tool.adoption(rows, "reacher", "ours")
    full = [r["change"] for r in rows if r["length"] == "full"]
    assert full == ([{}, a["best"]["change"]] if a["proposed"] else [])
    assert (a["confirm"] is None) == (not a["proposed"])  # a proposal is confirmed in the same call
    assert all(len(r["per_seed"]) == 2 and r["score"] > 0 for r in rows)
    capsys.readouterr()
    assert tool.main(argv) == 0  # every candidate scored: nothing trains again
    assert "(truncated): score" not in capsys.readouterr().out  # no candidate line: none trained
    assert json.loads(out.read_text())["rows"] == rows
    md = tmp_path / "tune.md"
    assert tool.main([*argv, "--summary-only", "--markdown", str(md)]) == 0
    text = md.read_text()
    assert text.startswith("### reacher, ours") and text.count("| truncated |") == 7
    assert tool._verdict(a) in text
    with pytest.raises(SystemExit) as e:  # another procedure's file is refused, not mixed in
        tool.main([*argv[:2], "800", *argv[3:]])
    assert e.value.code == 2
    assert json.loads(out.read_text())["rows"] == rows


@pytest.mark.parametrize(
    "argv, words",
    [
        (["--scenes", "pendulum"], "unknown scene"),
        (["--seeds", "0,100"], "other than the reported"),
        (["--methods", "ppo"], "unknown method"),
        (["--inits", "0"], "at least 1"),
        (["--jobs", "0"], "--jobs at least 1"),
        (["--candidate", "nope"], "--candidate: "),
        (["--candidate", '[{}, "truncated"]'], "with --row-out"),
    ],
)
def test_bad_input_is_one_line_exit_2(tool, argv, words, capsys):
    with pytest.raises(SystemExit) as e:
        tool.main(argv)
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and words in err, err


def test_markdown_never_overwrites_a_users_file(tool, tmp_path, capsys):
    """``--markdown`` writes a new ``.md`` or a summary of this tool; anything else is refused in one
    line before any candidate trains, and left byte for byte."""
    notes, readme = tmp_path / "notes.txt", tmp_path / "README.md"
    notes.write_text("mine")
    readme.write_text("# my project\n")
    for path, words in ((notes, "must be a .md file"), (readme, "not overwriting it")):
        with pytest.raises(SystemExit) as e:
            tool.main([*_tiny_argv(tmp_path), "--markdown", str(path)])
        err = capsys.readouterr().err
        assert e.value.code == 2 and err.count("\n") == 1 and words in err, err
    assert notes.read_text() == "mine" and readme.read_text() == "# my project\n"
    assert not (tmp_path / "tune.json").exists()


def test_an_adoption_for_ours_reaches_reproduce_and_the_search_undoes_it(tool, monkeypatch):
    """``TUNED`` may name ours too (one procedure for all): reproduce trains ours with the change,
    the task fields the baselines share stay ours' preset's, and the search starts from the preset."""
    from warp_critic.reproduce.experiments import settings

    before = settings.default_settings(False, 1)["metatrain"]["kuka"]
    kuka = settings.TUNED.get("kuka", {})
    monkeypatch.setitem(settings.TUNED, "kuka", {**kuka, "ours": {"lr": 1e-3}})
    after = settings.default_settings(False, 1)["metatrain"]["kuka"]
    assert before["ours"]["lr"] == 3e-3 and after["ours"]["lr"] == 1e-3
    assert {k: v for k, v in after["ours"].items() if k != "lr"} == {
        k: v for k, v in before["ours"].items() if k != "lr"
    }
    assert after["ddpg"] == before["ddpg"]
    assert tool.own_setting("kuka", "ours")["lr"] == 3e-3


@pytest.mark.slow
def test_a_candidate_stopped_before_its_first_checkpoint_starts_again(tool, tiny_search, tmp_path):
    """A search killed mid-candidate leaves seed folders without a checkpoint: the next call
    trains that candidate from the start instead of refusing the folder, to the row one
    uninterrupted search gives (one candidate, ``--candidate``)."""
    for s in tool.SEEDS:
        seed = tmp_path / "runs" / "reacher-ours-own" / f"seed{s}"
        seed.mkdir(parents=True)
        (seed / "metrics.jsonl").write_text('{"iteration": 0}\n')  # a started run, no checkpoint
    row = tmp_path / "row.json"
    argv = [*_tiny_argv(tmp_path), "--candidate", '[{}, "truncated"]', "--row-out", str(row)]
    assert tool.main(argv) == 0
    got = json.loads(row.read_text())
    ref = json.loads(tiny_search[1].read_text())["rows"][0]
    assert got["change"] == ref["change"] == {} and got["per_seed"] == ref["per_seed"]


def uniform_decisions(tool) -> tuple[dict, int]:
    """What the committed one-procedure searches (``docs/paper/tuning/uniform-*.json``) adopt, as
    scene -> method -> change (methods that keep their own setting absent), and how many of the
    eight robot-method searches have decided (complete, and a proposal confirmed or refused at
    full length)."""
    adopted: dict = {}
    decided = 0
    for f in sorted(TUNING.glob("uniform-*.json")):
        rows = json.loads(f.read_text())["rows"]
        for scene, method in sorted({(r["scene"], r["method"]) for r in rows}):
            a = tool.adoption(rows, scene, method)
            if a is None or not a["complete"] or (a["proposed"] and a["confirm"] is None):
                continue
            decided += 1
            if a["adopt"]:
                adopted.setdefault(scene, {})[method] = a["adopt"]
    return adopted, decided


#: how the departures name the one procedure's search once :data:`TUNED` is derived from it
UNIFORM_SEARCH = "the one tuning search of all four methods (docs/paper/tuning/uniform-*)"


def test_reproduce_adopts_exactly_what_the_committed_searches_decide(tool):
    """``settings.TUNED`` is exactly what the one procedure's decided robot-method searches adopt
    (each complete, and a proposal confirmed or refused at full length). A method whose search has
    not decided runs its own setting, and the rerun runs none of its stages until it has
    (``docs/rerun/README.md``): a later adoption then changes only stages not yet run, and
    ``tests/test_rerun_archive.py`` fails on any archived stage that a change of ``TUNED``
    orphans. (The published report of 2026-12-06 ran the earlier baselines-only search's
    adoptions; its departures, in its ``results.json``, say so.)"""
    from warp_critic.reproduce.experiments.settings import TUNED, TUNED_FROM

    adopted, decided = uniform_decisions(tool)
    assert decided >= 6, "the committed searches decided fewer than the six of 2026-12-07"
    assert TUNED == adopted
    assert TUNED_FROM == UNIFORM_SEARCH  # what the report's departures say the change came from


@pytest.mark.parametrize("scene", ["reacher", "kuka"])
def test_a_confirmation_trains_for_the_methods_whole_reproduce_run(
    tool, scene, tmp_path, monkeypatch
):
    """Truncated: the search's environment steps; full: exactly the iterations reproduce trains
    the method for (ours 400 / 3000, a baseline 1600 / 1500), with the candidate's change."""
    import dataclasses
    from types import SimpleNamespace

    import warp_critic.methods as registry
    from warp_critic.reproduce.experiments.settings import default_settings

    seen = []

    def fake_train(cfg, progress, record):
        seen.append(cfg)
        return SimpleNamespace(
            seeds=[
                SimpleNamespace(run_dir=str(tmp_path / f"seed{s}"), metrics=[]) for s in cfg.seeds
            ]
        )

    args = SimpleNamespace(train_steps=tool.TRAIN_STEPS, tiny=False, seeds=[100, 101], device="cpu")
    real = registry.method
    monkeypatch.setattr(
        registry, "method", lambda m: dataclasses.replace(real(m), train=fake_train)
    )
    for m in ("ours", "ddpg"):
        reproduce = default_settings(False, 1)["metatrain"][scene][m]["iterations"]
        change = tool.candidates(scene, m)[1]
        for length, want in (
            (tool.TRUNCATED, {"ours": 100, "ddpg": 400}[m]),
            (tool.FULL, reproduce),
        ):
            tool.train(scene, m, change, args, tmp_path / f"{m}-{length}", length)
            cfg = seen[-1]
            assert cfg.iterations == want and cfg.seeds == [100, 101], (m, length)
            # a sitting's end loses at most 100 iterations of a candidate
            assert cfg.checkpoint_every == min(want // 4, tool.CHECKPOINT_EVERY) <= 100
            ((key, value),) = change.items()
            assert getattr(cfg, key) == value


def test_the_committed_summaries_are_the_tools_rendering_of_the_committed_rows(tool):
    """``docs/paper/tuning/uniform-ROBOT.md`` is ``--summary-only --markdown`` of its JSON: the
    tables and verdicts cannot drift from the rows."""
    files = sorted(TUNING.glob("uniform-*.json"))
    assert files
    for f in files:
        rows = json.loads(f.read_text())["rows"]
        scenes = sorted({r["scene"] for r in rows})
        text = "\n".join(tool.summary_markdown(rows, scenes, list(METHODS))) + "\n"
        assert f.with_suffix(".md").read_text() == text, f.name


def test_the_summary_says_what_the_rule_decided(tool):
    def row(change, score, length="truncated"):
        return {"scene": "kuka", "method": "ddpg", "change": change, "length": length,
                "score": score, "per_seed": [score - 0.01, score + 0.01], "scale": 1.0, "seconds": 1.0}  # fmt: skip

    search = [row(c, 0.5 - 0.05 * k) for k, c in enumerate(tool.candidates("kuka", "ddpg"))]
    best = search[-1]["change"]
    ((key, value),) = best.items()

    def verdict(rows):
        return "\n".join(tool.summary_markdown(rows, ["kuka"], ["ddpg"])).splitlines()[-1]

    assert verdict(search[:3]) == "Search incomplete: nothing proposed yet."
    assert verdict(search) == f"Proposed: {key} {value:g}; its full-length confirmation is pending."
    refused = [*search, row({}, 0.2, "full"), row(best, 0.199, "full")]
    assert verdict(refused).startswith(f"Not adopted: {key} {value:g} passes the rule truncated")
    confirmed = [*search, row({}, 0.2, "full"), row(best, 0.1, "full")]
    assert (
        verdict(confirmed) == f"Adopted: {key} {value:g} (it passes the rule at full length too)."
    )
    kept = [row(c, 0.5 + 0.05 * k) for k, c in enumerate(tool.candidates("kuka", "ddpg"))]
    assert verdict(kept) == "The own setting is kept: no candidate passes the rule."
    table = tool.summary_markdown(confirmed, ["kuka"], ["ddpg"])
    assert sum("| full |" in line for line in table) == 2  # the confirmation rows are listed too


@pytest.mark.slow
@pytest.mark.subprocess
def test_jobs_train_candidates_in_parallel_to_the_same_rows(tool, tiny_search, tmp_path):
    """``--jobs 2`` (worker processes) scores candidates, confirmations included, exactly as one
    process does: each candidate is seeded on its own. The parallel search starts from the serial
    one's rows less its last two candidates and its confirmations, so that two children run at once
    (twice, where the search proposes) rather than all nine."""
    serial = json.loads(tiny_search[1].read_text())
    kept = [r for r in serial["rows"] if r["length"] == "truncated"][:-2]
    out = tmp_path / "tune.json"
    out.write_text(json.dumps({**serial, "rows": kept}))
    assert tool.main(_tiny_argv(tmp_path, jobs=2)) == 0
    rows = {}
    for jobs, path in ((1, tiny_search[1]), (2, out)):
        got = json.loads(path.read_text())["rows"]
        rows[jobs] = {(json.dumps(r["change"]), r["length"]): r["per_seed"] for r in got}
    assert len(rows[1]) >= 7 and rows[2] == rows[1]


def test_a_resumed_candidates_seconds_count_every_call_that_trained_it(tool, tmp_path, monkeypatch):
    """A candidate resumed over several calls states its whole training time (its seeds' metrics:
    the batch's seconds per iteration), not only the last call's."""
    import argparse
    from types import SimpleNamespace

    import warp_critic.methods as methods

    seeds = [
        SimpleNamespace(
            run_dir=tmp_path / f"seed{s}", metrics=[{"seconds": 500.0}, {"seconds": 700.0}]
        )
        for s in (100, 101)
    ]
    real = methods.method

    class Resumed:  # the method, but its training returns runs resumed over calls
        def __init__(self, name):
            self.m = real(name)

        def __getattr__(self, key):
            return getattr(self.m, key)

        def train(self, cfg, **kw):
            return SimpleNamespace(seeds=seeds)

    monkeypatch.setattr(methods, "method", Resumed)
    args = argparse.Namespace(
        train_steps=tool.TRAIN_STEPS, tiny=True, seeds=[100, 101], device="cpu"
    )
    dirs, seconds = tool.train("reacher", "ours", {}, args, tmp_path / "run")
    assert dirs == [str(s.run_dir) for s in seeds] and seconds == 1200.0
