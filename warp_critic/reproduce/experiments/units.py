"""The unit of work of each stage (:class:`~warp_critic.reproduce.engine.executors.Unit`): the function
that runs it, by import path, and its inputs, with the run directories of the stages it reads
resolved (so that any executor can run it anywhere)."""

from __future__ import annotations

from pathlib import Path

from warp_critic.core.errors import UserError
from warp_critic.reproduce.engine.executors import Unit
from warp_critic.reproduce.engine.stage import Stage
from warp_critic.reproduce.engine.stages import read_stage
from warp_critic.reproduce.experiments.metatrain import identified_run_dirs, run_dirs
from warp_critic.reproduce.experiments.naming import stage_name
from warp_critic.reproduce.experiments.settings import ALL_METHODS

# the function each stage group runs, by import path (so that any executor can run it anywhere)
STAGE_FUNCTIONS = {
    "toy": "warp_critic.reproduce.experiments.analyses:run_toy_stage",
    "landscape": "warp_critic.reproduce.experiments.analyses:run_landscape_stage",
    "metatrain": "warp_critic.reproduce.experiments.metatrain:run_metatrain_stage",
    "maps": "warp_critic.reproduce.experiments.maps:run_maps_stage",
    "tables": "warp_critic.reproduce.experiments.tables:run_tables_stage",
    "budget": "warp_critic.reproduce.experiments.budget:run_budget_stage",
}
# the held-out tables and maps at a method's chosen budget: the tables / maps function's result,
# with the rows it shares with another stage named
REPORTING_FUNCTION = "warp_critic.reproduce.experiments.budget:run_reporting_stage"


def make_unit(st: Stage, settings: dict, device: str, progress: bool, out: Path) -> Unit:
    """The unit of work of the stage ``st`` of a plan of ``settings``, writing under ``out``."""
    group, name, o = st.kind, st.name, st.outputs
    if group == "toy":
        kwargs = {"s": settings["toy"]}
    elif group == "landscape":
        kwargs = {"s": settings["landscape"], "device": device}
    elif group == "metatrain":
        kwargs = {
            "scene": o.scene,
            "method": o.method,
            "values": st.settings["values"],
            "seeds": settings["metatrain"]["seeds"],
            "device": device,
            "progress": progress,
        }
    elif group == "budget":  # one method's choice: its meta-training's runs
        kwargs = {"s": st.settings, "runs": evaluated_runs(st, out)}
        kwargs.update(device=device, progress=progress)
    elif o.budget_of is not None:  # maps / tables at a method's chosen meta-test budget
        from warp_critic.reproduce.experiments.budget import reporting_kwargs

        kwargs = {"s": st.settings, **reporting_kwargs(st, out), "device": device}
        kwargs.update(group=group, progress=progress)
    else:  # maps / tables read the complete meta-training directories of their robot
        kwargs = {
            "s": st.settings,
            "runs": evaluated_runs(st, out),
            "device": device,
            "progress": progress,
        }
        if (
            o.rows is not None
        ):  # an extra baseline's evaluation: only its rows, ours' runs the reference
            kwargs["only"] = list(o.rows)
    reads = tuple(st.depends.values())
    if group == "maps" and name != "maps":  # beyond-maps: the paper's maps' floors, if complete
        floors = paper_maps_floors(out, st)
        if floors is not None:
            kwargs["floors_from"] = floors
            reads += (floors,)
    reporting = o is not None and o.budget_of is not None and group != "budget"
    fn = REPORTING_FUNCTION if reporting else STAGE_FUNCTIONS[group]
    return Unit(name=name, dir_name=st.dir_name, fn=fn, kwargs=kwargs, reads=reads)


def evaluated_runs(st: Stage, out: Path) -> dict[str, list[str]]:
    """Row label -> the run directories (relative to ``out``) an evaluation stage reads: each
    meta-training it depends on, labelled by its method (or the plan's label for it), and the same
    critics fed their identifier's estimate of the model (``<label>-identified``), where kept."""
    runs = {}
    labels = st.outputs.labels or {}
    for dep, dep_dir in st.depends.items():  # metatrain-<robot>-<method> -> its directory
        data = read_stage(out / dep_dir)
        if data is None:
            raise UserError(f"{out / dep_dir}: the stage {dep} this one needs is not complete")
        label = labels.get(dep) or stages_method(dep)
        runs[label] = [str(p.relative_to(out)) for p in run_dirs(out / dep_dir, data)]
        identified = identified_run_dirs(out / dep_dir, data)
        if identified:  # the same critics fed their identifier's estimate of the model
            runs[f"{label}-identified"] = [str(p.relative_to(out)) for p in identified]
    return runs


def stages_method(name: str) -> str:
    """The method of a ``metatrain-<robot>-<method>`` stage name."""
    return next(m for m in ALL_METHODS if name.endswith(f"-{m}"))


def paper_maps_floors(out: Path, st: Stage) -> str | None:
    """A complete ``maps`` stage directory under ``out`` whose reachability floors are exactly the
    ones the maps stage ``st`` would compute: the same settings and the same nominal reacher runs
    (the floors depend on nothing else: not on any critic). ``None``: none there."""
    nominal = stage_name("metatrain", "reacher", "ours")
    for d in sorted(out.glob("maps-*")):
        data = read_stage(d)
        if (
            data is not None
            and data.get("group") == "maps"
            and data.get("settings") == st.settings
            and data.get("depends", {}).get(nominal) == st.depends.get(nominal)
            and isinstance(data.get("result", {}).get("reach_floor"), dict)
        ):
            return d.name
    return None


__all__ = ["STAGE_FUNCTIONS", "make_unit", "paper_maps_floors", "stages_method"]
