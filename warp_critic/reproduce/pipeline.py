"""``reproduce``: run the selected stages in order (skipping complete ones), then write the report.

Stage order: toy, landscape, metatrain, maps, tables, tables-heldout (Tables 1-3 again on a goal
seed that chose nothing). ``maps`` needs the reacher ``metatrain`` sub-stages and ``tables`` the
KUKA ones: they are run (or found complete) first even when ``--only``
does not name ``metatrain``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

from warp_critic.core.errors import FieldError, UserError
from warp_critic.core.runtime import MAX_SEEDS
from warp_critic.reproduce.extra_baselines import (
    check_baselines,
    metatrain_stage,
    plan_extra,
    selected_extra,
)
from warp_critic.reproduce.settings import (
    BEYOND,
    METHODS,
    SCENES,
    STAGES,
    apply_overrides,
    default_settings,
    stage_hash,
)
from warp_critic.reproduce.stages import Runner, claim_out, read_complete


@dataclass
class ReproduceConfig:
    out: Path = Path("runs/paper")
    seeds: int = 5
    only: list[str] | None = None  # stage names; None = all
    quick: bool = False
    device: str = "auto"
    overrides: list[str] = field(default_factory=list)  # STAGE.KEY=VALUE
    progress: bool = True
    command: str = ""  # the command line, for the report
    seeds_given: bool = False  # --seeds was given (then metatrain.seeds may not contradict it)
    beyond: bool = False  # also the recipes beyond the paper (stage group "beyond")
    baselines: list[str] | None = None  # --baselines; None: the paper's two

    @property
    def extra(self) -> tuple[str, ...]:
        """The baselines beyond the paper's two that this call adds (:mod:`.extra_baselines`)."""
        return check_baselines(self.baselines)

    def validate(self) -> dict:
        """Check everything before any work; returns the settings. Raises a one-line :class:`UserError`."""
        if isinstance(self.seeds, bool) or not isinstance(self.seeds, int) or self.seeds < 1:
            raise FieldError("seeds", f"must be an integer >= 1 (got {self.seeds!r})")
        if self.seeds > MAX_SEEDS:  # one process trains them all (the stages' seeds= setting)
            raise FieldError(
                "seeds", f"{self.seeds} seeds: at most {MAX_SEEDS} train in one process"
            )
        extra = self.extra
        subs = metatrain_names(extra) + list(BEYOND_EVALS)
        for s in self.only or []:
            if s not in STAGES and s not in subs and s != BEYOND:
                raise FieldError(
                    "only",
                    f"unknown stage {s!r} (stages: {', '.join(STAGES)}, {BEYOND}, "
                    f"{', '.join(BEYOND_EVALS)}; one meta-training: {', '.join(metatrain_names(extra))})",
                )
        if self.only is not None and not self.only:
            raise UserError(f"--only: give one or more of {', '.join(STAGES)}")
        if self.device not in ("auto", "cpu", "cuda") and not str(self.device).startswith("cuda:"):
            raise UserError(f"--device: must be cpu, cuda or auto (got {self.device!r})")
        defaults = default_settings(self.quick, self.seeds, extra)
        settings = apply_overrides(defaults, self.overrides)
        seeds = settings["metatrain"]["seeds"]
        if self.seeds_given and seeds != defaults["metatrain"]["seeds"]:
            raise FieldError(
                "seeds",
                f"{self.seeds} and --set metatrain.seeds={seeds} disagree; give one of them",
            )
        from warp_critic.reproduce.validate import check_all

        check_all(settings, defaults)  # every setting of every stage, before any work
        return settings

    def selected(self) -> list[str]:
        """The selected stage groups, and single meta-trainings (``metatrain-<robot>-<method>``,
        ``beyond-metatrain-<robot>-<recipe>``)."""
        # --beyond adds the group to a whole call; with --only the call runs what its names need
        only = self.only or []
        extra = [BEYOND] if BEYOND in only or (self.beyond and self.only is None) else []
        if self.only is None:
            return list(STAGES) + selected_extra(list(STAGES), self.extra) + extra
        singles = [s for s in metatrain_names(self.extra) if s in self.only]
        if "metatrain" in self.only:
            singles = [s for s in singles if not s.startswith("metatrain-")]
        if BEYOND not in self.only:  # one of the beyond evaluations alone (with what it reads)
            singles += [s for s in BEYOND_EVALS if s in self.only]
        groups = [s for s in STAGES if s in self.only]
        return groups + selected_extra(groups, self.extra) + singles + extra

    @property
    def plans_beyond(self) -> bool:
        """Whether this call's plan holds the stages beyond the paper."""
        return any(s == BEYOND or s.startswith(f"{BEYOND}-") for s in self.selected())


#: the beyond group's evaluations, each also accepted alone by ``--only``
BEYOND_EVALS = (f"{BEYOND}-maps", f"{BEYOND}-tables")


def metatrain_names(extra: tuple[str, ...] = ()) -> list[str]:
    """The names of the single meta-trainings ``--only`` also accepts (the paper's, the ``extra``
    baselines' and the recipes beyond the paper)."""
    from warp_critic.reproduce.recipes import RECIPES

    return [f"metatrain-{scene}-{m}" for scene in SCENES for m in (*METHODS, *extra)] + [
        f"{BEYOND}-metatrain-{scene}-{recipe}" for scene in SCENES for recipe in RECIPES[scene]
    ]


def scene_hashes() -> dict[str, str]:
    from warp_critic.physics.load import load_scene
    from warp_critic.reproduce.metatrain import scene_file

    return {s: load_scene(scene_file(s)).content_hash for s in SCENES}


def plan(settings: dict, beyond: bool = False, extra: tuple[str, ...] = ()) -> dict[str, dict]:
    """Every stage (sub-stage) of ``settings``: name -> group, hash, settings, depends (dir names);
    with ``beyond``, also the recipes beyond the paper (:func:`plan_beyond`); with ``extra``, the
    stages of those baselines (:func:`~.extra_baselines.plan_extra`)."""
    hashes = scene_hashes()
    p: dict[str, dict] = {}
    p["toy"] = {
        "group": "toy",
        "settings": settings["toy"],
        "hash": stage_hash("toy", settings["toy"]),
        "depends": {},
    }
    p["landscape"] = {
        "group": "landscape",
        "settings": settings["landscape"],
        "depends": {},
        "hash": stage_hash("landscape", settings["landscape"], load_point_mass_hash()),
    }
    for scene in SCENES:
        for m in METHODS:
            p[f"metatrain-{scene}-{m}"] = metatrain_stage(settings, scene, m, hashes)
    for group, scene in (("maps", "reacher"), ("tables", "kuka")):
        dep = {
            f"metatrain-{scene}-{m}": f"metatrain-{scene}-{m}-{p[f'metatrain-{scene}-{m}']['hash']}"
            for m in METHODS
        }
        p[group] = {
            "group": group,
            "scene": scene,
            "settings": settings[group],
            "depends": dep,
            "hash": stage_hash(group, settings[group], dep),
        }
    from warp_critic.evaluation.seed_uses import HELDOUT_TABLES

    held = {**settings["tables"], **HELDOUT_TABLES}  # Tables 1-3 on a goal seed that chose nothing
    p["tables-heldout"] = {
        "group": "tables",
        "scene": "kuka",
        "settings": held,
        "depends": p["tables"]["depends"],
        "hash": stage_hash("tables", held, p["tables"]["depends"]),
    }
    plan_extra(settings, p, hashes, extra)
    if beyond:
        plan_beyond(settings, p, hashes)
    return p


def plan_beyond(settings: dict, p: dict, hashes: dict[str, str]) -> None:
    """Add the stages beyond the paper to ``p``: one meta-training per robot and recipe
    (``beyond-metatrain-<robot>-<recipe>``, group metatrain), and ``beyond-maps`` / ``beyond-tables``:
    the paper's maps and tables (the same settings) of the nominal critic (``ours``) next to each
    recipe's. The paper's stages and their hashes are unchanged."""
    seeds = settings["metatrain"]["seeds"]
    for group, scene in (("maps", "reacher"), ("tables", "kuka")):
        nominal = f"metatrain-{scene}-ours"
        dep = {nominal: f"{nominal}-{p[nominal]['hash']}"}
        labels = {nominal: "ours"}
        for recipe, values in settings[BEYOND][scene].items():
            name = f"{BEYOND}-metatrain-{scene}-{recipe}"
            p[name] = {
                "group": "metatrain",
                "scene": scene,
                "method": "ours",
                "recipe": recipe,
                "depends": {},
                "settings": {"values": values, "seeds": seeds, "scene_hash": hashes[scene]},
                "hash": stage_hash(name, values, seeds, hashes[scene]),
            }
            dep[name] = f"{name}-{p[name]['hash']}"
            labels[name] = recipe
        p[f"{BEYOND}-{group}"] = {
            "group": group,
            "scene": scene,
            "settings": settings[group],
            "depends": dep,
            "labels": labels,  # dependency -> the row it fills (the run sets of the stage)
            "hash": stage_hash(f"{BEYOND}-{group}", settings[group], dep),
        }


def needed(rc: ReproduceConfig, stages: dict) -> list[list[str]]:
    """The stages this call needs: what depends on nothing, then maps / tables (which read the
    meta-training of their robot, run or found complete first even when not selected). The driver
    starts each stage once the stages it reads are complete, whichever list it is in."""
    selected = rc.selected()
    first, second = [], []
    for group in selected:
        if group in ("toy", "landscape"):
            first.append(group)
        elif group == "metatrain":  # the paper's six
            first += [n for n in stages if n.startswith("metatrain-")]
        elif group in stages and stages[group]["group"] == "metatrain":  # one meta-training
            first.append(group)
        elif group == BEYOND:
            for ev in (f"{BEYOND}-maps", f"{BEYOND}-tables"):
                first += list(stages[ev]["depends"])
                second.append(ev)
        else:
            first += [n for n in stages[group]["depends"]]
            second.append(group)
    # each stage once: --beyond with --only beyond-maps names that stage twice
    return [list(dict.fromkeys(first)), list(dict.fromkeys(second))]


def reproduce(rc: ReproduceConfig, executor=None) -> dict:
    """Run the stages of ``rc`` (with ``executor``; default: in this process) and write the report.

    Returns ``{"report": path, "records": ..., "out": ..., "plan": ...}``.
    """
    from warp_critic.reproduce.executors import InProcess

    settings = rc.validate()
    out, lock = claim_out(Path(rc.out))
    try:
        return _reproduce(rc, settings, out, executor or InProcess())
    finally:
        lock.release()


def _reproduce(rc: ReproduceConfig, settings: dict, out: Path, executor) -> dict:
    from warp_critic.physics.simulator import resolve_device
    from warp_critic.reproduce.executors import jobs_hint
    from warp_critic.reproduce.ledger import Call
    from warp_critic.reproduce.units import make_unit

    device = resolve_device(rc.device)
    runner = Runner(out)
    t0 = time.perf_counter()
    stages = plan(settings, beyond=rc.plans_beyond, extra=rc.extra)
    call = Call(out, rc.command, rc.selected(), device)  # the folder's ledger
    waves = needed(rc, stages)
    todo = [  # reads every stage record first: a damaged one refuses the call here
        [
            n
            for n in wave
            if read_complete(runner.stage_dir(n, stages[n]["hash"]), stages[n]["group"]) is None
        ]
        for wave in waves
    ]
    runner.total = sum(len(wave) for wave in todo)
    with call:

        def done(unit, result, seconds):
            st = stages[unit.name]
            runner.finish(
                st["group"],
                unit.name,
                st["hash"],
                st["settings"],
                result,
                seconds,
                depends=st["depends"],
            )
            call.stage(unit.name, seconds, unit.dir_name)

        runner.log(
            f"reproduce: {runner.total} stage(s) to run ({executor.name}); complete ones are skipped"
        )
        hint = jobs_hint(executor, [len(wave) for wave in todo])
        if hint:
            runner.log(hint)
        waiting = [  # the complete ones are recorded (and said skipped) here
            n
            for n in dict.fromkeys(n for wave in waves for n in wave)
            if runner.complete(stages[n]["group"], n, stages[n]["hash"]) is None
        ]

        def ready() -> list:
            """The units of the waiting stages whose every input stage is now complete: a maps or
            tables stage starts as soon as its robot's meta-trainings are done, not after all."""
            units = []
            for n in list(waiting):
                if all(dep in runner.records for dep in stages[n]["depends"]):
                    waiting.remove(n)
                    units.append(make_unit(n, stages[n], settings, device, rc.progress, out))
            return units

        try:
            executor.run(ready(), out, done, runner.log, more=ready)
        finally:
            executor.close()
        if waiting:  # an input that this call neither found complete nor ran
            raise UserError(f"reproduce: {', '.join(waiting)}: an input stage did not complete")
        runner.log(
            f"reproduce: writing the report, {(time.perf_counter() - t0) / 60:.1f} min elapsed"
        )
        from warp_critic.reproduce.report import write_report

        report = write_report(
            out,
            stages,
            runner.records,
            config=rc,
            device=device,
            wall=time.perf_counter() - t0,
            call=call.id,
        )
    runner.log(f"reproduce: done in {(time.perf_counter() - t0):.1f} s; report {report}")
    return {"report": report, "records": runner.records, "out": out, "plan": stages}


def load_point_mass_hash() -> str:
    from warp_critic.analysis.landscape.problem import default_scene
    from warp_critic.physics.load import load_scene

    return load_scene(default_scene()).content_hash
