"""Does a run's integrator step hold the models a ``--train-variants`` range draws? A short probe.

Every end of every range (alone, on the world's own variant) and, for a group of several ranges,
all their low ends and all their high ends together, gets a few rollouts from the home pose under
saturated torques ``+-bound`` whose random signs (seeded) are redrawn every few control steps: the
bang-bang a fresh or badly trained policy plays, slamming the joints into their limits
(``tools/probe_variants.py`` prints a longer such probe for any variant). A model whose rollout goes
non-finite or beyond ``limit`` (the training guard's bound) stops a training run at once, so
meta-training refuses such a range up front and says from which value the model holds: the values
between the failing end and a model that holds (the range's other end, else the link unchanged)
are probed on a grid of :data:`GRID` points.

All probed models are worlds of one simulator, on the CPU, without gradients or graph capture: on
the reacher the probe takes a fraction of a second.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from warp_critic.physics.link_changes import LinkChange
from warp_critic.physics.scene import Scene, Variant
from warp_critic.physics.variant_draws import ChangeRange, groups, with_draws

#: rollouts per probed model; control steps a torque sign is held; most control steps probed;
#: candidate values between a failing end and a model that holds
ROLLOUTS = 4
HOLD = 5
MAX_STEPS = 60
GRID = 12
REMEDY = (
    "narrow the range, take a smaller dt or more substeps, or drop diverged worlds "
    "(on-divergence drop)"
)


@dataclass(frozen=True)
class Probe:
    """The run's step: what the probe simulates with (the filled training config's values)."""

    dt: float
    substeps: int
    gravity: float
    bound: Sequence[float]  # (dof,) torque bound of the policy
    steps: int  # control steps per rollout (the run's horizon; at most MAX_STEPS are probed)
    limit: float = 1e4  # |q| or |qd| beyond this counts as diverged (the training guard's bound)
    seed: int = 0

    def describe(self) -> str:
        return f"dt {self.dt:g} s x {self.substeps} substep(s)"


def failing(scene: Scene, variants: Sequence[Variant], probe: Probe) -> list[int]:
    """For each variant, how many of its :data:`ROLLOUTS` saturated-torque rollouts diverged."""
    import torch

    from warp_critic.physics.simulator import Simulator

    variants = list(variants)
    if not variants:
        return []
    sim = Simulator(
        scene,
        [v for v in variants for _ in range(ROLLOUTS)],
        dt=probe.dt,
        substeps=probe.substeps,
        device="cpu",
        differentiable=False,
        gravity=probe.gravity,
        graphs=False,
    )
    worlds = sim.worlds
    bound = torch.as_tensor(np.asarray(probe.bound, dtype=np.float32)).expand(worlds, scene.dof)
    gen = torch.Generator().manual_seed(probe.seed)
    home = getattr(scene, "home", None)
    q = torch.as_tensor(np.zeros(scene.dof) if home is None else home, dtype=torch.float32).expand(
        worlds, -1
    )
    q = q.clone()
    qd = torch.zeros_like(q)
    bad = torch.zeros(worlds, dtype=torch.bool)
    sign = torch.ones_like(q)
    with torch.no_grad():
        for t in range(min(int(probe.steps), MAX_STEPS)):
            if t % HOLD == 0:
                sign = torch.randint(0, 2, q.shape, generator=gen).float() * 2 - 1
            q, qd = sim.step(q, qd, sign * bound)
            ok = (
                torch.isfinite(q).all(-1)
                & torch.isfinite(qd).all(-1)
                & (q.abs().amax(-1) <= probe.limit)
                & (qd.abs().amax(-1) <= probe.limit)
            )
            bad |= ~ok
            q = torch.where(ok[:, None], q, torch.zeros_like(q))  # keep the others finite
            qd = torch.where(ok[:, None], qd, torch.zeros_like(qd))
            if bool(bad.all()):
                break
    return [int(x) for x in bad.view(len(variants), ROLLOUTS).sum(1)]


def _nominal(scene: Scene, base: Variant, change: LinkChange) -> float:
    """The value ``change`` would have to leave its link as the world's own variant has it."""
    if change.op == "+=":
        return 0.0
    if change.op == "*=":
        return 1.0
    from warp_critic.physics.variants import link_value

    builder = scene.world_builder(base)
    tip = scene.tip_offset_of(base)
    return link_value(builder, change, list(scene.body_names), scene.ee_body, tip)


def _grid(bad: float, good: float) -> list[float]:
    """:data:`GRID` values from next to ``bad`` to ``good`` (geometric over a wide positive span)."""
    if bad > 0 and good > 0 and max(bad, good) / min(bad, good) > 10:
        return [float(x) for x in np.geomspace(bad, good, GRID + 1)[1:]]
    return [float(x) for x in np.linspace(bad, good, GRID + 1)[1:]]


def _round_toward(x: float, good: float) -> float:
    """``x`` to two significant digits, rounded toward ``good`` (away from the failing end)."""
    if x == 0:
        return 0.0
    scale = 10 ** (math.floor(math.log10(abs(x))) - 1)
    up = good > x
    return float((math.ceil if up else math.floor)(x / scale) * scale)


def _holds_from(
    scene: Scene, base: Variant, r: ChangeRange, bad: float, good: float, probe: Probe
) -> float | None:
    """The value from which every probed model up to ``good`` holds (two digits, toward ``good``),
    or ``None``: the first holding value alone would be advice that a narrower range then contradicts
    where a failing value lies between it and ``good``."""
    values = _grid(bad, good)
    counts = failing(scene, [with_draws(base, (r,), [v]) for v in values], probe)
    last_bad = max((k for k, n in enumerate(counts) if n), default=-1)
    if last_bad + 1 >= len(values):
        return None
    return _round_toward(values[last_bad + 1], good)


def check_ranges(
    scene: Scene, base: Variant, ranges: tuple[ChangeRange, ...], probe: Probe
) -> str | None:
    """``None`` if the probe holds every model the ranges' ends make; else one line naming the first
    end that fails and the value from which the model holds (module docstring)."""
    cases: list[tuple[int | None, str, list[float]]] = []  # (range or None, which end, values)
    for i, r in enumerate(ranges):
        for end in ("lo", "hi") if r.lo != r.hi else ("lo",):
            values = [np.nan] * len(ranges)
            values[i] = getattr(r, end)
            cases.append((i, end, values))
    for g in range(groups(ranges)):
        members = [r for r in ranges if r.group == g]
        if len(members) > 1:
            for end in ("lo", "hi"):
                values = [getattr(r, end) if r.group == g else np.nan for r in ranges]
                cases.append((None, end, values))
    inside = []  # (range, value) inside each range: a model in the middle may fail where the ends hold
    for i, r in enumerate(ranges):
        if r.lo != r.hi:
            inside += [(i, v) for v in _grid(r.lo, r.hi)[:-1]]
    counts = failing(
        scene,
        [with_draws(base, ranges, v) for _, _, v in cases]
        + [with_draws(base, (ranges[i],), [v]) for i, v in inside],
        probe,
    )
    counts, inside_counts = counts[: len(cases)], counts[len(cases) :]
    alone = {(i, end): n for (i, end, _), n in zip(cases, counts) if i is not None}
    for (index, end, values), n in zip(cases, counts):
        if n == 0:
            continue
        held = f"{n} of {ROLLOUTS} probe rollouts under saturated torques diverged"
        if index is None:
            text = "; ".join(ranges[k].at(v).text() for k, v in enumerate(values) if v == v)
            return (
                f"{scene.name}'s step ({probe.describe()}) does not hold {text} together ({held}): "
                + REMEDY
            )
        i, r = index, ranges[index]
        bad = getattr(r, end)
        other = r.hi if end == "lo" else r.lo
        if r.lo != r.hi and alone.get((i, "hi" if end == "lo" else "lo")) == 0:
            good = other
        else:
            good = _nominal(scene, base, r.change)
        holds = None if good == bad else _holds_from(scene, base, r, bad, good, probe)
        where = (
            f"it holds from about {r.at(holds).text()} (probed)"
            if holds is not None
            else "no value between it and the unchanged link holds"
        )
        return (
            f"{scene.name}'s step ({probe.describe()}) does not hold {r.at(bad).text()} ({held}); "
            f"{where}: {REMEDY}"
        )
    for k, ((i, v), n) in enumerate(zip(inside, inside_counts)):
        if n == 0:
            continue
        r = ranges[i]
        held_up_to = [u for (j, u), m in zip(inside[:k], inside_counts[:k]) if j == i and m == 0]
        where = (
            f"it holds from {r.at(r.lo).text()} up to about "
            f"{r.at(_round_toward(held_up_to[-1], r.lo)).text()} (probed)"
            if held_up_to
            else f"only values next to {r.at(r.lo).text()} may hold"
        )
        return (
            f"{scene.name}'s step ({probe.describe()}) holds the ends of {r.text()} but not "
            f"{r.at(v).text()} inside it ({n} of {ROLLOUTS} probe rollouts under saturated "
            f"torques diverged); {where}: {REMEDY}"
        )
    return None


__all__ = ["Probe", "failing", "check_ranges", "ROLLOUTS", "HOLD", "MAX_STEPS", "GRID"]
