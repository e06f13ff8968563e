"""One batch's meta-test descent (:func:`descend`), and what it keeps on disk so that a killed call
goes on where it was.

A meta-test of hundreds of critic-gradient steps on thousands of worlds runs for hours (the
meta-test budget stages, :mod:`~warp_critic.reproduce.experiments.budget`); a session, a laptop lid
or a cluster's time limit ends it. :func:`~warp_critic.reproduce.experiments.evaluate.evaluate`
therefore keeps, per batch of worlds, in a folder its caller names (a stage's
:data:`~warp_critic.reproduce.engine.stage.PROGRESS` folder):

* ``batch-B.pt`` once batch ``B`` is done: its errors and its runs' step sizes;
* ``batch-B-partial.pt`` while it runs, rewritten every few minutes: its policies after the steps
  taken so far and what was read on the way (the untrained errors, the finite worlds, the errors at
  the budgets passed).

Resuming gives the same numbers as one uninterrupted call: a critic-gradient step is a function of
the policies alone (no optimiser state, no randomness), and the batches are independent
(``tests/test_descent.py`` compares bit for bit). Each file names the fingerprint of its
batch's inputs (the jobs, their goals, variants and step-size multiples, the runs' identities, the
budget, the seed, the horizon, the device); a file of other inputs is not used, and is replaced.
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from warp_critic.core.errors import warn
from warp_critic.running.files import atomic_torch_save


def run_key(run_dir: str | Path) -> str:
    """How a batch's files name a run: its last three path parts (``STAGE/run/seedN``), so that the
    same batch in an output folder restored elsewhere from an archive (another machine, another
    folder) is the same batch."""
    return "/".join(Path(run_dir).parts[-3:])


def fingerprint(jobs: list, runs: dict, settings: dict, key=run_key) -> str:
    """A hash of one batch's inputs: ``jobs`` (its :class:`~.evaluate.Job` list; each run by
    ``key``, :func:`run_key` unless two runs share one), ``runs`` (run
    directory -> its loaded run: the checkpoint's run id and iteration count) and ``settings``
    (plain JSON: steps, inits, seed, horizon, budgets read, device)."""
    described = [
        {
            "key": repr(j.key),
            "run_dir": key(j.run_dir),
            "run": [runs[str(j.run_dir)].ckpt.get(k) for k in ("run_id", "iteration")],
            "goals": j.goals.to(torch.float64).tolist(),
            "variant": repr(j.variant),
            "alpha_scale": float(j.alpha_scale),
        }
        for j in jobs
    ]
    text = json.dumps({"settings": settings, "jobs": described}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


@dataclass
class Partial:
    """An unfinished batch: ``done`` steps taken; ``params`` the policies after them (CPU);
    ``err0 (W,)`` the untrained final errors (rad^2), ``ok0``/``ok (W,)`` the worlds finite before
    and so far, ``err_at`` the errors at the budgets already passed."""

    done: int
    params: dict[str, torch.Tensor]
    err0: np.ndarray
    ok0: torch.Tensor
    ok: torch.Tensor
    err_at: dict[int, np.ndarray]


class BatchProgress:
    """The progress files of batch ``index`` under ``folder`` for the inputs ``key`` (a
    :func:`fingerprint`)."""

    def __init__(self, folder: Path, index: int, key: str):
        self.folder, self.key = Path(folder), key
        self.done_file = self.folder / f"batch-{index}.pt"
        self.partial_file = self.folder / f"batch-{index}-partial.pt"

    def _load(self, path: Path) -> dict[str, Any] | None:
        if not path.is_file():
            return None
        try:
            data = torch.load(path, map_location="cpu", weights_only=True)
        except Exception as e:  # a torn or foreign file: its work is lost, never used wrongly
            warn(f"{path}: unreadable ({type(e).__name__}); the batch starts again")
            return None
        if not isinstance(data, dict) or data.get("fingerprint") != self.key:
            return None  # another call's inputs: replaced when this batch saves
        return data

    def finished(self) -> tuple[tuple, dict[str, float]] | None:
        """A done batch's ``((err0, err, diverged, err_at), alphas)``, or ``None``."""
        d = self._load(self.done_file)
        if d is None:
            return None
        err_at = {int(n): e.numpy() for n, e in d["err_at"].items()}
        result = (d["err0"].numpy(), d["err"].numpy(), int(d["diverged"]), err_at)
        return result, {str(k): float(v) for k, v in d["alphas"].items()}

    def partial(self) -> Partial | None:
        d = self._load(self.partial_file)
        if d is None:
            return None
        return Partial(
            done=int(d["done"]),
            params=dict(d["params"]),
            err0=d["err0"].numpy(),
            ok0=d["ok0"],
            ok=d["ok"],
            err_at={int(n): e.numpy() for n, e in d["err_at"].items()},
        )

    def save_partial(self, state: Partial) -> None:
        self.folder.mkdir(parents=True, exist_ok=True)
        atomic_torch_save(
            {
                "fingerprint": self.key,
                "done": int(state.done),
                "params": {k: v.detach().cpu() for k, v in state.params.items()},
                "err0": torch.from_numpy(np.asarray(state.err0)),
                "ok0": state.ok0.cpu(),
                "ok": state.ok.cpu(),
                "err_at": {str(n): torch.from_numpy(e) for n, e in state.err_at.items()},
            },
            self.partial_file,
        )

    def finish(self, result: tuple, alphas: dict[str, float]) -> None:
        """Keep a done batch's ``result`` (as :meth:`finished` returns it) and drop its partial."""
        err0, err, diverged, err_at = result
        self.folder.mkdir(parents=True, exist_ok=True)
        atomic_torch_save(
            {
                "fingerprint": self.key,
                "err0": torch.from_numpy(np.asarray(err0)),
                "err": torch.from_numpy(np.asarray(err)),
                "diverged": int(diverged),
                "err_at": {str(n): torch.from_numpy(e) for n, e in err_at.items()},
                "alphas": dict(alphas),
            },
            self.done_file,
        )
        self.partial_file.unlink(missing_ok=True)


class PerWorldRate:
    """A learning rate per world: ``rate * grad`` scales each world's (leading-dim) gradient."""

    def __init__(self, rates: torch.Tensor):
        self.rates = rates

    def __mul__(self, grad: torch.Tensor) -> torch.Tensor:
        return self.rates.view(-1, *[1] * (grad.dim() - 1)) * grad

    __rmul__ = __mul__


#: critic-gradient steps taken between two looks at the clock (and at the worlds' finiteness):
#: the rollouts of at most this many steps are held at once
STEPS_PER_CHUNK = 10


def descend(
    sim, policy, critic, rate, goal, p, horizon: int, steps: int, at=(), saved=None, every=300.0
):
    """``steps`` policy updates with the critics from home; returns the final errors before and
    after ``(W,)`` rad^2 (``inf`` where a world diverged), the number of diverged worlds and
    ``{n: (W,) errors after n updates}`` for each ``n`` in ``at`` (one descent, read on the way).
    ``saved``: a :class:`BatchProgress` this descent starts from (where it holds
    one) and saves to every ``every`` seconds (wall)."""
    from warp_critic.learning.inner import inner_update, policy_fn
    from warp_critic.learning.losses import final_error
    from warp_critic.learning.rollout import finite_worlds, rollout

    q0, qd0 = sim.zeros(), sim.zeros()
    state = saved.partial() if saved is not None else None
    if state is None:
        untrained = rollout(sim, policy_fn(policy, p), q0, qd0, horizon, check=False)
        err0 = final_error(untrained.q[-1], goal).detach().cpu().numpy()
        ok0 = finite_worlds(untrained)
        state = Partial(0, p, err0, ok0, ok0.clone(), {})
    else:
        dev = goal.device
        state.params = {k: v.to(dev).requires_grad_(True) for k, v in state.params.items()}
        state.ok0, state.ok = state.ok0.to(dev), state.ok.to(dev)
    stops = sorted({int(n) for n in at} | {int(steps)})
    clock = time.monotonic()
    err = None
    while state.done < steps:
        stop = next(n for n in stops if n > state.done)
        state.params, trajs = inner_update(
            critic,
            policy,
            state.params,
            sim,
            q0,
            qd0,
            goal,
            horizon=horizon,
            alpha=PerWorldRate(rate),
            steps=min(stop - state.done, STEPS_PER_CHUNK),
            create_graph=False,
            check=False,
        )
        state.done += len(trajs)
        for t in trajs:
            state.ok &= finite_worlds(t)
        if state.done == stop:
            after = rollout(sim, policy_fn(policy, state.params), q0, qd0, horizon, check=False)
            err = final_error(after.q[-1], goal).detach().cpu().numpy()
            state.ok &= finite_worlds(after)
            err = np.where(state.ok.cpu().numpy(), err, np.inf)
            if stop in at:
                state.err_at[stop] = err
        if saved is not None and state.done < steps and time.monotonic() - clock > every:
            saved.save_partial(state)
            clock = time.monotonic()
    assert err is not None  # the last stop is ``steps``
    err0 = np.where(state.ok0.cpu().numpy(), state.err0, np.inf)
    return err0, err, int((~state.ok).sum()), state.err_at
