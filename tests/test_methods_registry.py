"""The method registry (``warp_critic.running.methods``): every method is one entry, and the places
that used to list methods read it."""

from __future__ import annotations

import ast
from dataclasses import fields

import pytest
from conftest import ROOT

import warp_critic.methods  # noqa: F401  (registers every method)
from warp_critic.core.errors import UserError
from warp_critic.running.methods import Method, method, methods, names, register
from warp_critic.running.task import TaskConfig

#: where a baseline's name may still be written as a string outside its own module: the paper's
#: own rows (data read from its LaTeX), a committed tuning result, and a Meta-Critic-only finding
ALLOWED_LITERALS = {
    "warp_critic/evaluation/paper.py",
    "warp_critic/reproduce/experiments/settings.py",
    "warp_critic/reproduce/report/training.py",
}


def test_every_method_is_one_complete_entry():
    entries = methods()
    assert [m.name for m in entries] == list(names())
    assert len(set(names())) == len(entries) and len({m.order for m in entries}) == len(entries)
    assert entries[0].name == "ours" and not entries[0].baseline
    for m in entries:
        assert issubclass(m.config, TaskConfig), m.name
        assert callable(m.train) and callable(m.critic_loader)
        if m.preset is not None:  # a preset names its own config's fields
            assert set(m.preset) <= {f.name for f in fields(m.config)}, m.name
            assert m.preset.get("method", m.name) == m.name


def test_unknown_method_is_a_user_error_and_a_name_is_registered_once():
    with pytest.raises(UserError, match="unknown method 'ppo'; known: ours, ddpg"):
        method("ppo")
    ddpg = method("ddpg")
    assert register(ddpg) is ddpg  # the same entry again (a module imported twice) is fine
    other = Method(**{**ddpg.__dict__, "label": "another DDPG"})
    with pytest.raises(ValueError, match="registered twice"):
        register(other)
    assert method("ddpg") is ddpg


def test_the_readers_follow_the_registry():
    from warp_critic.cli.main import build_parser
    from warp_critic.evaluation.presets import DESCRIPTIONS, PRESETS
    from warp_critic.reproduce.experiments.metatrain import STEPS_COUNTED
    from warp_critic.reproduce.experiments.settings import METHOD_LABELS
    from warp_critic.reproduce.report.plots import COLORS

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    baseline = sub.choices["baseline"]  # type: ignore[index]
    per_method = next(a for a in baseline._actions if a.dest == "method")
    assert list(per_method.choices) == list(names(baseline=True))  # type: ignore[arg-type]
    for m in methods():
        assert METHOD_LABELS[m.name] == m.label and COLORS[m.name] == m.colour
        assert STEPS_COUNTED[m.name] == m.samples_text
        if m.preset is not None:
            assert PRESETS[m.name] == m.preset and DESCRIPTIONS[m.name] == m.preset_description


@pytest.mark.slow
def test_no_module_lists_the_baselines_by_name():
    """A baseline's name as a string literal only in its own module (and the few listed data)."""
    baselines = set(names(baseline=True))
    found = []
    for path in sorted((ROOT / "warp_critic").rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        if rel in ALLOWED_LITERALS:
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Constant) and node.value in baselines:
                own = rel == f"warp_critic/methods/{str(node.value).replace('-', '_')}.py"
                if not own and rel != "warp_critic/methods/baseline_config.py":
                    found.append(f"{rel}:{node.lineno}: {node.value!r}")
    assert not found, "read the method registry instead:\n" + "\n".join(found)
