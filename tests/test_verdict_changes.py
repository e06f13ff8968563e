"""tools/verdict_changes.py: two reports' verdicts side by side, and why each change happened."""

from __future__ import annotations

import json

import pytest
from helpers import load_tool

vc = load_tool("verdict_changes")

RULE_A = "rule (comparative claims): met when ours is below in at least 75% of the cells"
RULE_B = "rule (comparative claims): met when ours is below in at least 90% of the cells"


def _claim(name: str, verdict: str, ours: str, rule: str) -> dict:
    return {"claim": name, "paper": "p", "ours": ours, "verdict": verdict, "reason": f"x. {rule}"}


def _write(path, claims):
    path.write_text(json.dumps({"claims": claims}))
    return str(path)


@pytest.fixture
def reports(tmp_path):
    before = [
        _claim("Figure 5: masses", "met", "44 of 49 cells", RULE_A),
        _claim("Figure 6: lengths", "met", "44 of 49 cells", RULE_A),
        _claim("Table 1: values", "not met", "0.0539", "rule: met when at most 0.05"),
        _claim("Figure 3: fewer steps", "not met", "ours 1.1e3", "rule: fewest steps"),
    ]
    after = [
        _claim("Figure 5: masses", "not met", "44 of 49 cells", RULE_B),  # the rule changed
        _claim("Figure 6: lengths", "met", "45 of 49 cells", RULE_A),  # numbers only: same verdict
        _claim("Table 1: values", "met", "0.0431", "rule: met when at most 0.05"),  # numbers
        _claim("Table 1: at own budget", "met", "10 of 10", RULE_A),  # new
    ]
    return _write(tmp_path / "before.json", before), _write(tmp_path / "after.json", after)


def test_each_changed_verdict_says_whether_its_rule_or_its_numbers_changed(reports):
    before, after = reports
    text = vc.block(vc.load(before), vc.load(after))
    assert "| Figure 5: masses | **met** | **not met** |" in text
    assert "| Figure 6: lengths | met | met |" in text  # a same verdict is never bold
    assert "| Table 1: at own budget | (not judged) | met |" in text
    assert "| Figure 3: fewer steps | not met | (not judged) |" in text
    assert (
        "2 of the 3 claims both reports judge changed verdict (1 claim(s) new, 1 no longer" in text
    )
    (fig5,) = [line for line in text.splitlines() if line.startswith("- **Figure 5")]
    assert "its rule changed" in fig5 and "75%" in fig5 and "90%" in fig5
    assert "its measurement is the same" in fig5
    (tab1,) = [line for line in text.splitlines() if line.startswith("- **Table 1: values")]
    assert "its rule is the same" in tab1 and '"0.0539"; after: "0.0431"' in tab1
    assert not [line for line in text.splitlines() if line.startswith("- **Figure 6")]


def test_the_rule_is_read_after_its_label_with_or_without_a_scope():
    assert vc.rule_of({"reason": "ours first. rule: met when x"}) == "met when x"
    assert (
        vc.rule_of({"reason": f"y. {RULE_A}"})
        == "met when ours is below in at least 75% of the cells"
    )
    assert vc.rule_of({"reason": "no rule quoted"}) == ""


def test_write_fills_the_block_and_check_fails_once_it_is_stale(reports, tmp_path, capsys):
    before, after = reports
    readme = tmp_path / "README.md"
    readme.write_text(f"head\n{vc.BEGIN}\nold\n{vc.END}\ntail\n")
    assert vc.main([before, after, "--check", str(readme)]) == 1
    assert vc.main([before, after, "--write", str(readme)]) == 0
    text = readme.read_text()
    assert text.startswith("head\n") and text.endswith(f"{vc.END}\ntail\n") and "old" not in text
    assert vc.main([before, after, "--check", str(readme)]) == 0
    assert vc.main([after, after, "--check", str(readme)]) == 1  # other reports: stale
    capsys.readouterr()


@pytest.mark.subprocess
def test_a_report_is_read_from_git_history_by_rev_and_path(reports, tmp_path, monkeypatch):
    """``REV:PATH``: a report as a commit holds it, named by that commit (not the moving ``HEAD``);
    read from a repository of its own, so the test runs in an exported tree too."""
    import shutil
    import subprocess

    repo = tmp_path / "repo"
    (repo / "docs").mkdir(parents=True)
    shutil.copy(reports[0], repo / "docs" / "results.json")
    git = ["git", "-c", "user.name=t", "-c", "user.email=t@t", "-C", str(repo)]
    for cmd in (["init", "-q"], ["add", "."], ["commit", "-q", "-m", "report"]):
        subprocess.run([*git, *cmd], check=True, capture_output=True)
    head = subprocess.run([*git, "rev-parse", "--short", "HEAD"], capture_output=True, text=True)
    monkeypatch.setattr(vc, "ROOT", repo)
    source, claims = vc.load("HEAD:docs/results.json")
    assert source == f"{head.stdout.strip()}:docs/results.json"
    assert [c["claim"] for c in claims] == [c["claim"] for c in vc.load(reports[0])[1]]


@pytest.mark.parametrize(
    "content, words",
    [
        (None, "no such file"),
        ("{not json", "not a reproduce report's results.json"),
        ('{"claims": []}', "not a list of claim/verdict records"),
        ('{"claims": [{"claim": 1}]}', "not a list of claim/verdict records"),
    ],
)
def test_bad_input_is_one_line_exit_2(content, words, reports, tmp_path, capsys):
    bad = tmp_path / "bad.json"
    if content is not None:
        bad.write_text(content)
    assert vc.main([str(bad), reports[1]]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{bad}: " in err and words in err, err


@pytest.mark.subprocess
def test_bad_revisions_and_blocks_are_one_line_exit_2(reports, tmp_path, capsys):
    assert vc.main(["nosuchrev0:docs/paper/results.json", reports[1]]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not in this repository's history" in err
    readme = tmp_path / "README.md"
    readme.write_text("no markers\n")
    assert vc.main([*reports, "--write", str(readme)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "needs one <!-- verdicts:begin --> line" in err
    assert readme.read_text() == "no markers\n"
