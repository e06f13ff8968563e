"""Misuse, part three (issues 47 and 48): the cases the third held-out probe found, through the real
command line, in the misuse table's form (``tests/misuse_table.py``: its finished tiny runs, its
snapshot of every file, its rule -- one line naming the file or flag, exit 2, nothing written, nothing
lost).

* a blank ``--train-variants`` (a traceback before);
* ``--train-variants`` whose models the run's step cannot hold (``physics/stability``): refused up
  front naming the value from which the model holds, where they used to diverge at iteration 0;
* unbounded work: more than 100 ``--seeds`` in one process, a policy lifetime x inner steps or
  ``--policy-steps`` over 10000 critic-gradient steps per policy at meta-test;
* dead ends and lost results: ``--resume`` of a run stopped before its first checkpoint starts it
  over (it was refused, and so was a new run there); ``meta-test --out`` on another run's result.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch
from helpers import TWO_LINK, variants_train_argv
from misuse_table import (  # noqa: F401 (base, world: the fixtures)
    MT,
    RESUME,
    TEST,
    TINY,
    C,
    base,
    check_case,
    result_written,
    run_written,
    world,
)

HORIZON = ["--horizon", "20"]
TINY_ARGS = [
    *TINY,
    "--out",
    "{new}",
]  # long enough for a model the step cannot hold to diverge


def variants(text: str, *more: str) -> list[str]:
    return [*MT, *HORIZON, "--train-variants", text, *more, "--out", "{new}"]


def no_checkpoint(w):
    """The run as a process killed (or stopped by a divergence) before its first checkpoint left it."""
    (w.run / "checkpoint.pt").unlink()


def lifetime(value: int):
    def setup(w):
        path = w.run / "checkpoint.pt"
        ckpt = torch.load(path, weights_only=False)
        ckpt["config"]["policy_lifetime"] = value
        torch.save(ckpt, path)

    return setup


def other_kind(w):
    (w.t / "table.json").write_text(json.dumps({"kind": "warp-critic/protocol-v1", "rows": [1]}))


def started_over(w):
    run_written("run", 3)(w)
    rows = [json.loads(x) for x in (w.run / "metrics.jsonl").read_text().splitlines()]
    assert all(r["seconds"] >= 0 for r in rows) and len(rows) == 3


def deleted_cwd(w):
    (w.t / "gone").mkdir()
    os.chdir(w.t / "gone")  # the world fixture's monkeypatch restores the directory after
    (w.t / "gone").rmdir()


def truncated_recording(w):
    data = (w.run / "recording.rrd").read_bytes()
    (w.run / "recording.rrd").write_bytes(data[: len(data) * 2 // 3])  # a killed merge's copy


def truncated_segment(w):
    """The segment a process killed while recording left (its file without rerun's footer)."""
    data = (w.run / "recording.rrd").read_bytes()
    (w.run / "recording.segment.rrd").write_bytes(data[: len(data) // 2])


def zero_axis_urdf(w):
    import re

    text = re.sub(r"<visual>.*?</visual>", "", TWO_LINK)  # no missing-mesh warning
    (w.t / "zeroaxis.urdf").write_text(
        text.replace('<axis xyz="0 1 0"/>', '<axis xyz="0 0 0"/>', 1)
    )


SEEDS_101 = ",".join(str(s) for s in range(101))

CASES = [
    # 1. tracebacks
    C("t47", "train-variants-blank", variants("   "), says=("--train-variants", "blank")),
    C("t47", "train-variants-empty", variants(""), says=("--train-variants", "blank")),
    C(
        "t47",
        "urdf-zero-axis-meta-train",
        ["meta-train", "{t}/zeroaxis.urdf", *TINY_ARGS],
        setup=zero_axis_urdf,
        says=("zeroaxis.urdf", "joint j1", "zero joint axis"),
    ),
    C(
        "t47",
        "urdf-zero-axis-import",
        ["import", "{t}/zeroaxis.urdf", "--out", "{t}/scene.usda"],
        setup=zero_axis_urdf,
        says=("zeroaxis.urdf", "joint j1", "zero joint axis"),
    ),
    # 2. models the run's step cannot hold: refused before any work, naming where it holds
    C(
        "s47",
        "train-variants-massless-link",
        variants("arm1.mass=0"),
        says=("--train-variants", "arm1.mass=0", "it holds from about arm1.mass="),
        seconds=20,
    ),
    C(
        "s47",
        "train-variants-light-second-link",
        variants("arm2.mass=0.01..1:keep"),
        says=("--train-variants", "arm2.mass=0.01:keep", "holds from about arm2.mass=0."),
        seconds=20,
    ),
    C(
        "s47",
        "train-variants-point-mass-off-the-link",
        variants("ee.point-mass+=0..1e6@0.5,0,0"),
        says=("--train-variants", "ee.point-mass+=1e+06@0.5,0,0", "substeps"),
        seconds=20,
    ),
    C(
        "s47",
        "train-variants-short-second-link",
        variants("arm1.mass=0.25..6; arm2.stretch=0.5..2"),
        says=("--train-variants", "arm2.stretch=0.5", "holds from about arm2.stretch=0."),
        seconds=20,
    ),
    C(
        "s47",
        "train-variants-open-range",
        variants("arm1.mass=1e3.."),
        says=("--train-variants", "LO..HI"),
    ),
    C(  # a 1000 kg to 1e9 kg first link: the step holds it, so it trains
        "s47",
        "train-variants-heavy-link-trains",
        variants("arm1.mass=1e3..1e9"),
        code=0,
        check=run_written("new_out", 1),
        seconds=40,
    ),
    C(  # dropped worlds are the user's choice: no probe
        "s47",
        "train-variants-light-link-with-drop-trains",
        variants("arm2.mass=0.2..1:keep", "--on-divergence", "drop"),
        code=0,
        check=run_written("new_out", 1),
        seconds=40,
    ),
    # 3. unbounded work
    C(
        "u47",
        "seeds-101",
        [*MT, "--seeds", SEEDS_101, "--out", "{new}"],
        says=("--seeds", "101 seeds", "at most 100"),
        seconds=10,
    ),
    C(
        "u47",
        "policy-lifetime-1e6",
        [*MT, "--policy-lifetime", "1000000", "--out", "{new}"],
        says=("--policy-lifetime", "10000"),
        seconds=10,
    ),
    C(
        "u47",
        "policy-lifetime-times-inner-steps",
        [*MT, "--policy-lifetime", "5000", "--inner-steps", "3", "--out", "{new}"],
        says=("--policy-lifetime", "15000", "at most 10000"),
        seconds=10,
    ),
    C(
        "u47",
        "meta-test-policy-steps-20000",
        [*TEST, "--policy-steps", "20000", "--out", "{t}/mt.json"],
        says=("--policy-steps", "10000"),
        seconds=10,
    ),
    C(
        "u47",
        "meta-test-run-with-lifetime-1e6",
        [*TEST, "--out", "{t}/mt.json"],
        setup=lifetime(1_000_000),
        says=("--policy-steps", "000000 critic-gradient steps", "at most 10000"),
        seconds=15,
    ),
    C(  # the limit itself is stated, and --policy-steps takes over a run's too-long default
        "u47",
        "meta-test-run-with-lifetime-1e6-steps-given",
        [*TEST, "--policy-steps", "2", "--out", "{t}/mt.json"],
        setup=lifetime(1_000_000),
        code=0,
        check=result_written("mt.json"),
    ),
    # 4. dead ends and lost results
    C(
        "d48",
        "resume-run-stopped-before-first-checkpoint",
        RESUME,
        setup=no_checkpoint,
        code=0,
        warns=1,
        says=("no checkpoint", "starts over", "2 iteration(s)"),
        changes=("run/",),
        check=started_over,
    ),
    C(
        "d48",
        "new-run-in-a-run-stopped-before-first-checkpoint",
        [*MT, "--out", "{run}"],
        setup=no_checkpoint,
        says=("already holds a run", "--resume"),
    ),
    C(
        "d48",
        "resume-run-stopped-before-first-checkpoint-other-settings",
        [*RESUME, "--horizon", "5"],
        setup=no_checkpoint,
        says=("horizon", "3 -> 5"),
    ),
    C(
        "d48",
        "meta-test-out-is-another-runs-result",
        ["meta-test", "{ddpg}", "--device", "cpu", "--num-goals", "1", "--inits", "1"]
        + ["--out", "{run}/metatest.json"],
        says=("--out", "metatest.json", "not replacing"),
    ),
    C(
        "d48",
        "meta-test-out-is-another-commands-result",
        [*TEST, "--out", "{t}/table.json"],
        setup=other_kind,
        says=("--out", "table.json", "protocol"),
    ),
]


CASES += [
    # 5. messages that mislead
    C(
        "m48",
        "working-directory-deleted",
        [*MT, "--out", "{new}"],
        setup=deleted_cwd,
        says=("the working directory no longer exists",),
    ),
    C(
        "m48",
        "resume-repairs-a-truncated-recording-and-says-what-it-kept",
        RESUME,
        setup=truncated_recording,
        code=0,
        warns=1,
        says=("recording.rrd had been cut short", "recorded iteration(s)"),
        changes=("run/",),
        check=run_written("run", 3),
    ),
    C(
        "m48",
        "resume-repairs-a-truncated-segment-and-says-what-it-kept",
        RESUME,
        setup=truncated_segment,
        code=0,
        warns=1,
        says=("recording.segment.rrd had been cut short", "recorded iteration(s), 0 to"),
        changes=("run/",),
        check=run_written("run", 3),
    ),
]


@pytest.mark.parametrize("case", CASES)
def test_misuse_three(case, world, capfd, monkeypatch):  # noqa: F811 (the fixture)
    check_case(case, world, capfd, monkeypatch)


@pytest.mark.slow
def test_interrupt_after_import_wrote_the_scene_says_it_is_whole(tmp_path, capfd, monkeypatch):
    """A signal that lands after ``import`` wrote its scene: exit 130 with one line saying the scene
    was written whole (it said only "interrupted")."""
    import warp_critic.cli.import_robot as command
    import warp_critic.cli.main as cli

    robot = tmp_path / "twolink.urdf"
    robot.write_text(TWO_LINK)
    out = tmp_path / "scene.usda"

    def signalled_print(*args, **kw):
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(5)  # the handler raises here
        print(*args, **kw)

    monkeypatch.setattr(command, "print", signalled_print, raising=False)
    capfd.readouterr()
    code = cli.main(["import", str(robot), "--out", str(out)])
    lines = [x for x in capfd.readouterr().err.splitlines() if "warning" not in x]
    assert code == 130 and lines == [
        f"warp-critic: interrupted; the scene {out} was written whole"
    ], lines
    assert out.is_file()


def _cli_ascii_locale(*args: bytes, cwd) -> subprocess.CompletedProcess:
    env = {**os.environ, "LC_ALL": "C", "PYTHONUTF8": "0", "WARP_CRITIC_TORCH_THREADS": "1"}
    cmd = [sys.executable.encode(), b"-m", b"warp_critic.cli.main", *args]
    return subprocess.run(cmd, env=env, cwd=cwd, capture_output=True, timeout=300)


@pytest.mark.slow
@pytest.mark.subprocess
def test_utf8_paths_under_an_ascii_locale(tmp_path):
    """``LC_ALL=C PYTHONUTF8=0``: valid UTF-8 names are taken (they were refused as "not valid
    UTF-8"), a name with a stray byte is still refused naming its flag, nothing written."""
    from conftest import REACHER

    folder = tmp_path / "réa"
    folder.mkdir()
    (folder / "scène.usda").write_text(Path(REACHER).read_text())
    tiny = [b"--iterations", b"1", b"--horizon", b"3", b"--worlds-per-goal", b"1"]
    scene = "réa/scène.usda".encode()
    p = _cli_ascii_locale(b"meta-train", scene, *tiny, b"--device", b"cpu", b"--out",
                          "réa/rün".encode(), cwd=tmp_path)  # fmt: skip
    assert p.returncode == 0, p.stderr
    config = json.loads((folder / "rün" / "config.json").read_text())
    assert config["scene"] == "réa/scène.usda"
    p = _cli_ascii_locale(b"meta-train", scene, *tiny, b"--out", b"bad\xff", cwd=tmp_path)
    err = p.stderr.decode(errors="replace").strip().splitlines()
    assert p.returncode == 2 and len(err) == 1 and "--out" in err[0] and "UTF-8" in err[0], err
    assert sorted(x.name for x in tmp_path.iterdir()) == ["réa"]


@pytest.mark.slow
def test_a_stopped_identification_continues_where_it_stopped(tmp_path):
    """reproduce's identification step (``train_identifier`` with a ``resume_file``) saves its state
    every ``checkpoint_every`` steps; stopped, it continues from there (it started at iteration 0)
    to exactly the identifier an uninterrupted run trains, and removes the file."""
    from warp_critic.cli.main import main
    from warp_critic.methods.identify import IDENTIFY_FILE, train_identifier

    told = tmp_path / "told"
    assert main(variants_train_argv(told, "--critic-input", "pose-dynamics", iterations=1)) == 0
    kw = dict(iterations=4, goals=2, inits=2, hidden=16, seed=0, device="cpu")
    torch.manual_seed(0)  # the identifier's initial weights
    train_identifier(str(told), str(tmp_path / "a"), **kw)
    resume = tmp_path / "b.progress.pt"

    def stop(it, loss):
        if it == 2:
            raise KeyboardInterrupt

    torch.manual_seed(0)
    with pytest.raises(KeyboardInterrupt):
        train_identifier(
            str(told),
            str(tmp_path / "b"),
            resume_file=resume,
            checkpoint_every=2,
            progress=stop,
            **kw,
        )
    assert resume.is_file() and not (tmp_path / "b").exists()
    seen: list[int] = []
    torch.manual_seed(1)  # not needed: the saved state holds the weights
    train_identifier(
        str(told),
        str(tmp_path / "b"),
        resume_file=resume,
        checkpoint_every=2,
        progress=lambda it, loss: seen.append(it),
        **kw,
    )
    assert seen == [2, 3] and not resume.exists()
    a, b = (tmp_path / d / IDENTIFY_FILE for d in ("a", "b"))
    assert a.read_text() == b.read_text() and len(a.read_text().splitlines()) == 4
    sa, sb = (
        torch.load(tmp_path / d / "checkpoint.pt", weights_only=False)["identifier_state"]
        for d in ("a", "b")
    )
    assert sa.keys() == sb.keys() and all(torch.equal(sa[k], sb[k]) for k in sa)
