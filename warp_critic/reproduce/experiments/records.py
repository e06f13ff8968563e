"""What the paper's stages keep: the keys each stage group's record must hold, and what carrying
a stage to another machine keeps of it (the engine is told both: it knows no stage and no method).

:func:`stage_problem` is the ``check`` of :func:`~warp_critic.reproduce.engine.stages.read_complete`
and :class:`~warp_critic.reproduce.engine.stages.Runner`; :data:`CARRY` the rules of
:mod:`~warp_critic.reproduce.engine.carry` (``tools/carry_stages.py`` passes them).
"""

from __future__ import annotations

import numpy as np

from warp_critic.methods.meta_critic import AUX_KEYS
from warp_critic.reproduce.engine.carry import CarryRules
from warp_critic.reproduce.experiments.naming import is_beyond

#: what the report and the stages that read a stage take from its result: key -> JSON type
RESULT_KEYS: dict[str, dict[str, type | tuple[type, ...]]] = {
    "toy": {"closed_form": dict, "numerical": dict, "table_markdown": str, "files": dict},
    "landscape": {"goals": list, "fractions": (list, dict), "files": dict, "generalising": dict},
    "metatrain": {"seeds": dict, "iterations": int, "env_steps_per_iteration": int},
    "maps": {"axis_q1": list, "axis_q2": list, "goals": dict, "mass": dict, "length": dict},
    "tables": {"columns": dict, "cells": list, "dof": int},
    "budget": {"curve": dict, "chosen": dict, "untrained": float, "method": str},
}


def stage_problem(group: str, data: dict) -> str | None:
    """What makes a complete ``group`` stage's ``stage.json`` unusable (edited or damaged) beyond
    what every record holds (:func:`~warp_critic.reproduce.engine.stages.record_problem`), or
    ``None``."""
    result = data["result"]
    for key, kind in RESULT_KEYS.get(group, {}).items():
        if not isinstance(result.get(key), kind):
            return f"its result has no {key}"
    if group == "metatrain":
        if not result["seeds"]:
            return "its result has no seeds"
        for seed, v in result["seeds"].items():
            ok = (
                isinstance(v, dict)
                and isinstance(v.get("run_dir"), str)
                and isinstance(v.get("iteration"), list)
                and isinstance(v.get("task_loss"), list)
                and isinstance(v.get("seconds"), (int, float))
            )
            if not ok or not str(seed).lstrip("-").isdigit():
                return f"its result for seed {seed} is incomplete"
    return None


def record_only(data: dict) -> bool:
    """Whether publishing keeps only the record of the stage whose ``stage.json`` is ``data``:
    a recipe's meta-training (its critics were scored by ``beyond-maps`` / ``beyond-tables``)."""
    return data.get("group") == "metatrain" and is_beyond(str(data.get("stage", "")))


def published_checkpoint(data: dict, run: str) -> bool:
    """Whether publishing keeps the checkpoint of the run directory ``run`` (relative to its stage,
    ``run/seed3``) of the meta-training whose ``stage.json`` is ``data``: its first seed's only.

    A published folder (``docs/paper``) is part of every clone for ever, and a rerun's critics are
    new blobs (float weights barely compress: about 0.7 MB a seed); one critic per meta-training
    lets a reader meta-test it again beside the per-seed numbers every record holds."""
    seeds = data.get("result", {}).get("seeds", {})
    firsts = sorted(seeds, key=lambda s: int(s))[:1]
    return bool(firsts) and run == str(seeds[firsts[0]].get("run_dir"))


#: the note that stands in for a checkpoint publishing leaves out (``running.rundir.OMITTED``)
OMITTED_NOTE = (
    "a published report keeps the critic of each meta-training's first seed only, to keep the "
    "clone small (docs/paper/README.md, 'What this folder keeps'); this seed's record and config "
    "are here, and its numbers are in the stage record; train it again with warp-critic "
    "reproduce on an output folder without this stage"
)


#: what carrying keeps of the paper's stages: a meta-training's runs lose the checkpoint entries
#: only a resumed training reads (optimisers, ours' last policies, the baselines' target networks
#: and replay buffers), and its ``metrics.jsonl`` keeps only Meta-Critic's auxiliary-loss columns
#: (the report reads them for records written before the share was kept in ``stage.json``)
CARRY = CarryRules(
    check=stage_problem,
    slim_group="metatrain",
    training_only=("optimizer_state", "policy_params", "agent_state", "buffer"),
    metrics_keys=AUX_KEYS,
    metrics_row="aux_loss",
    record_only=record_only,
    published_checkpoint=published_checkpoint,
    omitted_note=OMITTED_NOTE,
)


def float32_list(a: np.ndarray) -> list:
    """``a`` as nested lists for JSON, each float32-representable value (every raw meta-test error:
    the descent runs in float32) written as the shortest decimal that reads back as that float32
    (``2.9574289`` rather than float64's ``2.9574289321899414``): about half the size compressed,
    nothing lost. An array with other values is written as it is (float64)."""
    a = np.asarray(a)
    a32 = a.astype(np.float32)
    if not np.array_equal(a32.astype(a.dtype), a, equal_nan=True):
        return a.tolist()
    flat = [float(str(x)) for x in a32.ravel()]  # numpy's str of a float32 is its shortest form
    return flat if a.ndim == 1 else np.asarray(flat, dtype=object).reshape(a.shape).tolist()
