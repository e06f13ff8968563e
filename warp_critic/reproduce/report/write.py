"""``REPORT.md``, ``results.json``, ``figures/*.png`` and ``report.rrd`` from the stage files.

Every number comes from a stage's ``stage.json`` (or a file it names); nothing is typed in. The
paper's values come from :data:`warp_critic.evaluation.paper.PAPER_TABLES`. The report covers
every stage of the current settings that is complete, whether it ran in this call or earlier. The
sections live in :mod:`~warp_critic.reproduce.report.analyses`, :mod:`~warp_critic.reproduce.report.training`, :mod:`~warp_critic.reproduce.report.maps` and
:mod:`~warp_critic.reproduce.report.tables`; they share one :class:`~warp_critic.reproduce.report.draft.Draft`.
"""

from __future__ import annotations

import json
import platform
import time
from pathlib import Path

import numpy as np

from warp_critic.reproduce.engine import ledger
from warp_critic.reproduce.engine.stage import Stage
from warp_critic.reproduce.engine.stages import STAGE_FILE, StageRecord, read_stage
from warp_critic.reproduce.experiments.extra_baselines import merge_rows
from warp_critic.reproduce.experiments.naming import stage_name
from warp_critic.reproduce.experiments.settings import SCENES, STAGES
from warp_critic.reproduce.report import paper as rp
from warp_critic.reproduce.report.analyses import landscape_section, toy_section
from warp_critic.reproduce.report.beyond import beyond_section
from warp_critic.reproduce.report.budget import budget_section
from warp_critic.reproduce.report.draft import Draft, rel
from warp_critic.reproduce.report.heldout import heldout_section
from warp_critic.reproduce.report.maps import maps_section
from warp_critic.reproduce.report.tables import tables_section
from warp_critic.reproduce.report.training import metatrain_section
from warp_critic.running.files import atomic_write_text

#: The sections after the stage table, in the report's order (each appends to the :class:`Draft`).
SECTIONS = (
    toy_section,
    landscape_section,
    metatrain_section,
    maps_section,
    tables_section,
    heldout_section,
    budget_section,
    beyond_section,
)


# ------------------------------------------------------------------------------------------------
# collecting
# ------------------------------------------------------------------------------------------------


def collect(out: Path, plan: dict[str, Stage], records: dict) -> dict[str, StageRecord | None]:
    got: dict[str, StageRecord | None] = {}
    for name, st in plan.items():
        if name in records:
            got[name] = records[name]
            continue
        d = out / st.dir_name
        data = read_stage(d)
        got[name] = StageRecord(st.kind, name, d, data, ran=False) if data is not None else None
    return got


def versions() -> dict[str, str]:
    import newton
    import torch
    import warp

    return {
        "python": platform.python_version(),
        "warp": str(getattr(warp.config, "version", "?")),
        "newton": str(getattr(newton, "__version__", "?")),
        "torch": torch.__version__,
        "platform": platform.platform(),
    }


def write_report(
    out: Path,
    plan: dict[str, Stage],
    records: dict,
    *,
    config,
    device: str,
    wall: float,
    call: str | None = None,
) -> Path:
    """Write the report of ``out``'s complete stages of ``plan``; ``call`` is this call's id in
    the folder's ledger (:mod:`~warp_critic.reproduce.engine.ledger`), whose total wall time the header gives."""
    out = Path(out)
    recs = merge_rows(
        collect(out, plan, records), plan
    )  # an extra baseline's rows join the paper's
    book = ledger.summary(ledger.read(out), open_call=call, open_wall=wall)
    stage_seconds = {r.dir.name: float(r.data["seconds"]) for r in recs.values() if r is not None}
    # a stage's compute: its completing call's wall time, or its iteration times over all calls
    # where that is more (a stage resumed over several calls records only the last call's time)
    stage_compute = {r.dir.name: ledger.stage_compute(r) for r in recs.values() if r is not None}
    figs = out / "figures"
    figs.mkdir(exist_ok=True)
    results: dict = {
        "kind": "warp-critic/reproduce-results-v1",
        "tables": [],
        "metatrain": {},
        "maps": None,
        "toy": None,
        "landscape": None,
        "stages": {},
    }
    figures: list[tuple[str, Path, str]] = []  # (title, png, sentence)
    ver = versions()
    seeds = seeds_trained(plan)
    md = _header(
        config, device, seeds, ver, wall, ledger.header_line(book, stage_seconds, stage_compute)
    )
    claims_at = len(md)
    claims: list[dict] = []  # filled by the sections below, rendered here
    solved: dict[str, dict[str, list[bool]]] = {}  # robot -> baseline -> per seed
    for scene in SCENES:
        solved[scene] = {}
        for m in rp.ALL_BASELINES:
            rec = recs.get(stage_name("metatrain", scene, m))
            if rec is not None:
                solved[scene][m] = rp.solved_seeds(rec.data["result"], scene)
    md += _stage_table(plan, recs, results)
    d = Draft(out, figs, recs, config, solved, md, results, figures, claims)
    for section in SECTIONS:
        section(d)
    md[claims_at:claims_at] = _claims_table(claims) + [""]
    results["claims"] = claims
    md += ["## Figures", ""]
    for title, png, sentence in figures:
        md += [f"### {title}", "", f"![{title}]({rel(png, out)})", "", sentence, ""]
    results["figures"] = [{"title": t, "file": rel(p, out), "sentence": s} for t, p, s in figures]
    results.update(
        command=config.command,
        device=device,
        seeds=seeds,
        quick=config.quick,
        versions=ver,
        ledger={
            "file": ledger.LEDGER,
            "calls": book["calls"],
            "wall_seconds": book["wall"],
            "first_start": book["first"],
            "last_end": book["last"],
            "stage_seconds_sum": sum(stage_seconds.values()),
            "stages_before_ledger": [n for n in stage_seconds if n not in book["stages_run"]],
            "carried_compute_seconds": sum(
                stage_compute[n] for n in stage_seconds if n not in book["stages_run"]
            ),
        },
    )
    text = "\n".join(md) + "\n"
    atomic_write_text(out / "results.json", json.dumps(results, indent=1) + "\n")
    atomic_write_text(out / "REPORT.md", text)
    write_recording(out / "report.rrd", text, figures)
    return out / "REPORT.md"


def _header(config, device: str, seeds: list[int], ver: dict, wall: float, book: str) -> list[str]:
    """The report's title and header lines: command, device, seeds, versions, time, ledger."""
    return [
        "# Reproduction: Model Based Meta Learning of Critics for Policy Gradients (ICML 2022)",
        "",
        f"- command: `{config.command}`",
        f"- device: {device}; seeds: {len(seeds)} ({', '.join(map(str, seeds))}); "
        f"{'QUICK settings (plumbing check, not the paper setting)' if config.quick else 'paper settings, except where a section states the settings that differ from the paper text'}",
        f"- versions: python {ver['python']}, warp {ver['warp']}, newton {ver['newton']}, torch {ver['torch']} "
        f"({ver['platform']})",
        f"- written {time.strftime('%Y-%m-%d %H:%M:%S')}; this call took {wall:.1f} s",
        book,
        "",
    ]


def _stage_table(plan: dict[str, Stage], recs: dict, results: dict) -> list[str]:
    """The "Stages" section's lines: each stage of the plan, run, skipped or not run; fills
    ``results["stages"]``."""
    md = [
        "## Stages",
        "",
        "Wall time: of the call that completed the stage (a stage resumed over several calls counts only the "
        "last). Training time: the sum of the stage's iteration times over all calls (the seeds of a "
        "meta-training run batched, so it is the whole stage's).",
        "",
        "| stage | directory | this call | wall time (s) | training time, all calls (s) |",
        "|---|---|---|---|---|",
    ]
    for name, st in plan.items():
        r = recs.get(name)
        if r is None:
            md.append(f"| {name} | `{st.dir_name}` | not run | — | — |")
            continue
        status = "ran" if r.ran else "complete, skipped"
        per_seed = r.data["result"].get("seeds") if r.group == "metatrain" else None
        train = f"{next(iter(per_seed.values()))['seconds']:.1f}" if per_seed else "—"
        md.append(f"| {name} | `{r.dir.name}` | {status} | {r.data['seconds']:.1f} | {train} |")
        results["stages"][name] = {
            "dir": r.dir.name,
            "file": f"{r.dir.name}/{STAGE_FILE}",
            "seconds": r.data["seconds"],
            "ran_this_call": r.ran,
        }
    md.append("")
    return md


def _claims_table(claims: list[dict]) -> list[str]:
    """The claims table, at the report's top: one row per claim the sections computed."""
    head = [
        "## The paper's claims: verdicts computed from the numbers below",
        "",
        "| claim | the paper's evidence | this run's measurement | verdict | why |",
        "|---|---|---|---|---|",
    ] + [
        f"| {c['claim']} | {c['paper']} | {c['ours']} | **{c['verdict']}** | {c['reason']} |"
        for c in claims
    ]
    if not claims:
        head.append("| (no stage ran) | — | — | not comparable | nothing measured |")
    return head


def seeds_trained(plan: dict[str, Stage]) -> list[int]:
    """The meta-training seeds of a plan (``metatrain.seeds``, which ``--set`` may have changed)."""
    return next(list(st.settings["seeds"]) for st in plan.values() if st.kind == "metatrain")


def write_recording(path: Path, text: str, figures: list[tuple[str, Path, str]]) -> None:
    import rerun.blueprint as rrb
    from matplotlib.image import imread

    from warp_critic.running.recording import Recorder

    names = [f"figures/{Path(p).stem}" for _, p, _ in figures]
    views = [rrb.Spatial2DView(origin=n, name=t) for n, (t, _, _) in zip(names, figures)]
    blueprint = rrb.Blueprint(
        rrb.Tabs(
            rrb.TextDocumentView(origin="report", name="REPORT.md"),
            rrb.Grid(*views, name="figures") if views else rrb.Grid(name="figures"),
        )
    )
    tmp = path.with_name(f".{path.name}.tmp")
    rec = Recorder(tmp, application_id="warp-critic-reproduce", blueprint=blueprint)
    try:
        rec.text("report", text)
        for n, (_, p, s) in zip(names, figures):
            img = imread(p)
            if img.dtype != np.uint8:
                img = (np.clip(img, 0, 1) * 255).astype(np.uint8)
            rec.image(n, img[..., :3], static=True)
            rec.text(f"{n}/caption", s)
    finally:
        rec.close()
    tmp.replace(path)


__all__ = ["write_report", "seeds_trained", "STAGES"]
