"""``reproduce --status``: where an output folder stands for one reproduce command, read from its
stage folders without running anything, taking no lock and writing nothing.

A paper-setting reproduction runs over many sittings (every stage resumes where it stopped). Before
the next sitting one asks what is done, what is part way and how long the part-way meta-trainings
have left; this answers beside a running call too. Each stage of the command's plan is

* **complete**: its record is there (its time, the record's);
* **part way**: its folder is there without a record: a meta-training's iteration (its first seed's
  ``metrics.jsonl``; the seeds of a stage train as one batch) of the run's iterations, and the time
  left at its mean seconds per iteration over the last :data:`RECENT` iterations; a meta-test stage's
  batches kept in its ``progress/`` folder;
* **not started**, with the stage time the same stage took in a reference run where its archive
  holds it (by default the published run, ``docs/paper/stages`` of this checkout: the same stage
  directory, so the same settings), and the sum of those times: what a sitting plan can go by,
  measured on that run's machine (``docs/paper/README.md`` names it). A held-out tables or maps
  stage at a method's chosen meta-test budget, which no earlier run holds, is estimated from this
  folder (:func:`budget_estimate`): the hours of a plan with ``--beyond`` are mostly there.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

from warp_critic.reproduce import reference_times as rt
from warp_critic.reproduce.engine.stage import PROGRESS, dir_name

__all__ = [
    "RECENT",
    "StageState",
    "budget_estimate",
    "estimator",
    "pace",
    "published_archive",
    "render",
    "stage_states",
    "status",
]

#: the iterations a part-way meta-training's speed is read from
RECENT = 50


@dataclass(frozen=True)
class StageState:
    """One stage of a plan in an output folder."""

    name: str
    directory: str
    state: str  # "complete", "part way" or "not started"
    detail: str  # what is done, in words
    seconds_left: float | None = None  # a part-way meta-training's estimate
    reference_seconds: float | None = None  # a not-started stage's time in the reference run
    estimate_seconds: float | None = None  # a not-started stage's time estimated from this folder


def _last_rows(path: Path, n: int) -> list[dict]:
    """The last ``n`` readable rows of a JSON-lines file (a torn last line skipped)."""
    rows = []
    for line in path.read_text(encoding="utf-8", errors="replace").splitlines()[-(n + 1) :]:
        try:
            row = json.loads(line)
        except ValueError:
            continue
        if isinstance(row, dict):
            rows.append(row)
    return rows[-n:]


def _training(d: Path) -> tuple[str, float | None] | None:
    """A part-way meta-training's progress (words, seconds left), or ``None`` when ``d`` holds no
    run with metrics."""
    got = _iterations_done(d)
    if got is None:
        return None
    done, total, rows = got
    if not rows:
        return "started, no iteration finished", None
    times = [float(r["seconds"]) for r in rows if isinstance(r.get("seconds"), (int, float))]
    if not times:
        return f"iteration {done} of {total}", None
    per = sum(times) / len(times)
    left = max(total - done, 0) * per
    return f"iteration {done} of {total}, {per:.2f} s per iteration", left


def _iterations_done(d: Path) -> tuple[int, int, list[dict]] | None:
    """``(iterations done, of, the last RECENT metrics rows)`` of the part-way meta-training ``d``
    (its first seed's; the seeds train as one batch), ``None`` when it holds no run with metrics."""
    seeds = sorted(d.glob("run/seed*/metrics.jsonl"))
    if not seeds:
        return None
    metrics = seeds[0]
    try:
        rows = [r for r in _last_rows(metrics, RECENT) if "iteration" in r]
        total = int(json.loads((metrics.parent / "config.json").read_text())["iterations"])
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return (int(rows[-1]["iteration"]) + 1 if rows else 0), total, rows


def _identify_left(d: Path) -> float:
    """The share of a part-way meta-training's seeds (``d/run/seed*``) whose model identifier
    (``seedN-identified``, :func:`~warp_critic.reproduce.experiments.metatrain.identify_seed`) is
    not complete yet."""
    from warp_critic.methods.identify import identified

    seeds = [p for p in d.glob("run/seed*") if p.is_dir() and p.name[4:].isdigit()]
    done = [p for p in seeds if identified(p.with_name(f"{p.name}-identified")) is not None]
    return 1.0 - len(done) / len(seeds) if seeds else 1.0


def budget_estimate(out: Path, st, stages: dict) -> tuple[float, str] | None:
    """``(seconds, how reckoned)`` of the held-out tables or maps stage ``st`` at a method's chosen
    meta-test budget, from ``out``: the time per row of a held-out stage of the same settings (goal
    seed) at the default budget, complete in ``out``, times the rows ``st`` runs (a shared row
    not counted) and ``(N + 2) / (N0 + 2)`` rollouts per world (``N`` updates, the untrained and
    the final rollout; ``N0`` the default's). Measured on the 2-core CPU machine (2026-12-07) this
    is within about 15% of a stage's per-update cost. ``None``: not such a stage, or the default
    stage or a choice it reads is not complete."""
    from warp_critic.core.errors import UserError
    from warp_critic.reproduce.engine.stages import read_stage
    from warp_critic.reproduce.experiments.budget import reporting_kwargs

    o = st.outputs
    if o is None or o.budget_of is None or st.kind not in ("tables", "maps"):
        return None
    # the same evaluation at the default budget: the held-out stage of the seed, or another
    # method's (TD3's, ours' at equal steps) with the same settings
    same = [
        b for b in stages.values()
        if b.kind == st.kind and b.settings == st.settings
        and (b.outputs is None or b.outputs.budget_of is None)
    ]  # fmt: skip
    found = ((b, read_stage(out / b.dir_name)) for b in same)
    base, data = next(((b, x) for b, x in found if x is not None), (None, None))
    if base is None or data is None:
        return None
    r = data["result"]
    rows = {c["method"] for c in r["cells"]} if "cells" in r else set(r.get("goals", {}))
    try:
        kw = reporting_kwargs(st, out)
    except UserError:  # a choice it reads is not complete
        return None
    n, n0, k = int(kw["steps"]), int(r["policy_updates"]), len(kw["only"])
    per_row = rt.took(data, base.kind) / max(len(rows), 1)
    how = (
        f"estimated from {base.name}: {per_row / 60:.1f} min per row x {k} row(s) x "
        f"({n} + 2) / ({n0} + 2) rollouts"
    )
    return per_row * k * (n + 2) / (n0 + 2), how


def _state(out: Path, st, check, reference: Path | None, stages: dict) -> StageState:
    from warp_critic.reproduce.engine.stages import read_complete

    name, kind = st.name, st.kind
    d = out / dir_name(name, st.hash)
    data = read_complete(d, kind, check)
    if data is not None:
        return StageState(name, d.name, "complete", f"{rt.took(data, kind) / 60:.1f} min")
    if not d.is_dir():
        ref, detail = rt.total(rt.recorded(reference, d.name, kind)), "the reference run"
        if ref is None and kind == "metatrain":
            ref, detail = (
                rt.total(rt.reference_by_name(reference, name, st)),
                "the reference run, other step sizes or length",
            )
        if ref is None and (guess := budget_estimate(out, st, stages)) is not None:
            return StageState(
                name, d.name, "not started", f"{guess[1]}: {guess[0] / 60:.0f} min",
                estimate_seconds=guess[0],
            )  # fmt: skip
        detail = f"{detail}: {ref / 60:.1f} min" if ref is not None else ""
        return StageState(name, d.name, "not started", detail, reference_seconds=ref)
    trained = _training(d) if kind == "metatrain" else None
    if trained is not None:
        return StageState(name, d.name, "part way", trained[0], trained[1])
    kept = sorted((d / PROGRESS).glob("batch-*.pt"))
    done = [p for p in kept if not p.stem.endswith("-partial")]
    if kept:
        partial = len(kept) - len(done)
        return StageState(
            name, d.name, "part way", f"{len(done)} meta-test batch(es) done, {partial} part way"
        )
    return StageState(name, d.name, "part way", "started (resumes from its start)")


def pace(out: Path, stages: dict, reference: Path | None) -> float:
    """How much longer this machine takes than the reference run: the median, over the
    meta-trainings complete in ``out`` that the ``reference`` archive also holds, of their time
    over the reference's; 1 where there is none."""
    from warp_critic.reproduce.engine.stages import read_stage, record_problem

    ratios = []
    for n, st in stages.items():
        if st.kind != "metatrain":
            continue
        d = dir_name(n, st.hash)
        data = read_stage(Path(out) / d)
        ref = rt.total(rt.recorded(reference, d, st.kind))
        if data is not None and not record_problem(data) and ref:
            ratios.append(rt.took(data, st.kind) / ref)
    ratios.sort()
    if not ratios:
        return 1.0
    mid = len(ratios) // 2
    return ratios[mid] if len(ratios) % 2 else 0.5 * (ratios[mid - 1] + ratios[mid])


def estimator(out: Path, stages: dict, reference: Path | None):
    """``name -> (expected seconds, how reckoned) | None`` for ``reproduce --hours``
    (:class:`~warp_critic.reproduce.engine.timelimit.TimeLimit`): a meta-training by its time in
    the ``reference`` archive times this folder's :func:`pace`, part way in ``out`` the share of
    its iterations left of that; one that archive lacks, part way, by its iterations left at its
    recent speed. ``None`` (no estimate: started while time is left) for every other stage, which
    keeps its finished batches; seconds ``nan`` for a meta-training not started without a
    reference time."""
    factor = pace(out, stages, reference)

    def estimate(name: str) -> tuple[float, str] | None:
        st = stages[name]
        if st.kind != "metatrain":
            return None
        d = Path(out) / dir_name(name, st.hash)
        trained = _training(d) if d.is_dir() else None
        parts = rt.recorded(reference, d.name, st.kind)
        how = "in the reference run"
        if parts is None:
            parts = rt.reference_by_name(reference, name, st)
            how = "in the reference run with other step sizes or length, per iteration"
        ref = rt.total(parts)
        whole = f"{ref / 60:.0f} min {how}, x {factor:.2f}: this folder's pace" if ref else ""
        got = _iterations_done(d) if trained is not None else None
        if parts is not None and trained is not None and got is not None and got[1] > 0:
            # part way: the same reckoning for what is left. Its own last iterations' speed says
            # more about the load it ran under than about the next call's (a stage slowed by other
            # work beside it would otherwise never fit a sitting again)
            left = max(got[1] - got[0], 0) / got[1] * parts[0]
            if parts[1]:  # a recipe that identifies the model: its identifiers not complete
                left += _identify_left(d) * parts[1]
            share = f"{left / ref:.0%}" if ref else "all"
            return left * factor, f"part way: {trained[0]}; {whole}, {share} left"
        if trained is not None and trained[1] is not None:
            return trained[1], f"part way: {trained[0]}"
        if ref is None:
            return math.nan, "no estimate: no reference run with the same work per iteration"
        return ref * factor, whole

    return estimate


def stage_states(rc, reference: Path | None = None) -> list[StageState]:
    """Each stage the reproduce command ``rc`` (a validated
    :class:`~warp_critic.reproduce.experiments.plan.ReproduceConfig`) would run, in its order, as
    its output folder holds it; a not-started stage with its time in the ``reference`` archive (a
    folder of stage directories, e.g. ``docs/paper/stages``) where that holds it."""
    from warp_critic.reproduce.experiments.plan import needed, plan
    from warp_critic.reproduce.experiments.records import stage_problem

    settings = rc.validate()
    stages = plan(settings, rc.plans_beyond, rc.extra, rc.plans_budget)
    names = [n for wave in needed(rc, stages) for n in wave]
    out = Path(rc.out)
    return [_state(out, stages[n], stage_problem, reference, stages) for n in names]


def published_archive() -> Path | None:
    """``docs/paper/stages`` of the checkout this package runs from (``None`` for an installed
    package without it)."""
    archive = Path(__file__).resolve().parents[2] / "docs" / "paper" / "stages"
    return archive if archive.is_dir() else None


def render(states: list[StageState], out: Path, running: str | None) -> str:
    """The status lines: a summary, then one line per stage."""
    count = {s: sum(x.state == s for x in states) for s in ("complete", "part way", "not started")}
    left = sum(x.seconds_left or 0.0 for x in states)
    timed = [x.reference_seconds for x in states if x.reference_seconds is not None]
    guessed = [x.estimate_seconds for x in states if x.estimate_seconds is not None]
    lines = [
        f"reproduce: {out}: {count['complete']} of {len(states)} stages complete, "
        f"{count['part way']} part way, {count['not started']} not started"
        + (f"; the part-way meta-trainings need about {left / 3600:.1f} h more" if left else "")
        + (
            f"; {len(timed)} of the not-started stages took {sum(timed) / 3600:.1f} h of stage "
            "time in the reference run"
            if timed
            else ""
        )
        + (
            f"; {len(guessed)} at a chosen meta-test budget need about "
            f"{sum(guessed) / 3600:.1f} h, estimated from this folder's stages"
            if guessed
            else ""
        ),
        running or "no reproduce call is running on this folder now",
    ]
    for x in states:
        eta = f"; about {x.seconds_left / 3600:.1f} h left" if x.seconds_left else ""
        detail = f" ({x.detail}{eta})" if x.detail else ""
        lines.append(f"  {x.state:<11}  {x.directory}{detail}")
    return "\n".join(lines)


def status(rc, reference: Path | None = None) -> str:
    """:func:`render` of :func:`stage_states` for ``rc``'s output folder (with the not-started
    stages' times in the ``reference`` archive), naming a call that holds it now. Raises a one-line
    ``UserError`` for a folder that is not a reproduce output."""
    from warp_critic.core.errors import UserError
    from warp_critic.reproduce.engine.stages import MARKER
    from warp_critic.running.locks import holder

    out = Path(rc.out)
    if out.exists() and not (out / MARKER).is_file():
        raise UserError(f"--out {out}: not a reproduce output (no {MARKER})")
    who = holder(out) if out.is_dir() else None
    running = None
    if who is not None:
        running = (
            f"a reproduce call is running on this folder now (process {who.get('pid', '?')} on "
            f"{who.get('host', '?')})"
        )
    return render(stage_states(rc, reference), out, running)
