"""Baselines beyond the paper's two in ``reproduce`` (``--baselines ddpg,meta-critic,td3``): their
own stages, and their rows merged into the paper's maps and tables for the report.

A baseline ``m`` that the registry does not reproduce by default (:data:`~warp_critic.reproduce.experiments.settings.EXTRA_BASELINES`)
adds, when selected, ``metatrain-<robot>-<m>`` (as the paper's baselines, with its published settings
at the baselines' budget) and two evaluations: ``<m>-maps`` (reacher) and ``<m>-tables`` (KUKA), the
paper's maps and tables settings for its runs only, with the same goals, initialisations and policy
updates as the paper's stages (read from ours' nominal runs, a dependency of both). The paper's
stages, their hashes and their report are unchanged: without the selection nothing here is planned,
and with it the report shows the extra rows only where their stages are complete.
"""

from __future__ import annotations

import copy
from dataclasses import replace

from warp_critic.core.errors import FieldError
from warp_critic.reproduce.engine.stage import Stage
from warp_critic.reproduce.engine.stages import StageRecord
from warp_critic.reproduce.experiments.naming import Outputs, stage_name
from warp_critic.reproduce.experiments.settings import EXTRA_BASELINES, METHODS, SCENES, stage_hash

#: the evaluation groups an extra baseline gets, and the robot each reads
EVALUATIONS = (("maps", "reacher"), ("tables", "kuka"))


def check_baselines(names: list[str] | None) -> tuple[str, ...]:
    """The extra baselines of a ``--baselines`` list (``None``: the default ones, no extra); the
    paper's baselines may not be left out (their stages carry the report's claims)."""
    if names is None:
        return ()
    default = [m for m in METHODS if m != "ours"]
    known = (*default, *EXTRA_BASELINES)
    for name in names:
        if name not in known:
            raise FieldError("baselines", f"unknown baseline {name!r} (known: {', '.join(known)})")
    missing = [m for m in default if m not in names]
    if missing:
        raise FieldError(
            "baselines",
            f"the paper's baselines are always reproduced: add {', '.join(missing)} "
            f"(e.g. {','.join([*default, *EXTRA_BASELINES])})",
        )
    return tuple(m for m in EXTRA_BASELINES if m in names)


def metatrain_stage(settings: dict, scene: str, m: str, hashes: dict[str, str]) -> Stage:
    """The meta-training ``metatrain-<scene>-<m>`` (the paper's or an extra)."""
    values, seeds = settings["metatrain"][scene][m], settings["metatrain"]["seeds"]
    name = stage_name("metatrain", scene, m)
    return Stage(
        name,
        "metatrain",
        {"values": values, "seeds": seeds, "scene_hash": hashes[scene]},
        {},
        stage_hash(name, values, seeds, hashes[scene]),
        Outputs(scene=scene, method=m),
    )


def plan_extra(
    settings: dict, p: dict[str, Stage], hashes: dict[str, str], extra: tuple[str, ...]
) -> None:
    """Add each extra baseline's meta-trainings and evaluations to the plan ``p``."""
    for m in extra:
        for scene in SCENES:
            st = metatrain_stage(settings, scene, m, hashes)
            p[st.name] = st
        for group, scene in EVALUATIONS:
            dep = {
                n: p[n].dir_name
                for n in (stage_name("metatrain", scene, "ours"), stage_name("metatrain", scene, m))
            }
            name = stage_name(group, by=m)
            p[name] = Stage(
                name,
                group,
                settings[group],
                dep,
                stage_hash(name, settings[group], dep),
                # ours' runs are the reference, not evaluated again
                Outputs(scene=scene, rows=(m,), adds_to=group),
            )


def selected_extra(groups: list[str], extra: tuple[str, ...]) -> list[str]:
    """The extra baselines' evaluations a selection of stage groups implies (their meta-trainings
    are in the ``metatrain`` group, or run first as what an evaluation reads)."""
    return [stage_name(group, by=m) for m in extra for group, _ in EVALUATIONS if group in groups]


def merge_rows(
    recs: dict[str, StageRecord | None], plan: dict[str, Stage]
) -> dict[str, StageRecord | None]:
    """``recs`` with each complete extra evaluation's rows added to its paper stage's result (a
    copy): the maps' per-method grids, the tables' cells. The report then shows them as rows."""
    out = dict(recs)
    for name, st in plan.items():
        base, extra = st.outputs.adds_to if st.outputs else None, recs.get(name)
        if base is None or extra is None or out.get(base) is None:
            continue
        target = out[base]
        assert target is not None
        data = copy.deepcopy(target.data)
        res, add = data["result"], extra.data["result"]
        if st.kind == "maps":
            for key in ("goals", "mass", "length"):
                res[key].update(add[key])
        else:
            res["cells"] = res["cells"] + add["cells"]
        out[base] = replace(target, data=data)
    return out
