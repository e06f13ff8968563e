"""``reproduce --hours H``: a call starts a meta-training only if it is expected to end in time, stops
what still runs at the limit, and exits 75 with one line; the estimates come from the reference
run's records (the same stage, or the same name under other settings, per iteration) scaled by the
folder's pace, or from a part-way run's recent speed."""

from __future__ import annotations

import _thread
import json
import math
import signal
from pathlib import Path

import pytest
from helpers import run_cli

from warp_critic.reproduce.engine.executors import InProcess, Unit
from warp_critic.reproduce.engine.stage import Stage
from warp_critic.reproduce.engine.stages import STAGE_KIND, Runner
from warp_critic.reproduce.engine.timelimit import (
    EXIT_TIME_LIMIT,
    TimeLimit,
    TimeLimitReached,
    check_hours,
)


class Clock:
    def __init__(self):
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def test_a_stage_fits_by_its_estimate_and_an_unknown_one_while_time_is_left():
    clock = Clock()
    est = {"long": (3000.0, "ref"), "short": (600.0, "ref"), "huge": (9000.0, "ref")}
    limit = TimeLimit(1.0, est.get, clock=clock, stop=lambda: None)
    assert limit.fits("short") and limit.fits("unknown") and not limit.held
    clock.now = 1000.0  # 2600 s left
    assert not limit.fits("long")
    assert limit.held["long"] == "expected 50 min (ref), 43 min left"
    assert not limit.fits("huge") and "more than the whole --hours 1" in limit.held["huge"]
    assert limit.fits("short")
    limit.estimate = {**est, "blind": (math.nan, "no estimate")}.get
    assert limit.fits("blind")  # 2600 s of 3600 left: a meta-training of unknown length starts
    clock.now = 1900.0
    assert not limit.fits("blind")
    assert limit.held["blind"] == "no estimate, and less than half of --hours 1 is left"
    assert limit.fits("unknown")  # a meta-test keeps its batches: it starts while time is left
    clock.now = 3600.0
    assert not limit.fits("unknown") and limit.held["unknown"] == "no time left"
    out = str(limit.outcome(["long", "unknown", "other"]))
    assert out.startswith("no stage left could end within --hours 1, 3 stage(s) left")
    assert "long not started: expected 50 min" in out and "huge" not in out


@pytest.mark.parametrize("bad", [0, -1.0, float("nan"), float("inf"), True, "2"])
def test_hours_must_be_a_positive_finite_number(bad):
    from warp_critic.core.errors import FieldError

    with pytest.raises(FieldError, match="hours"):
        check_hours(bad)


def _stage(name: str, kind: str, depends: tuple[str, ...] = ()) -> Stage:
    return Stage(name, kind, {}, {d: f"{d}-0" for d in depends}, "0")


class _Call:
    def stage(self, name, seconds, dir_name):
        pass


def _run(tmp_path: Path, stages: dict, limit: TimeLimit, iterations: dict, executor=None) -> Runner:
    from warp_critic.reproduce.engine.scheduler import pending, run_stages

    runner = Runner(tmp_path, lambda group, data: None, log=lambda line: None)
    waves = [list(stages)]
    todo = pending(stages, waves, runner)

    def unit(st: Stage) -> Unit:
        kwargs = {"values": {"iterations": iterations[st.name]}, "pause": 0.05}
        return Unit(st.name, st.dir_name, "progress_unit:slow_iterations", kwargs)

    run_stages(stages, waves, todo, runner, executor or InProcess(), _Call(), unit, limit)
    return runner


def test_a_meta_training_that_cannot_end_in_time_waits_with_its_readers(tmp_path):
    """The held meta-training does not start, nor the stage that reads it; the others run; the call
    ends early with the stages left named."""
    stages = {
        "train": _stage("train", "metatrain"),
        "maps": _stage("maps", "maps", ("train",)),
        "toy": _stage("toy", "toy"),
    }
    est = {"train": (7200.0, "the reference run")}
    limit = TimeLimit(1.0, est.get, stop=lambda: None)
    runner = None
    with pytest.raises(TimeLimitReached) as e:
        runner = _run(tmp_path, stages, limit, {"train": 2, "maps": 2, "toy": 2})
    assert runner is None
    assert (tmp_path / "toy-0" / "stage.json").is_file()
    assert not (tmp_path / "train-0").exists() and not (tmp_path / "maps-0").exists()
    msg = str(e.value)
    assert msg.startswith("no stage left could end within --hours 1, 2 stage(s) left")
    assert "train not started: expected 120 min (the reference run), more than the whole" in msg


@pytest.mark.parametrize("jobs", [1, 2])
def test_a_stage_is_judged_when_a_worker_is_free_for_it_not_when_it_became_ready(tmp_path, jobs):
    """Both stages are ready at the start, where the meta-training (2 s expected) fits the 3 s
    limit; a worker is free for it only after the toy's 2 s, when it no longer does."""
    from warp_critic.reproduce.engine.executors import LocalProcesses

    stages = {"toy": _stage("toy", "toy"), "train": _stage("train", "metatrain")}
    limit = TimeLimit(3.0 / 3600, {"train": (2.0, "guess")}.get, stop=lambda: None)
    executor = LocalProcesses(1) if jobs == 2 else InProcess()  # one worker either way
    with pytest.raises(TimeLimitReached, match="train not started: (expected 0 min|no time left)"):
        _run(tmp_path, stages, limit, {"toy": 40, "train": 2}, executor)
    assert (tmp_path / "toy-0" / "stage.json").is_file() and not (tmp_path / "train-0").exists()


def test_at_the_limit_the_running_stage_is_stopped(tmp_path):
    """The limit interrupts the stage that runs (as Ctrl-C does: here the main thread's
    KeyboardInterrupt) and the call ends with the limit named; what finished before is kept."""
    stages = {"toy": _stage("toy", "toy"), "maps": _stage("maps", "maps")}
    limit = TimeLimit(1.0 / 3600, lambda name: None, stop=_thread.interrupt_main)  # 1 s
    # interrupt_main calls the SIGINT handler: Python's own here, whatever an earlier in-process
    # command (warp_critic.cli.signals) or the test runner's worker left installed
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(TimeLimitReached) as e:
            _run(tmp_path, stages, limit, {"toy": 2, "maps": 400})  # maps: 20 s
    finally:
        signal.signal(signal.SIGINT, before)
    assert limit.reached
    assert str(e.value).startswith("the --hours 0.000277778 limit was reached, 1 stage(s) left")
    assert (tmp_path / "toy-0" / "stage.json").is_file()
    assert not (tmp_path / "maps-0" / "stage.json").exists()
    assert 0 < len((tmp_path / "maps-0" / "run" / "seed0" / "metrics.jsonl").read_text()) < 400 * 40


def _record(d: Path, name: str, seconds: float, iterations: int, **values) -> None:
    d.mkdir(parents=True)
    data = {
        "kind": STAGE_KIND,
        "stage": name,
        "group": "metatrain",
        "settings": {"values": {"iterations": iterations, **values}},
        "seconds": seconds,
        "result": {},
    }
    (d / "stage.json").write_text(json.dumps(data))


def test_estimates_read_the_reference_run_the_pace_and_a_part_way_run(tmp_path):
    from warp_critic.reproduce.status import estimator, pace

    ref, out = tmp_path / "ref", tmp_path / "out"
    st = {
        n: Stage(n, "metatrain", {"values": {"iterations": 100}}, {}, h * 10)
        for n, h in [("a", "1"), ("b", "2"), ("c", "3"), ("d", "4"), ("b-wide", "5"), ("e", "8")]
    }
    st["maps"] = Stage("maps", "maps", {}, {}, "6" * 10)
    _record(ref / st["a"].dir_name, "a", 100.0, 100)
    _record(out / st["a"].dir_name, "a", 150.0, 100)  # complete here: 1.5x the reference
    _record(ref / st["b"].dir_name, "b", 200.0, 100)  # the same stage: 200 s x 1.5
    # a step size and the length differ: 2 s per iteration x 100 x 1.5
    _record(ref / f"c-{'9' * 10}", "c", 400.0, 200, actor_lr=0.1)
    _record(ref / f"e-{'9' * 10}", "e", 400.0, 100, horizon=5)  # other work per iteration
    _record(ref / f"b-wide-{'7' * 10}", "b-wide", 50.0, 100)  # never taken for stage "b"
    run = out / st["d"].dir_name / "run" / "seed0"  # part way: 40 of 100 at 3 s
    run.mkdir(parents=True)
    (run / "config.json").write_text(json.dumps({"iterations": 100}))
    (run / "metrics.jsonl").write_text(
        "".join(json.dumps({"iteration": i, "seconds": 3.0}) + "\n" for i in range(40))
    )
    assert pace(out, st, ref) == 1.5
    est = estimator(out, st, ref)
    assert est("b") == (300.0, "3 min in the reference run, x 1.50: this folder's pace")
    c = est("c")
    assert c[0] == 300.0 and "with other step sizes or length, per iteration" in c[1]
    e = est("e")  # a meta-training without an estimate: held back in the limit's second half
    assert math.isnan(e[0]) and e[1].startswith("no estimate")
    assert est("d") == (180.0, "part way: iteration 40 of 100, 3.00 s per iteration")
    # part way with a reference time: 60% of 100 s x 1.5 is left, whatever its last iterations took
    # (here 10 s each, under other work: at that speed it would fit no sitting again)
    run = out / st["b"].dir_name / "run" / "seed0"
    run.mkdir(parents=True)
    (run / "config.json").write_text(json.dumps({"iterations": 100}))
    (run / "metrics.jsonl").write_text(
        "".join(json.dumps({"iteration": i, "seconds": 10.0}) + "\n" for i in range(40))
    )
    b = est("b")
    assert b[0] == pytest.approx(180.0) and b[1].startswith("part way: iteration 40 of 100")
    assert b[1].endswith("3 min in the reference run, x 1.50: this folder's pace, 60% left")
    assert est("maps") is None  # a meta-test keeps its finished batches: never held back
    b_wide = est("b-wide")
    assert b_wide[0] == 75.0 and "other step sizes or length" in b_wide[1]
    assert pace(tmp_path / "empty", st, ref) == 1.0


def test_a_recipe_that_identifies_the_model_is_reckoned_with_its_identifiers(tmp_path):
    """A recipe that identifies the model trains one identifier per seed after its meta-training,
    one after the other. Its reference record, resumed in its last call (``seconds`` 19), took
    its seeds' training (100 s) and their identifiers (2 x 50 s): 200 s, not 100. Part way, what
    is left is the training's share left plus the identifiers not complete."""
    from warp_critic.methods.identify import SUMMARY_FILE
    from warp_critic.reproduce.reference_times import parts
    from warp_critic.reproduce.status import estimator

    ref, out = tmp_path / "ref", tmp_path / "out"
    st = {"p": Stage("p", "metatrain", {"values": {"iterations": 100}}, {}, "1" * 10)}
    _record(ref / st["p"].dir_name, "p", 19.0, 100)
    data = json.loads((ref / st["p"].dir_name / "stage.json").read_text())
    seed = {"seconds": 100.0, "identified": {"seconds": 50.0}}
    data["result"] = {"seeds": {"0": seed, "1": seed}}
    (ref / st["p"].dir_name / "stage.json").write_text(json.dumps(data))
    assert parts(data, "metatrain") == (100.0, 100.0)
    # one call's record: its seconds hold the identifiers too
    assert parts({**data, "seconds": 230.0}, "metatrain") == (130.0, 100.0)
    est = estimator(out, st, ref)
    assert est("p")[0] == 200.0
    for n in (0, 1):  # part way: training done, seed 0's identifier complete, seed 1's not
        run = out / st["p"].dir_name / "run" / f"seed{n}"
        run.mkdir(parents=True)
        (run / "config.json").write_text(json.dumps({"iterations": 100}))
        (run / "metrics.jsonl").write_text(
            "".join(json.dumps({"iteration": i, "seconds": 1.0}) + "\n" for i in range(100))
        )
    (out / st["p"].dir_name / "run" / "seed0-identified").mkdir()
    (out / st["p"].dir_name / "run" / "seed0-identified" / SUMMARY_FILE).write_text(
        json.dumps(dict.fromkeys(("loss", "held_out", "varied", "seconds", "iterations"), 0))
    )
    left = est("p")
    assert left[0] == pytest.approx(50.0) and left[1].endswith("25% left")


@pytest.mark.parametrize(
    "argv, words",
    [
        (["--hours", "0"], "--hours must be a positive, finite number of hours (got 0.0)"),
        (["--hours", "nan"], "--hours must be a positive, finite number of hours"),
        (["--hours", "two"], "invalid number: 'two'"),
        (
            ["--hours", "1", "--status"],
            "--hours: limits a call that runs stages; --status runs none",
        ),
    ],
)
def test_bad_hours_are_one_line(tmp_path, capsys, argv, words):
    from warp_critic.cli.main import main

    try:
        code = main(["reproduce", "--quick", "--out", str(tmp_path / "o"), *argv])
    except SystemExit as e:  # argparse's own refusal of a value that is no number
        code = e.code
    err = capsys.readouterr().err
    assert code == 2 and words in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()


@pytest.mark.subprocess
def test_a_call_stopped_by_its_limit_exits_75_and_the_same_command_goes_on(tmp_path):
    out = tmp_path / "out"
    cmd = ["reproduce", "--quick", "--device", "cpu", "--only", "toy", "--out", str(out)]
    r = run_cli(*cmd, "--hours", "0.00001")
    assert r.returncode == EXIT_TIME_LIMIT, r.stderr
    last = r.stderr.strip().splitlines()[-1]
    assert last.startswith("warp-critic: reproduce: stopped: ")
    assert last.endswith("; the same command goes on from here")
    calls = [json.loads(x) for x in (out / "ledger.jsonl").read_text().splitlines()]
    assert calls[-1].get("status") == "interrupted"
    r = run_cli(*cmd)
    assert r.returncode == 0, r.stderr
