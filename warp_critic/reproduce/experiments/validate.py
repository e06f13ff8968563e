"""Every setting of every reproduce stage, checked before the first stage runs.

One pass over the whole settings tree (defaults with the ``--set`` overrides applied): each value
must have its default's type, then each stage's values their ranges -- by the same checks the
stage's own command uses (``analyze toy``, ``analyze landscape``, the meta-train and baseline
configs against their scenes), plus the ranges of the maps and tables. A problem is one
:class:`~warp_critic.core.errors.FieldError` of ``--set`` that names the key and the value,
``--set tables.goal_noise="bogus": must be one of per-joint, distance``; never a flag of another
command. Keys that reproduce sets itself (``out``, ``scene``, ``resume``, ``device``, ``seed``,
``seeds`` of a meta-training) are refused.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

from warp_critic.core.errors import FieldError

#: meta-training keys reproduce sets itself: where the run goes, on what, resumed or not, its seeds
RESERVED = ("out", "scene", "resume", "device", "seed", "seeds")
MAX_GRID = 1000  # maps: grid x grid goals per run, seed and init


def show(value) -> str:
    if isinstance(value, float) and not math.isfinite(value):
        return repr(value)
    try:
        return json.dumps(value, allow_nan=True)
    except (TypeError, ValueError):
        return repr(value)


def bad(key: str, value, problem: str) -> FieldError:
    return FieldError("set", f"{key}={show(value)}: {problem}")


# -- types ------------------------------------------------------------------------------------------


def check_types(value, default, key: str) -> None:
    """``value`` has the JSON type of ``default`` (recursively; ``None`` defaults take anything)."""
    if default is None:
        return
    if isinstance(default, bool):
        ok = isinstance(value, bool)
        want = "true or false"
    elif isinstance(default, int):
        ok = isinstance(value, int) and not isinstance(value, bool)
        want = "an integer"
    elif isinstance(default, float):
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        want = "a number"
        if ok and not math.isfinite(value):
            raise bad(key, value, "must be a finite number")
    elif isinstance(default, str):
        ok, want = isinstance(value, str), "a string"
    elif isinstance(default, list):
        ok, want = isinstance(value, list), "a list"
        if ok and default:
            for v in value:
                check_types(v, default[0], key)
    elif isinstance(default, dict):
        ok, want = isinstance(value, dict), "a table of settings"
        if ok:
            for k in value:
                if k in default:
                    check_types(value[k], default[k], f"{key}.{k}")
    else:
        return
    if not ok:
        raise bad(key, value, f"must be {want}")


def number(key: str, v, *, lo=None, hi=None, open_lo=False, integer=False) -> None:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise bad(key, v, "must be a finite number")
    if integer and not isinstance(v, int):
        raise bad(key, v, "must be an integer")
    if lo is not None and (v <= lo if open_lo else v < lo):
        raise bad(key, v, f"must be {'>' if open_lo else '>='} {lo}")
    if hi is not None and v > hi:
        raise bad(key, v, f"must be <= {hi}")


def numbers(key: str, values, **kw) -> None:
    if not isinstance(values, list) or not values:
        raise bad(key, values, "must be a non-empty list of numbers")
    for v in values:
        number(key, v, **kw)


# -- the stages -------------------------------------------------------------------------------------


def _as_set(stage: str, values: dict, e: FieldError) -> FieldError:
    key = f"{stage}.{e.field}"
    return bad(key, values.get(e.field, "?"), e.problem)


def check_toy(s: dict) -> None:
    from warp_critic.analysis.toy.report import check_settings

    try:
        check_settings(
            **{k: s[k] for k in ("s0", "goal", "theta0", "alpha", "plain_lr")},
            iters=s["iters"],
            grid=s["grid"],
        )
    except FieldError as e:
        raise _as_set("toy", s, e) from None


def check_landscape(s: dict) -> None:
    from pathlib import Path

    from warp_critic.reproduce.experiments.analyses import landscape_configs

    try:
        landscape_configs(Path("unused"), s, "cpu")
    except FieldError as e:
        over = s.get("generalising") or {}
        stage = "landscape.generalising" if e.field in over else "landscape"
        raise _as_set(stage, over if e.field in over else s, e) from None


def check_metatrain(m: dict) -> dict[str, int]:
    """Every method x robot config against its scene; returns each robot's number of training goals."""
    from warp_critic.core.runtime import MAX_SEED, MAX_SEEDS  # a stage's seeds: one process
    from warp_critic.reproduce.experiments.settings import SCENES

    seeds = m["seeds"]
    if not isinstance(seeds, list) or not seeds or len(seeds) > MAX_SEEDS:
        raise bad("metatrain.seeds", seeds, f"must be a list of 1 to {MAX_SEEDS} seeds")
    for s in seeds:
        number("metatrain.seeds", s, lo=0, hi=MAX_SEED, integer=True)
    if len(set(seeds)) != len(seeds):
        raise bad("metatrain.seeds", seeds, "must be distinct")
    goals = {}
    for scene in SCENES:
        for method in m[scene]:  # the default methods, and any --baselines added
            cfg, _ = _check_train(
                scene, method, m[scene][method], seeds, f"metatrain.{scene}.{method}"
            )
            if method == "ours":
                goals[scene] = len(cfg.goals)
    return goals


def _check_train(scene: str, method: str, values: dict, seeds: list, where: str):
    """One meta-training config (``values``) against its scene; returns the filled config and the
    loaded robot."""
    from warp_critic.reproduce.experiments.metatrain import check_fields_known, make_config
    from warp_critic.running.task import load_task_scene
    from warp_critic.running.task_inputs import check_memory

    for k in RESERVED:
        if k in values:
            raise bad(f"{where}.{k}", values[k], "may not be set (reproduce sets it)")
    check_fields_known(method, values, f"--set {where}")
    try:
        cfg = make_config(scene, method, values, seeds, Path("unused"), "cpu", False)
        # the defaults filled from the scene, checked
        cfg, robot = load_task_scene(replace(cfg, seeds=None))
        check_memory(cfg, robot.dof, copies=len(seeds))
    except FieldError as e:
        raise _as_set(where, values, e) from None
    except TypeError as e:  # a value of a type the config cannot take
        raise FieldError("set", f"{where}: {e}") from None
    return cfg, robot


def _common(stage: str, s: dict) -> None:
    number(f"{stage}.inits", s["inits"], lo=1, hi=10**6, integer=True)
    number(f"{stage}.seed", s["seed"], lo=0, hi=2**32 - 1, integer=True)
    number(f"{stage}.max_worlds", s["max_worlds"], lo=1, hi=10**8, integer=True)
    numbers(f"{stage}.masses", s["masses"], lo=0, hi=1e4)
    numbers(f"{stage}.lengths", s["lengths"], lo=0, open_lo=True, hi=100)


def check_tables(s: dict, train_goals: int) -> None:
    from warp_critic.evaluation.paper import GOAL_NOISE

    _common("tables", s)
    numbers("tables.stds", s["stds"], lo=0, hi=100)
    number("tables.dynamics_goal_std", s["dynamics_goal_std"], lo=0, hi=100)
    number("tables.num_goals", s["num_goals"], lo=1, hi=10**6, integer=True)
    # the stress tables: a point mass added at the tip (as --ee-mass), link 7 stretched to a length
    # (as --link-length); the open-loop reachability floor's Adam steps (0: no floor)
    numbers("tables.stress_masses", s["stress_masses"], lo=0, hi=1e4)
    numbers("tables.stress_lengths", s["stress_lengths"], lo=0, open_lo=True, hi=100)
    number("tables.reach_iterations", s["reach_iterations"], lo=0, hi=10**6, integer=True)
    if s["goal_noise"] not in GOAL_NOISE:
        raise bad("tables.goal_noise", s["goal_noise"], f"must be one of {', '.join(GOAL_NOISE)}")
    around = s["around"]
    if not isinstance(around, list):
        raise bad("tables.around", around, "must be a list of training-goal indices")
    for i in around:
        number("tables.around", i, lo=0, hi=train_goals - 1, integer=True)


def check_maps(s: dict) -> None:
    _common("maps", s)
    number("maps.grid", s["grid"], lo=1, hi=MAX_GRID, integer=True)
    number("maps.limit_fraction", s["limit_fraction"], lo=0, open_lo=True, hi=1)
    # the open-loop reachability floor: Adam steps (0: none) at each learning rate
    number("maps.reach_iterations", s["reach_iterations"], lo=0, hi=10**6, integer=True)
    numbers("maps.reach_lrs", s["reach_lrs"], lo=0, open_lo=True, hi=100)


def check_all(settings: dict, defaults: dict) -> None:
    """The whole settings tree (see the module docstring); raises a one-line :class:`FieldError`."""
    for stage, values in settings.items():
        check_types(values, defaults[stage], stage)
    check_toy(settings["toy"])
    check_landscape(settings["landscape"])
    goals = check_metatrain(settings["metatrain"])
    check_tables(settings["tables"], goals["kuka"])
    check_maps(settings["maps"])
    check_beyond(settings["beyond"], settings["metatrain"]["seeds"])
    check_heldout(settings["heldout"], settings["tables"], settings["maps"])
    check_budget(settings["budget"], settings)


def check_heldout(h: dict, tables: dict, maps: dict) -> None:
    """The held-out goal seeds: each chose nothing, none equals the seed ``tables`` / ``maps``
    score on, and no two draw a Table 1 goal twice (column ``c`` draws from ``seed + c``); ours'
    iterations at the baselines' environment steps, a positive whole number per robot."""
    from warp_critic.evaluation.seed_uses import chose

    seeds = h["seeds"]
    if not isinstance(seeds, list) or not seeds:
        raise bad("heldout.seeds", seeds, "must be a list of one or more goal seeds")
    columns = len(tables["stds"])
    for s in seeds:
        number("heldout.seeds", s, lo=0, hi=2**32 - 1, integer=True)
        if chose(s):
            raise bad("heldout.seeds", s, f"goal seed {s} chose a setting: it cannot be held out")
        if s in (tables["seed"], maps["seed"]):
            raise bad("heldout.seeds", s, "is the seed the tables and maps stages score on")
    ranges = sorted((int(s), int(s) + columns) for s in [*seeds, tables["seed"]])
    for (a, a_end), (b, _) in zip(ranges, ranges[1:]):
        if b < a_end:
            raise bad(
                "heldout.seeds",
                seeds,
                f"seeds {a} and {b} draw the same Table 1 goals (each draws {columns} seeds, "
                "one per column): space them at least that far apart",
            )
    for robot, n in h["equal_step_iterations"].items():
        number(f"heldout.equal_step_iterations.{robot}", n, lo=1, hi=10**7, integer=True)


def check_budget(b: dict, settings: dict) -> None:
    """Each method's meta-test budget: distinct positive step counts, positive step-size multiples,
    and a choosing goal seed that chose nothing else and draws no goal a table or map reports on."""
    from warp_critic.evaluation.seed_uses import CHOOSE_BUDGET_SEED, chose

    steps, scales = b["steps"], b["alpha_scales"]
    numbers("budget.steps", steps, lo=1, hi=10**5, integer=True)
    if len(set(steps)) != len(steps):
        raise bad("budget.steps", steps, "a step count is given twice")
    numbers("budget.alpha_scales", scales, lo=0, open_lo=True, hi=1e6)
    if len(set(scales)) != len(scales):
        raise bad("budget.alpha_scales", scales, "a step-size multiple is given twice")
    number("budget.inits", b["inits"], lo=1, hi=10**6, integer=True)
    number("budget.max_worlds", b["max_worlds"], lo=1, hi=10**8, integer=True)
    seed = b["seed"]
    number("budget.seed", seed, lo=0, hi=2**32 - 1, integer=True)
    if seed != CHOOSE_BUDGET_SEED and chose(seed):
        raise bad("budget.seed", seed, f"goal seed {seed} chose another setting (seed_uses.py)")
    columns = len(settings["tables"]["stds"])  # a reporting seed s draws s .. s + columns - 1
    reporting = [
        *settings["heldout"]["seeds"],
        settings["tables"]["seed"],
        settings["maps"]["seed"],
    ]
    if any(int(r) <= seed < int(r) + columns for r in reporting):
        raise bad("budget.seed", seed, "draws the goals a table or map reports on; use another")


def check_beyond(b: dict, seeds: list) -> None:
    """Every recipe beyond the paper: an ours config, against its robot's scene."""
    from warp_critic.reproduce.experiments.settings import SCENES

    for scene in SCENES:
        if not isinstance(b.get(scene), dict) or not b[scene]:
            raise bad(f"beyond.{scene}", b.get(scene), "must name at least one recipe")
        for recipe, values in b[scene].items():
            where = f"beyond.{scene}.{recipe}"
            if not isinstance(values, dict):
                raise bad(where, values, "must be a meta-train config")
            train = {k: v for k, v in values.items() if k != "identify"}
            cfg, robot = _check_train(scene, "ours", train, seeds, where)
            if "identify" in values:
                check_identify(values["identify"], train, f"{where}.identify")
                if values["identify"].get("variants"):
                    _check_identify_draws(robot, cfg, values["identify"]["variants"], where)


def check_identify(s, train: dict, where: str) -> None:
    """A recipe's ``identify`` settings: a model identifier for a critic told the drawn models."""
    from warp_critic.learning.critic_inputs import TOLD_INPUTS
    from warp_critic.methods.identify import SETTINGS

    if not isinstance(s, dict):
        raise bad(where, s, f"must be a table of {', '.join(SETTINGS)}")
    unknown = sorted(set(s) - set(SETTINGS))
    if unknown:
        raise bad(f"{where}.{unknown[0]}", s[unknown[0]], f"unknown (known: {', '.join(SETTINGS)})")
    for k in ("iterations", "goals", "inits", "hidden"):
        if k in s:
            number(f"{where}.{k}", s[k], lo=1, hi=10**6, integer=True)
    if "lr" in s:
        number(f"{where}.lr", s["lr"], lo=0, open_lo=True, hi=10)
    if "version" in s and (isinstance(s["version"], bool) or s["version"] not in (1, 2)):
        raise bad(
            f"{where}.version", s["version"], "must be 1 or 2 (the identifier's architecture)"
        )
    if train.get("critic_input") not in TOLD_INPUTS or not train.get("train_variants"):
        raise bad(
            where,
            s,
            f"identifies the drawn models for a critic told them: the recipe needs train_variants "
            f"and critic_input {' or '.join(TOLD_INPUTS)}",
        )


def _check_identify_draws(robot, cfg, variants, where: str) -> None:
    """``identify.variants``: draw ranges (the ``train_variants`` form) that apply to the recipe's
    robot, checked as the identifier checks them (:func:`~warp_critic.physics.variant_draws.ranges_on_scene`)."""
    from warp_critic.physics.variant_draws import ranges_on_scene
    from warp_critic.running.task import task_variant

    key = f"{where}.identify.variants"
    if not isinstance(variants, str):
        raise bad(key, variants, "must be draw ranges in the train_variants form")
    try:
        ranges_on_scene(robot, task_variant(cfg), variants)
    except FieldError as e:
        raise bad(key, variants, e.problem) from None


__all__ = ["RESERVED", "check_all", "show"]
