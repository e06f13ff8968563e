#!/usr/bin/env python
"""One tuning procedure for every reproduced method: ours, DDPG, Meta-Critic and TD3.

A reviewer's first question of a comparison is whether every method had the same chance. This
search gives each method exactly the same one, scene by scene:

* **Candidates** (:func:`candidates`): the method's own setting as ``reproduce`` would train it
  before any adoption (the baselines' published settings, ours' scene preset) and six
  one-at-a-time changes of the same three knobs (:data:`KNOBS`): the critic's learning rate and the
  policy's learning rate, each half a decade down and up (x0.316, x3.16), and the critic's width
  (x0.5, x2). Seven candidates per method. Ours' policy learning rate is its inner step ``alpha``;
  a baseline's is its actor's. Nothing else is searched for anyone (the task fields -- goals,
  starts, horizon, meta-test updates -- are reproduce's, shared by all).
* **Training**: reproduce's training task on seeds :data:`SEEDS` (never the reported 0-4), for the
  same number of environment steps, :data:`TRAIN_STEPS` (counted as reproduce counts them: ours
  ``(inner_steps + 1) x worlds x horizon`` per iteration, a baseline ``worlds x horizon``); each
  method's learning-rate schedule spans its own truncated run.
* **Score** (:func:`score_runs`): the meta-test the tables use, on the run's training goals:
  ``--inits`` fresh policies per goal drawn from goal seed :data:`TUNE_SEED` (it draws nothing
  else: ``warp_critic/evaluation/seed_uses.py``), ``inner_steps`` critic-gradient steps at each
  step size in the run's own meta-test step size x :data:`SCALES`. The score is the lowest over
  the step sizes of the mean final MSE (rad^2, mean over joints, seeds, goals and inits); the
  per-seed MSEs at that step size give the seed spread.
* **Adoption** (:data:`ADOPT_RULE`, :func:`adoption`): the best candidate of a complete search is
  *proposed* when its score is lower than the own setting's by more than half the spread of the
  own setting's per-seed scores. A proposal is *confirmed* at full length: the own setting and the
  proposal train again for the method's whole ``reproduce`` run (its iterations, on the same seeds)
  and the proposal is adopted only if it passes the same rule there. A truncated search favours
  settings that learn fast; without this step a change that helps early can be adopted and hurt at
  full length (an earlier search adopted 2x updates for Meta-Critic that way).

Every scored candidate is a row of ``--out`` (JSON, rewritten after each), so the search resumes:
a rerun keeps the rows already scored (same scene, method, change, steps, seeds, inits) and
continues an interrupted training from its last checkpoint (every quarter of the run), kept in
``--runs``. ``--jobs N`` trains N candidates at once, each in its own process (the same rows: every
candidate is seeded on its own). Prints one line per candidate and, per scene and method, the
candidates sorted by score and what the rule decides (``--markdown FILE`` writes that summary).

Usage::

    nice python bench/tune.py --scenes reacher --out docs/paper/tuning/uniform-reacher.json \
        --runs runs/tune-uniform --jobs 2
    python bench/tune.py --summary-only --scenes reacher --out docs/paper/tuning/uniform-reacher.json \
        --markdown docs/paper/tuning/uniform-reacher.md
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path
from typing import Any

from warp_critic.cli.flags import ToolParser, comma_list, user_message
from warp_critic.core.errors import UserError
from warp_critic.evaluation.seed_uses import TUNE_SEED

PROG = "tune"
#: environment steps every candidate trains for: a quarter of every method's reacher budget
#: (1.28M) and of the baselines' KUKA budget (1.2M rounded up to ours' whole iterations)
TRAIN_STEPS = 320_000
SEEDS = (100, 101)
#: multiples of a run's own meta-test step size the score is the best of
SCALES = (0.1, 0.316, 1.0, 3.16, 10.0)
#: the three knobs every method's candidates change one at a time: the config field per method
#: kind, and the factors applied to the method's own value
KNOBS: dict[str, dict[str, Any]] = {
    "critic learning rate": {"ours": "lr", "baseline": "critic_lr", "factors": (0.316, 3.16)},
    "policy learning rate": {"ours": "alpha", "baseline": "actor_lr", "factors": (0.316, 3.16)},
    "critic width": {"ours": "critic_hidden", "baseline": "critic_hidden", "factors": (0.5, 2.0)},
}
ADOPT_RULE = (
    "the best candidate replaces the method's own setting when its score is lower by more than "
    "half the spread of the own setting's per-seed scores, both after the truncated search and "
    "again at the method's full training length; the same rule for every method"
)
#: a row's training length: the search's truncation or the method's whole reproduce run
TRUNCATED, FULL = "truncated", "full"
#: the most iterations between two checkpoints of a candidate's runs
CHECKPOINT_EVERY = 100


# ------------------------------------------------------------------------------------------------
# the candidates (pure but for reading the scene's defaults)
# ------------------------------------------------------------------------------------------------


def own_setting(scene: str, method: str) -> dict[str, Any]:
    """The method's training values as ``reproduce`` sets them, without any earlier adoption
    (``settings.TUNED``): its published setting (a baseline) or its scene preset (ours)."""
    from warp_critic.evaluation.presets import preset
    from warp_critic.reproduce.experiments.settings import OURS_PRESETS, TUNED, default_settings

    values = dict(default_settings(False, 1, extra=_extra(method))["metatrain"][scene][method])
    published = preset(OURS_PRESETS[scene] if method == "ours" else method)
    for key in TUNED.get(scene, {}).get(method, {}):
        if key in published:
            values[key] = published[key]
        else:
            values.pop(key, None)
    return values


def _extra(method: str) -> tuple[str, ...]:
    from warp_critic.reproduce.experiments.settings import METHODS

    return () if method in METHODS else (method,)


def knob_values(scene: str, method: str) -> dict[str, float]:
    """The method's own value of each knob's field (a scene default filled in where unset)."""
    from warp_critic.methods import method as method_of
    from warp_critic.physics.load import load_scene
    from warp_critic.reproduce.experiments.metatrain import scene_file

    kind = "baseline" if method_of(method).baseline else "ours"
    values = own_setting(scene, method)
    defaults = load_scene(scene_file(scene)).defaults
    config = method_of(method).config
    out = {}
    for knob in KNOBS.values():
        name = knob[kind]
        v = values.get(name)
        if v is None:
            v = defaults.get(name)
        if v is None:
            v = config.__dataclass_fields__[name].default
        out[name] = v
    return out


def candidates(scene: str, method: str) -> list[dict[str, float]]:
    """The changes to :func:`own_setting` tried: ``{}`` (the own setting) first, then one
    ``{field: value}`` per knob and factor (:data:`KNOBS`): seven for every method."""
    out: list[dict[str, float]] = [{}]
    for name, v in knob_values(scene, method).items():
        factors = next(k["factors"] for k in KNOBS.values() if name in (k["ours"], k["baseline"]))
        for f in factors:
            new = v * f
            out.append({name: int(round(new)) if isinstance(v, int) else float(f"{new:.3g}")})
    return out


def iterations_for(scene: str, method: str, values: dict, steps: int) -> int:
    """Iterations of ``method`` that take ``steps`` environment steps (rounded up)."""
    from warp_critic.methods import method as method_of
    from warp_critic.physics.load import load_scene
    from warp_critic.reproduce.experiments.metatrain import make_config, scene_file
    from warp_critic.running.config import filled

    cfg = make_config(scene, method, values, list(SEEDS), Path("unused"), "cpu", False)
    cfg = cfg.fill_defaults(load_scene(scene_file(scene)))
    worlds = len(filled(cfg.goals, "goals")) * cfg.worlds_per_goal
    per = method_of(method).samples_per_iteration(cfg) * worlds * filled(cfg.horizon, "horizon")
    return math.ceil(steps / per)


# ------------------------------------------------------------------------------------------------
# training and scoring
# ------------------------------------------------------------------------------------------------


def train(
    scene: str, method: str, change: dict, args, run: Path, length: str = TRUNCATED
) -> tuple[list[str], float]:
    """Trains one candidate on every seed (resuming from its checkpoints) for the search's
    environment steps or (``length`` :data:`FULL`) the method's reproduce iterations; returns its
    seeds' run dirs and the seconds its training took: over every call that trained it (the
    seeds train batched, each iteration's ``seconds`` the batch's), not only this one."""
    from warp_critic.methods import method as method_of
    from warp_critic.reproduce.experiments.metatrain import clear_unstarted, make_config

    values = {**own_setting(scene, method), **change}
    iterations = iterations_for(scene, method, values, args.train_steps)
    if length == FULL:
        iterations = 2 * iterations if args.tiny else int(values["iterations"])
    every = max(1, iterations // 4)
    # a checkpoint at least every CHECKPOINT_EVERY iterations: a call killed mid-candidate (the end
    # of a sitting) loses at most that much of it; how often a run checkpoints changes no number
    checkpoint = min(every, CHECKPOINT_EVERY)
    values.update(iterations=iterations, checkpoint_every=checkpoint, record_every=every)
    if args.tiny:  # plumbing only (tests)
        values.update(
            worlds_per_goal=1, horizon=5, critic_hidden=min(values.get("critic_hidden") or 400, 16)
        )
    # a run stopped before its first checkpoint starts again; one with checkpoints resumes
    resume = clear_unstarted(run, list(args.seeds))
    cfg = make_config(scene, method, values, list(args.seeds), run, args.device, resume)
    t0 = time.perf_counter()
    result = method_of(method).train(cfg, progress=False, record=False)
    over_calls = max(sum(float(x.get("seconds", 0.0)) for x in r.metrics) for r in result.seeds)
    return [str(r.run_dir) for r in result.seeds], max(time.perf_counter() - t0, over_calls)


def score_runs(run_dirs: list[str], inits: int, device: str) -> dict[str, Any]:
    """The candidate's score (module docstring): the meta-test budget sweep
    (:func:`~warp_critic.reproduce.experiments.budget.sweep`) at the run's own number of policy
    updates only, then :func:`pick`: ``{"score", "per_seed", "scale", "by_scale"}``."""
    from warp_critic.reproduce.experiments.budget import sweep
    from warp_critic.reproduce.experiments.evaluate import default_steps

    steps = default_steps(run_dirs[0])
    r = sweep(
        run_dirs,
        budgets=[steps],
        scales=list(SCALES),
        inits=inits,
        seed=TUNE_SEED,
        device=device,
        max_worlds=4096,
    )
    return pick({f"{s:g}": r["per_seed"][s][steps] for s in SCALES})


def pick(by_scale: dict[str, list[float]]) -> dict[str, Any]:
    """The step size with the lowest mean per-seed MSE (ties: the smaller; a diverged seed makes
    its step size ``inf``); ``score`` is that mean, ``per_seed`` its seeds' MSEs."""
    means = {
        s: (sum(v) / len(v) if all(map(math.isfinite, v)) else math.inf)
        for s, v in by_scale.items()
    }
    scale = min(means, key=lambda s: (means[s], float(s)))
    return {
        "score": means[scale],
        "per_seed": by_scale[scale],
        "scale": float(scale),
        "by_scale": by_scale,
    }


def adopted(best: dict, own: dict) -> bool:
    """Whether ``best`` beats the method's own setting ``own`` by more than the seed noise
    (:data:`ADOPT_RULE`)."""
    if best["change"] == own["change"] or not math.isfinite(best["score"]):
        return False
    spread = max(own["per_seed"]) - min(own["per_seed"])
    return own["score"] - best["score"] > spread / 2


def adoption(rows: list[dict], scene: str, method: str) -> dict | None:
    """What a scene and method's rows decide, or ``None`` before its own setting is scored:
    ``{"best", "own", "complete", "proposed", "confirm", "adopt"}``. ``complete``: every candidate
    of the truncated search is scored (only a complete search proposes); ``proposed``: the best
    passes :func:`adopted`; ``confirm``: ``None`` while the full-length runs of the own setting and
    the proposal are not both scored, else whether the proposal passes there too; ``adopt``: the
    change adopted (``{}``: the own setting)."""
    mine = [r for r in rows if (r["scene"], r["method"]) == (scene, method)]
    search = sorted((r for r in mine if r.get("length", TRUNCATED) == TRUNCATED), key=_score)
    own = next((r for r in search if r["change"] == {}), None)
    if own is None:
        return None
    complete = all(any(r["change"] == c for r in search) for c in candidates(scene, method))
    proposed = complete and adopted(search[0], own)
    confirm = None
    if proposed:
        full = {json.dumps(r["change"]): r for r in mine if r.get("length") == FULL}
        pair = full.get("{}"), full.get(json.dumps(search[0]["change"]))
        if pair[0] is not None and pair[1] is not None:
            confirm = adopted(pair[1], pair[0])
    return {
        "best": search[0],
        "own": own,
        "complete": complete,
        "proposed": proposed,
        "confirm": confirm,
        "adopt": search[0]["change"] if confirm else {},
    }


def _score(row: dict) -> float:
    return row["score"]


# ------------------------------------------------------------------------------------------------
# the command
# ------------------------------------------------------------------------------------------------


def main(argv=None) -> int:
    from warp_critic.reproduce.experiments.settings import ALL_METHODS

    p = ToolParser(prog=PROG, description=__doc__.split("\n\n")[0])
    p.add_argument("--scenes", type=comma_list(str), default=["reacher", "kuka"])
    p.add_argument(
        "--methods", type=comma_list(str), default=["ours", "ddpg", "meta-critic", "td3"]
    )
    p.add_argument(
        "--train-steps", type=int, default=TRAIN_STEPS, help="environment steps per candidate"
    )
    p.add_argument("--seeds", type=comma_list(int), default=list(SEEDS))
    p.add_argument(
        "--inits", type=int, default=5, help="fresh policies per training goal in the score"
    )
    p.add_argument("--device", default="cpu")
    p.add_argument(
        "--jobs",
        type=int,
        default=1,
        help="candidates trained at once, each in its own process (one core each on the CPU)",
    )
    p.add_argument("--markdown", help="also write the summary (markdown tables) to this file")
    p.add_argument(
        "--candidate",
        help='train and score only this candidate, \'[change, "truncated"|"full"]\' as JSON, of '
        "the one --scenes and --methods, and write its row to --row-out (how --jobs runs one)",
    )
    p.add_argument("--row-out", help="with --candidate: where its row (JSON) goes")
    p.add_argument(
        "--summary-only", action="store_true", help="train nothing: summarise the rows in --out"
    )
    p.add_argument("--out", default="runs/tune-uniform/tune.json")
    p.add_argument(
        "--runs", default="runs/tune-uniform", help="where the candidates' runs (checkpoints) go"
    )
    p.add_argument(
        "--tiny", action="store_true", help="plumbing only: tiny rollouts and networks (tests)"
    )
    args = p.parse_args(argv)
    for s in args.scenes:
        if s not in ("reacher", "kuka"):
            p.error(f"--scenes: unknown scene {s!r} (reacher, kuka)")
    for m in args.methods:
        if m not in ALL_METHODS:
            p.error(f"--methods: unknown method {m!r} ({', '.join(ALL_METHODS)})")
    if args.train_steps < 1 or args.inits < 1 or args.jobs < 1 or not args.seeds:
        p.error("--train-steps, --inits and --jobs at least 1, and at least one seed")
    if any(s < 5 for s in args.seeds):
        p.error("--seeds: use seeds other than the reported 0-4")
    if args.markdown and not _summary_file(Path(args.markdown)):
        p.error(
            f"--markdown {args.markdown}: must be a .md file that is new or a summary this tool "
            "wrote (it starts with '### '); not overwriting it"
        )
    if args.candidate is not None:
        return _one(p, args)
    out = Path(args.out)
    try:
        rows = _done_rows(out, args)
        if not args.summary_only:
            _search(rows, args, out)
    except UserError as e:  # a user mistake (bad path, ...) as one line
        p.exit(2, f"{PROG}: error: {user_message(e)}\n")
    text = "\n".join(summary_markdown(rows, args.scenes, args.methods))
    print(f"\n{text}\nRule: {ADOPT_RULE}.")
    if args.markdown:
        Path(args.markdown).write_text(text + "\n")
    return 0


def pending(rows: list[dict], scenes: list[str], methods: list[str]) -> list[tuple]:
    """The candidates that can train now, in order, as ``(scene, method, change, length)``: every
    unscored candidate of each search, and for a method whose complete search proposes a change,
    the unscored full-length runs of its own setting and of the proposal."""
    done = {
        (r["scene"], r["method"], json.dumps(r["change"]), r.get("length", TRUNCATED)) for r in rows
    }
    out = []
    for scene in scenes:
        for method in methods:
            wanted = [(c, TRUNCATED) for c in candidates(scene, method)]
            a = adoption(rows, scene, method)
            if a is not None and a["proposed"]:  # confirm at full length (module docstring)
                wanted += [({}, FULL), (a["best"]["change"], FULL)]
            out += [
                (scene, method, c, length)
                for c, length in wanted
                if (scene, method, json.dumps(c), length) not in done
            ]
    return out


def _task(scene: str, method: str, change: dict, length: str, args) -> dict:
    """Trains and scores one candidate (in a worker process with ``--jobs`` > 1): its row."""
    tail = "" if length == TRUNCATED else "-full"
    run = Path(args.runs) / f"{scene}-{method}-{_slug(change)}{tail}"
    dirs, seconds = train(scene, method, change, args, run, length)
    row = {"scene": scene, "method": method, "change": change, "length": length}
    row.update(seconds=seconds, **score_runs(dirs, args.inits, args.device))
    return row


def _search(rows: list[dict], args, out: Path) -> None:
    """Trains every :func:`pending` candidate, ``--jobs`` at once, until none is left (a
    confirmation becomes pending when its search completes); each row is written to ``out`` as it
    comes. With ``--jobs`` > 1 each candidate is this script in a child process (:func:`_child`)."""
    import concurrent.futures as cf

    if args.jobs == 1:
        while todo := pending(rows, args.scenes, args.methods):
            _done(rows, _task(*todo[0], args), args, out)
        return
    with cf.ThreadPoolExecutor(args.jobs) as pool:  # threads that only wait on their child
        running: dict = {}
        while True:
            busy = set(running.values())
            for task in pending(rows, args.scenes, args.methods):
                key = json.dumps(task)
                if len(running) < args.jobs and key not in busy:
                    running[pool.submit(_child, task, args)] = key
                    busy.add(key)
            if not running:
                return
            finished, _ = cf.wait(running, return_when=cf.FIRST_COMPLETED)
            for f in finished:
                running.pop(f)
                _done(rows, f.result(), args, out)


def _summary_file(path: Path) -> bool:
    """Whether ``--markdown`` may write ``path``: a ``.md`` in a folder that is there, new or holding
    a summary of this tool (checked before any candidate trains)."""
    if path.suffix != ".md" or not path.parent.is_dir() or path.is_dir():
        return False
    if not path.exists():
        return True
    try:
        with path.open("rb") as f:
            return f.read(4) == b"### "
    except OSError:
        return False


def _one(p, args) -> int:
    """``--candidate``: one candidate's row into ``--row-out``."""
    try:
        change, length = json.loads(args.candidate)
        assert isinstance(change, dict) and length in (TRUNCATED, FULL)
        assert len(args.scenes) == 1 and len(args.methods) == 1 and args.row_out
    except (ValueError, TypeError, AssertionError):
        p.error(
            '--candidate: \'[change, "truncated"|"full"]\' for one --scenes and --methods, with --row-out'
        )
    try:
        row = _task(args.scenes[0], args.methods[0], change, length, args)
    except UserError as e:
        p.exit(2, f"{PROG}: error: {user_message(e)}\n")
    Path(args.row_out).write_text(json.dumps(row) + "\n")
    return 0


def _child(task: tuple, args) -> dict:
    """Runs :func:`_task` for ``task`` as ``python bench/tune.py --candidate ...`` and returns its
    row; a failed child raises :class:`UserError` with its last line of output."""
    import subprocess
    import tempfile

    scene, method, change, length = task
    with tempfile.TemporaryDirectory() as tmp:
        row_file = Path(tmp) / "row.json"
        cmd = [sys.executable, str(Path(__file__).resolve()), "--scenes", scene, "--methods", method,
               "--train-steps", str(args.train_steps), "--seeds", ",".join(map(str, args.seeds)),
               "--inits", str(args.inits), "--device", args.device, "--runs", str(args.runs),
               "--candidate", json.dumps([change, length]), "--row-out", str(row_file),
               *(["--tiny"] if args.tiny else [])]  # fmt: skip
        done = subprocess.run(cmd, capture_output=True, text=True)
        if done.returncode != 0:
            lines = (done.stderr or done.stdout).strip().splitlines() or ["no output"]
            raise UserError(
                f"candidate {scene} {method} {change or 'own setting'} ({length}): {lines[-1]}"
            )
        return json.loads(row_file.read_text())


def _done(rows: list[dict], row: dict, args, out: Path) -> None:
    rows.append(row)
    _write(out, args, rows)
    print(
        f"{row['scene']} {row['method']} {row['change'] or 'own setting'} ({row['length']}): "
        f"score {row['score']:.4g} (per seed {', '.join(f'{x:.4g}' for x in row['per_seed'])}, "
        f"x{row['scale']:g} step; {row['seconds']:.0f} s)",
        flush=True,
    )


def summary_markdown(rows: list[dict], scenes: list[str], methods: list[str]) -> list[str]:
    """Per scene and method: every scored candidate (score, per-seed scores, the step-size scale
    the score is at, training seconds) and what the rule decides, as markdown lines."""
    out = []
    for scene in scenes:
        for method in methods:
            a = adoption(rows, scene, method)
            if a is None:
                continue
            out += [
                f"### {scene}, {method}",
                "",
                "| candidate | training | score (MSE, rad^2) | per seed | step size | seconds |",
                "|---|---|---|---|---|---|",
            ]
            mine = [r for r in rows if (r["scene"], r["method"]) == (scene, method)]
            for r in sorted(
                mine, key=lambda r: (r.get("length", TRUNCATED) != TRUNCATED, _score(r))
            ):
                change = ", ".join(f"{k} {v:g}" for k, v in r["change"].items()) or "own setting"
                seeds = ", ".join(f"{x:.4g}" for x in r["per_seed"])
                out.append(
                    f"| {change} | {r.get('length', TRUNCATED)} | {r['score']:.4g} | {seeds} | "
                    f"x{r['scale']:g} | {r['seconds']:.0f} |"
                )
            out += ["", _verdict(a), ""]
    return out


def _verdict(a: dict) -> str:
    best = ", ".join(f"{k} {v:g}" for k, v in a["best"]["change"].items())
    if not a["complete"]:
        return "Search incomplete: nothing proposed yet."
    if not a["proposed"]:
        return "The own setting is kept: no candidate passes the rule."
    if a["confirm"] is None:
        return f"Proposed: {best}; its full-length confirmation is pending."
    if a["confirm"]:
        return f"Adopted: {best} (it passes the rule at full length too)."
    return f"Not adopted: {best} passes the rule truncated, not at full length; the own setting is kept."


def _slug(change: dict) -> str:
    return "own" if not change else "-".join(f"{k}{v:g}" for k, v in change.items())


def _done_rows(out: Path, args) -> list[dict]:
    """The candidates an earlier call scored into ``out`` with the same procedure (none when it
    does not exist yet); another procedure's file is refused."""
    if not out.is_file():
        return []
    try:
        data = json.loads(out.read_text())
        rows, procedure = data["rows"], data["procedure"]
        for r in rows:
            r["scene"], r["method"], r["change"], r["score"]
    except (ValueError, KeyError, TypeError):
        raise UserError(f"{out}: not a {PROG} result file; choose another --out") from None
    if procedure != _procedure(args):
        raise UserError(f"{out}: scored with another procedure ({procedure}); choose another --out")
    return rows


def _procedure(args) -> dict:
    return {
        "train_steps": args.train_steps,
        "seeds": list(args.seeds),
        "inits": args.inits,
        "score_seed": TUNE_SEED,
        "scales": list(SCALES),
        "tiny": bool(args.tiny),
    }


def _write(out: Path, args, rows: list[dict]) -> None:
    from warp_critic.running.files import atomic_write_text

    out.parent.mkdir(parents=True, exist_ok=True)
    data = {"procedure": _procedure(args), "rule": ADOPT_RULE, "rows": rows}
    atomic_write_text(out, json.dumps(data, indent=1) + "\n")  # never a half-written file


if __name__ == "__main__":
    sys.exit(main())
