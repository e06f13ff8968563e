"""One seed's share of a run and the resume rule (used by :class:`warp_critic.running.loop.Session`).

A :class:`SeedRun` holds one seed's config, run directory, checkpoint, generator and files. On resume
the run's saved config is the truth: only ``iterations`` may grow, any other difference is a
:class:`ResumeMismatch` that lists them, and the checkpoint must belong to the run whose files lie
next to it.
"""

from __future__ import annotations

from dataclasses import fields, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

import torch

from warp_critic.core.errors import FieldError, UserError, warn
from warp_critic.core.runtime import MAX_SEEDS
from warp_critic.running.config import check_fields
from warp_critic.running.files import MARKER
from warp_critic.running.locks import holder
from warp_critic.running.rundir import RECORDING, RUN_KIND, SEGMENT, RunDir
from warp_critic.running.task import RUNTIME_FIELDS, TaskConfig

if TYPE_CHECKING:
    from warp_critic.running.recording import TrainingRecorder


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
        self.start_over = False  # --resume of a run that holds no checkpoint (it starts over)
        self.cleared = False  # ... and its old files are gone (claim)
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
        elif self.start_over:
            metrics = self.rundir.path / "metrics.jsonl"
            text = metrics.read_text(errors="replace") if metrics.is_file() else ""
            done = sum(1 for line in text.splitlines() if line.strip())
            self.rundir.lock()  # a live run keeps its directory
            self.cleared = True
            for name in ("config.json", "metrics.jsonl", RECORDING, SEGMENT, MARKER):
                (self.rundir.path / name).unlink(missing_ok=True)
            warn(
                f"{self.rundir.path} held no checkpoint (its run was stopped before the first, "
                f"after {done} iteration(s) in its metrics): nothing to continue, so it starts over"
            )
        else:
            self.rundir = RunDir.create(cfg.out or cfg.default_out(), cfg.method)
        self.run_id = self.rundir.ensure_marker(cfg.method).get("run_id")

    def _resume_config(self, requested: TaskConfig, given: set[str] | None) -> TaskConfig:
        """The run's saved config, with what may change on resume taken from ``requested`` (a new
        object; ``requested`` is left as it was). Loads the checkpoint into ``self.ckpt``."""
        out = requested.out if requested.out is not None else requested.default_out()
        requested = replace(requested, out=out)
        self.rundir = RunDir.open(out)
        if (
            not self.rundir.checkpoint_path.exists()
            and self.rundir.marker().get("kind") == RUN_KIND
        ):
            return self._start_over_config(requested, given)
        ckpt = self.rundir.load_checkpoint(require=self.require)
        _same_run(self.rundir, ckpt)
        if ckpt["method"] != requested.method:
            raise UserError(
                f"run directory {requested.out}: holds a {ckpt['method']} run, not {requested.method}"
            )
        saved = _saved_config(
            ckpt["config"], requested, given, "its checkpoint holds an unusable config"
        )
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
        return _continued(saved, requested, iterations, resume=True)

    def _start_over_config(self, requested: TaskConfig, given: set[str] | None) -> TaskConfig:
        """``--resume`` of a run of ours that holds no checkpoint (killed or stopped before its
        first): nothing to continue and nothing to lose, so the run starts over in its directory
        with its saved settings (``config.json``, when it got that far; the resume rule holds)."""
        owner = holder(self.rundir.path)
        if owner is not None:  # a live run that has not checkpointed yet: refused at once
            self.rundir.lock()
        method = self.rundir.marker().get("method")
        if method not in (None, requested.method):
            raise UserError(
                f"run directory {requested.out}: holds a {method} run, not {requested.method}"
            )
        config = self.rundir.saved_config()
        cfg = replace(requested, resume=False)
        if config:
            saved = _saved_config(config, requested, given, "its config.json is unusable")
            asked = given is None or "iterations" in given
            iterations = requested.iterations if asked else saved.iterations
            cfg = _continued(saved, requested, iterations, resume=False)
        self.start_over = True
        return cfg

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


def check_seed_count(seeds: list[int] | None) -> None:
    """At most :data:`~warp_critic.core.runtime.MAX_SEEDS` seeds in one process (a run directory
    each, all in one simulator): a :class:`FieldError` on ``seeds`` before anything is created."""
    if seeds is not None and len(seeds) > MAX_SEEDS:
        raise FieldError(
            "seeds",
            f"{len(seeds)} seeds: at most {MAX_SEEDS} in one process (each gets a run directory "
            "and its worlds); split them over several runs",
        )


def seed_configs(cfg: TaskConfig) -> list[TaskConfig]:
    """One config per seed: ``cfg`` itself, or with ``seeds`` one copy per seed in ``OUT/seed<k>``."""
    if not cfg.seeds:
        return [cfg]
    check_seed_count(cfg.seeds)
    if len(set(cfg.seeds)) != len(cfg.seeds):
        raise FieldError("seeds", f"must be distinct (got {cfg.seeds})")
    out = cfg.out if cfg.out is not None else cfg.default_out()
    return [replace(cfg, seed=s, seeds=None, out=str(Path(out) / f"seed{s}")) for s in cfg.seeds]


def _saved_config(data: dict, requested: TaskConfig, given: set[str] | None, unusable: str):
    """A run's saved config (``data``, from its checkpoint or ``config.json``) as ``requested``'s
    class, checked, and refused with :class:`ResumeMismatch` where ``requested`` changes what may
    not change on resume."""
    try:
        saved = type(requested).from_dict(data)
        check_fields(saved)
    except (TypeError, UserError) as e:
        raise UserError(f"run directory {requested.out}: {unusable} ({e})") from None
    diffs = config_differences(saved, requested, given)
    if diffs:
        raise ResumeMismatch(requested.out, diffs)
    return saved


def _continued(saved: TaskConfig, requested: TaskConfig, iterations, resume: bool) -> TaskConfig:
    """``saved`` with what a resumed or restarted run takes from ``requested``: the iterations, the
    device, where the run directory and the scene are now, the threads; one seed per run."""
    threads = requested.cpu_threads if requested.cpu_threads is not None else saved.cpu_threads
    return replace(
        saved,
        iterations=iterations,
        resume=resume,
        device=requested.device,
        out=requested.out,
        scene=requested.scene,
        seeds=None,
        cpu_threads=threads,
    )
