"""The one training harness every method runs through (ours and every baseline of the registry).

A method builds its networks and writes one function, ``step(iteration) -> (one metrics row per seed,
result)``, plus ``state(seed index) -> dict`` for its checkpoints; :class:`Session` does everything
around it, the same way for all methods:

1. **start**: check the config, claim (or, on resume, open) the run directory and lock it, apply the
   resume rule (the run's saved config is the truth: only ``iterations`` may grow, any other
   difference is an error that lists them, and the scene's content must match: one
   :class:`~warp_critic.running.seedrun.SeedRun` per seed does this), build the task's worlds and
   seed every generator;
2. **resume**: after the method has built its networks (so the random draws happen in the same order
   as in a fresh run), restore the checkpoint's states and RNG;
3. **run**: the iteration loop with progress bar, ``metrics.jsonl``, callbacks (the recorder is one),
   divergence and interrupt messages that say truthfully what was kept, and checkpoint cadence.
"""

from __future__ import annotations

import contextlib
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from warp_critic.core import interrupts
from warp_critic.core.errors import DivergenceError, UserError
from warp_critic.core.runtime import restore_rng, seed_everything, set_threads
from warp_critic.running.config import check_fields
from warp_critic.running.seedrun import SeedRun, seed_configs
from warp_critic.running.task import Task, TaskConfig, build_task, load_task_scene
from warp_critic.running.task_inputs import check_memory


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
    config: TaskConfig | None = None  # the run's config, with the scene's defaults filled in
    seeds: list[TrainResult] = field(default_factory=list)  # every seed's result (a batched run)


Callback = Callable[[IterationInfo], None]


class Session:
    """One run of one method, for one seed or several seeds sharing one simulator (see the module
    docstring). With ``S`` seeds the task holds ``S`` copies of the ``G x K`` worlds, seed-major."""

    def __init__(
        self,
        cfg: TaskConfig,
        *,
        differentiable: bool,
        given: set[str] | None = None,
        require: tuple[str, ...] = (),
    ):
        """``require``: the checkpoint entries the method reads on resume (checked up front)."""
        check_fields(cfg)
        self.runs: list[SeedRun] = []
        try:
            for c in seed_configs(cfg):
                self.runs.append(SeedRun(c, given, require))
            starts = {r.start for r in self.runs}
            if len(starts) > 1:
                raise UserError(
                    "resume: the seeds' run directories are at different iterations "
                    f"({', '.join(f'{r.cfg.out}: {r.start}' for r in self.runs)}); resume them one by one"
                )
            for k, r in enumerate(self.runs):  # the same scene file for every seed
                r.cfg, scene = load_task_scene(r.cfg, announce=k == 0)
            self.scene_hash = getattr(scene, "content_hash", None)
            if cfg.seeds:
                check_memory(self.runs[0].cfg, scene.dof, copies=len(self.runs))
            for r in self.runs:
                r.claim(self.scene_hash)
            self.task: Task = build_task(
                self.runs[0].cfg, scene, differentiable=differentiable, copies=len(self.runs)
            )
        except BaseException:
            self.close(failed=True)
            raise

    @property
    def cfg(self) -> TaskConfig:
        return self.runs[0].cfg

    @property
    def start(self) -> int:
        return self.runs[0].start

    # -- set-up and resume -------------------------------------------------------------------------
    def seed(self, i: int) -> torch.Generator:
        """Seed everything for seed ``i`` (call right before building that seed's networks, so its
        random draws are those of a single-seed run); returns its generator."""
        run = self.runs[i]
        run.gen = seed_everything(run.cfg.seed)
        return run.gen

    def seeded(self, i: int) -> None:
        """Mark the end of seed ``i``'s set-up: its share of torch's global RNG state is saved."""
        self.runs[i].global_rng = torch.get_rng_state()

    @contextlib.contextmanager
    def loading(self, i: int = 0):
        """Around loading seed ``i``'s checkpoint states into the method's objects: a checkpoint whose
        entries do not fit them is a one-line error, not a traceback."""
        try:
            yield
        except (KeyError, RuntimeError, ValueError, TypeError, IndexError, AttributeError) as e:
            raise UserError(
                f"{self.runs[i].rundir.checkpoint_path}: its states do not fit this {self.cfg.method} "
                f"run ({type(e).__name__}: {' '.join(str(e).split())[:160]})"
            ) from None

    def restore(self, i: int = 0) -> dict | None:
        """Seed ``i``'s checkpoint to load the method's states from (RNG restored), or ``None``."""
        run = self.runs[i]
        if run.ckpt is not None:
            restore_rng(run.gen, run.ckpt)
            run.global_rng = torch.get_rng_state()
        return run.ckpt

    # -- the loop ----------------------------------------------------------------------------------
    def _checkpoint(self, run: SeedRun, iteration: int, state: dict) -> None:
        scene = self.task.scene
        torch_rng = run.global_rng if run.global_rng is not None else torch.get_rng_state()
        run.rundir.save_checkpoint(
            {
                "method": run.cfg.method,
                "scene": scene.name,
                "scene_path": str(run.cfg.scene),
                "scene_file": _absolute(run.cfg.scene),
                "scene_hash": self.scene_hash,
                "run_id": run.run_id,
                "dof": scene.dof,
                "config": run.cfg.to_dict(),
                "iteration": iteration,
                "rng_state": run.gen.get_state(),
                "torch_rng_state": torch_rng,
                **state,
                "metrics": _plain(run.history[-1]) if run.history else {},
            }
        )
        run.last_checkpoint = iteration

    def run(
        self,
        step: Callable[[int], tuple[list[dict], Any]],
        state: Callable[[int], dict],
        *,
        callbacks: list[Callback] | None = None,
        progress: bool = True,
        record: bool = True,
        describe: Callable[[dict], str] = lambda row: f"task {row['task_loss']:.4f}",
    ) -> TrainResult:
        """Iterate ``step`` from the resume point to the last iteration.

        ``step(it)`` returns one metrics row per seed and the iteration's result (trajectories over
        all worlds); ``state(i)`` seed ``i``'s checkpoint content. Returns seed 0's result; with several
        seeds, ``result.seeds`` holds every seed's.
        """
        cfg, task = self.cfg, self.task
        threads = torch.get_num_threads()
        if cfg.cpu_threads is not None:
            set_threads(cfg.cpu_threads)
        callbacks = list(callbacks or [])
        bar, merge = None, True
        try:
            for i, r in enumerate(self.runs):
                r.history = r.rundir.read_metrics(upto=self.start)
                r.rundir.save_config(
                    {
                        **r.cfg.to_dict(),
                        "scene_file": _absolute(r.cfg.scene),
                        "scene_hash": self.scene_hash,
                    }
                )
                if record:
                    from warp_critic.running.recording import TrainingRecorder

                    r.rundir.merge_recording()  # a segment left by a killed process
                    r.recorder = TrainingRecorder(
                        r.rundir.segment_path(),
                        task.sim,
                        task.goals,
                        r.history,
                        record_every=cfg.record_every,
                        last_iteration=cfg.iterations - 1,
                        method=cfg.method,
                        recording_id=r.rundir.marker().get("run_id"),
                        world_offset=i * task.Wc,
                    )
                r.metrics_file = r.rundir.open_metrics(r.history)
            bar = progress_bar(cfg.iterations, self.start, enabled=progress)
            for it in range(self.start, cfg.iterations):
                t0 = time.perf_counter()
                try:
                    rows, result = step(it)
                except DivergenceError as e:
                    err = DivergenceError(
                        f"iteration {it}: {e} -- stopped; {self._kept()}",
                        world=e.world,
                        step=e.step,
                    )
                    err.checkpoint = self.runs[0].last_checkpoint
                    raise err from None
                seconds = time.perf_counter() - t0
                checkpoint_now = (it + 1) % cfg.checkpoint_every == 0 or it + 1 == cfg.iterations
                self._write(it, rows, result, state, seconds, checkpoint_now, callbacks)
                bar.set_description_str(f"{describe(rows[0])} {seconds:.2f}s/it", refresh=False)
                bar.update(1)
                interrupts.check()  # a signal whose KeyboardInterrupt a callback swallowed
        except KeyboardInterrupt as e:
            # several seeds stop at once: their recordings are merged on resume, one rerun call
            # each, so that the signal takes effect in seconds
            merge = len(self.runs) == 1 or not record
            if isinstance(e, Interrupted):
                raise
            later = "" if merge else "; each seed's last recording segment is merged on resume"
            raise Interrupted(
                f"interrupted; {self._kept()}{later}", self.runs[0].last_checkpoint
            ) from None
        finally:
            if bar is not None:
                bar.close()
            for r in self.runs:
                if r.metrics_file is not None:
                    r.metrics_file.close()
                if r.recorder is not None:
                    r.recorder.close()
                    if merge:
                        r.rundir.merge_recording()
            torch.set_num_threads(threads)
        results = [TrainResult(r.rundir.path, r.history, None, r.cfg) for r in self.runs]
        results[0].seeds = results
        return results[0]

    def _write(self, it, rows, result, state, seconds, checkpoint_now, callbacks) -> None:
        """Iteration ``it``'s metrics row, recording and (when due) checkpoint of every seed (the
        checkpoints all or none: a signal waits for them)."""
        for i, (r, row) in enumerate(zip(self.runs, rows)):
            row = {"iteration": it, **row, "seconds": seconds}
            r.history.append(row)
            assert r.metrics_file is not None  # opened by run() for every seed
            r.metrics_file.write(_json_line(row))
            r.metrics_file.flush()
            info = IterationInfo(it, row, result, self.task.goal_index_of(i))
            for cb in ([r.recorder] if r.recorder is not None else []) + (
                callbacks if i == 0 else []
            ):
                cb(info)
        if checkpoint_now:
            with interrupts.deferred():  # every seed's checkpoint of this iteration, or none
                for i, r in enumerate(self.runs):
                    if (
                        r.recorder is not None
                    ):  # on disk before the checkpoint: a crash loses nothing
                        r.recorder.flush()
                    self._checkpoint(r, it, state(i))

    def _kept(self) -> str:
        if len(self.runs) == 1:
            return self.runs[0].kept()
        where = self.runs[0].rundir.path.parent
        done = {r.last_checkpoint for r in self.runs}
        if done == {None}:
            return f"no checkpoint was written yet in the {len(self.runs)} seed run directories under {where}"
        if len(done) == 1:
            return (
                f"the checkpoints of iteration {done.pop()} in the {len(self.runs)} seed run directories "
                f"under {where} are kept"
            )
        parts = []  # (seeds stopped between their checkpoints): one part per iteration kept
        for last in sorted(done, key=lambda x: -1 if x is None else x):
            names = [r.rundir.path.name for r in self.runs if r.last_checkpoint == last]
            what = "no checkpoint was written yet" if last is None else f"iteration {last} is kept"
            parts.append(f"{what} in {len(names)} of them ({', '.join(names)})")
        return f"{len(self.runs)} seed run directories under {where}: " + "; ".join(parts)

    def __enter__(self) -> Session:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close(failed=exc_type is not None)

    def close(self, failed: bool = False) -> None:
        for r in self.runs:
            if not r.claimed or (r.start_over and not r.cleared):
                continue  # (a run to start over is not touched before its claim)
            # a new run that failed before its first iteration leaves nothing behind
            if failed and r.ckpt is None and not (r.rundir.path / "metrics.jsonl").exists():
                r.rundir.abandon()
            else:
                r.rundir.unlock()


def _absolute(path) -> str:
    return str(Path(path).resolve())


def _plain(row: dict) -> dict:
    return {
        k: v
        for k, v in row.items()
        if isinstance(v, (int, float, str, list, dict, bool, type(None)))
    }


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
    return tqdm(
        total=total,
        initial=start,
        disable=not enabled,
        desc=desc or "",
        dynamic_ncols=tty,
        ascii=not tty,
        file=sys.stderr if tty else _Lines(sys.stderr),
        mininterval=0.1 if tty else 5.0,
        leave=True,
        bar_format="[{bar:24}] {n_fmt}/{total_fmt} {desc} [{elapsed}<{remaining}]",
    )
