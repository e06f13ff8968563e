"""Misuse, part four (issue 56): the cases the fourth held-out probe found, through the real command
line where it can be, in the misuse table's form (``tests/test_bad_input.py``: its finished tiny runs,
its snapshot of every file, its rule -- one line naming the file or flag, exit 2, nothing written,
nothing lost).

* results lost: ``score --out`` on a run's own file or on a meta-test result, ``meta-test --out X.json``
  over someone's ``X.rrd``, ``gpu_check --out`` over a result (one rule for every writer:
  :func:`warp_critic.running.files.check_replaceable`);
* unbounded or crashing: a result path that is a FIFO or a device, the recording on a full disk, a
  replay buffer that cannot fit, a console that cannot encode the result's path;
* accepted and silently wrong: ``score`` pooling a run twice or two methods, or writing into a run
  folder a live training or reproduce owns; scene files not checked like robot files; ``--lock-mimic``
  ignoring ``--home``; ``reproduce --beyond --only``; a flag the method does not use; a minibatch
  larger than the buffer; a variant's point 1e9 m away; ``robot_zoo.py --only`` matching nothing;
* messages that mislead: a signal while the interpreter shuts down, non-finite inertia entries and
  axes, ``--max-torque -1,1``, a URDF saved as ``.txt``, ``identify --goals``, ``reproduce --seeds``,
  ``robot_zoo.py --runs-dir FILE``.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import misuse_table as table
import pytest
from conftest import REACHER
from helpers import MIMIC, load_tool, urdf
from misuse_table import MT, TEST, C, base, world  # noqa: F401 (fixtures)

from warp_critic.cli.main import main

SCORE = ["score", "--device", "cpu", "--num-goals", "1", "--inits", "1", "--stds", "0.1"]
SCORE += ["--goal-noise", "per-joint"]
DDPG_TINY = ["baseline", "ddpg", "{R}", *table.TINY]
REACHER_TEXT = Path(REACHER).read_text()


def score(*runs: str, out: str | None = None) -> list[str]:
    return [*SCORE, *runs] + (["--out", out] if out else [])


def meta_test_result(name: str):
    """``{t}/NAME`` holds the run's meta-test result (an earlier ``meta-test --out``)."""

    def setup(w):
        shutil.copy(w.run / "metatest.json", w.t / name)

    return setup


def user_recording(w):
    (w.t / "notes.rrd").write_text("my notes, not a recording\n")


def reproduce_stage_run(w):
    """A reproduce output whose stage folder holds a finished run."""
    table.reproduce_output(w)
    shutil.copytree(w.run, w.t / "rep" / "stagedir" / "run")


def scene_copy(name: str, old: str, new: str):
    def setup(w):
        assert old in REACHER_TEXT
        (w.t / name).write_text(REACHER_TEXT.replace(old, new, 1))

    return setup


def robot(name: str, text: str):
    def setup(w):
        (w.t / name).write_text(text)

    return setup


def little_memory(monkeypatch, w):
    """A machine with 8 GiB free (the estimate, not this machine's memory, decides)."""
    from warp_critic.core import memory

    monkeypatch.setattr(memory, "available_memory", lambda device="cpu": 8 * 2**30)


NO_VISUAL = urdf()  # test_robot_misuse's two-link arm: no meshes, no warnings
NAN_IYY = urdf(inertia='ixx="0.01" iyy="nan" izz="0.05" ixy="0" ixz="0" iyz="0"')
INF_IXZ = urdf(inertia='ixx="0.01" iyy="0.05" izz="0.05" ixy="0" ixz="inf" iyz="0"')
NAN_AXIS = urdf().replace('<axis xyz="0 1 0"/>', '<axis xyz="nan 1 0"/>', 1)

CASES = [
    # 1. results lost or damaged
    C(
        "l56",
        "score-out-a-runs-config",
        score("{run}", out="{run}/config.json"),
        says=("--out", "config.json", "a run's own files"),
    ),
    C(
        "l56",
        "score-out-a-meta-test-result",
        score("{run}", out="{t}/mt.json"),
        setup=meta_test_result("mt.json"),
        says=("--out", "mt.json", "metatest-v1", "not replacing"),
    ),
    C(
        "l56",
        "meta-test-out-beside-someones-rrd",
        [*TEST, "--out", "{t}/notes.json"],
        setup=user_recording,
        says=("--out", "notes.rrd", "not replacing"),
    ),
    # 2. unbounded or crashing
    C(
        "u56",
        "meta-test-recording-on-a-full-disk",
        [*TEST, "--out", "{t}/mt.json"],
        patch=table.disk_full_on("mt.rrd"),
        code=1,
        says=("mt.rrd", "No space left on device", "mt.json were written whole"),
        changes=("mt.json",),
    ),
    C(
        "u56",
        "baseline-replay-buffer-over-memory",
        [*DDPG_TINY, "--buffer-size", "1000000000", "--iterations", "1000000", "--horizon", "300"]
        + ["--out", "{new}"],
        patch=little_memory,
        says=("--buffer-size", "1,000,000,000 transitions", "GiB"),
        seconds=15,
    ),
    # 3. accepted and silently wrong
    C("w56", "score-a-run-twice", score("{run}", "{run}"), says=("RUN_DIR", "again")),
    C(
        "w56",
        "score-two-methods",
        score("{run}", "{ddpg}"),
        says=("RUN_DIR", "ours", "ddpg", "one method"),
    ),
    C(
        "w56",
        "score-a-run-a-live-training-holds",
        score("{run}"),
        setup=table.hold_lock("run"),
        says=("RUN_DIR", "in use by"),
        check=table.live_run_kept,
    ),
    C(
        "w56",
        "score-a-reproduce-stages-run",
        score("{t}/rep/stagedir/run"),
        setup=reproduce_stage_run,
        says=("RUN_DIR", "belongs to reproduce"),
    ),
    C(
        "w56",
        "scene-with-a-1e30-kg-link",
        ["meta-train", "{t}/heavy.usda", *table.TINY, "--out", "{new}"],
        setup=scene_copy("heavy.usda", "float physics:mass = 1\n", "float physics:mass = 1e30\n"),
        says=("heavy.usda", "arm1", "1e+30 kg", "outside 1e-06..1e+06"),
    ),
    C(
        "w56",
        "scene-with-an-unknown-attribute",
        ["meta-train", "{t}/typo.usda", *table.TINY, "--out", "{new}"],
        setup=scene_copy("typo.usda", "warp_critic:horizon", "warp_critic:horizn"),
        says=("typo.usda", "unknown attribute warp_critic:horizn", "warp_critic:horizon?"),
    ),
    C(
        "w56",
        "scene-with-a-tip-1e9-m-away",
        ["meta-train", "{t}/far.usda", *table.TINY, "--out", "{new}"],
        setup=scene_copy("far.usda", "tipOffset = (1, 0, 0)", "tipOffset = (1e9, 0, 0)"),
        says=("far.usda", "warp_critic:tipOffset", "at most 10 m"),
    ),
    C(
        "w56",
        "td3-with-a-meta-critic-flag",
        ["baseline", "td3", "{R}", *table.TINY, "--aux-lr", "0.01", "--out", "{new}"],
        says=("--aux-lr", "Meta-Critic setting", "td3 does not use it"),
    ),
    C(
        "w56",
        "batch-larger-than-the-buffer",
        [*DDPG_TINY, "--batch-size", "1000000", "--buffer-size", "100", "--out", "{new}"],
        says=("--batch-size", "--buffer-size 100"),
    ),
    C(
        "w56",
        "meta-test-point-mass-1e9-m-away",
        [*TEST, "--variant", "ee.point-mass+=1@1e9,0,0", "--out", "{t}/mt.json"],
        says=("--variant", "1e+09 m", "at most 10 m"),
    ),
    # 4. messages that mislead
    C(
        "m56",
        "max-torque-negative-list",
        [*MT, "--max-torque", "-1,1", "--out", "{new}"],
        says=("--max-torque",),
        not_says=("expected one argument",),
    ),
    C(
        "m56",
        "inertia-entry-inf",
        ["import", "{t}/inf.urdf", "--out", "{t}/s.usda"],
        setup=robot("inf.urdf", INF_IXZ),
        says=("inf.urdf", "body 'l1'", "ixz=inf"),
    ),
    C(
        "m56",
        "inertia-entry-nan-with-repair",
        ["import", "{t}/nan.urdf", "--out", "{t}/s.usda", "--repair-inertia"],
        setup=robot("nan.urdf", NAN_IYY),
        says=("nan.urdf", "iyy=nan", "cannot project"),
        not_says=("ixx=nan",),
    ),
    C(
        "m56",
        "joint-axis-nan",
        ["import", "{t}/axis.urdf", "--out", "{t}/s.usda"],
        setup=robot("axis.urdf", NAN_AXIS),
        says=("axis.urdf", "joint 'j1'", "(nan, 1, 0)", "not finite"),
        not_says=("zero joint axis",),
    ),
    C(
        "m56",
        "identify-goals-1e8",
        ["identify", "{run}", "--out", "{new}", "--goals", "100000000"],
        says=("--goals",),
        not_says=("--num-goals",),
    ),
    C(
        "m56",
        "reproduce-seeds-101",
        ["reproduce", "--quick", "--seeds", "101", "--out", "{new}"],
        says=("--seeds", "101 seeds", "at most 100"),
        not_says=("--set", "metatrain.seeds"),
    ),
]


@pytest.mark.parametrize("case", CASES)
def test_misuse_four(case, world, capfd, monkeypatch):  # noqa: F811 (the fixture)
    table.check_case(case, world, capfd, monkeypatch)


# ------------------------------------------------------------------------------------------------
# the same rule for every writer, at the level of its one function
# ------------------------------------------------------------------------------------------------


def test_result_files_are_read_bounded(tmp_path):
    """A result path that is a link to ``/dev/full`` (an endless read), or a file over the cap, is
    refused without reading it (it grew the process to 24 GB)."""
    from warp_critic.core.errors import UserError
    from warp_critic.running.files import check_replaceable, read_bounded

    link = tmp_path / "X.json"
    link.symlink_to("/dev/full")
    with pytest.raises(UserError, match="character device"):
        check_replaceable(link, "out", "warp-critic/metatest-v1", lambda old: None)
    big = tmp_path / "big.json"
    big.write_text('{"kind": "warp-critic/metatest-v1"}' + " " * 2000)
    with pytest.raises(UserError, match="more than the 1,000 a result file can be"):
        read_bounded(big, cap=1000)


def test_a_figure_is_checked_by_its_signature_alone(tmp_path):
    """``--figure``: an existing PNG of any size may be replaced (only its 8-byte signature is
    read; a large picture is no result file to cap), any other file and a device are refused."""
    from warp_critic.core.errors import UserError
    from warp_critic.running.files import MAX_RESULT_BYTES, PNG_SIGNATURE, check_figure_file

    big = tmp_path / "big.png"
    with open(big, "wb") as f:  # sparse: a signature, then a hole past the result files' cap
        f.write(PNG_SIGNATURE)
        f.truncate(MAX_RESULT_BYTES + 1)
    assert check_figure_file(big) == big
    (tmp_path / "notes.png").write_bytes(b"my notes, not a picture")
    with pytest.raises(UserError, match="exists and is not a PNG image"):
        check_figure_file(tmp_path / "notes.png")
    link = tmp_path / "dev.png"
    link.symlink_to("/dev/zero")
    with pytest.raises(UserError, match="character device"):
        check_figure_file(link)


@pytest.mark.parametrize("name", ["auto", "cpu", "cuda", "cuda:0", "cuda:12"])
def test_a_device_name_is_checked_once_for_every_command(name):
    """One check of a device's name (``core.runtime.check_device``) for the simulator, ``reproduce``
    and ``budget``: what it accepts, each accepts, and each refuses the rest with one message."""
    from warp_critic.core.errors import FieldError
    from warp_critic.core.runtime import check_device
    from warp_critic.reproduce.budget import BudgetConfig
    from warp_critic.reproduce.experiments.plan import ReproduceConfig

    assert check_device(name) == name
    for bad in ("tpu", "cuda:", "cuda:x", "CPU", "", None, 0):
        with pytest.raises(FieldError, match="must be auto, cpu, cuda or cuda:N"):
            check_device(bad)
    checks = (
        lambda d: BudgetConfig(runs={"ours": ["r"]}, device=d).validate(),
        lambda d: ReproduceConfig(device=d).validate(),
    )
    for validate in checks:
        with pytest.raises(
            FieldError, match=r"device: must be auto, cpu, cuda or cuda:N \(got 'tp"
        ):
            validate("tpu")


def test_meta_test_out_a_fifo_is_refused_not_read(world, capfd):  # noqa: F811 (the fixture)
    """A FIFO as ``--out``: refused naming it (opening it to see whether it is an earlier result
    waited for a writer forever). Outside the table: its snapshot would read the FIFO."""
    w = world
    os.mkfifo(w.t / "pipe.json")
    argv = [a.format(run=w.run) for a in TEST] + ["--out", str(w.t / "pipe.json")]
    capfd.readouterr()
    code, _ = table.run_main(argv, limit=60)
    err = [x for x in capfd.readouterr().err.splitlines() if x.strip()]
    assert code == 2 and len(err) == 1 and "pipe.json" in err[0] and "FIFO" in err[0], err
    assert not (w.t / "pipe.rrd").exists()


def test_score_replaces_only_its_own_score(world, capfd):  # noqa: F811 (the fixture)
    """``score --out`` writes a result of kind ``warp-critic/score-v1``; the same command again
    replaces it, a score of other runs is refused."""
    w = world
    out = w.t / "score.json"
    args = [a.format(run=w.run) for a in score("{run}", out=str(out))]
    assert main(args) == 0
    first = json.loads(out.read_text())
    assert first["kind"] == "warp-critic/score-v1" and first["runs"] == [str(w.run)]
    assert main(args) == 0  # the same runs: replaced
    capfd.readouterr()
    assert main([a.format(run=w.ddpg) for a in score("{run}", out=str(out))]) == 2
    assert "not replacing" in capfd.readouterr().err
    assert json.loads(out.read_text())["runs"] == [str(w.run)]


def test_gpu_check_out_replaces_only_a_gpu_check(tmp_path, capsys):
    gpu_check = load_tool("gpu_check")
    result = tmp_path / "mt.json"
    result.write_text('{"kind": "warp-critic/metatest-v1", "mean": 1.0}\n')
    before = result.read_bytes()
    assert gpu_check.main(["--device", "cpu", "--tiny", "--out", str(result)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--out" in err[0] and "not replacing" in err[0], err
    assert result.read_bytes() == before


def test_robot_zoo_only_matching_nothing_and_runs_dir_a_file(tmp_path, capsys):
    zoo = load_tool("robot_zoo")
    assert zoo.main(["--only", "no_such_robot_file"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--only" in err[0] and "no_such_robot_file" in err[0], err
    afile = tmp_path / "afile"
    afile.write_text("not a folder\n")
    with pytest.raises(SystemExit) as e:
        zoo.main(["--floor", "--runs-dir", str(afile)])
    err = capsys.readouterr().err.strip().splitlines()
    assert e.value.code == 2 and len(err) == 1 and "not a folder" in err[0], err


# ------------------------------------------------------------------------------------------------
# import, reproduce and the console
# ------------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_lock_mimic_follows_the_given_home(tmp_path, capfd):
    """``--lock-mimic --home j1=0.5``: j2 = 0.1 + 0.5 j1 is welded at 0.35 (it was welded where the
    file's home put it, 0.1, breaking the coupling at the home the scene records)."""
    from pxr import Usd

    robot_file, out = tmp_path / "r.urdf", tmp_path / "r.usda"
    robot_file.write_text(urdf(j2=MIMIC))
    assert (
        main(["import", str(robot_file), "--out", str(out), "--lock-mimic", "--home", "j1=0.5"])
        == 0
    )
    stage = Usd.Stage.Open(str(out))
    root = stage.GetDefaultPrim()
    assert list(root.GetAttribute("warp_critic:homePose").Get()) == [0.5]
    repairs = list(root.GetAttribute("warp_critic:importRepairs").Get())
    assert repairs == ["joint j2 locked at 0.35: coupled as j2 = 0.1 + 0.5 x j1 at j1's home 0.5"]
    assert "locked at 0.35" in capfd.readouterr().out


def test_a_urdf_saved_as_txt_is_imported(tmp_path, capfd):
    """The format is read from the content (the help says so): a URDF named ``.txt`` imports (it got
    "not a USD file (unknown extension '.txt')")."""
    robot_file, out = tmp_path / "arm.txt", tmp_path / "arm.usda"
    robot_file.write_text(NO_VISUAL)
    assert main(["import", str(robot_file), "--out", str(out)]) == 0, capfd.readouterr().err
    assert out.is_file()


@pytest.mark.slow
def test_reproduce_beyond_only_runs_what_its_names_need(tmp_path):
    """``reproduce --quick --beyond --only metatrain-reacher-ours`` plans that one stage, as without
    ``--beyond`` (it planned 13)."""
    from warp_critic.reproduce.pipeline import ReproduceConfig, needed, plan

    def stages(**kw) -> list[str]:
        rc = ReproduceConfig(out=tmp_path / "rep", quick=True, seeds=2, **kw)
        settings = rc.validate()
        waves = needed(rc, plan(settings, beyond=rc.plans_beyond, extra=rc.extra))
        return [n for wave in waves for n in wave]

    only = ["metatrain-reacher-ours"]
    assert stages(only=only, beyond=True) == stages(only=only) == only
    assert len(stages(beyond=True)) > len(stages())  # --beyond alone still adds the group


@pytest.mark.slow
@pytest.mark.subprocess
def test_a_signal_while_the_interpreter_shuts_down_is_not_a_kill(tmp_path):
    """A SIGTERM that lands after the command, while Python tears itself down (it has put the default
    handlers back by then): the process ends as the command did, not killed (exit 143, no line)."""
    script = tmp_path / "late.py"
    script.write_text(
        textwrap.dedent(
            """
            import os, signal, sys, time
            from warp_critic.cli.main import main

            class Late:  # collected with the module's globals, after the exit handlers
                def __del__(self):
                    os.kill(os.getpid(), signal.SIGTERM)
                    time.sleep(0.5)

            late = Late()
            sys.argv = ["warp-critic", "import", "missing.urdf", "--out", "x.usda"]
            sys.exit(main())
            """
        )
    )
    env = {**os.environ, "WARP_CRITIC_TORCH_THREADS": "1"}
    p = subprocess.run(
        [sys.executable, str(script)], cwd=tmp_path, env=env, capture_output=True, timeout=300
    )
    err = p.stderr.decode(errors="replace").strip().splitlines()
    assert p.returncode == 2 and len(err) == 1 and "missing.urdf" in err[0], (p.returncode, err)


@pytest.mark.slow
@pytest.mark.subprocess
def test_a_console_that_cannot_encode_the_path(tmp_path, base):  # noqa: F811 (the fixture)
    """``PYTHONIOENCODING=ascii`` under ``LC_ALL=C``: the result path ``R ü/metatest.json`` is printed
    escaped (it was a ``UnicodeEncodeError`` traceback after the files were written)."""
    run = tmp_path / "R ü"
    shutil.copytree(base / "run", run)
    (run / "metatest.json").unlink()
    env = {**os.environ, "LC_ALL": "C", "PYTHONUTF8": "0", "PYTHONIOENCODING": "ascii"}
    env["WARP_CRITIC_TORCH_THREADS"] = "1"
    args = [
        b"meta-test",
        "R ü".encode(),
        b"--device",
        b"cpu",
        b"--num-goals",
        b"1",
        b"--inits",
        b"1",
    ]
    cmd = [sys.executable.encode(), b"-m", b"warp_critic.cli.main", *args]
    p = subprocess.run(cmd, env=env, cwd=tmp_path, capture_output=True, timeout=300)
    assert p.returncode == 0 and b"Traceback" not in p.stderr, p.stderr.decode(errors="replace")
    assert b"results: R \\xfc/metatest.json" in p.stdout, p.stdout
    assert (run / "metatest.json").is_file()
