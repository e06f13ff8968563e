"""The one training harness every method runs through (ours, DDPG, Meta-Critic).

A method builds its networks and writes one function, ``step(iteration) -> (one metrics row per seed,
result)``, plus ``state(seed index) -> dict`` for its checkpoints; :class:`Session` does everything
around it, the same way for all methods:

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

import contextlib
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

import torch

from warp_critic.core.errors import DivergenceError, FieldError, UserError
from warp_critic.core.runtime import restore_rng, seed_everything, set_threads
from warp_critic.running.rundir import RunDir
from warp_critic.running.task import (
    RUNTIME_FIELDS,
    Task,
    TaskConfig,
    build_task,
    check_fields,
    check_memory,
    load_task_scene,
)

if TYPE_CHECKING:
    from warp_critic.running.recording import TrainingRecorder


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


def config_differences(
    saved: TaskConfig, requested: TaskConfig, given: set[str] | None
) -> list[tuple[str, Any, Any]]:
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
        elif value is None or value == (
            f.default if not callable(f.default_factory) else f.default_factory()
        ):
            continue
        old = getattr(saved, f.name, None)
        if value != old and not (
            isinstance(value, (int, float))
            and isinstance(old, (int, float))
            and float(value) == float(old)
        ):
            diffs.append((f.name, old, value))
    return diffs


class ResumeMismatch(UserError):
    """A resume asked for settings that differ from the run's; ``diffs``: ``(field, saved, requested)``."""

    def __init__(self, run_dir, diffs: list[tuple[str, Any, Any]], name=lambda field: field):
        self.run_dir, self.diffs = run_dir, diffs
        super().__init__(self.render(name))

    def __reduce__(self):  # a worker process's error reaches the driver whole
        return (type(self), (self.run_dir, self.diffs))

    def render(self, name) -> str:
        listed = "; ".join(f"{name(f)} {old!r} -> {new!r}" for f, old, new in self.diffs)
        return (
            f"resume: run directory {self.run_dir} was trained with other settings ({listed}); "
            f"its saved settings hold on resume"
        )


class SeedRun:
    """One seed's share of a session: its config, run directory, checkpoint, generator and files."""

    def __init__(self, cfg: TaskConfig, given: set[str] | None, require: tuple[str, ...] = ()):
        self.require = ("config", "iteration", "method", "rng_state", "torch_rng_state") + tuple(
            require
        )
        self.ckpt: dict | None = None
        self._rundir: RunDir | None = None  # opened on resume, else created by claim()
        self.cfg = self._resume_config(cfg, given) if cfg.resume else cfg
        self._gen: torch.Generator | None = None  # made by Session.seed()
        self.global_rng: torch.Tensor | None = (
            None  # torch's global RNG state after this seed's set-up
        )
        self.history: list[dict] = []
        self.metrics_file: TextIO | None = None
        self.recorder: TrainingRecorder | None = None
        self.run_id: str | None = None
        self.last_checkpoint: int | None = self.ckpt["iteration"] if self.ckpt is not None else None

    @property
    def rundir(self) -> RunDir:
        if self._rundir is None:
            raise RuntimeError("the run directory is not claimed yet (SeedRun.claim)")
        return self._rundir

    @rundir.setter
    def rundir(self, value: RunDir) -> None:
        self._rundir = value

    @property
    def claimed(self) -> bool:
        """Whether this seed holds its run directory (opened on resume or created)."""
        return self._rundir is not None

    @property
    def gen(self) -> torch.Generator:
        if self._gen is None:
            raise RuntimeError("this seed's generator is not made yet (Session.seed)")
        return self._gen

    @gen.setter
    def gen(self, value: torch.Generator) -> None:
        self._gen = value

    @property
    def start(self) -> int:
        return 0 if self.ckpt is None else self.ckpt["iteration"] + 1

    def claim(self, scene_hash: str | None) -> None:
        """Create (new run) or lock (resume) the run directory; the scene content must match."""
        cfg = self.cfg
        if self.ckpt is not None:
            if self.ckpt.get("scene_hash") and scene_hash and self.ckpt["scene_hash"] != scene_hash:
                raise FieldError(
                    "scene",
                    f"{cfg.scene} differs in content from the scene the run in "
                    f"{cfg.out} was trained on",
                )
            self.rundir.lock()
        else:
            self.rundir = RunDir.create(cfg.out or cfg.default_out(), cfg.method)
        self.run_id = self.rundir.ensure_marker(cfg.method).get("run_id")

    def _resume_config(self, requested: TaskConfig, given: set[str] | None) -> TaskConfig:
        """The run's saved config, with what may change on resume taken from ``requested`` (a new
        object; ``requested`` is left as it was). Loads the checkpoint into ``self.ckpt``."""
        cls = type(requested)
        out = requested.out if requested.out is not None else requested.default_out()
        requested = replace(requested, out=out)
        self.rundir = RunDir.open(out)
        ckpt = self.rundir.load_checkpoint(require=self.require)
        _same_run(self.rundir, ckpt)
        if ckpt["method"] != requested.method:
            raise UserError(
                f"run directory {requested.out}: holds a {ckpt['method']} run, not {requested.method}"
            )
        try:
            saved = cls.from_dict(ckpt["config"])
            check_fields(saved)
        except (TypeError, UserError) as e:
            raise UserError(
                f"run directory {requested.out}: its checkpoint holds an unusable config ({e})"
            ) from None
        diffs = config_differences(saved, requested, given)
        if diffs:
            raise ResumeMismatch(requested.out, diffs)
        done = ckpt["iteration"] + 1
        asked = given is None or "iterations" in given
        iterations = (
            requested.iterations if asked and requested.iterations is not None else saved.iterations
        )
        if iterations < done:
            raise FieldError(
                "iterations",
                f"may only grow on resume: the run in {requested.out} has "
                f"{done} iterations done (got {iterations})",
            )
        if not Path(requested.scene).is_file():
            raise FieldError("scene", f"{requested.scene}: no such scene file")
        # a moved or copied run directory records where it now is; the scene is the one given now
        self.ckpt = ckpt
        return replace(
            saved,
            iterations=iterations,
            resume=True,
            device=requested.device,
            out=requested.out,
            scene=requested.scene,
            seeds=None,
            cpu_threads=(
                requested.cpu_threads if requested.cpu_threads is not None else saved.cpu_threads
            ),
        )

    def kept(self) -> str:
        if self.last_checkpoint is None:
            return f"no checkpoint was written yet in {self.rundir.path}"
        return f"the checkpoint of iteration {self.last_checkpoint} in {self.rundir.path} is kept"


def _same_run(rundir: RunDir, ckpt: dict) -> None:
    """The checkpoint belongs to the run whose files lie next to it (a checkpoint copied in from
    another run would resume with that run's state and mix both runs' metrics)."""
    mine = rundir.marker().get("run_id")
    theirs = ckpt.get("run_id")
    saved = rundir.saved_config()
    other = (
        mine and theirs and mine != theirs
    ) or (  # checkpoints without a run id: the scene content recorded next to it
        saved.get("scene_hash")
        and ckpt.get("scene_hash")
        and saved["scene_hash"] != ckpt["scene_hash"]
    )
    if other:
        raise UserError(
            f"run directory {rundir.path}: its checkpoint.pt belongs to another run (not the one "
            "whose config.json and metrics.jsonl lie next to it); not resuming it"
        )


def seed_configs(cfg: TaskConfig) -> list[TaskConfig]:
    """One config per seed: ``cfg`` itself, or with ``seeds`` one copy per seed in ``OUT/seed<k>``."""
    if not cfg.seeds:
        return [cfg]
    if len(set(cfg.seeds)) != len(cfg.seeds):
        raise FieldError("seeds", f"must be distinct (got {cfg.seeds})")
    out = cfg.out if cfg.out is not None else cfg.default_out()
    return [replace(cfg, seed=s, seeds=None, out=str(Path(out) / f"seed{s}")) for s in cfg.seeds]


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
        bar = None
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
                for i, (r, row) in enumerate(zip(self.runs, rows)):
                    row = {"iteration": it, **row, "seconds": seconds}
                    r.history.append(row)
                    assert r.metrics_file is not None  # opened above for every seed
                    r.metrics_file.write(_json_line(row))
                    r.metrics_file.flush()
                    info = IterationInfo(it, row, result, task.goal_index_of(i))
                    for cb in ([r.recorder] if r.recorder is not None else []) + (
                        callbacks if i == 0 else []
                    ):
                        cb(info)
                    if checkpoint_now:
                        if (
                            r.recorder is not None
                        ):  # on disk before the checkpoint: a crash loses nothing it covers
                            r.recorder.flush()
                        self._checkpoint(r, it, state(i))
                bar.set_description_str(f"{describe(rows[0])} {seconds:.2f}s/it", refresh=False)
                bar.update(1)
        except KeyboardInterrupt as e:
            if isinstance(e, Interrupted):
                raise
            raise Interrupted(
                f"interrupted; {self._kept()}", self.runs[0].last_checkpoint
            ) from None
        finally:
            if bar is not None:
                bar.close()
            for r in self.runs:
                if r.metrics_file is not None:
                    r.metrics_file.close()
                if r.recorder is not None:
                    r.recorder.close()
                    r.rundir.merge_recording()
            torch.set_num_threads(threads)
        results = [TrainResult(r.rundir.path, r.history, None, r.cfg) for r in self.runs]
        results[0].seeds = results
        return results[0]

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
        return "; ".join(r.kept() for r in self.runs)

    def __enter__(self) -> Session:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close(failed=exc_type is not None)

    def close(self, failed: bool = False) -> None:
        for r in self.runs:
            if not r.claimed:
                continue
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
