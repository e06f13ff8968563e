"""Train an :class:`~warp_critic.learning.identify.Identifier` for a run whose critic was told the
model (``--critic-input pose-dynamics`` / ``relative-dynamics``), and write the run with it.

Every iteration draws a new model for every world from the run's own ``train_variants`` (seeded by
``(seed, iteration)``, apart from training's draws), rolls fresh policies out from home towards goals
sampled around the training goals, and updates them with the told critic as meta-test does (the
teacher: the true model told). Each of those rollouts -- the ones a meta-test's critic evaluates --
is a regression sample: the identifier's estimate from the rollout's observed states and torques
against the world's true descriptor (mean squared error). A world that diverges is treated as the
run's meta-train treated one (its ``on_divergence``): ``stop`` (the default) stops with a
:class:`~warp_critic.core.errors.DivergenceError` naming the iteration, world and drawn model, before
anything is written; ``drop`` leaves the world out, and stops only when every world of an
iteration diverged. The run
written to ``out`` is the input run with the identifier in its checkpoint: ``meta-test``, the maps
and the tables then use the :class:`~warp_critic.learning.identify.IdentifiedCritic`, which never
reads the model.
"""

from __future__ import annotations

import json
import shutil
import time
from collections.abc import Callable
from pathlib import Path

import torch

from warp_critic.core.errors import DivergenceError, UserError

#: separates the identifier's model draws from training's (``variant_draws.draw``'s seed)
DRAW_SEED_OFFSET = 7_919
IDENTIFY_FILE = "identify.jsonl"
#: the summary :func:`train_identifier` returns, written last: an identified run is complete with it
SUMMARY_FILE = "identify.json"
#: :func:`train_identifier`'s settings, as ``reproduce`` recipes name them (``identify``)
SETTINGS = ("iterations", "goals", "inits", "lr", "hidden", "version", "variants")


def train_identifier(
    run_dir: str,
    out: str,
    *,
    iterations: int = 1000,
    goals: int = 8,
    inits: int = 16,
    lr: float = 1e-3,
    hidden: int = 128,
    version: int = 2,
    variants: str | None = None,
    seed: int = 0,
    device: str = "cpu",
    progress: Callable[[int, float], None] | None = None,
    resume_file: str | Path | None = None,
    checkpoint_every: int = 100,
) -> dict:
    """Train on ``goals x inits`` worlds per iteration; write ``out`` (a new folder) and return
    ``{"loss": the last training loss, "held_out": the mean |d_hat - d| over the descriptor entries
    the draws vary, on a draw never trained on, "varied": how many entries they vary, "seconds":
    the wall time, "iterations": iterations, "version": version}``, also written to
    ``out/identify.json`` (last). ``variants``: draw the models from these ranges
    (``--train-variants`` text) instead of the run's own ``train_variants``, the held-out draw
    too (and then ``"variants"`` is in the summary); ``None`` or ``""``: the run's own.

    ``resume_file`` (outside ``out``): every ``checkpoint_every`` iterations the regression's state
    (identifier, Adam, generator, losses) is saved there, and a call that finds it for the same
    run and settings continues from it, to exactly the identifier an uninterrupted call trains;
    it is removed once ``out`` is complete."""
    from warp_critic.learning.identify import Identifier, trajectory_inputs
    from warp_critic.running.files import atomic_torch_save, atomic_write_text

    t0 = time.perf_counter()
    dst = Path(out)
    if dst.exists() and (not dst.is_dir() or any(dst.iterdir())):
        raise UserError(f"--out {out}: exists and is not an empty folder")
    m, ranges, variants = _told_run(run_dir, goals, inits, seed, device, variants)
    dev = m.sim.torch_device
    with torch.random.fork_rng(devices=[]):  # the initial weights from the seed, so that two runs
        torch.manual_seed(seed)  # with one --seed agree (torch's global RNG is left as it was)
        ident = Identifier(m.scene.dof, m.sim.dynamics_size, hidden, version).to(dev)
    opt = torch.optim.Adam(ident.parameters(), lr=lr)
    gen = torch.Generator().manual_seed(seed)
    samples = _sampler(m, ranges, seed, gen)

    def loss_of(trajs, settled) -> torch.Tensor:
        errs = [((ident.of_trajectory(t) - t.dynamics) ** 2).mean(-1) for t in trajs]
        return torch.stack(errs).mean(0)[settled].mean()

    rows: list[dict] = []
    key = [str(Path(run_dir).resolve()), iterations, goals, inits, lr, hidden, version]
    key += [variants, seed]
    state = _load_progress(resume_file, key)
    if state is not None:
        ident.load_state_dict(state["identifier_state"])
        opt.load_state_dict(state["optimizer_state"])
        gen.set_state(state["generator"])
        rows = state["rows"]
    start = state["iteration"] + 1 if state is not None else 0
    for it in range(start, iterations):
        trajs, settled = samples(it)
        if not rows:  # the first batch fixes the input scales
            with torch.no_grad():
                ident.standardise_from(
                    torch.cat([trajectory_inputs(t)[:, settled] for t in trajs], dim=1)
                )
        loss = loss_of(trajs, settled)
        opt.zero_grad()
        loss.backward()
        opt.step()
        rows.append({"iteration": it, "loss": float(loss.detach())})
        if resume_file is not None and (it + 1) % checkpoint_every == 0 and it + 1 < iterations:
            progress_state = {"key": key, "iteration": it, "rows": rows}
            progress_state["identifier_state"] = ident.state_dict()
            progress_state["optimizer_state"] = opt.state_dict()
            atomic_torch_save({**progress_state, "generator": gen.get_state()}, Path(resume_file))
        if progress is not None:
            progress(it, rows[-1]["loss"])
    trajs, settled = samples(iterations)  # a draw never trained on
    with torch.no_grad():
        err = torch.stack([(ident.of_trajectory(t) - t.dynamics).abs() for t in trajs])
        held_out = err[:, settled].mean((0, 1))
        varied = torch.stack([t.dynamics for t in trajs]).abs().amax((0, 1)) > 0
    info = {"hidden": hidden, "size": ident.size, "iterations": iterations, "version": version}
    _write_run(run_dir, dst, m.ckpt, ident, info, rows)
    summary = {
        "loss": rows[-1]["loss"] if rows else float("nan"),
        "held_out": float(held_out[varied].mean()) if bool(varied.any()) else 0.0,
        "varied": int(varied.sum()),
        "seconds": time.perf_counter() - t0,
        "iterations": iterations,
        "version": version,
        **({"variants": variants} if variants is not None else {}),
    }
    atomic_write_text(dst / SUMMARY_FILE, json.dumps(summary) + "\n")
    if resume_file is not None:
        Path(resume_file).unlink(missing_ok=True)
    return summary


def _told_run(run_dir: str, goals: int, inits: int, seed: int, device: str, variants: str | None):
    """The told run's meta-test set-up (``goals x inits`` worlds), the ranges the models are drawn
    from and the ``variants`` text (``None``: the run's own ``train_variants``); the runs and ranges
    an identifier cannot be trained for are refused here, before any work."""
    from warp_critic.learning.critic_inputs import DYNAMICS, rollout_data_of
    from warp_critic.physics.variant_draws import parse_ranges, ranges_on_scene
    from warp_critic.running.metatest_setup import MetaTestConfig, setup_meta_test
    from warp_critic.running.task import task_variant

    tc = MetaTestConfig(
        run_dir=run_dir, num_goals=goals, inits=inits, goal_std=0.3, seed=seed, device=device
    )
    m = setup_meta_test(tc)
    if DYNAMICS not in rollout_data_of(m.critic):
        raise UserError(
            f"{run_dir}: its critic is not told the model (critic input "
            f"{m.ckpt.get('critic_input')!r}); identify a pose-dynamics or relative-dynamics run"
        )
    variants = variants or None
    if variants is None:
        ranges = parse_ranges(m.ckpt["config"].get("train_variants"))
        if not ranges:
            raise UserError(
                f"{run_dir}: trained on one model (no train_variants): nothing to identify"
            )
    else:  # other draws than training's (the same text form, checked on the scene before any work)
        ranges = ranges_on_scene(m.scene, task_variant(m.cfg), variants)
        if m.ckpt["config"].get("on_divergence", "stop") == "stop":
            # the models the run's step cannot hold are refused up front, as meta-train refuses them
            from warp_critic.methods.train_variants import check_held

            check_held(m.cfg, m.scene, ranges, variants)
    return m, ranges, variants


def _sampler(m, ranges, seed: int, gen: torch.Generator):
    """``samples(it)``: iteration ``it``'s rollouts of fresh policies (drawn from ``gen``) and of
    their updates by the told critic, each world under a model drawn for ``(seed, it)``, and the
    worlds that stayed settled; a diverged world is handled as the run's ``on_divergence``."""
    from warp_critic.learning.rollout import settled_worlds
    from warp_critic.physics.redraw import set_variants
    from warp_critic.physics.variant_draws import draw, with_draws
    from warp_critic.running.task import task_variant

    base, W, dev = task_variant(m.cfg), m.sim.worlds, m.sim.torch_device
    drop = m.ckpt["config"].get("on_divergence") == "drop"  # as the run's meta-train did

    def samples(it: int):
        values = draw(ranges, W, DRAW_SEED_OFFSET + seed, it)
        set_variants(m.sim, [with_draws(base, ranges, v) for v in values])
        params = {
            k: v.requires_grad_(True)
            for k, v in m.policy.init(W, generator=gen, device=dev).items()
        }
        _, trajs = m.update(params, check=False, guard=True)
        settled = torch.stack([settled_worlds(t) for t in trajs]).all(0)
        if not bool(settled.all()) and (not drop or not bool(settled.any())):
            w = int((~settled).nonzero()[0, 0])
            model = "; ".join(c.text() for c in with_draws(base, ranges, values[w]).changes)
            raise DivergenceError(
                f"iteration {it} of the identification: world {w} diverged under the drawn model {model!r} "
                + (
                    "(every world did)"
                    if drop
                    else "(the run stops on divergence, on_divergence stop)"
                ),
                world=w,
            )
        return trajs, settled

    return samples


def _write_run(run_dir: str, dst: Path, ckpt: dict, ident, info: dict, rows: list[dict]) -> None:
    """``dst``: a copy of the told run, its checkpoint ``ckpt`` with the identifier's state and
    settings ``info``, and the regression's losses ``rows``."""
    from warp_critic.running.files import atomic_torch_save, atomic_write_text

    shutil.copytree(
        run_dir,
        dst,
        ignore=shutil.ignore_patterns("recording.rrd", "metatest.json", ".lock"),
        dirs_exist_ok=True,
    )
    ckpt = dict(ckpt)
    ckpt["identifier_state"] = {k: v.detach().cpu() for k, v in ident.state_dict().items()}
    ckpt["identifier"] = info
    atomic_torch_save(ckpt, dst / "checkpoint.pt")
    atomic_write_text(dst / IDENTIFY_FILE, "".join(json.dumps(r) + "\n" for r in rows))


def _load_progress(path: str | Path | None, key: list) -> dict | None:
    """The saved regression state of the same run and settings at ``path``, or ``None`` (none, or
    of other settings: it starts over)."""
    if path is None or not Path(path).is_file():
        return None
    try:
        state = torch.load(Path(path), weights_only=True)
    except Exception:  # noqa: BLE001 - a cut or foreign file: start over
        return None
    return state if isinstance(state, dict) and state.get("key") == key else None


def identified(out: str | Path) -> dict | None:
    """The summary of a complete identified run ``out`` (:func:`train_identifier`'s), or ``None``."""
    try:
        data = json.loads((Path(out) / SUMMARY_FILE).read_text())
    except (OSError, ValueError, UnicodeDecodeError):
        return None
    keys = ("loss", "held_out", "varied", "seconds", "iterations")
    return data if isinstance(data, dict) and all(k in data for k in keys) else None


def probe_identifier(
    run_dir: str,
    variants: list[str],
    *,
    goals: int = 4,
    goal_std: float = 0.0,
    inits: int = 5,
    seed: int = 1,
    device: str = "cpu",
) -> dict:
    """What an identified run's identifier reads from each rollout of a meta-test, model by model.

    For each ``--variant`` text in ``variants``: a meta-test's fresh policies (``goals x inits``
    worlds around the training goals, ``goal_std`` rad) updated by the identified critic as
    meta-test does; per update, the identifier's estimate from the rollout that update evaluated,
    its mean and standard deviation over the worlds that stayed finite, beside the model's true
    descriptor. Returns ``{"names": the K descriptor entries' names, "rows": [{"variant", "truth"
    (K,), "mean" (updates, K), "std" (updates, K), "torque" (updates,): the mean |tau| (N m) of
    each rollout}]}``."""
    from warp_critic.learning.identify import IdentifiedCritic
    from warp_critic.learning.rollout import settled_worlds
    from warp_critic.running.metatest_setup import MetaTestConfig, setup_meta_test

    rows, names = [], None
    for text in variants:
        tc = MetaTestConfig(
            run_dir=run_dir,
            num_goals=goals,
            goal_std=goal_std,
            inits=inits,
            seed=seed,
            device=device,
            variant=text,
        )
        m = setup_meta_test(tc)
        if not isinstance(m.critic, IdentifiedCritic):
            raise UserError(
                f"{run_dir}: its critic has no model identifier (see warp-critic identify --help)"
            )
        names = m.sim.dynamics_names
        _, trajs = m.update(m.params, check=False, guard=True)
        with torch.no_grad():
            ok = torch.stack([settled_worlds(t) for t in trajs]).all(0)
            est = torch.stack([m.critic.identifier.of_trajectory(t) for t in trajs])[:, ok]
        rows.append(
            {
                "variant": text,
                "truth": trajs[0].dynamics[0].tolist(),
                "mean": est.mean(1).tolist(),
                "std": est.std(1, unbiased=est.shape[1] > 1).tolist(),
                "torque": [float(t.tau.abs().mean()) for t in trajs],
            }
        )
    return {"names": names, "rows": rows}
