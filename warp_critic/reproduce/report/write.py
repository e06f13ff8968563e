"""``REPORT.md``, ``results.json``, ``figures/*.png`` and ``report.rrd`` from the stage files.

Every number comes from a stage's ``stage.json`` (or a file it names); nothing is typed in. The
paper's values come from :data:`warp_critic.evaluation.paper.PAPER_TABLES`. The report covers
every stage of the current settings that is complete, whether it ran in this call or earlier.

:func:`write_report` computes every section of :data:`SECTIONS` (a
:class:`~warp_critic.reproduce.report.section.Section`: ``compute(Inputs) -> dict`` and
``render(view) -> list[str]``, the contract in :mod:`~warp_critic.reproduce.report.section`) into
one results dict, writes ``results.json``, and renders the whole of ``REPORT.md`` -- its header
(command, device, seeds, versions, time, ledger) too -- from ``json.loads`` of the very text it
wrote (:func:`render_report`), so the markdown shows only what ``results.json`` holds. A new
section is one more entry in :data:`SECTIONS`.
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
from warp_critic.reproduce.report.analyses import (
    landscape_compute,
    landscape_render,
    toy_compute,
    toy_render,
)
from warp_critic.reproduce.report.beyond import beyond_compute, beyond_render
from warp_critic.reproduce.report.budget import budget_compute, budget_render
from warp_critic.reproduce.report.heldout_section import heldout_compute, heldout_render
from warp_critic.reproduce.report.maps import maps_compute, maps_render
from warp_critic.reproduce.report.section import Inputs, Section
from warp_critic.reproduce.report.tables import tables_compute, tables_render
from warp_critic.reproduce.report.training import metatrain_compute, metatrain_render
from warp_critic.running.files import atomic_write_text

#: The sections after the stage table, in the report's order (their views are ``results.json``'s
#: ``sections.<name>``).
SECTIONS: tuple[Section, ...] = (
    Section("toy", toy_compute, toy_render),
    Section("landscape", landscape_compute, landscape_render),
    Section("metatrain", metatrain_compute, metatrain_render),
    Section("maps", maps_compute, maps_render),
    Section("tables", tables_compute, tables_render),
    Section("heldout", heldout_compute, heldout_render),
    Section("budget", budget_compute, budget_render),
    Section("beyond", beyond_compute, beyond_render),
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
    ver = versions()
    seeds = seeds_trained(plan)
    results = compute_results(Inputs(recs, solved_of(recs), config.quick, out, figs), plan)
    results.update(
        command=config.command,
        device=device,
        seeds=seeds,
        quick=config.quick,
        versions=ver,
        call={"written": time.strftime("%Y-%m-%d %H:%M:%S"), "seconds": wall},
        ledger=ledger.numbers(book, stage_seconds, stage_compute),
    )
    results["sections"] = results.pop("sections")  # the views last, after the numbers
    written = json.dumps(results, indent=1) + "\n"
    atomic_write_text(out / "results.json", written)
    loaded = json.loads(written)  # the markdown shows what results.json holds, nothing else
    text = render_report(loaded)
    atomic_write_text(out / "REPORT.md", text)
    write_recording(out / "report.rrd", text, out, loaded["figures"])
    return out / "REPORT.md"


def solved_of(recs: dict) -> dict[str, dict[str, list[bool]]]:
    """Robot -> baseline -> per seed, whether it solved the training task."""
    solved: dict[str, dict[str, list[bool]]] = {}
    for scene in SCENES:
        solved[scene] = {}
        for m in rp.ALL_BASELINES:
            rec = recs.get(stage_name("metatrain", scene, m))
            if rec is not None:
                solved[scene][m] = rp.solved_seeds(rec.data["result"], scene)
    return solved


def compute_results(inp: Inputs, plan: dict[str, Stage]) -> dict:
    """The results dict of every section (:data:`SECTIONS`) and the stage table, with their
    claims, figures and views (``sections``); writes the figures into ``inp.figures_dir``."""
    results: dict = {
        "kind": "warp-critic/reproduce-results-v1",
        "tables": [],
        "metatrain": {},
        "maps": None,
        "toy": None,
        "landscape": None,
        "stages": stages_of(plan, inp.recs),
    }
    views: dict = {"stages": stage_rows(plan, inp.recs)}
    claims: list[dict] = []
    figures: list[dict] = []
    for section in SECTIONS:
        got = section.compute(inp)
        results.update(got["results"])
        claims += got["claims"]
        figures += got["figures"]
        views[section.name] = got["view"]
    return results | {"claims": claims, "figures": figures, "sections": views}


def render_report(results: dict) -> str:
    """``REPORT.md`` below its header from ``results`` (``results.json`` as loaded): the claims
    table, the stage table, every section of :data:`SECTIONS` and the figures."""
    views = results["sections"]
    md = (
        header_lines(results)
        + _claims_table(results["claims"])
        + [""]
        + _stage_table(views["stages"])
    )
    for section in SECTIONS:
        md += section.render(views[section.name])
    md += ["## Figures", ""]
    for f in results["figures"]:
        title = f["title"]
        md += [f"### {title}", "", f"![{title}]({f['file']})", "", f["sentence"], ""]
    return "\n".join(md) + "\n"


def header_lines(results: dict) -> list[str]:
    """The report's title and header lines from ``results``: command, device, seeds, versions,
    when it was written and how long the call took, the ledger."""
    ver, seeds, call = results["versions"], results["seeds"], results["call"]
    setting = (
        "QUICK settings (plumbing check, not the paper setting)"
        if results["quick"]
        else "paper settings, except where a section states the settings that differ from the paper text"
    )
    return [
        "# Reproduction: Model Based Meta Learning of Critics for Policy Gradients (ICML 2022)",
        "",
        f"- command: `{results['command']}`",
        f"- device: {results['device']}; seeds: {len(seeds)} ({', '.join(map(str, seeds))}); "
        + setting,
        f"- versions: python {ver['python']}, warp {ver['warp']}, newton {ver['newton']}, torch {ver['torch']} "
        f"({ver['platform']})",
        f"- written {call['written']}; this call took {call['seconds']:.1f} s",
        ledger.header_line_of(results["ledger"]),
        "",
    ]


def stages_of(plan: dict[str, Stage], recs) -> dict:
    """``results.json``'s ``stages``: each complete stage's folder, record, wall time and whether
    it ran in this call."""
    return {
        name: {
            "dir": r.dir.name,
            "file": f"{r.dir.name}/{STAGE_FILE}",
            "seconds": r.data["seconds"],
            "ran_this_call": r.ran,
        }
        for name in plan
        if (r := recs.get(name)) is not None
    }


def stage_rows(plan: dict[str, Stage], recs) -> list[dict]:
    """The stage table's rows: every stage of the plan, with its record's times where complete
    (``train_seconds``: one seed's training time of a meta-training stage, s, else ``None``)."""
    rows: list[dict] = []
    for name, st in plan.items():
        r = recs.get(name)
        if r is None:
            rows.append({"name": name, "dir": st.dir_name, "status": "not run"})
            continue
        per_seed = r.data["result"].get("seeds") if r.group == "metatrain" else None
        rows.append(
            {
                "name": name,
                "dir": r.dir.name,
                "status": "ran" if r.ran else "complete, skipped",
                "seconds": r.data["seconds"],
                "train_seconds": next(iter(per_seed.values()))["seconds"] if per_seed else None,
            }
        )
    return rows


def _stage_table(rows: list[dict]) -> list[str]:
    """The "Stages" section's lines from :func:`stage_rows`'s rows."""
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
    for r in rows:
        if r["status"] == "not run":
            md.append(f"| {r['name']} | `{r['dir']}` | not run | — | — |")
            continue
        train = f"{r['train_seconds']:.1f}" if r["train_seconds"] is not None else "—"
        md.append(f"| {r['name']} | `{r['dir']}` | {r['status']} | {r['seconds']:.1f} | {train} |")
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


def write_recording(path: Path, text: str, out: Path, figures: list[dict]) -> None:
    """``report.rrd``: ``REPORT.md``'s text and each figure of ``figures`` (``results.json``'s
    entries, files relative to ``out``) with its sentence."""
    import rerun.blueprint as rrb
    from matplotlib.image import imread

    from warp_critic.running.recording import Recorder

    names = [f"figures/{Path(f['file']).stem}" for f in figures]
    views = [rrb.Spatial2DView(origin=n, name=f["title"]) for n, f in zip(names, figures)]
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
        for n, f in zip(names, figures):
            img = imread(out / f["file"])
            if img.dtype != np.uint8:
                img = (np.clip(img, 0, 1) * 255).astype(np.uint8)
            rec.image(n, img[..., :3], static=True)
            rec.text(f"{n}/caption", f["sentence"])
    finally:
        rec.close()
    tmp.replace(path)


__all__ = ["write_report", "render_report", "seeds_trained", "SECTIONS", "STAGES"]
