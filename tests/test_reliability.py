"""Ownership of outputs, signals at any moment, orphaned workers, asymmetric limits, full disks,
errors that cross processes: the cases of the misuse sweep that need more than one process or a
look inside (the one-line CLI cases are in ``test_bad_input.py``)."""

from __future__ import annotations

import errno
import json
import os
import pickle
import signal
import socket
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest
import torch
from conftest import REACHER
from helpers import TINY_ONE_WORLD, cli_command

from warp_critic.cli.main import main

TINY = TINY_ONE_WORLD


def error_lines(err: str) -> list[str]:
    return [x for x in err.splitlines() if x.strip() and not x.startswith("[")]


def lock_held(path: Path) -> bool:
    from filelock import FileLock, Timeout

    if not path.exists():
        return False
    lock = FileLock(str(path), timeout=0)
    try:
        lock.acquire()
    except Timeout:
        return True
    lock.release()
    return False


def children(pid: int) -> set[int]:
    """Live (not zombie) child processes of ``pid``."""
    out = set()
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            out |= {int(x) for x in (task / "children").read_text().split()}
        except OSError:
            pass
    return {c for c in out if alive(c)}


def catches_sigterm(pid: int) -> bool:
    """Whether ``pid`` has a handler for SIGTERM (``SigCgt`` of ``/proc/PID/status``)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    mask = next((x.split()[1] for x in status.splitlines() if x.startswith("SigCgt:")), "0")
    return bool(int(mask, 16) & (1 << (signal.SIGTERM - 1)))


def alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state not in ("Z", "X")


# ------------------------------------------------------------------------------------------------
# one owner per output
# ------------------------------------------------------------------------------------------------


def test_another_commands_check_of_a_folder_is_no_owner(tmp_path):
    """Two commands that check one folder at once (each takes its lock for an instant to see whether
    anyone holds it) do not see each other as its owner; a lock held throughout is one."""
    from filelock import FileLock

    from warp_critic.running.locks import LOCK, PROBE_WAIT_S, holder

    (tmp_path / LOCK).write_text('{"pid": 1, "host": "elsewhere"}')
    other = FileLock(str(tmp_path / LOCK), timeout=0, thread_local=False)
    other.acquire()  # the other command's check, let go while this one still looks
    threading.Timer(PROBE_WAIT_S, other.release).start()
    assert holder(tmp_path) is None
    other.acquire()  # an owner
    try:
        assert holder(tmp_path) == {"pid": 1, "host": "elsewhere"}
    finally:
        other.release()


@pytest.mark.slow
@pytest.mark.subprocess
def test_a_second_reproduce_driver_on_one_out_is_refused_and_the_first_untouched(tmp_path, capfd):
    out = tmp_path / "paper"
    first = subprocess.Popen(
        [*cli_command(), "reproduce", "--quick", "--only", "toy,landscape", "--out", str(out)]
        + ["--device", "cpu"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 120
        while not lock_held(out / ".lock"):
            assert first.poll() is None and time.monotonic() < deadline, first.communicate()
            time.sleep(0.05)
        capfd.readouterr()
        code = main(["reproduce", "--quick", "--only", "toy", "--out", str(out), "--device", "cpu"])
        lines = error_lines(capfd.readouterr().err)
        assert code == 2 and len(lines) == 1, lines
        assert "in use by" in lines[0] and str(first.pid) in lines[0], lines
        _, err = first.communicate(timeout=300)
    finally:
        first.kill()
    assert first.returncode == 0, err
    assert (out / "REPORT.md").is_file() and len(list(out.glob("*/stage.json"))) == 2
    assert not (out / ".lock").exists()


# ------------------------------------------------------------------------------------------------
# signals at any moment of start-up and shutdown
# ------------------------------------------------------------------------------------------------


def maps(pid: int, library: str) -> bool:
    """Whether process ``pid`` has loaded the shared library ``library`` (``/proc/PID/maps``)."""
    try:
        return f"/{library}" in Path(f"/proc/{pid}/maps").read_text()
    except OSError:
        return False


# the moments of a meta-train's start-up, in order, each as the condition that says it has come
START_UP = {
    "handlers installed": lambda pid, out: catches_sigterm(pid),
    "torch loaded": lambda pid, out: maps(pid, "libtorch_cpu.so"),
    "warp loaded": lambda pid, out: maps(pid, "warp.so"),
    "run directory written": lambda pid, out: (out / "config.json").is_file(),
    "training": lambda pid, out: (
        (out / "metrics.jsonl").is_file() and (out / "metrics.jsonl").stat().st_size > 0
    ),
}


@pytest.mark.slow
@pytest.mark.subprocess
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_at_any_moment_of_start_up_is_one_line_and_exit_130(tmp_path, signum):
    """One process per moment of start-up (``START_UP``), one after the other, each signalled as
    soon as its moment has come (polled, at most 120 s). The interpreter's own start-up (before the
    first line of any Python program runs) cannot be guarded by a program, so the first moment is
    the handlers' installation."""
    for i, (moment, reached) in enumerate(START_UP.items()):
        out = tmp_path / f"r{i}"
        argv = ["meta-train", REACHER, *TINY, "--iterations", "100000"]
        p = subprocess.Popen(
            [*cli_command(), *argv, "--out", str(out)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        deadline = time.monotonic() + 120
        while not reached(p.pid, out):
            assert p.poll() is None and time.monotonic() < deadline, (moment, p.communicate())
            time.sleep(0.005)
        assert p.poll() is None, (moment, p.communicate())
        p.send_signal(signum)
        _, err = p.communicate(timeout=120)
        lines = error_lines(err)
        assert p.returncode == 130, (moment, p.returncode, err)
        assert "Traceback" not in err and "terminate" not in err, (moment, err)
        assert len(lines) == 1 and lines[0].startswith("warp-critic: "), (moment, lines)


@pytest.mark.slow
@pytest.mark.subprocess
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_during_shutdown_is_one_line_and_exit_130(tmp_path, signum):
    """The signal arrives after the command finished, while the interpreter shuts down."""
    script = textwrap.dedent(f"""
        import atexit, os, sys, time
        atexit.register(lambda: (os.kill(os.getpid(), {int(signum)}), time.sleep(5)))
        sys.argv = ["warp-critic", "analyze", "toy", "--iters", "5", "--grid", "5",
                    "--out", {str(tmp_path / "toy")!r}]
        from warp_critic.cli.main import main
        sys.exit(main())
    """)
    p = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    lines = error_lines(p.stderr)
    assert p.returncode == 130 and "Traceback" not in p.stderr, (p.returncode, p.stderr)
    assert len(lines) == 1 and lines[0].startswith("warp-critic: "), lines


# ------------------------------------------------------------------------------------------------
# orphaned workers
# ------------------------------------------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.subprocess
def test_workers_exit_when_their_driver_is_killed(tmp_path):
    out = tmp_path / "paper"
    driver = subprocess.Popen(
        [
            *cli_command(),
            "reproduce",
            "--quick",
            "--jobs",
            "2",
            "--only",
            "metatrain",
            "--seeds",
            "1",
        ]
        + ["--out", str(out), "--device", "cpu"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 180
        while not list(out.glob("metatrain-*/run/seed0/.warp-critic-run")):
            assert driver.poll() is None and time.monotonic() < deadline
            time.sleep(0.1)
        workers = children(driver.pid)
        assert len(workers) >= 2, workers
    finally:
        driver.kill()
        driver.wait()
    deadline = time.monotonic() + 10
    while any(alive(w) for w in workers) and time.monotonic() < deadline:
        time.sleep(0.1)
    left = [w for w in workers if alive(w)]
    for w in left:
        os.kill(w, signal.SIGKILL)
    assert not left, "workers outlived their driver by 10 s"


# ------------------------------------------------------------------------------------------------
# asymmetric joint limits
# ------------------------------------------------------------------------------------------------


def asymmetric(tmp_path: Path) -> str:
    text = Path(REACHER).read_text()
    text = text.replace("float physics:lowerLimit = -170", "float physics:lowerLimit = 30", 1)
    text = text.replace("float physics:upperLimit = 170", "float physics:upperLimit = 90", 1)
    text = text.replace("warp_critic:homePose = [0, 0]", "warp_critic:homePose = [1, 0]")
    text = text.replace(
        "warp_critic:goals = [1, 0.5, -1, -0.5, 0.5, -1, -0.5, 1]",
        "warp_critic:goals = [1, 0.5, 1.2, -0.5]",
    )
    path = tmp_path / "asym.usda"
    path.write_text(text)
    return str(path)


def test_start_states_and_sampled_goals_stay_inside_asymmetric_limits(tmp_path):
    from warp_critic.evaluation.metatest import sample_goals
    from warp_critic.methods.ours import TrainConfig
    from warp_critic.running.task import build_task, load_task_scene

    cfg = TrainConfig(
        scene=asymmetric(tmp_path),
        goals=[[1.0, 0.3]],
        worlds_per_goal=64,
        start_std=2.0,
        horizon=3,
        device="cpu",
    )
    cfg, scene = load_task_scene(cfg)
    task = build_task(cfg, scene, differentiable=False)
    lo, hi = task.sim.q_lower.cpu(), task.sim.q_upper.cpu()
    assert float(lo[0]) > 0.5  # 30 degrees: 0.95 * lower would lie below it
    q = task.start_states(torch.Generator().manual_seed(0)).cpu()
    assert bool(((q >= lo) & (q <= hi)).all()), (q.min(0).values, lo)
    g = sample_goals(
        torch.tensor([[1.0, 0.3]]), 200, 2.0, None, lo, hi, torch.Generator().manual_seed(0)
    )
    assert bool(((g >= lo) & (g <= hi)).all()), (g.min(0).values, lo)


def test_meta_test_of_an_asymmetric_run_does_not_blame_goals(tmp_path, capfd):
    scene = asymmetric(tmp_path)
    run = tmp_path / "run"
    argv = [
        "meta-train",
        scene,
        *TINY,
        "--iterations",
        "1",
        "--goals",
        "1.0,0.3",
        "--out",
        str(run),
    ]
    assert main(argv) == 0
    capfd.readouterr()
    code = main(
        ["meta-test", str(run), "--device", "cpu", "--num-goals", "20", "--goal-std", "2"]
        + ["--inits", "1"]
    )
    err = capfd.readouterr().err
    assert code == 0 and "--goals" not in err, err


# ------------------------------------------------------------------------------------------------
# full disks
# ------------------------------------------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.subprocess
def test_a_full_disk_while_warp_builds_its_kernels_is_one_line(tmp_path):
    script = textwrap.dedent(f"""
        import errno, sys
        import warp._src.build as build
        def full(*a, **k):
            raise OSError(errno.ENOSPC, "No space left on device")
        build.build_cpu = full
        from warp_critic.cli.main import main
        sys.exit(main(["meta-train", {REACHER!r}, "--iterations", "1", "--horizon", "3",
                       "--worlds-per-goal", "1", "--device", "cpu", "--out", {str(tmp_path / "r")!r}]))
    """)
    env = {**os.environ, "WARP_CACHE_PATH": str(tmp_path / "cache")}
    p = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=300
    )
    lines = error_lines(p.stderr)
    assert "Traceback" not in p.stderr, p.stderr
    assert p.returncode == 1 and len(lines) == 1, (p.returncode, lines)
    assert lines[0].startswith("warp-critic: error:") and "space" in lines[0], lines


def test_a_full_disk_while_saving_a_checkpoint_leaves_the_old_one(tmp_path, monkeypatch):
    from warp_critic.running import files
    from warp_critic.running.files import DiskFullError, atomic_torch_save

    path = tmp_path / "checkpoint.pt"
    atomic_torch_save({"iteration": 1}, path)
    before = path.read_bytes()

    def full(target, data):
        Path(target).write_bytes(data[:7])
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(files, "_write_bytes", full)
    with pytest.raises(DiskFullError, match="space"):
        atomic_torch_save({"iteration": 2}, path)
    assert path.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == [path.name]


# ------------------------------------------------------------------------------------------------
# errors that cross processes; the Ray address
# ------------------------------------------------------------------------------------------------


def test_user_errors_survive_pickling():
    from warp_critic.core.errors import FieldError, SceneError, UserError
    from warp_critic.running.rundir import RunExistsError
    from warp_critic.running.seedrun import ResumeMismatch

    for e in (
        FieldError("horizon", "must be > 0 (got 0)"),
        UserError("x: bad"),
        SceneError("s.usda: no articulation"),
        RunExistsError("run directory r: already holds a run"),
        ResumeMismatch("r", [("horizon", 3, 4)]),
    ):
        back = pickle.loads(pickle.dumps(e))
        assert type(back) is type(e) and str(back) == str(e)
        assert getattr(back, "field", None) == getattr(e, "field", None)


def test_a_user_error_in_a_ray_task_arrives_as_one_line(capfd):
    """What Ray hands back for a task that raised (a RayTaskError with the cause) is the one line."""
    from warp_critic.core.errors import FieldError, UserError
    from warp_critic.reproduce.engine.on_ray import unit_failure

    class RayTaskError(Exception):  # Ray's wrapper keeps the task's exception as ``cause``
        def __init__(self, cause):
            super().__init__("ray.exceptions.RayTaskError(FieldError): ...traceback...")
            self.cause = cause

    e = unit_failure("metatrain-kuka-ours", RayTaskError(FieldError("horizon", "must be > 0")))
    assert isinstance(e, FieldError) and e.field == "horizon"
    e = unit_failure("toy", RayTaskError(RuntimeError("boom")))
    assert isinstance(e, UserError) and "run again to resume" in str(e)


def _serve(sock: socket.socket, reply: bytes) -> None:
    def loop():
        while True:
            try:
                conn, _ = sock.accept()
            except OSError:
                return
            with conn:
                conn.recv(1024)
                conn.sendall(reply)
                time.sleep(0.2)

    threading.Thread(target=loop, daemon=True).start()


@pytest.mark.slow
def test_ray_address_must_speak_grpc():
    from warp_critic.core.errors import FieldError
    from warp_critic.reproduce.engine.on_ray import check_ray_address

    http = socket.create_server(("127.0.0.1", 0))
    _serve(http, b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\n\r\n")
    h2 = socket.create_server(("127.0.0.1", 0))
    _serve(h2, b"\x00\x00\x00\x04\x00\x00\x00\x00\x00")  # an HTTP/2 SETTINGS frame, as gRPC sends
    silent = socket.create_server(("127.0.0.1", 0))
    try:
        t0 = time.monotonic()
        with pytest.raises(FieldError, match="not a Ray"):
            check_ray_address(f"127.0.0.1:{http.getsockname()[1]}")
        with pytest.raises(FieldError, match="not a Ray"):
            check_ray_address(f"127.0.0.1:{silent.getsockname()[1]}")
        assert time.monotonic() - t0 < 10
        check_ray_address(f"127.0.0.1:{h2.getsockname()[1]}")
    finally:
        for s in (http, h2, silent):
            s.close()


# ------------------------------------------------------------------------------------------------
# what the report and config record
# ------------------------------------------------------------------------------------------------


def test_config_records_the_scene_file_and_its_content_hash(tmp_path):
    from warp_critic.physics.load import load_scene

    run = tmp_path / "run"
    assert main(["meta-train", REACHER, *TINY, "--iterations", "1", "--out", str(run)]) == 0
    config = json.loads((run / "config.json").read_text())
    assert Path(config["scene_file"]).is_absolute()
    assert Path(config["scene_file"]) == Path(REACHER).resolve()
    assert config["scene_hash"] == load_scene(REACHER).content_hash


@pytest.mark.slow
def test_report_names_the_seeds_that_were_trained():
    from warp_critic.reproduce.experiments.plan import ReproduceConfig, plan
    from warp_critic.reproduce.report.write import seeds_trained

    rc = ReproduceConfig(quick=True, seeds=2, overrides=["metatrain.seeds=[5]"])
    assert seeds_trained(plan(rc.validate())) == [5]
