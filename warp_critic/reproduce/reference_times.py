"""A stage's time in a reference run (by default the published one, ``docs/paper/stages``): what
``reproduce --status`` and ``--hours`` (:mod:`warp_critic.reproduce.status`) reckon a stage not run
yet by. A record's time is split into training and identification, because a recipe that
identifies the model trains one identifier per seed after its meta-training, one after the other
(about twice the meta-training's time for ``pose-dynamics-full``), and its record's own ``seconds``
count only its last call."""

from __future__ import annotations

from pathlib import Path

from warp_critic.reproduce.engine.stage import stage_of_dir

__all__ = ["parts", "recorded", "reference_by_name", "took", "total"]


def parts(data: dict, kind: str) -> tuple[float, float]:
    """A complete stage's ``(training, identification)`` seconds from its record. A meta-training
    resumed over calls took its seeds' iteration times (they train as one batch), not its last
    call's; a recipe that identifies the model then trains one identifier per seed, one after the
    other (``seeds.*.identified.seconds``)."""
    seeds = (data.get("result") or {}).get("seeds") if kind == "metatrain" else None
    rows = [v for v in (seeds or {}).values() if isinstance(v, dict)]
    ident = sum(
        float(v["identified"].get("seconds", 0.0))
        for v in rows
        if isinstance(v.get("identified"), dict)
    )
    train = max([float(v.get("seconds", 0.0)) for v in rows], default=0.0)
    return max(float(data["seconds"]) - ident, train), ident


def took(data: dict, kind: str) -> float:
    """A complete stage's time (s) from its record (:func:`parts`, summed)."""
    return sum(parts(data, kind))


def recorded(reference: Path | None, directory: str, kind: str) -> tuple[float, float] | None:
    """The ``(training, identification)`` seconds the stage ``directory`` took in the
    ``reference`` archive, where it has a record."""
    from warp_critic.reproduce.engine.stages import read_stage, record_problem

    data = read_stage(reference / directory) if reference is not None else None
    return None if data is None or record_problem(data) else parts(data, kind)


def total(p: tuple[float, float] | None) -> float | None:
    """``p``'s training and identification seconds summed; ``None`` for ``None``."""
    return None if p is None else sum(p)


def _iterations(settings) -> int | None:
    values = settings.get("values") if isinstance(settings, dict) else None
    n = values.get("iterations") if isinstance(values, dict) else None
    return n if isinstance(n, int) and not isinstance(n, bool) and n > 0 else None


#: settings that do not change a meta-training's work per iteration: a step size, how often it
#: writes (``iterations`` itself scales the time)
_COST_NEUTRAL = ("iterations", "record_every", "checkpoint_every")


def _leaves(x, prefix: str = "") -> dict:
    if not isinstance(x, dict):
        return {prefix: x}
    out = {}
    for k, v in x.items():
        out.update(_leaves(v, f"{prefix}{k}."))
    return out


def _same_work(a, b) -> bool:
    """Whether meta-training settings ``a`` and ``b`` differ only in step sizes (``*_lr``) and
    :data:`_COST_NEUTRAL` entries: the same work per iteration."""
    la, lb = _leaves(a), _leaves(b)
    for key in set(la) | set(lb):
        if la.get(key) != lb.get(key):
            leaf = key.rstrip(".").rpartition(".")[2]
            if not (leaf.endswith("_lr") or leaf in _COST_NEUTRAL):
                return False
    return True


def reference_by_name(reference: Path | None, name: str, st) -> tuple[float, float] | None:
    """A meta-training's time estimated from the ``reference`` archive's record of the stage of the
    same name whose settings differ only in step sizes or length (a tuned step size changes the
    hash, not the work): its ``(training, identification)`` seconds, the training's per iteration
    times this stage's iterations. ``None`` where there is none (other settings may do other work
    per iteration: no estimate)."""
    from warp_critic.reproduce.engine.stages import read_stage, record_problem

    if reference is None or not reference.is_dir():
        return None
    want = _iterations(st.settings)
    for d in sorted(reference.glob(f"{name}-*")):
        if stage_of_dir(d.name) != name:
            continue  # another stage whose name starts with this one's
        data = read_stage(d)
        if (
            data is None
            or record_problem(data)
            or not _same_work(st.settings, data.get("settings"))
        ):
            continue
        had = _iterations(data.get("settings"))
        if want is None or had is None:
            continue
        train, ident = parts(data, st.kind)
        return train * want / had, ident
    return None
