"""``reproduce``'s executors: local processes and a local Ray cluster give the in-process numbers,
and a worker killed mid-task costs only its own unit (it is run again)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import run_cli, start_cli

from warp_critic.cli.main import main

VOLATILE = (
    "seconds",
    "seconds_each",
    "train_seconds",
    "wall",
    "finished",
    "written",
    "command",
    "seconds_this_call",
    "ledger",
)


def numbers_of(x):
    """``x`` without wall times and command lines (:data:`VOLATILE`), at every depth."""
    if isinstance(x, dict):
        return {k: numbers_of(v) for k, v in x.items() if k not in VOLATILE}
    if isinstance(x, list):
        return [numbers_of(v) for v in x]
    return x


def numbers(out: Path) -> dict:
    """``results.json`` without wall times and the command line: every number the report shows."""
    return numbers_of(json.loads((out / "results.json").read_text()))


@pytest.fixture(scope="module")
def in_process(tmp_path_factory) -> Path:
    """The stages the Ray run below runs (the reacher's maps and the three meta-trainings they
    read), run in this process: what Ray's numbers are compared with."""
    out = tmp_path_factory.mktemp("inproc") / "out"
    argv = ["reproduce", "--quick", "--only", "maps", "--out", str(out), "--device", "cpu"]
    assert main(argv) == 0
    return out


@pytest.fixture(scope="module")
def on_ray(tmp_path_factory) -> tuple[Path, Path, subprocess.CompletedProcess]:
    """A local 2-CPU Ray cluster started by reproduce itself, for the reacher's maps and the three
    meta-trainings they read (a stage that waits for others); the first try of one meta-training
    unit kills its worker process (SIGKILL), as a lost node or an OOM kill would."""
    pytest.importorskip("ray")
    tmp = tmp_path_factory.mktemp("ray")
    out, marker = tmp / "out", tmp / "killed"
    p = run_cli(
        "reproduce",
        "--quick",
        "--only",
        "maps",
        "--out",
        str(out),
        "--device",
        "cpu",
        "--ray",
        env={
            "WARP_CRITIC_UNIT_FAULT": f"metatrain-reacher-ours:{marker}",
            "RAY_DISABLE_USAGE_STATS": "1",
        },
    )
    return out, marker, p


@pytest.mark.slow
@pytest.mark.subprocess
def test_ray_reproduce_gives_the_in_process_numbers(in_process, on_ray):
    """Every stage Ray ran (the maps and the meta-trainings they read) holds the in-process
    stage's numbers, and so does the report's maps section."""
    out, _, p = on_ray
    assert p.returncode == 0, p.stderr[-3000:]
    assert "submitted to Ray" in p.stderr
    ran = sorted(d.name for d in out.iterdir() if (d / "stage.json").is_file())
    assert [n.rsplit("-", 1)[0] for n in ran] == [
        "maps",
        "metatrain-reacher-ddpg",
        "metatrain-reacher-meta-critic",
        "metatrain-reacher-ours",
    ]
    for name in ran:
        mine, ref = (json.loads((o / name / "stage.json").read_text()) for o in (out, in_process))
        assert numbers_of(mine["result"]) == numbers_of(ref["result"]), name
    assert numbers(out)["maps"] == numbers(in_process)["maps"]
    assert (out / "REPORT.md").read_text().count("|") > 50


@pytest.mark.slow
@pytest.mark.subprocess
def test_a_killed_ray_worker_costs_only_its_unit(in_process, on_ray):
    out, marker, p = on_ray
    assert p.returncode == 0, p.stderr[-3000:]
    assert (
        marker.exists() and int(marker.read_text()) != os.getpid()
    )  # the first try died in a worker
    stage = next(out.glob("metatrain-reacher-ours-*"))
    assert (stage / "stage.json").exists()
    ours = json.loads((stage / "stage.json").read_text())["result"]
    ref = json.loads(
        next(in_process.glob("metatrain-reacher-ours-*")).joinpath("stage.json").read_text()
    )["result"]
    assert {k: v["task_loss"] for k, v in ours["seeds"].items()} == {
        k: v["task_loss"] for k, v in ref["seeds"].items()
    }


@pytest.mark.slow
@pytest.mark.subprocess
def test_local_processes_rerun_a_unit_whose_process_died(tmp_path):
    ref_out = tmp_path / "ref"
    argv = ["reproduce", "--quick", "--only", "toy", "--out", str(ref_out), "--device", "cpu"]
    assert main(argv) == 0  # the toy in this process: what the rerun unit must give
    out, marker = tmp_path / "out", tmp_path / "killed"
    p = run_cli(
        "reproduce",
        "--quick",
        "--only",
        "toy,landscape",
        "--out",
        str(out),
        "--device",
        "cpu",
        "--jobs",
        "2",
        env={"WARP_CRITIC_UNIT_FAULT": f"toy:{marker}"},
    )
    assert p.returncode == 0, p.stderr[-3000:]
    assert marker.exists() and "a worker process died; running it again" in p.stderr
    toy = json.loads(next(out.glob("toy-*")).joinpath("stage.json").read_text())["result"]
    ref = json.loads(next(ref_out.glob("toy-*")).joinpath("stage.json").read_text())["result"]
    assert toy == ref


@pytest.mark.slow
@pytest.mark.parametrize(
    "argv, words",
    [
        (["--ray", "127.0.0.1:1"], ("--ray", "127.0.0.1:1")),
        (["--ray", "nowhere"], ("--ray", "HOST:PORT")),
        (["--jobs", "0"], ("--jobs",)),
        (["--jobs", "2", "--ray"], ("--jobs", "--ray")),
    ],
)
def test_bad_executor_flags_are_one_line_and_start_nothing(tmp_path, capsys, argv, words):
    out = tmp_path / "out"
    assert main(["reproduce", "--quick", "--out", str(out), *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert (
        len(err) == 1
        and err[0].startswith("warp-critic: error:")
        and all(w in err[0] for w in words)
    ), err
    assert not out.exists()


@pytest.mark.slow
@pytest.mark.subprocess
def test_stopping_a_jobs_driver_stops_its_workers_cleanly(tmp_path):
    """SIGTERM to ``reproduce --jobs 2`` mid-meta-training: one line, exit 130, every worker's run closed
    (no lock left behind for the next call to take over, recordings that verify)."""
    import signal
    import time

    out = tmp_path / "out"
    args = [
        "reproduce",
        "--quick",
        "--only",
        "metatrain",
        "--out",
        str(out),
        "--device",
        "cpu",
        "--jobs",
        "2",
        "--set",
        "metatrain.reacher.ours.iterations=100000",
        "--set",
        "metatrain.reacher.ddpg.iterations=100000",
    ]
    p = start_cli(*args)
    deadline = time.time() + 300
    # both long units are past their first checkpoint (quick: every 3 iterations)
    while (
        time.time() < deadline
        and len(list(out.glob("metatrain-reacher-*/run/seed*/checkpoint.pt"))) < 4
    ):
        assert p.poll() is None, p.communicate()
        time.sleep(0.5)
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=120)
    assert p.returncode == 130, err
    assert "Traceback" not in err and err.strip().splitlines()[-1].startswith(
        "warp-critic: interrupted"
    ), err
    assert not list(out.rglob(".lock")), "a worker left its run locked"
    for rec in out.glob("metatrain-reacher-*/run/seed*/recording.rrd"):
        v = subprocess.run(
            [sys.executable, "-m", "rerun_cli", "rrd", "verify", str(rec)],
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert v.returncode == 0, v.stderr


@pytest.mark.slow
@pytest.mark.subprocess
def test_a_failing_unit_under_jobs_stops_the_driver(tmp_path):
    """One unit diverges while another trains in the other worker: the driver reports the error and
    exits (it used to hang at exit: the stopped worker blocked handing back its result)."""
    out = tmp_path / "out"
    argv = ["reproduce", "--quick", "--out", str(out), "--device", "cpu", "--jobs", "2"]
    argv += ["--only", "metatrain-reacher-ours,metatrain-kuka-ours"]
    argv += ["--set", "metatrain.reacher.ours.dt=0.5", "--set", "metatrain.kuka.ours.iterations=60"]
    p = run_cli(*argv, timeout=240)
    assert p.returncode == 1, p.stderr[-2000:]
    assert "diverged: iteration 0" in p.stderr
    assert not list(out.glob("metatrain-kuka-ours-*/stage.json"))  # stopped, left to resume


def test_unit_progress_reads_the_runs_metrics(tmp_path):
    """The driver's progress line: the iteration every seed has reached, of the unit's iterations,
    the rate of the last rows and the time left; an evaluation unit (no metrics) is running."""
    from warp_critic.reproduce.engine.executors import Unit, unit_progress

    unit = Unit("metatrain-x", "metatrain-x-0", "m:f", {"values": {"iterations": 100}})
    assert unit_progress(unit, tmp_path) == "reproduce: metatrain-x: running"
    for seed, n in ((0, 30), (1, 25)):
        run = tmp_path / "metatrain-x-0" / "run" / f"seed{seed}"
        run.mkdir(parents=True)
        rows = [json.dumps({"iteration": i, "seconds": 3.0}) for i in range(n)]
        (run / "metrics.jsonl").write_text("".join(r + "\n" for r in rows))
    line = unit_progress(unit, tmp_path)
    assert line == (
        "reproduce: metatrain-x: iteration 25 of 100 (2 run(s)), 3.00 s/iteration, "
        "about 4 min of training left"
    ), line
    other = Unit("maps", "metatrain-x-0", "m:f", {})  # no iteration count given
    assert unit_progress(other, tmp_path) == "reproduce: maps: iteration 25 (2 run(s))"


@pytest.mark.slow
def test_jobs_driver_logs_the_progress_of_its_running_units(tmp_path):
    """Under --jobs the workers draw no progress bars: the driver logs each running unit's
    iteration every ``progress_every`` seconds."""
    from warp_critic.reproduce.engine.executors import LocalProcesses, Unit

    units = [
        Unit(
            f"u{k}",
            f"u{k}-0",
            "progress_unit:slow_iterations",
            {"values": {"iterations": 12}, "pause": 0.25},
        )
        for k in range(2)
    ]
    lines: list[str] = []
    finished: list[str] = []
    LocalProcesses(2, progress_every=0.5).run(
        units, tmp_path, lambda u, result, s: finished.append(u.name), lines.append
    )
    assert sorted(finished) == ["u0", "u1"]
    progress = [x for x in lines if " of 12 (2 run(s))" in x]
    assert {x.split(":")[1].strip() for x in progress} == {"u0", "u1"}, lines


def test_an_in_process_call_on_several_cores_names_jobs(monkeypatch):
    """One line names --jobs where stages could run at once on more than one core; none where they
    cannot (one core, one stage a wave) or already do."""
    from warp_critic.reproduce.engine import choose_executor as ex

    monkeypatch.setattr(ex.os, "cpu_count", lambda: 8)
    line = ex.jobs_hint(ex.InProcess(), [6, 3])
    assert line is not None and "--jobs 6" in line and "8 cores" in line
    assert ex.jobs_hint(ex.InProcess(), [1, 1]) is None
    assert ex.jobs_hint(ex.LocalProcesses(2), [6, 3]) is None
    monkeypatch.setattr(ex.os, "cpu_count", lambda: 1)
    assert ex.jobs_hint(ex.InProcess(), [6, 3]) is None


@pytest.mark.slow
@pytest.mark.parametrize("jobs", [1, 2])
def test_a_stage_starts_as_soon_as_its_inputs_are_complete(tmp_path, jobs):
    """The driver hands an executor the units that its finished stages made ready (``more``): under
    --jobs the dependent unit runs while an independent long one still does, not after it."""
    from warp_critic.reproduce.engine.executors import InProcess, LocalProcesses, Unit

    def unit(name: str, iterations: int) -> Unit:
        kwargs = {"values": {"iterations": iterations}, "pause": 0.05}
        return Unit(name, f"{name}-0", "progress_unit:slow_iterations", kwargs)

    finished: list[str] = []
    waiting = [unit("reads-short", 4)]

    def more() -> list[Unit]:
        ready = [u for u in waiting if "short" in finished]
        for u in ready:
            waiting.remove(u)
        return ready

    executor = LocalProcesses(2) if jobs == 2 else InProcess()
    executor.run(
        [unit("long", 120), unit("short", 4)],
        tmp_path,
        lambda u, result, s: finished.append(u.name),
        lambda line: None,
        more=more,
    )
    assert not waiting
    expected = ["short", "reads-short", "long"] if jobs == 2 else ["long", "short", "reads-short"]
    assert finished == expected
