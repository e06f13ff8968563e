"""``reproduce``: the quick end-to-end run, resume, --only, changed settings, bad input, and the
batched evaluator against ``meta-test`` (CPU; the quick run is shared by the module's tests)."""

from __future__ import annotations

import json
import lzma
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch
from helpers import load_tool

from warp_critic.cli.main import main as cli_main
from warp_critic.core.errors import UserError
from warp_critic.reproduce.report.maps import elbow_bent


def reproduce_main(argv):
    return cli_main(["reproduce", *argv])


PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
SECTIONS = (
    "## Stages",
    "## Section 4.1",
    "## Section 4.2",
    "## Figure 3",
    "### reacher",
    "### kuka",
    "## Figures 4-6",
    "## Tables 1-3",
    "### Table 1",
    "### Table 2",
    "### Table 3",
    "### Stress table A",
    "### Stress table B",
    "## The paper's claims",
    "## Figures",
)
FIGURES = (
    "fig1_landscape.png",
    "fig2_exploration.png",
    "fig3_metatrain_reacher.png",
    "fig3_metatrain_kuka.png",
    "fig4_reacher_goals.png",
    "fig5_reacher_mass.png",
    "fig6_reacher_length.png",
)


def _stage_mtimes(out: Path) -> dict[str, float]:
    return {p.parent.name: p.stat().st_mtime_ns for p in out.glob("*/stage.json")}


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("reproduce") / "paper"
    t = time.perf_counter()
    rc = reproduce_main(["--quick", "--out", str(out), "--device", "cpu"])
    return out, rc, time.perf_counter() - t


def _stage(out: Path, name: str) -> dict:
    """The record of the stage ``name`` in ``out`` (``maps-*`` also matches ``maps-heldout-*``)."""
    (found,) = [
        d
        for p in out.glob(f"{name}-*/stage.json")
        if (d := json.loads(p.read_text()))["stage"] == name
    ]
    return found


@pytest.mark.slow
@pytest.mark.subprocess
def test_quick_end_to_end(quick):
    out, rc, _ = quick
    assert rc == 0
    report = (out / "REPORT.md").read_text()
    for section in SECTIONS:
        assert section in report, section
    assert "not run" not in report.lower()
    for name in FIGURES:
        data = (out / "figures" / name).read_bytes()
        assert data.startswith(PNG_MAGIC), name
        assert f"figures/{name}" in report
    results = json.loads((out / "results.json").read_text())
    # every table cell traces back to an existing stage file and existing run checkpoints
    # quick: Table 1 3 columns, Tables 2-3 3 + the training column, two stress tables 2 columns
    assert len(results["tables"]) == (3 + 4 + 4 + 2 + 2) * 3
    assert {c["table"] for c in results["tables"]} == {
        "table1",
        "table2",
        "table3",
        "stress_mass",
        "stress_length",
    }
    floors = [c["reach_floor"] for c in results["tables"] if c["table"].startswith("stress")]
    assert all(f is not None and f >= 0 for f in floors)
    # the maps' open-loop floor: every goal of the 4 x 4 grid and every cell of the 3 x 3 maps
    maps = _stage(out, "maps")["result"]
    floor = {k: np.asarray(v) for k, v in maps["reach_floor"].items()}
    assert floor["goals"].shape == (4, 4) and floor["mass"].shape == floor["length"].shape == (9,)
    assert all(np.isfinite(v).all() and (v >= 0).all() for v in floor.values())
    assert "Open-loop reachability floor" in report
    # every claim has a verdict computed from numbers, shown in the claims table
    assert len(results["claims"]) >= 9
    for claim in results["claims"]:
        assert claim["verdict"] in ("met", "not met", "not comparable"), claim
        assert f"**{claim['verdict']}**" in report
    assert "as in the paper" not in report
    # goal seed 1 chose the settings: Tables 1-3 and Figures 4-6 are judged on the held-out seeds
    names = [c["claim"] for c in results["claims"]]
    for fig in ("Table 1", "Table 2", "Table 3", "Figure 4", "Figure 5", "Figure 6"):
        judged = [n for n in names if n.startswith(fig)]
        assert judged and all(n.startswith(f"{fig} (held-out goal seeds 1000)") for n in judged)
    held = results["heldout"]["tables"]["table1"]
    assert {"ours", "ddpg", "meta-critic", "ours-equal-steps"} <= set(held["rows"])
    assert all(c["lo"] <= c["mean"] <= c["hi"] for r in held["rows"].values() for c in r)
    assert "Shown, not judged" in report and "Equal budgets (kuka)" in report
    for cell in results["tables"]:
        stage = out / cell["file"]
        assert stage.is_file()
        data = json.loads(stage.read_text())
        match = [
            c
            for c in data["result"]["cells"]
            if c["table"] == cell["table"]
            and c["value"] == cell["value"]
            and c["method"] == cell["method"]
        ]
        assert len(match) == 1 and match[0]["mse_mean"] == cell["mse_mean"]
        assert len(cell["runs"]) == 2  # quick: 2 seeds
        for run in cell["runs"]:
            assert (out / run).is_file(), run
        assert f"{cell['mse_mean']:.3g}({cell['mse_std']:.3g})" in report
    for entry in results["figures"]:
        assert (out / entry["file"]).is_file()
    verify = subprocess.run(
        [sys.executable, "-m", "rerun_cli", "rrd", "verify", str(out / "report.rrd")],
        capture_output=True,
        text=True,
    )
    assert verify.returncode == 0, verify.stderr


@pytest.mark.slow
def test_second_call_skips_every_stage(quick, capsys):
    out, rc, _ = quick
    assert rc == 0
    before = _stage_mtimes(out)
    # toy, landscape, 6 metatrain, maps, tables; held out: tables, maps, ours at the baselines'
    # environment steps (its meta-training and its rows)
    assert len(before) == 14
    t = time.perf_counter()
    capsys.readouterr()
    assert reproduce_main(["--quick", "--out", str(out), "--device", "cpu"]) == 0
    seconds = time.perf_counter() - t
    err = capsys.readouterr().err
    assert _stage_mtimes(out) == before
    assert err.count("complete, skipped") >= 10
    assert seconds < 20, f"the resumed call took {seconds:.1f} s"
    assert "| complete, skipped |" in (out / "REPORT.md").read_text()


@pytest.mark.slow
def test_only_toy_and_changed_setting(tmp_path, capsys):
    out = tmp_path / "r"
    assert reproduce_main(["--quick", "--only", "toy", "--out", str(out), "--device", "cpu"]) == 0
    dirs = sorted(p.name for p in out.iterdir() if p.is_dir() and p.name != "figures")
    assert len(dirs) == 1 and dirs[0].startswith("toy-")
    old = out / dirs[0] / "stage.json"
    mtime = old.stat().st_mtime_ns
    report = (out / "REPORT.md").read_text()
    assert (
        "Not run (stage `tables`)" in report and "| theta" not in report.split("## Section 4.2")[1]
    )
    assert (
        reproduce_main(
            [
                "--quick",
                "--only",
                "toy",
                "--out",
                str(out),
                "--device",
                "cpu",
                "--set",
                "toy.iters=60",
            ]
        )
        == 0
    )
    dirs2 = sorted(p.name for p in out.iterdir() if p.is_dir() and p.name != "figures")
    assert len(dirs2) == 2 and dirs[0] in dirs2
    assert old.stat().st_mtime_ns == mtime
    new = json.loads((out / [d for d in dirs2 if d != dirs[0]][0] / "stage.json").read_text())
    assert new["settings"]["iters"] == 60


@pytest.mark.parametrize(
    "argv, words",
    [
        (["--only", "toy,bogus"], "unknown stage"),
        (["--seeds", "0"], "--seeds"),
        (["--seeds", "-3"], "--seeds"),
        (["--set", "toy.nope=1"], "unknown key"),
        (["--set", "metatrain.kuka.ours.nope=1"], "unknown ours setting"),
        (["--device", "tpu"], "--device"),
        (["--only", "metatrain-kuka-bogus"], "one meta-training: metatrain-reacher-ours"),
        (["--set", "beyond.kuka.randomised.train_variants=ee.mass=5..1"], "is empty (LO > HI)"),
        (["--set", "beyond.reacher.randomised-long.train_variants=arm9.mass=1..2"], "unknown link"),
        (["--set", "beyond.kuka.randomised.seeds=[1]"], "may not be set"),
        (["--set", "beyond.reacher.pose-dynamics-full.identify.steps=3"], "unknown (known:"),
        (["--set", "beyond.reacher.pose-dynamics-full.identify.inits=0"], "must be >= 1"),
        (["--set", "beyond.reacher.pose-dynamics-full.identify.version=3"], "must be 1 or 2"),
        (
            ["--set", "beyond.reacher.pose-dynamics-full.identify.variants=arm9.mass=1..2"],
            "identify.variants=",
        ),
        (
            ["--set", "beyond.reacher.pose-dynamics-full.identify.variants=arm1.mass=5..1"],
            "is empty (LO > HI)",
        ),
        (["--set", "beyond.reacher.pose-dynamics-full.identify.variants= | "], "an empty group"),
        (["--set", 'beyond.reacher.pose-long.identify={"iterations": 5}'], "critic told them"),
    ],
)
def test_bad_input(tmp_path, capsys, argv, words):
    out = tmp_path / "o"
    rc = reproduce_main(["--quick", "--out", str(out), *argv])
    err = capsys.readouterr().err
    assert rc == 2
    assert err.count("\n") == 1 and err.startswith("warp-critic: error:") and words in err
    assert not out.exists()


@pytest.mark.slow
def test_bad_out(tmp_path, capsys):
    f = tmp_path / "file"
    f.write_text("keep me")
    assert reproduce_main(["--quick", "--out", str(f)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is a file" in err and f.read_text() == "keep me"
    d = tmp_path / "theirs"
    d.mkdir()
    (d / "notes.txt").write_text("keep me")
    assert reproduce_main(["--quick", "--out", str(d)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not a reproduce output" in err
    assert sorted(p.name for p in d.iterdir()) == ["notes.txt"]
    with pytest.raises(SystemExit) as e:
        reproduce_main(["--seeds", "x"])
    assert e.value.code == 2


@pytest.mark.slow
def test_batched_evaluator_matches_meta_test(quick, tmp_path):
    """One job of the batched evaluator (here next to other runs and variants) = meta-test on that run."""
    import torch

    from warp_critic.evaluation.metatest import MetaTestConfig, meta_test
    from warp_critic.physics.scene import Variant
    from warp_critic.reproduce.experiments.evaluate import Job, evaluate

    out, rc, _ = quick
    runs = {
        m: sorted((next(out.glob(f"metatrain-reacher-{m}-*")) / "run").glob("seed*"))
        for m in ("ours", "ddpg")
    }
    goals = torch.tensor([[0.3, -0.2], [-1.0, 0.8], [1.5, 0.1]])
    jobs = [
        Job("ours0", str(runs["ours"][0]), goals, Variant()),
        Job("ddpg1", str(runs["ddpg"][1]), goals, Variant(ee_mass=2.0)),
        Job("ours1", str(runs["ours"][1]), goals[:2], Variant(link_length=1.4)),
        Job("ddpg0", str(runs["ddpg"][0]), goals, Variant(changes="arm1.mass=2; arm2.stretch=1.4")),
    ]
    r = evaluate(jobs, inits=2, steps=3, seed=7, device="cpu", progress=False)
    for job, err in zip(jobs, r["errors"]):
        v = job.variant
        tc = MetaTestConfig(
            run_dir=job.run_dir,
            goals=job.goals.tolist(),
            inits=2,
            policy_steps=3,
            seed=7,
            device="cpu",
            ee_mass=v.ee_mass,
            link_length=v.link_length,
            variant=v.text or None,
            out=str(tmp_path / f"{job.key}.json"),
        )
        ref = np.asarray(meta_test(tc, progress=None)["final_error_all"])
        np.testing.assert_allclose(err, ref, rtol=1e-4, atol=1e-6)


@pytest.mark.slow
def test_one_descent_read_at_several_budgets_equals_separate_descents(quick):
    """``evaluate(at=...)`` (the budget sweep's one descent) gives each budget's errors exactly as a
    separate evaluation of that many steps; ``alpha_scale`` scales the run's step size."""
    import torch

    from warp_critic.physics.scene import Variant
    from warp_critic.reproduce.experiments.evaluate import Job, evaluate

    out, rc, _ = quick
    run = str(sorted((next(out.glob("metatrain-reacher-ours-*")) / "run").glob("seed*"))[0])
    goals = torch.tensor([[0.3, -0.2], [-1.0, 0.8]])
    jobs = [Job("x1", run, goals, Variant()), Job("x3", run, goals, Variant(), alpha_scale=3.0)]
    r = evaluate(jobs, inits=2, steps=3, seed=5, device="cpu", progress=False, at=(1, 3))
    for n in (1, 3):
        alone = evaluate(jobs, inits=2, steps=n, seed=5, device="cpu", progress=False)
        for k in range(2):
            np.testing.assert_allclose(r["errors_at"][n][k], alone["errors"][k], rtol=1e-5)
    np.testing.assert_array_equal(r["errors_at"][3][0], r["errors"][0])
    assert not np.allclose(r["errors"][0], r["errors"][1])  # 3x the step: other policies
    with pytest.raises(UserError, match="between 1 and the 3 steps"):
        evaluate(jobs, inits=2, steps=3, seed=5, device="cpu", progress=False, at=(4,))


@pytest.mark.slow
def test_a_diverged_world_is_inf_and_leaves_the_others_alone(quick):
    """A variant whose worlds go non-finite (1/1000 of the reacher's masses and inertias at its dt)
    does not stop the evaluation: its errors are inf and counted, and the job beside it gets
    exactly the numbers it gets alone (the worlds are independent)."""
    import torch

    from warp_critic.physics.scene import Variant
    from warp_critic.reproduce.experiments.evaluate import Job, evaluate, pool_errors

    out, rc, _ = quick
    run = str(sorted((next(out.glob("metatrain-reacher-ours-*")) / "run").glob("seed*"))[0])
    goals = torch.tensor([[0.3, -0.2], [-1.0, 0.8]])
    light = Variant(changes="arm1.mass=0.001:scale; arm2.mass=0.001:scale")
    jobs = [Job("nominal", run, goals, Variant()), Job("light", run, goals, light)]
    r = evaluate(jobs, inits=2, steps=2, seed=3, device="cpu", progress=False)
    alone = evaluate(jobs[:1], inits=2, steps=2, seed=3, device="cpu", progress=False)
    assert np.array_equal(r["errors"][0], alone["errors"][0]) and np.isfinite(r["errors"][0]).all()
    assert np.isinf(r["errors"][1]).any() and r["diverged"] == int(np.isinf(r["errors"][1]).sum())
    assert alone["diverged"] == 0
    cell = pool_errors([r["errors"][1]], 2)
    assert cell["mse_mean"] == float("inf") and cell["diverged"] == r["diverged"]


@pytest.mark.slow
def test_grid_figure_shows_a_diverged_cell_in_black(tmp_path):
    from warp_critic.reproduce.experiments.settings import METHODS
    from warp_critic.reproduce.report import paper as rp
    from warp_critic.reproduce.report.plots import figure

    values = [0.5, 1.0]
    cells = [{"mse_mean": v} for v in (0.01, 0.2, float("inf"), 0.05)]
    M = {"masses": values, "trained_mass": [1.0, 1.0], **{"mass": {m: cells for m in METHODS}}}
    path = tmp_path / "grid.png"
    rp.plot_grid_2d(path, M, "mass", figure)
    import matplotlib.image

    img = matplotlib.image.imread(path)
    assert (img[..., :3].sum(-1) < 0.05).mean() > 0.05  # black cells drawn (text alone: 0.9%)
    assert rp.diverged_line(3).startswith("3 evaluated world(s) went non-finite")


@pytest.mark.slow
def test_interrupted_metatrain_resumes(tmp_path, capsys):
    """A sub-stage without stage.json (killed mid-training) resumes its run directories to the end;
    seed directories without a checkpoint (killed before the first one) are started afresh."""
    from warp_critic.reproduce.engine.stages import prepare_out
    from warp_critic.reproduce.experiments.metatrain import run_metatrain_stage
    from warp_critic.reproduce.experiments.plan import ReproduceConfig, plan

    out = prepare_out(tmp_path / "r")
    settings = ReproduceConfig(out=out, quick=True, seeds=2).validate()
    st = plan(settings)["metatrain-reacher-ours"]
    d = out / st.dir_name
    values = dict(settings["metatrain"]["reacher"]["ours"], iterations=3)
    run_metatrain_stage(
        d, "reacher", "ours", values, [0, 1], "cpu", progress=False
    )  # "killed" after 3 iterations
    lines = (d / "run" / "seed0" / "metrics.jsonl").read_text().splitlines()
    assert len(lines) == 3 and not (d / "stage.json").exists()
    other = plan(settings)["metatrain-reacher-ddpg"]
    stray = out / other.dir_name / "run" / "seed0"
    stray.mkdir(parents=True)
    (stray / ".warp-critic-run").write_text("{}")  # claimed, but no checkpoint was ever written
    assert (
        reproduce_main(["--quick", "--only", "metatrain", "--out", str(out), "--device", "cpu"])
        == 0
    )
    data = json.loads((d / "stage.json").read_text())
    rows = [json.loads(x) for x in (d / "run" / "seed0" / "metrics.jsonl").read_text().splitlines()]
    assert [r["iteration"] for r in rows] == list(range(6))
    assert rows[:3] == [
        json.loads(x) for x in lines
    ]  # the first three iterations were kept, not retrained
    assert data["result"]["seeds"]["0"]["iteration"] == list(range(6))
    assert (stray / "checkpoint.pt").is_file()


@pytest.mark.slow
def test_carried_stages_resume_on_another_machine(quick, tmp_path, capsys):
    """save -> restore without the maps and tables: reproduce reruns only those two, from the slim
    meta-training checkpoints, to the same cells; the archive holds no optimiser or buffer state."""
    import torch

    from warp_critic.reproduce.experiments.records import CARRY

    out, rc, _ = quick
    assert rc == 0
    carry = load_tool("carry_stages")
    archive = tmp_path / "archive"
    assert carry.main(["save", str(out), str(archive)]) == 0
    calls_saved = (out / "ledger.jsonl").read_text().count('"event": "start"')
    names = {p.name for p in archive.iterdir() if p.is_dir()}
    assert len(names) == 14 and not list(archive.rglob("*.rrd"))
    assert {p.name for p in archive.iterdir() if not p.is_dir()} == {"ledger.jsonl.xz"}
    ckpts = list(archive.rglob("checkpoint.pt"))
    assert len(ckpts) == 7 * 2  # 7 meta-trainings (ours twice on the KUKA) x 2 quick seeds
    from warp_critic.physics.scene import scenes_dir

    shipped = str(scenes_dir().resolve())
    for c in ckpts:
        ckpt = torch.load(c, weights_only=True)
        assert not set(ckpt) & set(CARRY.training_only), c
        # no machine's folders: a shipped scene is named scenes/NAME (found by its content hash)
        assert ckpt["scene_file"].startswith("scenes/") and ckpt["config"]["scene"].startswith(
            "scenes/"
        ), c
        config = lzma.decompress((c.parent / "config.json.xz").read_bytes()).decode()
        assert shipped not in config and str(out) not in config, c
        # the run's own directory as it lies in the output: STAGE/run/seedN, no machine's folder
        rel = c.parent.relative_to(archive).as_posix()
        assert ckpt["config"]["out"] == rel and json.loads(config)["out"] == rel, c
    # JSON is stored compressed; a run's metrics only where the report reads them (Meta-Critic's
    # auxiliary-loss columns), never ours' or DDPG's (their curves are in stage.json)
    assert not list(archive.rglob("*.json")) and not list(archive.rglob("*.jsonl"))
    metrics = sorted(archive.rglob("metrics.jsonl.xz"))
    assert metrics and all("-meta-critic-" in str(m) for m in metrics)
    from warp_critic.methods.meta_critic import AUX_KEYS

    for m in metrics:
        rows = [json.loads(r) for r in lzma.decompress(m.read_bytes()).decode().splitlines()]
        assert rows and all(set(r) <= set(AUX_KEYS) and "aux_loss" in r for r in rows), m
    # a second save copies nothing; a differing stage in the archive is refused on one line
    assert carry.main(["save", str(out), str(archive)]) == 0
    assert "0 stage(s) copied" in capsys.readouterr().out
    for name in [n for n in names if n.startswith(("maps-", "tables-"))]:
        import shutil

        shutil.rmtree(archive / name)
    other = tmp_path / "other"
    assert carry.main(["restore", str(archive), str(other)]) == 0
    capsys.readouterr()
    assert reproduce_main(["--quick", "--out", str(other), "--device", "cpu"]) == 0
    err = capsys.readouterr().err
    assert "4 stage(s) to run" in err  # maps, tables, tables-heldout, maps-heldout
    cells = {
        (c["table"], c["value"], c["method"]): c["mse_mean"]
        for c in json.loads((out / "results.json").read_text())["tables"]
    }
    again = {
        (c["table"], c["value"], c["method"]): c["mse_mean"]
        for c in json.loads((other / "results.json").read_text())["tables"]
    }
    assert again == cells
    # the restored stages came with the calls that ran them: none is "carried in", and the ledger
    # counts the first machine's calls and this one's
    ledger = json.loads((other / "results.json").read_text())["ledger"]
    assert ledger["stages_before_ledger"] == [] and ledger["calls"] == calls_saved + 1
    # restored plain: the same records and the report's auxiliary-loss shares from thinned metrics
    for name in names - {n for n in names if n.startswith(("maps-", "tables-"))}:
        assert (other / name / "stage.json").read_bytes() == (
            out / name / "stage.json"
        ).read_bytes()
    mc = json.loads((other / "results.json").read_text())["metatrain"]
    was = json.loads((out / "results.json").read_text())["metatrain"]
    assert [v.get("aux_alive") for v in mc.values()] == [v.get("aux_alive") for v in was.values()]
    stage = next(p for p in archive.glob("toy-*/stage.json.xz"))
    text = lzma.decompress(stage.read_bytes()).decode()
    stage.write_bytes(lzma.compress(text.replace('"seconds"', '"secs"').encode()))
    with pytest.raises(SystemExit) as e:
        carry.main(["save", str(out), str(archive)])
    assert e.value.code == 2
    assert "edited or damaged" in capsys.readouterr().err


@pytest.mark.slow
def test_publish_writes_the_report_beside_the_records_it_read(quick, tmp_path, capsys):
    """publish: REPORT.md, results.json, figures and each read stage's records, no runs; an earlier
    report's records and figures go, the folder's other contents stay; bad input is one line."""
    out, rc, _ = quick
    assert rc == 0
    carry = load_tool("carry_stages")
    dest = tmp_path / "docs"
    (dest / "stages" / "toy-0000000000").mkdir(parents=True)  # a carried stage: never touched
    (dest / "stages" / "toy-0000000000" / "stage.json").write_text("{}")
    (dest / "README.md").write_text("kept")
    (dest / "tables-0000000000").mkdir()  # the earlier report's record
    (dest / "tables-0000000000" / "stage.json").write_text("{}")
    (dest / "figures").mkdir()
    (dest / "figures" / "fig9_gone.png").write_bytes(PNG_MAGIC)
    assert carry.main(["publish", str(out), str(dest)]) == 0
    printed = capsys.readouterr().out
    results = json.loads((dest / "results.json").read_text())
    read = {v["dir"] for v in results["stages"].values()}
    assert f"{len(read)} stage record(s)" in printed and "tables-0000000000" in printed
    # the records of the stages it read are in the archive dest/stages, none beside the report
    from warp_critic.reproduce.engine.carry import complete_stages
    from warp_critic.reproduce.experiments.records import stage_problem

    archived = complete_stages(dest / "stages", stage_problem)
    assert read <= set(archived) and "toy-0000000000" in {
        p.name for p in (dest / "stages").iterdir()
    }
    assert (dest / "REPORT.md").read_bytes() == (out / "REPORT.md").read_bytes()
    assert {p.name for p in (dest / "figures").iterdir()} == {
        p.name for p in (out / "figures").glob("*.png")
    }
    assert {p.name for p in dest.iterdir() if p.is_dir()} == {"figures", "stages"}
    assert (dest / "README.md").read_text() == "kept"
    # the published ledger: the same calls, the output folder by its name, not this machine's path
    ledger = (dest / "ledger.jsonl").read_text()
    assert str(out) not in ledger and f"--out {out.name} " in ledger
    assert len(ledger.splitlines()) == len((out / "ledger.jsonl").read_text().splitlines())
    assert (dest / "stages" / "toy-0000000000" / "stage.json").read_text() == "{}"
    for name in read:
        assert archived[name] == json.loads((out / name / "stage.json").read_text())
        assert not list((dest / "stages" / name).rglob("*.rrd"))
    tables = next(n for n in read if n.startswith("tables-") and "heldout" not in n)
    raw = dest / "stages" / tables / "errors.json.xz"  # the raw cells the report cites
    assert lzma.decompress(raw.read_bytes()) == (out / tables / "errors.json").read_bytes()
    assert f"{tables}/errors.json" in (dest / "REPORT.md").read_text()
    import shutil

    from warp_critic.reproduce.engine.stages import MARKER

    # a recipe's meta-training is archived as its record alone, also one archived whole before
    mine = tmp_path / "with-recipes"
    shutil.copytree(out, mine, ignore=shutil.ignore_patterns("*.rrd", ".lock"))
    nominal = next(n for n in read if n.startswith("metatrain-reacher-ours-"))
    recipes = []
    for i in range(2):
        name = f"beyond-metatrain-reacher-r{i}-000000000{i}"
        shutil.copytree(mine / nominal, mine / name)
        record = json.loads((mine / name / "stage.json").read_text())
        (mine / name / "stage.json").write_text(
            json.dumps({**record, "stage": name.rsplit("-", 1)[0]})
        )
        recipes.append(name)
    shutil.copytree(mine / recipes[1], dest / "stages" / recipes[1])  # an earlier publish's, whole
    book = json.loads((mine / "results.json").read_text())
    book["stages"].update({n: {"dir": n} for n in recipes})
    (mine / "results.json").write_text(json.dumps(book))
    assert carry.main(["publish", str(mine), str(dest)]) == 0
    for name in recipes:
        kept = [p.name for p in (dest / "stages" / name).iterdir()]
        assert kept in (["stage.json.xz"], ["stage.json"]), (name, kept)
    # of a paper meta-training, the first seed's critic is published; a note stands in for the
    # other seeds' (their records and configs stay), and reading one says why on one line
    from warp_critic.core.errors import UserError
    from warp_critic.running.rundir import OMITTED, load_checkpoint_file

    runs = dest / "stages" / nominal / "run"
    assert [p.parent.name for p in runs.glob("seed*/checkpoint.pt")] == ["seed0"]
    assert sorted(p.parent.name for p in runs.glob(f"seed*/{OMITTED}")) == ["seed1"]
    assert (runs / "seed1" / "config.json.xz").is_file()
    with pytest.raises(UserError, match="not in this archive .a published report keeps"):
        load_checkpoint_file(runs / "seed1" / "checkpoint.pt")
    assert "run(s) published without their checkpoint" in printed  # the first call omitted them
    # the report regenerates from the published archive alone: every stage is complete there
    again = tmp_path / "again"
    assert carry.main(["restore", str(dest / "stages"), str(again)]) == 0
    assert reproduce_main(["--quick", "--out", str(again), "--device", "cpu"]) == 0
    assert "0 stage(s) to run" in capsys.readouterr().err
    volatile = {"stages", "command", "call", "ledger", "sections"}  # the call, not the numbers
    first, second = (json.loads((o / "results.json").read_text()) for o in (out, again))
    assert {k: v for k, v in second.items() if k not in volatile} == {
        k: v for k, v in first.items() if k not in volatile
    }

    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / MARKER).write_text("{}")  # a reproduce output that never wrote its report
    for argv, words in (
        (["publish", str(empty), str(dest)], "results.json: missing; run reproduce"),
        (["publish", str(tmp_path / "nothing"), str(dest)], "not a reproduce output"),
        (["publish", str(dest / "stages"), str(dest)], "not a reproduce output"),
    ):
        with pytest.raises(SystemExit) as e:
            carry.main(argv)
        assert e.value.code == 2
        err = capsys.readouterr().err.strip()
        assert words in err and len(err.splitlines()) == 1


def test_a_cell_with_a_diverged_world_has_no_spread_and_no_warning():
    """A diverged world (``inf``) makes the cell's mean ``inf`` and its spreads, pooled and per
    seed, ``nan``: said as such, not by numpy's ``inf - inf`` with a RuntimeWarning."""
    import warnings

    from warp_critic.reproduce.experiments.evaluate import pool_errors

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        cell = pool_errors([np.array([[1.0, np.inf]]), np.array([[2.0, 4.0]])], 2)
    assert cell["mse_mean"] == float("inf") and cell["diverged"] == 1 and cell["n"] == 4
    assert np.isnan(cell["mse_std"]) and np.isnan(cell["mse_std_per_seed"][0])
    assert cell["mse_std_per_seed"][1] == 0.5 and cell["mse_per_seed"] == [float("inf"), 1.5]


@pytest.mark.slow
def test_every_table_cell_is_pooled_from_its_raw_errors_read_as_float32(quick):
    """``errors.json`` holds each raw error as the shortest decimal of its float32 (half the size
    compressed): read as float32, the raw errors give every cell of the tables stage exactly."""
    from warp_critic.reproduce.experiments.evaluate import pool_errors

    out, rc, _ = quick
    assert rc == 0
    (folder,) = [
        p.parent
        for p in out.glob("tables-*/stage.json")
        if json.loads(p.read_text())["stage"] == "tables"
    ]
    data = json.loads((folder / "stage.json").read_text())
    raw = json.loads((folder / "errors.json").read_text())["jobs"]
    first = raw[0]["final_sq_error"][0][0]
    assert len(repr(first)) <= 12, first  # not float64's 17 digits
    dof = data["result"]["dof"]
    for cell in data["result"]["cells"]:
        errs = [
            np.asarray(j["final_sq_error"], dtype=np.float32).astype(np.float64)
            for j in raw
            if (j["table"], j["column"], j["method"])
            == (cell["table"], cell["column"], cell["method"])
        ]
        again = pool_errors(errs, dof)
        assert again["mse_mean"] == cell["mse_mean"] and again["n"] == cell["n"], cell["table"]


@pytest.mark.slow
def test_republish_publishes_and_writes_every_generated_block(quick, tmp_path, capsys):
    """tools/republish.py: the report and its stages published, the replaced report's verdicts
    beside the new ones (a changed one in bold), the ledger's calls and the folder's contents
    written where the page has their markers; a run with carried stages is refused untouched."""
    out, rc, _ = quick
    assert rc == 0
    tool = load_tool("republish")
    results = json.loads((out / "results.json").read_text())
    flipped = results["claims"][0]
    old = {"claims": [{**flipped, "verdict": "met" if flipped["verdict"] != "met" else "not met"}]}
    (tmp_path / "old.json").write_text(json.dumps(old))
    dest = tmp_path / "paper"
    dest.mkdir()
    (dest / "results.json").write_text(json.dumps(old))  # the replaced report
    markers = ("verdicts", "calls", "contents")
    (dest / "README.md").write_text(
        "".join(f"<!-- {m}:begin -->\n<!-- {m}:end -->\n" for m in markers)
    )
    (dest / "figures").mkdir()
    (dest / "figures" / "gone.png").write_bytes(PNG_MAGIC)  # the replaced report's figure
    argv = [str(out), "--dest", str(dest), "--before", str(tmp_path / "old.json")]
    # refused before anything is written: a quick run's report, a folder of other files
    assert tool.main([*argv, "--readme", str(tmp_path / "none.md")]) == 2
    assert "a --quick run's report" in capsys.readouterr().err
    mine = tmp_path / "mine"
    (mine / "figures").mkdir(parents=True)
    (mine / "figures" / "plot.png").write_bytes(PNG_MAGIC)
    assert tool.main([str(out), "--dest", str(mine), "--before", argv[-1], "--allow-quick"]) == 2
    assert "holds files but no published report" in capsys.readouterr().err
    assert [p.name for p in mine.rglob("*")] == ["figures", "plot.png"]
    assert not (dest / "REPORT.md").exists()
    argv.append("--allow-quick")
    assert tool.main([*argv, "--readme", str(tmp_path / "none.md")]) == 0
    page = (dest / "README.md").read_text()
    assert f"| {flipped['claim']} | **" in page and "changed verdict" in page
    assert "| call | start (UTC) |" in page and "files besides this page" in page
    assert not (dest / "figures" / "gone.png").exists() and (dest / "REPORT.md").is_file()
    assert "run(s) without their checkpoint" in capsys.readouterr().out
    # a report with carried stages: refused on one line, the folder untouched
    fake = tmp_path / "carried"
    fake.mkdir()
    ledger = {"stages_before_ledger": ["toy-e95b4993a1"]}
    (fake / "results.json").write_text(json.dumps({"ledger": ledger}))
    before = sorted(str(p) for p in dest.rglob("*"))
    assert tool.main([str(fake), "--dest", str(dest), "--before", str(tmp_path / "old.json")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "1 stage(s) of its report were carried in" in err
    assert sorted(str(p) for p in dest.rglob("*")) == before


def test_a_published_ledger_names_the_output_folder_as_the_report_did(tmp_path):
    """Each call that gave the output folder's absolute path names it as shown; a call on another
    folder, a record without a command and a torn last line are kept byte for byte."""
    from warp_critic.reproduce.engine.ledger_text import portable_ledger

    out = tmp_path / "runs" / "paper"
    out.mkdir(parents=True)
    mine = {"call": "a", "command": f"warp-critic reproduce --out {out} --beyond", "event": "start"}
    other = {"call": "b", "command": "warp-critic reproduce --out /elsewhere/x", "event": "start"}
    beat = {"call": "a", "event": "alive", "time": "t"}
    lines = [json.dumps(r, sort_keys=True) + "\n" for r in (mine, other, beat)] + ['{"torn']
    text = portable_ledger("".join(lines), out, "runs/paper")
    got = text.splitlines(keepends=True)
    assert json.loads(got[0])["command"] == "warp-critic reproduce --out runs/paper --beyond"
    assert got[1:] == lines[1:] and str(tmp_path) not in text


def test_an_archive_carries_the_calls_that_ran_its_stages_over_sittings(tmp_path):
    """A run resumed over sittings on fresh machines from an archive it commits: ``save`` merges
    the output's ledger into the archive's (no machine's folder in it), ``restore`` merges it into
    the next machine's output, and the stages the first machine's calls completed are then no
    stage "completed by no call of this ledger". A torn line (a call writing) is dropped, never
    merged into the middle of a ledger."""
    from warp_critic.reproduce.engine import carry, ledger, ledger_text
    from warp_critic.reproduce.engine.stages import MARKER
    from warp_critic.reproduce.experiments.records import CARRY

    def rec(**r):
        return json.dumps(r, sort_keys=True) + "\n"

    one, two, archive = tmp_path / "one" / "paper", tmp_path / "two" / "paper", tmp_path / "arch"
    one.mkdir(parents=True)
    (one / MARKER).write_text("{}")
    cmd = f"warp-critic reproduce --out {one}"
    first = [
        rec(event="start", call="a", command=cmd, time="2026-12-01T10:00:00Z"),
        rec(
            event="stage",
            call="a",
            stage="toy",
            dir="toy-e95b4993a1",
            seconds=2.0,
            time="2026-12-01T10:00:02Z",
        ),
    ]
    (one / "ledger.jsonl").write_text("".join(first) + '{"event": "ali')
    assert carry.save(one, archive, CARRY) == carry.Carried([], [])
    assert carry.restore(archive, two, CARRY) == carry.Carried([], [])
    carried = (two / "ledger.jsonl").read_text()
    assert str(tmp_path) not in carried and "--out paper" in carried
    assert [json.loads(x)["event"] for x in carried.splitlines()] == ["start", "stage"]
    # the next sitting: its own call, then a save; the archive holds both sittings' calls, once
    (two / "ledger.jsonl").write_text(
        carried + rec(event="start", call="b", time="2026-12-02T09:00:00Z")
    )
    carry.save(two, archive, CARRY)
    carry.save(two, archive, CARRY)
    both = lzma.decompress((archive / carry.ARCHIVED_LEDGER).read_bytes()).decode()
    assert [json.loads(x)["call"] for x in both.splitlines()] == ["a", "a", "b"]
    s = ledger.summary(ledger.read(two))
    n = ledger.numbers(s, {"toy-e95b4993a1": 2.0, "landscape-08f0d79b23": 160.0})
    assert n["stages_before_ledger"] == ["landscape-08f0d79b23"] and n["calls"] == 2
    assert ledger_text.merge("", "") == "" and ledger_text.merge(
        first[0], "".join(first)
    ) == "".join(first)


def test_an_archive_names_a_shipped_scene_from_any_checkout_as_scenes_name():
    """A run trained from another checkout (``/elsewhere/scenes/kuka.usda``) is archived as
    ``scenes/kuka.usda``, as one of this install's is: an archive names no machine's folders. A
    file that is no shipped scene keeps its path (its run reads it there or fails on one line)."""
    from warp_critic.physics.scene import scenes_dir
    from warp_critic.reproduce.engine.carry import _portable

    here = str(scenes_dir().resolve() / "reacher.usda")
    record = {
        "scene": "/elsewhere/checkout/scenes/kuka.usda",
        "scene_file": here,
        "scene_path": "/elsewhere/checkout/scenes/mine.usda",
        "seed": 3,
    }
    assert _portable(record) == {
        "scene": "scenes/kuka.usda",
        "scene_file": "scenes/reacher.usda",
        "scene_path": "/elsewhere/checkout/scenes/mine.usda",
        "seed": 3,
    }
    assert (
        _portable({"scene": "/elsewhere/robots/kuka.usda"})["scene"]
        == "/elsewhere/robots/kuka.usda"
    )


@pytest.mark.slow
def test_only_one_beyond_evaluation_plans_it_and_what_it_reads():
    from warp_critic.reproduce.experiments.plan import ReproduceConfig, needed, plan

    rc = ReproduceConfig(out="unused", only=["beyond-maps"], quick=True)
    settings = rc.validate()
    assert rc.selected() == ["beyond-maps"] and rc.plans_beyond
    first, second = needed(rc, plan(settings, beyond=True))
    assert second == ["beyond-maps"]
    assert sorted(first) == [
        "beyond-metatrain-reacher-history-randomised-long",
        "beyond-metatrain-reacher-pose-dynamics-full",
        "beyond-metatrain-reacher-pose-long",
        "beyond-metatrain-reacher-pose-randomised-full",
        "beyond-metatrain-reacher-pose-randomised-long",
        "beyond-metatrain-reacher-randomised-long",
        "beyond-metatrain-reacher-wide-long",
        "metatrain-reacher-ours",
    ]
    # --beyond as well: --only still runs only the stage named and what it reads, each once
    both = ReproduceConfig(out="unused", only=["beyond-maps"], quick=True, beyond=True)
    first2, second2 = needed(both, plan(both.validate(), beyond=True))
    assert second2 == ["beyond-maps"] and sorted(first2) == sorted(first)
    assert len(first2) == len(set(first2))


def test_elbow_bent_marks_the_goals_past_a_right_angle_row_major():
    res = {"axis_q1": [-1.0, 0.0, 1.0], "axis_q2": [-2.0, -1.5, 0.0, 1.6]}
    bent = elbow_bent(res)
    assert bent.shape == (12,)
    # q1 major: every row of 4 goals repeats the q2 pattern
    assert bent.tolist() == [True, False, False, True] * 3


@pytest.mark.slow
def test_beyond_runs_apart_from_the_paper(quick, tmp_path, capsys):
    """--only beyond on a copy of the quick output: the paper's stages are found complete (their
    hashes do not depend on the recipes), the recipes train and are evaluated next to the nominal
    critic, and the report's "Beyond the paper" section has computed verdicts, outside the claims."""
    import shutil

    from warp_critic.reproduce.experiments.plan import plan
    from warp_critic.reproduce.experiments.settings import default_settings

    settings = default_settings(True, 2)
    paper, both = plan(settings), plan(settings, beyond=True)
    assert {k: v.hash for k, v in paper.items()} == {
        k: both[k].hash for k in paper
    }  # the recipes change no stage of the paper
    assert sorted(set(both) - set(paper)) == [
        "beyond-maps",
        "beyond-metatrain-kuka-randomised",
        "beyond-metatrain-kuka-randomised-history",
        "beyond-metatrain-reacher-history-randomised-long",
        "beyond-metatrain-reacher-pose-dynamics-full",
        "beyond-metatrain-reacher-pose-long",
        "beyond-metatrain-reacher-pose-randomised-full",
        "beyond-metatrain-reacher-pose-randomised-long",
        "beyond-metatrain-reacher-randomised-long",
        "beyond-metatrain-reacher-wide-long",
        "beyond-tables",
    ]
    out, rc, _ = quick
    assert rc == 0
    other = tmp_path / "paper"
    shutil.copytree(out, other, ignore=shutil.ignore_patterns(".lock"))
    capsys.readouterr()
    assert (
        reproduce_main(["--quick", "--out", str(other), "--only", "beyond", "--device", "cpu"]) == 0
    )
    assert "11 stage(s) to run" in capsys.readouterr().err
    report = (other / "REPORT.md").read_text()
    beyond = report[report.index("## Beyond the paper") :]
    assert "### Targets" in beyond and "randomised" in beyond
    results = json.loads((other / "results.json").read_text())
    targets = results["beyond"]["targets"]
    # 7 reacher recipes and one identified, 2 KUKA recipes x (goals + 2 maps; Table 1 + 2 tables)
    assert len(targets) == 8 * 3 + 2 * 3
    assert "pose-dynamics-full-identified" in results["beyond"]["maps"]  # its own row
    # the goal grid split by the arrival's elbow: the two parts add up to the whole grid's share
    (bmaps_stage,) = [json.loads(p.read_text()) for p in other.glob("beyond-maps-*/stage.json")]
    bent = elbow_bent(bmaps_stage["result"])
    for m, sh in results["beyond"]["maps"].items():
        if m == "open-loop floor":
            continue
        whole = (~bent).sum() * sh["goals_elbow_within_90"] + bent.sum() * sh["goals_elbow_past_90"]
        assert whole / bent.size == pytest.approx(sh["goals"], abs=1e-9)
    # each reacher target names the share the open-loop floor reaches, from the stage's own floor
    assert all("open-loop floor" in t["measured"] for t in targets if "reacher" in t["target"])
    assert "| open-loop floor |" in beyond
    for t in targets:
        assert isinstance(t["met"], bool)
        assert (
            f"| {t['target']} | {t['measured']} | **{'met' if t['met'] else 'not met'}** |"
            in beyond
        )
    assert not any("randomised" in c["claim"] for c in results["claims"])
    rows = results["beyond"]["training"]
    assert set(rows) == {
        "reacher/ours",
        "reacher/history-randomised-long",
        "reacher/pose-dynamics-full",
        "reacher/pose-dynamics-full-identified",
        "reacher/pose-long",
        "reacher/pose-randomised-full",
        "reacher/pose-randomised-long",
        "reacher/randomised-long",
        "reacher/wide-long",
        "kuka/ours",
        "kuka/randomised",
        "kuka/randomised-history",
    }
    # the floors depend on no critic: beyond-maps takes the paper's maps stage's, not computes them
    maps = _stage(other, "maps")
    (bmaps,) = [json.loads(p.read_text()) for p in other.glob("beyond-maps-*/stage.json")]
    assert bmaps["result"]["reach_floor_from"] == f"maps-{maps['hash']}"
    assert bmaps["result"]["reach_floor"] == maps["result"]["reach_floor"]
    # the told recipe's seeds each got an identifier, seeded by the seed, which the maps read
    told = next(other.glob("beyond-metatrain-reacher-pose-dynamics-full-*/stage.json"))
    seeds = json.loads(told.read_text())["result"]["seeds"]
    for seed, v in seeds.items():
        ident = told.parent / v["identified"]["run_dir"]
        assert ident.name == f"seed{seed}-identified" and v["identified"]["iterations"] == 3
        assert "identifier_state" in torch.load(ident / "checkpoint.pt", weights_only=False)
    stage = next(other.glob("beyond-metatrain-kuka-randomised-[0-9a-f]*/stage.json"))
    run = stage.parent / json.loads(stage.read_text())["result"]["seeds"]["0"]["run_dir"]
    first = json.loads((run / "metrics.jsonl").read_text().splitlines()[0])
    assert len(first["train_variant_values"]) == 4 * 2  # quick: 4 goals x 2 worlds


def test_beyond_maps_takes_floors_only_from_a_maps_stage_of_the_same_inputs(tmp_path):
    """The floors of a maps stage are reused only with the same settings and nominal runs."""
    from warp_critic.reproduce.engine.stage import Stage
    from warp_critic.reproduce.engine.stages import STAGE_FILE, STAGE_KIND
    from warp_critic.reproduce.experiments.units import paper_maps_floors

    nominal = {"metatrain-reacher-ours": "metatrain-reacher-ours-aaaa"}
    settings = {"grid": 3, "reach_iterations": 5}
    st = Stage("beyond-maps", "maps", settings, dict(nominal, other="x"), "0")

    def stage(name, settings, depends, floor=True):
        d = tmp_path / name
        d.mkdir()
        result = {"reach_floor": {"goals": [[0.0]]}} if floor else {}
        record = {"kind": STAGE_KIND, "group": "maps", "settings": settings, "depends": depends}
        (d / STAGE_FILE).write_text(json.dumps({**record, "result": result}))

    assert paper_maps_floors(tmp_path, st) is None
    stage("maps-1", {"grid": 4, "reach_iterations": 5}, nominal)  # other grid
    stage("maps-2", settings, {"metatrain-reacher-ours": "metatrain-reacher-ours-bbbb"})
    stage("maps-3", settings, nominal, floor=False)  # computed no floor
    assert paper_maps_floors(tmp_path, st) is None
    stage("maps-4", settings, {**nominal, "metatrain-reacher-ddpg": "d"})
    assert paper_maps_floors(tmp_path, st) == "maps-4"


@pytest.mark.slow
def test_ledger_records_every_call_and_a_refused_call_writes_nothing(tmp_path, capsys):
    from warp_critic.reproduce.engine import ledger

    out = tmp_path / "r"
    args = ["--quick", "--only", "toy", "--out", str(out), "--device", "cpu"]
    assert reproduce_main(args) == 0
    assert reproduce_main(args) == 0  # every stage complete: a call that runs nothing
    rows = ledger.read(out)
    assert [r["event"] for r in rows] == ["start", "stage", "end", "start", "end"]
    assert rows[1]["stage"] == "toy" and rows[2]["stages_run"] == ["toy"]
    assert rows[1]["dir"].startswith("toy-") and (out / rows[1]["dir"] / "stage.json").is_file()
    assert rows[4]["stages_run"] == [] and {rows[2]["status"], rows[4]["status"]} == {"done"}
    assert rows[0]["machine"]["device"] == "cpu" and rows[0]["selected"] == ["toy"]
    assert rows[0]["call"] == rows[2]["call"] != rows[3]["call"]
    text = (out / "REPORT.md").read_text()
    assert "- ledger (`ledger.jsonl`): 2 call(s) on this folder" in text
    assert "sum of the report's 1 stage times" in text and "by no call of this ledger" not in text
    book = json.loads((out / "results.json").read_text())["ledger"]
    assert book["calls"] == 2 and book["stages_before_ledger"] == []
    before = (out / "ledger.jsonl").read_bytes()
    capsys.readouterr()
    assert reproduce_main([*args, "--set", "toy.nope=1"]) == 2  # refused: writes nothing
    assert (out / "ledger.jsonl").read_bytes() == before
    stage = out / rows[1]["dir"] / "stage.json"
    stage.write_text(json.dumps({**json.loads(stage.read_text()), "result": {}}))
    assert reproduce_main(args) == 2  # a damaged stage record: refused before any work
    assert "edited or damaged" in capsys.readouterr().err
    assert (out / "ledger.jsonl").read_bytes() == before


def test_ledger_calls_a_run_stopped_inside_a_stage_interrupted(tmp_path):
    """A stage's run stops with its own ``Interrupted`` (a KeyboardInterrupt subclass that says
    what it kept): the ledger says interrupted, not failed; any other error says failed."""
    from warp_critic.reproduce.engine import ledger
    from warp_critic.running.loop import Interrupted

    for error, status in (
        (Interrupted("interrupted; checkpoints kept", 799), "interrupted"),
        (KeyboardInterrupt(), "interrupted"),
        (RuntimeError("boom"), "failed"),
    ):
        out = tmp_path / status / type(error).__name__
        out.mkdir(parents=True)
        with pytest.raises(type(error)), ledger.Call(out, "warp-critic reproduce", ["toy"], "cpu"):
            raise error
        assert ledger.read(out)[-1]["status"] == status, error


def test_a_working_call_beats_so_a_killed_one_still_counts_its_time(tmp_path):
    """``alive`` records while a call works: one killed where it cannot write its end (the OS's
    kill at a session's end, a power cut) counts to its last beat, not to its last stage."""
    import time

    from warp_critic.reproduce.engine import ledger

    with ledger.Call(tmp_path, "warp-critic reproduce", ["tables"], "cpu", heartbeat=0.05) as c:
        time.sleep(0.4)
    rows = ledger.read(tmp_path)
    events = [r["event"] for r in rows]
    assert events[0] == "start" and events[-1] == "end" and events.count("alive") >= 3
    assert all(r["call"] == c.id for r in rows)
    time.sleep(0.2)
    assert len(ledger.read(tmp_path)) == len(rows)  # the beat stopped with the call
    killed = [r for r in rows if r["event"] != "end"]  # as if killed before its end
    killed[0]["time"] = "2026-12-01T10:00:00Z"
    killed[-1]["time"] = "2026-12-01T12:30:00Z"  # its last beat
    s = ledger.summary(killed)
    assert s["wall"] == 9000 and s["unfinished"] == 1


def test_each_call_says_which_commit_it_ran(tmp_path):
    """A run resumed over sittings may span commits: each call's ``start`` names the package's
    version and the commit its checkout's HEAD names (detached, a loose branch ref or a packed
    one; none outside a checkout), read from ``.git`` without running git."""
    from warp_critic.reproduce.engine import ledger

    a, b = "0123456789abcdef0123456789abcdef01234567", "fedcba9876543210fedcba9876543210fedcba98"
    git = tmp_path / "checkout" / ".git"
    (git / "refs" / "heads").mkdir(parents=True)
    (git / "HEAD").write_text("ref: refs/heads/main\n")
    (git / "packed-refs").write_text(f"# pack-refs with: peeled\n{a} refs/heads/main\n")
    assert ledger.code(git.parent)["commit"] == a[:12]  # a fresh clone's branch, packed
    (git / "refs" / "heads" / "main").write_text(b + "\n")
    assert ledger.code(git.parent)["commit"] == b[:12]  # a loose ref is the newer
    (git / "HEAD").write_text(a + "\n")
    assert ledger.code(git.parent)["commit"] == a[:12]  # detached
    (git / "HEAD").write_text("ref: refs/heads/gone\n")
    assert "commit" not in ledger.code(git.parent)
    assert "commit" not in ledger.code(tmp_path / "installed")  # no .git: the version alone
    out = tmp_path / "out"
    out.mkdir()
    with ledger.Call(out, "warp-critic reproduce", ["toy"], "cpu") as call:
        assert call.id
    start = ledger.read(out)[0]
    assert start["event"] == "start" and start["code"] == ledger.code()
    assert start["code"]["warp_critic"] not in ("", "?")


def test_the_ledger_names_the_cpus_instruction_sets(monkeypatch, tmp_path):
    """Two machines whose CPUs differ in AVX-512 give last-bit different numbers; the ledger says
    which a call ran on (vendor, family, model and the instruction sets), read from /proc/cpuinfo."""
    from pathlib import Path

    from warp_critic.reproduce.engine import ledger

    info = tmp_path / "cpuinfo"
    block = "vendor_id\t: GenuineIntel\ncpu family\t: 6\nmodel\t\t: 143\nmodel name\t: Intel(R) Xeon(R) Processor\nflags\t\t: fpu avx avx2 fma avx512f amx_tile\n"
    info.write_text(block + "\n" + block.replace("GenuineIntel", "Other"))
    real = Path.read_text
    monkeypatch.setattr(
        Path,
        "read_text",
        lambda p, *a, **k: real(info) if str(p) == "/proc/cpuinfo" else real(p, *a, **k),
    )
    m = ledger.machine("cpu")
    assert m["cpu"] == "Intel(R) Xeon(R) Processor" and m["cpu_id"] == "GenuineIntel 6 143"
    assert m["simd"] == ["avx", "avx2", "fma", "avx512f", "amx_tile"]  # the first CPU's, in order


def test_ledger_total_wall_time_counts_every_call():
    from warp_critic.reproduce.engine import ledger

    rows = [
        {"event": "start", "call": "a", "time": "2026-12-01T10:00:00Z"},
        {"event": "stage", "call": "a", "time": "2026-12-01T10:30:00Z", "stage": "toy"},
        {"event": "end", "call": "a", "time": "2026-12-01T11:00:00Z"},
        {"event": "start", "call": "b", "time": "2026-12-02T09:00:00Z"},  # killed: no end
        {"event": "stage", "call": "b", "time": "2026-12-02T09:20:00Z", "stage": "maps"},
    ]
    s = ledger.summary(rows)
    assert s["calls"] == 2 and s["unfinished"] == 1
    assert s["wall"] == 3600 + 1200  # a call without an end counts to its last record
    assert s["first"] == "2026-12-01T10:00:00Z" and s["last"] == "2026-12-02T09:20:00Z"
    line = ledger.header_line_of(ledger.numbers(s, {"toy": 5.0, "maps": 100.0, "tables": 50.0}))
    assert "total wall time 4800 s" in line and "stage times 155 s" in line
    assert "(1 without an end)" in line
    assert "1 of these stages were completed by no call of this ledger" in line
    assert line.endswith("not in the ledger's total): tables")  # named, not only counted
    # a carried stage resumed over calls: its compute is its iteration times, not its last call's
    times = {"toy": 5.0, "maps": 100.0, "tables": 50.0}
    line = ledger.header_line_of(ledger.numbers(s, times, {"tables": 7200.0}))
    assert "tables. Their compute" in line and ": 7200 s (2.0 h), which the ledger's 1.3 h" in line

    class _Rec:
        group = "metatrain"
        data = {"seconds": 19.0, "result": {"seeds": {"0": {"seconds": 2715.0}}}}

    assert ledger.stage_compute(_Rec()) == 2715.0
