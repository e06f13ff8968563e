"""The plan of a ``reproduce`` call: its flags checked (:class:`ReproduceConfig`), every stage with
its settings, hash and inputs (:func:`plan`), and the stages the call needs, in waves (:func:`needed`).

Stage order: toy, landscape, metatrain, maps, tables, tables-heldout and maps-heldout (Tables 1-3
and the maps again on each goal seed that chose nothing, with ours at the baselines' environment
steps: :mod:`~warp_critic.reproduce.experiments.heldout`). ``maps`` needs the reacher ``metatrain`` sub-stages and ``tables`` the
KUKA ones: they are run (or found complete) first even when ``--only``
does not name ``metatrain``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from warp_critic.core.errors import FieldError, UserError
from warp_critic.core.runtime import MAX_SEEDS, check_device
from warp_critic.reproduce.engine.stage import Stage
from warp_critic.reproduce.experiments.budget import BUDGET_GROUPS, plan_budget
from warp_critic.reproduce.experiments.extra_baselines import (
    EVALUATIONS,
    check_baselines,
    metatrain_stage,
    plan_extra,
    selected_extra,
)
from warp_critic.reproduce.experiments.heldout import plan_heldout
from warp_critic.reproduce.experiments.naming import BEYOND, Outputs, is_beyond, stage_name
from warp_critic.reproduce.experiments.settings import (
    METHODS,
    SCENES,
    STAGES,
    apply_overrides,
    default_settings,
    stage_hash,
)


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
        """The baselines beyond the paper's two that this call adds (:mod:`~warp_critic.reproduce.experiments.extra_baselines`)."""
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
        subs = metatrain_names(extra) + list(BEYOND_EVALS) + list(BUDGET_GROUPS)
        for s in self.only or []:
            if s not in STAGES and s not in subs and s != BEYOND:
                raise FieldError(
                    "only",
                    f"unknown stage {s!r} (stages: {', '.join(STAGES)}, {BEYOND}, "
                    f"{', '.join(BEYOND_EVALS)}, {', '.join(BUDGET_GROUPS)}; one meta-training: "
                    f"{', '.join(metatrain_names(extra))})",
                )
        if self.only is not None and not self.only:
            raise UserError(f"--only: give one or more of {', '.join(STAGES)}")
        check_device(self.device)
        defaults = default_settings(self.quick, self.seeds, extra)
        settings = apply_overrides(defaults, self.overrides)
        seeds = settings["metatrain"]["seeds"]
        if self.seeds_given and seeds != defaults["metatrain"]["seeds"]:
            raise FieldError(
                "seeds",
                f"{self.seeds} and --set metatrain.seeds={seeds} disagree; give one of them",
            )
        from warp_critic.reproduce.experiments.validate import check_all

        check_all(settings, defaults)  # every setting of every stage, before any work
        return settings

    def selected(self) -> list[str]:
        """The selected stage groups, and single meta-trainings (``metatrain-<robot>-<method>``,
        ``beyond-metatrain-<robot>-<recipe>``)."""
        # --beyond adds the group to a whole call; with --only the call runs what its names need
        only = self.only or []
        extra = [BEYOND] if BEYOND in only or (self.beyond and self.only is None) else []
        if self.only is None:  # --beyond also runs each method's own meta-test budget
            budget = list(BUDGET_GROUPS) if self.beyond else []
            return list(STAGES) + selected_extra(list(STAGES), self.extra) + extra + budget
        singles = [s for s in metatrain_names(self.extra) if s in self.only]
        if "metatrain" in self.only:
            singles = [s for s in singles if is_beyond(s)]  # the paper's are in the group
        if BEYOND not in self.only:  # one of the beyond evaluations alone (with what it reads)
            singles += [s for s in BEYOND_EVALS if s in self.only]
        groups = [s for s in STAGES if s in self.only]
        budget = [s for s in BUDGET_GROUPS if s in self.only]
        return groups + selected_extra(groups, self.extra) + singles + extra + budget

    @property
    def plans_beyond(self) -> bool:
        """Whether this call's plan holds the stages beyond the paper."""
        return any(is_beyond(s) for s in self.selected())

    @property
    def plans_budget(self) -> bool:
        """Whether this call's plan holds each method's meta-test budget stages (``--beyond``, or
        one of :data:`~warp_critic.reproduce.experiments.budget.BUDGET_GROUPS` in ``--only``)."""
        return any(s in BUDGET_GROUPS for s in self.selected())


#: the beyond group's evaluations, each also accepted alone by ``--only``
BEYOND_EVALS = (stage_name("maps", by=BEYOND), stage_name("tables", by=BEYOND))


def metatrain_names(extra: tuple[str, ...] = ()) -> list[str]:
    """The names of the single meta-trainings ``--only`` also accepts (the paper's, the ``extra``
    baselines' and the recipes beyond the paper)."""
    from warp_critic.reproduce.experiments.recipes import RECIPES

    return [stage_name("metatrain", scene, m) for scene in SCENES for m in (*METHODS, *extra)] + [
        stage_name("metatrain", scene, recipe=recipe)
        for scene in SCENES
        for recipe in RECIPES[scene]
    ]


def scene_hashes() -> dict[str, str]:
    from warp_critic.physics.load import load_scene
    from warp_critic.reproduce.experiments.metatrain import scene_file

    return {s: load_scene(scene_file(s)).content_hash for s in SCENES}


def plan(
    settings: dict, beyond: bool = False, extra: tuple[str, ...] = (), budget: bool = False
) -> dict[str, Stage]:
    """Every stage (sub-stage) of ``settings``, by name; with ``beyond``, also the recipes beyond
    the paper (:func:`plan_beyond`); with ``extra``, the stages of those baselines
    (:func:`~warp_critic.reproduce.experiments.extra_baselines.plan_extra`); with ``budget``, each
    method's own meta-test budget (:func:`~warp_critic.reproduce.experiments.budget.plan_budget`)."""
    hashes = scene_hashes()
    p: dict[str, Stage] = {}
    p["toy"] = Stage("toy", "toy", settings["toy"], {}, stage_hash("toy", settings["toy"]))
    landscape_hash = stage_hash("landscape", settings["landscape"], load_point_mass_hash())
    p["landscape"] = Stage("landscape", "landscape", settings["landscape"], {}, landscape_hash)
    for scene in SCENES:
        for m in METHODS:
            st = metatrain_stage(settings, scene, m, hashes)
            p[st.name] = st
    for group, scene in EVALUATIONS:
        dep = {n: p[n].dir_name for n in (stage_name("metatrain", scene, m) for m in METHODS)}
        h = stage_hash(group, settings[group], dep)
        p[group] = Stage(group, group, settings[group], dep, h, Outputs(scene=scene))
    plan_extra(settings, p, hashes, extra)
    plan_heldout(settings, p, hashes, extra)
    if beyond:
        plan_beyond(settings, p, hashes)
    if budget:
        plan_budget(settings, p, extra)
    return p


def plan_beyond(settings: dict, p: dict[str, Stage], hashes: dict[str, str]) -> None:
    """Add the stages beyond the paper to ``p``: one meta-training per robot and recipe
    (``beyond-metatrain-<robot>-<recipe>``, group metatrain), and ``beyond-maps`` / ``beyond-tables``:
    the paper's maps and tables (the same settings) of the nominal critic (``ours``) next to each
    recipe's. The paper's stages and their hashes are unchanged."""
    seeds = settings["metatrain"]["seeds"]
    for group, scene in EVALUATIONS:
        nominal = stage_name("metatrain", scene, "ours")
        dep = {nominal: p[nominal].dir_name}
        labels = {nominal: "ours"}
        for recipe, values in settings[BEYOND][scene].items():
            name = stage_name("metatrain", scene, recipe=recipe)
            p[name] = Stage(
                name,
                "metatrain",
                {"values": values, "seeds": seeds, "scene_hash": hashes[scene]},
                {},
                stage_hash(name, values, seeds, hashes[scene]),
                Outputs(scene=scene, method="ours", recipe=recipe),
            )
            dep[name] = p[name].dir_name
            labels[name] = recipe
        name = stage_name(group, by=BEYOND)
        h = stage_hash(name, settings[group], dep)
        p[name] = Stage(name, group, settings[group], dep, h, Outputs(scene=scene, labels=labels))


def needed(rc: ReproduceConfig, stages: dict[str, Stage]) -> list[list[str]]:
    """The stages this call needs: what depends on nothing, then maps / tables (which read the
    meta-training of their robot, run or found complete first even when not selected). The driver
    starts each stage once the stages it reads are complete, whichever list it is in."""
    selected = rc.selected()
    first, second = [], []
    for group in selected:
        if group in ("toy", "landscape"):
            first.append(group)
        elif group == "metatrain":  # the paper's six, and the extra baselines'
            first += [
                n
                for n, st in stages.items()
                if st.kind == "metatrain" and st.outputs.recipe is None
            ]
        elif group in stages and stages[group].kind == "metatrain":  # one meta-training
            first.append(group)
        elif group == BEYOND:
            for ev in BEYOND_EVALS:
                first += list(stages[ev].depends)
                second.append(ev)
        else:  # an evaluation, and the stages that run with it (the other held-out seeds)
            own = [group] if group in stages else []  # a budget group is no stage of its own
            for name in own + [n for n, st in stages.items() if _part_of(st) == group]:
                first += list(stages[name].depends)
                second.append(name)
    # each stage once: --beyond with --only beyond-maps names that stage twice, and --only
    # budget,budget-tables-heldout a choice both as a stage of its group and as what one reads
    first = list(dict.fromkeys(first))
    return [first, [n for n in dict.fromkeys(second) if n not in first]]


def _part_of(st: Stage) -> str | None:
    return getattr(st.outputs, "part_of", None)


def load_point_mass_hash() -> str:
    from warp_critic.analysis.landscape.problem import default_scene
    from warp_critic.physics.load import load_scene

    return load_scene(default_scene()).content_hash
