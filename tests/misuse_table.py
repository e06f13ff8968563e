"""The misuse table's machinery, shared by ``test_bad_input.py`` and ``test_misuse_three.py``.

Every case runs ``warp_critic.cli.main.main`` in a fresh temporary directory (``world``) that already
holds a finished tiny run (``run/``, with its own ``metatest.json``), a finished tiny DDPG run
(``ddpg/``), a folder of someone else's files that happen to be named like ours (``user/config.json``,
``user/metrics.jsonl``, ``user/recording.rrd``), a user's ``user_file.json`` and ``notes.txt``, a plain
file ``afile``, scene copies and goals files; :func:`check_case` hashes every file before and after
and holds the case to the table's rule (``test_bad_input.py``'s docstring).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import random
import shutil
import signal
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace

import pytest
from conftest import REACHER
from helpers import TINY_ONE_WORLD

from warp_critic.cli.main import main

TINY = ["--iterations", "1", *TINY_ONE_WORLD]
MT = ["meta-train", "{R}", *TINY]  # a new tiny meta-train run (add --out)
DDPG = ["baseline", "ddpg", "{R}", *TINY]
MC = ["baseline", "meta-critic", "{R}", *TINY]
TEST = ["meta-test", "{run}", "--device", "cpu", "--num-goals", "1", "--inits", "1"]
RESUME = ["meta-train", "{R}", "--resume", "--out", "{run}", "--device", "cpu", "--iterations", "3"]
RESUME_DDPG = [
    "baseline",
    "ddpg",
    "{R}",
    "--resume",
    "--out",
    "{ddpg}",
    "--device",
    "cpu",
    "--iterations",
    "2",
]

# ------------------------------------------------------------------------------------------------
# the finished runs (once per module) and each case's directory
# ------------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    from warp_critic.core.runtime import init
    from warp_critic.evaluation.metatest import MetaTestConfig, meta_test
    from warp_critic.methods.baseline_config import BaselineConfig
    from warp_critic.methods.ddpg import train_ddpg
    from warp_critic.methods.ours import TrainConfig, meta_train

    init()
    d = tmp_path_factory.mktemp("base")
    meta_train(
        TrainConfig(
            scene=REACHER,
            iterations=2,
            horizon=3,
            worlds_per_goal=1,
            device="cpu",
            out=str(d / "run"),
        ),
        progress=False,
    )
    meta_test(
        MetaTestConfig(run_dir=str(d / "run"), num_goals=1, inits=1, device="cpu"), progress=None
    )
    train_ddpg(
        BaselineConfig(
            scene=REACHER,
            iterations=1,
            horizon=3,
            worlds_per_goal=1,
            device="cpu",
            out=str(d / "ddpg"),
        ),
        progress=False,
    )
    assert (d / "run" / "metatest.json").is_file() and (d / "ddpg" / "checkpoint.pt").is_file()
    return d


@pytest.fixture
def world(tmp_path, base, monkeypatch):
    t = tmp_path
    shutil.copytree(base / "run", t / "run")
    shutil.copytree(base / "ddpg", t / "ddpg")
    user = t / "user"
    user.mkdir()
    (user / "config.json").write_text('{"learning_rate": 0.1, "mine": true}\n')
    (user / "metrics.jsonl").write_text('{"step": 0, "loss": 1.0}\n{"step": 1, "loss": 0.5}\n')
    (user / "recording.rrd").write_bytes(b"RRF2\x00someone else's recording")
    (t / "user_file.json").write_text('{"results": [1, 2, 3]}\n')
    (t / "notes.txt").write_text("my notes\n")
    (t / "afile").write_text("a file, not a directory\n")
    reacher = Path(REACHER).read_text()
    (t / "myrobot.usda").write_text(reacher)
    assert "warp_critic:goals" in reacher
    (t / "nogoals.usda").write_text(
        "".join(x for x in reacher.splitlines(keepends=True) if "warp_critic:goals" not in x)
    )
    assert "float physics:mass = 1\n" in reacher
    (t / "changed").mkdir()
    (t / "changed" / "reacher.usda").write_text(
        reacher.replace("float physics:mass = 1\n", "float physics:mass = 1.5\n", 1)
    )
    goals = t / "goals"
    goals.mkdir()
    (goals / "good.txt").write_text("# two goals\n0.5 0.3\n-0.4, 0.2\n")
    (goals / "nan.txt").write_text("0.5 0.3\n0.1 nan\n")
    (goals / "nan.json").write_text("[[0.5, 0.3], [NaN, 0.1]]")
    (goals / "inf.json").write_text("[[0.5, Infinity]]")
    (goals / "huge.json").write_text("[[1" + "0" * 400 + ", 0]]")
    (goals / "deep.json").write_text("[" * 100_000 + "]" * 100_000)
    (goals / "ragged.txt").write_text("0.1 0.2\n0.3\n")
    (goals / "empty.txt").write_text("# no goals here\n\n")
    noise = random.Random(0).randbytes(512) + b"\xff\xfe\x00"
    (goals / "binary.txt").write_bytes(noise)
    (goals / "binary.json").write_bytes(noise)
    (t / "binary.usda").write_bytes(noise)
    (t / "empty.usda").write_bytes(b"")
    monkeypatch.chdir(t)  # default output locations (runs/...) land here too
    monkeypatch.delenv("WARP_CRITIC_TORCH_THREADS", raising=False)
    monkeypatch.delenv("WARP_CRITIC_GRAPHS", raising=False)
    w = SimpleNamespace(
        t=t,
        run=t / "run",
        ddpg=t / "ddpg",
        user=user,
        new=t / "new_out",
        goals=goals,
        marker=t / "code-ran",
        cleanups=[],
    )
    yield w
    for cleanup in reversed(w.cleanups):
        cleanup()


def snapshot(root: Path) -> tuple[dict[str, str], set[str]]:
    files, dirs = {}, set()
    for p in sorted(root.rglob("*")):
        rel = p.relative_to(root).as_posix()
        if p.is_dir() and not p.is_symlink():
            dirs.add(rel)
        else:
            files[rel] = hashlib.sha256(p.read_bytes()).hexdigest()
    return files, dirs


class _Deadline(KeyboardInterrupt):
    """The alarm of :func:`run_main`: an interrupt, so the command stops as on Ctrl-C (exit 130)."""


def run_main(argv: list[str], limit: float) -> tuple[int, float]:
    """``main(argv)`` (argparse's exit taken as the code); a run still going after ``limit`` s is
    interrupted (as Ctrl-C: exit 130), so an absurd size that is not refused fails fast."""

    def expire(signum, frame):
        raise _Deadline

    old = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, limit)
    t0 = time.monotonic()
    try:
        try:
            code = main(argv)
        except SystemExit as e:
            code = e.code
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
    return code, time.monotonic() - t0


# ------------------------------------------------------------------------------------------------
# checks after a successful case, the table's cases and its rule
# ------------------------------------------------------------------------------------------------


def metrics_rows(path: Path) -> list[dict]:
    return [
        json.loads(x) for x in path.read_text().splitlines()
    ]  # every line must be complete JSON


def run_written(rel: str, iterations: int, scene: str | None = None):
    def check(w):
        d = w.t / rel
        assert (d / "checkpoint.pt").is_file() and (d / "recording.rrd").is_file()
        assert [r["iteration"] for r in metrics_rows(d / "metrics.jsonl")] == list(
            range(iterations)
        )
        assert not (d / ".lock").exists()
        if scene is not None:
            assert Path(json.loads((d / "config.json").read_text())["scene"]).name == scene

    return check


def result_written(rel: str, method: str = "ours"):
    def check(w):
        res = json.loads((w.t / rel).read_text())
        assert res["kind"] == "warp-critic/metatest-v1" and res["method"] == method

    return check


@dataclass
class Case:
    argv: list[str]
    code: int = 2
    says: tuple[str, ...] = ()  # in the one error line (or in every warning line, for exit 0)
    setup: Callable | None = None
    env: dict = field(default_factory=dict)
    changes: tuple[str, ...] = ()  # exit 0: paths (prefixes) the command may rewrite
    warns: int = 0  # exit 0: this many "warp-critic: warning:" lines
    check: Callable | None = None
    seconds: float = 30.0  # must finish within
    not_says: tuple[
        str, ...
    ] = ()  # never in the error line (e.g. a flag the command does not have)
    patch: Callable | None = (
        None  # patch(monkeypatch, w): faults the file system cannot make on demand
    )


# the cases that take half a second or more (they train, resume, start a pool or meet a live lock):
# left out of the fast loop
SLOW = frozenset(
    {
        "c01-no-goals-given-file",
        "c01-no-goals-given-inline",
        "c01-renamed-scene-ddpg",
        "c01-renamed-scene-meta-train",
        "c01-renamed-scene-resumes-run",
        "c03-truncated-last-metrics-line",
        "c04-reproduce-out-name-too-long",
        "c05-resume-user-dir",
        "c06-ddpg-live-lock",
        "c06-ddpg-dead-lock-taken-over",
        "c06-dead-lock-taken-over",
        "c06-garbage-lock-taken-over",
        "c06-stale-lock-pid-1-taken-over",
        "c07-resume-missing-metrics",
        "c12-ddpg",
        "c12-meta-critic",
        "c12-meta-train",
        "c12-resume",
        "c13-jobs-huge",
        "c13-jobs-zero",
        "c14-meta-test-out-inside-a-live-run",
        "c14-meta-test-out-replaces-results-json",
        "c14-meta-train-inside-a-live-run",
        "c14-reproduce-inside-a-live-run",
        "c15-asymmetric-limits-start-std",
        "c15-resume-a-checkpoint-of-another-run",
        "c16-ddpg-garbage-recording-resume",
        "c16-garbage-recording-resume",
        "c16-garbage-segment-of-a-killed-process",
        "c17-disk-full-png",
        "c17-lock-naming-a-huge-pid",
        "c17-metrics-row-without-task-loss",
        "c17-stage-json-with-empty-result",
        "c18-ray-address-of-a-plain-http-server",
        "d48-resume-run-stopped-before-first-checkpoint",
        "m48-resume-repairs-a-truncated-recording-and-says-what-it-kept",
        "m48-resume-repairs-a-truncated-segment-and-says-what-it-kept",
        "s47-train-variants-heavy-link-trains",
        "s47-train-variants-light-link-with-drop-trains",
        "t47-train-variants-blank",
        "w56-score-a-run-a-live-training-holds",
    }
)


def C(cls: str, name: str, argv: list[str], *, marks=(), **kw):
    case_id = f"{cls}-{name}"
    slow = (pytest.mark.slow,) if case_id in SLOW else ()
    given = (marks,) if isinstance(marks, pytest.MarkDecorator) else tuple(marks)
    return pytest.param(Case(argv=argv, **kw), id=case_id, marks=(*given, *slow))


def check_case(case: Case, world, capfd, monkeypatch) -> None:
    """Run ``case`` in ``world`` and hold it to the table's rule (exit code, the one line, the files)."""
    w = world
    for key, value in case.env.items():
        monkeypatch.setenv(key, value)
    if case.setup is not None:
        case.setup(w)
    if case.patch is not None:
        case.patch(monkeypatch, w)
    names = dict(
        R=REACHER,
        t=w.t,
        run=w.run,
        ddpg=w.ddpg,
        user=w.user,
        new=w.new,
        lock_pid=getattr(w, "lock_pid", None),
        port=getattr(w, "port", None),
    )
    argv = [a.format(**names) for a in case.argv]
    says = [s.format(**names) for s in case.says]
    files, dirs = snapshot(w.t)
    capfd.readouterr()

    code, seconds = run_main(argv, limit=case.seconds + 2)

    out, err = capfd.readouterr()
    lines = [
        x for x in err.splitlines() if x.strip() and not x.startswith("[")
    ]  # minus progress-bar lines
    assert "Traceback" not in err, err
    assert code == case.code, (code, err)
    assert seconds < case.seconds, f"took {seconds:.1f} s"
    after_files, after_dirs = snapshot(w.t)
    assert not [p for p in after_files if p.endswith(".tmp")], after_files
    if case.code == 2:
        assert len(lines) == 1 and lines[0].startswith("warp-critic: error: "), lines
        for s in says:
            assert s in lines[0], (s, lines[0])
        for s in case.not_says:
            assert s not in lines[0], (s, lines[0])
        # nothing written, nothing created (not even an empty directory), nothing removed
        assert after_files == files and after_dirs == dirs, (
            sorted(set(after_files) ^ set(files)),
            sorted(after_dirs ^ dirs),
            [p for p in files if after_files.get(p) != files[p]],
        )
    elif case.code == 1:  # a failure of the machine (a full disk): one line, only `changes` touched
        assert len(lines) == 1 and lines[0].startswith("warp-critic: error: "), lines
        for s in says:
            assert s in lines[0], (s, lines[0])
        kept = {p: h for p, h in files.items() if not p.startswith(case.changes)}
        assert {p: after_files.get(p) for p in kept} == kept
        assert not [p for p in after_files if p.endswith(".lock") and p not in files], after_files
    else:
        assert len(lines) == case.warns and all(
            x.startswith("warp-critic: warning: ") for x in lines
        ), lines
        for s in says:
            assert all(s in x for x in lines), (s, lines)
        kept = {
            p: h for p, h in files.items() if not p.startswith(case.changes) or not case.changes
        }
        assert {p: after_files.get(p) for p in kept} == kept, [
            p for p in kept if after_files.get(p) != kept[p]
        ]
        assert not [p for p in after_files if p.endswith(".lock") and p not in files], after_files
    if case.check is not None:
        case.check(w)


# ------------------------------------------------------------------------------------------------
# set-ups and checks shared by the misuse tables
# ------------------------------------------------------------------------------------------------


def hold_lock(run: str):
    """A live process holds the run directory's OS lock (this test process, through its own file lock)."""

    def setup(w):
        from filelock import FileLock

        d = getattr(w, run) if hasattr(w, run) else w.t / run
        lock = FileLock(str(d / ".lock"), timeout=0)
        lock.acquire()
        w.lock_pid = os.getpid()
        (d / ".lock").write_text(
            json.dumps({"pid": w.lock_pid, "host": socket.gethostname(), "started": 0.0})
        )

        def release():
            with contextlib.suppress(OSError):
                (d / ".lock").unlink()
            lock.release()

        w.cleanups.append(release)

    return setup


def reproduce_output(w):
    """A reproduce output ``rep/`` (marker, results.json, a stage directory with its stage.json)."""
    rep = w.t / "rep"
    (rep / "stagedir").mkdir(parents=True)
    (rep / ".warp-critic-reproduce").write_text('{"kind": "warp-critic/reproduce-output-v1"}\n')
    (rep / "results.json").write_text('{"kind": "warp-critic/metatest-v1"}\n')
    (rep / "stagedir" / "stage.json").write_text('{"kind": "warp-critic/metatest-v1"}\n')


def disk_full_on(name_part: str):
    """Writes of files whose name holds ``name_part`` fail as on a full disk (after a partial write)."""

    def patch(monkeypatch, w):
        import errno

        from warp_critic.running import files

        real = files._write_bytes

        def write(path, data):
            if name_part in Path(path).name:
                real(path, data[:10])
                raise OSError(errno.ENOSPC, "No space left on device")
            real(path, data)

        monkeypatch.setattr(files, "_write_bytes", write)

    return patch


def live_run_kept(w):
    assert (w.run / ".lock").is_file() and not (w.run / "metatest2.json").exists()
