"""Bad input through the real command line: one line, exit code 2, no traceback, nothing of the user's touched.

Every case runs ``warp_critic.cli.main.main`` in a fresh temporary directory that already holds a finished tiny
run (``run/``, with its own ``metatest.json``), a finished tiny DDPG run (``ddpg/``), a folder of someone
else's files that happen to be named like ours (``user/config.json``, ``user/metrics.jsonl``,
``user/recording.rrd``), a user's ``user_file.json`` and ``notes.txt``, a plain file ``afile``, scene copies
and goals files. Every file is hashed before and after:

* exit code 2: exactly one stderr line ``warp-critic: error: ...`` (progress-bar lines start with ``[``),
  naming what was wrong; no traceback; the directory tree is exactly as before (no file changed, no file
  or directory -- not even an empty one -- created, no ``.tmp`` left behind);
* exit code 0 (valid input, tiny runs): no stderr line but the expected ``warp-critic: warning:`` lines;
  every file outside the paths the command may write is byte-identical.

The absurd-size cases must be refused within seconds (a timer interrupts a run that started anyway).
Property-based cases (hypothesis) feed arbitrary numbers to numeric flags of meta-train and meta-test
through the CLI down to the config checks, with the training / meta-test itself replaced by those checks.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import math
import os
import shlex
import shutil
import socket
import subprocess
import tempfile
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace
from unittest import mock

import pytest
import torch
from conftest import REACHER
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from misuse_table import (  # noqa: F401 (base, world: the fixtures)
    DDPG,
    MC,
    MT,
    RESUME,
    RESUME_DDPG,
    TEST,
    TINY,
    C,
    Case,
    base,
    check_case,
    disk_full_on,
    hold_lock,
    live_run_kept,
    metrics_rows,
    reproduce_output,
    result_written,
    run_written,
    snapshot,
    world,
)

from warp_critic.cli.main import main

LONG = "a" * 300  # a file name the OS refuses (ENAMETOOLONG)
IS_ROOT = hasattr(os, "geteuid") and os.geteuid() == 0
HAS_CUDA = torch.cuda.is_available()


# ------------------------------------------------------------------------------------------------
# set-ups that change a case's directory before the snapshot
# ------------------------------------------------------------------------------------------------


def drop_key(run: str, key: str):
    def setup(w):
        path = getattr(w, run) / "checkpoint.pt"
        ckpt = torch.load(path, weights_only=False)
        del ckpt[key]
        torch.save(ckpt, path)

    return setup


class RunsCode:
    """Unpickling this runs a shell command (a crafted checkpoint)."""

    def __init__(self, marker: Path):
        self.marker = str(marker)

    def __reduce__(self):
        return (os.system, ("touch " + shlex.quote(self.marker),))


def crafted(run: str, full: bool):
    def setup(w):
        path = getattr(w, run) / "checkpoint.pt"
        ckpt = (
            torch.load(path, weights_only=False) if full else {"kind": "warp-critic/checkpoint-v1"}
        )
        ckpt["x"] = RunsCode(w.marker)
        torch.save(ckpt, path)

    return setup


def write_lock(run: str, pid: Callable[[], int], host: Callable[[], str] = socket.gethostname):
    def setup(w):
        w.lock_pid = pid()
        (getattr(w, run) / ".lock").write_text(
            json.dumps({"pid": w.lock_pid, "host": host(), "started": 0.0})
        )

    return setup


def dead_pid() -> int:
    proc = subprocess.Popen(["true"])
    proc.wait()
    return proc.pid


def garbage_lock(w):
    (w.run / ".lock").write_bytes(b"\x00garbage")


def truncate_metrics(w):
    with open(w.run / "metrics.jsonl", "a") as f:
        f.write('{"iteration": 2, "task_lo')  # a killed process's last, unfinished row


def corrupt_metrics_middle(w):
    lines = (w.run / "metrics.jsonl").read_text().splitlines(keepends=True)
    (w.run / "metrics.jsonl").write_text("not json\n" + "".join(lines))


def delete_metrics(w):
    (w.run / "metrics.jsonl").unlink()


def garbage_checkpoint(w):
    (w.run / "checkpoint.pt").write_bytes(b"not a torch file at all")


def list_checkpoint(w):
    torch.save([1, 2, 3], w.run / "checkpoint.pt")


def make_dir(name: str):
    def setup(w):
        (w.t / name).mkdir(parents=True)

    return setup


def read_only_dir(w):
    (w.t / "ro").mkdir()
    (w.t / "ro").chmod(0o555)


def copy_result(w):
    shutil.copy(w.run / "metatest.json", w.t / "prev.json")


def huge_pid_lock(w):
    (w.run / ".lock").write_text(
        json.dumps({"pid": 10**20 - 1, "host": socket.gethostname(), "started": 0})
    )


def asymmetric_scene(w):
    """A reacher whose first joint moves in [30, 90] degrees (home inside)."""
    text = Path(REACHER).read_text()
    assert text.count("float physics:lowerLimit = -170") == 2
    text = text.replace("float physics:lowerLimit = -170", "float physics:lowerLimit = 30", 1)
    text = text.replace("float physics:upperLimit = 170", "float physics:upperLimit = 90", 1)
    text = text.replace("warp_critic:homePose = [0, 0]", "warp_critic:homePose = [1, 0]")
    goals = "warp_critic:goals = [1, 0.5, -1, -0.5, 0.5, -1, -0.5, 1]"
    assert goals in text
    text = text.replace(goals, "warp_critic:goals = [1, 0.5, 1.2, -0.5]")
    (w.t / "asym.usda").write_text(text)


def checkpoint_of_another_scene(w):
    """run/checkpoint.pt replaced by the checkpoint of a run on another scene (changed/reacher.usda)."""
    from warp_critic.methods.ours import TrainConfig, meta_train

    other = w.t / "other"
    meta_train(
        TrainConfig(
            scene=str(w.t / "changed" / "reacher.usda"),
            iterations=2,
            horizon=3,
            worlds_per_goal=1,
            device="cpu",
            out=str(other),
        ),
        progress=False,
    )
    shutil.copy(other / "checkpoint.pt", w.run / "checkpoint.pt")
    shutil.rmtree(other)


def garbage_recording(w):
    (w.run / "recording.rrd").write_bytes(b"\x00not a rerun recording\xff" * 40)


def kept_aside(w):
    aside = [p for p in w.run.iterdir() if p.name.startswith("recording.") and "bad" in p.name]
    assert len(aside) == 1 and aside[0].read_bytes() == b"\x00not a rerun recording\xff" * 40
    assert (w.run / "recording.rrd").stat().st_size > 0
    assert not (w.run / "recording.segment.rrd").exists()


def garbage_segment(w):
    (w.run / "recording.segment.rrd").write_bytes(b"\x00not a rerun segment\xff" * 40)


def segment_kept_aside(w):
    aside = [p for p in w.run.iterdir() if p.name.startswith("recording.segment.bad")]
    assert len(aside) == 1 and aside[0].read_bytes() == b"\x00not a rerun segment\xff" * 40
    assert (w.run / "recording.rrd").stat().st_size > 0


def metrics_first_row(row: dict):
    def setup(w):
        lines = (w.run / "metrics.jsonl").read_text().splitlines(keepends=True)
        (w.run / "metrics.jsonl").write_text(json.dumps(row) + "\n" + "".join(lines[1:]))

    return setup


def relative_scene(w, cwd_scene: str | None = None):
    """The run as trained from the repository root (scene recorded as ``scenes/reacher.usda``)."""
    path = w.run / "checkpoint.pt"
    ckpt = torch.load(path, weights_only=False)
    ckpt["config"]["scene"] = "scenes/reacher.usda"
    ckpt.pop("scene_file", None)
    torch.save(ckpt, path)
    config = json.loads((w.run / "config.json").read_text())
    config["scene"] = "scenes/reacher.usda"
    config.pop("scene_file", None)
    (w.run / "config.json").write_text(json.dumps(config))
    if cwd_scene is not None:
        (w.t / "scenes").mkdir()
        (w.t / "scenes" / "reacher.usda").write_text(cwd_scene)


def other_scene_in_cwd(w):
    relative_scene(w, (w.t / "changed" / "reacher.usda").read_text())


def empty_stage_results(w):
    """A reproduce output whose reacher meta-training stages are complete but hold ``"result": {}``."""
    from warp_critic.reproduce.engine.stages import MARKER, STAGE_KIND
    from warp_critic.reproduce.experiments.plan import ReproduceConfig, plan

    rep = w.t / "rep"
    rep.mkdir()
    (rep / MARKER).write_text('{"kind": "warp-critic/reproduce-output-v1"}\n')
    st = plan(ReproduceConfig(out=rep, quick=True, seeds=2).validate())
    for name, stage in st.items():
        if name.startswith("metatrain-reacher-"):
            d = rep / stage.dir_name
            d.mkdir()
            (d / "stage.json").write_text(
                json.dumps({"kind": STAGE_KIND, "stage": name, "seconds": 1.0, "result": {}})
            )


def http_server(w):
    """A plain HTTP server on loopback (not a Ray head)."""
    import http.server
    import threading

    class Quiet(http.server.SimpleHTTPRequestHandler):
        def log_message(self, *args):  # its log would be on the test's stderr
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Quiet)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    w.port = server.server_address[1]
    w.cleanups.append(server.shutdown)


# ------------------------------------------------------------------------------------------------
# checks after a successful case
# ------------------------------------------------------------------------------------------------


def no_code_ran(w):
    assert not w.marker.exists(), "unpickling the checkpoint ran code"


def lock_released(w):
    assert not (w.run / ".lock").exists()


# ------------------------------------------------------------------------------------------------
# the table
# ------------------------------------------------------------------------------------------------


def NEW(*argv: str) -> list[str]:  # a command that must not create its --out (it does not exist)
    return [*argv, "--out", "{new}"]


def xfail(reason: str):
    return pytest.mark.xfail(strict=True, reason=reason)


FINITE_TRAIN = [
    ("gravity", "nan"),
    ("start-std", "inf"),
    ("alpha", "-inf"),
    ("lr", "nan"),
    ("ee-mass", "inf"),
    ("link-length", "nan"),
    ("link-scale", "-inf"),
    ("qd-scale", "inf"),
    ("dt", "nan"),
    ("dt", "1e999"),
    ("clip-grad", "NaN"),
    ("running-weight", "Infinity"),
]

CASES = [
    # 1. scene defaults come from the scene's content, not its file name
    C(
        "c01",
        "renamed-scene-meta-train",
        ["meta-train", "{t}/myrobot.usda", *TINY, "--out", "{new}"],
        code=0,
        check=run_written("new_out", 1, "myrobot.usda"),
    ),
    C(
        "c01",
        "renamed-scene-ddpg",
        ["baseline", "ddpg", "{t}/myrobot.usda", *TINY, "--out", "{new}"],
        code=0,
        check=run_written("new_out", 1, "myrobot.usda"),
    ),
    C(
        "c01",
        "renamed-scene-resumes-run",
        [
            "meta-train",
            "{t}/myrobot.usda",
            "--resume",
            "--out",
            "{run}",
            "--device",
            "cpu",
            "--iterations",
            "3",
        ],
        code=0,
        changes=("run/",),
        check=run_written("run", 3, "myrobot.usda"),
    ),
    C(
        "c01",
        "no-goals-meta-train",
        NEW("meta-train", "{t}/nogoals.usda", *TINY),
        says=("--goals", "nogoals.usda"),
    ),
    C(
        "c01",
        "no-goals-ddpg",
        NEW("baseline", "ddpg", "{t}/nogoals.usda", *TINY),
        says=("--goals",),
    ),
    C(
        "c01",
        "no-goals-meta-critic",
        NEW("baseline", "meta-critic", "{t}/nogoals.usda", *TINY),
        says=("--goals",),
    ),
    C(
        "c01",
        "no-goals-given-inline",
        ["meta-train", "{t}/nogoals.usda", *TINY, "--goals", "0.5,0.3", "--out", "{new}"],
        code=0,
        check=run_written("new_out", 1),
    ),
    C(
        "c01",
        "no-goals-given-file",
        [
            "meta-train",
            "{t}/nogoals.usda",
            *TINY,
            "--goals",
            "{t}/goals/good.txt",
            "--out",
            "{new}",
        ],
        code=0,
        check=run_written("new_out", 1),
    ),
    # 2. non-finite numbers in every kind of float flag and in goals files: refused before any work
    *[
        C(
            "c02",
            f"meta-train-{flag}-{value}",
            NEW(*MT, f"--{flag}={value}"),
            says=(f"--{flag}", value),
        )
        for flag, value in FINITE_TRAIN
    ],
    C(
        "c02",
        "meta-train-max-torque-list",
        NEW(*MT, "--max-torque", "20,nan"),
        says=("--max-torque", "nan"),
    ),
    C(
        "c02",
        "meta-train-max-torque-one",
        NEW(*MT, "--max-torque=inf"),
        says=("--max-torque", "inf"),
    ),
    C("c02", "meta-test-goal-std", [*TEST, "--goal-std", "nan"], says=("--goal-std", "nan")),
    C("c02", "meta-test-alpha", [*TEST, "--alpha", "inf"], says=("--alpha", "inf")),
    C("c02", "meta-test-link-scale", [*TEST, "--link-scale=-inf"], says=("--link-scale", "-inf")),
    C("c02", "ddpg-gamma", NEW(*DDPG, "--gamma", "nan"), says=("--gamma", "nan")),
    C("c02", "ddpg-tau", NEW(*DDPG, "--tau", "inf"), says=("--tau", "inf")),
    C("c02", "ddpg-actor-lr", NEW(*DDPG, "--actor-lr=-inf"), says=("--actor-lr", "-inf")),
    C("c02", "meta-critic-aux-lr", NEW(*MC, "--aux-lr", "nan"), says=("--aux-lr", "nan")),
    C(
        "c02",
        "goals-txt-nan",
        NEW(*MT, "--goals", "{t}/goals/nan.txt"),
        says=("--goals", "nan.txt", "nan"),
    ),
    C(
        "c02",
        "goals-json-nan",
        NEW(*MT, "--goals", "{t}/goals/nan.json"),
        says=("--goals", "nan.json", "nan"),
    ),
    C(
        "c02",
        "goals-json-infinity",
        NEW(*DDPG, "--goals", "{t}/goals/inf.json"),
        says=("--goals", "inf.json", "inf"),
    ),
    C(
        "c02",
        "goals-json-huge-int",
        NEW(*MT, "--goals", "{t}/goals/huge.json"),
        says=("--goals", "huge.json"),
    ),
    C("c02", "goals-inline-inf", NEW(*MT, "--goals", "0.5,inf"), says=("--goals", "inf")),
    C(
        "c02",
        "meta-test-goals-nan",
        [*TEST, "--goals", "{t}/goals/nan.txt"],
        says=("--goals", "nan.txt", "nan"),
    ),
    # 3. user mistakes that used to end in tracebacks
    C("c03", "seed-2**32", NEW(*MT, "--seed", str(2**32)), says=("--seed", str(2**32))),
    C("c03", "seed-minus-1", NEW(*MT, "--seed", "-1"), says=("--seed", "-1")),
    C("c03", "ddpg-seed-minus-1", NEW(*DDPG, "--seed=-1"), says=("--seed", "-1")),
    C("c03", "meta-test-seed-2**32", [*TEST, "--seed", str(2**32)], says=("--seed", str(2**32))),
    C(
        "c03",
        "ragged-goals-file",
        NEW(*MT, "--goals", "{t}/goals/ragged.txt"),
        says=("--goals", "ragged.txt"),
    ),
    C(
        "c03",
        "binary-goals-txt",
        NEW(*MT, "--goals", "{t}/goals/binary.txt"),
        says=("--goals", "binary.txt"),
    ),
    C(
        "c03",
        "binary-goals-json",
        [*TEST, "--goals", "{t}/goals/binary.json"],
        says=("--goals", "binary.json"),
    ),
    C(
        "c03",
        "deeply-nested-goals-json",
        NEW(*MT, "--goals", "{t}/goals/deep.json"),
        says=("--goals", "deep.json"),
    ),
    C("c03", "cpu-threads-minus-1", NEW(*MT, "--cpu-threads=-1"), says=("--cpu-threads", "-1")),
    C(
        "c03",
        "cpu-threads-100000",
        NEW(*MT, "--cpu-threads", "100000"),
        says=("--cpu-threads", "100000"),
    ),
    C(
        "c03",
        "ddpg-cpu-threads-100000",
        NEW(*DDPG, "--cpu-threads", "100000"),
        says=("--cpu-threads",),
    ),
    C(
        "c03",
        "meta-test-no-critic-state",
        TEST,
        setup=drop_key("run", "critic_state"),
        says=("critic_state",),
    ),
    C(
        "c03",
        "resume-no-critic-state",
        RESUME,
        setup=drop_key("run", "critic_state"),
        says=("critic_state",),
    ),
    C(
        "c03",
        "ddpg-resume-no-agent-state",
        RESUME_DDPG,
        setup=drop_key("ddpg", "agent_state"),
        says=("agent_state",),
    ),
    C(
        "c03",
        "meta-test-garbage-checkpoint",
        TEST,
        setup=garbage_checkpoint,
        says=("checkpoint.pt", "readable"),
    ),
    C(
        "c03",
        "meta-test-list-checkpoint",
        TEST,
        setup=list_checkpoint,
        says=("checkpoint.pt", "not a warp-critic"),
    ),
    C(
        "c03",
        "resume-a-ddpg-run",
        ["meta-train", "{R}", "--resume", "--out", "{ddpg}", "--device", "cpu"],
        says=("ddpg",),
    ),
    C(
        "c03",
        "meta-critic-resume-a-ddpg-run",
        ["baseline", "meta-critic", "{R}", "--resume", "--out", "{ddpg}", "--device", "cpu"],
        says=("ddpg", "meta-critic"),
    ),
    C(
        "c03",
        "truncated-last-metrics-line",
        RESUME,
        code=0,
        setup=truncate_metrics,
        changes=("run/",),
        check=run_written("run", 3),
    ),
    C(
        "c03",
        "corrupt-metrics-middle-line",
        RESUME,
        setup=corrupt_metrics_middle,
        says=("metrics.jsonl", "line 1"),
    ),
    *[
        C(
            "c03",
            f"threads-env-{value}",
            NEW(*MT),
            env={"WARP_CRITIC_TORCH_THREADS": value},
            says=("WARP_CRITIC_TORCH_THREADS", value),
        )
        for value in ("abc", "0", "-2", "100000", "1.5")
    ],
    C(
        "c03",
        "threads-env-meta-test",
        TEST,
        env={"WARP_CRITIC_TORCH_THREADS": "abc"},
        says=("WARP_CRITIC_TORCH_THREADS",),
    ),
    *[
        C(
            "c03",
            f"graphs-env-{value}",
            NEW(*MT),
            env={"WARP_CRITIC_GRAPHS": value},
            says=("WARP_CRITIC_GRAPHS", value),
        )
        for value in ("yes", "2", "-1")
    ],
    C("c03", "empty-goals", NEW(*MT, "--goals="), says=("--goals", "no goals")),
    C("c03", "goals-only-separators", NEW(*MT, "--goals", ";;"), says=("--goals", "no goals")),
    C("c03", "goals-a-directory", NEW(*MT, "--goals", "{t}/goals"), says=("--goals", "directory")),
    C(
        "c03",
        "goals-empty-file",
        NEW(*MT, "--goals", "{t}/goals/empty.txt"),
        says=("--goals", "empty.txt"),
    ),
    C(
        "c03",
        "goals-missing-file",
        NEW(*MT, "--goals", "{t}/goals/missing.json"),
        says=("--goals", "missing.json"),
    ),
    C(
        "c03",
        "goals-wrong-dof",
        NEW(*MT, "--goals", "0.1,0.2,0.3"),
        says=("--goals", "2 joint values"),
    ),
    C(
        "c03",
        "meta-test-goals-wrong-dof",
        [*TEST, "--goals", "0.1,0.2,0.3"],
        says=("--goals", "2 joint values"),
    ),
    C("c03", "meta-test-around-minus-1", [*TEST, "--around=-1"], says=("--around", "-1")),
    C("c03", "meta-test-around-past-the-goals", [*TEST, "--around", "0,9"], says=("--around", "9")),
    C("c03", "binary-scene", NEW("meta-train", "{t}/binary.usda", *TINY), says=("binary.usda",)),
    C("c03", "empty-scene", NEW("meta-train", "{t}/empty.usda", *TINY), says=("empty.usda",)),
    C("c03", "scene-a-directory", NEW("baseline", "ddpg", "{t}/goals", *TINY), says=("goals",)),
    C("c03", "unknown-device", NEW(*MT, "--device", "tpu"), says=("--device", "tpu")),
    C("c03", "home-starts-over-worlds", NEW(*MT, "--home-starts", "2"), says=("--home-starts",)),
    C("c03", "max-torque-wrong-count", NEW(*MT, "--max-torque", "1,2,3"), says=("--max-torque",)),
    C("c03", "max-torque-no-values", NEW(*MT, "--max-torque", ","), says=("--max-torque",)),
    C(
        "c03",
        "meta-test-run-is-a-file",
        ["meta-test", "{t}/afile", "--device", "cpu"],
        says=("afile",),
    ),
    C(
        "c03",
        "meta-test-run-is-user-dir",
        ["meta-test", "{user}", "--device", "cpu"],
        says=("user",),
    ),
    C(
        "c03",
        "meta-test-missing-run",
        ["meta-test", "{new}", "--device", "cpu"],
        says=("new_out", "not found"),
    ),
    C("c03", "unknown-flag", NEW(*MT, "--horizn", "3"), says=("--horizn",)),
    C("c03", "unknown-command", ["meta-trian", "{R}"], says=("meta-trian",)),
    C("c03", "int-flag-float-text", NEW(*MT, "--horizon", "2.5"), says=("--horizon", "2.5")),
    # 4. the file system: refused before any work, nothing created, no temporary file left
    C("c04", "out-is-a-file", [*MT, "--out", "{t}/afile"], says=("afile", "file")),
    C("c04", "out-under-a-file", [*MT, "--out", "{t}/afile/sub"], says=("afile",)),
    C("c04", "ddpg-out-under-a-file", [*DDPG, "--out", "{t}/afile/sub/deeper"], says=("afile",)),
    C("c04", "meta-test-out-is-a-directory", [*TEST, "--out", "{user}"], says=("user",)),
    C(
        "c04",
        "meta-test-out-is-a-json-directory",
        [*TEST, "--out", "{t}/dir.json"],
        setup=make_dir("dir.json"),
        says=("dir.json", "directory"),
    ),
    C(
        "c04",
        "meta-test-out-parent-is-a-file",
        [*TEST, "--out", "{t}/afile/x.json"],
        says=("afile",),
    ),
    C(
        "c04",
        "meta-test-out-grandparent-is-a-file",
        [*TEST, "--out", "{t}/afile/a/b/x.json"],
        says=("afile",),
    ),
    C(
        "c04",
        "read-only-out-parent",
        [*MT, "--out", "{t}/ro/sub"],
        setup=read_only_dir,
        says=("ro",),
        marks=pytest.mark.skipif(IS_ROOT, reason="root ignores permissions"),
    ),
    C(
        "c04",
        "meta-test-read-only-out",
        [*TEST, "--out", "{t}/ro/x.json"],
        setup=read_only_dir,
        says=("ro",),
        marks=pytest.mark.skipif(IS_ROOT, reason="root ignores permissions"),
    ),
    # paths the system refuses: a name over 255 bytes
    C("c04", "meta-train-out-name-too-long", [*MT, "--out", "{t}/" + LONG], says=("too long",)),
    C(
        "c04",
        "meta-train-scene-name-too-long",
        ["meta-train", "{t}/" + LONG + ".usda", *TINY],
        says=("too long",),
    ),
    C(
        "c04",
        "meta-train-goals-name-too-long",
        NEW(*MT, "--goals", "{t}/" + LONG + ".json"),
        says=("too long",),
    ),
    C(
        "c04",
        "meta-test-run-name-too-long",
        ["meta-test", "{t}/" + LONG, "--device", "cpu"],
        says=("too long",),
    ),
    C(
        "c04",
        "reproduce-out-name-too-long",
        ["reproduce", "--quick", "--out", "{t}/" + LONG],
        says=("too long",),
    ),
    C(
        "c04",
        "toy-out-name-too-long",
        ["analyze", "toy", "--out", "{t}/" + LONG],
        says=("too long",),
    ),
    # 5. files that are not ours are never overwritten, files of ours only by their own kind
    C(
        "c05",
        "meta-test-out-checkpoint",
        [*TEST, "--out", "{run}/checkpoint.pt"],
        says=("checkpoint.pt",),
    ),
    C(
        "c05",
        "meta-test-out-run-config",
        [*TEST, "--out", "{run}/config.json"],
        says=("config.json",),
    ),
    C(
        "c05",
        "meta-test-out-user-json",
        [*TEST, "--out", "{t}/user_file.json"],
        says=("user_file.json",),
    ),
    C(
        "c05",
        "meta-test-out-user-config",
        [*TEST, "--out", "{user}/config.json"],
        says=("config.json",),
    ),
    C(
        "c05",
        "meta-test-out-user-metrics",
        [*TEST, "--out", "{user}/metrics.jsonl"],
        says=("metrics.jsonl",),
    ),
    C("c05", "meta-test-out-user-notes", [*TEST, "--out", "{t}/notes.txt"], says=("notes.txt",)),
    C("c05", "meta-train-into-user-dir", [*MT, "--out", "{user}"], says=("user", "not empty")),
    C("c05", "meta-train-into-cwd", [*MT, "--out", "."], says=("not empty",)),
    C("c05", "ddpg-into-user-dir", [*DDPG, "--out", "{user}"], says=("user", "not empty")),
    C("c05", "meta-critic-into-user-dir", [*MC, "--out", "{user}"], says=("user",)),
    C(
        "c05",
        "resume-user-dir",
        ["meta-train", "{R}", "--resume", "--out", "{user}", "--device", "cpu"],
        says=("user",),
    ),
    C("c05", "meta-train-over-a-run", [*MT, "--out", "{run}"], says=("run", "--resume")),
    C("c05", "ddpg-over-a-run", [*DDPG, "--out", "{ddpg}"], says=("ddpg", "--resume")),
    C("c05", "ddpg-over-our-run", [*DDPG, "--out", "{run}"], says=("run",)),
    # 6. locks (an OS file lock: held while its process lives; the .lock file only names the holder)
    C("c06", "live-lock", RESUME, setup=hold_lock("run"), says=("process {lock_pid}",)),
    C(
        "c06",
        "stale-lock-pid-1-taken-over",
        RESUME,
        code=0,
        setup=write_lock("run", lambda: 1),
        warns=1,
        says=("process 1 ", "taking over"),
        changes=("run/",),
        check=lambda w: (run_written("run", 3)(w), lock_released(w)),
    ),
    C(
        "c06",
        "lock-of-another-host",
        RESUME,
        setup=write_lock("run", dead_pid, lambda: "another-host.example"),
        marks=pytest.mark.subprocess,  # dead_pid starts and reaps a process
        says=("another-host.example",),
    ),
    C(
        "c06",
        "garbage-lock-taken-over",
        RESUME,
        code=0,
        setup=garbage_lock,
        warns=1,
        says=("taking over",),
        changes=("run/",),
        check=run_written("run", 3),
    ),
    C("c06", "ddpg-live-lock", RESUME_DDPG, setup=hold_lock("ddpg"), says=("process {lock_pid}",)),
    C(
        "c06",
        "dead-lock-taken-over",
        RESUME,
        code=0,
        setup=write_lock("run", dead_pid),
        marks=pytest.mark.subprocess,  # dead_pid starts and reaps a process
        warns=1,
        says=("{lock_pid}", "taking over"),
        changes=("run/",),
        check=lambda w: (run_written("run", 3)(w), lock_released(w)),
    ),
    C(
        "c06",
        "ddpg-dead-lock-taken-over",
        RESUME_DDPG,
        code=0,
        setup=write_lock("ddpg", dead_pid),
        marks=pytest.mark.subprocess,  # dead_pid starts and reaps a process
        warns=1,
        says=("{lock_pid}",),
        changes=("ddpg/",),
        check=run_written("ddpg", 2),
    ),
    # 7. resume: the saved settings hold
    C("c07", "resume-other-horizon", [*RESUME, "--horizon", "4"], says=("horizon", "3", "4")),
    C("c07", "resume-other-worlds", [*RESUME, "--worlds-per-goal", "3"], says=("worlds", "1 -> 3")),
    C(
        "c07",
        "resume-other-critic-input",
        [*RESUME, "--critic-input", "relative"],
        says=("--critic-input", "relative"),
    ),
    C("c07", "resume-other-seed", [*RESUME, "--seed", "7"], says=("seed", "7")),
    C("c07", "ddpg-resume-other-gamma", [*RESUME_DDPG, "--gamma", "0.5"], says=("gamma", "0.5")),
    C("c07", "resume-iterations-0", [*RESUME, "--iterations", "0"], says=("--iterations",)),
    C("c07", "resume-fewer-iterations", [*RESUME, "--iterations", "1"], says=("--iterations", "2")),
    C(
        "c07",
        "resume-changed-scene",
        [
            "meta-train",
            "{t}/changed/reacher.usda",
            "--resume",
            "--out",
            "{run}",
            "--device",
            "cpu",
            "--iterations",
            "3",
        ],
        says=("scene", "differs"),
    ),
    C(
        "c07",
        "resume-missing-run",
        ["meta-train", "{R}", "--resume", "--out", "{new}", "--device", "cpu"],
        says=("new_out", "not found"),
    ),
    C(
        "c07",
        "resume-missing-metrics",
        RESUME,
        code=0,
        setup=delete_metrics,
        warns=1,
        says=("metrics.jsonl", "missing"),
        changes=("run/",),
    ),
    # 8. absurd sizes: refused at once, naming an estimate or a limit
    C(
        "c08",
        "worlds-per-goal-1e9",
        NEW(*MT, "--worlds-per-goal", "1000000000"),
        says=("--worlds-per-goal", "GiB"),
        seconds=5,
    ),
    C(
        "c08",
        "inner-steps-1e9",
        NEW(*MT, "--inner-steps", "1000000000"),
        says=("--inner-steps", "10000"),
        seconds=5,
    ),
    C(
        "c08",
        "horizon-1e8",
        NEW(*MT, "--horizon", "100000000"),
        says=("--horizon", "1000000"),
        seconds=5,
    ),
    C(
        "c08",
        "iterations-1e12",
        NEW(*MT, "--iterations", str(10**12)),
        says=("--iterations", "100000000"),
        seconds=5,
    ),
    C("c08", "substeps-1e9", NEW(*MT, "--substeps", str(10**9)), says=("--substeps",), seconds=5),
    C(
        "c08",
        "critic-hidden-1e9",
        NEW(*MT, "--critic-hidden", str(10**9)),
        says=("--critic-hidden",),
        seconds=5,
    ),
    C(
        "c08",
        "ddpg-worlds-per-goal-1e9",
        NEW(*DDPG, "--worlds-per-goal", str(10**9)),
        says=("--worlds-per-goal", "GiB"),
        seconds=5,
    ),
    C(
        "c08",
        "ddpg-buffer-size-1e12",
        NEW(*DDPG, "--buffer-size", str(10**12)),
        says=("--buffer-size", "1000000000"),
        seconds=5,
    ),
    C(
        "c08",
        "ddpg-batch-size-1e9",
        NEW(*DDPG, "--batch-size", str(10**9)),
        says=("--batch-size", "10000000"),
        seconds=5,
    ),
    C(
        "c08",
        "ddpg-updates-1e12",
        NEW(*DDPG, "--updates-per-iteration", str(10**12)),
        says=("--updates-per-iteration",),
        seconds=5,
    ),
    C(
        "c08",
        "meta-test-inits-1e9",
        [*TEST, "--inits", str(10**9)],
        says=("--inits", "1000000"),
        seconds=5,
    ),
    C(
        "c08",
        "meta-test-num-goals-1e9",
        [*TEST, "--num-goals", str(10**9)],
        says=("--num-goals",),
        seconds=5,
    ),
    C(
        "c08",
        "meta-test-policy-steps-1e9",
        [*TEST, "--policy-steps", str(10**9)],
        says=("--policy-steps",),
        seconds=5,
    ),
    C(
        "c08",
        "meta-test-horizon-1e9",
        [*TEST, "--horizon", str(10**9)],
        says=("--horizon",),
        seconds=5,
    ),
    C(
        "c08",
        "meta-test-1e7-worlds",
        ["meta-test", "{run}", "--device", "cpu", "--num-goals", "10", "--inits", "1000000"],
        says=("--inits",),
        seconds=5,
    ),
    # 9. a crafted checkpoint's code never runs
    C(
        "c09",
        "meta-test-crafted-checkpoint",
        TEST,
        setup=crafted("run", full=False),
        says=("checkpoint.pt", "refused"),
        check=no_code_ran,
    ),
    C(
        "c09",
        "resume-crafted-checkpoint",
        RESUME,
        setup=crafted("run", full=True),
        says=("checkpoint.pt", "refused"),
        check=no_code_ran,
    ),
    C(
        "c09",
        "ddpg-resume-crafted-checkpoint",
        RESUME_DDPG,
        setup=crafted("ddpg", full=True),
        says=("checkpoint.pt", "refused"),
        check=no_code_ran,
    ),
    C(
        "c09",
        "meta-test-crafted-ddpg-checkpoint",
        ["meta-test", "{ddpg}", "--device", "cpu"],
        setup=crafted("ddpg", full=True),
        says=("checkpoint.pt", "refused"),
        check=no_code_ran,
    ),
    # 10. zero is a value, not "the default"
    *[
        C("c10", f"meta-test-{flag}-0", [*TEST, f"--{flag}", "0"], says=(f"--{flag}", "> 0"))
        for flag in ("alpha", "horizon", "policy-steps", "inits", "num-goals")
    ],
    *[
        C("c10", f"meta-train-{flag}-0", NEW(*MT, f"--{flag}", "0"), says=(f"--{flag}", "> 0"))
        for flag in (
            "worlds-per-goal",
            "inner-steps",
            "dt",
            "qd-scale",
            "substeps",
            "critic-hidden",
        )
    ],
    *[
        C("c10", f"ddpg-{flag}-0", NEW(*DDPG, f"--{flag}", "0"), says=(f"--{flag}",))
        for flag in ("batch-size", "gamma", "tau", "updates-per-iteration")
    ],
    # 11. early failures leave no directory behind, not even the parents of --out
    C("c11", "nested-out-bad-flag", [*MT, "--lr", "nan", "--out", "{t}/a/b/c"], says=("--lr",)),
    C(
        "c11",
        "nested-out-bad-scene",
        ["meta-train", "{t}/missing.usda", *TINY, "--out", "{t}/a/b/c"],
        says=("missing.usda",),
    ),
    C(
        "c11",
        "ddpg-nested-out-bad-seed",
        [*DDPG, "--seed=-1", "--out", "{t}/a/b/c"],
        says=("--seed",),
    ),
    C(
        "c11",
        "meta-test-nested-out-bad-alpha",
        [*TEST, "--alpha", "0", "--out", "{t}/a/b/x.json"],
        says=("--alpha",),
    ),
    C(
        "c11",
        "meta-test-nested-out-bad-checkpoint",
        [*TEST, "--out", "{t}/a/b/x.json"],
        setup=drop_key("run", "critic_state"),
        says=("critic_state",),
    ),
    C(
        "c11",
        "no-cuda-device",
        NEW(*MT, "--device", "cuda"),
        says=("--device", "cuda"),
        marks=pytest.mark.skipif(HAS_CUDA, reason="needs a machine without CUDA"),
    ),
    C(
        "c11",
        "no-cuda-device-nested-out",
        [*MT, "--device", "cuda", "--out", "{t}/a/b/c"],
        says=("--device", "cuda"),
        marks=pytest.mark.skipif(HAS_CUDA, reason="needs a machine without CUDA"),
    ),
    # 12. valid input still works
    C("c12", "meta-train", NEW(*MT), code=0, check=run_written("new_out", 1)),
    C("c12", "ddpg", NEW(*DDPG), code=0, check=run_written("new_out", 1)),
    C("c12", "meta-critic", NEW(*MC), code=0, check=run_written("new_out", 1)),
    C("c12", "resume", RESUME, code=0, changes=("run/",), check=run_written("run", 3)),
    C(
        "c12",
        "meta-test-out-json",
        [*TEST, "--out", "{t}/x.json"],
        code=0,
        check=result_written("x.json"),
    ),
    C(
        "c12",
        "meta-test-out-new-dirs",
        [*TEST, "--out", "{t}/results/today/x.json"],
        code=0,
        check=result_written("results/today/x.json"),
    ),
    C(
        "c12",
        "meta-test-overwrites-own-result",
        TEST,
        code=0,
        changes=("run/metatest.json",),
        check=result_written("run/metatest.json"),
    ),
    C(
        "c12",
        "meta-test-overwrites-earlier-result",
        [*TEST, "--out", "{t}/prev.json"],
        setup=copy_result,
        code=0,
        changes=("prev.json",),
        check=result_written("prev.json"),
    ),
    C(
        "c12",
        "meta-test-ddpg",
        [
            "meta-test",
            "{ddpg}",
            "--device",
            "cpu",
            "--num-goals",
            "1",
            "--inits",
            "1",
            "--out",
            "{t}/d.json",
        ],
        code=0,
        check=result_written("d.json", "ddpg"),
    ),
    C("c12", "meta-test-goal-std-0", [*TEST, "--goal-std", "0", "--out", "{t}/x.json"], code=0),
    C(
        "c12",
        "meta-test-goals-file",
        [*TEST, "--goals", "{t}/goals/good.txt", "--out", "{t}/x.json"],
        code=0,
    ),
    C("c12", "meta-train-gravity-0", NEW(*MT, "--gravity", "0", "--start-std", "0"), code=0),
    # a long inline goal list is not a file name (the OS refuses names over 255 bytes)
    C(
        "c12",
        "meta-test-long-inline-goals",
        [*TEST, "--goals=" + ";".join(["-0.25,0.125"] * 40), "--out", "{t}/x.json"],
        code=0,
        check=result_written("x.json"),
    ),
    # 13. reproduce --set: every setting of every stage checked before the first stage runs
    *[
        C(
            "c13",
            f"set-{key}-{value}",
            ["reproduce", "--quick", "--only", only, "--set", f"{key}={value}", "--out", "{new}"],
            says=("--set", key, shown),
            seconds=10,
        )
        for only, key, value, shown in (
            ("toy", "toy.iters", "abc", "abc"),
            ("toy", "toy.iters", "NaN", "nan"),
            ("toy", "toy.iters", "1e400", "inf"),
            ("toy", "toy.grid", "1000000000000", "1000000000000"),
            ("toy", "toy.s0", "[1]", "[1]"),
            ("toy", "maps.grid", "0", "0"),
            ("toy", "maps.limit_fraction", "5", "5"),
            ("toy", "maps.masses", "[-1]", "-1"),
            ("toy", "maps.reach_iterations", "-1", "-1"),
            ("toy", "maps.reach_lrs", "[0]", "0"),
            ("toy", "maps.reach_lrs", "[]", "[]"),
            ("toy", "landscape.grid", "-3", "-3"),
            ("toy", "tables.around", "[7]", "7"),
            ("toy", "tables.stds", "[]", "[]"),
            ("toy", "tables.stress_masses", "[-1]", "-1"),
            ("toy", "tables.stress_lengths", "[0]", "0"),
            ("toy", "tables.reach_iterations", "-1", "-1"),
            ("toy", "tables.reach_iterations", "1.5", "1.5"),
            ("toy", "metatrain.seeds", "[-1]", "-1"),
            ("toy", "metatrain.seeds", "[]", "[]"),
            ("toy", "metatrain.kuka.ddpg.horizon", "0", "0"),
            ("toy", "metatrain.reacher.ours.goals", "[[9,9]]", "goals"),
            ("toy", "metatrain.reacher.ours.max_torque", "[1e9]", "1000000000"),
        )
    ],
    *[
        C(
            "c13",
            f"set-metatrain-{key}",
            [
                "reproduce",
                "--quick",
                "--only",
                "toy",
                "--set",
                f'metatrain.reacher.ours.{key}="x"',
                "--out",
                "{new}",
            ],
            says=("--set", f"metatrain.reacher.ours.{key}", "may not be set"),
            seconds=10,
        )
        for key in ("out", "scene", "resume", "device", "seed", "seeds")
    ],
    C(
        "c13",
        "set-tables-goal-noise-before-training",
        [
            "reproduce",
            "--quick",
            "--seeds",
            "1",
            "--only",
            "tables",
            "--set",
            "tables.goal_noise=bogus",
            "--out",
            "{new}",
        ],
        says=("--set", "tables.goal_noise", "bogus"),
        not_says=("--goal-noise",),
        seconds=10,
    ),
    C(
        "c13",
        "seeds-and-set-metatrain-seeds-disagree",
        [
            "reproduce",
            "--quick",
            "--seeds",
            "3",
            "--only",
            "toy",
            "--set",
            "metatrain.seeds=[5]",
            "--out",
            "{new}",
        ],
        says=("--seeds", "metatrain.seeds"),
        seconds=10,
    ),
    C(
        "c13",
        "jobs-huge",
        [
            "reproduce",
            "--quick",
            "--only",
            "toy",
            "--jobs",
            "99999999999999999999",
            "--out",
            "{new}",
        ],
        says=("--jobs",),
        seconds=10,
    ),
    C(
        "c13",
        "jobs-zero",
        ["reproduce", "--quick", "--only", "toy", "--jobs", "0", "--out", "{new}"],
        says=("--jobs",),
        seconds=10,
    ),
    # 14. a directory that holds a live lock, or a reproduce output, belongs to its owner
    C("c14", "meta-test-next-to-a-live-run", TEST, setup=hold_lock("run"), says=("run", "in use")),
    C(
        "c14",
        "meta-test-out-inside-a-live-run",
        [*TEST, "--out", "{run}/metatest2.json"],
        setup=hold_lock("run"),
        says=("run", "in use"),
    ),
    C(
        "c14",
        "meta-test-of-a-live-run-writes-elsewhere",
        [*TEST, "--out", "{t}/x.json"],
        setup=hold_lock("run"),
        code=0,
        check=lambda w: (result_written("x.json")(w), live_run_kept(w)),
    ),
    C(
        "c14",
        "meta-train-inside-a-live-run",
        [*MT, "--out", "{run}/sub"],
        setup=hold_lock("run"),
        says=("run", "in use"),
    ),
    C(
        "c14",
        "reproduce-inside-a-live-run",
        ["reproduce", "--quick", "--only", "toy", "--out", "{run}/rep"],
        setup=hold_lock("run"),
        says=("run", "in use"),
        seconds=10,
    ),
    C(
        "c14",
        "meta-test-out-replaces-stage-json",
        [*TEST, "--out", "{t}/rep/stagedir/stage.json"],
        setup=reproduce_output,
        says=("rep", "reproduce"),
    ),
    C(
        "c14",
        "meta-test-out-replaces-results-json",
        [*TEST, "--out", "{t}/rep/results.json"],
        setup=reproduce_output,
        says=("rep", "reproduce"),
    ),
    C(
        "c14",
        "meta-train-inside-a-reproduce-output",
        [*MT, "--out", "{t}/rep/mine"],
        setup=reproduce_output,
        says=("rep", "reproduce"),
    ),
    C(
        "c14",
        "toy-inside-a-reproduce-output",
        ["analyze", "toy", "--iters", "5", "--grid", "5", "--out", "{t}/rep/toy"],
        setup=reproduce_output,
        says=("rep", "reproduce"),
    ),
    # 15. numbers that were silently wrong
    C(
        "c15",
        "max-torque-above-the-effort-limit",
        NEW(*MT, "--max-torque", "1000"),
        says=("--max-torque", "1000", "20"),
    ),
    C(
        "c15",
        "ddpg-max-torque-above-the-effort-limit",
        NEW(*DDPG, "--max-torque", "5,21"),
        says=("--max-torque", "21", "20"),
    ),
    C(
        "c15",
        "resume-a-checkpoint-of-another-run",
        [
            "meta-train",
            "{t}/changed/reacher.usda",
            "--resume",
            "--out",
            "{run}",
            "--device",
            "cpu",
            "--iterations",
            "3",
        ],
        setup=checkpoint_of_another_scene,
        says=("checkpoint.pt", "another run"),
    ),
    C(
        "c15",
        "asymmetric-limits-start-std",
        ["meta-train", "{t}/asym.usda", *TINY, "--goals", "1.0,0.3", "--start-std", "2"]
        + ["--out", "{new}"],
        setup=asymmetric_scene,
        code=0,
        check=run_written("new_out", 1),
    ),
    # 16. nothing lost
    C(
        "c16",
        "garbage-recording-resume",
        RESUME,
        code=0,
        setup=garbage_recording,
        warns=1,
        says=("recording.rrd", "kept"),
        changes=("run/",),
        check=kept_aside,
    ),
    C(
        "c16",
        "ddpg-garbage-recording-resume",
        RESUME_DDPG,
        code=0,
        setup=lambda w: garbage_recording(SimpleNamespace(run=w.ddpg)),
        warns=1,
        says=("recording.rrd", "kept"),
        changes=("ddpg/",),
        check=lambda w: kept_aside(SimpleNamespace(run=w.ddpg)),
    ),
    C(
        "c16",
        "garbage-segment-of-a-killed-process",
        RESUME,
        code=0,
        setup=garbage_segment,
        warns=1,
        says=("recording.segment.rrd", "kept"),
        changes=("run/",),
        check=segment_kept_aside,
    ),
    # 17. edited or odd files, full disks: one line, never a traceback
    C(
        "c17",
        "stage-json-with-empty-result",
        ["reproduce", "--quick", "--only", "maps", "--out", "{t}/rep", "--device", "cpu"],
        setup=empty_stage_results,
        says=("stage.json",),
        seconds=15,
    ),
    C(
        "c17",
        "metrics-row-without-task-loss",
        RESUME,
        setup=metrics_first_row({"iteration": 0}),
        says=("metrics.jsonl", "line 1", "task_loss"),
    ),
    C(
        "c17",
        "metrics-row-task-loss-a-string",
        RESUME,
        setup=metrics_first_row({"iteration": 0, "task_loss": "low"}),
        says=("metrics.jsonl", "line 1", "task_loss"),
    ),
    C(
        "c17",
        "lock-naming-a-huge-pid",
        RESUME,
        code=0,
        setup=huge_pid_lock,
        warns=1,
        says=("taking over",),
        changes=("run/",),
        check=run_written("run", 3),
    ),
    C("c17", "out-not-utf8", [*MT, "--out", "{t}/bad\udcffname"], says=("--out", "UTF-8")),
    C(
        "c17",
        "meta-test-out-not-utf8",
        [*TEST, "--out", "{t}/bad\udcff.json"],
        says=("--out", "UTF-8"),
    ),
    C(
        "c17",
        "disk-full-checkpoint-resume",
        RESUME,
        patch=disk_full_on("checkpoint.pt"),
        code=1,
        says=("checkpoint.pt", "space"),
        changes=("run/",),
        check=lambda w: torch.load(w.run / "checkpoint.pt", weights_only=False)["iteration"] == 1,
    ),
    C(
        "c17",
        "disk-full-png",
        NEW("analyze", "toy", "--iters", "5", "--grid", "5"),
        patch=disk_full_on(".png"),
        code=1,
        says=("png", "space"),
        changes=("new_out",),
    ),
    # 18. errors that pointed the wrong way
    C(
        "c18",
        "meta-test-scene-recorded-relative-elsewhere",
        TEST,
        setup=relative_scene,
        code=0,
        warns=1,
        says=("scenes/reacher.usda", "same content"),
        changes=("run/metatest.json",),
        check=result_written("run/metatest.json"),
    ),
    C(
        "c18",
        "meta-test-other-scene-of-that-name-in-cwd",
        TEST,
        setup=other_scene_in_cwd,
        code=0,
        warns=1,
        says=("scenes/reacher.usda", "same content"),
        changes=("run/metatest.json",),
        check=result_written("run/metatest.json"),
    ),
    C(
        "c18",
        "ray-address-of-a-plain-http-server",
        ["reproduce", "--quick", "--only", "toy", "--ray", "127.0.0.1:{port}", "--out", "{new}"],
        setup=http_server,
        says=("--ray", "127.0.0.1:{port}", "not a Ray"),
        seconds=10,
    ),
    # the analyses (being refactored elsewhere)
    C("ana", "toy-s0-nan", NEW("analyze", "toy", "--s0", "nan"), says=("--s0", "nan")),
    C("ana", "toy-iters-0", NEW("analyze", "toy", "--iters", "0"), says=("--iters",)),
    C("ana", "toy-alpha-minus-inf", NEW("analyze", "toy", "--alpha=-inf"), says=("--alpha", "inf")),
    C("ana", "toy-out-is-a-file", ["analyze", "toy", "--out", "{t}/afile"], says=("afile",)),
    C("ana", "toy-out-under-a-file", ["analyze", "toy", "--out", "{t}/afile/sub"], says=("afile",)),
    C(
        "ana",
        "landscape-grid-1e5",
        NEW("analyze", "landscape", "--grid", "100000"),
        says=("--grid",),
        seconds=5,
    ),
    C(
        "ana",
        "landscape-range-nan",
        NEW("analyze", "landscape", "--range", "nan"),
        says=("--range", "nan"),
    ),
    C(
        "ana",
        "landscape-goal-nan",
        NEW("analyze", "landscape", "--goal", "nan,1"),
        says=("--goal", "nan"),
    ),
    C(
        "ana",
        "landscape-iterations-0",
        NEW("analyze", "landscape", "--iterations", "0"),
        says=("--iterations",),
    ),
]


@pytest.mark.parametrize("case", CASES)
def test_bad_input(case: Case, world, capfd, monkeypatch):  # noqa: F811 (the fixture)
    check_case(case, world, capfd, monkeypatch)


def test_table_covers_every_class():
    classes = {}
    for p in CASES:
        classes.setdefault(p.id.split("-")[0], []).append(p.id)
    assert sorted(classes) == ["ana", *[f"c{i:02d}" for i in range(1, 19)]]
    assert all(len(v) >= 3 for v in classes.values()), {k: len(v) for k, v in classes.items()}
    assert len(CASES) >= 70
    assert len({p.id for p in CASES}) == len(CASES)


# ------------------------------------------------------------------------------------------------
# property-based: arbitrary numbers in numeric flags, down to the config checks
# ------------------------------------------------------------------------------------------------

SPECIAL = [
    "nan",
    "NaN",
    "-nan",
    "inf",
    "+inf",
    "-inf",
    "Infinity",
    "1e999",
    "-1e999",
    "0",
    "-0",
    "0.0",
    "1e-320",
    "1e308",
    "-1",
    "1",
    "2",
    "4294967295",
    "4294967296",
    "1000000",
    "1000001",
    "100000000",
    "1e3",
    "0x10",
    "1_000",
    " 3 ",
    "",
]
NUMBER_TEXT = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(min_value=-(10**13), max_value=10**13).map(str),
    st.sampled_from(SPECIAL),
)


def _parse(kind, text: str):
    try:
        value = kind(text)
    except ValueError:
        return None
    return value


def in_spec(meta, x) -> bool:
    if not math.isfinite(x):
        return False
    return not (
        ("cap" in meta and x > meta["cap"])
        or ("gt" in meta and not x > meta["gt"])
        or ("ge" in meta and not x >= meta["ge"])
        or ("lt" in meta and not x < meta["lt"])
        or ("le" in meta and not x <= meta["le"])
    )


def run_quiet(argv: list[str]) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            code = main(argv)
        except SystemExit as e:
            code = e.code
    return code, err.getvalue()


def check_outcome(cls, name: str, text: str, code: int, err: str) -> None:
    f = {f.name: f for f in dataclasses.fields(cls)}[name]
    hint = f.type if isinstance(f.type, str) else str(f.type)
    kind = int if hint.startswith("int") else float
    value = _parse(kind, text)
    valid = value is not None and in_spec(f.metadata, value)
    lines = [x for x in err.splitlines() if x.strip() and not x.startswith("[")]
    event(f"exit {code} ({'valid' if valid else 'invalid'} value)")
    assert "Traceback" not in err, err
    assert code in (0, 2), (code, err)
    if code == 2:
        assert len(lines) == 1 and lines[0].startswith("warp-critic: error: "), lines
        assert "--" + name.replace("_", "-") in lines[0], lines
        # a value within its range is refused only when the run would not fit in memory, or its
        # policy lifetime x inner steps is over meta-test's step limit (a rule across two fields)
        assert not valid or "GiB" in lines[0] or "critic-gradient steps" in lines[0], (text, lines)
    else:
        assert valid and not lines, (text, lines)


TRAIN_NUMBERS = [
    "gravity",
    "start_std",
    "alpha",
    "lr",
    "ee_mass",
    "link_length",
    "link_scale",
    "qd_scale",
    "dt",
    "clip_grad",
    "horizon",
    "worlds_per_goal",
    "iterations",
    "inner_steps",
    "seed",
    "policy_lifetime",
]
TEST_NUMBERS = [
    "goal_std",
    "alpha",
    "ee_mass",
    "link_length",
    "link_scale",
    "inits",
    "num_goals",
    "horizon",
    "policy_steps",
    "seed",
]


@pytest.mark.slow
@settings(
    max_examples=40, deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow]
)
@given(name=st.sampled_from(TRAIN_NUMBERS), text=NUMBER_TEXT)
def test_meta_train_numbers_property(name, text):
    from warp_critic.methods import ours as train
    from warp_critic.running.loop import TrainResult
    from warp_critic.running.task import load_task_scene

    def checks_only(
        cfg, given=None, **kw
    ):  # everything meta_train checks before it builds the worlds
        load_task_scene(cfg)
        return TrainResult(Path(cfg.out), [])

    with tempfile.TemporaryDirectory() as tmp, mock.patch.object(train, "meta_train", checks_only):
        out = Path(tmp) / "run"
        code, err = run_quiet(
            ["meta-train", REACHER, *TINY, f"--{name.replace('_', '-')}={text}", "--out", str(out)]
        )
        check_outcome(train.TrainConfig, name, text, code, err)
        assert not out.exists()


@pytest.mark.slow
@settings(
    max_examples=40, deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow]
)
@given(name=st.sampled_from(TEST_NUMBERS), text=NUMBER_TEXT)
def test_meta_test_numbers_property(name, text, base):  # noqa: F811 (the fixture)
    from warp_critic.evaluation import metatest
    from warp_critic.running.config import check_fields
    from warp_critic.running.files import check_output_file

    def checks_only(tc, **kw):  # meta-test's checks before it loads the run
        out = check_output_file(Path(tc.out), "out")
        check_fields(tc)
        return {"output": str(out)}

    with (
        tempfile.TemporaryDirectory() as tmp,
        mock.patch.object(metatest, "meta_test", checks_only),
    ):
        out = Path(tmp) / "x.json"
        code, err = run_quiet(
            [
                "meta-test",
                str(base / "run"),
                "--device",
                "cpu",
                f"--{name.replace('_', '-')}={text}",
                "--out",
                str(out),
            ]
        )
        check_outcome(metatest.MetaTestConfig, name, text, code, err)
        assert not out.exists()
