"""The held-out stages: Tables 1-3 and the maps again on every held-out goal seed, and ours
meta-trained on the KUKA at the baselines' environment steps, evaluated on them.

A reviewer's two questions, each answered by stages of its own (the paper's stages and their hashes
are unchanged):

* **Did the seed that chose the settings also score them?** The ``tables`` and ``maps`` stages use
  goal seed 1, which chose ours' settings (:mod:`~warp_critic.evaluation.seed_uses`). Here every
  held-out seed (``settings["heldout"]["seeds"]``, none of which chose anything) gets
  ``tables-heldout[-<seed>]`` (KUKA Tables 1-3; the stress tables cut to one column) and
  ``maps-heldout[-<seed>]`` (the reacher maps; their reachability floors are the ``maps`` stage's:
  they depend on no seed). An extra baseline (``--baselines ...,td3``) gets its rows on every seed
  too (``td3-tables-heldout-1010``), added to the seed's stage as on seed 1.
* **Did ours win only by training longer?** Ours trains the KUKA on 9.6M environment steps, the
  baselines on 1.2M. ``metatrain-kuka-ours-equal-steps`` is ours with the same settings and
  ``equal_step_iterations`` iterations (1.2M steps), and ``equal-steps-tables-heldout[-<seed>]``
  adds its rows (``ours-equal-steps``) to each held-out seed's tables.

The first held-out seed's tables stage keeps the name and hash it had before there were three.
"""

from __future__ import annotations

from warp_critic.evaluation.seed_uses import HELDOUT_MAPS, HELDOUT_TABLES
from warp_critic.reproduce.engine.stage import Stage
from warp_critic.reproduce.experiments.naming import EQUAL_STEPS, Outputs, stage_name
from warp_critic.reproduce.experiments.settings import stage_hash

#: the row of ours at the baselines' environment steps, in the held-out tables
EQUAL_STEPS_ROW = "ours-equal-steps"
#: each held-out evaluation: its group, robot and the settings replaced on every held-out seed
HELDOUT_EVALUATIONS = (("tables", "kuka", HELDOUT_TABLES), ("maps", "reacher", HELDOUT_MAPS))


def plan_heldout(
    settings: dict,
    p: dict[str, Stage],
    hashes: dict[str, str],
    extra: tuple[str, ...],
) -> None:
    """Add to ``p`` (which holds the paper's and the extra baselines' meta-trainings and
    evaluations) every held-out seed's tables and maps, the extra baselines' rows on them, and ours
    at the baselines' environment steps with its held-out tables (module docstring)."""
    seeds = [int(s) for s in settings["heldout"]["seeds"]]
    for group, scene, replaced in HELDOUT_EVALUATIONS:
        dep = p[group].depends  # the paper's evaluation's meta-trainings
        for seed in seeds:
            held = {**settings[group], **replaced, "seed": seed}
            name = stage_name(group, heldout=seed)
            first = name == stage_name(group, heldout=True)
            # the first seed's tables stage keeps the hash it had (the group, not its name, hashed)
            h = stage_hash(group if group == "tables" else name, held, dep)
            part_of = None if first else stage_name(group, heldout=True)
            p[name] = Stage(name, group, held, dep, h, Outputs(scene=scene, part_of=part_of))
            for m in extra:
                _add_rows(p, group, scene, held, seed, m, m)
    _plan_equal_steps(settings, p, hashes, seeds)


def _add_rows(
    p: dict[str, Stage],
    group: str,
    scene: str,
    held: dict,
    seed: int,
    by: str,
    row: str,
    dep_name: str | None = None,
) -> None:
    """One held-out evaluation of ``row``'s runs (the meta-training ``dep_name``, by default the
    method ``row``'s) on ``seed``, its rows added to that seed's paper stage; it runs with the
    held-out group (``--only tables-heldout``)."""
    nominal = stage_name("metatrain", scene, "ours")
    labels = {dep_name: row} if dep_name else None  # else the row is its method's name
    dep_name = dep_name or stage_name("metatrain", scene, row)
    dep = {nominal: p[nominal].dir_name, dep_name: p[dep_name].dir_name}
    name = stage_name(group, by=by, heldout=seed)
    p[name] = Stage(
        name,
        group,
        held,
        dep,
        stage_hash(name, held, dep),
        # ours' runs are the reference (they set the goals), not evaluated again
        Outputs(
            scene=scene,
            rows=(row,),
            adds_to=stage_name(group, heldout=seed),
            labels=labels,
            part_of=stage_name(group, heldout=True),
        ),
    )


def _plan_equal_steps(
    settings: dict, p: dict[str, Stage], hashes: dict[str, str], seeds: list[int]
) -> None:
    """Ours meta-trained at the baselines' environment steps on each robot where they differ, and
    its rows on every held-out seed's tables."""
    for scene, iterations in settings["heldout"]["equal_step_iterations"].items():
        values = {**settings["metatrain"][scene]["ours"], "iterations": int(iterations)}
        msettings = settings["metatrain"]
        name = stage_name("metatrain", scene, "ours", equal_steps=True)
        p[name] = Stage(
            name,
            "metatrain",
            {"values": values, "seeds": msettings["seeds"], "scene_hash": hashes[scene]},
            {},
            stage_hash(name, values, msettings["seeds"], hashes[scene]),
            Outputs(scene=scene, method="ours"),
        )
        group = next(g for g, s, _ in HELDOUT_EVALUATIONS if s == scene)
        for seed in seeds:
            held = p[stage_name(group, heldout=seed)].settings
            _add_rows(p, group, scene, held, seed, EQUAL_STEPS, EQUAL_STEPS_ROW, dep_name=name)


__all__ = ["EQUAL_STEPS_ROW", "HELDOUT_EVALUATIONS", "plan_heldout"]
