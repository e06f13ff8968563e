"""The one training harness every method runs through (ours, DDPG, Meta-Critic).

A method builds its networks and writes one function, ``step(iteration) -> (metrics row, result)``,
plus ``state() -> dict`` for its checkpoint; :class:`Session` does everything around it, the same way
for all methods:

1. **start**: check the config, claim (or, on resume, open) the run directory and lock it, apply the
   resume rule (the run's saved config is the truth: only ``iterations`` may grow, any other
   difference is an error that lists them, and the scene's content must match), build the task's
   worlds and seed every generator;
2. **resume**: after the method has built its networks (so the random draws happen in the same order
   as in a fresh run), restore the checkpoint's states and RNG;
3. **run**: the iteration loop with progress bar, ``metrics.jsonl``, callbacks (the recorder is one),
   divergence and interrupt messages that say truthfully what was kept, and checkpoint cadence.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, Callable

import torch

from .errors import DivergenceError, FieldError, UserError
from .rundir import RunDir, _fault_point
from .runtime import restore_rng, rng_state, seed_everything, set_threads
from .task import RUNTIME_FIELDS, Task, TaskConfig, build_task, check_fields, load_task_scene


class Interrupted(KeyboardInterrupt):
    """Ctrl-C / SIGTERM during a run; the message says what was kept (``checkpoint``: its iteration)."""

    def __init__(self, message: str, checkpoint: int | None = None):
        super().__init__(message)
        self.checkpoint = checkpoint


@dataclass
class IterationInfo:
    """What callbacks get after every iteration."""

    iteration: int
    metrics: dict
    result: Any  # has ``before`` / ``after`` trajectories and, for ours, ``params_new``
    goal_index: torch.Tensor  # (W,) goal of each world


@dataclass
class TrainResult:
    run_dir: Path
    metrics: list[dict] = field(default_factory=list)
    model: Any = None  # the critic (ours) or the agent (baselines)
    config: TaskConfig | None = None


Callback = Callable[[IterationInfo], None]


def config_differences(saved: TaskConfig, requested: TaskConfig, given: set[str] | None) -> list[str]:
    """Settings of ``requested`` that contradict the saved run (runtime fields excepted).

    ``given``: the fields the user set explicitly (the CLI knows); ``None`` = every field that differs
    from the dataclass default counts as given.
    """
    diffs = []
    for f in fields(requested):
        if f.name in RUNTIME_FIELDS or f.name == "scene":
            continue
        value = getattr(requested, f.name)
        if given is not None:
            if f.name not in given:
                continue
        elif value is None or value == (f.default if not callable(f.default_factory) else f.default_factory()):
            continue
        old = getattr(saved, f.name, None)
        if value != old and not (isinstance(value, (int, float)) and isinstance(old, (int, float)) and float(value) == float(old)):
            diffs.append(f"{f.name} {old!r} -> {value!r}")
    return diffs


class Session:
    """One run of one method in its run directory (see the module docstring)."""

    def __init__(self, cfg: TaskConfig, *, differentiable: bool, given: set[str] | None = None):
        self.ckpt: dict | None = None
        check_fields(cfg)
        if cfg.resume:
            cfg = self._resume_config(cfg, given)
        scene = load_task_scene(cfg)
        self.scene_hash = getattr(scene, "content_hash", None)
        if self.ckpt is not None and self.ckpt.get("scene_hash") and self.scene_hash \
                and self.ckpt["scene_hash"] != self.scene_hash:
            raise FieldError("scene", f"{cfg.scene} differs in content from the scene the run in "
                                      f"{cfg.out} was trained on")
        if self.ckpt is None:
            self.rundir = RunDir.create(cfg.out, cfg.method)
        else:
            self.rundir.lock()
        self.cfg = cfg
        try:
            self.rundir.ensure_marker(cfg.method)
            self.gen = seed_everything(cfg.seed)
            self.task: Task = build_task(cfg, scene, differentiable=differentiable)
        except BaseException:
            self.close(failed=True)
            raise
        self.start = 0 if self.ckpt is None else self.ckpt["iteration"] + 1

    def _resume_config(self, requested: TaskConfig, given: set[str] | None) -> TaskConfig:
        cls = type(requested)
        if requested.out is None:
            requested.out = requested.default_out()
        self.rundir = RunDir.open(requested.out)
        ckpt = self.rundir.load_checkpoint(require=("config", "iteration", "method"))
        if ckpt["method"] != requested.method:
            raise UserError(f"run directory {requested.out}: holds a {ckpt['method']} run, not {requested.method}")
        saved = cls.from_dict(ckpt["config"])
        diffs = config_differences(saved, requested, given)
        if diffs:
            raise UserError(f"resume: run directory {requested.out} was trained with other settings "
                            f"({'; '.join(diffs)}); its saved settings hold on resume")
        done = ckpt["iteration"] + 1
        iterations = requested.iterations if (given is None or "iterations" in given) else saved.iterations
        if iterations < done:
            raise FieldError("iterations", f"may only grow on resume: the run in {requested.out} has "
                                           f"{done} iterations done (got {iterations})")
        if Path(saved.scene).name != Path(requested.scene).name and not Path(requested.scene).is_file():
            raise FieldError("scene", f"{requested.scene}: no such scene file")
        # a moved or copied run directory records where it now is; the scene is the one given now
        saved.iterations, saved.resume, saved.device, saved.out = iterations, True, requested.device, requested.out
        saved.scene = requested.scene
        if requested.cpu_threads is not None:
            saved.cpu_threads = requested.cpu_threads
        self.ckpt = ckpt
        return saved

    # -- resume ------------------------------------------------------------------------------------
    def restore(self) -> dict | None:
        """The checkpoint to load the method's states from (RNG restored), or ``None`` for a new run."""
        if self.ckpt is not None:
            restore_rng(self.gen, self.ckpt)
        return self.ckpt

    # -- the loop ----------------------------------------------------------------------------------
    def checkpoint(self, iteration: int, state: dict, history: list[dict]) -> None:
        scene = self.task.scene
        self.rundir.save_checkpoint({
            "method": self.cfg.method, "scene": scene.name, "scene_path": str(self.cfg.scene),
            "scene_hash": self.scene_hash, "dof": scene.dof, "config": self.cfg.to_dict(),
            "iteration": iteration, **rng_state(self.gen), **state,
            "metrics": _plain(history[-1]) if history else {},
        })
        self.last_checkpoint = iteration

    def run(self, step: Callable[[int], tuple[dict, Any]], state: Callable[[], dict], *,
            callbacks: list[Callback] | None = None, progress: bool = True, record: bool = True,
            describe: Callable[[dict], str] = lambda row: f"task {row['task_loss']:.4f}") -> TrainResult:
        """Iterate ``step`` from the resume point to ``cfg.iterations``; returns the metrics."""
        cfg, rd, task = self.cfg, self.rundir, self.task
        threads = torch.get_num_threads()
        if cfg.cpu_threads is not None:
            set_threads(cfg.cpu_threads)
        self.last_checkpoint = self.ckpt["iteration"] if self.ckpt is not None else None
        callbacks = list(callbacks or [])
        recorder = metrics_file = bar = None
        history: list[dict] = []
        try:
            history = rd.read_metrics(upto=self.start)
            rd.save_config(cfg.to_dict())
            if record:
                from .recording import TrainingRecorder

                rd.merge_recording()  # a segment left by a killed process
                recorder = TrainingRecorder(rd.segment_path(), task.sim, task.goals, history,
                                            record_every=cfg.record_every, last_iteration=cfg.iterations - 1,
                                            method=cfg.method, recording_id=rd.marker().get("run_id"))
                callbacks.append(recorder)
            metrics_file = rd.open_metrics(history)
            bar = progress_bar(cfg.iterations, self.start, enabled=progress)
            for it in range(self.start, cfg.iterations):
                t0 = time.perf_counter()
                try:
                    row, result = step(it)
                except DivergenceError as e:
                    err = DivergenceError(f"iteration {it}: {e} -- stopped; {self._kept()}", world=e.world, step=e.step)
                    err.checkpoint = self.last_checkpoint
                    raise err from None
                row = {"iteration": it, **row, "seconds": time.perf_counter() - t0}
                history.append(row)
                metrics_file.write(_json_line(row))
                metrics_file.flush()
                _fault_point("metrics-row")
                info = IterationInfo(it, row, result, task.goal_index)
                for cb in callbacks:
                    cb(info)
                bar.set_description_str(f"{describe(row)} {row['seconds']:.2f}s/it", refresh=False)
                bar.update(1)
                if (it + 1) % cfg.checkpoint_every == 0 or it + 1 == cfg.iterations:
                    if recorder is not None:  # on disk before the checkpoint: a crash loses nothing it covers
                        recorder.flush()
                    self.checkpoint(it, state(), history)
        except KeyboardInterrupt as e:
            if isinstance(e, Interrupted):
                raise
            raise Interrupted(f"interrupted; {self._kept()}", self.last_checkpoint) from None
        finally:
            if bar is not None:
                bar.close()
            if metrics_file is not None:
                metrics_file.close()
            if recorder is not None:
                recorder.close()
                rd.merge_recording()
            torch.set_num_threads(threads)
        return TrainResult(rd.path, history, None, cfg)

    def _kept(self) -> str:
        if self.last_checkpoint is None:
            return f"no checkpoint was written yet in {self.rundir.path}"
        return f"the checkpoint of iteration {self.last_checkpoint} in {self.rundir.path} is kept"

    def __enter__(self) -> "Session":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        # a new run that failed before its first iteration leaves nothing behind
        self.close(failed=exc_type is not None and not (self.rundir.path / "metrics.jsonl").exists())

    def close(self, failed: bool = False) -> None:
        if failed and self.ckpt is None:
            self.rundir.abandon()
        else:
            self.rundir.unlock()


def grad_norm(module: torch.nn.Module) -> float:
    total = 0.0
    for p in module.parameters():
        if p.grad is not None:
            total += float(p.grad.detach().pow(2).sum())
    return math.sqrt(total)


def _plain(row: dict) -> dict:
    return {k: v for k, v in row.items() if isinstance(v, (int, float, str, list, dict, bool, type(None)))}


def _json_line(row: dict) -> str:
    import json

    return json.dumps(row) + "\n"


# ------------------------------------------------------------------------------------------------
# progress
# ------------------------------------------------------------------------------------------------

class _Lines:
    """A file for tqdm that turns its carriage-return refreshes into whole lines (logs, CI)."""

    def __init__(self, out):
        self.out = out

    def write(self, text: str) -> None:
        text = text.replace("\r", "").strip()
        if text:
            self.out.write(text + "\n")

    def flush(self) -> None:
        self.out.flush()


def progress_bar(total: int, start: int = 0, enabled: bool = True, desc: str | None = None):
    """A tqdm bar on stderr: live on a terminal, one line every 5 s (and the last) otherwise."""
    from tqdm import tqdm

    tty = sys.stderr.isatty()
    return tqdm(total=total, initial=start, disable=not enabled, desc=desc or "", dynamic_ncols=tty, ascii=not tty,
                file=sys.stderr if tty else _Lines(sys.stderr), mininterval=0.1 if tty else 5.0,
                leave=True, bar_format="[{bar:24}] {n_fmt}/{total_fmt} {desc} [{elapsed}<{remaining}]")
