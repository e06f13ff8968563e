"""Meta-Critic's own config: its ``aux_*`` and ``virtual_lr`` settings live in ``MetaCriticConfig``
alone, another baseline's command refuses them in one line, and runs written before the split
(every baseline's config then held them) still load: the shipped Meta-Critic and DDPG runs of
``docs/paper/stages`` meta-test, and an old DDPG run resumes."""

from __future__ import annotations

import json
import lzma
import math
import shutil
from dataclasses import fields
from pathlib import Path

import pytest
import torch
from conftest import REACHER, ROOT
from helpers import tiny_baseline_cfg

from warp_critic.cli.main import main
from warp_critic.evaluation.metatest import MetaTestConfig, meta_test
from warp_critic.methods import method, methods
from warp_critic.methods.baseline_config import BaselineConfig
from warp_critic.methods.ddpg import train_ddpg
from warp_critic.methods.meta_critic import MetaCriticConfig
from warp_critic.running.config import check_fields

#: the settings only Meta-Critic reads (before 2026-12 on every baseline's config)
OWN = {"aux_lr", "aux_weight_decay", "aux_hidden", "aux_input", "aux_weight", "virtual_lr"}


def names(cls) -> set[str]:
    return {f.name for f in fields(cls)}


def test_meta_critics_settings_are_its_config_alone():
    assert method("meta-critic").config is MetaCriticConfig
    assert names(MetaCriticConfig) - names(BaselineConfig) == OWN
    for entry in methods(baseline=True):
        if entry.name != "meta-critic":
            assert not OWN & names(entry.config), entry.name
    assert MetaCriticConfig(scene=REACHER).method == "meta-critic"


@pytest.mark.parametrize(
    "argv, says",
    [
        (["ddpg", "--aux-lr", "1e-3"], "--aux-lr is a Meta-Critic setting; ddpg does not use it"),
        (["td3", "--virtual-lr=0.01"], "--virtual-lr is a Meta-Critic setting; td3 does not use"),
        (["sac", "--aux-input", "features"], "--aux-input is a Meta-Critic setting; sac does not"),
        (["meta-critic", "--policy-delay", "3"], "--policy-delay is a TD3 setting; meta-critic"),
        (["ddpg", "--temperature-lr", "1"], "--temperature-lr is a SAC setting; ddpg does not"),
    ],
)
def test_another_methods_flag_is_one_line_naming_its_owner(tmp_path, capsys, argv, says):
    name, *flags = argv
    with pytest.raises(SystemExit) as e:
        main(["baseline", name, REACHER, *flags, "--out", str(tmp_path / "run")])
    err = capsys.readouterr().err.strip().splitlines()
    assert e.value.code == 2 and len(err) == 1 and says in err[0], err
    assert not (tmp_path / "run").exists()


def test_a_flag_no_method_has_is_still_argparses_unrecognized(tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        main(["baseline", "ddpg", REACHER, "--aux-lrr", "1", "--out", str(tmp_path / "run")])
    err = capsys.readouterr().err.strip().splitlines()
    assert e.value.code == 2 and len(err) == 1 and "unrecognized arguments: --aux-lrr" in err[0]


def shipped_seed(method_name: str, dest: Path) -> Path:
    """A copy of seed 0 of the shipped reacher ``method_name`` stage (written before 2026-12, its
    config holding every ``aux_*`` key), its ``.xz`` files unpacked; ``docs/paper`` is only read."""
    (src,) = (ROOT / "docs" / "paper" / "stages").glob(f"metatrain-reacher-{method_name}-*")
    dest.mkdir(parents=True)
    for f in (src / "run" / "seed0").iterdir():
        if f.suffix == ".xz":
            (dest / f.stem).write_bytes(lzma.decompress(f.read_bytes()))
        else:
            shutil.copy2(f, dest / f.name)
    return dest


@pytest.mark.slow
@pytest.mark.parametrize("name", ["meta-critic", "ddpg"])
def test_a_shipped_run_from_before_the_split_loads_and_meta_tests(tmp_path, name):
    run = shipped_seed(name, tmp_path / name)
    saved = json.loads((run / "config.json").read_text())
    assert OWN <= set(saved) and saved["method"] == name  # what makes it an old run
    cfg = method(name).config.from_dict(saved)
    check_fields(cfg)
    kept = cfg.to_dict()
    # every field as saved (these runs also predate ``alpha``'s rename to ``metatest_alpha``)
    renamed = {("metatest_alpha" if k == "alpha" else k): v for k, v in saved.items()}
    assert all(kept[k] == renamed[k] for k in kept), name
    assert OWN & set(kept) == (OWN if name == "meta-critic" else set())  # DDPG's are dropped
    ckpt = torch.load(run / "checkpoint.pt", weights_only=False)
    assert method(name).config.from_dict(ckpt["config"]) == cfg
    out = tmp_path / "mt.json"
    result = meta_test(
        MetaTestConfig(run_dir=str(run), num_goals=1, inits=1, device="cpu", out=str(out))
    )
    assert result["method"] == name and math.isfinite(result["mean"])
    assert json.loads(out.read_text())["mean"] == result["mean"]


def old_config(d: dict) -> dict:
    """``d`` as a baseline run wrote its config before 2026-12: with Meta-Critic's settings at
    their defaults then (the same as :class:`MetaCriticConfig`'s now)."""
    old = {f.name: f.default for f in fields(MetaCriticConfig) if f.name in OWN}
    return {**d, **old}


@pytest.mark.slow
def test_an_old_ddpg_run_with_meta_critic_keys_resumes_exactly(tmp_path):
    straight = train_ddpg(
        tiny_baseline_cfg(tmp_path / "a", "ddpg", iterations=3), progress=False, record=False
    )
    out = tmp_path / "b"
    train_ddpg(tiny_baseline_cfg(out, "ddpg", iterations=2), progress=False, record=False)
    ckpt = torch.load(out / "checkpoint.pt", weights_only=False)
    ckpt["config"] = old_config(ckpt["config"])
    torch.save(ckpt, out / "checkpoint.pt")
    config = json.loads((out / "config.json").read_text())
    (out / "config.json").write_text(json.dumps(old_config(config), indent=2))
    resumed = train_ddpg(
        tiny_baseline_cfg(out, "ddpg", iterations=3, resume=True), progress=False, record=False
    )
    losses = [
        [(r["task_loss"], r.get("critic_loss")) for r in x.metrics] for x in (straight, resumed)
    ]
    assert len(losses[0]) == 3 and losses[0] == losses[1]
    assert type(resumed.config) is BaselineConfig and not OWN & set(resumed.config.to_dict())
