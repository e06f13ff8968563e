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
from warp_critic.reproduce.extra_baselines import (
    check_baselines,
    metatrain_stage,
    plan_extra,
    selected_extra,
)
from warp_critic.reproduce.settings import (
    ALL_METHODS,
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
        if self.seeds > 1000:
            raise FieldError("seeds", f"must be <= 1000 (got {self.seeds})")
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
        extra = [BEYOND] if self.beyond or BEYOND in (self.only or []) else []
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


# the function each stage group runs, by import path (so that any executor can run it anywhere)
STAGE_FUNCTIONS = {
    "toy": "warp_critic.reproduce.analyses:run_toy_stage",
    "landscape": "warp_critic.reproduce.analyses:run_landscape_stage",
    "metatrain": "warp_critic.reproduce.metatrain:run_metatrain_stage",
    "maps": "warp_critic.reproduce.generalize:run_maps_stage",
    "tables": "warp_critic.reproduce.generalize:run_tables_stage",
}


def needed(rc: ReproduceConfig, stages: dict) -> list[list[str]]:
    """The stages this call needs, in two waves: what depends on nothing, then maps / tables (which
    read the meta-training of their robot, run or found complete first even when not selected)."""
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


def stages_method(name: str) -> str:
    """The method of a ``metatrain-<robot>-<method>`` stage name."""
    return next(m for m in ALL_METHODS if name.endswith(f"-{m}"))


def make_unit(name: str, st: dict, settings: dict, device: str, progress: bool, out: Path):
    from warp_critic.reproduce.executors import Unit
    from warp_critic.reproduce.metatrain import identified_run_dirs, run_dirs

    group, dir_name = st["group"], f"{name}-{st['hash']}"
    if group == "toy":
        kwargs = {"s": settings["toy"]}
    elif group == "landscape":
        kwargs = {"s": settings["landscape"], "device": device}
    elif group == "metatrain":
        kwargs = {
            "scene": st["scene"],
            "method": st["method"],
            "values": st["settings"]["values"],
            "seeds": settings["metatrain"]["seeds"],
            "device": device,
            "progress": progress,
        }
    else:  # maps / tables read the complete meta-training directories of their robot
        from warp_critic.reproduce.stages import read_stage

        runs = {}
        for dep, dep_dir in st["depends"].items():  # metatrain-<robot>-<method> -> its directory
            data = read_stage(out / dep_dir)
            if data is None:
                raise UserError(f"{out / dep_dir}: the stage {dep} this one needs is not complete")
            label = st.get("labels", {}).get(dep) or stages_method(dep)
            runs[label] = [str(p.relative_to(out)) for p in run_dirs(out / dep_dir, data)]
            identified = identified_run_dirs(out / dep_dir, data)
            if identified:  # the same critics fed their identifier's estimate of the model
                runs[f"{label}-identified"] = [str(p.relative_to(out)) for p in identified]
        kwargs = {"s": st["settings"], "runs": runs, "device": device, "progress": progress}
        if "rows" in st:  # an extra baseline's evaluation: only its rows, ours' runs the reference
            kwargs["only"] = st["rows"]
    reads = tuple(st["depends"].values())
    if group == "maps" and name != "maps":  # beyond-maps: the paper's maps' floors, if complete
        floors = paper_maps_floors(out, st)
        if floors is not None:
            kwargs["floors_from"] = floors
            reads += (floors,)
    return Unit(name=name, dir_name=dir_name, fn=STAGE_FUNCTIONS[group], kwargs=kwargs, reads=reads)


def paper_maps_floors(out: Path, st: dict) -> str | None:
    """A complete ``maps`` stage directory under ``out`` whose reachability floors are exactly the
    ones the maps stage ``st`` would compute: the same settings and the same nominal reacher runs
    (the floors depend on nothing else: not on any critic). ``None``: none there."""
    from warp_critic.reproduce.stages import read_stage

    nominal = "metatrain-reacher-ours"
    for d in sorted(out.glob("maps-*")):
        data = read_stage(d)
        if (
            data is not None
            and data.get("group") == "maps"
            and data.get("settings") == st["settings"]
            and data.get("depends", {}).get(nominal) == st["depends"].get(nominal)
            and isinstance(data.get("result", {}).get("reach_floor"), dict)
        ):
            return d.name
    return None


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
        try:
            for wave in waves:
                units = [
                    make_unit(n, stages[n], settings, device, rc.progress, out)
                    for n in wave
                    if runner.complete(stages[n]["group"], n, stages[n]["hash"]) is None
                ]
                executor.run(units, out, done, runner.log)
        finally:
            executor.close()
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
