"""``reproduce``: run the selected stages in order (skipping complete ones), then write the report.

Stage order: toy, landscape, metatrain, maps, tables. ``maps`` needs the reacher ``metatrain``
sub-stages and ``tables`` the KUKA ones: they are run (or found complete) first even when ``--only``
does not name ``metatrain``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import FieldError, UserError
from .settings import METHODS, SCENES, STAGES, apply_overrides, default_settings, stage_hash
from .stages import Runner, prepare_out


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

    def validate(self) -> dict:
        """Check everything before any work; returns the settings. Raises a one-line :class:`UserError`."""
        if isinstance(self.seeds, bool) or not isinstance(self.seeds, int) or self.seeds < 1:
            raise FieldError("seeds", f"must be an integer >= 1 (got {self.seeds!r})")
        if self.seeds > 1000:
            raise FieldError("seeds", f"must be <= 1000 (got {self.seeds})")
        for s in self.only or []:
            if s not in STAGES:
                raise FieldError("only", f"unknown stage {s!r} (stages: {', '.join(STAGES)})")
        if self.only is not None and not self.only:
            raise UserError(f"--only: give one or more of {', '.join(STAGES)}")
        if self.device not in ("auto", "cpu", "cuda") and not str(self.device).startswith("cuda:"):
            raise UserError(f"--device: must be cpu, cuda or auto (got {self.device!r})")
        settings = apply_overrides(default_settings(self.quick, self.seeds), self.overrides)
        from .training import check_fields_known

        for scene in SCENES:
            for m in METHODS:
                check_fields_known(m, settings["metatrain"][scene][m], f"--set metatrain.{scene}.{m}")
        return settings

    def selected(self) -> list[str]:
        return [s for s in STAGES if self.only is None or s in self.only]


def scene_hashes() -> dict[str, str]:
    from ..scene import load_scene
    from .training import scene_file

    return {s: load_scene(scene_file(s)).content_hash for s in SCENES}


def plan(settings: dict) -> dict[str, dict]:
    """Every stage (sub-stage) of ``settings``: name -> group, hash, settings, depends (dir names)."""
    hashes = scene_hashes()
    seeds = settings["metatrain"]["seeds"]
    p: dict[str, dict] = {}
    p["toy"] = {"group": "toy", "settings": settings["toy"], "hash": stage_hash("toy", settings["toy"]), "depends": {}}
    p["landscape"] = {"group": "landscape", "settings": settings["landscape"], "depends": {},
                      "hash": stage_hash("landscape", settings["landscape"], load_point_mass_hash())}
    for scene in SCENES:
        for m in METHODS:
            values = settings["metatrain"][scene][m]
            name = f"metatrain-{scene}-{m}"
            p[name] = {"group": "metatrain", "scene": scene, "method": m, "depends": {},
                       "settings": {"values": values, "seeds": seeds, "scene_hash": hashes[scene]},
                       "hash": stage_hash(name, values, seeds, hashes[scene])}
    for group, scene in (("maps", "reacher"), ("tables", "kuka")):
        dep = {f"metatrain-{scene}-{m}": f"metatrain-{scene}-{m}-{p[f'metatrain-{scene}-{m}']['hash']}" for m in METHODS}
        p[group] = {"group": group, "scene": scene, "settings": settings[group], "depends": dep,
                    "hash": stage_hash(group, settings[group], dep)}
    return p


def reproduce(rc: ReproduceConfig) -> dict:
    """Run the stages of ``rc`` and write the report; returns ``{"report": path, "records": ...}``."""
    settings = rc.validate()
    out = prepare_out(Path(rc.out))
    from ..simulator import resolve_device

    device = resolve_device(rc.device)
    selected = rc.selected()
    runner = Runner(out, total=len(selected))
    t0 = time.perf_counter()
    stages = plan(settings)
    seeds = settings["metatrain"]["seeds"]

    def run(name: str, fn):
        st = stages[name]
        return runner.run(st["group"], name, st["hash"], st["settings"], fn, depends=st["depends"])

    def metatrain(scene: str) -> dict[str, list[Path]]:
        from .training import run_dirs, run_metatrain_stage

        dirs = {}
        for m in METHODS:
            values = settings["metatrain"][scene][m]
            rec = run(f"metatrain-{scene}-{m}", lambda d, scene=scene, m=m, values=values: run_metatrain_stage(
                d, scene, m, values, seeds, device, progress=rc.progress))
            dirs[m] = run_dirs(rec.dir, rec.data)
        return dirs

    for group in selected:
        runner.begin_group(group)
        if group == "toy":
            from .analyses import run_toy_stage

            run("toy", lambda d: run_toy_stage(d, settings["toy"]))
        elif group == "landscape":
            from .analyses import run_landscape_stage

            run("landscape", lambda d: run_landscape_stage(d, settings["landscape"], device))
        elif group == "metatrain":
            for scene in SCENES:
                metatrain(scene)
        elif group == "maps":
            from .generalize import run_maps_stage

            runs = metatrain("reacher")
            run("maps", lambda d: run_maps_stage(d, settings["maps"], runs, device, progress=rc.progress))
        elif group == "tables":
            from .generalize import run_tables_stage

            runs = metatrain("kuka")
            run("tables", lambda d: run_tables_stage(d, settings["tables"], runs, device, progress=rc.progress))
    runner.log(f"reproduce: writing the report, {(time.perf_counter() - t0) / 60:.1f} min elapsed")
    from .report import write_report

    report = write_report(out, stages, runner.records, config=rc, device=device, wall=time.perf_counter() - t0)
    runner.log(f"reproduce: done in {(time.perf_counter() - t0):.1f} s; report {report}")
    return {"report": report, "records": runner.records, "out": out, "plan": stages}


def load_point_mass_hash() -> str:
    from ..analysis.landscape_problem import default_scene
    from ..scene import load_scene

    return load_scene(default_scene()).content_hash
