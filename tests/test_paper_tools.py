"""bench/tune_baselines.py, tools/diagnose_reacher_map.py and tools/probe_variants.py: their draws,
the probe's verdicts and their bad input."""

from __future__ import annotations

import pytest
from conftest import REACHER
from helpers import load_tool


def test_tune_draws_the_published_setting_first_without_repetition():
    tool = load_tool("tune_baselines", "bench")
    drawn = tool.settings(6, seed=0)
    assert drawn[0] == tool.PUBLISHED and len(drawn) == 6
    assert len({tuple(sorted(s.items())) for s in drawn}) == 6
    for s in drawn:
        assert all(s[k] in tool.GRID[k] for k in tool.GRID)
    assert tool.settings(6, seed=0) == drawn and tool.settings(6, seed=1) != drawn


def test_tune_one_at_a_time_adds_meta_critics_virtual_step_and_one_rule_adopts_for_both():
    """One adoption rule for both baselines: better than the published setting by more than half
    its seed spread; whether Meta-Critic's h_omega was alive does not enter it."""
    tool = load_tool("tune_baselines", "bench")
    ddpg, mc = tool.one_at_a_time("ddpg"), tool.one_at_a_time("meta-critic")
    assert len(ddpg) == 7 and ddpg[0] == tool.PUBLISHED and mc[:7] == ddpg
    assert [s.get("virtual_lr") for s in mc[7:]] == [1e-3, 1e-2]
    assert not hasattr(tool, "eligible_row")
    for method, setting in (("ddpg", ddpg[5]), ("meta-critic", mc[5])):
        published = {
            "method": method,
            "setting": tool.PUBLISHED,
            "score": 0.9,
            "per_seed": [1.0, 0.8],
        }
        for alive in (None, [0.0, 0.0], [1.0, 1.0]):
            better = {"method": method, "setting": setting, "score": 0.79, "aux_alive": alive}
            assert tool.adopted(better, published), (method, alive)  # margin 0.11 > 0.1
            assert not tool.adopted({**better, "score": 0.81}, published), (method, alive)
        assert not tool.adopted({**published, "score": 0.1}, published)  # the published itself


@pytest.mark.parametrize(
    "name, argv, words",
    [
        ("bench/tune_baselines", ["--scenes", "pendulum"], "unknown scene"),
        ("bench/tune_baselines", ["--seeds", "0,100"], "other than the reported"),
        ("bench/tune_baselines", ["--methods", "ppo"], "unknown method"),
        ("tools/diagnose_reacher_map", ["/nonexistent/run"], "not a run directory"),
        (
            "tools/reference_runs",
            ["--compare", "/nonexistent/a", "/nonexistent/b"],
            "does not exist",
        ),
        ("tools/diagnose_reacher_map", ["x", "--grid", "1"], "--grid >= 2"),
        ("tools/probe_variants", [REACHER, "--variants", "arm9.mass=1"], "unknown link 'arm9'"),
        (
            "tools/probe_variants",
            [REACHER, "--variants", "nominal", "--hold", "0"],
            "--hold must be >= 1",
        ),
    ],
)
def test_tools_bad_input_is_one_line_exit_2(name, argv, words, capsys):
    with pytest.raises(SystemExit) as e:
        folder, _, script = name.partition("/")
        load_tool(script, folder).main(argv)
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and ": error: " in err and words in err, err


@pytest.mark.slow
def test_probe_finds_the_reachers_light_links_unstable_at_its_dt_and_stable_at_half():
    """The reacher at its dt (0.01 s x 2): nominal stable, 0.25 kg links non-finite under saturated
    switching torques; the same control period at dt 0.005 s x 4 keeps them finite."""
    from warp_critic.core import runtime
    from warp_critic.running.task import TaskConfig, load_task_scene

    runtime.init()
    tool = load_tool("probe_variants")
    own, scene = load_task_scene(TaskConfig(scene=REACHER), announce=False)
    half, _ = load_task_scene(TaskConfig(scene=REACHER, dt=0.005, substeps=4), announce=False)
    assert (own.dt, own.substeps) == (0.01, 2)
    light = "arm1.mass=0.25:keep; arm2.mass=0.25:keep"
    kw = dict(worlds=16, hold=5, seed=0)
    assert tool.probe(own, scene, "", **kw)[0] == 0
    assert tool.probe(own, scene, light, **kw)[0] > 0
    bad, fastest = tool.probe(half, scene, light, **kw)
    assert bad == 0 and fastest < 1e3


@pytest.mark.slow
def test_reacher_map_shifts_keep_the_offsets_and_the_response_is_reciprocal(finished_run, capsys):
    """``diagnose_reacher_map --shifts`` on a tiny run: the unshifted row repeats the grid's own
    share, a shift moves start and goal together (same ``q0 - g``), and the measured one-step
    response to unit torques is symmetric (``dt M(q)^-1``) and changes with the elbow angle."""
    import re

    import torch

    tool = load_tool("diagnose_reacher_map")
    grid = [[0.5, 0.3], [-0.4, 2.0]]
    plain, _, _ = tool._run(str(finished_run), grid, 1, 1)
    moved, _, _ = tool._run(str(finished_run), grid, 1, 1, (1,))
    assert torch.allclose(moved.q0 - moved.goal, plain.q0 - plain.goal, atol=1e-6)
    assert torch.allclose(moved.goal[:, 1], torch.zeros(2)) and not torch.equal(moved.q0, plain.q0)
    assert tool.main([str(finished_run), "--grid", "3", "--inits", "1", "--shifts"]) == 0
    out = capsys.readouterr().out
    share = re.search(r"all: MSE<0.05 on (\d+)%", out).group(1)
    assert re.search(rf"no joint\s+{share}%", out)
    rows = re.findall(r"elbow\s+([\d.]+) rad: \[(\S+), (\S+)\] / \[(\S+), (\S+)\]", out)
    assert len(rows) == 4
    for _, a11, a21, a12, a22 in rows:
        assert float(a21) == pytest.approx(float(a12), abs=2e-3)
        assert float(a11) > 0 and float(a22) > 0
    assert float(rows[0][4]) > 2 * float(rows[2][4])  # the elbow's own response falls as it bends
